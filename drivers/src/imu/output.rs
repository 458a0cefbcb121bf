//! The common end of every IMU driver: check a decoded sample ([`SampleChecks`]), stamp it,
//! publish it on `navsync/imu/{id}/sample`, and keep the health report (counters, rates,
//! rate-limited logs). Nothing here allocates per sample.

use std::time::Instant;

use navsync_shared::health_reporter::{CounterId, HealthReporter, RateId};
use navsync_shared::ipc::{IpcNode, Publisher};
use navsync_shared::reflect::fixed_str;
use navsync_shared::samples::{IMU_FLAG_SATURATED, ImuSample, Stamp, StampSource};
use navsync_shared::services;
use tracing::warn;

use super::sample_checks::{Accepted, Candidate, CheckCounters, Limits, Rejection, SampleChecks};
use crate::rate_log::RateLimitedLog;

/// What a driver knows about a sample beyond what the checks look at.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Extras {
    /// How the candidate's `host_ns` was obtained.
    pub source: StampSource,
    /// Temperature, °C (NaN when not known).
    pub temperature_c: f64,
    /// The device flagged the sample as clipped (or a raw value sits at full scale).
    pub saturated: bool,
    /// Length of the sample's interval if the device says it (e.g. from its own clock), s.
    pub dt_s: Option<f64>,
}

/// Checks, stamps and publishes the samples of one IMU.
pub struct SampleOutput {
    publisher: Publisher<ImuSample>,
    health: HealthReporter,
    checks: SampleChecks,
    imu_id: [u8; 8],
    nominal_dt_s: Option<f64>,
    last_dt_s: Option<f64>,
    last_host_ns: Option<(i64, u64)>,
    /// The first sample waits here when nothing tells its interval yet.
    pending: Option<ImuSample>,
    r_out: RateId,
    c_publish_err: CounterId,
    log: RateLimitedLog,
    published: u64,
    /// A counter did not fit the health report (logged once).
    health_full_logged: bool,
}

impl SampleOutput {
    /// Publishes on `navsync/imu/{id}/sample` and reports health as `navsync/health/{process}`.
    pub fn new(
        node: &IpcNode,
        id: &str,
        process: &str,
        limits: Limits,
        nominal_dt_s: Option<f64>,
    ) -> Result<Self, super::ImuError> {
        let publisher = node.publisher::<ImuSample>(&services::imu_sample(id))?;
        let mut health = HealthReporter::new(node, process)?;
        let r_out = health.rate("samples_out")?;
        let c_publish_err = health.counter("publish_errors")?;
        Ok(Self {
            publisher,
            health,
            checks: SampleChecks::new(limits),
            imu_id: fixed_str(id),
            nominal_dt_s,
            last_dt_s: None,
            last_host_ns: None,
            pending: None,
            r_out,
            c_publish_err,
            log: RateLimitedLog::default(),
            published: 0,
            health_full_logged: false,
        })
    }

    /// The health reporter (to register a driver's own counters).
    pub fn health(&mut self) -> &mut HealthReporter {
        &mut self.health
    }

    /// The checks' counters.
    pub fn counters(&self) -> &CheckCounters {
        self.checks.counters()
    }

    /// Samples published so far.
    pub fn published(&self) -> u64 {
        self.published
    }

    /// Sets the nominal sample interval once the driver learns it (e.g. after reading the
    /// device's sampling frequency).
    pub fn set_nominal_dt_s(&mut self, dt_s: Option<f64>) {
        self.nominal_dt_s = dt_s.filter(|d| d.is_finite() && *d > 0.0 && *d < 1.0);
    }

    /// Checks `c` and publishes it; returns what the checks decided.
    pub fn offer(&mut self, c: &Candidate, x: &Extras) -> Result<Accepted, Rejection> {
        let a = self.checks.check(c)?;
        let host_interval_s = self
            .last_host_ns
            .map(|(t, seq)| (c.host_ns as f64 - t as f64) * 1e-9 / (a.seq.saturating_sub(seq).max(1)) as f64);
        self.last_host_ns = Some((c.host_ns, a.seq));
        let valid = |d: &f64| d.is_finite() && *d > 0.0 && *d < 1.0;
        let dt_s = x
            .dt_s
            .filter(valid)
            .or(a.device_interval_ns.map(|n| n as f64 * 1e-9).filter(valid))
            .or(self.nominal_dt_s)
            .or(self.last_dt_s)
            .or(host_interval_s.filter(valid));
        let stamp = match a.device_ns {
            Some(d) => Stamp::with_device(c.host_ns, d, a.seq, x.source),
            None => Stamp::host(c.host_ns, a.seq, x.source),
        };
        let mut sample = ImuSample {
            stamp,
            gyro_rps: c.gyro_rps,
            accel_mps2: c.accel_mps2,
            dt_s: dt_s.unwrap_or(f64::NAN),
            temperature_c: x.temperature_c,
            imu_id: self.imu_id,
            flags: if x.saturated || a.at_range {
                IMU_FLAG_SATURATED
            } else {
                0
            },
            reserved: 0,
        };
        let Some(dt_s) = dt_s else {
            // Only the very first sample can get here: keep it until the next one tells the
            // interval (a later resync keeps the last known interval).
            self.pending = Some(sample);
            return Ok(a);
        };
        self.last_dt_s = Some(dt_s);
        if let Some(mut first) = self.pending.take() {
            first.dt_s = dt_s;
            self.publish(&first);
        }
        sample.dt_s = dt_s;
        self.publish(&sample);
        Ok(a)
    }

    fn publish(&mut self, s: &ImuSample) {
        match self.publisher.publish(s) {
            Ok(()) => {
                self.published += 1;
                self.health.tick(self.r_out);
            }
            Err(e) => {
                self.health.add(self.c_publish_err, 1);
                warn!("publishing an IMU sample: {e}");
            }
        }
    }

    /// Copies the check counters and `extra` counters into the health report, logs the
    /// growing error counters (rate-limited per kind) and publishes the report when due.
    /// A counter that does not fit the report is logged, not dropped silently.
    pub fn tick(&mut self, extra: impl IntoIterator<Item = (&'static str, u64)>) {
        // Every source's loop (reads and reopen backoff) ticks: the systemd watchdog.
        navsync_shared::sd_notify::watchdog();
        let now = Instant::now();
        let counters = *self.checks.counters();
        for (name, v) in counters.named().into_iter().chain(extra) {
            if let Err(e) = self.health.set_named(name, v)
                && !self.health_full_logged
            {
                warn!("{e}");
                self.health_full_logged = true;
            }
            if let Some(what) = describe(name) {
                self.log.update(name, v, what, now);
            }
        }
        if let Err(e) = self.health.maybe_publish(navsync_shared::time::monotonic_now_ns()) {
            warn!("publishing health: {e}");
        }
    }

    /// Publishes the final health report (alive = 0).
    pub fn finish(&mut self) {
        let _ = self.health.publish_final();
    }
}

/// Human description of an error counter, `None` for counters that are not errors.
fn describe(name: &str) -> Option<&'static str> {
    Some(match name {
        "samples_dropped" => "samples lost (sequence gaps)",
        "rejected_not_finite" => "samples rejected: NaN or infinite values",
        "rejected_range" => "samples rejected: values beyond the sensor's range",
        "rejected_host_back" => "samples rejected: host time went backwards",
        "rejected_device_back" => "samples rejected: device time went backwards",
        "rejected_duplicate" => "samples rejected: repeated or backwards counter",
        "timeline_resyncs" => "device counter restarted; following the new timeline",
        "xbus_noise_bytes" => "bytes outside Xbus messages skipped (noise, wrong baud rate?)",
        "xbus_bad_checksum" => "Xbus messages with a bad checksum dropped",
        "xbus_bad_header" => "Xbus message starts with a bad bus id or length skipped",
        "xbus_truncated" => "partial Xbus messages dropped when the port closed",
        "mtdata2_bad_items" => "MTData2 messages with malformed items dropped",
        "mtdata2_no_inertial" => "MTData2 messages without rate of turn or acceleration ignored",
        "iio_short_reads" => "IIO reads that ended inside a record",
        "iio_bad_stamps" => "IIO records with a time stamp in the future or over a minute old dropped",
        _ => return None,
    })
}
