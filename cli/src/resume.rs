//! The state files of an interrupted table command. `iai table write`
//! keeps `FILE.csv.iai-state` ([`ResumeState`]): which CSV, how many of
//! its records the controller confirmed (in file order), over which line,
//! and whether the table was cleared first (`--replace`). `iai table read
//! -o OUT.csv` keeps `OUT.csv.iai-read-state` ([`ReadState`]): the range
//! asked, the positions read so far (their records are in `OUT.csv`) and
//! the line. A resume continues where the state says, on the same line
//! only: the records are on that controller, not on another. A state file
//! left behind stops a new start ([`refuse_stale`]) until the user says
//! `--resume` or `--restart`.

use std::path::{Path, PathBuf};

/// The state kept beside the CSV.
#[derive(serde::Serialize, serde::Deserialize, PartialEq, Eq, Debug, Clone)]
pub struct ResumeState {
    /// FNV-1a hash of the CSV file.
    pub csv_hash: String,
    /// Records in the file.
    pub records: u32,
    /// Records confirmed by the controller, in file order.
    pub confirmed: u32,
    /// The line they were written over: port or address, station,
    /// profile.
    #[serde(default)]
    pub line: String,
    /// A `--replace` write: the positions 246H reaches were cleared
    /// before the first record was written.
    #[serde(default)]
    pub replace: bool,
}

impl ResumeState {
    /// The state of a write of `csv` (its bytes, `records` records) over
    /// `line`, nothing confirmed yet.
    pub fn new(csv: &[u8], records: u32, line: &str) -> Self {
        ResumeState {
            csv_hash: fnv(csv),
            records,
            confirmed: 0,
            line: line.to_string(),
            replace: false,
        }
    }

    /// Reads the state of `csv` and checks that it belongs to this write:
    /// the same file (`bytes`, `records`) over the same `line`. The
    /// records to skip, or a message for the user.
    pub fn resume(csv: &Path, bytes: &[u8], records: u32, line: &str) -> Result<Self, String> {
        let path = path(csv);
        let text = std::fs::read_to_string(&path).map_err(|e| {
            format!(
                "--resume: no state file {} ({e}); run without --resume",
                path.display()
            )
        })?;
        let st: ResumeState = serde_json::from_str(&text)
            .map_err(|e| format!("--resume: {} is damaged ({e})", path.display()))?;
        if st.csv_hash != fnv(bytes) || st.records != records {
            return Err(format!(
                "--resume: {} changed since the interrupted write; run without --resume",
                csv.display()
            ));
        }
        if st.line != line {
            let was = if st.line.is_empty() {
                "an unrecorded line"
            } else {
                &st.line
            };
            return Err(format!(
                "--resume: the interrupted write went to {was}, not to {line}; its records are not on this line's controller: run without --resume"
            ));
        }
        Ok(ResumeState {
            confirmed: st.confirmed.min(records),
            ..st
        })
    }

    /// Writes the state beside `csv` (atomically: a temporary file renamed).
    pub fn save(&self, csv: &Path) {
        save_json(&path(csv), self);
    }

    /// Removes the state of `csv` (the write completed).
    pub fn remove(csv: &Path) {
        let _ = std::fs::remove_file(path(csv));
    }
}

/// Where the state of `csv` is kept.
pub fn path(csv: &Path) -> PathBuf {
    let mut s = csv.as_os_str().to_owned();
    s.push(".iai-state");
    PathBuf::from(s)
}

/// Writes `value` as JSON to `path` through a temporary file renamed
/// over it, so that a crash leaves the old state or the new, never half.
fn save_json(path: &Path, value: &impl serde::Serialize) {
    if let Ok(text) = serde_json::to_string(value) {
        let mut tmp = path.as_os_str().to_owned();
        tmp.push(".tmp");
        if std::fs::write(&tmp, text).is_ok() {
            let _ = std::fs::rename(&tmp, path);
        }
    }
}

/// A new start while `state` (the state file of an interrupted `what`)
/// exists is refused: it would lose the resume point silently. The
/// message says what the file holds and how to go on.
pub fn refuse_stale(state: &Path, what: &str, progress: &str) -> Result<(), String> {
    if !state.exists() {
        return Ok(());
    }
    Err(format!(
        "an interrupted {what} left {} ({progress}); run with --resume to continue it, or --restart to start over (the state file is then replaced)",
        state.display()
    ))
}

/// What the write state at `path` says, for [`refuse_stale`].
pub fn write_progress(path: &Path) -> String {
    std::fs::read_to_string(path)
        .ok()
        .and_then(|t| serde_json::from_str::<ResumeState>(&t).ok())
        .map_or_else(
            || "unreadable".to_string(),
            |s| {
                format!(
                    "{} of {} records confirmed over {}",
                    s.confirmed, s.records, s.line
                )
            },
        )
}

/// The state of an interrupted `iai table read -o OUT.csv`.
#[derive(serde::Serialize, serde::Deserialize, PartialEq, Eq, Debug, Clone)]
pub struct ReadState {
    /// The first position asked.
    pub first: u16,
    /// The last position asked.
    pub last: u16,
    /// `--all`: the whole table was asked (first and last are the
    /// profile's range).
    pub all: bool,
    /// The first position not read yet (`last + 1` once done).
    pub next: u32,
    /// Defined records read so far (they are in the output file).
    pub records: u32,
    /// The line they were read over.
    pub line: String,
    /// FNV-1a hash of the output file as this read left it.
    pub output_hash: String,
}

impl ReadState {
    /// Reads the state kept for `out` and checks it belongs to this read:
    /// the same range (or `--all`), the same line, and an output file as
    /// the interrupted read left it.
    pub fn resume(
        out: &Path,
        first: u16,
        last: u16,
        all: bool,
        line: &str,
    ) -> Result<Self, String> {
        let path = read_path(out);
        let text = std::fs::read_to_string(&path).map_err(|e| {
            format!(
                "--resume: no state file {} ({e}); run without --resume",
                path.display()
            )
        })?;
        let st: ReadState = serde_json::from_str(&text)
            .map_err(|e| format!("--resume: {} is damaged ({e})", path.display()))?;
        let asked = |all: bool, f: u16, l: u16| {
            if all {
                "--all".to_string()
            } else {
                format!("positions {f}..={l}")
            }
        };
        if st.all != all || (!all && (st.first, st.last) != (first, last)) {
            return Err(format!(
                "--resume: the interrupted read asked for {}, this one for {}; run with the same range, or --restart",
                asked(st.all, st.first, st.last),
                asked(all, first, last)
            ));
        }
        if st.line != line {
            return Err(format!(
                "--resume: the interrupted read went to {}, not to {line}; run with --restart to read this controller from the start",
                st.line
            ));
        }
        let now = std::fs::read(out).map(|b| fnv(&b)).unwrap_or_default();
        if now != st.output_hash {
            return Err(format!(
                "--resume: {} changed since the interrupted read; run with --restart",
                out.display()
            ));
        }
        Ok(st)
    }

    /// Writes the state beside `out`, whose bytes are `written` now.
    pub fn save(&mut self, out: &Path, written: &[u8]) {
        self.output_hash = fnv(written);
        save_json(&read_path(out), self);
    }

    /// Removes the state of `out` (the read completed).
    pub fn remove(out: &Path) {
        let _ = std::fs::remove_file(read_path(out));
    }
}

/// What the read state at `path` says, for [`refuse_stale`].
pub fn read_progress(path: &Path) -> String {
    std::fs::read_to_string(path)
        .ok()
        .and_then(|t| serde_json::from_str::<ReadState>(&t).ok())
        .map_or_else(
            || "unreadable".to_string(),
            |s| {
                format!(
                    "positions {}..{} read, {} records, over {}",
                    s.first, s.next, s.records, s.line
                )
            },
        )
}

/// Where the state of a read into `out` is kept.
pub fn read_path(out: &Path) -> PathBuf {
    let mut s = out.as_os_str().to_owned();
    s.push(".iai-read-state");
    PathBuf::from(s)
}

/// 64-bit FNV-1a of `bytes`, as hex.
fn fnv(bytes: &[u8]) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x100_0000_01b3);
    }
    format!("{h:016x}")
}
