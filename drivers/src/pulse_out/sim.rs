//! `sim:FILE`: a simulated pulse output. Every edge appends one line `HOST_NS high` or
//! `HOST_NS low` to the file (host `CLOCK_MONOTONIC` ns of the edge, read just before the
//! line is written, one `write` per line): what the tests read to check when `navsync
//! pps-out` raises and lowers its line. The file is created (truncated) when opened.

use std::fs::File;
use std::io::Write;
use std::path::Path;

use navsync_shared::time::monotonic_now_ns;

use super::{PulseOutError, PulseOutput};

/// A pulse output that writes its edges into a file.
pub struct Simulated {
    file: File,
    path: String,
}

impl Simulated {
    /// Creates (or truncates) `path`.
    pub fn create(path: &Path) -> Result<Self, PulseOutError> {
        let name = path.display().to_string();
        let file = File::create(path).map_err(|source| PulseOutError::Open {
            path: name.clone(),
            source,
        })?;
        Ok(Self { file, path: name })
    }
}

/// One edge as the file holds it: `HOST_NS high|low` and a newline. Pure.
pub fn edge_line(host_ns: i64, high: bool) -> String {
    format!("{host_ns} {}\n", if high { "high" } else { "low" })
}

/// The edges of a simulated output's file, `(host_ns, high)`; `None` for a line that is not
/// an edge. Pure.
pub fn parse_edge_line(line: &str) -> Option<(i64, bool)> {
    let (ns, level) = line.trim_end().split_once(' ')?;
    let high = match level {
        "high" => true,
        "low" => false,
        _ => return None,
    };
    Some((ns.parse().ok()?, high))
}

impl PulseOutput for Simulated {
    fn set(&mut self, high: bool) -> Result<i64, PulseOutError> {
        let now = monotonic_now_ns();
        self.file
            .write_all(edge_line(now, high).as_bytes())
            .map_err(|source| PulseOutError::Write {
                path: self.path.clone(),
                source,
            })?;
        Ok(now)
    }

    fn describe(&self) -> String {
        format!("simulated output {}", self.path)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn edges_are_lines_of_the_file() {
        let path = std::env::temp_dir().join(format!("navsync-pulse-sim-{}", std::process::id()));
        let mut out = Simulated::create(&path).unwrap();
        let up = out.set(true).unwrap();
        let down = out.set(false).unwrap();
        assert!(down >= up);
        let text = std::fs::read_to_string(&path).unwrap();
        let edges: Vec<_> = text.lines().map(|l| parse_edge_line(l).unwrap()).collect();
        assert_eq!(edges, [(up, true), (down, false)]);
        assert_eq!(parse_edge_line("12 up"), None);
        assert_eq!(parse_edge_line("x high"), None);
        let _ = std::fs::remove_file(&path);
    }
}
