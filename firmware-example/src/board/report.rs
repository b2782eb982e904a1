//! Text to the host through semihosting, without `core::fmt` (its
//! machinery costs several KiB of flash), the start-up banner the QEMU
//! tests wait for, the end of a run, and the fault handlers (each prints
//! where it happened and exits QEMU with a failure).
//!
//! The STM32G0 boards run on silicon only (QEMU has no model of them),
//! where a semihosting call without a debugger attached is itself a
//! HardFault: there nothing is written and the end of a run, a panic or a
//! fault resets the part ([`SEMIHOSTING`]).

use cortex_m_rt::{exception, ExceptionFrame};
use cortex_m_semihosting::{debug, hio};

use crate::config::{BlockError, Source};
use crate::serial::FlowControl;

/// Whether this board talks to a host through semihosting: the boards
/// that run under QEMU (or a debugger), not the STM32G0 parts.
pub const SEMIHOSTING: bool = !cfg!(any(
    feature = "board-stm32g030",
    feature = "board-stm32g070"
));

/// Writes to the host's standard output through semihosting: strings,
/// decimals and hex, each written as it comes. Failures are ignored (this
/// also runs on the way down, where a second panic must not happen).
pub struct Out(Option<hio::HostStream>);

impl Default for Out {
    fn default() -> Self {
        Self::new()
    }
}

impl Out {
    /// The host's standard output (writes go nowhere without a host, or
    /// on a board without [`SEMIHOSTING`]).
    pub fn new() -> Self {
        Self(if SEMIHOSTING {
            hio::hstdout().ok()
        } else {
            None
        })
    }

    /// Writes `s`.
    #[inline(always)]
    pub fn str(&mut self, s: &str) -> &mut Self {
        if SEMIHOSTING {
            self.bytes(s.as_bytes());
        }
        self
    }

    /// Writes `n` in decimal.
    #[inline(always)]
    pub fn dec(&mut self, n: u64) -> &mut Self {
        if SEMIHOSTING {
            self.put_dec(n);
        }
        self
    }

    /// Writes `n` as `0x` and eight lower-case hex digits (`{:#010x}`).
    #[inline(always)]
    pub fn hex(&mut self, n: u32) -> &mut Self {
        if SEMIHOSTING {
            self.put_hex(n);
        }
        self
    }

    /// Writes `b` as two lower-case hex digits.
    #[inline(always)]
    pub fn hex_byte(&mut self, b: u8) -> &mut Self {
        if SEMIHOSTING {
            self.bytes(&[hex_digit(u32::from(b >> 4)), hex_digit(u32::from(b))]);
        }
        self
    }

    fn bytes(&mut self, b: &[u8]) {
        if let Some(host) = self.0.as_mut() {
            let _ = host.write_all(b);
        }
    }

    fn put_dec(&mut self, n: u64) {
        let mut digits = [b'0'; 20];
        let mut at = digits.len();
        let mut n = n;
        for d in digits.iter_mut().rev() {
            *d = b'0' + (n % 10) as u8;
            at -= 1;
            n /= 10;
            if n == 0 {
                break;
            }
        }
        self.bytes(digits.get(at..).unwrap_or(&[]));
    }

    fn put_hex(&mut self, n: u32) {
        let mut digits = *b"0x00000000";
        for (i, d) in digits.iter_mut().skip(2).enumerate() {
            *d = hex_digit(n >> (28 - 4 * i));
        }
        self.bytes(&digits);
    }
}

/// The lower-case hex digit of `n`'s low four bits.
fn hex_digit(n: u32) -> u8 {
    match (n & 0xF) as u8 {
        d @ 0..=9 => b'0' + d,
        d => b'a' + d - 10,
    }
}

/// The start-up line the QEMU tests wait for:
/// `firmware-example: bridge up on <board> (config <source>, flow <flow>)`,
/// the configuration's source and the flow control spelled as their
/// `Debug` forms.
pub fn banner(board: &str, source: Source, flow: FlowControl) {
    let mut out = Out::new();
    out.str("firmware-example: bridge up on ")
        .str(board)
        .str(" (config ");
    match source {
        Source::Default => out.str("Default"),
        Source::Block => out.str("Block"),
        Source::Blank => out.str("Blank"),
        Source::Invalid(e) => {
            out.str("Invalid(");
            match e {
                BlockError::TooShort => out.str("TooShort"),
                BlockError::Crc => out.str("Crc"),
                BlockError::Version => out.str("Version"),
                BlockError::Field(at) => out.str("Field(").dec(u64::from(at)).str(")"),
            };
            out.str(")")
        }
    };
    out.str(", flow ").str(match flow {
        FlowControl::None => "None",
        FlowControl::XonXoff => "XonXoff",
        FlowControl::RtsCts => "RtsCts",
    });
    out.str(")\n");
}

/// Ends the QEMU run with the given status; resets a board without
/// [`SEMIHOSTING`].
pub fn exit(status: debug::ExitStatus) -> ! {
    if !SEMIHOSTING {
        cortex_m::peripheral::SCB::sys_reset();
    }
    debug::exit(status);
    // Only reached when no debugger or QEMU handles semihosting.
    loop {
        cortex_m::asm::wfi();
    }
}

/// Prints where the panic happened and its message if that is a plain
/// string (`panicked at <file>:<line>:<column>:` then the message, as
/// `PanicInfo`'s `Display` would); a message with arguments is not
/// printed, as formatting it would link `core::fmt`.
#[panic_handler]
fn panic(info: &core::panic::PanicInfo<'_>) -> ! {
    cortex_m::interrupt::disable();
    let mut out = Out::new();
    out.str("firmware-example: panicked");
    if let Some(at) = info.location() {
        out.str(" at ")
            .str(at.file())
            .str(":")
            .dec(u64::from(at.line()))
            .str(":")
            .dec(u64::from(at.column()))
            .str(":");
    }
    out.str("\n")
        .str(
            info.message()
                .as_str()
                .unwrap_or("(message with arguments)"),
        )
        .str("\n");
    exit(debug::EXIT_FAILURE)
}

#[exception]
unsafe fn HardFault(frame: &ExceptionFrame) -> ! {
    Out::new()
        .str("firmware-example: HardFault at pc=")
        .hex(frame.pc())
        .str(" lr=")
        .hex(frame.lr())
        .str("\n");
    exit(debug::EXIT_FAILURE)
}

#[exception]
unsafe fn DefaultHandler(irqn: i16) {
    cortex_m::interrupt::disable();
    let mut out = Out::new();
    out.str("firmware-example: unexpected interrupt or exception ");
    if irqn < 0 {
        out.str("-");
    }
    out.dec(u64::from(irqn.unsigned_abs())).str("\n");
    exit(debug::EXIT_FAILURE)
}
