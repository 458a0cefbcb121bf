//! Writes MCAP files (<https://mcap.dev/spec>) with the maintained `mcap` crate: chunked,
//! zstd-compressed chunks, message and chunk indexes, statistics and a summary.
//!
//! Durability: a chunk goes to the operating system (`write`) as soon as it is closed, either
//! because it reached the size limit or because the caller asked ([`flush_chunk`]; the
//! recorder does so every second). A process that dies (`kill -9`) therefore loses only the
//! open chunk; the file then ends without Data End, summary and footer, and
//! [`McapReader`](super::McapReader) reads every complete chunk of it.
//!
//! [`flush_chunk`]: McapWriter::flush_chunk

use std::collections::BTreeMap;
use std::io::{Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use super::error::RecordingError;

/// Default size at which a chunk is closed, bytes of records before compression.
pub const DEFAULT_CHUNK_SIZE: usize = 1024 * 1024;

/// Chunk compression of the files navsync writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ChunkCompression {
    /// zstd (level 3, mcap's default): what `ros2 bag record --storage mcap` offers and every
    /// MCAP reader supports.
    #[default]
    Zstd,
    /// No compression (for debugging a file with a hex editor).
    None,
}

/// Id of a schema in a file (1-based; 0 means "no schema" in MCAP).
pub type SchemaId = u16;
/// Id of a channel in a file.
pub type ChannelId = u16;

/// Counts the bytes handed to the sink.
struct Counted<W> {
    inner: W,
    bytes: Arc<AtomicU64>,
}

impl<W: Write> Write for Counted<W> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.bytes.fetch_add(n as u64, Ordering::Relaxed);
        Ok(n)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

impl<W: Seek> Seek for Counted<W> {
    fn seek(&mut self, pos: SeekFrom) -> std::io::Result<u64> {
        self.inner.seek(pos)
    }
}

/// An MCAP writer over any seekable byte sink (it writes in one pass and never seeks back).
pub struct McapWriter<W: Write + Seek> {
    inner: Option<mcap::Writer<Counted<W>>>,
    path: PathBuf,
    bytes: Arc<AtomicU64>,
    messages: u64,
    /// Per channel id: the next sequence number.
    sequences: Vec<u32>,
}

fn mcap_err(path: &Path, what: &'static str, e: mcap::McapError) -> RecordingError {
    match e {
        mcap::McapError::Io(source) => RecordingError::io(path, what, source),
        other => RecordingError::Usage {
            path: path.to_path_buf(),
            problem: format!("{what}: {other}"),
        },
    }
}

impl<W: Write + Seek> McapWriter<W> {
    /// Starts a file on `out`: writes the magic and the Header (`profile`, `library`).
    /// `path` only names the file in errors.
    pub fn new(
        out: W,
        path: &Path,
        profile: &str,
        library: &str,
        chunk_size: usize,
        compression: ChunkCompression,
    ) -> Result<Self, RecordingError> {
        let bytes = Arc::new(AtomicU64::new(0));
        let options = mcap::WriteOptions::new()
            .profile(profile)
            .library(library)
            .chunk_size(Some(chunk_size.max(1) as u64))
            .compression(match compression {
                ChunkCompression::Zstd => Some(mcap::Compression::Zstd),
                ChunkCompression::None => None,
            })
            .disable_seeking(true);
        let inner = options
            .create(Counted {
                inner: out,
                bytes: bytes.clone(),
            })
            .map_err(|e| mcap_err(path, "writing the header", e))?;
        Ok(Self {
            inner: Some(inner),
            path: path.to_path_buf(),
            bytes,
            messages: 0,
            sequences: Vec::new(),
        })
    }

    fn writer(&mut self) -> Result<&mut mcap::Writer<Counted<W>>, RecordingError> {
        self.inner.as_mut().ok_or_else(|| RecordingError::Usage {
            path: self.path.clone(),
            problem: "the file is already finished".into(),
        })
    }

    /// Bytes handed to the sink so far (the open chunk is not counted until it is closed).
    pub fn bytes_written(&self) -> u64 {
        self.bytes.load(Ordering::Relaxed)
    }

    /// Messages written so far.
    pub fn message_count(&self) -> u64 {
        self.messages
    }

    /// Adds a Schema record; returns its id.
    pub fn add_schema(&mut self, name: &str, encoding: &str, data: &[u8]) -> Result<SchemaId, RecordingError> {
        let path = self.path.clone();
        self.writer()?
            .add_schema(name, encoding, data)
            .map_err(|e| mcap_err(&path, "writing a schema", e))
    }

    /// Adds a Channel record (`schema` 0: none) with key-value `metadata`; returns its id.
    pub fn add_channel(
        &mut self,
        schema: SchemaId,
        topic: &str,
        message_encoding: &str,
        metadata: &[(&str, &str)],
    ) -> Result<ChannelId, RecordingError> {
        let path = self.path.clone();
        let meta: BTreeMap<String, String> = metadata.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect();
        let id = self
            .writer()?
            .add_channel(schema, topic, message_encoding, &meta)
            .map_err(|e| mcap_err(&path, "writing a channel", e))?;
        if self.sequences.len() <= usize::from(id) {
            self.sequences.resize(usize::from(id) + 1, 0);
        }
        Ok(id)
    }

    /// Writes one message on `channel` (log and publish time in ns).
    pub fn write_message(
        &mut self,
        channel: ChannelId,
        log_time: u64,
        publish_time: u64,
        data: &[u8],
    ) -> Result<(), RecordingError> {
        let path = self.path.clone();
        let Some(seq) = self.sequences.get_mut(usize::from(channel)) else {
            return Err(RecordingError::Usage {
                path,
                problem: format!("message on channel {channel}, which was not added"),
            });
        };
        let sequence = *seq;
        *seq = seq.wrapping_add(1);
        let header = mcap::records::MessageHeader {
            channel_id: channel,
            sequence,
            log_time,
            publish_time,
        };
        self.writer()?
            .write_to_known_channel(&header, data)
            .map_err(|e| mcap_err(&path, "writing a message", e))?;
        self.messages += 1;
        Ok(())
    }

    /// Closes the open chunk (if any) and hands everything to the sink (`flush`).
    pub fn flush_chunk(&mut self) -> Result<(), RecordingError> {
        let path = self.path.clone();
        self.writer()?
            .flush()
            .map_err(|e| mcap_err(&path, "writing a chunk", e))
    }

    /// Closes the open chunk and writes Data End, the summary (schemas, channels, statistics,
    /// chunk indexes), the summary offsets and the footer; returns the sink.
    pub fn finish(mut self) -> Result<W, RecordingError> {
        let path = self.path.clone();
        let mut w = self.inner.take().ok_or_else(|| RecordingError::Usage {
            path: path.clone(),
            problem: "the file is already finished".into(),
        })?;
        w.finish().map_err(|e| mcap_err(&path, "writing the summary", e))?;
        let mut out = w.into_inner().inner;
        out.flush()
            .map_err(|e| RecordingError::io(&path, "writing the summary", e))?;
        Ok(out)
    }
}
