//! `navsync imu --source iio:DEVICE`: the process shell around an IIO buffered device.
//!
//! set up through sysfs ([`iio_device::configure`]) → read whole records from the character
//! device (poll, non-blocking read, partial records carried over) → decode
//! ([`RecordDecoder`], pure) → axis map → checks and publish ([`SampleOutput`]).
//!
//! Stamps: the kernel's per-record `timestamp` channel (`current_timestamp_clock` =
//! `monotonic`, so it is `CLOCK_MONOTONIC`; taken by the driver at the data-ready interrupt or
//! FIFO read) as `StampSource::KernelEvent`. Without a timestamp channel the read time is
//! used (`Receipt`, later records of one read back-dated by the nominal period). A record
//! whose stamp lies after the read that returned it, or more than a minute before, is corrupt
//! and dropped (`iio_bad_stamps`).
//! Sequence numbers come from the stamps: a step of n nominal periods means n − 1 lost
//! records (IIO has no sample counter; the kernel drops the oldest records when the buffer
//! overflows).
//!
//! A vanished device (read error, end of file, node or sysfs directory gone) is reopened
//! with exponential backoff (0.1 s → 5 s); the setup is redone each time.

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

use super::axes::AxisMap;
use super::iio_device::{self, IioDevice, IioSetup};
use super::output::{Extras, SampleOutput};
use super::sample_checks::{Candidate, Sequence};

/// Records read per `read()` at most.
const RECORDS_PER_READ: usize = 64;
/// Largest record accepted (the kernel's records are far smaller).
const MAX_RECORD: usize = 256;
/// How far a kernel stamp may lie after the read that returned it (clock granularity), ns.
const STAMP_FUTURE_NS: i64 = 1_000_000;
/// How old a kernel stamp may be when read (a full buffer at a low rate), ns.
const STAMP_MAX_AGE_NS: i64 = 60_000_000_000;

/// Settings of the IIO driver.
#[derive(Debug, Clone)]
pub struct IioArgs {
    /// Device: `iio:deviceN`, `N` or its name.
    pub device: String,
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
}

impl Counters {
    fn named(&self) -> [(&'static str, u64); 6] {
        [
            ("device_opens", self.opens),
            ("device_open_failures", self.open_failures),
            ("device_reopens", self.reopens),
            ("iio_records", self.records),
            ("iio_short_reads", self.short_reads),
            ("iio_bad_stamps", self.bad_stamps),
        ]
    }
}

/// Runs the driver until SIGINT/SIGTERM.
pub fn run(node: &IpcNode, args: &IioArgs, out: &mut SampleOutput) {
    let mut c = Counters::default();
    let mut backoff = Duration::from_millis(100);
    let mut last_error = String::new();
    let mut configured: Option<PathBuf> = None;
    while !node.termination_requested() {
        let dev = iio_device::resolve(&args.sysfs_root, &args.device)
            .and_then(|dir| iio_device::configure(&dir, &args.dev_root, &args.setup))
            .and_then(|d| match open(&d) {
                Ok(f) => Ok((d, f)),
                Err(e) => {
                    // Set up but not readable: do not leave it capturing into a full buffer.
                    iio_device::disable(&d.dir);
                    Err(e)
                }
            });
        let (dev, file) = match dev {
            Ok(x) => x,
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
        info!(
            device = %dev.dir.display(),
            name = %dev.name,
            rate_hz = dev.sampling_hz.unwrap_or(f64::NAN),
            record_bytes = dev.decoder.record_bytes(),
            timestamps = dev.decoder.has_timestamp(),
            "capturing"
        );
        if !dev.decoder.has_timestamp() {
            warn!("the device has no timestamp channel: samples are stamped when read (ms-level)");
        }
        out.set_nominal_dt_s(dev.sampling_hz.map(|f| 1.0 / f));
        configured = Some(dev.dir.clone());
        let got_data = capture(node, &dev, file, args, out, &mut c);
        iio_device::disable(&dev.dir);
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
    if let Some(dir) = configured {
        iio_device::disable(&dir);
    }
    out.tick(c.named());
}

fn open(dev: &IioDevice) -> Result<File, iio_device::IioError> {
    std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK | libc::O_CLOEXEC)
        .open(&dev.dev_node)
        .map_err(|source| iio_device::IioError::Io {
            path: dev.dev_node.clone(),
            source,
        })
}

/// Waits up to `timeout` for the descriptor to become readable (or hung up).
fn wait_readable(file: &File, timeout: Duration) -> bool {
    let mut pfd = libc::pollfd {
        fd: file.as_raw_fd(),
        events: libc::POLLIN,
        revents: 0,
    };
    // SAFETY: one valid pollfd for the duration of the call.
    let n = unsafe { libc::poll(&mut pfd, 1, timeout.as_millis() as libc::c_int) };
    n > 0 && pfd.revents != 0
}

/// Reads and publishes until the device goes away or termination is requested; returns
/// whether any record arrived.
fn capture(
    node: &IpcNode,
    dev: &IioDevice,
    mut file: File,
    args: &IioArgs,
    out: &mut SampleOutput,
    c: &mut Counters,
) -> bool {
    let rec = dev.decoder.record_bytes();
    if rec == 0 || rec > MAX_RECORD {
        warn!(record_bytes = rec, "unusable record size");
        return false;
    }
    let period_ns = dev.sampling_hz.map(|f| (1e9 / f).round() as i64).filter(|p| *p > 0);
    let sequence = period_ns.map_or(Sequence::Consecutive, |period_ns| Sequence::Period { period_ns });
    let mut buf = [0u8; RECORDS_PER_READ * MAX_RECORD];
    let cap = RECORDS_PER_READ * rec;
    let mut have = 0usize;
    let mut got = false;
    loop {
        if node.termination_requested() {
            return got;
        }
        out.tick(c.named());
        if !wait_readable(&file, Duration::from_millis(100)) {
            continue;
        }
        let n = match file.read(&mut buf[have..cap]) {
            Ok(0) => {
                info!("end of data from {}: the device went away", dev.dev_node.display());
                return got;
            }
            Ok(n) => n,
            Err(e) if e.kind() == ErrorKind::WouldBlock || e.kind() == ErrorKind::Interrupted => continue,
            Err(e) => {
                warn!("reading {}: {e}; reopening", dev.dev_node.display());
                return got;
            }
        };
        let read_ns = monotonic_now_ns();
        got = true;
        have += n;
        let whole = have / rec;
        if !have.is_multiple_of(rec) {
            c.short_reads += 1;
        }
        for k in 0..whole {
            let r = dev.decoder.decode(&buf[k * rec..(k + 1) * rec]);
            c.records += 1;
            let (host_ns, source) = match r.timestamp_ns {
                // A kernel stamp is taken before the read returns, and a record does not wait
                // in the buffer for minutes: anything else is a corrupt record.
                Some(t)
                    if t > read_ns.saturating_add(STAMP_FUTURE_NS) || t < read_ns.saturating_sub(STAMP_MAX_AGE_NS) =>
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
            let candidate = Candidate {
                host_ns,
                device: None,
                sequence,
                gyro_rps: args.axes.apply(r.gyro_rps),
                accel_mps2: args.axes.apply(r.accel_mps2),
            };
            let _ = out.offer(
                &candidate,
                &Extras {
                    source,
                    temperature_c: r.temperature_c,
                    saturated: r.at_full_scale,
                    dt_s: None,
                },
            );
        }
        buf.copy_within(whole * rec..have, 0);
        have -= whole * rec;
    }
}
