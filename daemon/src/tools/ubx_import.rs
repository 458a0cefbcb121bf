//! `navsync import ubx LOG.ubx --imu IMU.txt --out REC.mcap [--tag LOG.ubx.tag]`: a u-blox
//! receiver's own log (as RTKLIB's `str2str`/`rtknavi` write it) and an IMU file in KF-GINS's
//! format (`navsync import kf-gins`'s, GPS seconds of week) as one recording that
//! `navsync replay --estimate` processes.
//!
//! The log goes through the live driver's decoder (`navsync_drivers::gnss::Decoder`, UBX,
//! `GnssDecoder::push_extras`, as `navsync decode` reads a capture): its fixes on
//! `navsync/gnss/{id}/fix`, raw epochs (RXM-RAWX) on `…/raw`, navigation data (RXM-SFRBX) on
//! `…/nav-data`, satellites on `…/sky`, time pulses (TIM-TP) on `…/timepulse`, time marks
//! (TIM-TM2) on `…/event`, HNR-PVT on `…/hnr` (the receiver's own IMU readings, ESF-MEAS, are
//! counted and left out).
//!
//! # One host time axis
//!
//! Host time is GPS time shifted (`navsync.time_axis` on the IMU's channel), the same
//! synthetic axis as `import kf-gins` ([`HOST_BASE_NS`](super::kf_gins::HOST_BASE_NS) at the
//! earliest sample); the IMU rows at their GPS time (each increment over the interval ending
//! at its tag).
//!
//! * Without `--tag`, each output of the receiver is received [`OUTPUT_LATENCY_S`] (or
//!   `--gnss-latency`) after its epoch: a fix, HNR fix, raw epoch or sky after its own GPS
//!   time; navigation data, time pulses and time marks after the latest epoch before them in
//!   the log.
//! * With `--tag`, each message is stamped as the live driver stamps it (the time of its first
//!   byte) with the logging PC's time of the chunk that holds that byte, and published at the
//!   time of the chunk that completes it; the PC's time (RTKLIB writes GPS time read from the
//!   PC's clock, see [`TimeTags`]) is taken as GPS time, as an IMU file tagged by the same PC is.
//!
//! PPS edges on every whole GPS second of the span (as `import kf-gins`), so the estimator
//! maps host time to GNSS time (hardware sync); `--no-pps` leaves them out (software sync: the
//! estimator finds the receipt delay itself).

use std::path::{Path, PathBuf};

use navsync_drivers::gnss::{Decoder, GnssDecoder, GnssExtra, Protocol};
use navsync_recording::RecordingError;
use navsync_shared::reflect::fixed_str;
use navsync_shared::samples::AnySample;
use navsync_shared::services;
use navsync_shared::time::{NS_PER_S, gps_ns_from_utc_ns};

use super::kf_gins::{self, HOST_BASE_NS, Item, KfGinsError, Rows, Stream, Timeline, WEEK_NS};

/// Without a time-tag file: how long after its epoch the receiver's output of that epoch is
/// taken as received, s (a u-blox receiver's NAV-PVT at 4 Hz over USB leaves 20–60 ms after
/// its epoch; the figure only orders the samples: with PPS the estimator fuses each fix at its
/// own GPS time).
pub const OUTPUT_LATENCY_S: f64 = 0.05;

/// GPS time at the Unix epoch's 1980-01-06 as seconds since 1970 (what RTKLIB's `gtime_t`
/// holds for GPS time: its `time` counts seconds of the GPS time scale since 1970-01-01).
const GPS_EPOCH_UNIX_S: i64 = 315_964_800;

/// `navsync import ubx`.
#[derive(Debug, Clone, clap::Args)]
pub struct UbxArgs {
    /// The receiver's log: UBX (NMEA and RTCM3 on the same port are skipped).
    pub log: PathBuf,
    /// IMU file in KF-GINS's format: GPS seconds of week, 3 angle increments (rad), 3 velocity
    /// increments (m/s), body forward-right-down.
    #[arg(long)]
    pub imu: PathBuf,
    /// The output recording (MCAP).
    #[arg(short, long)]
    pub out: PathBuf,
    /// RTKLIB's time-tag file of the log (`LOG.ubx.tag`, written by `str2str`/`rtknavi` with
    /// `::T`): each message at the logging PC's time of the chunk it arrived in.
    #[arg(long)]
    pub tag: Option<PathBuf>,
    /// GPS week of the IMU file's seconds of week (default: the log's first epoch's, or the
    /// tag file's start).
    #[arg(long)]
    pub week: Option<i64>,
    /// Without --tag: how long after its epoch each output of the receiver is received, s.
    #[arg(long, conflicts_with = "tag", default_value_t = OUTPUT_LATENCY_S)]
    pub gnss_latency: f64,
    /// IMU rate, Hz (default: from the median spacing of the time tags).
    #[arg(long = "imu-rate")]
    pub imu_rate_hz: Option<f64>,
    /// No PPS edges: the estimator finds the receipt delay of the fixes itself (software sync).
    #[arg(long)]
    pub no_pps: bool,
    /// Receiver id in the recording (`navsync/gnss/ID/…`).
    #[arg(long, default_value = "0", value_parser = crate::config::estimator::parse_id)]
    pub gnss_id: String,
    /// IMU id in the recording (`navsync/imu/ID/sample`).
    #[arg(long, default_value = "0", value_parser = crate::config::estimator::parse_id)]
    pub imu_id: String,
    /// Replace an existing recording at --out (never one of the inputs).
    #[arg(long)]
    pub force: bool,
}

/// Errors of the UBX import.
#[derive(Debug, thiserror::Error)]
pub enum UbxImportError {
    /// A file could not be read (the cause follows in the error's chain).
    #[error("reading {path}")]
    Io {
        /// File.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
    /// A time-tag file that is not RTKLIB's, or whose records go back.
    #[error(transparent)]
    Tag(#[from] TagError),
    /// The log has no epoch with a GPS time (nothing to put on the axis).
    #[error("{0}: no UBX epoch with a GPS time (NAV-PVT, RXM-RAWX …) in the log")]
    NoEpoch(String),
    /// The IMU file (file:line) or the recording.
    #[error(transparent)]
    KfGins(#[from] KfGinsError),
    /// Writing the recording.
    #[error(transparent)]
    Recording(#[from] RecordingError),
}

/// A time-tag file that cannot be read as RTKLIB's.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{file}: byte {offset}: {problem}")]
pub struct TagError {
    /// File.
    pub file: String,
    /// Byte offset in the file of the field (or record) that is wrong.
    pub offset: usize,
    /// What is wrong.
    pub problem: String,
}

/// RTKLIB's time-tag file (`stream.c`, `openfile_`/`writefile`: the `::T` option of a file
/// stream; `str2str -out file://LOG.ubx::T` writes `LOG.ubx.tag` beside the log). Binary,
/// little-endian (the logging PC's byte order; x86 and ARM both little-endian):
///
/// | offset | size | field |
/// |---|---|---|
/// | 0 | 60 | text `TIMETAG RTKLIB <version>`, NUL-padded |
/// | 60 | 4 | u32: the PC's millisecond tick when the file was opened (`tickget()`) |
/// | 64 | 4 | u32: open time, whole seconds of **GPS time** since 1970-01-01 (`utc2gpst(timeget())`'s `time`) |
/// | 68 | 8 | f64: its fraction of a second |
/// | 76 | 8 or 12 each | one record per write: u32 ms since the open (tick − open tick), then the log's size after the write, u32 (default) or u64 (`::P=8`) |
///
/// Record *k* says the log's bytes from the previous record's size up to its own were written
/// (received by the PC) at open time + ms. The width of the size is not in the header: the one
/// whose records fit the file and never go back is taken (4 bytes first). A partial record at
/// the end (a log cut while writing) is ignored, as RTKLIB's player ignores it.
#[derive(Debug, Clone, PartialEq)]
pub struct TimeTags {
    /// The header's text (`TIMETAG RTKLIB demo5 …`).
    pub version: String,
    /// The open time, GPS ns since 1980-01-06.
    pub start_gps_ns: i64,
    /// The records: (ms since the open, log size after the write).
    pub records: Vec<(u32, u64)>,
    /// Bytes per record (8 or 12).
    pub record_len: usize,
}

impl TimeTags {
    /// Header length: text and tick (60 + 4), open time (4 + 8).
    pub const HEADER_LEN: usize = 76;

    /// Parses a time-tag file's bytes (`file` names it in errors).
    pub fn parse(file: &str, bytes: &[u8]) -> Result<Self, TagError> {
        let err = |offset: usize, problem: String| TagError {
            file: file.to_string(),
            offset,
            problem,
        };
        if bytes.len() < Self::HEADER_LEN || !bytes.starts_with(b"TIMETAG") {
            return Err(err(
                0,
                format!(
                    "not an RTKLIB time-tag file ({} bytes; it starts with `TIMETAG` and has a {}-byte header)",
                    bytes.len(),
                    Self::HEADER_LEN
                ),
            ));
        }
        let text = &bytes[..60];
        let version = String::from_utf8_lossy(&text[..text.iter().position(|&b| b == 0).unwrap_or(60)])
            .trim()
            .to_string();
        let secs = u32::from_le_bytes([bytes[64], bytes[65], bytes[66], bytes[67]]);
        let frac = f64::from_le_bytes(bytes[68..76].try_into().unwrap_or([0; 8]));
        if !(0.0..1.0).contains(&frac) {
            return Err(err(
                68,
                format!("fraction of the open time {frac} is not within [0, 1)"),
            ));
        }
        let start_gps_ns = (i64::from(secs) - GPS_EPOCH_UNIX_S) * NS_PER_S + (frac * 1e9).round() as i64;
        let body = &bytes[Self::HEADER_LEN..];
        let mut first_err = None;
        for record_len in [8usize, 12] {
            match Self::records(body, record_len) {
                Ok(records) => {
                    return Ok(Self {
                        version,
                        start_gps_ns,
                        records,
                        record_len,
                    });
                }
                Err((k, problem)) => {
                    first_err.get_or_insert_with(|| err(Self::HEADER_LEN + k * record_len, problem));
                }
            }
        }
        Err(first_err.unwrap_or_else(|| err(Self::HEADER_LEN, "no records".into())))
    }

    /// The records of a body of `record_len`-byte records; the index and problem of the first
    /// that goes back.
    fn records(body: &[u8], record_len: usize) -> Result<Vec<(u32, u64)>, (usize, String)> {
        let mut out: Vec<(u32, u64)> = Vec::with_capacity(body.len() / record_len);
        for (k, r) in body.chunks_exact(record_len).enumerate() {
            let ms = u32::from_le_bytes([r[0], r[1], r[2], r[3]]);
            let size = if record_len == 8 {
                u64::from(u32::from_le_bytes([r[4], r[5], r[6], r[7]]))
            } else {
                u64::from_le_bytes(r[4..12].try_into().unwrap_or([0; 8]))
            };
            if let Some(&(pms, psize)) = out.last()
                && (ms < pms || size < psize)
            {
                return Err((
                    k,
                    format!(
                        "record {k} ({ms} ms, {size} bytes) goes back from the one before ({pms} ms, {psize} bytes)"
                    ),
                ));
            }
            out.push((ms, size));
        }
        Ok(out)
    }

    /// GPS time of record `k`'s write, ns.
    pub fn gps_ns(&self, k: usize) -> i64 {
        self.start_gps_ns + self.records.get(k).map_or(0, |r| i64::from(r.0) * 1_000_000)
    }
}

/// What an import wrote.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct UbxStats {
    /// IMU samples.
    pub imu: u64,
    /// Fixes (NAV-PVT epochs).
    pub fixes: u64,
    /// Raw epochs (RXM-RAWX).
    pub raw: u64,
    /// Navigation data messages (RXM-SFRBX).
    pub nav_data: u64,
    /// Skies (NAV-SAT).
    pub sky: u64,
    /// Time pulses, time marks and HNR fixes.
    pub other: u64,
    /// The receiver's own IMU readings (ESF-MEAS), not imported.
    pub receiver_imu: u64,
    /// PPS edges.
    pub pps: u64,
    /// The GPS week of the IMU file.
    pub week: i64,
    /// Time-tag records used (0 without `--tag`).
    pub tag_records: u64,
    /// Bytes of the log after the last time tag (stamped at the last tag's time).
    pub untagged_bytes: u64,
    /// Fixes' receipt minus their epoch, s: smallest, median, largest.
    pub fix_latency_s: [f64; 3],
    /// Samples moved 1 µs after the one before on their channel (equal receipt times).
    pub nudged: u64,
    /// The decoder's error counters that grew (damaged frames skipped, …), by their
    /// health-report name, with what each means.
    pub decoder_errors: Vec<(&'static str, u64, &'static str)>,
}

/// Runs `navsync import ubx` and prints what it wrote.
pub fn main(args: &UbxArgs) -> anyhow::Result<()> {
    use anyhow::Context;
    let s = import(args).with_context(|| format!("importing into {}", args.out.display()))?;
    eprintln!(
        "{}: {} IMU samples, {} fixes, {} raw epochs, {} navigation data messages, {} skies, \
         {} time pulses/marks/HNR fixes, {} PPS edges (GPS week {}); {} receiver IMU readings left out",
        args.out.display(),
        s.imu,
        s.fixes,
        s.raw,
        s.nav_data,
        s.sky,
        s.other,
        s.pps,
        s.week,
        s.receiver_imu
    );
    let [lo, med, hi] = s.fix_latency_s;
    eprintln!(
        "  fixes received {lo:.3} / {med:.3} / {hi:.3} s after their epoch (min / median / max){}",
        if args.tag.is_some() {
            format!(
                "; {} time tags, {} bytes after the last",
                s.tag_records, s.untagged_bytes
            )
        } else {
            String::new()
        }
    );
    for (name, n, meaning) in &s.decoder_errors {
        eprintln!("  {}: {name} {n}: {meaning}", args.log.display());
    }
    anyhow::ensure!(s.imu > 0, "no IMU sample in {}", args.imu.display());
    Ok(())
}

fn read(path: &Path) -> Result<Vec<u8>, UbxImportError> {
    std::fs::read(path).map_err(|source| UbxImportError::Io {
        path: path.display().to_string(),
        source,
    })
}

/// A decoded output of the receiver: its channel, sample and receipt time (GPS ns).
struct Output {
    service: String,
    sample: AnySample,
    /// The GPS time of its own epoch, when it has one.
    epoch_gps_ns: Option<i64>,
    /// Stamp (receipt of the first byte) and delivery, GPS ns on the axis.
    stamp_gps_ns: i64,
    publish_gps_ns: i64,
}

/// The log decoded by the live driver's decoder; each output stamped (GPS ns) at the time the
/// decoder gave it (`read_gps_ns` of the chunk; without tags restamped later).
fn decode(log: &[u8], chunks: &[(usize, i64)], id: &str, stats: &mut UbxStats) -> Vec<Output> {
    let mut d = Decoder::new(Protocol::Ubx);
    let mut out = Vec::new();
    let mut start = 0usize;
    let fix_service = services::gnss_fix(id);
    for &(end, at) in chunks {
        let bytes = log.get(start..end.min(log.len())).unwrap_or(&[]);
        start = end.max(start);
        let mut put = |x: Option<(String, AnySample)>, stats: &mut UbxStats| {
            let Some((service, sample)) = x else {
                stats.receiver_imu += 1;
                return;
            };
            let (stamp, epoch) = match &sample {
                AnySample::GnssFix(f) => (f.stamp.host_ns, valid(f.gps_ns)),
                AnySample::Raw(r) => (
                    r.stamp.host_ns,
                    (r.week > 0).then(|| i64::from(r.week) * WEEK_NS + (r.rcv_tow_s * 1e9).round() as i64),
                ),
                AnySample::Sky(s) => (s.stamp.host_ns, valid(s.utc_ns).map(gps_ns_from_utc_ns)),
                AnySample::NavData(n) => (n.stamp.host_ns, None),
                AnySample::TimePulse(t) => (t.stamp.host_ns, None),
                AnySample::Event(e) => (e.stamp.host_ns, None),
                _ => (at, None),
            };
            out.push(Output {
                service,
                sample,
                epoch_gps_ns: epoch,
                stamp_gps_ns: stamp,
                publish_gps_ns: at,
            });
        };
        let mut extras = Vec::new();
        let mut fixes = Vec::new();
        d.push_extras(
            bytes,
            at,
            0,
            &mut |f| fixes.push((fix_service.clone(), AnySample::GnssFix(*f))),
            &mut |x| extras.push(sample_of(&x, id)),
        );
        // Extras and fixes keep their stream order closely enough: fixes are completed by the
        // frame that ends their epoch, after that epoch's other messages.
        for x in extras {
            put(x, stats);
        }
        for f in fixes {
            put(Some(f), stats);
        }
    }
    let at = chunks.last().map_or(0, |c| c.1);
    let mut fixes = Vec::new();
    let mut extras = Vec::new();
    d.flush_extras(&mut |f| fixes.push(AnySample::GnssFix(*f)), &mut |x| {
        extras.push(sample_of(&x, id))
    });
    for (service, sample) in extras.into_iter().flatten() {
        out.push(Output {
            service,
            sample,
            epoch_gps_ns: None,
            stamp_gps_ns: at,
            publish_gps_ns: at,
        });
    }
    d.each_counter(&mut |name, n| {
        if let Some(meaning) = Decoder::describe_counter(name).filter(|_| n > 0) {
            stats.decoder_errors.push((name, n, meaning));
        }
    });
    for f in fixes {
        let (stamp, epoch) = match &f {
            AnySample::GnssFix(x) => (x.stamp.host_ns, valid(x.gps_ns)),
            _ => (at, None),
        };
        out.push(Output {
            service: fix_service.clone(),
            sample: f,
            epoch_gps_ns: epoch,
            stamp_gps_ns: stamp,
            publish_gps_ns: at,
        });
    }
    out
}

fn valid(t: i64) -> Option<i64> {
    (t != i64::MIN).then_some(t)
}

/// A decoder's extra product as the driver publishes it: its service and sample (`None` for
/// the receiver's own IMU, which the import leaves out).
fn sample_of(x: &GnssExtra<'_>, id: &str) -> Option<(String, AnySample)> {
    Some(match x {
        GnssExtra::TimePulse(s) => (services::gnss_time_pulse(id), AnySample::TimePulse(**s)),
        GnssExtra::Event(s) => (services::gnss_event(id), AnySample::Event(**s)),
        GnssExtra::Raw(s) => (services::gnss_raw(id), AnySample::Raw(**s)),
        GnssExtra::NavData(s) => (services::gnss_nav_data(id), AnySample::NavData(**s)),
        GnssExtra::Hnr(s) => (services::gnss_hnr(id), AnySample::GnssFix(**s)),
        GnssExtra::Sky(s) => (services::gnss_sky(id), AnySample::Sky(**s)),
        GnssExtra::Imu(_) => return None,
    })
}

/// Without tags: each output at its own epoch (else the latest epoch before it in the log)
/// plus `latency_ns`; outputs before the first epoch at the first epoch.
fn stamp_at_epochs(outputs: &mut [Output], latency_ns: i64) -> Option<()> {
    let first = outputs.iter().find_map(|o| o.epoch_gps_ns)?;
    let mut latest = first;
    for o in outputs.iter_mut() {
        let epoch = o.epoch_gps_ns.unwrap_or(latest);
        latest = latest.max(epoch);
        o.stamp_gps_ns = epoch + latency_ns;
        o.publish_gps_ns = o.stamp_gps_ns;
    }
    Some(())
}

fn set_stamp(sample: &mut AnySample, host_ns: i64) {
    match sample {
        AnySample::GnssFix(s) => s.stamp.host_ns = host_ns,
        AnySample::Raw(s) => s.stamp.host_ns = host_ns,
        AnySample::NavData(s) => s.stamp.host_ns = host_ns,
        AnySample::Sky(s) => s.stamp.host_ns = host_ns,
        AnySample::TimePulse(s) => s.stamp.host_ns = host_ns,
        AnySample::Event(s) => s.stamp.host_ns = host_ns,
        _ => {}
    }
}

/// Runs `navsync import ubx`.
pub fn import(args: &UbxArgs) -> Result<UbxStats, UbxImportError> {
    let log_name = args.log.display().to_string();
    let log = read(&args.log)?;
    let mut stats = UbxStats::default();
    let tags = match &args.tag {
        Some(p) => Some(TimeTags::parse(&p.display().to_string(), &read(p)?)?),
        None => None,
    };
    // The log in chunks: as written (tags), else in reads of 4 KiB (times replaced below).
    let chunks: Vec<(usize, i64)> = match &tags {
        Some(t) => {
            stats.tag_records = t.records.len() as u64;
            let mut c: Vec<(usize, i64)> = (0..t.records.len())
                .map(|k| (usize::try_from(t.records[k].1).unwrap_or(usize::MAX), t.gps_ns(k)))
                .collect();
            let last = c.last().map_or((0, t.start_gps_ns), |x| *x);
            if last.0 < log.len() {
                stats.untagged_bytes = (log.len() - last.0) as u64;
                c.push((log.len(), last.1));
            }
            c
        }
        None => (1..=log.len().div_ceil(4096))
            .map(|k| ((k * 4096).min(log.len()), 0))
            .collect(),
    };
    let mut outputs = decode(&log, &chunks, &args.gnss_id, &mut stats);
    if tags.is_none() {
        stamp_at_epochs(&mut outputs, (args.gnss_latency * 1e9).round() as i64)
            .ok_or_else(|| UbxImportError::NoEpoch(log_name.clone()))?;
    }
    let first_epoch = outputs
        .iter()
        .find_map(|o| o.epoch_gps_ns)
        .or(tags.as_ref().map(|t| t.start_gps_ns))
        .ok_or_else(|| UbxImportError::NoEpoch(log_name.clone()))?;
    let week = args.week.unwrap_or(first_epoch.div_euclid(WEEK_NS));
    stats.week = week;

    // The IMU file's span and rate.
    let dt = match args.imu_rate_hz {
        Some(r) if r > 0.0 => 1.0 / r,
        _ => kf_gins::median_spacing(&args.imu)?,
    };
    let (mut first_imu, mut last_imu) = (f64::NAN, f64::NAN);
    for r in Rows::open(&args.imu, &[7, 8])? {
        let t = r?.1[0];
        if first_imu.is_nan() {
            first_imu = t;
        }
        last_imu = t;
    }
    if first_imu.is_nan() {
        return Err(KfGinsError::Format {
            path: args.imu.display().to_string(),
            line: 1,
            problem: "no IMU records".into(),
        }
        .into());
    }
    // The axis starts at the earliest sample: the IMU's first interval or the log's first output.
    let sow_of = |g: i64| (g - week * WEEK_NS) as f64 * 1e-9;
    let first_gnss = outputs
        .iter()
        .map(|o| o.stamp_gps_ns)
        .min()
        .map_or(f64::INFINITY, sow_of);
    let last_gnss = outputs
        .iter()
        .map(|o| o.publish_gps_ns)
        .max()
        .map_or(f64::NEG_INFINITY, sow_of);
    let sow0 = (first_imu - dt).min(first_gnss);
    let tl = Timeline { week, sow0 };
    let gps0 = tl.gps_ns(sow0);
    let host_of = |g: i64| HOST_BASE_NS + (g - gps0);

    // Per channel: stamps strictly increase (equal chunk times 1 µs apart), publish ≥ stamp.
    let mut last: std::collections::HashMap<String, i64> = Default::default();
    let mut latencies = Vec::new();
    let mut items: Vec<Item> = Vec::with_capacity(outputs.len());
    for mut o in outputs {
        let mut stamp = host_of(o.stamp_gps_ns);
        let prev = last.entry(o.service.clone()).or_insert(i64::MIN);
        if stamp <= *prev {
            stamp = *prev + 1_000;
            stats.nudged += 1;
        }
        *prev = stamp;
        set_stamp(&mut o.sample, stamp);
        match &o.sample {
            AnySample::GnssFix(_) if o.service.ends_with("/fix") => {
                stats.fixes += 1;
                if let Some(e) = o.epoch_gps_ns {
                    latencies.push((o.stamp_gps_ns - e) as f64 * 1e-9);
                }
            }
            AnySample::Raw(_) => stats.raw += 1,
            AnySample::NavData(_) => stats.nav_data += 1,
            AnySample::Sky(_) => stats.sky += 1,
            _ => stats.other += 1,
        }
        items.push(Item {
            publish_ns: host_of(o.publish_gps_ns).max(stamp),
            service: o.service,
            sample: o.sample,
        });
    }
    items.sort_by_key(|i| i.publish_ns);
    latencies.sort_by(f64::total_cmp);
    if let (Some(lo), Some(hi)) = (latencies.first(), latencies.last()) {
        stats.fix_latency_s = [*lo, latencies[latencies.len() / 2], *hi];
    }

    let imu_service = services::imu_sample(&args.imu_id);
    let first_edge = sow0.ceil() as i64;
    let last_edge = last_imu.max(last_gnss).floor() as i64;
    let edges = if args.no_pps { 0 } else { last_edge - first_edge + 1 };
    let imu_rows = Rows::open(&args.imu, &[7, 8])?;
    let mut streams: Vec<Stream> = vec![
        (Box::new(kf_gins::imu_items(
            imu_rows,
            tl,
            dt,
            imu_service.clone(),
            fixed_str::<8>(&args.imu_id),
        )) as Box<dyn Iterator<Item = _>>)
            .peekable(),
        (Box::new(kf_gins::pps_items(tl, first_edge, edges)) as Box<dyn Iterator<Item = _>>).peekable(),
        (Box::new(items.into_iter().map(Ok)) as Box<dyn Iterator<Item = _>>).peekable(),
    ];
    let inputs: Vec<&Path> = [Some(args.log.as_path()), Some(args.imu.as_path()), args.tag.as_deref()]
        .into_iter()
        .flatten()
        .collect();
    let (rec, _) = kf_gins::imported_recording(&args.out, &inputs, args.force, &imu_service, gps0)?;
    kf_gins::write_streams(rec, &mut streams, gps0, &mut |s| match s {
        AnySample::Imu(_) => stats.imu += 1,
        AnySample::PpsEdge(_) => stats.pps += 1,
        _ => {}
    })?;
    Ok(stats)
}

#[cfg(test)]
mod tests {
    use super::*;
    use navsync_shared::reflect::Reflect;
    use navsync_shared::samples::GnssNavData;

    fn header(secs: u32, frac: f64) -> Vec<u8> {
        let mut b = vec![0u8; 60];
        b[..19].copy_from_slice(b"TIMETAG RTKLIB demo");
        b.extend(12345u32.to_le_bytes());
        b.extend(secs.to_le_bytes());
        b.extend(frac.to_le_bytes());
        b
    }

    #[test]
    fn a_tag_file_gives_each_write_its_gps_time() {
        // 2025-08-28 17:30:39.657 GPST as RTKLIB's gtime_t: the walk's tag file's open time.
        let mut b = header(1_756_402_239, 0.657);
        for (ms, size) in [(112u32, 2048u32), (143, 2650), (391, 5300)] {
            b.extend(ms.to_le_bytes());
            b.extend(size.to_le_bytes());
        }
        b.extend([1, 2, 3]); // a partial record: ignored
        let t = TimeTags::parse("x.tag", &b).unwrap();
        assert_eq!(t.version, "TIMETAG RTKLIB demo");
        assert_eq!(t.record_len, 8);
        assert_eq!(t.records, vec![(112, 2048), (143, 2650), (391, 5300)]);
        // GPS week 2381, 408639.657 s of week.
        assert_eq!(t.start_gps_ns, 2381 * WEEK_NS + 408_639_657_000_000);
        assert_eq!(t.gps_ns(1), t.start_gps_ns + 143_000_000);
    }

    #[test]
    fn eight_byte_sizes_are_recognised_and_bad_files_are_errors_at_their_byte() {
        let mut b = header(1_756_402_239, 0.5);
        for (ms, size) in [(0u32, 10u64), (100, 5_000_000_000), (200, 5_000_000_100)] {
            b.extend(ms.to_le_bytes());
            b.extend(size.to_le_bytes());
        }
        let t = TimeTags::parse("x.tag", &b).unwrap();
        assert_eq!((t.record_len, t.records[2]), (12, (200, 5_000_000_100)));

        let e = TimeTags::parse("x.tag", b"TIMETAG short").unwrap_err();
        assert_eq!(e.offset, 0, "{e}");
        let e = TimeTags::parse("x.tag", &[0u8; 100]).unwrap_err();
        assert!(
            e.to_string().starts_with("x.tag: byte 0: not an RTKLIB time-tag file"),
            "{e}"
        );
        let e = TimeTags::parse("x.tag", &header(1, 1.5)).unwrap_err();
        assert_eq!(e.offset, 68, "{e}");
        // Records going back in both widths: the 4-byte reading's error, at its record.
        let mut b = header(1_756_402_239, 0.5);
        for (ms, size) in [(100u32, 200u32), (50, 300), (10, 5), (1, 1), (0, 0), (0, 0)] {
            b.extend(ms.to_le_bytes());
            b.extend(size.to_le_bytes());
        }
        let e = TimeTags::parse("x.tag", &b).unwrap_err();
        assert_eq!(e.offset, TimeTags::HEADER_LEN + 8, "{e}");
        assert!(e.problem.contains("goes back"), "{e}");
    }

    #[test]
    fn arbitrary_bytes_are_a_tag_file_or_an_error_never_a_panic() {
        let mut x = 0x2545_f491_4f6c_dd1du64;
        for len in 0..400usize {
            let mut b: Vec<u8> = (0..len)
                .map(|_| {
                    x ^= x << 13;
                    x ^= x >> 7;
                    x ^= x << 17;
                    x as u8
                })
                .collect();
            if len >= 7 {
                b[..7].copy_from_slice(b"TIMETAG");
            }
            if len >= TimeTags::HEADER_LEN && len % 2 == 0 {
                // A valid open time, so the records are read.
                b[68..76].copy_from_slice(&0.5f64.to_le_bytes());
            }
            if let Ok(t) = TimeTags::parse("x.tag", &b) {
                assert!(t.records.windows(2).all(|w| w[0].0 <= w[1].0 && w[0].1 <= w[1].1));
                let _ = t.gps_ns(t.records.len());
            }
        }
    }

    #[test]
    fn outputs_without_tags_are_received_after_their_epoch() {
        let o = |epoch: Option<i64>| Output {
            service: String::new(),
            sample: AnySample::NavData(GnssNavData::zeroed()),
            epoch_gps_ns: epoch,
            stamp_gps_ns: 0,
            publish_gps_ns: 0,
        };
        let mut v = vec![o(None), o(Some(1_000)), o(None), o(Some(2_000)), o(Some(1_500))];
        stamp_at_epochs(&mut v, 50).unwrap();
        let stamps: Vec<i64> = v.iter().map(|x| x.stamp_gps_ns).collect();
        assert_eq!(stamps, [1_050, 1_050, 1_050, 2_050, 1_550]);
        assert!(stamp_at_epochs(&mut [o(None)], 50).is_none());
    }
}
