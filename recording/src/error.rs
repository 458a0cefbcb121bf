//! Errors of reading and writing recordings. Every variant names the file; a corrupt file also
//! names the byte offset and the record type where reading failed.

use std::path::{Path, PathBuf};

/// What went wrong with a recording.
#[derive(Debug, thiserror::Error)]
pub enum RecordingError {
    /// The operating system refused a read or write.
    #[error("{path}: {what}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The operation (e.g. "writing a chunk").
        what: &'static str,
        /// The cause.
        source: std::io::Error,
    },
    /// The file does not start with the MCAP magic.
    #[error("{path}: not an MCAP file (the first 8 bytes are not the MCAP magic)")]
    NotMcap {
        /// The file.
        path: PathBuf,
    },
    /// A record is malformed.
    #[error("{path}: corrupt {record} record at byte offset {offset}: {problem}")]
    Corrupt {
        /// The file.
        path: PathBuf,
        /// File offset of the problem (of the record, or of the field within it).
        offset: u64,
        /// Record type, e.g. "Chunk".
        record: String,
        /// What was wrong.
        problem: String,
    },
    /// A message does not decode as the navsync sample type of its channel.
    #[error("{path}: message on `{topic}` at byte offset {offset}: {problem}")]
    Decode {
        /// The file.
        path: PathBuf,
        /// File offset the reader had reached (see [`Message::offset`](crate::mcap_reader::Message::offset)).
        offset: u64,
        /// The channel's topic.
        topic: String,
        /// What was wrong.
        problem: String,
    },
    /// The output is one of the inputs (same device and inode, whatever the paths say).
    #[error(
        "{output} is the same file as the input {input}: refused (writing it would destroy the input; choose another output)"
    )]
    SameFile {
        /// The output asked for.
        output: PathBuf,
        /// The input it is.
        input: PathBuf,
    },
    /// The output is an existing recording.
    #[error("{path} exists: refused, it would be overwritten (--force replaces it)")]
    Exists {
        /// The file.
        path: PathBuf,
    },
    /// A service name that navsync does not know, or a sample of the wrong type for a channel.
    #[error("{path}: {problem}")]
    Usage {
        /// The file.
        path: PathBuf,
        /// What was wrong.
        problem: String,
    },
}

impl RecordingError {
    pub(crate) fn io(path: &Path, what: &'static str, source: std::io::Error) -> Self {
        Self::Io {
            path: path.to_path_buf(),
            what,
            source,
        }
    }
}
