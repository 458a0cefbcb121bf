//! What the gpsd conformance tests share: the captures of a corpus with gpsd's output.

use std::path::{Path, PathBuf};

/// One capture: its file name, the receiver's bytes (`NAME.log`) and gpsd's output
/// (`NAME.log.chk`).
pub struct Capture {
    /// File name of the log.
    pub name: String,
    /// The receiver's bytes.
    pub bytes: Vec<u8>,
    /// gpsd's JSON output lines.
    pub chk: String,
}

/// Every `*.log` of `dir` with its `.log.chk`, sorted by name; panics when there are fewer
/// than `expected` (an incomplete corpus) or a file cannot be read.
pub fn captures(dir: &Path, expected: usize) -> Vec<Capture> {
    let entries = std::fs::read_dir(dir).unwrap_or_else(|e| {
        panic!(
            "corpus not found at {} ({e}); it lives outside the repository",
            dir.display()
        )
    });
    let mut logs: Vec<PathBuf> = entries
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "log"))
        .collect();
    logs.sort();
    assert!(
        logs.len() >= expected,
        "expected {expected} captures in {}, found {}",
        dir.display(),
        logs.len()
    );
    logs.iter()
        .map(|log| {
            let name = log.file_name().and_then(|n| n.to_str()).unwrap_or("?").to_owned();
            let bytes = std::fs::read(log).unwrap_or_else(|e| panic!("reading {}: {e}", log.display()));
            let chk_path = log.with_extension("log.chk");
            let chk = std::fs::read(&chk_path).unwrap_or_else(|e| panic!("reading {}: {e}", chk_path.display()));
            Capture {
                name,
                bytes,
                chk: String::from_utf8_lossy(&chk).into_owned(),
            }
        })
        .collect()
}
