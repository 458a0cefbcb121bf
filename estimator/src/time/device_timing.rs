//! Sample times from each IMU's own clock: a [`DeviceClock`] per IMU fed with every sample's
//! (device time, host stamp) pair, the host clock as reference ([`DeviceClock::on_host_stamp`]).
//! Once converged, a sample's host time is its device time mapped to host time: the device's
//! sample-to-sample precision (µs) instead of the receipt stamp's scatter (ms over a serial
//! line or USB). Before that, and for samples without device time, the stamp is kept.
//!
//! A mapped time far from the stamp (beyond any transport delay: a device reset, a counter
//! jump) is not used; [`RESET_AFTER_OUTLIERS`] of those in a row start the clock afresh.

use navsync_shared::samples::{ImuSample, MAX_IMUS, StampSource};

use super::device_clock::{DeviceClock, DeviceClockConfig, DeviceUpdate};

/// Consecutive samples whose mapped time disagrees with the stamp after which the device
/// clock of that IMU is restarted.
pub const RESET_AFTER_OUTLIERS: u32 = 50;

/// Settings of the device timing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DeviceTimingConfig {
    /// Use the device clocks (default true).
    pub enabled: bool,
    /// 1-sigma of the least delayed host stamp of a window against the device event, ns
    /// (default 100 µs; a single receipt scatters by 0.3–0.6 ms through a pseudo-terminal, by
    /// several ms under load).
    pub host_stamp_sigma_ns: f64,
    /// Host stamps per window of the minimum-delay filter (default 40: 0.2 s at 200 Hz; see
    /// [`DeviceClockConfig::host_stamp_window`]).
    pub host_stamp_window: u32,
    /// Largest 1-sigma of the mapping (its offset's uncertainty, a slowly varying error, not
    /// the scatter) at which it replaces the stamp, ns (default 100 µs: a few seconds at
    /// 200 Hz; the receipt scatter it replaces is ~600 µs).
    pub max_sigma_ns: f64,
    /// Largest |mapped − stamp| accepted, ns (default 50 ms: longer than any transport delay).
    pub max_residual_ns: i64,
}

impl Default for DeviceTimingConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            host_stamp_sigma_ns: 100_000.0,
            host_stamp_window: 40,
            max_sigma_ns: 100_000.0,
            max_residual_ns: 50_000_000,
        }
    }
}

/// Counters of the device timing.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DeviceTimingCounters {
    /// Samples whose time came from their device clock.
    pub mapped: u64,
    /// Samples with device time, kept at their stamp (clock not converged yet).
    pub converging: u64,
    /// Samples whose mapped time disagreed with the stamp by more than the limit.
    pub outliers: u64,
    /// Device clocks restarted after [`RESET_AFTER_OUTLIERS`] outliers in a row.
    pub resets: u64,
}

/// One device clock per IMU slot.
#[derive(Debug, Clone)]
pub struct DeviceTiming {
    cfg: DeviceTimingConfig,
    clocks: [Option<DeviceClock>; MAX_IMUS],
    outliers_in_a_row: [u32; MAX_IMUS],
    counters: DeviceTimingCounters,
}

impl DeviceTiming {
    /// Device timing with no clock known yet.
    pub fn new(cfg: DeviceTimingConfig) -> Self {
        Self {
            cfg,
            clocks: std::array::from_fn(|_| None),
            outliers_in_a_row: [0; MAX_IMUS],
            counters: DeviceTimingCounters::default(),
        }
    }

    /// Counters so far.
    pub fn counters(&self) -> &DeviceTimingCounters {
        &self.counters
    }

    fn clock_config(&self) -> DeviceClockConfig {
        // `device_ns` is already in ns (the driver converted its ticks), unwrapped to 63 bits.
        let mut c = DeviceClockConfig::crystal(1.0, 64);
        c.host_stamp_sigma_ns = self.cfg.host_stamp_sigma_ns;
        c.host_stamp_window = self.cfg.host_stamp_window;
        c
    }

    /// The sample of IMU slot `index` with its host time from its device clock when that has
    /// converged (stamp source [`StampSource::DeviceCounter`]), else unchanged.
    pub fn retime(&mut self, index: usize, s: &ImuSample) -> ImuSample {
        let mut out = *s;
        if !self.cfg.enabled || s.stamp.has_device_time == 0 || index >= MAX_IMUS || s.stamp.device_ns < 0 {
            return out;
        }
        let cfg = self.clock_config();
        let clock = self.clocks[index].get_or_insert_with(|| DeviceClock::new(cfg));
        let raw = s.stamp.device_ns as u64;
        let update = clock.on_host_stamp(raw, s.stamp.host_ns);
        let Some(t) = clock.map(raw) else {
            self.counters.converging += 1;
            return out;
        };
        if (t.time_ns - s.stamp.host_ns).abs() > self.cfg.max_residual_ns || matches!(update, DeviceUpdate::Ignored) {
            self.counters.outliers += 1;
            self.outliers_in_a_row[index] += 1;
            if self.outliers_in_a_row[index] >= RESET_AFTER_OUTLIERS {
                self.clocks[index] = None;
                self.outliers_in_a_row[index] = 0;
                self.counters.resets += 1;
            }
            return out;
        }
        self.outliers_in_a_row[index] = 0;
        if t.sigma_ns > self.cfg.max_sigma_ns {
            self.counters.converging += 1;
            return out;
        }
        out.stamp.host_ns = t.time_ns;
        out.stamp.source = StampSource::DeviceCounter as u8;
        self.counters.mapped += 1;
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use navsync_shared::reflect::Reflect;

    /// A 200 Hz IMU whose clock runs 40 ppm slow, received with a one-sided 0.5–3 ms delay.
    fn sample(k: i64, delay_ns: i64) -> (ImuSample, i64) {
        let true_host = 5_000_000_000 + k * 5_000_000;
        let mut s = ImuSample::zeroed();
        s.stamp.host_ns = true_host + delay_ns;
        s.stamp.device_ns = 1_000_000 + (k as f64 * 5_000_000.0 * (1.0 - 40e-6)).round() as i64;
        s.stamp.has_device_time = 1;
        s.stamp.seq = k as u64;
        (s, true_host)
    }

    fn delay(k: i64) -> i64 {
        500_000 + ((k * 7919) % 2_500) * 1_000
    }

    #[test]
    fn mapped_times_have_the_device_precision_and_a_reset_device_is_followed() {
        let mut t = DeviceTiming::new(DeviceTimingConfig::default());
        let mut errs = Vec::new();
        for k in 0..12_000 {
            let (s, truth) = sample(k, delay(k));
            let out = t.retime(0, &s);
            if k >= 6_000 {
                assert_eq!(out.stamp.source, StampSource::DeviceCounter as u8, "{k}");
                errs.push((out.stamp.host_ns - truth) as f64);
            }
        }
        let mean = errs.iter().sum::<f64>() / errs.len() as f64;
        let sd = (errs.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / errs.len() as f64).sqrt();
        // Receipt scatter ~0.72 ms σ (delays 0.5–3 ms, mean 1.75 ms); the mapped times scatter
        // by µs and carry the lower envelope of the delay (the least of 20: ≈ 0.62 ms).
        assert!(sd < 20_000.0, "σ {sd} ns");
        assert!((0.5e6..0.8e6).contains(&mean), "mean {mean} ns");
        // The device restarts its counter: after the outliers, a new clock converges.
        for k in 12_000..30_000 {
            let (mut s, _) = sample(k, delay(k));
            s.stamp.device_ns -= 1_000_000_000;
            t.retime(0, &s);
        }
        assert_eq!(t.counters().resets, 1);
        let (mut s, truth) = sample(30_000, 0);
        s.stamp.device_ns -= 1_000_000_000;
        let out = t.retime(0, &s);
        assert_eq!(out.stamp.source, StampSource::DeviceCounter as u8);
        assert!((out.stamp.host_ns - truth - 650_000).abs() < 200_000);
    }

    #[test]
    fn samples_without_device_time_keep_their_stamp() {
        let mut t = DeviceTiming::new(DeviceTimingConfig::default());
        let (mut s, _) = sample(3, 1_000);
        s.stamp.has_device_time = 0;
        assert_eq!(t.retime(0, &s).stamp.host_ns, s.stamp.host_ns);
        assert_eq!(*t.counters(), DeviceTimingCounters::default());
    }
}
