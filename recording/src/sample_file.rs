//! Recordings of navsync samples: [`SampleRecorder`] writes [`AnySample`]s by service name,
//! [`SampleReader`] gives them back with their times, both following the
//! [channel conventions](super::channels).

use std::collections::HashMap;
use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Seek, Write};
use std::path::{Path, PathBuf};

use super::channels::{self, Encoding, LIBRARY, META_LAYOUT, META_QOS, PROFILE, QOS_PROFILES};
use super::error::RecordingError;
use super::mcap_reader::{McapReader, ScanEnd, SummarySection};
use super::mcap_writer::{ChannelId, ChunkCompression, DEFAULT_CHUNK_SIZE, McapWriter, SchemaId};
use super::output::{OutputFile, Overwrite};
use super::ros_std::{RosFrames, RosStd, StdType};
use navsync_shared::samples::AnySample;
use navsync_shared::services::ServiceKind;

/// The standard-message converter, its channels by topic and its schemas by type.
type StdChannels = (RosStd, HashMap<String, ChannelId>, Vec<(StdType, SchemaId)>);

/// How a recording is written.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RecordingOptions {
    /// Message encoding (default CDR).
    pub encoding: Encoding,
    /// Chunk compression (default zstd).
    pub compression: ChunkCompression,
    /// Bytes of records at which a chunk is closed (default [`DEFAULT_CHUNK_SIZE`]).
    pub chunk_size: usize,
    /// Also write the standard ROS 2 messages ([`ros_std`](super::ros_std)) with these frame
    /// ids (CDR recordings only; default off).
    pub ros_std: Option<RosFrames>,
}

impl Default for RecordingOptions {
    fn default() -> Self {
        Self {
            encoding: Encoding::Cdr,
            compression: ChunkCompression::Zstd,
            chunk_size: DEFAULT_CHUNK_SIZE,
            ros_std: None,
        }
    }
}

/// Writes navsync samples into an MCAP file: one channel per service, one schema per type,
/// created when a service is first seen.
pub struct SampleRecorder<W: Write + Seek = BufWriter<File>> {
    mcap: McapWriter<W>,
    encoding: Encoding,
    path: PathBuf,
    schemas: [Option<SchemaId>; ServiceKind::ALL.len()],
    channels: HashMap<String, (ChannelId, ServiceKind)>,
    /// Key-value metadata for channels not created yet, by service.
    metadata: HashMap<String, Vec<(String, String)>>,
    buf: Vec<u8>,
    /// The standard-message converter and its channels by topic.
    ros_std: Option<StdChannels>,
}

impl SampleRecorder<BufWriter<OutputFile>> {
    /// A recording made by a command (an offline tool): written to a temporary file beside
    /// `target` and renamed over it by [`close`](Self::close), so that `target` is never opened
    /// for writing; refused if `target` is one of `rules.inputs` or an existing recording
    /// without `rules.force` ([`crate::output`]). Dropped without `close`, nothing changes.
    pub fn create(target: &Path, rules: &Overwrite<'_>, options: RecordingOptions) -> Result<Self, RecordingError> {
        let f = OutputFile::create(target, rules)?;
        Self::new(BufWriter::with_capacity(256 * 1024, f), target, options)
    }

    /// Closes the recording properly (summary, footer), syncs it and renames it into place.
    pub fn close(self) -> Result<(), RecordingError> {
        let path = self.path.clone();
        let w = self.finish()?;
        let f = w
            .into_inner()
            .map_err(|e| RecordingError::io(&path, "flushing", e.into_error()))?;
        f.commit()
    }
}

impl SampleRecorder<BufWriter<File>> {
    /// A live recording (`navsync record`): written at `path` itself, so it can be read while
    /// it grows and a `kill -9` loses at most the open chunk. Created exclusively: an existing
    /// file is refused, unless `force`, which removes it first (a reader that has it open
    /// keeps its data).
    pub fn create_live(path: &Path, force: bool, options: RecordingOptions) -> Result<Self, RecordingError> {
        if force && let Ok(m) = std::fs::symlink_metadata(path) {
            if !m.is_file() {
                return Err(RecordingError::Usage {
                    path: path.to_path_buf(),
                    problem: "exists and is not a regular file: refused as an output".into(),
                });
            }
            std::fs::remove_file(path).map_err(|e| RecordingError::io(path, "removing the old file", e))?;
        }
        let f = File::options()
            .write(true)
            .create_new(true)
            .open(path)
            .map_err(|e| match e.kind() {
                std::io::ErrorKind::AlreadyExists => RecordingError::Exists {
                    path: path.to_path_buf(),
                },
                _ => RecordingError::io(path, "creating", e),
            })?;
        Self::new(BufWriter::with_capacity(256 * 1024, f), path, options)
    }

    /// Closes the file properly (summary, footer) and syncs it to disk.
    pub fn close(self) -> Result<(), RecordingError> {
        let path = self.path.clone();
        let w = self.finish()?;
        let f = w
            .into_inner()
            .map_err(|e| RecordingError::io(&path, "flushing", e.into_error()))?;
        f.sync_all().map_err(|e| RecordingError::io(&path, "syncing", e))
    }
}

impl<W: Write + Seek> SampleRecorder<W> {
    /// A recorder writing to `out`; `path` names it in errors.
    pub fn new(out: W, path: &Path, options: RecordingOptions) -> Result<Self, RecordingError> {
        let profile = match options.encoding {
            Encoding::Cdr => PROFILE,
            Encoding::Json => "",
        };
        Ok(Self {
            mcap: McapWriter::new(out, path, profile, LIBRARY, options.chunk_size, options.compression)?,
            encoding: options.encoding,
            path: path.to_path_buf(),
            schemas: [None; ServiceKind::ALL.len()],
            channels: HashMap::new(),
            metadata: HashMap::new(),
            buf: Vec::with_capacity(4096),
            ros_std: match (options.ros_std, options.encoding) {
                (Some(frames), Encoding::Cdr) => Some((RosStd::new(frames), HashMap::new(), Vec::new())),
                (Some(_), Encoding::Json) => {
                    return Err(RecordingError::Usage {
                        path: path.to_path_buf(),
                        problem: "standard ROS 2 messages need the CDR encoding".into(),
                    });
                }
                (None, _) => None,
            },
        })
    }

    /// The message encoding.
    pub fn encoding(&self) -> Encoding {
        self.encoding
    }

    /// Adds `key` = `value` to the metadata of `service`'s channel (what the data were made
    /// with: see [`channels`](super::channels)); before the channel's first sample.
    pub fn set_channel_metadata(&mut self, service: &str, key: &str, value: &str) -> Result<(), RecordingError> {
        if self.channels.contains_key(service) {
            return Err(RecordingError::Usage {
                path: self.path.clone(),
                problem: format!("metadata `{key}` for `{service}` after its first sample"),
            });
        }
        self.metadata
            .entry(service.to_string())
            .or_default()
            .push((key.to_string(), value.to_string()));
        Ok(())
    }

    /// The channel of `service`, created (with its type's schema) on first use.
    pub fn channel(&mut self, service: &str) -> Result<ChannelId, RecordingError> {
        if let Some(&(id, _)) = self.channels.get(service) {
            return Ok(id);
        }
        let kind = ServiceKind::of(service).ok_or_else(|| RecordingError::Usage {
            path: self.path.clone(),
            problem: format!("`{service}` is not a navsync service"),
        })?;
        let slot = ServiceKind::ALL.iter().position(|k| *k == kind).unwrap_or(0);
        let schema = match self.schemas[slot] {
            Some(s) => s,
            None => {
                let s = self.mcap.add_schema(
                    &self.encoding.schema_name(kind),
                    self.encoding.schema_encoding(),
                    &self.encoding.schema_data(kind),
                )?;
                self.schemas[slot] = Some(s);
                s
            }
        };
        let metadata = self.metadata.remove(service).unwrap_or_default();
        let mut pairs: Vec<(&str, &str)> = metadata.iter().map(|(k, v)| (k.as_str(), v.as_str())).collect();
        let topic = match self.encoding {
            Encoding::Cdr => {
                pairs.push((META_QOS, QOS_PROFILES));
                pairs.push((META_LAYOUT, kind.type_name()));
                channels::topic_of(service)
            }
            Encoding::Json => service.to_string(),
        };
        let id = self
            .mcap
            .add_channel(schema, &topic, self.encoding.message_encoding(), &pairs)?;
        self.channels.insert(service.to_string(), (id, kind));
        Ok(id)
    }

    /// Writes `sample` on `service` with its log and publish times (ns; see the
    /// [module docs](super) for what each navsync writer puts there).
    pub fn write(
        &mut self,
        service: &str,
        sample: &AnySample,
        log_time: u64,
        publish_time: u64,
    ) -> Result<(), RecordingError> {
        let (id, kind) = match self.channels.get(service) {
            Some(&c) => c,
            None => {
                self.channel(service)?;
                self.channels[service]
            }
        };
        if kind != ServiceKind::of_sample(sample) {
            return Err(RecordingError::Usage {
                path: self.path.clone(),
                problem: format!(
                    "a {:?} sample on `{service}`, which carries {:?}",
                    ServiceKind::of_sample(sample),
                    kind
                ),
            });
        }
        self.encoding.encode(sample, &mut self.buf);
        self.mcap.write_message(id, log_time, publish_time, &self.buf)?;
        if let Some((conv, channels, schemas)) = &mut self.ros_std
            && let Some(m) = conv.convert(service, sample, log_time)
        {
            let id = match channels.get(&m.topic) {
                Some(&id) => id,
                None => {
                    let schema = match schemas.iter().find(|(t, _)| *t == m.ty) {
                        Some(&(_, s)) => s,
                        None => {
                            let s = self
                                .mcap
                                .add_schema(m.ty.name(), "ros2msg", m.ty.definition().as_bytes())?;
                            schemas.push((m.ty, s));
                            s
                        }
                    };
                    let mut meta: Vec<(&str, &str)> = vec![(META_QOS, QOS_PROFILES)];
                    meta.extend(m.metadata.iter().map(|(k, v)| (*k, v.as_str())));
                    let id = self.mcap.add_channel(schema, &m.topic, "cdr", &meta)?;
                    channels.insert(m.topic.clone(), id);
                    id
                }
            };
            self.mcap.write_message(id, log_time, publish_time, m.data)?;
        }
        Ok(())
    }

    /// Closes the open chunk and hands it to the operating system.
    pub fn flush_chunk(&mut self) -> Result<(), RecordingError> {
        self.mcap.flush_chunk()
    }

    /// Bytes written so far (including the open chunk).
    pub fn bytes_written(&self) -> u64 {
        self.mcap.bytes_written()
    }

    /// Messages written so far.
    pub fn message_count(&self) -> u64 {
        self.mcap.message_count()
    }

    /// Writes the summary and footer; returns the sink.
    pub fn finish(self) -> Result<W, RecordingError> {
        self.mcap.finish()
    }
}

/// One recorded sample.
#[derive(Debug, Clone, Copy)]
pub struct RecordedSample<'a> {
    /// The service (the channel's topic without the leading `/`).
    pub service: &'a str,
    /// The channel id in the file.
    pub channel_id: u16,
    /// The sample.
    pub sample: AnySample,
    /// MCAP log time, ns.
    pub log_time: u64,
    /// MCAP publish time, ns.
    pub publish_time: u64,
}

/// Reads the navsync samples of an MCAP file in file order. Channels that are not navsync
/// channels (another topic, encoding or layout version) are skipped and listed in
/// [`skipped_channels`](Self::skipped_channels).
pub struct SampleReader<R: Read + Seek = BufReader<File>> {
    mcap: McapReader<R>,
    path: PathBuf,
    /// Per channel id: its kind, or why it is skipped.
    kinds: Vec<Option<Result<channels::ChannelType, String>>>,
}

impl SampleReader<BufReader<File>> {
    /// Opens a recording.
    pub fn open(path: &Path) -> Result<Self, RecordingError> {
        Ok(Self::from_mcap(McapReader::open(path)?))
    }
}

impl<R: Read + Seek> SampleReader<R> {
    /// Reads samples through an open MCAP reader.
    pub fn from_mcap(mcap: McapReader<R>) -> Self {
        Self {
            path: mcap.path().to_path_buf(),
            mcap,
            kinds: Vec::new(),
        }
    }

    /// The MCAP reader (summary, position, how the scan ended).
    pub fn mcap(&self) -> &McapReader<R> {
        &self.mcap
    }

    /// The summary of a properly closed file.
    pub fn summary(&self) -> Option<&SummarySection> {
        self.mcap.summary()
    }

    /// How the scan ended, once [`next_sample`](Self::next_sample) returned `None`.
    pub fn scan_end(&self) -> Option<&ScanEnd> {
        self.mcap.scan_end()
    }

    /// The metadata of the channel of `service`, from the summary of a closed file (else from
    /// the channels read so far); empty when there is none.
    pub fn channel_metadata(&self, service: &str) -> Vec<(String, String)> {
        let from_summary = self
            .summary()
            .and_then(|s| s.channels.iter().find(|c| channels::service_of(&c.topic) == service))
            .map(|c| c.metadata.clone());
        from_summary
            .or_else(|| {
                (0..=u16::MAX)
                    .take(self.kinds.len())
                    .filter_map(|id| self.mcap.channel(id))
                    .find(|c| channels::service_of(&c.topic) == service)
                    .map(|c| c.metadata.clone())
            })
            .unwrap_or_default()
    }

    /// Damaged chunks skipped so far (their messages are not given out; the rest of the file
    /// is read): where, which time range, why.
    pub fn skipped_chunks(&self) -> &[super::mcap_reader::SkippedChunk] {
        self.mcap.skipped_chunks()
    }

    /// Channels skipped so far: (topic, reason).
    pub fn skipped_channels(&self) -> Vec<(String, String)> {
        self.kinds
            .iter()
            .enumerate()
            .filter_map(|(id, k)| match k {
                Some(Err(why)) => Some((
                    self.mcap
                        .channel(id as u16)
                        .map(|c| c.topic.clone())
                        .unwrap_or_default(),
                    why.clone(),
                )),
                _ => None,
            })
            .collect()
    }

    /// The next navsync sample, `None` at the end of the data.
    pub fn next_sample(&mut self) -> Result<Option<RecordedSample<'_>>, RecordingError> {
        let Some((channel_id, sample, log_time, publish_time)) = self.next_owned()? else {
            return Ok(None);
        };
        let service = self
            .mcap
            .channel(channel_id)
            .map(|c| channels::service_of(&c.topic))
            .unwrap_or("");
        Ok(Some(RecordedSample {
            service,
            channel_id,
            sample,
            log_time,
            publish_time,
        }))
    }

    fn next_owned(&mut self) -> Result<Option<(u16, AnySample, u64, u64)>, RecordingError> {
        loop {
            let Some(m) = self.mcap.next_message()? else {
                return Ok(None);
            };
            let id = usize::from(m.channel.id);
            if self.kinds.len() <= id {
                self.kinds.resize(id + 1, None);
            }
            let kind = match &self.kinds[id] {
                Some(Ok(k)) => *k,
                Some(Err(_)) => continue,
                None => {
                    let k = channels::channel_kind(m.channel, m.schema);
                    self.kinds[id] = Some(k.clone());
                    match k {
                        Ok(k) => k,
                        Err(_) => continue,
                    }
                }
            };
            let sample = channels::decode(kind, m.data).map_err(|problem| RecordingError::Decode {
                path: self.path.clone(),
                offset: m.offset,
                topic: m.channel.topic.clone(),
                problem,
            })?;
            return Ok(Some((m.channel.id, sample, m.log_time, m.publish_time)));
        }
    }
}
