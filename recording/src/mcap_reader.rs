//! Reads MCAP files (<https://mcap.dev/spec>) written by [`McapWriter`](super::McapWriter) or by
//! any other writer that uses uncompressed chunks or no chunks.
//!
//! Messages come from a linear scan of the data section in file order (for navsync recordings
//! that is the order in which they were recorded), one top-level record at a time, so memory
//! stays bounded by the largest chunk. Schema and Channel records are collected as they are
//! met, in or outside chunks; Message Index, Attachment, Metadata and unknown records are
//! skipped (spec: readers must skip unknown opcodes).
//!
//! The summary section is read at open when the file has a valid footer ([`McapReader::summary`]:
//! schemas, channels, statistics, chunk indexes, checked against the footer's summary CRC).
//!
//! A file whose writer died (no Data End, summary or footer; perhaps a partial last record)
//! is not an error: the scan yields every complete record and then reports
//! [`ScanEnd::Truncated`] with the offset where the usable data stops. A damaged record inside
//! the file (a chunk whose CRC does not match, a field that overruns its record) is an error
//! naming the byte offset and the record type. Nothing in a file makes the reader panic.

use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use super::crc32::crc32;
use super::error::RecordingError;
use super::mcap_format::{Dec, FOOTER_AND_MAGIC_LEN, FOOTER_CONTENT_LEN, FieldError, MAGIC, Opcode, RECORD_PREFIX_LEN};

/// The Header record (spec "Header").
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Header {
    /// Profile (navsync writes "").
    pub profile: String,
    /// Writing library.
    pub library: String,
}

/// A Schema record (spec "Schema").
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Schema {
    /// Id (> 0).
    pub id: u16,
    /// Name (navsync: the sample type name, e.g. `navsync.ImuSample.v1`).
    pub name: String,
    /// Encoding of `data` (navsync: `jsonschema`).
    pub encoding: String,
    /// The schema.
    pub data: Vec<u8>,
}

/// A Channel record (spec "Channel").
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Channel {
    /// Id.
    pub id: u16,
    /// Schema id (0: none).
    pub schema_id: u16,
    /// Topic (navsync: the service name).
    pub topic: String,
    /// Encoding of the messages (navsync: `json`).
    pub message_encoding: String,
    /// Key-value metadata.
    pub metadata: Vec<(String, String)>,
}

/// The Statistics record (spec "Statistics").
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Statistics {
    /// Messages in the file.
    pub message_count: u64,
    /// Schemas.
    pub schema_count: u16,
    /// Channels.
    pub channel_count: u32,
    /// Attachments.
    pub attachment_count: u32,
    /// Metadata records.
    pub metadata_count: u32,
    /// Chunks.
    pub chunk_count: u32,
    /// Earliest message log time, ns.
    pub message_start_time: u64,
    /// Latest message log time, ns.
    pub message_end_time: u64,
    /// Messages per channel id.
    pub channel_message_counts: Vec<(u16, u64)>,
}

/// A Chunk Index record (spec "Chunk Index").
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChunkIndex {
    /// Earliest log time in the chunk, ns.
    pub message_start_time: u64,
    /// Latest log time in the chunk, ns.
    pub message_end_time: u64,
    /// File offset of the Chunk record.
    pub chunk_start_offset: u64,
    /// Length of the Chunk record, prefix included.
    pub chunk_length: u64,
    /// File offset of each channel's Message Index record.
    pub message_index_offsets: Vec<(u16, u64)>,
    /// Bytes of the Message Index records after the chunk.
    pub message_index_length: u64,
    /// Compression ("" none).
    pub compression: String,
    /// Size of the chunk's records as stored.
    pub compressed_size: u64,
    /// Size of the chunk's records uncompressed.
    pub uncompressed_size: u64,
}

/// The summary section of a cleanly closed file.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct SummarySection {
    /// Schemas.
    pub schemas: Vec<Schema>,
    /// Channels.
    pub channels: Vec<Channel>,
    /// Statistics, when written.
    pub statistics: Option<Statistics>,
    /// One per chunk.
    pub chunk_indexes: Vec<ChunkIndex>,
}

/// One message, borrowed from the reader until the next call.
#[derive(Debug, Clone, Copy)]
pub struct Message<'a> {
    /// Its channel.
    pub channel: &'a Channel,
    /// The channel's schema, if it has one and it was seen.
    pub schema: Option<&'a Schema>,
    /// Sequence number.
    pub sequence: u32,
    /// Log time, ns.
    pub log_time: u64,
    /// Publish time, ns.
    pub publish_time: u64,
    /// The payload.
    pub data: &'a [u8],
    /// File offset of the Message record (inside its chunk for chunked files).
    pub offset: u64,
}

/// How the linear scan of the data section ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ScanEnd {
    /// At Data End (or a Footer): the file was closed properly.
    Clean,
    /// The file stops before Data End: everything before `offset` was read; what starts
    /// there (`record`, or "end of file") is missing or incomplete.
    Truncated {
        /// File offset where the usable data stops.
        offset: u64,
        /// The incomplete record's type, or "end of file" when the file ends between records.
        record: String,
    },
}

struct ChunkCursor {
    /// Position of the next inner record in `buf`.
    pos: usize,
    /// End of the chunk's records in `buf`.
    end: usize,
}

struct MsgLoc {
    channel: u16,
    sequence: u32,
    log_time: u64,
    publish_time: u64,
    data: core::ops::Range<usize>,
    offset: u64,
}

/// A streaming MCAP reader.
pub struct McapReader<R: Read + Seek> {
    src: R,
    path: PathBuf,
    len: u64,
    /// File offset of the next top-level record.
    pos: u64,
    header: Header,
    summary: Option<SummarySection>,
    schemas: Vec<Option<Schema>>,
    channels: Vec<Option<Channel>>,
    /// Content of the current top-level record.
    buf: Vec<u8>,
    /// File offset of `buf[0]`.
    buf_offset: u64,
    chunk: Option<ChunkCursor>,
    end: Option<ScanEnd>,
}

impl McapReader<BufReader<File>> {
    /// Opens a file.
    pub fn open(path: &Path) -> Result<Self, RecordingError> {
        let f = File::open(path).map_err(|e| RecordingError::io(path, "opening", e))?;
        Self::new(BufReader::with_capacity(256 * 1024, f), path)
    }
}

fn field_err(path: &Path, content_offset: u64, op: u8, e: FieldError) -> RecordingError {
    RecordingError::corrupt(path, content_offset + e.at as u64, op, e.problem)
}

impl<R: Read + Seek> McapReader<R> {
    /// Reads the magic, the Header and (when the file was closed properly) the summary from
    /// `src`; `path` names the file in errors.
    pub fn new(mut src: R, path: &Path) -> Result<Self, RecordingError> {
        let len = src
            .seek(SeekFrom::End(0))
            .map_err(|e| RecordingError::io(path, "reading the length", e))?;
        src.seek(SeekFrom::Start(0))
            .map_err(|e| RecordingError::io(path, "seeking", e))?;
        let mut magic = [0u8; 8];
        if len < 8 || src.read_exact(&mut magic).is_err() || magic != MAGIC {
            return Err(RecordingError::NotMcap {
                path: path.to_path_buf(),
            });
        }
        let mut r = Self {
            src,
            path: path.to_path_buf(),
            len,
            pos: 8,
            header: Header {
                profile: String::new(),
                library: String::new(),
            },
            summary: None,
            schemas: Vec::new(),
            channels: Vec::new(),
            buf: Vec::new(),
            buf_offset: 0,
            chunk: None,
            end: None,
        };
        match r.read_record_prefix()? {
            Some((op, content_len)) if op == Opcode::Header as u8 => {
                if content_len > r.len - r.pos {
                    return Err(RecordingError::corrupt(path, 8, op, "the file ends inside the Header"));
                }
                r.read_content(content_len)?;
                let mut d = Dec::new(&r.buf);
                let profile = d.str("profile").map_err(|e| field_err(path, r.buf_offset, op, e))?;
                let library = d.str("library").map_err(|e| field_err(path, r.buf_offset, op, e))?;
                r.header = Header {
                    profile: profile.to_string(),
                    library: library.to_string(),
                };
            }
            Some((op, _)) => {
                return Err(RecordingError::corrupt(
                    path,
                    8,
                    op,
                    "the first record must be a Header",
                ));
            }
            None => {
                return Err(RecordingError::corrupt(
                    path,
                    8,
                    Opcode::Header as u8,
                    "the file ends inside the Header",
                ));
            }
        }
        let after_header = r.pos;
        r.summary = r.read_summary()?;
        if let Some(s) = &r.summary {
            // A reader may meet messages before their channel in a file that keeps channels
            // in the summary only; start from the summary's.
            for sc in &s.schemas {
                put(&mut r.schemas, sc.id, sc.clone());
            }
            for ch in &s.channels {
                put(&mut r.channels, ch.id, ch.clone());
            }
        }
        r.pos = after_header;
        r.src
            .seek(SeekFrom::Start(after_header))
            .map_err(|e| RecordingError::io(path, "seeking", e))?;
        Ok(r)
    }

    /// The file's name as given.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// File length, bytes.
    pub fn file_len(&self) -> u64 {
        self.len
    }

    /// File offset up to which the scan has read.
    pub fn position(&self) -> u64 {
        self.pos
    }

    /// The Header record.
    pub fn header(&self) -> &Header {
        &self.header
    }

    /// The summary, when the file was closed properly.
    pub fn summary(&self) -> Option<&SummarySection> {
        self.summary.as_ref()
    }

    /// How the scan ended (`None` while messages remain).
    pub fn scan_end(&self) -> Option<&ScanEnd> {
        self.end.as_ref()
    }

    /// A channel seen so far (or listed in the summary).
    pub fn channel(&self, id: u16) -> Option<&Channel> {
        self.channels.get(usize::from(id)).and_then(Option::as_ref)
    }

    /// A schema seen so far (or listed in the summary).
    pub fn schema(&self, id: u16) -> Option<&Schema> {
        self.schemas.get(usize::from(id)).and_then(Option::as_ref)
    }

    /// Every channel seen so far (or listed in the summary), by id.
    pub fn channels(&self) -> impl Iterator<Item = &Channel> {
        self.channels.iter().flatten()
    }

    fn seek_err(&self, e: std::io::Error) -> RecordingError {
        RecordingError::io(&self.path, "reading", e)
    }

    /// Reads a record's opcode and length at `pos`; `None` when fewer than 9 bytes remain.
    fn read_record_prefix(&mut self) -> Result<Option<(u8, u64)>, RecordingError> {
        if self.len - self.pos < RECORD_PREFIX_LEN {
            return Ok(None);
        }
        let mut p = [0u8; 9];
        self.src.read_exact(&mut p).map_err(|e| self.seek_err(e))?;
        self.pos += RECORD_PREFIX_LEN;
        let mut l = [0u8; 8];
        l.copy_from_slice(&p[1..]);
        Ok(Some((p[0], u64::from_le_bytes(l))))
    }

    /// Reads `n` bytes of record content at `pos` into `buf` (the caller checked they exist).
    fn read_content(&mut self, n: u64) -> Result<(), RecordingError> {
        let n = usize::try_from(n).map_err(|_| RecordingError::Unsupported {
            path: self.path.clone(),
            offset: self.pos,
            record: "record".into(),
            problem: format!("{n} bytes do not fit in memory"),
        })?;
        self.buf.resize(n, 0);
        self.src.read_exact(&mut self.buf).map_err(|e| self.seek_err(e))?;
        self.buf_offset = self.pos;
        self.pos += n as u64;
        Ok(())
    }

    fn skip_content(&mut self, n: u64) -> Result<(), RecordingError> {
        self.pos += n;
        self.src
            .seek(SeekFrom::Start(self.pos))
            .map(|_| ())
            .map_err(|e| self.seek_err(e))
    }

    /// The footer's summary, if the file ends in a valid footer.
    fn read_summary(&mut self) -> Result<Option<SummarySection>, RecordingError> {
        if self.len < 8 + FOOTER_AND_MAGIC_LEN {
            return Ok(None);
        }
        let footer_at = self.len - FOOTER_AND_MAGIC_LEN;
        self.src
            .seek(SeekFrom::Start(footer_at))
            .map_err(|e| self.seek_err(e))?;
        let mut f = [0u8; FOOTER_AND_MAGIC_LEN as usize];
        self.src.read_exact(&mut f).map_err(|e| self.seek_err(e))?;
        let op = f[0];
        let content_len = u64::from_le_bytes(f[1..9].try_into().unwrap_or_default());
        if op != Opcode::Footer as u8 || content_len != FOOTER_CONTENT_LEN || f[29..] != MAGIC {
            return Ok(None); // no footer: an unclean stop
        }
        let summary_start = u64::from_le_bytes(f[9..17].try_into().unwrap_or_default());
        let summary_offset_start = u64::from_le_bytes(f[17..25].try_into().unwrap_or_default());
        let summary_crc = u32::from_le_bytes(f[25..29].try_into().unwrap_or_default());
        if summary_start == 0 {
            return Ok(None);
        }
        let footer_op = Opcode::Footer as u8;
        if summary_start < self.pos || summary_start > footer_at {
            return Err(RecordingError::corrupt(
                &self.path,
                footer_at,
                footer_op,
                format!("summary_start {summary_start} is outside the file's data"),
            ));
        }
        if summary_offset_start != 0 && !(summary_start..=footer_at).contains(&summary_offset_start) {
            return Err(RecordingError::corrupt(
                &self.path,
                footer_at,
                footer_op,
                format!("summary_offset_start {summary_offset_start} is outside the summary"),
            ));
        }
        let end = if summary_offset_start == 0 {
            footer_at
        } else {
            summary_offset_start
        };
        self.src
            .seek(SeekFrom::Start(summary_start))
            .map_err(|e| self.seek_err(e))?;
        let mut bytes = vec![0u8; (footer_at - summary_start) as usize];
        self.src.read_exact(&mut bytes).map_err(|e| self.seek_err(e))?;
        if summary_crc != 0 {
            let mut covered = bytes.clone();
            covered.extend_from_slice(&f[..25]);
            let actual = crc32(&covered);
            if actual != summary_crc {
                return Err(RecordingError::corrupt(
                    &self.path,
                    footer_at,
                    footer_op,
                    format!("summary CRC 0x{actual:08x} does not match the footer's 0x{summary_crc:08x}"),
                ));
            }
        }
        let mut s = SummarySection::default();
        let region = &bytes[..(end - summary_start) as usize];
        let mut at = 0usize;
        while at < region.len() {
            let rec_offset = summary_start + at as u64;
            if region.len() - at < RECORD_PREFIX_LEN as usize {
                return Err(RecordingError::corrupt(
                    &self.path,
                    rec_offset,
                    region[at],
                    "record prefix overruns the summary section",
                ));
            }
            let op = region[at];
            let n = u64::from_le_bytes(region[at + 1..at + 9].try_into().unwrap_or_default());
            let body_at = at + 9;
            if n > (region.len() - body_at) as u64 {
                return Err(RecordingError::corrupt(
                    &self.path,
                    rec_offset,
                    op,
                    format!("length {n} overruns the summary section"),
                ));
            }
            let body = &region[body_at..body_at + n as usize];
            let content_offset = summary_start + body_at as u64;
            let fe = |e: FieldError| field_err(&self.path, content_offset, op, e);
            match op {
                x if x == Opcode::Schema as u8 => s.schemas.push(parse_schema(body).map_err(fe)?),
                x if x == Opcode::Channel as u8 => s.channels.push(parse_channel(body).map_err(fe)?),
                x if x == Opcode::Statistics as u8 => s.statistics = Some(parse_statistics(body).map_err(fe)?),
                x if x == Opcode::ChunkIndex as u8 => s.chunk_indexes.push(parse_chunk_index(body).map_err(fe)?),
                _ => {}
            }
            at = body_at + n as usize;
        }
        Ok(Some(s))
    }

    /// The next message in file order; `Ok(None)` at the end of the data (see [`scan_end`](Self::scan_end)).
    pub fn next_message(&mut self) -> Result<Option<Message<'_>>, RecordingError> {
        let Some(loc) = self.advance()? else {
            return Ok(None);
        };
        let channel = self
            .channels
            .get(usize::from(loc.channel))
            .and_then(Option::as_ref)
            .ok_or_else(|| {
                RecordingError::corrupt(
                    &self.path,
                    loc.offset,
                    Opcode::Message as u8,
                    format!("channel {} has no Channel record before it", loc.channel),
                )
            })?;
        let schema = match channel.schema_id {
            0 => None,
            id => self.schemas.get(usize::from(id)).and_then(Option::as_ref),
        };
        Ok(Some(Message {
            channel,
            schema,
            sequence: loc.sequence,
            log_time: loc.log_time,
            publish_time: loc.publish_time,
            data: &self.buf[loc.data],
            offset: loc.offset,
        }))
    }

    fn advance(&mut self) -> Result<Option<MsgLoc>, RecordingError> {
        loop {
            if let Some(c) = &self.chunk {
                let (pos, end) = (c.pos, c.end);
                if pos >= end {
                    self.chunk = None;
                    continue;
                }
                let rec_offset = self.buf_offset + pos as u64;
                if end - pos < RECORD_PREFIX_LEN as usize {
                    return Err(RecordingError::corrupt(
                        &self.path,
                        rec_offset,
                        self.buf[pos],
                        "record prefix overruns its chunk",
                    ));
                }
                let op = self.buf[pos];
                let n = u64::from_le_bytes(self.buf[pos + 1..pos + 9].try_into().unwrap_or_default());
                let body = pos + 9;
                if n > (end - body) as u64 {
                    return Err(RecordingError::corrupt(
                        &self.path,
                        rec_offset,
                        op,
                        format!("length {n} overruns its chunk ({} bytes left)", end - body),
                    ));
                }
                let body_end = body + n as usize;
                if let Some(c) = &mut self.chunk {
                    c.pos = body_end;
                }
                if let Some(loc) = self.inner_record(op, body, body_end, rec_offset)? {
                    return Ok(Some(loc));
                }
                continue;
            }
            if self.end.is_some() {
                return Ok(None);
            }
            let rec_offset = self.pos;
            let Some((op, n)) = self.read_record_prefix()? else {
                let record = if self.len == self.pos {
                    "end of file".to_string()
                } else {
                    "record prefix".to_string()
                };
                self.end = Some(ScanEnd::Truncated {
                    offset: rec_offset,
                    record,
                });
                return Ok(None);
            };
            if n > self.len - self.pos {
                self.end = Some(ScanEnd::Truncated {
                    offset: rec_offset,
                    record: super::mcap_format::opcode_name(op),
                });
                self.pos = rec_offset;
                return Ok(None);
            }
            match op {
                x if x == Opcode::Chunk as u8 => {
                    self.read_content(n)?;
                    let (start, end) = self.chunk_records(rec_offset)?;
                    self.chunk = Some(ChunkCursor { pos: start, end });
                }
                x if x == Opcode::Message as u8 || x == Opcode::Schema as u8 || x == Opcode::Channel as u8 => {
                    self.read_content(n)?;
                    let len = self.buf.len();
                    if let Some(loc) = self.inner_record(op, 0, len, rec_offset)? {
                        return Ok(Some(loc));
                    }
                }
                x if x == Opcode::DataEnd as u8 || x == Opcode::Footer as u8 => {
                    self.skip_content(n)?;
                    self.end = Some(ScanEnd::Clean);
                    return Ok(None);
                }
                _ => self.skip_content(n)?,
            }
        }
    }

    /// Checks the Chunk record in `buf`; returns the range of its records.
    fn chunk_records(&self, rec_offset: u64) -> Result<(usize, usize), RecordingError> {
        let op = Opcode::Chunk as u8;
        let fe = |e: FieldError| field_err(&self.path, self.buf_offset, op, e);
        let mut d = Dec::new(&self.buf);
        d.u64("message_start_time").map_err(fe)?;
        d.u64("message_end_time").map_err(fe)?;
        let uncompressed_size = d.u64("uncompressed_size").map_err(fe)?;
        let crc = d.u32("uncompressed_crc").map_err(fe)?;
        let compression = d.str("compression").map_err(fe)?;
        if !compression.is_empty() {
            return Err(RecordingError::Unsupported {
                path: self.path.clone(),
                offset: rec_offset,
                record: "Chunk".into(),
                problem: format!("compression `{compression}` (navsync reads uncompressed chunks only)"),
            });
        }
        let records = d.bytes64("records").map_err(fe)?;
        let start = d.pos() - records.len();
        if uncompressed_size != records.len() as u64 {
            return Err(RecordingError::corrupt(
                &self.path,
                rec_offset,
                op,
                format!(
                    "uncompressed_size {uncompressed_size} but {} bytes of records",
                    records.len()
                ),
            ));
        }
        if crc != 0 {
            let actual = crc32(records);
            if actual != crc {
                return Err(RecordingError::corrupt(
                    &self.path,
                    rec_offset,
                    op,
                    format!("CRC of the records is 0x{actual:08x}, the chunk says 0x{crc:08x}"),
                ));
            }
        }
        Ok((start, start + records.len()))
    }

    /// Handles a Schema, Channel or Message record whose content is `buf[body..end]`.
    fn inner_record(
        &mut self,
        op: u8,
        body: usize,
        end: usize,
        rec_offset: u64,
    ) -> Result<Option<MsgLoc>, RecordingError> {
        let content_offset = self.buf_offset + body as u64;
        let path = &self.path;
        let fe = |e: FieldError| field_err(path, content_offset, op, e);
        let content = &self.buf[body..end];
        match op {
            x if x == Opcode::Message as u8 => {
                let mut d = Dec::new(content);
                let channel = d.u16("channel_id").map_err(fe)?;
                let sequence = d.u32("sequence").map_err(fe)?;
                let log_time = d.u64("log_time").map_err(fe)?;
                let publish_time = d.u64("publish_time").map_err(fe)?;
                let data_start = body + d.pos();
                Ok(Some(MsgLoc {
                    channel,
                    sequence,
                    log_time,
                    publish_time,
                    data: data_start..end,
                    offset: rec_offset,
                }))
            }
            x if x == Opcode::Schema as u8 => {
                let s = parse_schema(content).map_err(fe)?;
                put(&mut self.schemas, s.id, s);
                Ok(None)
            }
            x if x == Opcode::Channel as u8 => {
                let c = parse_channel(content).map_err(fe)?;
                put(&mut self.channels, c.id, c);
                Ok(None)
            }
            _ => Ok(None),
        }
    }
}

fn put<T>(v: &mut Vec<Option<T>>, id: u16, x: T) {
    let i = usize::from(id);
    if v.len() <= i {
        v.resize_with(i + 1, || None);
    }
    v[i] = Some(x);
}

fn parse_schema(b: &[u8]) -> Result<Schema, FieldError> {
    let mut d = Dec::new(b);
    Ok(Schema {
        id: d.u16("id")?,
        name: d.str("name")?.to_string(),
        encoding: d.str("encoding")?.to_string(),
        data: d.bytes32("data")?.to_vec(),
    })
}

fn parse_channel(b: &[u8]) -> Result<Channel, FieldError> {
    let mut d = Dec::new(b);
    Ok(Channel {
        id: d.u16("id")?,
        schema_id: d.u16("schema_id")?,
        topic: d.str("topic")?.to_string(),
        message_encoding: d.str("message_encoding")?.to_string(),
        metadata: d.str_map("metadata")?,
    })
}

fn parse_statistics(b: &[u8]) -> Result<Statistics, FieldError> {
    let mut d = Dec::new(b);
    Ok(Statistics {
        message_count: d.u64("message_count")?,
        schema_count: d.u16("schema_count")?,
        channel_count: d.u32("channel_count")?,
        attachment_count: d.u32("attachment_count")?,
        metadata_count: d.u32("metadata_count")?,
        chunk_count: d.u32("chunk_count")?,
        message_start_time: d.u64("message_start_time")?,
        message_end_time: d.u64("message_end_time")?,
        channel_message_counts: d.u16_u64_map("channel_message_counts")?,
    })
}

fn parse_chunk_index(b: &[u8]) -> Result<ChunkIndex, FieldError> {
    let mut d = Dec::new(b);
    Ok(ChunkIndex {
        message_start_time: d.u64("message_start_time")?,
        message_end_time: d.u64("message_end_time")?,
        chunk_start_offset: d.u64("chunk_start_offset")?,
        chunk_length: d.u64("chunk_length")?,
        message_index_offsets: d.u16_u64_map("message_index_offsets")?,
        message_index_length: d.u64("message_index_length")?,
        compression: d.str("compression")?.to_string(),
        compressed_size: d.u64("compressed_size")?,
        uncompressed_size: d.u64("uncompressed_size")?,
    })
}
