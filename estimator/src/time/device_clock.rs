//! Mapping a device's own counter to GNSS time: for any source with its own clock (an IMU's
//! sample counter such as the Xsens `SampleTimeFine` at 10 kHz, a microcontroller's 1 MHz
//! capture counter).
//!
//! The classic relation between two PPS edges latched by the counter at C1 (GNSS second t1)
//! and C3 (t1 + 1 s), for a sample at counter C2, is
//!
//! t2 = t1 + (C2 − C1)·T + bt·(C2 − C1)/(C3 − C1),
//!
//! with T the nominal tick and bt = 1 s − (C3 − C1)·T the error the device clock accumulated
//! over the second: linear interpolation on the device's counter between GNSS-labelled
//! instants. Generalised to a filter, the same mapping is the two-state clock model of
//! [`ClockModel`] (Brown & Hwang §9.3: offset and fractional frequency of the device clock
//! against GNSS time, process noise from the device oscillator's Allan deviation) with the
//! device time C·T in place of host time. It averages the capture noise over many seconds,
//! bridges missing edges by extrapolation with growing, honest uncertainty, and rejects
//! outliers with its innovation gate.
//!
//! Inputs (pure state machine, no clocks or I/O; fixed memory):
//! - [`DeviceClock::on_pps_capture`]: the counter latched at a PPS edge and that edge's GNSS
//!   time (the device's SyncIn, a timer capture input), the best;
//! - [`DeviceClock::on_host_pair`]: a (counter, host stamp) pair with the host → GNSS
//!   [`TimeState`] mapping: the counter of a sample and the host time its data-ready event
//!   was stamped (kernel event, or receipt time minus a known transport latency), noisier
//!   but needs no wiring;
//! - [`DeviceClock::on_host_stamp`]: the same pair with the host clock itself as the
//!   reference time scale: the mapping then gives host time (what the estimator fuses in;
//!   host → GNSS is the host clock model's job), and works before and without PPS. One clock
//!   uses one reference scale: host stamps, or PPS captures and host pairs.
//!
//! [`DeviceClock::map`] gives the reference time of any counter value with its 1-sigma and the
//! [`StampSource`] to record; until the filter has two measurements it returns `None` and the
//! caller stamps with receipt time (flag [`StampSource::Receipt`]), the fallback.
//!
//! Receipt stamps are late by a transport delay that varies (serial line, USB latency timer,
//! scheduler: a one-sided distribution with a long tail under load). With
//! [`DeviceClockConfig::host_stamp_window`] > 1 only the least delayed stamp of each window
//! is fused (the lower envelope, NTP's minimum-delay filter), so the tail does not pull the
//! mapping; otherwise the filter maps to their mean. A constant share of the delay stays in
//! the mapped times (the estimator's IMU offset estimation takes it up), the scatter does not.

use navsync_wire::samples::{StampSource, TimeState};

use super::clock_model::{ClockModel, ClockUpdate, OscillatorNoise};

/// Settings of one device clock.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DeviceClockConfig {
    /// Nominal tick length T, ns (10 kHz: 100_000; 1 MHz: 1_000).
    pub tick_ns: f64,
    /// Width of the counter in bits (it wraps at 2^bits), 1..=64.
    pub counter_bits: u32,
    /// The device oscillator's stability (a crystal: white FM 1e−9, random walk 1e−9 at 1 s).
    pub noise: OscillatorNoise,
    /// 1-sigma of a PPS capture, ns (at least the tick quantisation T/√12).
    pub capture_sigma_ns: f64,
    /// 1-sigma of a host stamp of a device event, ns, before the mapping's own uncertainty.
    pub host_stamp_sigma_ns: f64,
    /// Mean delay of the host stamp after the device event, ns (subtracted).
    pub host_stamp_latency_ns: f64,
    /// Host stamps taken together by [`DeviceClock::on_host_stamp`]: of each group of this
    /// many consecutive pairs only the least delayed one (the smallest host − mapped time)
    /// is fused, the lower envelope of a one-sided delay, as NTP's minimum-delay filter does
    /// (1: every pair).
    pub host_stamp_window: u32,
    /// Initial uncertainty of the device's frequency (e.g. 1e−4 for a crystal).
    pub initial_rate_sigma: f64,
}

impl DeviceClockConfig {
    /// A counter of `tick_ns` and `counter_bits` with crystal-class defaults.
    pub fn crystal(tick_ns: f64, counter_bits: u32) -> Self {
        Self {
            tick_ns,
            counter_bits,
            noise: OscillatorNoise::from_allan(1e-9, 1e-9),
            capture_sigma_ns: (tick_ns / 12f64.sqrt()).max(1.0),
            host_stamp_sigma_ns: 100_000.0,
            host_stamp_latency_ns: 0.0,
            host_stamp_window: 1,
            initial_rate_sigma: 1e-4,
        }
    }
}

/// A mapped device time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DeviceTime {
    /// Time of the counter value in the reference scale, ns: GNSS (UTC) time since 1970 from
    /// PPS captures and host pairs, host `CLOCK_MONOTONIC` time from host stamps.
    pub time_ns: i64,
    /// 1-sigma, ns.
    pub sigma_ns: f64,
    /// How it was obtained (device counter through PPS captures or host pairs).
    pub source: StampSource,
}

/// What a measurement did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DeviceUpdate {
    /// Used (first one: initialised the mapping).
    Used,
    /// Outside the filter's gate; innovation ns.
    Rejected(f64),
    /// The counter went backwards (beyond half its range) or the host mapping is not valid.
    Ignored,
    /// Kept in the host-stamp window (see [`DeviceClockConfig::host_stamp_window`]).
    Buffered,
}

/// Counters of the device clock.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DeviceClockCounters {
    /// PPS captures used.
    pub captures: u64,
    /// Host pairs used.
    pub host_pairs: u64,
    /// Measurements rejected by the gate.
    pub rejected: u64,
    /// Measurements ignored (counter backwards, no host mapping).
    pub ignored: u64,
    /// Counter wraps seen.
    pub wraps: u64,
}

/// Extends a wrapping counter to 64 bits (pure).
#[derive(Debug, Clone, Copy, Default)]
struct Unwrapper {
    last_raw: Option<u64>,
    extended: i64,
}

impl Unwrapper {
    /// The extended count of `raw`; `None` when it is more than half the range behind the
    /// last one (a reset or garbage). Counts `wraps`.
    fn extend(&mut self, raw: u64, bits: u32, wraps: &mut u64) -> Option<i64> {
        let bits = bits.clamp(1, 64);
        let mask = if bits == 64 { u64::MAX } else { (1u64 << bits) - 1 };
        let raw = raw & mask;
        let Some(last) = self.last_raw else {
            self.last_raw = Some(raw);
            self.extended = raw.min(i64::MAX as u64) as i64;
            return Some(self.extended);
        };
        let delta = raw.wrapping_sub(last) & mask;
        let half = if bits == 64 { 1u64 << 63 } else { 1u64 << (bits - 1) };
        if delta >= half {
            // Backwards by (range − delta): a sample older than the last one.
            let back = (mask - delta).saturating_add(1);
            return Some(self.extended.saturating_sub(back.min(i64::MAX as u64) as i64));
        }
        if raw < last {
            *wraps += 1;
        }
        self.last_raw = Some(raw);
        self.extended = self.extended.saturating_add(delta.min(i64::MAX as u64) as i64);
        Some(self.extended)
    }
}

/// The device-clock state machine.
#[derive(Debug, Clone)]
pub struct DeviceClock {
    cfg: DeviceClockConfig,
    unwrap: Unwrapper,
    model: ClockModel,
    counters: DeviceClockCounters,
    /// Whether any PPS capture was used (the better [`StampSource`]).
    has_captures: bool,
    /// The least delayed host stamp of the window so far (device ns, host ns, delay ns) and
    /// the pairs seen in it.
    window_best: Option<(i64, i64, i64)>,
    window_n: u32,
}

impl DeviceClock {
    /// A device clock with nothing known.
    pub fn new(cfg: DeviceClockConfig) -> Self {
        Self {
            cfg,
            unwrap: Unwrapper::default(),
            model: ClockModel::new(cfg.noise),
            counters: DeviceClockCounters::default(),
            has_captures: false,
            window_best: None,
            window_n: 0,
        }
    }

    /// Counters so far.
    pub fn counters(&self) -> &DeviceClockCounters {
        &self.counters
    }

    /// Estimated fractional frequency error of the device clock against GNSS time
    /// (d GNSS / d device − 1), once initialised.
    pub fn rate_error(&self) -> Option<f64> {
        self.model.is_initialized().then(|| self.model.rate_error())
    }

    fn device_ns(&self, extended: i64) -> i64 {
        (extended as f64 * self.cfg.tick_ns).round() as i64
    }

    fn fuse(&mut self, device_ns: i64, ref_ns: i64, sigma_ns: f64) -> DeviceUpdate {
        if !self.model.is_initialized() {
            self.model
                .init(device_ns, ref_ns, sigma_ns, self.cfg.initial_rate_sigma);
            return DeviceUpdate::Used;
        }
        match self.model.update(device_ns, ref_ns, sigma_ns) {
            ClockUpdate::Accepted(_) => DeviceUpdate::Used,
            ClockUpdate::Rejected(innovation) => {
                self.counters.rejected += 1;
                DeviceUpdate::Rejected(innovation)
            }
        }
    }

    /// The counter latched `raw` at a PPS edge that marks GNSS time `utc_ns`.
    pub fn on_pps_capture(&mut self, raw: u64, utc_ns: i64) -> DeviceUpdate {
        let Some(ext) = self.unwrap.extend(raw, self.cfg.counter_bits, &mut self.counters.wraps) else {
            self.counters.ignored += 1;
            return DeviceUpdate::Ignored;
        };
        let r = self.fuse(self.device_ns(ext), utc_ns, self.cfg.capture_sigma_ns);
        if r == DeviceUpdate::Used {
            self.counters.captures += 1;
            self.has_captures = true;
        }
        r
    }

    /// A device event with counter `raw` was stamped at host time `host_ns`; `time` maps host
    /// time to GNSS time.
    pub fn on_host_pair(&mut self, raw: u64, host_ns: i64, time: &TimeState) -> DeviceUpdate {
        if !time.is_valid() {
            self.counters.ignored += 1;
            return DeviceUpdate::Ignored;
        }
        let Some(ext) = self.unwrap.extend(raw, self.cfg.counter_bits, &mut self.counters.wraps) else {
            self.counters.ignored += 1;
            return DeviceUpdate::Ignored;
        };
        let event_host = host_ns - self.cfg.host_stamp_latency_ns.round() as i64;
        let utc = time.utc_ns_at(event_host);
        // A mapping whose σ is not known (NaN: a term of it was never set) adds none here, as
        // the device clock has always taken it.
        let map_sigma = Some(time.utc_std_ns_at(event_host))
            .filter(|s| !s.is_nan())
            .unwrap_or(0.0);
        let sigma = (self.cfg.host_stamp_sigma_ns.powi(2) + map_sigma.powi(2)).sqrt();
        let r = self.fuse(self.device_ns(ext), utc, sigma);
        if r == DeviceUpdate::Used {
            self.counters.host_pairs += 1;
        }
        r
    }

    /// A device event with counter `raw` was stamped at host time `host_ns`, the host clock
    /// being the reference time scale (module docs).
    pub fn on_host_stamp(&mut self, raw: u64, host_ns: i64) -> DeviceUpdate {
        let Some(ext) = self.unwrap.extend(raw, self.cfg.counter_bits, &mut self.counters.wraps) else {
            self.counters.ignored += 1;
            return DeviceUpdate::Ignored;
        };
        let event_host = host_ns - self.cfg.host_stamp_latency_ns.round() as i64;
        let device_ns = self.device_ns(ext);
        if self.cfg.host_stamp_window > 1 {
            // The least delayed pair of the window (delay against the mapping so far, or the
            // raw offset before there is one: the clock's drift over a window is negligible).
            let delay = if self.model.is_initialized() {
                event_host - self.model.utc_ns_at(device_ns)
            } else {
                event_host - device_ns
            };
            if self.window_best.is_none_or(|(_, _, d)| delay < d) {
                self.window_best = Some((device_ns, event_host, delay));
            }
            self.window_n += 1;
            if self.window_n < self.cfg.host_stamp_window {
                return DeviceUpdate::Buffered;
            }
            self.window_n = 0;
        }
        let (device_ns, event_host) = match self.window_best.take() {
            Some((d, h, _)) => (d, h),
            None => (device_ns, event_host),
        };
        let r = self.fuse(device_ns, event_host, self.cfg.host_stamp_sigma_ns);
        if r == DeviceUpdate::Used {
            self.counters.host_pairs += 1;
        }
        r
    }

    /// Reference time of counter value `raw` (a sample's), once two measurements were used;
    /// `None` before: stamp with receipt time instead ([`StampSource::Receipt`]).
    pub fn map(&self, raw: u64) -> Option<DeviceTime> {
        if self.model.updates() < 2 {
            return None;
        }
        // A query must not move the unwrapper: extend a copy.
        let mut unwrap = self.unwrap;
        let ext = unwrap.extend(raw, self.cfg.counter_bits, &mut 0)?;
        let d = self.device_ns(ext);
        Some(DeviceTime {
            time_ns: self.model.utc_ns_at(d),
            sigma_ns: self.model.std_ns_at(d),
            source: StampSource::DeviceCounter,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use navsync_wire::samples::TimeStatus;

    const U0: i64 = 1_790_000_000_000_000_000;

    /// The textbook relation t2 = t1 + (C2 − C1)·T + bt·(C2 − C1)/(C3 − C1).
    fn interpolate(t1: i64, c1: u64, c3: u64, c2: u64, tick: f64) -> f64 {
        let bt = 1e9 - (c3 - c1) as f64 * tick;
        t1 as f64 + (c2 - c1) as f64 * tick + bt * (c2 - c1) as f64 / (c3 - c1) as f64
    }

    #[test]
    fn exact_captures_reproduce_the_interpolation_formula() {
        // A 1 MHz counter running 20 ppm fast: 1_000_020 ticks per GNSS second.
        let mut cfg = DeviceClockConfig::crystal(1_000.0, 32);
        cfg.capture_sigma_ns = 1.0;
        let mut dc = DeviceClock::new(cfg);
        let c = |k: u64| 5_000 + k * 1_000_020;
        for k in 0..10 {
            assert_eq!(
                dc.on_pps_capture(c(k), U0 + k as i64 * 1_000_000_000),
                DeviceUpdate::Used
            );
        }
        let c2 = c(9) + 400_008; // 0.4 s after the last edge
        let t = dc.map(c2).expect("mapped");
        let expected = interpolate(U0 + 8_000_000_000, c(8), c(9), c2, 1_000.0);
        assert!(
            (t.time_ns as f64 - expected).abs() <= 2.0,
            "{} vs {expected}",
            t.time_ns
        );
        assert_eq!(t.source, StampSource::DeviceCounter);
        assert!(t.sigma_ns < 10.0);
        assert!((dc.rate_error().unwrap() + 20e-6 / 1.00002).abs() < 1e-9);
    }

    #[test]
    fn wraps_of_a_16_bit_counter_are_followed() {
        // 10 kHz, 16 bits: wraps every 6.5536 s.
        let mut cfg = DeviceClockConfig::crystal(100_000.0, 16);
        cfg.capture_sigma_ns = 30_000.0;
        let mut dc = DeviceClock::new(cfg);
        for k in 0..40u64 {
            let raw = (k * 10_000) & 0xffff;
            assert_eq!(
                dc.on_pps_capture(raw, U0 + k as i64 * 1_000_000_000),
                DeviceUpdate::Used,
                "{k}"
            );
        }
        assert!(dc.counters().wraps >= 5);
        let t = dc.map((39 * 10_000 + 5_000) & 0xffff).expect("mapped");
        assert!((t.time_ns - (U0 + 39_500_000_000)).abs() < 30_000, "{}", t.time_ns - U0);
    }

    #[test]
    fn host_pairs_through_the_time_mapping_and_the_receipt_fallback() {
        let mut cfg = DeviceClockConfig::crystal(1_000.0, 32);
        cfg.host_stamp_sigma_ns = 50_000.0;
        let mut dc = DeviceClock::new(cfg);
        assert_eq!(dc.map(123), None, "receipt-time fallback until mapped");
        let mut time = TimeState::unknown();
        assert_eq!(dc.on_host_pair(1, 1, &time), DeviceUpdate::Ignored);
        time.status = TimeStatus::Locked as u8;
        time.ref_host_ns = 10_000_000_000;
        time.ref_utc_ns = U0;
        time.offset_std_ns = 1_000.0;
        time.rate_std = 0.0;
        time.offset_rate_cov_ns = 0.0;
        time.q_offset_ns2_per_s = 0.0;
        time.q_rate_per_s = 0.0;
        // A 200 Hz IMU with a 1 MHz counter; host stamps with ±40 µs deterministic scatter.
        for k in 0..2_000i64 {
            let counter = 7_000 + k as u64 * 5_000;
            let host = 10_000_000_000 + k * 5_000_000 + ((k * 7919) % 81 - 40) * 1_000;
            dc.on_host_pair(counter, host, &time);
        }
        let t = dc.map(7_000 + 1_999 * 5_000).expect("mapped");
        let truth = U0 + 1_999 * 5_000_000;
        assert!((t.time_ns - truth).abs() < 5_000, "{} ns", t.time_ns - truth);
        assert!(dc.counters().host_pairs > 1_990);
    }

    #[test]
    fn a_counter_reset_is_not_a_jump_forward() {
        let mut dc = DeviceClock::new(DeviceClockConfig::crystal(1_000.0, 32));
        dc.on_pps_capture(3_000_000_000, U0);
        dc.on_pps_capture(3_001_000_000, U0 + 1_000_000_000);
        // Counter reset to a small value: far behind (as a 32-bit counter it looks backwards).
        let r = dc.on_pps_capture(10, U0 + 2_000_000_000);
        assert!(matches!(r, DeviceUpdate::Rejected(_)), "{r:?}");
    }
}
