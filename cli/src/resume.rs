//! The state file of `iai table write` (`FILE.csv.iai-state`): which CSV,
//! how many of its records the controller confirmed (in file order), and
//! over which line. A resume continues after those records, on the same
//! line only: the records are on that controller, not on another.

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
        let path = path(csv);
        if let Ok(text) = serde_json::to_string(self) {
            let tmp = path.with_extension("iai-state.tmp");
            if std::fs::write(&tmp, text).is_ok() {
                let _ = std::fs::rename(&tmp, &path);
            }
        }
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

/// 64-bit FNV-1a of `bytes`, as hex.
fn fnv(bytes: &[u8]) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x100_0000_01b3);
    }
    format!("{h:016x}")
}
