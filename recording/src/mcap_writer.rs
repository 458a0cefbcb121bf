//! Writes MCAP files (<https://mcap.dev/spec>): chunked, uncompressed, indexed, with a
//! summary, in one pass and without seeking.
//!
//! Layout of a file this writer produces (spec sections in brackets):
//!
//! ```text
//! Magic, Header                                        ["Magic", "Header"]
//! Data section:                                        ["Data Section"]
//!   Schema, Channel records as they are added (outside chunks, before the chunk with their first message)
//!   Chunk (compression "", CRC-32 of its records)      ["Chunk"]
//!   Message Index per channel in that chunk            ["Message Index"]
//!   …
//!   Data End (CRC-32 of every byte before it, magic included)   ["Data End"]
//! Summary section: Schema…, Channel…, Statistics, Chunk Index…  ["Summary Section"]
//! Summary Offset section: one Summary Offset per group          ["Summary Offset"]
//! Footer (summary CRC), Magic                                   ["Footer"]
//! ```
//!
//! Durability: a chunk goes to the operating system (`write`) as soon as it is closed, either
//! because it reached the size limit or because the caller asked ([`flush_chunk`]; the
//! recorder does so every second). A process that dies (`kill -9`) therefore loses only the
//! open chunk; the file then ends without Data End, summary and footer, and
//! [`McapReader`](super::McapReader) reads every complete chunk of it.
//!
//! Allocation: message records are encoded straight into the open chunk's buffer and indexed
//! in per-channel vectors that keep their capacity from chunk to chunk, so in steady state
//! writing a message allocates nothing (the JSON encoding of a sample, done by the caller,
//! does).
//!
//! [`flush_chunk`]: McapWriter::flush_chunk

use std::io::Write;
use std::path::{Path, PathBuf};

use super::crc32::Crc32;
use super::error::RecordingError;
use super::mcap_format::{Enc, MAGIC, Opcode};

/// Default size at which a chunk is closed, bytes of records.
pub const DEFAULT_CHUNK_SIZE: usize = 512 * 1024;

/// Id of a schema in a file (1-based; 0 means "no schema" in MCAP).
pub type SchemaId = u16;
/// Id of a channel in a file.
pub type ChannelId = u16;

/// An MCAP writer over any byte sink.
pub struct McapWriter<W: Write> {
    out: W,
    path: PathBuf,
    /// Bytes written to `out` so far (the file offset of the next byte).
    pos: u64,
    /// CRC of every byte written before the Data End record.
    data_crc: Crc32,
    chunk_size: usize,
    // The open chunk.
    chunk: Vec<u8>,
    chunk_start_time: u64,
    chunk_end_time: u64,
    /// Channels with messages in the open chunk.
    chunk_channels: Vec<ChannelId>,
    /// Per channel id: (log_time, offset of the Message record in the chunk's records).
    chunk_entries: Vec<Vec<(u64, u64)>>,
    scratch: Vec<u8>,
    // What the summary will hold.
    summary_schemas: Vec<u8>,
    summary_channels: Vec<u8>,
    summary_chunk_indexes: Vec<u8>,
    schema_count: u16,
    channel_count: u16,
    chunk_count: u32,
    message_count: u64,
    message_start_time: u64,
    message_end_time: u64,
    /// Per channel id: messages written and the next sequence number.
    channel_messages: Vec<u64>,
}

impl<W: Write> McapWriter<W> {
    /// Starts a file on `out`: writes the magic and the Header (`profile`, `library`).
    /// `path` only names the file in errors.
    pub fn new(out: W, path: &Path, profile: &str, library: &str) -> Result<Self, RecordingError> {
        let mut w = Self {
            out,
            path: path.to_path_buf(),
            pos: 0,
            data_crc: Crc32::new(),
            chunk_size: DEFAULT_CHUNK_SIZE,
            chunk: Vec::new(),
            chunk_start_time: u64::MAX,
            chunk_end_time: 0,
            chunk_channels: Vec::new(),
            chunk_entries: vec![Vec::new()],
            scratch: Vec::new(),
            summary_schemas: Vec::new(),
            summary_channels: Vec::new(),
            summary_chunk_indexes: Vec::new(),
            schema_count: 0,
            channel_count: 0,
            chunk_count: 0,
            message_count: 0,
            message_start_time: u64::MAX,
            message_end_time: 0,
            channel_messages: vec![0],
        };
        let mut buf = Vec::new();
        buf.extend_from_slice(&MAGIC);
        let mut e = Enc(&mut buf);
        let at = e.begin(Opcode::Header);
        e.str(profile).str(library);
        e.end(at);
        w.write_data(&buf, "writing the header")?;
        Ok(w)
    }

    /// Closes chunks at `bytes` of records instead of [`DEFAULT_CHUNK_SIZE`].
    pub fn with_chunk_size(mut self, bytes: usize) -> Self {
        self.chunk_size = bytes.max(1);
        self
    }

    /// Bytes written to the sink so far plus the open chunk.
    pub fn bytes_written(&self) -> u64 {
        self.pos + self.chunk.len() as u64
    }

    /// Messages written so far.
    pub fn message_count(&self) -> u64 {
        self.message_count
    }

    fn write_data(&mut self, bytes: &[u8], what: &'static str) -> Result<(), RecordingError> {
        self.data_crc.update(bytes);
        self.write_raw(bytes, what)
    }

    fn write_raw(&mut self, bytes: &[u8], what: &'static str) -> Result<(), RecordingError> {
        self.out
            .write_all(bytes)
            .map_err(|e| RecordingError::io(&self.path, what, e))?;
        self.pos += bytes.len() as u64;
        Ok(())
    }

    /// Adds a Schema record (spec "Schema": id, name, encoding, data) and returns its id.
    pub fn add_schema(&mut self, name: &str, encoding: &str, data: &[u8]) -> Result<SchemaId, RecordingError> {
        self.schema_count = self.schema_count.checked_add(1).ok_or_else(|| RecordingError::Usage {
            path: self.path.clone(),
            problem: "more than 65535 schemas".into(),
        })?;
        let id = self.schema_count;
        let mut buf = std::mem::take(&mut self.scratch);
        buf.clear();
        let mut e = Enc(&mut buf);
        let at = e.begin(Opcode::Schema);
        e.u16(id).str(name).str(encoding).bytes32(data);
        e.end(at);
        self.summary_schemas.extend_from_slice(&buf);
        let r = self.write_data(&buf, "writing a schema");
        self.scratch = buf;
        r.map(|_| id)
    }

    /// Adds a Channel record (spec "Channel": id, schema_id, topic, message_encoding,
    /// metadata) and returns its id.
    pub fn add_channel(
        &mut self,
        schema: SchemaId,
        topic: &str,
        message_encoding: &str,
        metadata: &[(&str, &str)],
    ) -> Result<ChannelId, RecordingError> {
        self.channel_count = self.channel_count.checked_add(1).ok_or_else(|| RecordingError::Usage {
            path: self.path.clone(),
            problem: "more than 65535 channels".into(),
        })?;
        let id = self.channel_count;
        let mut buf = std::mem::take(&mut self.scratch);
        buf.clear();
        let mut e = Enc(&mut buf);
        let at = e.begin(Opcode::Channel);
        e.u16(id).u16(schema).str(topic).str(message_encoding);
        let m = e.begin_len32();
        for (k, v) in metadata {
            e.str(k).str(v);
        }
        e.end_len32(m);
        e.end(at);
        self.summary_channels.extend_from_slice(&buf);
        let r = self.write_data(&buf, "writing a channel");
        self.scratch = buf;
        self.channel_messages.push(0);
        self.chunk_entries.push(Vec::new());
        r.map(|_| id)
    }

    /// Adds a Message record (spec "Message": channel_id, sequence, log_time, publish_time,
    /// data) to the open chunk; the sequence number counts the channel's messages from 0.
    /// Times are ns; what they mean is the caller's convention (see the module docs of
    /// [`recording`](super)).
    pub fn write_message(
        &mut self,
        channel: ChannelId,
        log_time: u64,
        publish_time: u64,
        data: &[u8],
    ) -> Result<(), RecordingError> {
        let ch = usize::from(channel);
        if channel == 0 || ch >= self.channel_messages.len() {
            return Err(RecordingError::Usage {
                path: self.path.clone(),
                problem: format!("message on channel {channel}, which was not added"),
            });
        }
        let sequence = self.channel_messages[ch] as u32;
        self.channel_messages[ch] += 1;
        let offset = self.chunk.len() as u64;
        let mut e = Enc(&mut self.chunk);
        let at = e.begin(Opcode::Message);
        e.u16(channel).u32(sequence).u64(log_time).u64(publish_time);
        e.0.extend_from_slice(data);
        e.end(at);
        let entries = &mut self.chunk_entries[ch];
        if entries.is_empty() {
            self.chunk_channels.push(channel);
        }
        entries.push((log_time, offset));
        self.chunk_start_time = self.chunk_start_time.min(log_time);
        self.chunk_end_time = self.chunk_end_time.max(log_time);
        self.message_start_time = self.message_start_time.min(log_time);
        self.message_end_time = self.message_end_time.max(log_time);
        self.message_count += 1;
        if self.chunk.len() >= self.chunk_size {
            self.flush_chunk()?;
        }
        Ok(())
    }

    /// Closes the open chunk (if it holds messages): writes the Chunk record and its Message
    /// Index records and hands everything to the operating system.
    pub fn flush_chunk(&mut self) -> Result<(), RecordingError> {
        if self.chunk_channels.is_empty() {
            return Ok(());
        }
        let chunk_start = self.pos;
        let records_len = self.chunk.len() as u64;
        let mut buf = std::mem::take(&mut self.scratch);
        buf.clear();
        // Chunk: message_start_time, message_end_time, uncompressed_size, uncompressed_crc,
        // compression, records (u64 length prefix).
        let content_len = 8 + 8 + 8 + 4 + 4 + 8 + records_len;
        Enc(&mut buf)
            .u8(Opcode::Chunk as u8)
            .u64(content_len)
            .u64(self.chunk_start_time)
            .u64(self.chunk_end_time)
            .u64(records_len)
            .u32(super::crc32::crc32(&self.chunk))
            .str("")
            .u64(records_len);
        let chunk = std::mem::take(&mut self.chunk);
        let r = self
            .write_data(&buf, "writing a chunk")
            .and_then(|_| self.write_data(&chunk, "writing a chunk"));
        self.chunk = chunk;
        if let Err(e) = r {
            self.scratch = buf;
            return Err(e);
        }
        let chunk_length = self.pos - chunk_start;

        // Message Index records, one per channel in the chunk, in channel order.
        self.chunk_channels.sort_unstable();
        buf.clear();
        let mut index_offsets: Vec<(ChannelId, u64)> = Vec::with_capacity(self.chunk_channels.len());
        for &ch in &self.chunk_channels {
            index_offsets.push((ch, self.pos + buf.len() as u64));
            let mut e = Enc(&mut buf);
            let at = e.begin(Opcode::MessageIndex);
            e.u16(ch);
            let a = e.begin_len32();
            for &(t, off) in &self.chunk_entries[usize::from(ch)] {
                e.u64(t).u64(off);
            }
            e.end_len32(a);
            e.end(at);
        }
        let index_len = buf.len() as u64;
        let r = self.write_data(&buf, "writing message indexes");
        self.scratch = buf;
        r?;

        // Chunk Index for the summary: message_start_time, message_end_time,
        // chunk_start_offset, chunk_length, message_index_offsets, message_index_length,
        // compression, compressed_size, uncompressed_size.
        let mut e = Enc(&mut self.summary_chunk_indexes);
        let at = e.begin(Opcode::ChunkIndex);
        e.u64(self.chunk_start_time)
            .u64(self.chunk_end_time)
            .u64(chunk_start)
            .u64(chunk_length);
        let m = e.begin_len32();
        for (ch, off) in index_offsets {
            e.u16(ch).u64(off);
        }
        e.end_len32(m);
        e.u64(index_len).str("").u64(records_len).u64(records_len);
        e.end(at);

        for &ch in &self.chunk_channels {
            self.chunk_entries[usize::from(ch)].clear();
        }
        self.chunk_channels.clear();
        self.chunk.clear();
        self.chunk_start_time = u64::MAX;
        self.chunk_end_time = 0;
        self.chunk_count += 1;
        self.out
            .flush()
            .map_err(|e| RecordingError::io(&self.path, "flushing a chunk", e))
    }

    /// Closes the open chunk and writes Data End, the summary (schemas, channels, statistics,
    /// chunk indexes), the summary offsets, the footer and the closing magic. Returns the sink.
    pub fn finish(mut self) -> Result<W, RecordingError> {
        self.flush_chunk()?;
        let mut buf = Vec::new();
        let mut e = Enc(&mut buf);
        let at = e.begin(Opcode::DataEnd);
        e.u32(self.data_crc.value());
        e.end(at);
        self.write_raw(&buf, "writing the data end")?;

        // Summary section, grouped by record type; (opcode, start, length) per group.
        let summary_start = self.pos;
        let mut summary = Vec::new();
        let mut groups: Vec<(Opcode, u64, u64)> = Vec::new();
        let mut group = |summary: &mut Vec<u8>, op: Opcode, bytes: &[u8]| {
            if !bytes.is_empty() {
                groups.push((op, summary_start + summary.len() as u64, bytes.len() as u64));
                summary.extend_from_slice(bytes);
            }
        };
        group(&mut summary, Opcode::Schema, &self.summary_schemas);
        group(&mut summary, Opcode::Channel, &self.summary_channels);
        let stats = self.statistics_record();
        group(&mut summary, Opcode::Statistics, &stats);
        group(&mut summary, Opcode::ChunkIndex, &self.summary_chunk_indexes);

        let summary_offset_start = summary_start + summary.len() as u64;
        let mut e = Enc(&mut summary);
        for (op, start, len) in groups {
            let at = e.begin(Opcode::SummaryOffset);
            e.u8(op as u8).u64(start).u64(len);
            e.end(at);
        }
        // Footer: summary_start, summary_offset_start, summary_crc (CRC of the summary and
        // summary offset sections and of the footer up to and including summary_offset_start).
        e.u8(Opcode::Footer as u8)
            .u64(super::mcap_format::FOOTER_CONTENT_LEN)
            .u64(summary_start)
            .u64(summary_offset_start);
        let crc = super::crc32::crc32(&summary);
        Enc(&mut summary).u32(crc);
        summary.extend_from_slice(&MAGIC);
        self.write_raw(&summary, "writing the summary")?;
        self.out
            .flush()
            .map_err(|e| RecordingError::io(&self.path, "flushing the summary", e))?;
        Ok(self.out)
    }

    /// Statistics (spec "Statistics"): message_count, schema_count, channel_count,
    /// attachment_count, metadata_count, chunk_count, message_start_time, message_end_time,
    /// channel_message_counts.
    fn statistics_record(&self) -> Vec<u8> {
        let (start, end) = if self.message_count == 0 {
            (0, 0)
        } else {
            (self.message_start_time, self.message_end_time)
        };
        let mut buf = Vec::new();
        let mut e = Enc(&mut buf);
        let at = e.begin(Opcode::Statistics);
        e.u64(self.message_count)
            .u16(self.schema_count)
            .u32(u32::from(self.channel_count))
            .u32(0)
            .u32(0)
            .u32(self.chunk_count)
            .u64(start)
            .u64(end);
        let m = e.begin_len32();
        for (ch, &n) in self.channel_messages.iter().enumerate().skip(1) {
            e.u16(ch as u16).u64(n);
        }
        e.end_len32(m);
        e.end(at);
        buf
    }
}
