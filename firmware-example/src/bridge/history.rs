//! The last frames through the bridge, for the web page's download: every
//! command a host sent (a 26DH by its envelope only), every reply the
//! bridge relayed from the controller, every reply the bridge sent itself;
//! each with its tick, its length and its first [`KEPT`] bytes, the last
//! [`FRAMES`] of them (feature `frame-history`, which `ethernet` turns on;
//! without it nothing is kept and nothing is spent).

/// Frames kept.
pub const FRAMES: usize = 16;
/// Bytes kept of each.
pub const KEPT: usize = 48;

/// Which way a frame went.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dir {
    /// From the host to the bridge.
    FromHost,
    /// From the bridge to the host.
    ToHost,
}

/// One frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Entry {
    /// The tick it was seen.
    pub at_ms: u32,
    /// Which way it went.
    pub dir: Dir,
    /// Its whole length.
    pub len: u32,
    kept: [u8; KEPT],
}

impl Entry {
    /// Its first bytes (all of it if it is short).
    pub fn bytes(&self) -> &[u8] {
        let n = usize::try_from(self.len).map_or(KEPT, |l| l.min(KEPT));
        self.kept.get(..n).unwrap_or(&[])
    }
}

/// The last frames.
pub struct History {
    /// Oldest first. A `Deque` rather than a `HistoryBuf`: the latter's
    /// indexing keeps bounds checks (and their panics) in the image.
    #[cfg(feature = "frame-history")]
    frames: heapless::Deque<Entry, FRAMES>,
}

impl History {
    /// Nothing yet.
    pub const fn new() -> Self {
        History {
            #[cfg(feature = "frame-history")]
            frames: heapless::Deque::new(),
        }
    }

    /// Keeps `frame` (of `len` bytes in all: more than `frame` holds for a
    /// 26DH kept by its envelope), seen at `now` going `dir`.
    #[cfg_attr(not(feature = "frame-history"), allow(unused_variables))]
    pub fn record(&mut self, dir: Dir, frame: &[u8], len: usize, now: u32) {
        #[cfg(feature = "frame-history")]
        {
            let mut kept = [0u8; KEPT];
            let n = frame.len().min(KEPT);
            if let (Some(dst), Some(src)) = (kept.get_mut(..n), frame.get(..n)) {
                dst.copy_from_slice(src);
            }
            if self.frames.is_full() {
                self.frames.pop_front();
            }
            let _ = self.frames.push_back(Entry {
                at_ms: now,
                dir,
                len: u32::try_from(len).unwrap_or(u32::MAX),
                kept,
            });
        }
    }

    /// The frames kept, oldest first.
    pub fn oldest_first(&self) -> impl Iterator<Item = &Entry> {
        #[cfg(feature = "frame-history")]
        {
            self.frames.iter()
        }
        #[cfg(not(feature = "frame-history"))]
        {
            core::iter::empty()
        }
    }
}

impl Default for History {
    fn default() -> Self {
        Self::new()
    }
}
