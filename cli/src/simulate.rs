//! `iai simulate`'s frame log: the frames of the controller simulator
//! (crate `iai-simulator`, served by [`iai_simulator::server`]) logged as
//! `iai inspect` shows them ([`inspector_log`]).

use iai_simulator::server::{Direction, FrameLog, FrameLogMaker};

use std::sync::Arc;

use crate::inspect::{text_entry, Inspector, Origin};

/// A [`FrameLog`] that decodes the frames as `iai inspect` does: header,
/// fields and their meanings.
pub struct InspectorLog {
    inspector: Inspector,
}

impl InspectorLog {
    /// The log of one direction of a connection (`rx` or `tx` in the
    /// entries).
    pub fn new(dir: Direction) -> Self {
        let mut inspector = Inspector::new();
        inspector.set_origin(Origin {
            line: None,
            dir: Some(match dir {
                Direction::Received => "rx",
                Direction::Sent => "tx",
            }),
        });
        InspectorLog { inspector }
    }
}

impl FrameLog for InspectorLog {
    fn entries(&mut self, bytes: &[u8]) -> Vec<Vec<String>> {
        self.inspector.feed(bytes);
        self.inspector.take_items().iter().map(text_entry).collect()
    }
}

/// What `iai simulate` gives [`iai_simulator::server::Shared::with_frame_log`].
pub fn inspector_log() -> FrameLogMaker {
    Arc::new(|dir| Box::new(InspectorLog::new(dir)) as Box<dyn FrameLog>)
}
