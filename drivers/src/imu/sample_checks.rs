//! What every IMU sample goes through between decoding and publishing: plausibility checks
//! (non-finite values, values beyond the sensor's range, time going backwards, duplicates)
//! and sequence numbering with drop detection (device counter gaps and wraps, or gaps in the
//! time stamps when the device has no counter). Pure state machine, no I/O, no allocation.
//!
//! A sample that fails a check is rejected and counted; the state is not advanced, so one
//! corrupt sample costs only itself. A device that restarts (its counter or clock jumps
//! back and stays back) would be rejected forever, so after [`RESYNC_AFTER`] consecutive
//! rejections for going backwards the checker accepts the new timeline and counts a resync.

/// Consecutive "backwards"/duplicate rejections after which the new timeline is accepted.
pub const RESYNC_AFTER: u32 = 3;

/// Relative margin above the full-scale range within which a value is still plausible (a
/// clipped output rounds to the range, not exactly onto it).
pub const RANGE_MARGIN: f64 = 1e-3;

/// Full-scale ranges of the sensor, SI units; `f64::INFINITY` disables the check.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Gyroscope range, rad/s (each axis).
    pub gyro_rps: f64,
    /// Accelerometer range, m/s² (each axis).
    pub accel_mps2: f64,
}

/// How samples are numbered.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sequence {
    /// A device counter that wraps at `modulus` (the Xsens PacketCounter: 65536).
    Counter {
        /// The counter's reading.
        value: u64,
        /// Its period.
        modulus: u64,
    },
    /// No counter: a host-time step of n nominal periods means n − 1 samples were lost.
    Period {
        /// Nominal sample period, ns.
        period_ns: i64,
    },
    /// No counter and no known period: samples are taken as consecutive.
    Consecutive,
}

/// A device clock reading (a counter that wraps at `modulus`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CounterReading {
    /// Counter reading, ticks.
    pub ticks: u64,
    /// Counter period, ticks (2³² for SampleTimeFine).
    pub modulus: u64,
    /// Nominal tick length, ns.
    pub ns_per_tick: i64,
}

/// A decoded sample offered for publication.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Candidate {
    /// Host time stamp, ns (`CLOCK_MONOTONIC`).
    pub host_ns: i64,
    /// The device's clock at the sample, if it has one.
    pub device: Option<CounterReading>,
    /// How the sample is numbered.
    pub sequence: Sequence,
    /// Angular rate, rad/s (already in the published axes).
    pub gyro_rps: [f64; 3],
    /// Specific force, m/s² (already in the published axes).
    pub accel_mps2: [f64; 3],
}

/// Why a sample was not published.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Rejection {
    /// A rate or specific force is NaN or infinite.
    NotFinite,
    /// A value lies beyond the sensor's full-scale range (by more than [`RANGE_MARGIN`]).
    OutOfRange,
    /// The host stamp is earlier than the previous sample's.
    HostTimeBackwards,
    /// The device clock is earlier than the previous sample's (after unwrapping).
    DeviceTimeBackwards,
    /// The same counter value (or device time) as the previous sample, or a counter that
    /// went back.
    Duplicate,
}

/// A sample accepted for publication.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Accepted {
    /// Sequence number (0 for the first sample; gaps are drops).
    pub seq: u64,
    /// Samples lost just before this one.
    pub dropped: u64,
    /// The device clock unwrapped and converted to ns, if the device has one.
    pub device_ns: Option<i64>,
    /// Device time per sample since the previous accepted sample, ns (the measured interval,
    /// divided by the number of intervals when samples were lost); `None` for the first
    /// sample, after a resync, or without a device clock.
    pub device_interval_ns: Option<i64>,
    /// A value is at (within [`RANGE_MARGIN`] of) the full-scale range.
    pub at_range: bool,
}

/// Counters of [`SampleChecks`], since creation.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CheckCounters {
    /// Samples accepted.
    pub accepted: u64,
    /// Samples lost according to the sequence (sum of gaps).
    pub dropped: u64,
    /// Gaps (events, each of one or more lost samples).
    pub gaps: u64,
    /// Rejected: NaN or infinite values.
    pub rejected_not_finite: u64,
    /// Rejected: beyond the full-scale range.
    pub rejected_range: u64,
    /// Rejected: host time went backwards.
    pub rejected_host_back: u64,
    /// Rejected: device time went backwards.
    pub rejected_device_back: u64,
    /// Rejected: duplicate (or backwards) counter.
    pub rejected_duplicate: u64,
    /// Timelines accepted after [`RESYNC_AFTER`] consecutive backwards rejections.
    pub resyncs: u64,
    /// Accepted samples at the full-scale range.
    pub at_range: u64,
}

impl CheckCounters {
    /// The counters with short names for a `Health` report.
    pub fn named(&self) -> [(&'static str, u64); 10] {
        [
            ("samples_accepted", self.accepted),
            ("samples_dropped", self.dropped),
            ("sample_gaps", self.gaps),
            ("rejected_not_finite", self.rejected_not_finite),
            ("rejected_range", self.rejected_range),
            ("rejected_host_back", self.rejected_host_back),
            ("rejected_device_back", self.rejected_device_back),
            ("rejected_duplicate", self.rejected_duplicate),
            ("timeline_resyncs", self.resyncs),
            ("samples_at_range", self.at_range),
        ]
    }
}

#[derive(Debug, Clone, Copy)]
struct Last {
    host_ns: i64,
    seq: u64,
    counter: Option<u64>,
    device_raw: Option<u64>,
    device_ticks: i64,
}

/// The checker of one IMU stream.
#[derive(Debug, Clone)]
pub struct SampleChecks {
    limits: Limits,
    last: Option<Last>,
    backwards_run: u32,
    counters: CheckCounters,
}

fn wrapped_delta(now: u64, before: u64, modulus: u64) -> u64 {
    if modulus == 0 {
        now.wrapping_sub(before)
    } else {
        (now % modulus + modulus - before % modulus) % modulus
    }
}

impl SampleChecks {
    /// A checker with these ranges.
    pub fn new(limits: Limits) -> Self {
        Self {
            limits,
            last: None,
            backwards_run: 0,
            counters: CheckCounters::default(),
        }
    }

    /// Counters since creation.
    pub fn counters(&self) -> &CheckCounters {
        &self.counters
    }

    /// Checks `c` and numbers it, or says why it must not be published.
    pub fn check(&mut self, c: &Candidate) -> Result<Accepted, Rejection> {
        let values = c.gyro_rps.iter().chain(c.accel_mps2.iter());
        if values.clone().any(|v| !v.is_finite()) {
            self.counters.rejected_not_finite += 1;
            return Err(Rejection::NotFinite);
        }
        let over = |v: &f64, range: f64| v.abs() > range * (1.0 + RANGE_MARGIN);
        let at = |v: &f64, range: f64| v.abs() >= range * (1.0 - RANGE_MARGIN);
        if c.gyro_rps.iter().any(|v| over(v, self.limits.gyro_rps))
            || c.accel_mps2.iter().any(|v| over(v, self.limits.accel_mps2))
        {
            self.counters.rejected_range += 1;
            return Err(Rejection::OutOfRange);
        }
        let at_range = c.gyro_rps.iter().any(|v| at(v, self.limits.gyro_rps))
            || c.accel_mps2.iter().any(|v| at(v, self.limits.accel_mps2));

        let Some(last) = self.last else {
            return Ok(self.accept_first(c, at_range, 0));
        };
        match self.step(&last, c) {
            Ok((gap, device_ticks)) => {
                self.backwards_run = 0;
                let seq = last.seq.saturating_add(1).saturating_add(gap);
                let intervals = i64::try_from(gap).unwrap_or(i64::MAX).saturating_add(1);
                let device_interval_ns = match (device_ticks, c.device) {
                    (Some(t), Some(d)) => Some((t - last.device_ticks).saturating_mul(d.ns_per_tick) / intervals),
                    _ => None,
                };
                self.last = Some(Last {
                    host_ns: c.host_ns,
                    seq,
                    counter: counter_of(c),
                    device_raw: c.device.map(|d| d.ticks),
                    device_ticks: device_ticks.unwrap_or(0),
                });
                self.counters.accepted += 1;
                self.counters.dropped = self.counters.dropped.saturating_add(gap);
                self.counters.gaps += u64::from(gap > 0);
                self.counters.at_range += u64::from(at_range);
                Ok(Accepted {
                    seq,
                    dropped: gap,
                    device_ns: device_ticks.zip(c.device).map(|(t, d)| t.saturating_mul(d.ns_per_tick)),
                    device_interval_ns,
                    at_range,
                })
            }
            Err(r) => {
                match r {
                    Rejection::HostTimeBackwards => self.counters.rejected_host_back += 1,
                    Rejection::DeviceTimeBackwards => self.counters.rejected_device_back += 1,
                    _ => self.counters.rejected_duplicate += 1,
                }
                self.backwards_run += 1;
                if self.backwards_run >= RESYNC_AFTER {
                    // The device restarted (or its clock was reset): follow the new timeline.
                    self.counters.resyncs += 1;
                    self.backwards_run = 0;
                    return Ok(self.accept_first(c, at_range, last.seq.saturating_add(1)));
                }
                Err(r)
            }
        }
    }

    fn accept_first(&mut self, c: &Candidate, at_range: bool, seq: u64) -> Accepted {
        let device_ticks = c.device.map(|d| (d.ticks % d.modulus.max(1)) as i64);
        self.last = Some(Last {
            host_ns: c.host_ns,
            seq,
            counter: counter_of(c),
            device_raw: c.device.map(|d| d.ticks),
            device_ticks: device_ticks.unwrap_or(0),
        });
        self.counters.accepted += 1;
        self.counters.at_range += u64::from(at_range);
        Accepted {
            seq,
            dropped: 0,
            device_ns: device_ticks.zip(c.device).map(|(t, d)| t.saturating_mul(d.ns_per_tick)),
            device_interval_ns: None,
            at_range,
        }
    }

    /// The gap before `c` and its unwrapped device ticks, or why it goes backwards.
    fn step(&self, last: &Last, c: &Candidate) -> Result<(u64, Option<i64>), Rejection> {
        if c.host_ns < last.host_ns {
            return Err(Rejection::HostTimeBackwards);
        }
        let device_ticks = match (c.device, last.device_raw) {
            (Some(d), Some(before)) => {
                let delta = wrapped_delta(d.ticks, before, d.modulus);
                if delta == 0 {
                    return Err(Rejection::Duplicate);
                }
                if d.modulus > 0 && delta > d.modulus / 2 {
                    return Err(Rejection::DeviceTimeBackwards);
                }
                Some(last.device_ticks.saturating_add(delta as i64))
            }
            (Some(d), None) => Some((d.ticks % d.modulus.max(1)) as i64),
            (None, _) => None,
        };
        let gap = match (c.sequence, last.counter) {
            (Sequence::Counter { value, modulus }, Some(before)) => {
                let d = wrapped_delta(value, before, modulus);
                if d == 0 || (modulus > 0 && d > modulus / 2) {
                    return Err(Rejection::Duplicate);
                }
                d - 1
            }
            (Sequence::Period { period_ns }, _) if period_ns > 0 => {
                let n = ((c.host_ns as f64 - last.host_ns as f64) / period_ns as f64).round();
                (n.max(1.0) as u64) - 1
            }
            _ => 0,
        };
        Ok((gap, device_ticks))
    }
}

fn counter_of(c: &Candidate) -> Option<u64> {
    match c.sequence {
        Sequence::Counter { value, .. } => Some(value),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LIMITS: Limits = Limits {
        gyro_rps: 10.0,
        accel_mps2: 100.0,
    };

    fn xsens(host_ns: i64, pc: u64, stf: u64) -> Candidate {
        Candidate {
            host_ns,
            device: Some(CounterReading {
                ticks: stf,
                modulus: 1 << 32,
                ns_per_tick: 100_000,
            }),
            sequence: Sequence::Counter {
                value: pc,
                modulus: 65_536,
            },
            gyro_rps: [0.1, 0.2, 0.3],
            accel_mps2: [0.0, 0.0, -9.8],
        }
    }

    #[test]
    fn counter_wrap_and_gaps() {
        let mut c = SampleChecks::new(LIMITS);
        let s0 = (1u64 << 32) - 50;
        let a = c.check(&xsens(1_000, 65_534, s0)).unwrap();
        assert_eq!((a.seq, a.dropped, a.device_ns), (0, 0, Some(s0 as i64 * 100_000)));
        let b = c.check(&xsens(2_000, 65_535, s0 + 50)).unwrap();
        assert_eq!((b.seq, b.dropped, b.device_interval_ns), (1, 0, Some(5_000_000)));
        // Both counters wrap here; three samples lost.
        let d = c.check(&xsens(3_000, 3, s0 + 250)).unwrap();
        assert_eq!((d.seq, d.dropped), (5, 3));
        assert_eq!(d.device_ns, Some((s0 as i64 + 250) * 100_000), "unwrapped past 2^32");
        assert_eq!(d.device_interval_ns, Some(5_000_000));
        assert_eq!(c.counters().dropped, 3);
        assert_eq!(c.counters().gaps, 1);
    }

    #[test]
    fn rejections_do_not_advance_the_state() {
        let mut c = SampleChecks::new(LIMITS);
        c.check(&xsens(1_000, 10, 100)).unwrap();
        let mut nan = xsens(2_000, 11, 150);
        nan.gyro_rps[1] = f64::NAN;
        assert_eq!(c.check(&nan), Err(Rejection::NotFinite));
        let mut big = xsens(2_000, 11, 150);
        big.accel_mps2[2] = -150.0;
        assert_eq!(c.check(&big), Err(Rejection::OutOfRange));
        assert_eq!(c.check(&xsens(500, 11, 150)), Err(Rejection::HostTimeBackwards));
        assert_eq!(c.check(&xsens(2_000, 11, 90)), Err(Rejection::DeviceTimeBackwards));
        // The next good sample follows the last accepted one: the rejected ones are not drops
        // (the counter says 11 is next and it is).
        let ok = c.check(&xsens(2_000, 11, 150)).unwrap();
        assert_eq!((ok.seq, ok.dropped), (1, 0));
        assert_eq!(c.check(&xsens(2_000, 11, 200)), Err(Rejection::Duplicate));
        assert_eq!(c.check(&xsens(2_500, 12, 200)).unwrap().seq, 2);
        let k = c.counters();
        assert_eq!(
            (
                k.rejected_not_finite,
                k.rejected_range,
                k.rejected_host_back,
                k.rejected_device_back,
                k.rejected_duplicate
            ),
            (1, 1, 1, 1, 1)
        );
    }

    #[test]
    fn at_range_is_flagged_not_rejected() {
        let mut c = SampleChecks::new(LIMITS);
        let mut s = xsens(1_000, 0, 0);
        s.gyro_rps[0] = -10.0005;
        assert!(c.check(&s).unwrap().at_range);
        assert_eq!(c.counters().at_range, 1);
    }

    #[test]
    fn a_restarted_device_is_followed_after_three_samples() {
        let mut c = SampleChecks::new(LIMITS);
        c.check(&xsens(1_000, 40_000, 9_000_000)).unwrap();
        for k in 0..2 {
            assert!(c.check(&xsens(2_000 + k, k as u64, 50 * k as u64)).is_err());
        }
        let a = c.check(&xsens(3_000, 2, 100)).unwrap();
        assert_eq!(a.seq, 1);
        assert_eq!(a.device_interval_ns, None);
        let b = c.check(&xsens(4_000, 3, 150)).unwrap();
        assert_eq!((b.seq, b.dropped), (2, 0));
        assert_eq!(c.counters().resyncs, 1);
    }

    #[test]
    fn period_gaps_from_host_stamps() {
        let mut c = SampleChecks::new(LIMITS);
        let s = |t: i64| Candidate {
            host_ns: t,
            device: None,
            sequence: Sequence::Period { period_ns: 5_000_000 },
            gyro_rps: [0.0; 3],
            accel_mps2: [0.0; 3],
        };
        assert_eq!(c.check(&s(0)).unwrap().seq, 0);
        assert_eq!(c.check(&s(5_100_000)).unwrap().seq, 1);
        // Jitter below half a period is not a gap; equal stamps are not duplicates.
        assert_eq!(c.check(&s(7_400_000)).unwrap().seq, 2);
        assert_eq!(c.check(&s(7_400_000)).unwrap().seq, 3);
        let g = c.check(&s(27_400_000)).unwrap();
        assert_eq!((g.seq, g.dropped), (7, 3));
        assert_eq!(c.check(&s(1_000)), Err(Rejection::HostTimeBackwards));
    }
}
