//! `navsync imu --source iio:DEVICE[+DEVICE]`: the process shell around IIO buffered devices.
//!
//! set up through sysfs ([`device::configure`]) → read whole records from the character
//! devices (poll, non-blocking reads, partial records carried over) → decode
//! ([`RecordDecoder`](super::iio_record::RecordDecoder), pure) → for a split IMU, join gyroscope and accelerometer records by
//! stamp ([`Pairer`], pure) → axis map → checks and publish ([`SampleOutput`]).
//!
//! One device must carry both angular rate and acceleration (ADIS164xx, BMI160/270,
//! `inv_mpu6050`); a chip whose kernel driver registers two devices (`inv_icm42600`,
//! `st_lsm6dsx`, BMI088) is given as both, `iio:icm42600-gyro+icm42600-accel`, one with the
//! gyroscope and one with the accelerometer.
//!
//! Stamps: the kernel's per-record `timestamp` channel (`current_timestamp_clock` =
//! `monotonic`, so it is `CLOCK_MONOTONIC`; taken by the driver at the data-ready interrupt or
//! FIFO read) as `StampSource::KernelEvent`. Without a timestamp channel (single device only)
//! the read time is used (`Receipt`, later records of one read back-dated by the nominal
//! period). A record whose stamp lies after the read that returned it, or more than a minute
//! before, is corrupt and dropped (`iio_bad_stamps`).
//! Sequence numbers come from the stamps: a step of n nominal periods means n − 1 lost
//! records (IIO has no sample counter; the kernel drops the oldest records when the buffer
//! overflows).
//!
//! A vanished device (read error, end of file, node or sysfs directory gone) is reopened
//! with exponential backoff (0.1 s → 5 s); the setup is redone each time.

pub mod device;
pub mod pair;
pub mod record;
pub mod scan;

use std::fs::File;
use std::io::{ErrorKind, Read};
use std::os::fd::AsRawFd;
use std::os::unix::fs::OpenOptionsExt;
use std::path::PathBuf;
use std::time::Duration;

use navsync_shared::ipc::IpcNode;
use navsync_shared::samples::StampSource;
use navsync_shared::time::monotonic_now_ns;
use tracing::{info, warn};

use self::device::{IioDevice, IioError, IioSetup};
use self::pair::{Half, Pairer};
use self::record::IioSample;
use super::axes::AxisMap;
use super::output::{Extras, SampleOutput};
use super::sample_checks::{Candidate, Sequence};

/// Default IIO buffer length, records.
pub const BUFFER_LENGTH: u32 = 512;
/// Full-scale ranges of IIO devices when none is configured: none (their integer outputs cannot
/// exceed their range and are flagged at full scale instead).
pub const DEFAULT_RANGES: (f64, f64) = (f64::INFINITY, f64::INFINITY);

/// Records read per `read()` at most.
const RECORDS_PER_READ: usize = 64;
/// Largest record accepted (the kernel's records are far smaller).
const MAX_RECORD: usize = 256;
/// How far a kernel stamp may lie after the read that returned it (clock granularity), ns.
const STAMP_FUTURE_NS: i64 = 1_000_000;
/// How old a kernel stamp may be when read (a full buffer at a low rate), ns.
const STAMP_MAX_AGE_NS: i64 = 60_000_000_000;
/// Pairing tolerance when the sampling frequency is not known, ns.
const DEFAULT_PAIR_TOL_NS: i64 = 1_000_000;

/// Settings of the IIO driver.
#[derive(Debug, Clone)]
pub struct IioArgs {
    /// One device (`iio:deviceN`, `N` or its name), or two: the halves of a split IMU.
    pub devices: Vec<String>,
    /// sysfs directory of IIO devices.
    pub sysfs_root: PathBuf,
    /// Directory of the character devices.
    pub dev_root: PathBuf,
    /// Setup (rate, buffer length).
    pub setup: IioSetup,
    /// Device axes → published axes.
    pub axes: AxisMap,
}

/// Driver counters (besides the checks').
#[derive(Debug, Default, Clone, Copy)]
struct Counters {
    opens: u64,
    open_failures: u64,
    reopens: u64,
    records: u64,
    short_reads: u64,
    bad_stamps: u64,
    pairs: u64,
    unpaired: u64,
}

impl Counters {
    fn named(&self) -> [(&'static str, u64); 8] {
        [
            ("device_opens", self.opens),
            ("device_open_failures", self.open_failures),
            ("device_reopens", self.reopens),
            ("iio_records", self.records),
            ("iio_short_reads", self.short_reads),
            ("iio_bad_stamps", self.bad_stamps),
            ("iio_pairs", self.pairs),
            ("iio_unpaired", self.unpaired),
        ]
    }
}

/// One opened device and its read buffer.
struct Stream {
    dev: IioDevice,
    file: File,
    buf: Box<[u8; RECORDS_PER_READ * MAX_RECORD]>,
    have: usize,
}

/// Sets up and opens every device; on failure, what was set up is disabled again.
fn open_all(args: &IioArgs) -> Result<Vec<Stream>, IioError> {
    let mut streams: Vec<Stream> = Vec::with_capacity(args.devices.len());
    let result = (|| {
        for name in &args.devices {
            let dir = device::resolve(&args.sysfs_root, name)?;
            let dev = device::configure(&dir, &args.dev_root, &args.setup)?;
            let file = std::fs::OpenOptions::new()
                .read(true)
                .custom_flags(libc::O_NONBLOCK | libc::O_CLOEXEC)
                .open(&dev.dev_node);
            let file = match file {
                Ok(f) => f,
                Err(source) => {
                    // Set up but not readable: do not leave it capturing into a full buffer.
                    device::disable(&dev.dir);
                    return Err(IioError::Io {
                        path: dev.dev_node.clone(),
                        source,
                    });
                }
            };
            streams.push(Stream {
                dev,
                file,
                buf: Box::new([0; RECORDS_PER_READ * MAX_RECORD]),
                have: 0,
            });
        }
        check_roles(&streams)
    })();
    if let Err(e) = result {
        for s in &streams {
            device::disable(&s.dev.dir);
        }
        return Err(e);
    }
    Ok(streams)
}

/// One device with both triads, or two with one triad each, all with usable records.
fn check_roles(streams: &[Stream]) -> Result<(), IioError> {
    let bad = |what: String| {
        Err(IioError::Layout {
            dir: streams[0].dev.dir.clone(),
            what,
        })
    };
    for s in streams {
        let rec = s.dev.decoder.record_bytes();
        if rec == 0 || rec > MAX_RECORD {
            return bad(format!("{}: records of {rec} bytes", s.dev.dir.display()));
        }
    }
    match streams {
        [one] if one.dev.decoder.has_gyro() && one.dev.decoder.has_accel() => Ok(()),
        [one] => bad(format!(
            "{} has only {}; give its other half too (`iio:GYRO+ACCEL`)",
            one.dev.dir.display(),
            if one.dev.decoder.has_gyro() {
                "a gyroscope"
            } else {
                "an accelerometer"
            }
        )),
        [a, b] => {
            let (da, db) = (&a.dev.decoder, &b.dev.decoder);
            if !(da.has_timestamp() && db.has_timestamp()) {
                return bad("both halves of a split IMU need their timestamp channel".into());
            }
            if da.has_gyro() != db.has_gyro() && da.has_accel() != db.has_accel() && da.has_gyro() != da.has_accel() {
                Ok(())
            } else {
                bad("of two devices, one must have only the gyroscope and the other only the accelerometer".into())
            }
        }
        _ => bad(format!(
            "{} devices: expected one, or two halves of one IMU",
            streams.len()
        )),
    }
}

/// Runs the driver until SIGINT/SIGTERM.
pub fn run(node: &IpcNode, args: &IioArgs, out: &mut SampleOutput) {
    let mut c = Counters::default();
    let mut backoff = Duration::from_millis(100);
    let mut last_error = String::new();
    let mut configured: Vec<PathBuf> = Vec::new();
    while !node.termination_requested() {
        let mut streams = match open_all(args) {
            Ok(s) => s,
            Err(e) => {
                c.open_failures += 1;
                let msg = e.to_string();
                if msg != last_error {
                    warn!("cannot set up the device: {msg}; retrying with backoff");
                    last_error = msg;
                }
                out.tick(c.named());
                if !node.sleep(backoff) {
                    break;
                }
                backoff = (backoff * 2).min(Duration::from_secs(5));
                continue;
            }
        };
        c.opens += 1;
        if !last_error.is_empty() {
            info!("device is back");
        }
        last_error.clear();
        for s in &streams {
            info!(
                device = %s.dev.dir.display(),
                name = %s.dev.name,
                rate_hz = s.dev.sampling_hz.unwrap_or(f64::NAN),
                record_bytes = s.dev.decoder.record_bytes(),
                timestamps = s.dev.decoder.has_timestamp(),
                "capturing"
            );
            if !s.dev.decoder.has_timestamp() {
                warn!("the device has no timestamp channel: samples are stamped when read (ms-level)");
            }
        }
        let sampling_hz = streams.iter().find_map(|s| s.dev.sampling_hz);
        out.set_nominal_dt_s(sampling_hz.map(|f| 1.0 / f));
        configured = streams.iter().map(|s| s.dev.dir.clone()).collect();
        let got_data = capture(node, &mut streams, sampling_hz, args.axes, out, &mut c);
        for s in &streams {
            device::disable(&s.dev.dir);
        }
        if node.termination_requested() {
            break;
        }
        c.reopens += 1;
        if got_data {
            backoff = Duration::from_millis(100);
        }
        out.tick(c.named());
        if !node.sleep(backoff) {
            break;
        }
        backoff = (backoff * 2).min(Duration::from_secs(5));
    }
    for dir in &configured {
        device::disable(dir);
    }
    out.tick(c.named());
}

/// Waits up to `timeout` for any of the streams to become readable (or hang up); returns a
/// bit set of the ready ones.
fn wait_readable(streams: &[Stream], timeout: Duration) -> u32 {
    let mut pfds = [libc::pollfd {
        fd: -1,
        events: libc::POLLIN,
        revents: 0,
    }; 2];
    for (p, s) in pfds.iter_mut().zip(streams) {
        p.fd = s.file.as_raw_fd();
    }
    let n = streams.len().min(2);
    // SAFETY: `n` valid pollfds for the duration of the call.
    let rc = unsafe { libc::poll(pfds.as_mut_ptr(), n as libc::nfds_t, timeout.as_millis() as libc::c_int) };
    if rc <= 0 {
        return 0;
    }
    pfds[..n]
        .iter()
        .enumerate()
        .filter(|(_, p)| p.revents != 0)
        .fold(0, |m, (i, _)| m | 1 << i)
}

/// Reads and publishes until a device goes away or termination is requested; returns
/// whether any record arrived.
fn capture(
    node: &IpcNode,
    streams: &mut [Stream],
    sampling_hz: Option<f64>,
    axes: AxisMap,
    out: &mut SampleOutput,
    c: &mut Counters,
) -> bool {
    let period_ns = sampling_hz.map(|f| (1e9 / f).round() as i64).filter(|p| *p > 0);
    let sequence = period_ns.map_or(Sequence::Consecutive, |period_ns| Sequence::Period { period_ns });
    let mut pairer = Pairer::new(period_ns.map_or(DEFAULT_PAIR_TOL_NS, |p| p / 2));
    let mut got = false;
    let publish = |out: &mut SampleOutput, host_ns: i64, source, gyro, accel, temperature_c, saturated| {
        let candidate = Candidate {
            host_ns,
            device: None,
            sequence,
            gyro_rps: axes.apply(gyro),
            accel_mps2: axes.apply(accel),
        };
        let _ = out.offer(
            &candidate,
            &Extras {
                source,
                temperature_c,
                saturated,
                dt_s: None,
            },
        );
    };
    'capture: loop {
        if node.termination_requested() {
            break;
        }
        let pc = pairer.counters();
        c.pairs = pc.pairs;
        c.unpaired = pc.unpaired_gyro + pc.unpaired_accel;
        out.tick(c.named());
        let ready = wait_readable(streams, Duration::from_millis(100));
        for (i, s) in streams.iter_mut().enumerate() {
            if ready & (1 << i) == 0 {
                continue;
            }
            let rec = s.dev.decoder.record_bytes();
            let cap = RECORDS_PER_READ * rec;
            let n = match s.file.read(&mut s.buf[s.have..cap]) {
                Ok(0) => {
                    info!("end of data from {}: the device went away", s.dev.dev_node.display());
                    break 'capture;
                }
                Ok(n) => n,
                Err(e) if e.kind() == ErrorKind::WouldBlock || e.kind() == ErrorKind::Interrupted => continue,
                Err(e) => {
                    warn!("reading {}: {e}; reopening", s.dev.dev_node.display());
                    break 'capture;
                }
            };
            let read_ns = monotonic_now_ns();
            got = true;
            s.have += n;
            let whole = s.have / rec;
            if !s.have.is_multiple_of(rec) {
                c.short_reads += 1;
            }
            for k in 0..whole {
                let r: IioSample = s.dev.decoder.decode(&s.buf[k * rec..(k + 1) * rec]);
                c.records += 1;
                let (host_ns, source) = match r.timestamp_ns {
                    // A kernel stamp is taken before the read returns, and a record does not
                    // wait in the buffer for minutes: anything else is a corrupt record.
                    Some(t)
                        if t > read_ns.saturating_add(STAMP_FUTURE_NS)
                            || t < read_ns.saturating_sub(STAMP_MAX_AGE_NS) =>
                    {
                        c.bad_stamps += 1;
                        continue;
                    }
                    Some(t) => (t, StampSource::KernelEvent),
                    None => {
                        let back = (whole - 1 - k) as i64 * period_ns.unwrap_or(0);
                        (read_ns - back, StampSource::Receipt)
                    }
                };
                let half = |v| Half {
                    ts: host_ns,
                    v,
                    temperature_c: r.temperature_c,
                    at_full_scale: r.at_full_scale,
                };
                let pair = match (r.gyro_rps, r.accel_mps2) {
                    (Some(g), Some(a)) => {
                        publish(out, host_ns, source, g, a, r.temperature_c, r.at_full_scale);
                        None
                    }
                    (Some(g), None) => pairer.push_gyro(half(g)),
                    (None, Some(a)) => pairer.push_accel(half(a)),
                    (None, None) => None,
                };
                if let Some(p) = pair {
                    publish(out, p.ts, source, p.gyro, p.accel, p.temperature_c, p.at_full_scale);
                }
            }
            s.buf.copy_within(whole * rec..s.have, 0);
            s.have -= whole * rec;
        }
    }
    pairer.clear();
    let pc = pairer.counters();
    c.pairs = pc.pairs;
    c.unpaired = pc.unpaired_gyro + pc.unpaired_accel;
    got
}
