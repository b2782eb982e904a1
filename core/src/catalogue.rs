//! The message catalogue: every fact about a message that is not a field
//! layout, written once per message ID.
//!
//! Each entry states the ID, the name, whether the message queries or acts,
//! the controller families and generations that know it, whether sending it
//! twice is harmless, what the controller answers, how completely the
//! manuals document it, and where its frames carry raw text. Everything
//! else derives from here: the typed messages bind their structs to these
//! entries, [`crate::profile`] decides support from the families, the
//! decoder and the frame check take the text rule from
//! [`MessageInfo::text`], and the request engines take resend safety and
//! the reply kind from it.
//!
//! Sources: the message list of the 2003 X-SEL specification (2003
//! pp. 11–12: type and Cartesian / IX SCARA applicability) and the TTA
//! manual (section 4-3). Where neither states a fact it says so below.
//!
//! ```
//! use iai_protocol_b::catalogue::{self, Resend};
//! let m = catalogue::lookup(0x235).unwrap();
//! assert_eq!(m.name, "Relative-Coordinate Specification Movement");
//! assert_eq!(m.resend, Resend::Unsafe); // a lost reply must not move the axis twice
//! assert!(catalogue::lookup(0x217).is_none());
//! ```

use crate::header::Header;

/// What a message does (2003 pp. 11–12, "Type").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Kind {
    /// Reads state; changes nothing.
    Query,
    /// Changes state or starts an action.
    Execute,
}

/// Controller families that accept a message (2003 pp. 11–12, "Applicable
/// type": Cartesian and IX SCARA), as a set.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Families(u8);

impl Families {
    /// Cartesian controllers (TTA, X-SEL Cartesian, SSEL, ASEL, PSEL).
    pub const CARTESIAN: Families = Families(1);
    /// IX SCARA controllers.
    pub const SCARA: Families = Families(2);
    /// Both families.
    pub const BOTH: Families = Families(3);

    /// Whether every family of `other` is in `self`.
    pub const fn contains(self, other: Families) -> bool {
        self.0 & other.0 == other.0
    }

    /// Whether the two sets share a family.
    pub const fn intersects(self, other: Families) -> bool {
        self.0 & other.0 != 0
    }
}

/// The controller generation that introduced a message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Generation {
    /// Already in the 2003 X-SEL specification (X-SEL J/K, TT and later).
    Xsel2003,
    /// Documented only in the TTA manual (TTA, X-SEL P/Q/R/S…, SSEL, ASEL,
    /// PSEL): the 4-digit position messages, 271H, 2A3H, 2A4H.
    Tta,
}

/// Whether a command may be sent again when its reply was lost.
///
/// A lost reply does not mean a lost command: the controller may have
/// executed it. Sending it again executes it twice. For a query, or a
/// command that sets an absolute state (a position, a port, a target
/// coordinate), that is harmless; for a relative move it moves the axis
/// twice.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Resend {
    /// Executing it twice leaves the controller as executing it once.
    Safe,
    /// Executing it twice does something else (a second relative move, a
    /// second program step): the request engines do not resend it unless
    /// the caller opts in.
    Unsafe,
}

/// What the controller answers to a command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Reply {
    /// A normal (`#`) or error (`&`) response.
    Normal,
    /// No normal response; an error response is still possible. The
    /// controller accepts commands again about `ready_after_ms` after the
    /// command was sent (25BH, 2003 p. 50: "approx. 10 seconds").
    None {
        /// How long after the command the controller is ready again, ms.
        ready_after_ms: u32,
    },
}

/// How completely the manuals document a message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Status {
    /// Every field of both directions is documented.
    Complete,
    /// Some rows are missing or contradictory; the declared layout is a
    /// chosen reading (see the message type's documentation).
    Partial,
}

/// Where a message's frames carry raw characters instead of hex digits.
///
/// Only two messages do: 200H (10 characters echoed, both directions) and
/// the 216H response (a message string whose length is the 2 hex digits
/// before it). Everywhere else every body byte is a hex digit. Offsets are
/// frame offsets, counted from the header byte.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TextField {
    /// Bytes `start..end` of commands and normal responses.
    Fixed {
        /// First text byte.
        start: usize,
        /// One past the last text byte.
        end: usize,
    },
    /// In normal responses only: the 2 hex digits at `start - 2` give the
    /// number of text bytes from `start` on.
    CountedInResponse {
        /// First text byte; its count field ends here.
        start: usize,
    },
}

impl TextField {
    /// Frame offsets `[start, end)` of the text in a frame of this kind
    /// starting with `prefix`; `None` if the frame kind carries no text
    /// here or `prefix` is too short to tell.
    pub fn span(self, header: Header, prefix: &[u8]) -> Option<(usize, usize)> {
        match (self, header) {
            (TextField::Fixed { start, end }, Header::Command | Header::Response) => {
                Some((start, end))
            }
            (TextField::CountedInResponse { start }, Header::Response) => {
                let at = start.checked_sub(2)?;
                let n = hex_number(prefix.get(at..start)?)?;
                Some((start, start + usize::from(n)))
            }
            _ => None,
        }
    }

    /// How many bytes of a frame must be known to locate the text.
    pub const fn known_by(self) -> usize {
        match self {
            TextField::Fixed { start, .. } | TextField::CountedInResponse { start } => start,
        }
    }
}

/// Every fact about one message except its field layout.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MessageInfo {
    /// The message ID (3 hex digits on the wire).
    pub id: u16,
    /// The name (TTA wording; the 2003 names in `messages.toml`).
    pub name: &'static str,
    /// Query or execute.
    pub kind: Kind,
    /// Families that accept it.
    pub families: Families,
    /// The first generation that knows it.
    pub since: Generation,
    /// Whether a resend after a lost reply is harmless.
    pub resend: Resend,
    /// What the controller answers.
    pub reply: Reply,
    /// How completely it is documented.
    pub status: Status,
    /// Where its frames carry raw text, if anywhere.
    pub text: Option<TextField>,
}

impl MessageInfo {
    /// Whether the controller answers with a normal response.
    pub const fn has_normal_response(&self) -> bool {
        matches!(self.reply, Reply::Normal)
    }
}

/// Shorthands for the table below.
mod abbrev {
    pub use super::Families as F;
    pub use super::Generation::{Tta as TTA, Xsel2003 as X2003};
    pub use super::Kind::{Execute as EXEC, Query as QUERY};
    pub use super::Resend::Safe as SAFE;
    pub const UNSAFE: super::Resend = super::Resend::Unsafe;
    pub use super::Status::{Complete as COMPLETE, Partial as PARTIAL};
    pub const BOTH: F = F::BOTH;
    pub const CART: F = F::CARTESIAN;
    pub const SCARA: F = F::SCARA;
}

macro_rules! catalogue {
    ($( $(#[$m:meta])* $konst:ident = $id:literal, $name:literal,
        $kind:ident, $fam:ident, $gen:ident, $resend:ident, $status:ident
        $(, reply: $reply:expr)? $(, text: $text:expr)? ; )*) => {
        $(
            $(#[$m])*
            #[doc = concat!("`", stringify!($id), "` ", $name, ".")]
            pub const $konst: MessageInfo = {
                #[allow(unused_imports)]
                use abbrev::*;
                MessageInfo {
                    id: $id,
                    name: $name,
                    kind: $kind,
                    families: $fam,
                    since: $gen,
                    resend: $resend,
                    reply: catalogue!(@reply $($reply)?),
                    status: $status,
                    text: catalogue!(@text $($text)?),
                }
            };
        )*

        /// Every message, by ascending ID.
        pub const ALL: &[&MessageInfo] = &[ $( &$konst ),* ];

        /// The longest any controller takes to accept commands again after
        /// a command without normal response (25BH: about 10 s, 2003 p. 50).
        pub const LONGEST_RESTART_MS: u32 = {
            let mut rest = ALL;
            let mut longest = 0;
            while let Some((info, tail)) = rest.split_first() {
                if let Reply::None { ready_after_ms } = info.reply {
                    if ready_after_ms > longest {
                        longest = ready_after_ms;
                    }
                }
                rest = tail;
            }
            longest
        };

        /// The entry of message `id`, if the catalogue has one.
        pub const fn lookup(id: u16) -> Option<&'static MessageInfo> {
            // A binary search over `ALL` (ascending, checked below at
            // compile time): in flash it is the 54 pointers of `ALL` and a
            // loop, where a `match` on the ID compiles to a large jump
            // table.
            let (mut lo, mut hi) = (0, ALL.len());
            while lo < hi {
                let mid = lo + (hi - lo) / 2;
                let Some((_, [entry, ..])) = ALL.split_at_checked(mid) else {
                    // Cannot happen: `mid < hi <= ALL.len()`.
                    return None;
                };
                if entry.id == id {
                    return Some(entry);
                }
                if entry.id < id {
                    lo = mid + 1;
                } else {
                    hi = mid;
                }
            }
            None
        }
    };
    (@reply) => { Reply::Normal };
    (@reply $r:expr) => { $r };
    (@text) => { None };
    (@text $t:expr) => { Some($t) };
}

catalogue! {
    /// Echoes 10 raw characters (2003 p. 15).
    TEST_CALL = 0x200, "Test Call", QUERY, BOTH, X2003, SAFE, COMPLETE,
        text: TextField::Fixed { start: 6, end: 16 };
    VERSION_QUERY = 0x201, "Version Code Query", QUERY, BOTH, X2003, SAFE, COMPLETE;
    EFFECTIVE_POSITION_COUNT_QUERY = 0x208, "Number of Effective Position Data Query",
        QUERY, BOTH, X2003, SAFE, COMPLETE;
    EFFECTIVE_POSITION_QUERY = 0x209, "Effective Position Data Query",
        QUERY, BOTH, X2003, SAFE, COMPLETE;
    INPUT_PORT_QUERY = 0x20B, "Input Port Query", QUERY, BOTH, X2003, SAFE, COMPLETE;
    OUTPUT_PORT_QUERY = 0x20C, "Output Port Query", QUERY, BOTH, X2003, SAFE, COMPLETE;
    FLAG_QUERY = 0x20D, "Flag Query", QUERY, BOTH, X2003, SAFE, COMPLETE;
    INTEGER_VARIABLE_QUERY = 0x20E, "Integer Variable Query", QUERY, BOTH, X2003, SAFE, COMPLETE;
    REAL_VARIABLE_QUERY = 0x20F, "Real Variable Query", QUERY, BOTH, X2003, SAFE, COMPLETE;
    STRING_VARIABLE_QUERY = 0x210, "String Variable Query", QUERY, BOTH, X2003, SAFE, COMPLETE;
    /// Cartesian only in the 2003 list (p. 11); SCARA controllers use 2A1H/2A3H.
    AXIS_STATUS_QUERY = 0x212, "Axis Status Query", QUERY, CART, X2003, SAFE, COMPLETE;
    PROGRAM_STATUS_QUERY = 0x213, "Program Status Query", QUERY, BOTH, X2003, SAFE, COMPLETE;
    SYSTEM_STATUS_QUERY = 0x215, "System Status Query", QUERY, BOTH, X2003, SAFE, COMPLETE;
    /// Its response ends in a message string of counted raw characters
    /// (always empty on the TTA, TTA p. 33).
    ERROR_DETAIL_QUERY = 0x216, "Error Detail Information Query",
        QUERY, BOTH, X2003, SAFE, COMPLETE,
        text: TextField::CountedInResponse { start: 90 };
    EFFECTIVE_POSITION_QUERY_2 = 0x21F, "Effective Position Data Query 2",
        QUERY, BOTH, TTA, SAFE, COMPLETE;
    EFFECTIVE_POSITION_QUERY_3 = 0x22D, "Effective Position Data Query 3",
        QUERY, BOTH, TTA, SAFE, COMPLETE;
    SERVO_ON_OFF = 0x232, "Servo ON/OFF", EXEC, BOTH, X2003, SAFE, COMPLETE;
    /// Cartesian only: on IX SCARA the 2003 list reserves it for IAI's own
    /// "Z-axis ABS reset position movement" (2003 p. 12, note *1).
    HOME_RETURN = 0x233, "Home Return", EXEC, CART, X2003, SAFE, COMPLETE;
    /// A target coordinate: sending it twice moves to the same place.
    ABSOLUTE_MOVE = 0x234, "Absolute-Coordinate Specification Movement",
        EXEC, CART, X2003, SAFE, COMPLETE;
    /// A distance: sending it twice moves the axis twice.
    RELATIVE_MOVE = 0x235, "Relative-Coordinate Specification Movement",
        EXEC, CART, X2003, UNSAFE, COMPLETE;
    /// Inching moves a distance: sending it twice inches twice.
    JOG_INCH = 0x236, "Jogging/Inching", EXEC, BOTH, X2003, UNSAFE, COMPLETE;
    POSITION_NUMBER_MOVE = 0x237, "Position-Number Specification Movement",
        EXEC, CART, X2003, SAFE, COMPLETE;
    OPERATION_STOP = 0x238, "Operation Stop & Cancel", EXEC, BOTH, X2003, SAFE, COMPLETE;
    RANGE_WRITE_POSITION_DATA = 0x244, "Position Data Range-Specification Continuous Write",
        EXEC, BOTH, X2003, SAFE, COMPLETE;
    CHANGE_POSITION_DATA = 0x245, "Change Position Data Continuous Write",
        EXEC, BOTH, X2003, SAFE, COMPLETE;
    CLEAR_POSITION_DATA = 0x246, "Position Data Clear", EXEC, BOTH, X2003, SAFE, COMPLETE;
    OUTPUT_PORT_CHANGE = 0x24A, "Output Port Status Change", EXEC, BOTH, X2003, SAFE, COMPLETE;
    FLAG_CHANGE = 0x24B, "Flag Status Change", EXEC, BOTH, X2003, SAFE, COMPLETE;
    INTEGER_VARIABLE_CHANGE = 0x24C, "Integer Variable Change",
        EXEC, BOTH, X2003, SAFE, COMPLETE;
    REAL_VARIABLE_CHANGE = 0x24D, "Real Variable Change", EXEC, BOTH, X2003, SAFE, COMPLETE;
    STRING_VARIABLE_CHANGE = 0x24E, "String Variable Change",
        EXEC, BOTH, X2003, SAFE, COMPLETE;
    ALARM_RESET = 0x252, "Alarm Reset", EXEC, BOTH, X2003, SAFE, COMPLETE;
    /// A program that already ended would run again.
    PROGRAM_RUN = 0x253, "Program Run", EXEC, BOTH, X2003, UNSAFE, COMPLETE;
    PROGRAM_END = 0x254, "Program End", EXEC, BOTH, X2003, SAFE, COMPLETE;
    PROGRAM_PAUSE = 0x255, "Program Pause", EXEC, BOTH, X2003, SAFE, COMPLETE;
    /// A second step would run the next step.
    PROGRAM_STEP = 0x256, "Program One-Step Run", EXEC, BOTH, X2003, UNSAFE, COMPLETE;
    /// A program that paused again in between would resume again
    /// (conservative: the manuals do not say).
    PROGRAM_RESUME = 0x257, "Program Resume", EXEC, BOTH, X2003, UNSAFE, COMPLETE;
    /// No normal response; ready again about 10 s after it was sent (2003 p. 50).
    SOFTWARE_RESET = 0x25B, "Software Reset", EXEC, BOTH, X2003, UNSAFE, COMPLETE,
        reply: Reply::None { ready_after_ms: 10_000 };
    DRIVE_SOURCE_RECOVERY = 0x25C, "Drive-Source Recovery Request",
        EXEC, BOTH, X2003, SAFE, COMPLETE;
    PAUSE_CANCEL = 0x25E, "Operation Pause Cancellation Request",
        EXEC, BOTH, X2003, SAFE, COMPLETE;
    SPEED_CHANGE = 0x262, "Speed Change", EXEC, CART, X2003, SAFE, COMPLETE;
    /// Cartesian like its 3-digit predecessor 237H (**inferred**: the TTA
    /// page gives no applicability).
    POSITION_NUMBER_MOVE_2 = 0x26B, "Position-Number Specification Movement 2",
        EXEC, CART, TTA, SAFE, COMPLETE;
    CHANGE_POSITION_DATA_2 = 0x26D, "Change Position Data Continuous Write 2",
        EXEC, BOTH, TTA, SAFE, COMPLETE;
    CONTROLLER_FUNCTION_2 = 0x271, "Controller Function Specification 2",
        EXEC, BOTH, TTA, SAFE, COMPLETE;
    RANGE_WRITE_POSITION_DATA_3 = 0x290, "Position Data Range-Specification Continuous Write 3",
        EXEC, BOTH, TTA, SAFE, PARTIAL;
    CHANGE_POSITION_DATA_3 = 0x291, "Change Position Data Continuous Write 3",
        EXEC, BOTH, TTA, SAFE, PARTIAL;
    COORDINATE_SYSTEM_QUERY = 0x2A0,
        "Coordinate System Definition Data Range-Specification Continuous Query",
        QUERY, SCARA, X2003, SAFE, COMPLETE;
    SCARA_AXIS_STATUS_QUERY = 0x2A1, "SCARA Axis Status Query",
        QUERY, SCARA, X2003, SAFE, COMPLETE;
    INTERFERENCE_ZONE_QUERY = 0x2A2,
        "Simple-Interference-Check-Zone Definition Data Range-Specification Continuous Query",
        QUERY, SCARA, X2003, SAFE, COMPLETE;
    SCARA_AXIS_STATUS_QUERY_2 = 0x2A3, "SCARA Axis Status Query 2",
        QUERY, SCARA, TTA, SAFE, PARTIAL;
    COORDINATE_SYSTEM_QUERY_2 = 0x2A4,
        "Coordinate System Definition Data Range-Specification Continuous Query 2",
        QUERY, SCARA, TTA, SAFE, COMPLETE;
    SCARA_ABSOLUTE_MOVE = 0x2D4, "SCARA Absolute-Coordinate Specification Movement",
        EXEC, SCARA, X2003, SAFE, COMPLETE;
    /// A distance: sending it twice moves the arm twice.
    SCARA_RELATIVE_MOVE = 0x2D5, "SCARA Relative-Coordinate Specification Movement",
        EXEC, SCARA, X2003, UNSAFE, COMPLETE;
    SCARA_POSITION_NUMBER_MOVE = 0x2D6, "SCARA Position-Number Specification Movement",
        EXEC, SCARA, X2003, SAFE, COMPLETE;
}

/// The raw-text span `[start, end)` of a frame whose first bytes are
/// `prefix`: the framing layer's rule for where body bytes need not be hex
/// digits. `None` for frames without text, or while `prefix` is too short.
///
/// ```
/// use iai_protocol_b::catalogue::text_span;
/// use iai_protocol_b::frame::Header;
/// assert_eq!(text_span(Header::Command, b"!99200"), Some((6, 16)));
/// assert_eq!(text_span(Header::Command, b"!99216"), None);
/// ```
pub fn text_span(header: Header, prefix: &[u8]) -> Option<(usize, usize)> {
    let id = hex_number(prefix.get(3..6)?)?;
    let (_, text) = TEXTS.iter().find(|(x, _)| *x == id)?;
    text.span(header, prefix)
}

/// The value of up to 4 hex digits of either case.
fn hex_number(digits: &[u8]) -> Option<u16> {
    digits.iter().try_fold(0u16, |n, &b| {
        crate::field::hex_value(b).map(|d| (n << 4) | u16::from(d))
    })
}

// `lookup` searches `ALL` by halving: its IDs must ascend.
// Indexing in a const initialiser is checked at compile time.
#[allow(clippy::indexing_slicing)]
const _: () = {
    let mut i = 1;
    while i < ALL.len() {
        assert!(ALL[i - 1].id < ALL[i].id, "catalogue IDs must ascend");
        i += 1;
    }
};

/// Entries with a text field.
// Indexing in a const initialiser is checked at compile time.
#[allow(clippy::indexing_slicing)]
const TEXT_ENTRIES: usize = {
    let mut n = 0;
    let mut i = 0;
    while i < ALL.len() {
        if ALL[i].text.is_some() {
            n += 1;
        }
        i += 1;
    }
    n
};

/// Their IDs and text fields: what [`text_span`] searches, so that the
/// frame check does not link the whole catalogue.
// Indexing in a const initialiser is checked at compile time.
#[allow(clippy::indexing_slicing)]
const TEXTS: [(u16, TextField); TEXT_ENTRIES] = {
    let mut out = [(0, TextField::CountedInResponse { start: 0 }); TEXT_ENTRIES];
    let (mut i, mut k) = (0, 0);
    while i < ALL.len() {
        if let Some(t) = ALL[i].text {
            out[k] = (ALL[i].id, t);
            k += 1;
        }
        i += 1;
    }
    out
};

/// Every ID of [`ALL`], in its (ascending) order.
// Indexing in a const initialiser is checked at compile time.
#[allow(clippy::indexing_slicing)]
const IDS: [u16; ALL.len()] = {
    let mut ids = [0; ALL.len()];
    let mut i = 0;
    while i < ALL.len() {
        ids[i] = ALL[i].id;
        i += 1;
    }
    ids
};

/// Bit `i` set: entry `i` of [`ALL`] is [`Resend::Unsafe`].
// Indexing in a const initialiser is checked at compile time.
#[allow(clippy::indexing_slicing)]
const UNSAFE: u64 = {
    assert!(ALL.len() <= 64, "one bit per entry");
    let mut bits = 0;
    let mut i = 0;
    while i < ALL.len() {
        if let Resend::Unsafe = ALL[i].resend {
            bits |= 1 << i;
        }
        i += 1;
    }
    bits
};

/// Bit `i` set: entry `i` of [`ALL`] only reads ([`Kind::Query`]).
// Indexing in a const initialiser is checked at compile time.
#[allow(clippy::indexing_slicing)]
const QUERY_BITS: u64 = {
    let mut bits = 0;
    let mut i = 0;
    while i < ALL.len() {
        if let Kind::Query = ALL[i].kind {
            bits |= 1 << i;
        }
        i += 1;
    }
    bits
};

/// How many messages only read.
const QUERY_COUNT: usize = QUERY_BITS.count_ones() as usize;

/// The IDs of every message that only reads the controller's state
/// ([`Kind::Query`]), ascending.
// Indexing in a const initialiser is checked at compile time.
#[allow(clippy::indexing_slicing)]
pub const QUERIES: [u16; QUERY_COUNT] = {
    let mut out = [0; QUERY_COUNT];
    let (mut i, mut k) = (0, 0);
    while i < ALL.len() {
        if let Kind::Query = ALL[i].kind {
            out[k] = ALL[i].id;
            k += 1;
        }
        i += 1;
    }
    out
};

/// The lowest message ID of the catalogue (200H).
// Indexing in a const initialiser is checked at compile time.
#[allow(clippy::indexing_slicing)]
pub const LOWEST_ID: u16 = IDS[0];

/// Whether message `id` only reads the controller's state (as
/// [`lookup`]`(id)`'s kind says), without linking the entries: an ID table
/// and a bit set.
pub fn is_query(id: u16) -> bool {
    IDS.binary_search(&id)
        .is_ok_and(|i| QUERY_BITS.checked_shr(i as u32).unwrap_or(0) & 1 != 0)
}

/// Entries whose reply is not [`Reply::Normal`].
// Indexing in a const initialiser is checked at compile time.
#[allow(clippy::indexing_slicing)]
const SPECIAL_REPLIES: usize = {
    let mut n = 0;
    let mut i = 0;
    while i < ALL.len() {
        if !ALL[i].has_normal_response() {
            n += 1;
        }
        i += 1;
    }
    n
};

/// Their IDs and replies.
// Indexing in a const initialiser is checked at compile time.
#[allow(clippy::indexing_slicing)]
const REPLIES: [(u16, Reply); SPECIAL_REPLIES] = {
    let mut out = [(0, Reply::Normal); SPECIAL_REPLIES];
    let (mut i, mut k) = (0, 0);
    while i < ALL.len() {
        if !ALL[i].has_normal_response() {
            out[k] = (ALL[i].id, ALL[i].reply);
            k += 1;
        }
        i += 1;
    }
    out
};

/// What a request engine needs of message `id`'s entry, if the catalogue
/// has one: whether a resend is harmless and what the controller answers
/// (as [`lookup`]`(id)` gives them). Unlike [`lookup`], it does not link
/// the entries and their names into a program: an ID table and a bit set.
pub fn request_rules(id: u16) -> Option<(Resend, Reply)> {
    let i = IDS.binary_search(&id).ok()?;
    let resend = if UNSAFE.checked_shr(i as u32).unwrap_or(0) & 1 != 0 {
        Resend::Unsafe
    } else {
        Resend::Safe
    };
    let reply = REPLIES
        .iter()
        .find(|(x, _)| *x == id)
        .map_or(Reply::Normal, |&(_, r)| r);
    Some((resend, reply))
}

/// A frame's text span is known once this many bytes are in.
// Indexing in a const initialiser is checked at compile time.
#[allow(clippy::indexing_slicing)]
pub const TEXT_KNOWN_BY: usize = {
    let mut max = 6;
    let mut i = 0;
    while i < ALL.len() {
        if let Some(t) = ALL[i].text {
            let k = t.known_by();
            if k > max {
                max = k;
            }
        }
        i += 1;
    }
    max
};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_ascend_and_lookup_finds_each_entry() {
        for pair in ALL.windows(2) {
            assert!(pair[0].id < pair[1].id, "{:03X}", pair[1].id);
        }
        for m in ALL {
            assert_eq!(lookup(m.id), Some(*m));
        }
        assert_eq!(ALL.len(), 54);
    }

    #[test]
    fn families_follow_the_2003_message_list() {
        let cartesian_only = [0x212, 0x233, 0x234, 0x235, 0x237, 0x262, 0x26B];
        let scara_only = [0x2A0, 0x2A1, 0x2A2, 0x2A3, 0x2A4, 0x2D4, 0x2D5, 0x2D6];
        for m in ALL {
            let want = if cartesian_only.contains(&m.id) {
                Families::CARTESIAN
            } else if scara_only.contains(&m.id) {
                Families::SCARA
            } else {
                Families::BOTH
            };
            assert_eq!(m.families, want, "{:03X}", m.id);
        }
    }

    #[test]
    fn only_relative_moves_and_program_steps_are_unsafe_to_resend() {
        let unsafe_ids: [u16; 7] = [0x235, 0x236, 0x253, 0x256, 0x257, 0x25B, 0x2D5];
        for m in ALL {
            assert_eq!(
                m.resend == Resend::Unsafe,
                unsafe_ids.contains(&m.id),
                "{:03X}",
                m.id
            );
            if m.kind == Kind::Query {
                assert_eq!(m.resend, Resend::Safe);
            }
        }
    }

    #[test]
    fn only_software_reset_has_no_normal_response() {
        for m in ALL {
            assert_eq!(m.has_normal_response(), m.id != 0x25B, "{:03X}", m.id);
        }
        assert_eq!(
            SOFTWARE_RESET.reply,
            Reply::None {
                ready_after_ms: 10_000
            }
        );
    }

    #[test]
    fn request_rules_and_text_spans_agree_with_the_entries() {
        for id in 0..=0xFFF {
            let entry = lookup(id);
            assert_eq!(
                request_rules(id),
                entry.map(|m| (m.resend, m.reply)),
                "{id:03X}"
            );
            let text = TEXTS.iter().find(|(x, _)| *x == id).map(|&(_, t)| t);
            assert_eq!(text, entry.and_then(|m| m.text), "{id:03X}");
        }
    }

    #[test]
    fn text_spans_of_the_two_text_messages() {
        // 200H: ten characters after the ID, in both directions.
        assert_eq!(text_span(Header::Response, b"#99200"), Some((6, 16)));
        assert_eq!(text_span(Header::Error, b"&99200"), None);
        // 216H response: the count at 88..90 gives the length.
        let mut prefix = [b'0'; 90];
        prefix[..6].copy_from_slice(b"#99216");
        prefix[88] = b'1';
        prefix[89] = b'a';
        assert_eq!(text_span(Header::Response, &prefix), Some((90, 90 + 0x1A)));
        assert_eq!(text_span(Header::Response, &prefix[..89]), None);
        assert_eq!(text_span(Header::Command, &prefix), None);
        // No other message carries text.
        assert_eq!(text_span(Header::Response, b"#9926D"), None);
        assert_eq!(text_span(Header::Response, b"#99zzz"), None);
        assert_eq!(TEXT_KNOWN_BY, 90);
    }
}
