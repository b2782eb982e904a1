//! Controller profiles: what one kind of controller accepts.
//!
//! The message formats allow far larger frames than any controller can
//! buffer, a few messages exist only on newer controllers, and some code
//! values are controller-specific. A [`Profile`] states these limits; it is
//! always chosen explicitly (there is no default).
//!
//! ```
//! use iai_protocol_b::profile::Profile;
//! use iai_protocol_b::position::RecordLayout;
//! let p = Profile::TTA;
//! assert_eq!(p.max_command_frame(), 2051);
//! // 26DH with 4 axes per record: 14 + 40 × 50 = 2014 bytes fit, 41 records do not.
//! assert_eq!(p.max_records_per_command(RecordLayout::NUMBER_4, 4), Some(40));
//! assert!(!Profile::XSEL_2003.supports(0x26D));
//! ```

use crate::catalogue::{self, Families, Generation};
use crate::error::{Error, Result};
use crate::frame::{Station, MIN_FRAME_LEN};
use crate::limits;
use crate::message::{Command, Response, WordOrder};
use crate::position::{PositionStream, RecordLayout};

/// The limits of one kind of controller.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Profile {
    name: &'static str,
    max_command_frame: usize,
    max_response_frame: usize,
    table_write: PositionStream,
    generation: Generation,
    families: Families,
    max_unit_type: u8,
    max_error_detail_type: u8,
    real_word_order: Option<WordOrder>,
}

impl Profile {
    /// TTA, and the Cartesian controllers with the same buffers (X-SEL
    /// P/Q/PCT/QCT/PX/QX/R/S/RX/SX/RXD/SXD, SSEL, ASEL, PSEL; TTA p. 15):
    /// command frames up to 2051 bytes, responses up to 2048; every
    /// Cartesian message of the catalogue, the TTA generation's included;
    /// 201H unit type 3 and 216H type 5 allowed. The real-variable word
    /// order is a controller setting: choose it with
    /// [`Profile::with_real_word_order`]. For an IX SCARA controller of
    /// this generation use `Profile::TTA.with_families(Families::SCARA)`.
    pub const TTA: Profile = Profile {
        name: "TTA",
        max_command_frame: limits::TTA.command,
        max_response_frame: limits::TTA.response,
        table_write: PositionStream::CHANGE_2,
        generation: Generation::Tta,
        families: Families::CARTESIAN,
        max_unit_type: 3,
        max_error_detail_type: 5,
        real_word_order: None,
    };

    /// Cartesian X-SEL of the 2003 specification (and X-SEL
    /// J/K/KE/KT/KET/JX/KX/KTX, TT): command frames up to 1023 bytes,
    /// responses up to 1024 (2003 p. 14); messages of that generation only;
    /// 201H unit types 0–2 and 216H types 0–4 only.
    pub const XSEL_2003: Profile = Profile {
        name: "X-SEL 2003",
        max_command_frame: limits::XSEL_2003.command,
        max_response_frame: limits::XSEL_2003.response,
        table_write: PositionStream::CHANGE,
        generation: Generation::Xsel2003,
        families: Families::CARTESIAN,
        max_unit_type: 2,
        max_error_detail_type: 4,
        real_word_order: None,
    };

    /// IX SCARA X-SEL of the 2003 specification: as [`Profile::XSEL_2003`]
    /// with the SCARA message set (2A0H–2A2H, 2D4H–2D6H instead of 212H,
    /// 233H–235H, 237H, 262H; 2003 pp. 11–12).
    pub const XSEL_2003_SCARA: Profile = Profile::XSEL_2003
        .with_name("X-SEL 2003 IX SCARA")
        .with_families(Families::SCARA);

    /// This profile for controllers of these families.
    pub const fn with_families(mut self, families: Families) -> Profile {
        self.families = families;
        self
    }

    /// This profile under another name (for logs).
    pub const fn with_name(mut self, name: &'static str) -> Profile {
        self.name = name;
        self
    }

    /// The controller families this profile stands for.
    pub const fn families(self) -> Families {
        self.families
    }

    /// This profile with the real-variable word order set (from the
    /// controller's "Other parameter No. 46" or firmware version).
    pub const fn with_real_word_order(mut self, order: WordOrder) -> Profile {
        self.real_word_order = Some(order);
        self
    }

    /// A short name for logs.
    pub const fn name(self) -> &'static str {
        self.name
    }

    /// The real-variable word order; [`Error::NotSupportedByProfile`]
    /// (with ID 20FH) until one was chosen.
    pub const fn real_word_order(self) -> Result<WordOrder> {
        match self.real_word_order {
            Some(o) => Ok(o),
            None => Err(Error::NotSupportedByProfile {
                id: crate::catalogue::REAL_VARIABLE_QUERY.id,
            }),
        }
    }

    /// The message that writes position tables of any size: 26DH (4-digit
    /// numbers, TTA p. 60) on the TTA generation, 245H (3-digit, 2003
    /// p. 41) on a 2003 X-SEL. It is read back with its
    /// [`PositionStream::read_back`] query (21FH, 209H).
    pub const fn table_write(self) -> PositionStream {
        self.table_write
    }

    /// Largest command frame the controller receives, header through LF.
    pub const fn max_command_frame(self) -> usize {
        self.max_command_frame
    }

    /// Largest response frame the controller sends, header through LF.
    pub const fn max_response_frame(self) -> usize {
        self.max_response_frame
    }

    /// Whether the controller knows message `id`: the catalogue has it,
    /// for one of this profile's families, from this generation or before.
    pub fn supports(self, id: u16) -> bool {
        catalogue::lookup(id)
            .is_some_and(|m| m.since <= self.generation && m.families.intersects(self.families))
    }

    /// The most position records of `axes` effective axes that fit one
    /// command frame of a message using `layout`; `None` for a layout no
    /// command uses.
    pub fn max_records_per_command(self, layout: RecordLayout, axes: usize) -> Option<usize> {
        records_fitting(self.max_command_frame, layout, axes)
    }

    /// The most position records of `axes` effective axes that fit one
    /// response frame of a message using `layout` (209H, 21FH, 22DH).
    pub fn max_records_per_response(self, layout: RecordLayout, axes: usize) -> Option<usize> {
        records_fitting(self.max_response_frame, layout, axes)
    }

    /// Checks that the controller accepts `cmd`: message known to it and
    /// code values valid for it (201H unit type, 216H error type).
    pub fn check_command(self, cmd: &Command<'_>) -> Result<()> {
        let id = cmd.id();
        if !self.supports(id) {
            return Err(Error::NotSupportedByProfile { id });
        }
        match cmd {
            Command::VersionQuery(q) if q.unit_type > self.max_unit_type => {
                Err(Error::ValueOutOfRange { offset: 6 })
            }
            Command::ErrorDetailQuery(q) if q.type_1 > self.max_error_detail_type => {
                Err(Error::ValueOutOfRange { offset: 6 })
            }
            _ => Ok(()),
        }
    }

    /// Emits `cmd` after [`Profile::check_command`]; a frame longer than the
    /// controller receives is [`Error::FrameTooLong`].
    pub fn emit_command(
        self,
        cmd: &Command<'_>,
        station: Station,
        buf: &mut [u8],
    ) -> Result<usize> {
        self.check_command(cmd)?;
        let n = cmd.emit(station, buf)?;
        self.check_command_len(n)?;
        Ok(n)
    }

    /// Emits `resp` (e.g. in a simulator); a frame longer than the
    /// controller sends, or a message it does not know, is refused.
    pub fn emit_response(
        self,
        resp: &Response<'_>,
        station: Station,
        buf: &mut [u8],
    ) -> Result<usize> {
        let id = resp.id();
        if !self.supports(id) {
            return Err(Error::NotSupportedByProfile { id });
        }
        let n = resp.emit(station, buf)?;
        self.check_response_len(n)?;
        Ok(n)
    }

    /// [`Error::FrameTooLong`] if a command frame of `len` bytes exceeds the limit.
    pub const fn check_command_len(self, len: usize) -> Result<()> {
        check_len(len, self.max_command_frame)
    }

    /// [`Error::FrameTooLong`] if a response frame of `len` bytes exceeds the limit.
    pub const fn check_response_len(self, len: usize) -> Result<()> {
        check_len(len, self.max_response_frame)
    }
}

const fn check_len(len: usize, limit: usize) -> Result<()> {
    if len > limit {
        Err(Error::FrameTooLong { limit })
    } else {
        Ok(())
    }
}

/// Bytes of a position-table frame besides its records: the envelope and
/// the fixed fields before the records (count, start number, reserved).
const fn table_overhead(layout: RecordLayout) -> Option<usize> {
    let fixed = match (layout.number_width, layout.extended) {
        // 209H, 245H: 3-digit count.
        (3, false) => 3,
        // 21FH, 26DH: 4-digit count.
        (4, false) => 4,
        // 22DH response, 291H: reserved 00 and a 4-digit count.
        (4, true) => 2 + 4,
        // 244H: 3-digit start and count.
        (0, false) => 3 + 3,
        // 290H: reserved 00, 4-digit start and count.
        (0, true) => 2 + 4 + 4,
        _ => return None,
    };
    Some(MIN_FRAME_LEN + fixed)
}

fn records_fitting(limit: usize, layout: RecordLayout, axes: usize) -> Option<usize> {
    let overhead = table_overhead(layout)?;
    let per = layout.record_len(axes.min(crate::axis::MAX_AXES));
    Some(limit.saturating_sub(overhead) / per.max(1))
}
