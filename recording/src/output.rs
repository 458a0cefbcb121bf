//! Where a command writes what it made, so that no command destroys its own input or an
//! existing recording:
//!
//! * the output is written to a temporary file in the target's directory (`.NAME.PID.N.tmp`,
//!   created exclusively) and renamed over the target only once it is complete and synced
//!   ([`OutputFile::commit`]); the target is never opened for writing, so an input that is the
//!   target (under another path: `./b.mcap`, a hard link, a symbolic link) is read whole, and a
//!   command that fails or is stopped half-way leaves the target as it was (its temporary file
//!   is removed);
//! * inputs and the target are compared by device and inode ([`same_file`]), not by path: an
//!   output that is one of the inputs is refused, `--force` or not;
//! * an existing recording (a file that starts with the MCAP magic) is replaced only with
//!   `--force` ([`Overwrite::force`]); other existing files (an HTML report, a CSV) are replaced
//!   atomically;
//! * a target that exists but is not a regular file (a device, a FIFO, a directory) is refused:
//!   the rename would replace it.
//!
//! A live recording is the exception ([`crate::SampleRecorder::create_live`]): it grows at its
//! own name, readable while it is written and surviving `kill -9` up to its last chunk, so it is
//! created exclusively instead (an existing file is refused unless `--force`, which unlinks it
//! first: a reader that has it open keeps its data).

use std::fs::File;
use std::io::{Read, Seek, SeekFrom, Write};
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU32, Ordering};

use super::error::RecordingError;

/// The MCAP magic: the first 8 bytes of every recording.
pub const MCAP_MAGIC: [u8; 8] = [0x89, b'M', b'C', b'A', b'P', b'0', b'\r', b'\n'];

/// What an output may replace.
#[derive(Debug, Clone, Copy, Default)]
pub struct Overwrite<'a> {
    /// The command's inputs: the output may be none of them.
    pub inputs: &'a [&'a Path],
    /// Replace an existing recording (`--force`).
    pub force: bool,
}

impl<'a> Overwrite<'a> {
    /// An output of a command reading `inputs`, replacing an existing recording only if `force`.
    pub fn new(inputs: &'a [&'a Path], force: bool) -> Self {
        Self { inputs, force }
    }
}

/// True if `a` and `b` are the same file (device and inode, links followed); false if either
/// does not exist.
pub fn same_file(a: &Path, b: &Path) -> bool {
    match (std::fs::metadata(a), std::fs::metadata(b)) {
        (Ok(x), Ok(y)) => x.dev() == y.dev() && x.ino() == y.ino(),
        _ => false,
    }
}

/// True if `path` is a file that starts with the MCAP magic.
pub fn is_recording(path: &Path) -> bool {
    let mut magic = [0u8; 8];
    File::open(path)
        .and_then(|mut f| f.read_exact(&mut magic))
        .is_ok_and(|()| magic == MCAP_MAGIC)
}

/// Checks that `target` may be written under `rules` (see the [module](self) documentation).
pub fn check_target(target: &Path, rules: &Overwrite<'_>) -> Result<(), RecordingError> {
    for input in rules.inputs {
        if same_file(target, input) {
            return Err(RecordingError::SameFile {
                output: target.to_path_buf(),
                input: input.to_path_buf(),
            });
        }
    }
    match std::fs::metadata(target) {
        Ok(m) if !m.is_file() => Err(RecordingError::Usage {
            path: target.to_path_buf(),
            problem: "exists and is not a regular file: refused as an output".into(),
        }),
        Ok(_) if !rules.force && is_recording(target) => Err(RecordingError::Exists {
            path: target.to_path_buf(),
        }),
        _ => Ok(()),
    }
}

/// Distinguishes the temporary files of one process.
static TMP_SEQ: AtomicU32 = AtomicU32::new(0);

/// A file being written for `target`: a temporary file in its directory until
/// [`commit`](Self::commit) renames it into place; dropped uncommitted, it is removed.
#[derive(Debug)]
pub struct OutputFile {
    file: File,
    tmp: PathBuf,
    target: PathBuf,
    committed: bool,
}

impl OutputFile {
    /// Checks `target` under `rules` ([`check_target`]) and creates the temporary file.
    pub fn create(target: &Path, rules: &Overwrite<'_>) -> Result<Self, RecordingError> {
        check_target(target, rules)?;
        let name = target.file_name().ok_or_else(|| RecordingError::Usage {
            path: target.to_path_buf(),
            problem: "names a directory, not a file".into(),
        })?;
        let dir = match target.parent() {
            Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let tmp = dir.join(format!(
            ".{}.{}.{}.tmp",
            name.to_string_lossy(),
            std::process::id(),
            TMP_SEQ.fetch_add(1, Ordering::Relaxed)
        ));
        let file = File::options()
            .read(true)
            .write(true)
            .create_new(true)
            .open(&tmp)
            .map_err(|e| RecordingError::io(&tmp, "creating the temporary output", e))?;
        Ok(Self {
            file,
            tmp,
            target: target.to_path_buf(),
            committed: false,
        })
    }

    /// The file the output will have.
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// Syncs the file and renames it over the target, then syncs the directory.
    pub fn commit(mut self) -> Result<(), RecordingError> {
        self.file
            .sync_all()
            .map_err(|e| RecordingError::io(&self.tmp, "syncing", e))?;
        std::fs::rename(&self.tmp, &self.target)
            .map_err(|e| RecordingError::io(&self.target, "renaming into place", e))?;
        self.committed = true;
        if let Some(dir) = self.target.parent().filter(|d| !d.as_os_str().is_empty())
            && let Ok(d) = File::open(dir)
        {
            let _ = d.sync_all();
        }
        Ok(())
    }
}

impl Write for OutputFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.file.write(buf)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.file.flush()
    }
}

impl Seek for OutputFile {
    fn seek(&mut self, pos: SeekFrom) -> std::io::Result<u64> {
        self.file.seek(pos)
    }
}

impl Drop for OutputFile {
    fn drop(&mut self) {
        if !self.committed {
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

/// Writes `bytes` to `target` through an [`OutputFile`].
pub fn write_file(target: &Path, rules: &Overwrite<'_>, bytes: &[u8]) -> Result<(), RecordingError> {
    let mut f = OutputFile::create(target, rules)?;
    f.write_all(bytes)
        .map_err(|e| RecordingError::io(target, "writing", e))?;
    f.commit()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("navsync-output-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn an_input_under_another_name_is_the_same_file() {
        let d = scratch("same");
        let a = d.join("a.mcap");
        std::fs::write(&a, MCAP_MAGIC).unwrap();
        std::fs::hard_link(&a, d.join("hard.mcap")).unwrap();
        std::os::unix::fs::symlink(&a, d.join("soft.mcap")).unwrap();
        let dotted = d.join(".").join("a.mcap");
        for other in [dotted, d.join("hard.mcap"), d.join("soft.mcap")] {
            assert!(same_file(&a, &other), "{}", other.display());
            let e = OutputFile::create(&other, &Overwrite::new(&[&a], true)).unwrap_err();
            assert!(matches!(e, RecordingError::SameFile { .. }), "{e}");
        }
        assert!(!same_file(&a, &d.join("missing")));
        assert_eq!(std::fs::read(&a).unwrap(), MCAP_MAGIC, "the input is untouched");
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn a_recording_is_replaced_only_with_force_and_only_when_complete() {
        let d = scratch("force");
        let target = d.join("out.mcap");
        std::fs::write(&target, MCAP_MAGIC).unwrap();
        let e = OutputFile::create(&target, &Overwrite::default()).unwrap_err();
        assert!(matches!(e, RecordingError::Exists { .. }), "{e}");
        assert!(e.to_string().contains("--force"), "{e}");

        let mut f = OutputFile::create(&target, &Overwrite::new(&[], true)).unwrap();
        f.write_all(b"new").unwrap();
        assert_eq!(
            std::fs::read(&target).unwrap(),
            MCAP_MAGIC,
            "the old file until the commit"
        );
        drop(f);
        assert_eq!(
            std::fs::read(&target).unwrap(),
            MCAP_MAGIC,
            "an output abandoned changes nothing"
        );
        assert_eq!(std::fs::read_dir(&d).unwrap().count(), 1, "its temporary file is gone");

        write_file(&target, &Overwrite::new(&[], true), b"new").unwrap();
        assert_eq!(std::fs::read(&target).unwrap(), b"new");
        // Another kind of file is replaced atomically without --force.
        write_file(&target, &Overwrite::default(), b"html").unwrap();
        assert_eq!(std::fs::read(&target).unwrap(), b"html");
        assert_eq!(std::fs::read_dir(&d).unwrap().count(), 1);
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn a_device_or_directory_is_not_replaced() {
        let e = OutputFile::create(Path::new("/dev/null"), &Overwrite::new(&[], true)).unwrap_err();
        assert!(e.to_string().contains("not a regular file"), "{e}");
        let d = scratch("dir");
        let e = OutputFile::create(&d, &Overwrite::new(&[], true)).unwrap_err();
        assert!(e.to_string().contains("not a regular file"), "{e}");
        std::fs::remove_dir_all(&d).unwrap();
    }
}
