//! The line arguments at work: the target they name, warnings for
//! options that do not apply to it, the line's settings and identity.

use iai_cli::link::{Flow, Link, Parity, SerialSettings, Target};
use iai_cli::table::Plan;
use iai_protocol_b::frame::Station;

use crate::{FlowArg, LineArgs, LinkArgs, ParityArg, SerialArgs, Where};

/// The baud rate when none is given.
pub(crate) const DEFAULT_BAUD: u32 = 38_400;

/// The controller's station when none is given: 99, the spec's examples'
/// (the controller's I/O parameter No. 91).
pub(crate) const DEFAULT_STATION: u8 = 0x99;

/// A station as the command line writes it: two hex digits.
pub(crate) fn station_text(station: u8) -> String {
    format!("{station:02X}")
}

impl SerialArgs {
    /// The flow control asked, or `default`.
    fn flow(&self, default: Flow) -> Flow {
        match self.flow {
            Some(FlowArg::None) => Flow::None,
            Some(FlowArg::Xonxoff) => Flow::XonXoff,
            Some(FlowArg::Rtscts) => Flow::RtsCts,
            None => default,
        }
    }

    /// The target `place` names, at `baud` for a serial port.
    pub(crate) fn target(&self, place: &Where, baud: u32, default_flow: Flow) -> Target {
        let flow = self.flow(default_flow);
        match (&place.port, &place.tcp) {
            (Some(path), _) => Target::Serial {
                path: path.clone(),
                baud,
                settings: SerialSettings {
                    data_bits: self.data_bits.unwrap_or(SerialSettings::DEFAULT.data_bits),
                    parity: match self.parity {
                        Some(ParityArg::None) => Parity::None,
                        Some(ParityArg::Odd) => Parity::Odd,
                        Some(ParityArg::Even) => Parity::Even,
                        None => SerialSettings::DEFAULT.parity,
                    },
                    stop_bits: self.stop_bits.unwrap_or(SerialSettings::DEFAULT.stop_bits),
                    flow,
                },
            },
            (None, addr) => Target::Tcp {
                addr: addr.clone().unwrap_or_default(),
                flow: if flow == Flow::RtsCts {
                    Flow::None
                } else {
                    flow
                },
            },
        }
    }

    /// The options given that a TCP link ignores, as warnings
    /// (`baud_given`: --baud was given).
    pub(crate) fn warnings(&self, place: &Where, baud_given: bool) -> Vec<String> {
        if place.tcp.is_none() {
            return Vec::new();
        }
        let mut w: Vec<String> = [
            ("--baud", baud_given),
            ("--data-bits", self.data_bits.is_some()),
            ("--parity", self.parity.is_some()),
            ("--stop-bits", self.stop_bits.is_some()),
        ]
        .iter()
        .filter(|(_, given)| *given)
        .map(|(name, _)| {
            format!("{name} applies to a serial port (--port); ignored with --tcp (the serial server's own settings apply)")
        })
        .collect();
        if self.flow == Some(FlowArg::Rtscts) {
            w.push("--flow rtscts needs a serial port's modem lines; ignored with --tcp (no flow control)".into());
        }
        w
    }
}

impl LinkArgs {
    /// The target, with `default_flow` where `--flow` is not given.
    pub(crate) fn target_with(&self, default_flow: Flow) -> Target {
        self.serial.target(
            &self.target,
            self.baud.unwrap_or(DEFAULT_BAUD),
            default_flow,
        )
    }

    /// The options given that a TCP link ignores, as warnings.
    pub(crate) fn warnings(&self) -> Vec<String> {
        self.serial.warnings(&self.target, self.baud.is_some())
    }

    /// The target, after warning about options that do not apply.
    pub(crate) fn resolve(&self, default_flow: Flow) -> Target {
        for w in self.warnings() {
            eprintln!("iai: warning: {w}");
        }
        self.target_with(default_flow)
    }
}

impl LineArgs {
    /// The target (flow control none unless asked), warnings given.
    pub(crate) fn target(&self) -> Target {
        self.link.target_with(Flow::None)
    }

    /// Opens the line, after warning about options that do not apply.
    pub(crate) fn open(&self) -> Result<Link, String> {
        self.open_with(Flow::None)
    }

    /// [`LineArgs::open`] with another default flow control.
    pub(crate) fn open_with(&self, default_flow: Flow) -> Result<Link, String> {
        let target = self.link.resolve(default_flow);
        Link::open(&target, self.plan().line)
    }

    /// The controller's kind and the line's settings: station, duplicate
    /// window, `--timeout`, `--retries`.
    pub(crate) fn plan(&self) -> Plan {
        let mut plan = Plan::new(self.profile.profile(), Station(self.station));
        if let Some(ms) = self.duplicate_window_ms {
            plan.line = plan.line.with_duplicate_window(ms);
        }
        plan.line.timeout_ms = self.timeout;
        plan.line.max_sends = self.retries.saturating_add(1);
        plan
    }

    /// What a state file records of the line: a resume elsewhere is
    /// refused.
    pub(crate) fn identity(&self) -> String {
        format!(
            "{} station {:02X} profile {}",
            self.target(),
            self.station,
            self.profile.profile().name()
        )
    }
}
