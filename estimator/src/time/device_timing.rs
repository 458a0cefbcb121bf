//! Sample times from each IMU's own clock: a [`DeviceClock`] per IMU fed with every sample's
//! (device time, host stamp) pair, the host clock as reference ([`DeviceClock::on_host_stamp`]).
//! Once converged, a sample's host time is its device time mapped to host time: the device's
//! sample-to-sample precision (µs) instead of the receipt stamp's scatter (ms over a serial
//! line or USB). Before that, and for samples without device time, the stamp is kept.
//!
//! A mapped time far from the stamp (beyond any transport delay: a device reset, a counter
//! jump) is not used; [`RESET_AFTER_OUTLIERS`] of those in a row start the clock afresh.
//!
//! One crystal: an IMU sampling on the GNSS receiver's oscillator
//! ([`IMU_FLAG_RECEIVER_CLOCK`]) carries the receiver clock's reading t_r = t_GPS + b_r as
//! device time. With the receiver clock bias b̂_r of the tightly coupled filter and the PPS
//! clock model, t_r − b̂_r is GPS time and maps to host time absolutely
//! ([`DeviceTiming::retime_on_receiver_clock`]): no transport delay is left in it, where the
//! device-clock regression above keeps the least delay of its windows.

use navsync_wire::samples::{IMU_FLAG_RECEIVER_CLOCK, ImuSample, MAX_IMUS, StampSource};
use navsync_wire::time::utc_ns_from_gps_ns;

use super::device_clock::{DeviceClock, DeviceClockConfig, DeviceUpdate};

/// Consecutive samples whose mapped time disagrees with the stamp after which the device
/// clock of that IMU is restarted.
pub const RESET_AFTER_OUTLIERS: u32 = 50;

crate::settings_group! {
    /// Settings of the device timing.
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub struct DeviceTimingConfig {
        /// Time IMU samples by their device clocks where they carry one (Xsens SampleTimeFine;
        /// off: every sample at its receipt stamp).
        pub device_clocks: bool = true, file "estimator", switch "no-device-clocks" => false;
        /// 1-sigma of the least delayed host stamp of a window against the device event, ns
        /// (100 µs; a single receipt scatters by 0.3–0.6 ms through a pseudo-terminal, by
        /// several ms under load).
        pub host_stamp_sigma_ns: f64 = 100_000.0;
        /// Host stamps per window of the minimum-delay filter (40: 0.2 s at 200 Hz; see
        /// [`DeviceClockConfig::host_stamp_window`]).
        pub host_stamp_window: u32 = 40;
        /// Largest 1-sigma of the mapping (its offset's uncertainty, a slowly varying error, not
        /// the scatter) at which it replaces the stamp, ns (100 µs: a few seconds at 200 Hz;
        /// the receipt scatter it replaces is ~600 µs).
        pub max_sigma_ns: f64 = 100_000.0;
        /// Largest |mapped − stamp| accepted, ns (50 ms: longer than any transport delay).
        pub max_residual_ns: i64 = 50_000_000;
        /// Largest 1-sigma of the receiver clock bias at which an IMU on the receiver's clock is
        /// timed by it, ns (1 µs: any fused clock is far better; a TCXO in holdover reaches it
        /// after several minutes without satellites, then the device clock takes over).
        pub receiver_clock_max_sigma_ns: f64 = 1_000.0;
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
    /// Samples on the receiver's clock timed by it (GPS time through the PPS clock model).
    pub receiver_clock: u64,
    /// Samples on the receiver's clock not timed by it: no receiver clock solution within
    /// its σ limit, or no hardware time mapping (they keep the device-clock time).
    pub receiver_clock_waiting: u64,
    /// Samples on the receiver's clock whose time disagreed with the stamp beyond the limit.
    pub receiver_clock_outliers: u64,
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
        if !self.cfg.device_clocks || s.stamp.has_device_time == 0 || index >= MAX_IMUS || s.stamp.device_ns < 0 {
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

impl DeviceTiming {
    /// The sample with its host time from the GNSS receiver's clock, when it samples on it
    /// ([`IMU_FLAG_RECEIVER_CLOCK`]): GPS time t_r − b̂_r, with `receiver_bias_ns` the
    /// receiver clock bias and its 1-sigma (ns) at the sample, mapped to host time by
    /// `host_ns_at_utc` (the PPS clock model; `None` without a hardware time mapping). `None`
    /// (keep the device-clock time of [`Self::retime`]) for other samples, without a clock
    /// solution within [`DeviceTimingConfig::receiver_clock_max_sigma_ns`], or when the time
    /// is further than [`DeviceTimingConfig::max_residual_ns`] from the stamp.
    pub fn retime_on_receiver_clock(
        &mut self,
        s: &ImuSample,
        receiver_bias_ns: Option<(f64, f64)>,
        host_ns_at_utc: impl FnOnce(i64) -> Option<i64>,
    ) -> Option<ImuSample> {
        if !self.cfg.device_clocks || s.flags & IMU_FLAG_RECEIVER_CLOCK == 0 || s.stamp.has_device_time == 0 {
            return None;
        }
        // GPS time within 1980 … 2126 (2⁶² ns): a device time far outside is no receiver's
        // reading, and the time conversions stay clear of overflow.
        let mapped = receiver_bias_ns
            .filter(|(b, sd)| b.is_finite() && *sd <= self.cfg.receiver_clock_max_sigma_ns)
            .and_then(|(b, _)| s.stamp.device_ns.checked_sub(b.round() as i64))
            .filter(|gps_ns| (0..1i64 << 62).contains(gps_ns))
            .and_then(|gps_ns| host_ns_at_utc(utc_ns_from_gps_ns(gps_ns)));
        let Some(host_ns) = mapped else {
            self.counters.receiver_clock_waiting += 1;
            return None;
        };
        if (host_ns - s.stamp.host_ns).abs() > self.cfg.max_residual_ns {
            self.counters.receiver_clock_outliers += 1;
            return None;
        }
        self.counters.receiver_clock += 1;
        let mut out = *s;
        out.stamp.host_ns = host_ns;
        out.stamp.source = StampSource::ReceiverClock as u8;
        Some(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use navsync_wire::reflect::Reflect;

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
    fn a_sample_on_the_receivers_clock_is_its_reading_less_the_bias_in_host_time() {
        use navsync_wire::samples::IMU_FLAG_RECEIVER_CLOCK;
        use navsync_wire::time::gps_ns_from_utc_ns;
        let mut t = DeviceTiming::new(DeviceTimingConfig::default());
        // Host time = UTC − 1.7e18 ns + 3 µs (the PPS clock model's mapping).
        let host_at = |utc: i64| Some(utc - 1_700_000_000_000_000_000 + 3_000);
        let utc = 1_796_083_200_000_000_000;
        let mut s = ImuSample::zeroed();
        s.stamp.has_device_time = 1;
        s.flags = IMU_FLAG_RECEIVER_CLOCK;
        // The receiver's clock runs 57.5 µs ahead of GPS time.
        s.stamp.device_ns = gps_ns_from_utc_ns(utc) + 57_500;
        let true_host = host_at(utc).unwrap();
        s.stamp.host_ns = true_host + 4_000_000;
        let out = t.retime_on_receiver_clock(&s, Some((57_500.0, 20.0)), host_at).unwrap();
        assert_eq!(out.stamp.host_ns, true_host);
        assert_eq!(out.stamp.source, StampSource::ReceiverClock as u8);
        // No clock, a clock beyond its σ limit, no time mapping, a time far from the stamp,
        // a sample not on the receiver's clock: the device-clock time is kept.
        assert!(t.retime_on_receiver_clock(&s, None, host_at).is_none());
        assert!(
            t.retime_on_receiver_clock(&s, Some((57_500.0, 2_000.0)), host_at)
                .is_none()
        );
        assert!(
            t.retime_on_receiver_clock(&s, Some((57_500.0, 20.0)), |_| None)
                .is_none()
        );
        assert!(t.retime_on_receiver_clock(&s, Some((-60e6, 20.0)), host_at).is_none());
        let c = *t.counters();
        assert_eq!(
            (c.receiver_clock, c.receiver_clock_waiting, c.receiver_clock_outliers),
            (1, 3, 1)
        );
        // Device times no receiver reads: kept, counted, no overflow.
        for d in [i64::MIN, -1, i64::MAX] {
            s.stamp.device_ns = d;
            assert!(
                t.retime_on_receiver_clock(&s, Some((57_500.0, 20.0)), host_at)
                    .is_none()
            );
        }
        assert_eq!(t.counters().receiver_clock_waiting, c.receiver_clock_waiting + 3);
        let c = *t.counters();
        s.flags = 0;
        assert!(
            t.retime_on_receiver_clock(&s, Some((57_500.0, 20.0)), host_at)
                .is_none()
        );
        assert_eq!(*t.counters(), c);
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
