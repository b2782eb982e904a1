//! How large a frame each kind of controller can take in and send out.
//!
//! The message formats allow frames of megabytes (a 26DH of 20,000 records
//! is 1,640,014 bytes); a controller's buffers are the real limit (TTA
//! p. 15, 2003 p. 14). Whether the limits include SC, CR and LF is not
//! stated: they are read as whole-frame limits, header through LF
//! (**inferred**, the conservative reading). [`crate::profile`] carries
//! them per controller; the engines size their buffers from them.

/// The buffer limits of one kind of controller, in bytes, header through LF.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Buffers {
    /// Largest command frame it receives.
    pub command: usize,
    /// Largest response frame it sends.
    pub response: usize,
}

/// TTA, X-SEL P/Q/PCT/QCT/PX/QX/R/S/RX/SX/RXD/SXD, SSEL, ASEL, PSEL (TTA p. 15).
pub const TTA: Buffers = Buffers {
    command: 2051,
    response: 2048,
};

/// X-SEL J/K/KE/KT/KET/JX/KX/KTX and TT (TTA p. 15), the X-SEL of the
/// 2003 specification (2003 p. 14, "as of 26 June 2001").
pub const XSEL_2003: Buffers = Buffers {
    command: 1023,
    response: 1024,
};

/// The largest frame any known controller sends or receives: the default
/// capacity of buffers that must hold any frame.
pub const LARGEST_FRAME: usize = if TTA.command > TTA.response {
    TTA.command
} else {
    TTA.response
};
