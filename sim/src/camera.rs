//! The simulated camera on the GNSS receiver's EXTINT0 input, and the receiver's time marks of
//! its exposures (UBX-TIM-TM2, written by [`crate::ubx::tim_tm2`]).
//!
//! - **Triggers** on the true time axis: trigger k at the first whole UTC second at or after
//!   the scenario's start + k/`rate_hz` (rounded to the ns), up to the scenario's end.
//! - **Exposure** k starts `exposure_offset_s` + j_k after trigger k (never before it), j_k a
//!   Gaussian of σ `exposure_jitter_s` truncated at 4σ, drawn from its own stream of the seed
//!   for each k ([`Camera::exposure`] is a function of k: a test asks for any exposure), and
//!   lasts `exposure_s`. The camera's exposure-active output drives EXTINT0: rising edge at the
//!   start, falling edge at the end.
//! - **Time stamps.** The receiver latches an edge on the clock its time pulse comes out on
//!   (period P = `gnss.timepulse_quantization_ns`, with the phase whose sawtooth TIM-TP reports
//!   as qErr, [`crate::ubx::timepulse_q_err_ps`]): the time it reports is the first tick at or
//!   after the edge, rounded to the ns of `towSubMs`, so its error lies in [0, ⌈P⌉] ns. That is
//!   the only error of the receiver's GNSS time the simulator models (its epochs and its PPS
//!   are on true time too); `accEst` reports its bound, ⌈P⌉, at least the 1 ns resolution.
//!   With P = 0 the reported times are the true ones.
//! - **Reports.** The edges whose reported time is at or before a navigation epoch go out in
//!   that epoch's TIM-TM2 (as a receiver reports a mark after it happened): the latest rising
//!   and falling edge, the `newRisingEdge`/`newFallingEdge` flags for edges since the last
//!   report, and `count`, every rising edge so far. An epoch without a new edge has no
//!   TIM-TM2. A camera faster than the epochs loses marks (only the latest is reported), as on
//!   a u-blox receiver.

use navsync_shared::time::{NS_PER_S, gps_ns_from_utc_ns};

use super::rng::{Rng, streams};
use super::scenario::GnssConfig;
use super::ubx::{TimeMark, timepulse_q_err_ps};

/// The input the camera is wired to (`ch` of TIM-TM2): EXTINT0.
pub const CAMERA_CHANNEL: u8 = 0;

/// One exposure of the camera, on the true (UTC) time axis, ns.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Exposure {
    /// Index k of the trigger (0 = the first of the scenario).
    pub index: u64,
    /// The trigger, UTC ns.
    pub trigger_utc_ns: i64,
    /// Start of the exposure (the rising edge on EXTINT0), UTC ns.
    pub rising_utc_ns: i64,
    /// End of the exposure (the falling edge), UTC ns.
    pub falling_utc_ns: i64,
}

/// The camera of a scenario: its exposures as a function of the trigger index.
#[derive(Debug, Clone)]
pub struct Camera {
    rate_hz: f64,
    first_trigger_utc_ns: i64,
    end_utc_ns: i64,
    offset_ns: f64,
    jitter_ns: f64,
    exposure_ns: i64,
    seed: u64,
}

impl Camera {
    /// The camera of a validated receiver configuration for a scenario starting at UTC
    /// `start_utc_ns` and lasting `duration_s`; `None` when its rate is 0.
    pub fn new(cfg: &GnssConfig, seed: u64, start_utc_ns: i64, duration_s: f64) -> Option<Self> {
        let rate_hz = cfg.camera_rate_hz();
        if rate_hz <= 0.0 {
            return None;
        }
        let c = &cfg.camera;
        Some(Self {
            rate_hz,
            first_trigger_utc_ns: start_utc_ns.div_euclid(NS_PER_S) * NS_PER_S
                + if start_utc_ns.rem_euclid(NS_PER_S) == 0 {
                    0
                } else {
                    NS_PER_S
                },
            end_utc_ns: start_utc_ns + (duration_s * 1e9).round() as i64,
            offset_ns: c.exposure_offset_s * 1e9,
            jitter_ns: c.exposure_jitter_s * 1e9,
            exposure_ns: (c.exposure_s * 1e9).round() as i64,
            seed,
        })
    }

    /// Trigger rate, Hz.
    pub fn rate_hz(&self) -> f64 {
        self.rate_hz
    }

    /// Trigger k, UTC ns.
    pub fn trigger_utc_ns(&self, k: u64) -> i64 {
        self.first_trigger_utc_ns + (k as f64 * 1e9 / self.rate_hz).round() as i64
    }

    /// Exposure k; `None` when its trigger is after the scenario's end.
    pub fn exposure(&self, k: u64) -> Option<Exposure> {
        let trigger = self.trigger_utc_ns(k);
        if trigger > self.end_utc_ns {
            return None;
        }
        let jitter = Rng::stream(self.seed, streams::CAMERA ^ (k << 16))
            .gaussian(self.jitter_ns)
            .clamp(-4.0 * self.jitter_ns, 4.0 * self.jitter_ns);
        let rising = trigger + (self.offset_ns + jitter).max(0.0).round() as i64;
        Some(Exposure {
            index: k,
            trigger_utc_ns: trigger,
            rising_utc_ns: rising,
            falling_utc_ns: rising + self.exposure_ns,
        })
    }
}

/// The receiver's time-mark unit on EXTINT0: latches the camera's edges and reports them per
/// navigation epoch.
#[derive(Debug, Clone)]
pub struct TimeMarks {
    camera: Camera,
    /// Period of the receiver's latch clock, ns (0: exact).
    tick_ns: f64,
    /// The next edge: exposure index and whether it is its falling edge.
    next: (u64, bool),
    /// The next edge, as the receiver time-stamps it (UTC ns); `None` after the last.
    next_latched_utc_ns: Option<i64>,
    count: u16,
    rising_gps_ns: Option<i64>,
    falling_gps_ns: Option<i64>,
    new_rising: bool,
    new_falling: bool,
}

impl TimeMarks {
    /// The time marks of `camera` latched on a clock of period `tick_ns` (the receiver's
    /// time-pulse quantisation; 0: exact).
    pub fn new(camera: Camera, tick_ns: f64) -> Self {
        let mut marks = Self {
            camera,
            tick_ns,
            next: (0, false),
            next_latched_utc_ns: None,
            count: 0,
            rising_gps_ns: None,
            falling_gps_ns: None,
            new_rising: false,
            new_falling: false,
        };
        marks.next_latched_utc_ns = marks.latched(marks.next);
        marks
    }

    /// The camera.
    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    /// The accuracy estimate of the reported edges (`accEst`), ns: the bound of the latch
    /// error, at least the 1 ns resolution.
    pub fn acc_est_ns(&self) -> u32 {
        (self.tick_ns.ceil() as u32).max(1)
    }

    /// The time the receiver reports for an edge at true UTC `utc_ns`: the first tick of its
    /// latch clock at or after it, ns. The ticks of UTC second s are s + q(s) + j·P, q(s) the
    /// qErr of the pulse of second s.
    pub fn latch_utc_ns(&self, utc_ns: i64) -> i64 {
        let p = self.tick_ns;
        if p <= 0.0 {
            return utc_ns;
        }
        let s = utc_ns.div_euclid(NS_PER_S);
        let into = utc_ns.rem_euclid(NS_PER_S) as f64;
        let q = f64::from(timepulse_q_err_ps(p, s)) * 1e-3;
        let tick = q + ((into - q) / p).ceil() * p;
        s * NS_PER_S + tick.round() as i64
    }

    fn latched(&self, (k, falling): (u64, bool)) -> Option<i64> {
        let e = self.camera.exposure(k)?;
        Some(self.latch_utc_ns(if falling { e.falling_utc_ns } else { e.rising_utc_ns }))
    }

    /// The TIM-TM2 of the navigation epoch at UTC `epoch_utc_ns`: the edges latched at or
    /// before it since the last epoch; `None` when there is no new edge.
    pub fn report(&mut self, epoch_utc_ns: i64) -> Option<TimeMark> {
        while let Some(t) = self.next_latched_utc_ns.filter(|&t| t <= epoch_utc_ns) {
            let gps = Some(gps_ns_from_utc_ns(t));
            let (k, falling) = self.next;
            if falling {
                (self.falling_gps_ns, self.new_falling) = (gps, true);
                self.next = (k + 1, false);
            } else {
                (self.rising_gps_ns, self.new_rising) = (gps, true);
                self.count = self.count.wrapping_add(1);
                self.next = (k, true);
            }
            self.next_latched_utc_ns = self.latched(self.next);
        }
        if !(self.new_rising || self.new_falling) {
            return None;
        }
        let mark = TimeMark {
            channel: CAMERA_CHANNEL,
            count: self.count,
            rising_gps_ns: self.rising_gps_ns,
            new_rising: self.new_rising,
            falling_gps_ns: self.falling_gps_ns,
            new_falling: self.new_falling,
            acc_est_ns: self.acc_est_ns(),
        };
        (self.new_rising, self.new_falling) = (false, false);
        Some(mark)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::{OutputProtocol, SimConfig};

    /// Not on a whole second: the first trigger is the next one.
    const U0: i64 = 1_790_000_000_400_000_000;

    fn gnss(rate_hz: f64, offset_s: f64, jitter_s: f64, exposure_s: f64) -> GnssConfig {
        let mut cfg = SimConfig::default_drive();
        cfg.set_gnss_protocol(OutputProtocol::Ubx);
        cfg.set_camera_rate_hz(rate_hz);
        cfg.gnss.camera.exposure_offset_s = offset_s;
        cfg.gnss.camera.exposure_jitter_s = jitter_s;
        cfg.gnss.camera.exposure_s = exposure_s;
        cfg.validate().expect("valid camera");
        cfg.gnss
    }

    fn exposures(c: &Camera) -> Vec<Exposure> {
        (0..).map_while(|k| c.exposure(k)).collect()
    }

    #[test]
    fn exposures_follow_the_rate_the_offset_and_the_jitter() {
        let (offset, sigma) = (0.0123, 50e-6);
        let cfg = gnss(4.0, offset, sigma, 0.003);
        let c = Camera::new(&cfg, 7, U0, 600.0).expect("a camera");
        let all = exposures(&c);
        // Triggers at 1 790 000 001 s + k/4 up to the end (U0 + 600 s): 599.4 s / 0.25 s + 1.
        assert_eq!(all.len(), 2398);
        assert_eq!(all[0].trigger_utc_ns, 1_790_000_001_000_000_000);
        let (mut sum, mut sum2) = (0.0, 0.0);
        for (k, e) in all.iter().enumerate() {
            assert_eq!(e.index, k as u64);
            assert_eq!(e.trigger_utc_ns, all[0].trigger_utc_ns + k as i64 * 250_000_000);
            assert_eq!(e.falling_utc_ns - e.rising_utc_ns, 3_000_000);
            let j = (e.rising_utc_ns - e.trigger_utc_ns) as f64 * 1e-9 - offset;
            assert!(j.abs() <= 4.0 * sigma + 1e-9, "jitter {j} beyond 4σ");
            sum += j;
            sum2 += j * j;
        }
        let n = all.len() as f64;
        let (mean, sd) = (sum / n, (sum2 / n - (sum / n).powi(2)).sqrt());
        // The mean within 4σ/√n, σ within 10 % (n ≈ 2400: its own σ is ~1.4 %).
        assert!(mean.abs() < 4.0 * sigma / n.sqrt(), "mean {mean}");
        assert!((sd / sigma - 1.0).abs() < 0.1, "σ {sd}");
        // A function of k and the seed: asked again, the same; another seed, other jitter.
        let again = Camera::new(&cfg, 7, U0, 600.0).expect("a camera");
        assert_eq!(again.exposure(1234), Some(all[1234]));
        let other = Camera::new(&cfg, 8, U0, 600.0).expect("a camera");
        assert_ne!(other.exposure(1234), Some(all[1234]));
        assert_eq!(
            other.exposure(1234).map(|e| e.trigger_utc_ns),
            Some(all[1234].trigger_utc_ns)
        );
        // Without jitter, exactly the offset.
        let exact = Camera::new(&gnss(4.0, offset, 0.0, 0.003), 7, U0, 600.0).expect("a camera");
        assert!(
            exposures(&exact)
                .iter()
                .all(|e| e.rising_utc_ns - e.trigger_utc_ns == 12_300_000)
        );
        // Rate 0 (or NMEA by default): no camera.
        assert!(Camera::new(&gnss(0.0, offset, 0.0, 0.003), 7, U0, 600.0).is_none());
        assert!(Camera::new(&SimConfig::default_drive().gnss, 7, U0, 600.0).is_none());
    }

    #[test]
    fn the_receiver_latches_an_edge_on_its_time_pulse_clock() {
        let c = Camera::new(&gnss(1.0, 0.0, 0.0, 0.002), 1, U0, 60.0).expect("a camera");
        // P = 0: the true time.
        let exact = TimeMarks::new(c.clone(), 0.0);
        assert_eq!((exact.latch_utc_ns(U0 + 17), exact.acc_est_ns()), (U0 + 17, 1));
        // P = 20.83 ns (a u-blox M8T's 48 MHz): late by 0 … ⌈P⌉ ns, uniformly.
        let m = TimeMarks::new(c, 20.83);
        assert_eq!(m.acc_est_ns(), 21);
        let mut rng = Rng::new(3);
        let mut sum = 0.0;
        let n = 20_000;
        for _ in 0..n {
            let t = U0 + (rng.uniform() * 60e9) as i64;
            let err = m.latch_utc_ns(t) - t;
            assert!((0..=21).contains(&err), "{err} ns");
            sum += err as f64;
        }
        assert!(
            (sum / f64::from(n) - 20.83 / 2.0).abs() < 0.3,
            "mean {}",
            sum / f64::from(n)
        );
        // The ticks are those the time pulse comes out on: at s + qErr(s) when qErr ≥ 0.
        for s in 1_790_000_001..1_790_000_060i64 {
            let q = f64::from(timepulse_q_err_ps(20.83, s)) * 1e-3;
            if q >= 0.0 {
                assert_eq!(
                    m.latch_utc_ns(s * NS_PER_S) - s * NS_PER_S,
                    q.round() as i64,
                    "second {s}"
                );
            }
        }
    }

    /// Epochs at `rate` Hz from U0's next second for `seconds`: the reports.
    fn reports(m: &mut TimeMarks, rate: i64, seconds: i64) -> Vec<(i64, TimeMark)> {
        let first = 1_790_000_001_000_000_000;
        (0..seconds * rate)
            .map(|i| first + i * NS_PER_S / rate)
            .filter_map(|e| m.report(e).map(|r| (e, r)))
            .collect()
    }

    #[test]
    fn each_epoch_reports_the_latest_edges_before_it() {
        let gps = |utc: i64| Some(gps_ns_from_utc_ns(utc));
        // As fast as the epochs: every exposure once, both edges new.
        let c = Camera::new(&gnss(2.0, 0.1, 20e-6, 0.004), 4, U0, 30.0).expect("a camera");
        let mut m = TimeMarks::new(c.clone(), 0.0);
        let r = reports(&mut m, 2, 30);
        assert_eq!(r.len(), 59);
        for (k, (epoch, mark)) in r.iter().enumerate() {
            let e = c.exposure(k as u64).expect("exposure");
            assert!(e.falling_utc_ns <= *epoch && epoch - e.rising_utc_ns < 500_000_000);
            assert_eq!((mark.count, mark.channel, mark.acc_est_ns), (k as u16 + 1, 0, 1));
            assert_eq!(
                (mark.rising_gps_ns, mark.falling_gps_ns),
                (gps(e.rising_utc_ns), gps(e.falling_utc_ns))
            );
            assert!(mark.new_rising && mark.new_falling);
        }
        // Four times faster than the epochs: the latest of every four, counted.
        let c = Camera::new(&gnss(4.0, 0.1, 0.0, 0.004), 4, U0, 30.0).expect("a camera");
        let mut m = TimeMarks::new(c.clone(), 0.0);
        let r = reports(&mut m, 1, 30);
        assert_eq!(r.len(), 29);
        for (i, (_, mark)) in r.iter().enumerate() {
            let k = 4 * i as u64 + 3;
            assert_eq!(mark.count, k as u16 + 1);
            assert_eq!(mark.rising_gps_ns, gps(c.exposure(k).expect("exposure").rising_utc_ns));
        }
        // An exposure across the epoch: the rising edge in one report, the falling in the next.
        let c = Camera::new(&gnss(1.0, 0.499, 0.0, 0.002), 4, U0, 30.0).expect("a camera");
        let mut m = TimeMarks::new(c.clone(), 0.0);
        let r = reports(&mut m, 2, 10);
        assert_eq!(r.len(), 19);
        for (i, (epoch, mark)) in r.iter().enumerate() {
            let e = c.exposure(i as u64 / 2).expect("exposure");
            let rising_half = i % 2 == 0;
            assert_eq!(
                (mark.new_rising, mark.new_falling),
                (rising_half, !rising_half),
                "{epoch}"
            );
            assert_eq!(mark.rising_gps_ns, gps(e.rising_utc_ns));
            let falling = if rising_half {
                i.checked_sub(1)
                    .map(|_| c.exposure(i as u64 / 2 - 1).expect("exposure").falling_utc_ns)
            } else {
                Some(e.falling_utc_ns)
            };
            assert_eq!(mark.falling_gps_ns, falling.and_then(gps));
        }
    }
}
