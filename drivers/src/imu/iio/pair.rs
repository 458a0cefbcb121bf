//! Pairing the two halves of a split IMU: many kernel drivers register the gyroscope and the
//! accelerometer of one chip as two IIO devices with a buffer each (`inv_icm42600`,
//! `st_lsm6dsx`; BMI088 as `bmg160` + `bmi088-accel`). Their records are joined here by
//! kernel time stamp. Pure state machine, fixed memory.
//!
//! Both streams arrive in time order. A record is paired with the other stream's oldest
//! waiting record when their stamps are within the tolerance (half a sample period: FIFO
//! drivers that read both sensors in one packet give equal stamps; separate chips differ by up
//! to the period's fraction their clocks drift apart); waiting records older than that can no
//! longer find a partner and are dropped as unpaired. The pair is stamped with the gyroscope's
//! time.

use std::collections::VecDeque;

/// Records waiting per side at most (a longer wait means the other side stopped).
pub const QUEUE: usize = 64;

/// One half: a triad with its stamp.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Half {
    /// Kernel time stamp, ns.
    pub ts: i64,
    /// The triad, SI units, device axes.
    pub v: [f64; 3],
    /// Temperature, °C (NaN if not known).
    pub temperature_c: f64,
    /// An axis sits at full scale.
    pub at_full_scale: bool,
}

/// A joined sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pair {
    /// The gyroscope's stamp, ns.
    pub ts: i64,
    /// Angular rate, rad/s.
    pub gyro: [f64; 3],
    /// Acceleration, m/s².
    pub accel: [f64; 3],
    /// Temperature, °C (the gyroscope's if known, else the accelerometer's).
    pub temperature_c: f64,
    /// Either half sits at full scale.
    pub at_full_scale: bool,
}

/// Counters of the pairing.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PairCounters {
    /// Pairs formed.
    pub pairs: u64,
    /// Gyroscope records that found no accelerometer record.
    pub unpaired_gyro: u64,
    /// Accelerometer records that found no gyroscope record.
    pub unpaired_accel: u64,
}

/// Joins gyroscope and accelerometer records by time stamp.
#[derive(Debug, Clone)]
pub struct Pairer {
    tol_ns: i64,
    gyro: VecDeque<Half>,
    accel: VecDeque<Half>,
    counters: PairCounters,
}

impl Pairer {
    /// A pairer accepting stamps up to `tol_ns` apart.
    pub fn new(tol_ns: i64) -> Self {
        Self {
            tol_ns,
            gyro: VecDeque::with_capacity(QUEUE),
            accel: VecDeque::with_capacity(QUEUE),
            counters: PairCounters::default(),
        }
    }

    /// Counters since creation.
    pub fn counters(&self) -> &PairCounters {
        &self.counters
    }

    /// Forgets waiting records (the devices were reopened); they count as unpaired.
    pub fn clear(&mut self) {
        self.counters.unpaired_gyro += self.gyro.len() as u64;
        self.counters.unpaired_accel += self.accel.len() as u64;
        self.gyro.clear();
        self.accel.clear();
    }

    /// A gyroscope record; returns the pair it completes, if any.
    pub fn push_gyro(&mut self, h: Half) -> Option<Pair> {
        let tol = self.tol_ns;
        let c = &mut self.counters;
        Self::join(
            h,
            &mut self.accel,
            &mut self.gyro,
            tol,
            &mut c.unpaired_accel,
            &mut c.unpaired_gyro,
        )
        .map(|a| self.pair(h, a))
    }

    /// An accelerometer record; returns the pair it completes, if any.
    pub fn push_accel(&mut self, h: Half) -> Option<Pair> {
        let tol = self.tol_ns;
        let c = &mut self.counters;
        Self::join(
            h,
            &mut self.gyro,
            &mut self.accel,
            tol,
            &mut c.unpaired_gyro,
            &mut c.unpaired_accel,
        )
        .map(|g| self.pair(g, h))
    }

    fn pair(&mut self, g: Half, a: Half) -> Pair {
        self.counters.pairs += 1;
        Pair {
            ts: g.ts,
            gyro: g.v,
            accel: a.v,
            temperature_c: if g.temperature_c.is_finite() {
                g.temperature_c
            } else {
                a.temperature_c
            },
            at_full_scale: g.at_full_scale || a.at_full_scale,
        }
    }

    /// Looks for `h`'s partner in `other`; queues `h` in `own` when there is none yet.
    fn join(
        h: Half,
        other: &mut VecDeque<Half>,
        own: &mut VecDeque<Half>,
        tol: i64,
        other_lost: &mut u64,
        own_lost: &mut u64,
    ) -> Option<Half> {
        // Records of the other side too old for `h` can only be older still for what follows.
        while other.front().is_some_and(|o| o.ts < h.ts.saturating_sub(tol)) {
            other.pop_front();
            *other_lost += 1;
        }
        if let Some(o) = other.front()
            && o.ts <= h.ts.saturating_add(tol)
        {
            return other.pop_front();
        }
        if own.len() == QUEUE {
            own.pop_front();
            *own_lost += 1;
        }
        own.push_back(h);
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn h(ts: i64, x: f64) -> Half {
        Half {
            ts,
            v: [x, 0.0, 0.0],
            temperature_c: f64::NAN,
            at_full_scale: false,
        }
    }

    #[test]
    fn pairs_by_stamp_whatever_the_arrival_order() {
        let mut p = Pairer::new(2_500_000);
        // Gyro records arrive ahead of the accelerometer's (separate buffers, separate reads).
        assert_eq!(p.push_gyro(h(0, 1.0)), None);
        assert_eq!(p.push_gyro(h(5_000_000, 2.0)), None);
        let a = p.push_accel(h(100_000, 10.0)).unwrap();
        assert_eq!((a.ts, a.gyro[0], a.accel[0]), (0, 1.0, 10.0));
        // An accelerometer record lost: gyro 2 waits, gyro 3 comes, accel 3 pairs with 3 and
        // gyro 2 is dropped as unpaired.
        assert_eq!(p.push_gyro(h(10_000_000, 3.0)), None);
        let b = p.push_accel(h(10_000_000, 30.0)).unwrap();
        assert_eq!((b.ts, b.gyro[0], b.accel[0]), (10_000_000, 3.0, 30.0));
        assert_eq!(p.counters().unpaired_gyro, 1);
        // The other way round.
        assert_eq!(p.push_accel(h(15_000_000, 40.0)), None);
        let c = p.push_gyro(h(15_000_000, 4.0)).unwrap();
        assert_eq!(c.accel[0], 40.0);
        assert_eq!(p.counters().pairs, 3);
    }

    #[test]
    fn a_silent_side_does_not_grow_memory() {
        let mut p = Pairer::new(1_000);
        for k in 0..1_000 {
            assert_eq!(p.push_gyro(h(k * 5_000, 0.0)), None);
        }
        assert_eq!(p.counters().unpaired_gyro, 1_000 - QUEUE as u64);
        p.clear();
        assert_eq!(p.counters().unpaired_gyro, 1_000);
    }
}
