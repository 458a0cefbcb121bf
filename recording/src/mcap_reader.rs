//! Reads MCAP files (<https://mcap.dev/spec>) with the maintained `mcap` crate's streaming
//! (sans-I/O) reader: any MCAP writer's files, chunked or not, compressed with zstd or lz4 or
//! not at all.
//!
//! Messages come from a linear scan of the data section in file order (for navsync recordings
//! that is the order in which they were recorded), so memory stays bounded by the largest
//! chunk. Each chunk's CRC is checked before any of its messages is given out. Schema and
//! Channel records are collected as they are met, in or outside chunks; other records are
//! skipped (spec: readers must skip unknown opcodes).
//!
//! The summary section is read at open when the file has a valid footer ([`McapReader::summary`]:
//! schemas, channels, statistics, chunk indexes, checked against the footer's summary CRC).
//!
//! A file whose writer died (no Data End, summary or footer; perhaps a partial last chunk)
//! is not an error: the scan yields every complete chunk and then reports
//! [`ScanEnd::Truncated`]. A damaged chunk (its CRC does not match, it does not decompress, a
//! record in it overruns it) is skipped whole, none of its messages given out, and reported
//! with its byte offset and the time range of the messages it held
//! ([`McapReader::skipped_chunks`]); the rest of the file is read. Any other damaged record
//! (outside a chunk, where its length cannot be trusted to find the next one) is an error
//! naming the byte offset reached. Nothing in a file makes the reader panic.

use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use mcap::records::Record;
use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};

use super::error::RecordingError;

/// The MCAP magic, at both ends of a file.
const MAGIC: [u8; 8] = [0x89, b'M', b'C', b'A', b'P', b'0', b'\r', b'\n'];
/// Footer record with its opcode and length prefix, then the magic.
const FOOTER_AND_MAGIC_LEN: u64 = 1 + 8 + 20 + 8;
/// The longest record the reader accepts (a corrupt length must not allocate gigabytes).
const RECORD_LENGTH_LIMIT: usize = 256 << 20;

/// The Header record (spec "Header").
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Header {
    /// Profile (navsync writes `ros2`).
    pub profile: String,
    /// Writing library.
    pub library: String,
}

/// A Schema record (spec "Schema").
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Schema {
    /// Id (> 0).
    pub id: u16,
    /// Name (navsync: the ROS 2 type name, e.g. `navsync_msgs/msg/ImuSample`).
    pub name: String,
    /// Encoding of `data` (navsync: `ros2msg`; `jsonschema` in recordings before CDR).
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
    /// Topic (navsync: the service name as a ROS 2 topic, `/navsync/imu/0/sample`).
    pub topic: String,
    /// Encoding of the messages (navsync: `cdr`, or `json`).
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
    /// File offset up to which the reader had read when it met the message (the end of its
    /// chunk for chunked files).
    pub offset: u64,
}

/// How the linear scan of the data section ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ScanEnd {
    /// At Data End (or a Footer): the file was closed properly.
    Clean,
    /// The file stops before Data End (its writer died): every complete chunk and record was
    /// read; what was being written at the end is missing.
    Truncated {
        /// The file's length, where the data stops.
        offset: u64,
        /// What was cut off, as the MCAP reader describes it.
        record: String,
    },
}

/// A chunk the reader skipped because it was damaged.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SkippedChunk {
    /// File offset of the Chunk record.
    pub offset: u64,
    /// Length of the Chunk record, prefix included.
    pub length: u64,
    /// Log time range (ns) of the messages it held: the summary's chunk index when the file
    /// has one, else the chunk's own header (which may be damaged too).
    pub message_start_time: u64,
    /// See `message_start_time`.
    pub message_end_time: u64,
    /// What was wrong.
    pub problem: String,
}

impl std::fmt::Display for SkippedChunk {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let t = |ns: u64| match i64::try_from(ns) {
            // log_time is UTC-like in navsync's recordings; anything before 2000 is shown raw.
            Ok(v) if v > 946_684_800_000_000_000 => navsync_shared::time::format_rfc3339_ms(v),
            _ => format!("{ns} ns"),
        };
        write!(
            f,
            "skipped a corrupt chunk at byte offset {} ({} bytes; messages logged {} to {}): {}",
            self.offset,
            self.length,
            t(self.message_start_time),
            t(self.message_end_time),
            self.problem
        )
    }
}

/// A streaming MCAP reader.
pub struct McapReader<R: Read + Seek> {
    src: R,
    path: PathBuf,
    len: u64,
    /// Bytes of the file handed to the reader so far.
    fed: u64,
    reader: LinearReader,
    header: Header,
    summary: Option<SummarySection>,
    schemas: Vec<Option<Schema>>,
    channels: Vec<Option<Channel>>,
    /// The payload of the message given out last.
    data: Vec<u8>,
    /// The current chunk's records, uncompressed (reused from chunk to chunk).
    chunk: Vec<u8>,
    /// Its records not handed out yet: (opcode, body range in `chunk`), in order.
    pending: std::collections::VecDeque<(u8, core::ops::Range<usize>)>,
    end: Option<ScanEnd>,
    /// File offset of the next record the linear reader hands out.
    next_record_offset: u64,
    /// The chunk `pending` comes from, to skip it whole if one of its records is damaged.
    pending_chunk: Option<SkippedChunk>,
    /// The damaged chunks skipped so far.
    skipped: Vec<SkippedChunk>,
}

impl McapReader<BufReader<File>> {
    /// Opens a file.
    pub fn open(path: &Path) -> Result<Self, RecordingError> {
        let f = File::open(path).map_err(|e| RecordingError::io(path, "opening", e))?;
        Self::new(BufReader::with_capacity(256 * 1024, f), path)
    }
}

fn put<T>(v: &mut Vec<Option<T>>, id: u16, x: T) {
    let i = usize::from(id);
    if v.len() <= i {
        v.resize_with(i + 1, || None);
    }
    v[i] = Some(x);
}

fn schema_of(header: mcap::records::SchemaHeader, data: &[u8]) -> Schema {
    Schema {
        id: header.id,
        name: header.name,
        encoding: header.encoding,
        data: data.to_vec(),
    }
}

fn channel_of(c: mcap::records::Channel) -> Channel {
    Channel {
        id: c.id,
        schema_id: c.schema_id,
        topic: c.topic,
        message_encoding: c.message_encoding,
        metadata: c.metadata.into_iter().collect(),
    }
}

impl<R: Read + Seek> McapReader<R> {
    /// Checks the magic, reads (when the file was closed properly) the summary and the
    /// Header from `src`; `path` names the file in errors.
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
        src.seek(SeekFrom::Start(0))
            .map_err(|e| RecordingError::io(path, "seeking", e))?;
        // Chunks come whole: their records are checked and unpacked here (`unpack_chunk`), not
        // by the crate's chunk reader, whose arithmetic on a malformed uncompressed chunk
        // overflows (found by the fuzzer in mcap 0.26).
        let options = LinearReaderOptions::default()
            .with_emit_chunks(true)
            .with_record_length_limit(RECORD_LENGTH_LIMIT);
        let mut r = Self {
            src,
            path: path.to_path_buf(),
            len,
            fed: 0,
            reader: LinearReader::new_with_options(options),
            header: Header {
                profile: String::new(),
                library: String::new(),
            },
            summary: None,
            schemas: Vec::new(),
            channels: Vec::new(),
            data: Vec::new(),
            chunk: Vec::new(),
            pending: std::collections::VecDeque::new(),
            end: None,
            next_record_offset: MAGIC.len() as u64,
            pending_chunk: None,
            skipped: Vec::new(),
        };
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
        r.src
            .seek(SeekFrom::Start(0))
            .map_err(|e| RecordingError::io(path, "seeking", e))?;
        // The Header is the first record.
        match r.next_record()? {
            Some(Step::Header(h)) => r.header = h,
            Some(_) => return Err(r.corrupt("Header", "the first record must be a Header")),
            None => return Err(r.corrupt("Header", "the file ends before the end of the Header")),
        }
        Ok(r)
    }

    fn corrupt(&self, record: &str, problem: impl Into<String>) -> RecordingError {
        RecordingError::Corrupt {
            path: self.path.clone(),
            offset: self.fed,
            record: record.to_string(),
            problem: problem.into(),
        }
    }

    /// The file's path (for messages).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The file's length in bytes.
    pub fn file_len(&self) -> u64 {
        self.len
    }

    /// Bytes of the file read so far by the scan.
    pub fn position(&self) -> u64 {
        self.fed
    }

    /// The Header record.
    pub fn header(&self) -> &Header {
        &self.header
    }

    /// The summary of a properly closed file.
    pub fn summary(&self) -> Option<&SummarySection> {
        self.summary.as_ref()
    }

    /// How the scan ended, once [`next_message`](Self::next_message) returned `None`.
    pub fn scan_end(&self) -> Option<&ScanEnd> {
        self.end.as_ref()
    }

    /// The damaged chunks skipped so far, in file order.
    pub fn skipped_chunks(&self) -> &[SkippedChunk] {
        &self.skipped
    }

    /// Skips the chunk `info` (its records not given out), reporting it.
    fn skip_chunk(&mut self, mut info: SkippedChunk, problem: String) {
        self.pending.clear();
        self.pending_chunk = None;
        if let Some(ci) = self
            .summary
            .as_ref()
            .and_then(|s| s.chunk_indexes.iter().find(|c| c.chunk_start_offset == info.offset))
        {
            info.message_start_time = ci.message_start_time;
            info.message_end_time = ci.message_end_time;
        }
        info.problem = problem;
        self.skipped.push(info);
    }

    /// A channel seen so far (or in the summary).
    pub fn channel(&self, id: u16) -> Option<&Channel> {
        self.channels.get(usize::from(id)).and_then(Option::as_ref)
    }

    /// A schema seen so far (or in the summary).
    pub fn schema(&self, id: u16) -> Option<&Schema> {
        self.schemas.get(usize::from(id)).and_then(Option::as_ref)
    }

    /// The channels seen so far (or in the summary).
    pub fn channels(&self) -> impl Iterator<Item = &Channel> {
        self.channels.iter().flatten()
    }

    /// Reads the footer and, when it points to one, the summary section.
    fn read_summary(&mut self) -> Result<Option<SummarySection>, RecordingError> {
        if self.len < 8 + FOOTER_AND_MAGIC_LEN {
            return Ok(None);
        }
        let footer_at = self.len - FOOTER_AND_MAGIC_LEN;
        let mut tail = [0u8; FOOTER_AND_MAGIC_LEN as usize];
        self.src
            .seek(SeekFrom::Start(footer_at))
            .and_then(|_| self.src.read_exact(&mut tail))
            .map_err(|e| RecordingError::io(&self.path, "reading the footer", e))?;
        if tail[29..] != MAGIC || tail[0] != mcap::records::op::FOOTER || tail[1..9] != 20u64.to_le_bytes() {
            return Ok(None);
        }
        let u64_at = |i: usize| u64::from_le_bytes(tail[i..i + 8].try_into().unwrap_or([0; 8]));
        let summary_start = u64_at(9);
        let crc = u32::from_le_bytes(tail[25..29].try_into().unwrap_or([0; 4]));
        if summary_start == 0 {
            return Ok(None);
        }
        if summary_start < 8 || summary_start > footer_at {
            return Err(RecordingError::Corrupt {
                path: self.path.clone(),
                offset: footer_at,
                record: "Footer".into(),
                problem: format!("summary start {summary_start} outside the file"),
            });
        }
        let mut buf = vec![0u8; (footer_at - summary_start) as usize];
        self.src
            .seek(SeekFrom::Start(summary_start))
            .and_then(|_| self.src.read_exact(&mut buf))
            .map_err(|e| RecordingError::io(&self.path, "reading the summary", e))?;
        if crc != 0 {
            let mut h = crc32fast::Hasher::new();
            h.update(&buf);
            h.update(&tail[..25]);
            if h.finalize() != crc {
                return Err(RecordingError::Corrupt {
                    path: self.path.clone(),
                    offset: summary_start,
                    record: "Footer".into(),
                    problem: "the summary section does not match the footer's CRC".into(),
                });
            }
        }
        let mut s = SummarySection::default();
        let mut pos = 0usize;
        while pos < buf.len() {
            let at = summary_start + pos as u64;
            let bad = |problem: String| RecordingError::Corrupt {
                path: self.path.clone(),
                offset: at,
                record: "summary".into(),
                problem,
            };
            if buf.len() - pos < 9 {
                return Err(bad("a record prefix overruns the summary section".into()));
            }
            let op = buf[pos];
            let n = u64::from_le_bytes(buf[pos + 1..pos + 9].try_into().unwrap_or([0; 8]));
            let body_end = (pos as u64 + 9).checked_add(n).filter(|e| *e <= buf.len() as u64);
            let Some(body_end) = body_end else {
                return Err(bad(format!("a record of {n} bytes overruns the summary section")));
            };
            let body = &buf[pos + 9..body_end as usize];
            pos = body_end as usize;
            // Only what the summary is read for; anything else (allowed or not) is skipped
            // unparsed.
            use mcap::records::op as o;
            if !matches!(op, o::SCHEMA | o::CHANNEL | o::STATISTICS | o::CHUNK_INDEX) {
                continue;
            }
            if !fields_fit(op, body) {
                return Err(bad(format!("a field of record 0x{op:02x} overruns it")));
            }
            match mcap::parse_record(op, body).map_err(|e| bad(e.to_string()))? {
                Record::Schema { header, data } => s.schemas.push(schema_of(header, &data)),
                Record::Channel(c) => s.channels.push(channel_of(c)),
                Record::Statistics(st) => {
                    s.statistics = Some(Statistics {
                        message_count: st.message_count,
                        schema_count: st.schema_count,
                        channel_count: st.channel_count,
                        attachment_count: st.attachment_count,
                        metadata_count: st.metadata_count,
                        chunk_count: st.chunk_count,
                        message_start_time: st.message_start_time,
                        message_end_time: st.message_end_time,
                        channel_message_counts: st.channel_message_counts.into_iter().collect(),
                    })
                }
                Record::ChunkIndex(ci) => s.chunk_indexes.push(ChunkIndex {
                    message_start_time: ci.message_start_time,
                    message_end_time: ci.message_end_time,
                    chunk_start_offset: ci.chunk_start_offset,
                    chunk_length: ci.chunk_length,
                    message_index_offsets: ci.message_index_offsets.into_iter().collect(),
                    message_index_length: ci.message_index_length,
                    compression: ci.compression,
                    compressed_size: ci.compressed_size,
                    uncompressed_size: ci.uncompressed_size,
                }),
                _ => {}
            }
        }
        Ok(Some(s))
    }

    /// The next record of interest, feeding the reader from the file as it asks.
    fn next_record(&mut self) -> Result<Option<Step>, RecordingError> {
        loop {
            if let Some((opcode, range)) = self.pending.pop_front() {
                let chunk = core::mem::take(&mut self.chunk);
                let step = self.record(opcode, &chunk[range]);
                self.chunk = chunk;
                match step {
                    Ok(Some(step)) => return Ok(Some(step)),
                    Ok(None) => continue,
                    Err(e) => match self.pending_chunk.take() {
                        // A record of a chunk: the chunk goes, the file goes on.
                        Some(info) => {
                            let problem = match &e {
                                RecordingError::Corrupt { record, problem, .. } => format!("{record}: {problem}"),
                                other => other.to_string(),
                            };
                            self.skip_chunk(info, problem);
                            continue;
                        }
                        None => return Err(e),
                    },
                }
            }
            self.pending_chunk = None;
            if self.end.is_some() {
                return Ok(None);
            }
            let event = match self.reader.next_event() {
                None => {
                    self.end = Some(ScanEnd::Clean);
                    return Ok(None);
                }
                Some(Err(mcap::McapError::UnexpectedEof)) => {
                    self.end = Some(ScanEnd::Truncated {
                        offset: self.len,
                        record: "the record or chunk being written when the writer stopped".into(),
                    });
                    return Ok(None);
                }
                Some(Err(e)) => return Err(self.corrupt("data section", e.to_string())),
                Some(Ok(ev)) => ev,
            };
            match event {
                LinearReadEvent::ReadRequest(need) => {
                    let buf = self.reader.insert(need);
                    let n = self
                        .src
                        .read(buf)
                        .map_err(|e| RecordingError::io(&self.path, "reading", e))?;
                    self.reader.notify_read(n);
                    self.fed += n as u64;
                }
                LinearReadEvent::Record { data, opcode } => {
                    let offset = self.next_record_offset;
                    let length = 9 + data.len() as u64;
                    self.next_record_offset += length;
                    if opcode == mcap::records::op::CHUNK {
                        let time = |i: usize| {
                            data.get(i..i + 8)
                                .and_then(|b| b.try_into().ok())
                                .map_or(0, u64::from_le_bytes)
                        };
                        let info = SkippedChunk {
                            offset,
                            length,
                            message_start_time: time(0),
                            message_end_time: time(8),
                            problem: String::new(),
                        };
                        match unpack_chunk(data, &mut self.chunk, &mut self.pending) {
                            Ok(()) => self.pending_chunk = Some(info),
                            Err(problem) => self.skip_chunk(info, problem),
                        }
                        continue;
                    }
                    let body = data.to_vec();
                    match self.record(opcode, &body)? {
                        Some(step) => return Ok(Some(step)),
                        None => continue,
                    }
                }
            }
        }
    }

    /// One record outside or inside a chunk: a Header or Message to hand out, a Schema or
    /// Channel to keep, the end of the data section, or something to skip.
    fn record(&mut self, opcode: u8, data: &[u8]) -> Result<Option<Step>, RecordingError> {
        use mcap::records::op;
        if !matches!(
            opcode,
            op::HEADER | op::SCHEMA | op::CHANNEL | op::MESSAGE | op::DATA_END | op::FOOTER
        ) {
            return Ok(None);
        }
        let what = format!("record 0x{opcode:02x}");
        if !fields_fit(opcode, data) {
            return Err(self.corrupt(&what, "a field's length overruns the record"));
        }
        let record = mcap::parse_record(opcode, data).map_err(|e| self.corrupt(&what, e.to_string()))?;
        Ok(match record {
            Record::Header(h) => Some(Step::Header(Header {
                profile: h.profile,
                library: h.library,
            })),
            Record::Schema { header, data } => {
                let s = schema_of(header, &data);
                put(&mut self.schemas, s.id, s);
                None
            }
            Record::Channel(c) => {
                let c = channel_of(c);
                put(&mut self.channels, c.id, c);
                None
            }
            Record::Message { header, data } => {
                self.data.clear();
                self.data.extend_from_slice(&data);
                Some(Step::Message(header))
            }
            Record::DataEnd(_) | Record::Footer(_) => {
                self.pending.clear();
                self.end = Some(ScanEnd::Clean);
                None
            }
            _ => None,
        })
    }

    /// The next message in file order, `None` at the end of the data section (see
    /// [`scan_end`](Self::scan_end) for how it ended). A message on a channel that was never
    /// defined is an error.
    pub fn next_message(&mut self) -> Result<Option<Message<'_>>, RecordingError> {
        let header = loop {
            match self.next_record()? {
                Some(Step::Message(h)) => break h,
                Some(Step::Header(_)) => continue,
                None => return Ok(None),
            }
        };
        let Some(channel) = self.channel(header.channel_id) else {
            return Err(self.corrupt(
                "Message",
                format!("message on channel {}, which is not defined", header.channel_id),
            ));
        };
        let schema = if channel.schema_id == 0 {
            None
        } else {
            self.schema(channel.schema_id)
        };
        Ok(Some(Message {
            channel,
            schema,
            sequence: header.sequence,
            log_time: header.log_time,
            publish_time: header.publish_time,
            data: &self.data,
            offset: self.fed,
        }))
    }
}

/// The records of a Chunk record's body (MCAP spec "Chunk"): decompressed (zstd, lz4 or none)
/// within the declared size, the CRC of the uncompressed records checked (when not 0), and
/// every record's length checked against the chunk, before any of them is used.
fn unpack_chunk(
    body: &[u8],
    plain: &mut Vec<u8>,
    out: &mut std::collections::VecDeque<(u8, core::ops::Range<usize>)>,
) -> Result<(), String> {
    out.clear();
    plain.clear();
    // message_start_time, message_end_time, uncompressed_size (u64), uncompressed_crc (u32),
    // compression (string), records (u64 length + bytes).
    let u64_at = |i: usize| {
        body.get(i..i + 8)
            .and_then(|b| b.try_into().ok())
            .map(u64::from_le_bytes)
    };
    let short = || "shorter than its header".to_string();
    let size = u64_at(16).ok_or_else(short)?;
    let crc = u32::from_le_bytes(body.get(24..28).and_then(|b| b.try_into().ok()).ok_or_else(short)?);
    let clen = u32::from_le_bytes(body.get(28..32).and_then(|b| b.try_into().ok()).ok_or_else(short)?) as usize;
    let compression = body.get(32..32 + clen).ok_or_else(short)?;
    let rlen = u64_at(32 + clen).ok_or_else(short)?;
    let start = 32 + clen + 8;
    let records = usize::try_from(rlen)
        .ok()
        .and_then(|n| body.get(start..start.checked_add(n)?))
        .ok_or_else(|| format!("records of {rlen} bytes overrun the chunk"))?;
    if size > RECORD_LENGTH_LIMIT as u64 {
        return Err(format!(
            "{size} bytes uncompressed, more than navsync reads in one chunk"
        ));
    }
    match compression {
        b"" => plain.extend_from_slice(records),
        b"zstd" => {
            plain.reserve(size as usize);
            let n = zstd::bulk::Decompressor::new()
                .and_then(|mut d| d.decompress_to_buffer(records, plain))
                .map_err(|e| format!("zstd: {e}"))?;
            plain.truncate(n);
        }
        b"lz4" => {
            let mut d = lz4::Decoder::new(records).map_err(|e| format!("lz4: {e}"))?;
            std::io::Read::read_to_end(&mut std::io::Read::take(&mut d, size + 1), plain)
                .map_err(|e| format!("lz4: {e}"))?;
        }
        other => {
            return Err(format!(
                "compression `{}` is not supported",
                String::from_utf8_lossy(other)
            ));
        }
    }
    if plain.len() as u64 != size {
        return Err(format!("{} bytes uncompressed, the chunk says {size}", plain.len()));
    }
    if crc != 0 && crc32fast::hash(plain) != crc {
        return Err("the records do not match the chunk's CRC".into());
    }
    let mut pos = 0usize;
    while pos < plain.len() {
        let head = plain.get(pos..pos + 9).ok_or("a record header overruns the chunk")?;
        let n = u64::from_le_bytes(head[1..9].try_into().map_err(|_| "record header")?);
        let end = usize::try_from(n)
            .ok()
            .and_then(|n| (pos + 9).checked_add(n))
            .filter(|e| *e <= plain.len())
            .ok_or_else(|| format!("a record of {n} bytes overruns the chunk"))?;
        out.push_back((head[0], pos + 9..end));
        pos = end;
    }
    Ok(())
}

/// Whether every length-prefixed field of a record lies inside it. The `mcap` crate's parser
/// (binrw) allocates a string's declared length before reading it, so a corrupt length would
/// ask for gigabytes; records are checked here first (MCAP spec, "Records": the field layouts).
fn fields_fit(op: u8, body: &[u8]) -> bool {
    use mcap::records::op;
    struct Cur<'a> {
        b: &'a [u8],
        p: usize,
    }
    impl Cur<'_> {
        fn skip(&mut self, n: usize) -> bool {
            self.p = self.p.saturating_add(n);
            self.p <= self.b.len()
        }
        fn len32(&mut self) -> Option<usize> {
            let v = self.b.get(self.p..self.p.checked_add(4)?)?;
            self.p += 4;
            Some(u32::from_le_bytes(v.try_into().ok()?) as usize)
        }
        /// A u32-length-prefixed field (string, bytes, map) of at most `end`.
        fn prefixed(&mut self, end: usize) -> Option<(usize, usize)> {
            let n = self.len32()?;
            let start = self.p;
            let stop = start.checked_add(n).filter(|e| *e <= end)?;
            self.p = stop;
            Some((start, stop))
        }
        fn string(&mut self) -> bool {
            self.prefixed(self.b.len()).is_some()
        }
        fn str_map(&mut self) -> bool {
            let Some((start, stop)) = self.prefixed(self.b.len()) else {
                return false;
            };
            let mut inner = Cur {
                b: &self.b[..stop],
                p: start,
            };
            while inner.p < stop {
                if inner.prefixed(stop).is_none() || inner.prefixed(stop).is_none() {
                    return false;
                }
            }
            true
        }
    }
    let mut c = Cur { b: body, p: 0 };
    match op {
        op::HEADER => c.string() && c.string(),
        op::SCHEMA => c.skip(2) && c.string() && c.string() && c.string(),
        op::CHANNEL => c.skip(4) && c.string() && c.string() && c.str_map(),
        op::MESSAGE => body.len() >= 2 + 4 + 8 + 8,
        op::STATISTICS => c.skip(8 + 2 + 4 * 4 + 8 + 8) && c.string(),
        op::CHUNK_INDEX => c.skip(8 * 4) && c.string() && c.skip(8) && c.string() && c.skip(16),
        op::FOOTER => body.len() >= 20,
        op::CHUNK => {
            c.skip(8 * 3 + 4) && c.string() && {
                let n = body
                    .get(c.p..c.p + 8)
                    .and_then(|b| b.try_into().ok())
                    .map(u64::from_le_bytes);
                n.is_some_and(|n| n <= (body.len() - c.p - 8) as u64)
            }
        }
        op::DATA_END => body.len() >= 4,
        _ => true,
    }
}

/// What [`McapReader::next_record`] found.
enum Step {
    Header(Header),
    Message(mcap::records::MessageHeader),
}

#[cfg(test)]
mod field_tests {
    use super::fields_fit;
    use mcap::records::op;

    #[test]
    fn declared_lengths_beyond_the_record_are_caught() {
        // Header: two strings.
        let mut h = 4u32.to_le_bytes().to_vec();
        h.extend_from_slice(b"ros2");
        h.extend_from_slice(&0u32.to_le_bytes());
        assert!(fields_fit(op::HEADER, &h));
        h[0..4].copy_from_slice(&0xFFFF_FFFFu32.to_le_bytes());
        assert!(!fields_fit(op::HEADER, &h));
        // Chunk: 28 bytes, the compression string, the records' u64 length (found by the
        // fuzzer in a summary section: a 4 GiB compression name).
        let mut c = vec![0u8; 28];
        c.extend_from_slice(&4u32.to_le_bytes());
        c.extend_from_slice(b"zstd");
        c.extend_from_slice(&3u64.to_le_bytes());
        c.extend_from_slice(&[1, 2, 3]);
        assert!(fields_fit(op::CHUNK, &c));
        let mut long = c.clone();
        long[28..32].copy_from_slice(&0xFFFF_FFFFu32.to_le_bytes());
        assert!(!fields_fit(op::CHUNK, &long));
        let mut overrun = c.clone();
        overrun[36..44].copy_from_slice(&4u64.to_le_bytes());
        assert!(!fields_fit(op::CHUNK, &overrun));
    }
}
