//! Staleness of the estimator's inputs: an input (one IMU, receiver or PPS source) is stale
//! when nothing arrived for its learned sample interval plus [`STALE_MARGIN_NS`]. The
//! estimator process wakes at the nearest deadline (not only on samples), flags the input in
//! its Health at once (counter `stale_<kind>_<id>`: 0 while fresh, else the host time in ns
//! at which it was declared stale) and clears the flag with the next sample. An input whose
//! publishing process is gone (no live publisher left on its service, e.g. after `kill -9`) is
//! declared stale at once, without waiting for its interval: [`Liveness::gone`]. Pure: the
//! caller passes the times and what it found.

/// How long past its expected next sample an input is declared stale, ns.
pub const STALE_MARGIN_NS: i64 = 100_000_000;

/// One input's state.
#[derive(Debug, Clone)]
pub struct Input {
    /// Name as in the Health counter (`imu_1`, `gnss_0`, `pps_0`).
    pub name: String,
    last_rx_ns: Option<i64>,
    last_stamp_ns: Option<i64>,
    interval_ns: f64,
    stale_since_ns: Option<i64>,
    gone: bool,
}

impl Input {
    /// When it was declared stale, if it is.
    pub fn stale_since_ns(&self) -> Option<i64> {
        self.stale_since_ns
    }

    /// The learned sample interval, ns.
    pub fn interval_ns(&self) -> f64 {
        self.interval_ns
    }

    /// True while its publisher is gone (from [`Liveness::gone`] until its next sample).
    pub fn is_gone(&self) -> bool {
        self.gone
    }

    fn deadline(&self) -> Option<i64> {
        match (self.last_rx_ns, self.stale_since_ns) {
            (Some(t), None) => Some(t + self.interval_ns as i64 + STALE_MARGIN_NS),
            _ => None,
        }
    }
}

/// What changed for an input.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Change {
    /// It went stale now.
    Stale,
    /// A sample arrived after it had been stale, `stale_ns` later.
    Resumed {
        /// How long it was stale, ns.
        stale_ns: i64,
    },
}

/// The inputs of one process.
#[derive(Debug, Clone, Default)]
pub struct Liveness {
    inputs: Vec<Input>,
}

impl Liveness {
    /// Adds an input with its nominal interval (used until two samples tell the real one).
    pub fn add(&mut self, name: &str, nominal_interval_ns: i64) -> usize {
        self.inputs.push(Input {
            name: name.to_string(),
            last_rx_ns: None,
            last_stamp_ns: None,
            interval_ns: nominal_interval_ns as f64,
            stale_since_ns: None,
            gone: false,
        });
        self.inputs.len() - 1
    }

    /// The inputs.
    pub fn inputs(&self) -> &[Input] {
        &self.inputs
    }

    /// Number of inputs stale now.
    pub fn stale_count(&self) -> usize {
        self.inputs.iter().filter(|i| i.stale_since_ns.is_some()).count()
    }

    /// A sample stamped `stamp_ns` of input `i` was received at `now_ns`.
    pub fn seen(&mut self, i: usize, stamp_ns: i64, now_ns: i64) -> Option<Change> {
        let x = &mut self.inputs[i];
        if let Some(prev) = x.last_stamp_ns {
            let d = (stamp_ns - prev) as f64;
            // The interval follows the samples' own spacing (a slow average: single gaps and
            // bunched deliveries barely move it), within 1 ms … 5 s.
            if d > 0.0 && x.stale_since_ns.is_none() {
                x.interval_ns = (0.95 * x.interval_ns + 0.05 * d).clamp(1e6, 5e9);
            }
        }
        x.last_stamp_ns = Some(stamp_ns);
        x.last_rx_ns = Some(now_ns);
        x.gone = false;
        x.stale_since_ns
            .take()
            .map(|t| Change::Resumed { stale_ns: now_ns - t })
    }

    /// Input `i` has no live publisher at `now_ns` (its process exited or was killed). An input
    /// that had samples is declared stale now (`Some(Stale)`) unless it already is; one that
    /// never had any is left alone (its driver may not have started yet).
    pub fn gone(&mut self, i: usize, now_ns: i64) -> Option<Change> {
        let x = &mut self.inputs[i];
        x.last_rx_ns?;
        x.gone = true;
        if x.stale_since_ns.is_some() {
            return None;
        }
        x.stale_since_ns = Some(now_ns);
        Some(Change::Stale)
    }

    /// Marks inputs whose deadline passed; calls `f(index, change)` for each.
    pub fn check(&mut self, now_ns: i64, mut f: impl FnMut(usize, &Input, Change)) {
        for (i, x) in self.inputs.iter_mut().enumerate() {
            if x.deadline().is_some_and(|d| now_ns >= d) {
                x.stale_since_ns = Some(now_ns);
                f(i, x, Change::Stale);
            }
        }
    }

    /// The earliest deadline of the fresh inputs.
    pub fn next_deadline(&self) -> Option<i64> {
        self.inputs.iter().filter_map(Input::deadline).min()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stale_after_interval_plus_margin_and_back() {
        let mut l = Liveness::default();
        let imu = l.add("imu_1", 5_000_000);
        let gnss = l.add("gnss_0", 1_000_000_000);
        let mut t = 0;
        for k in 0..100 {
            t = k * 5_000_000;
            assert_eq!(l.seen(imu, t, t + 1_000), None);
        }
        l.seen(gnss, 0, 10);
        assert_eq!(l.next_deadline(), Some(t + 1_000 + 5_000_000 + STALE_MARGIN_NS));
        let mut changes = Vec::new();
        l.check(t + 50_000_000, |i, _, c| changes.push((i, c)));
        assert!(changes.is_empty());
        l.check(t + 1_000 + 5_000_000 + STALE_MARGIN_NS, |i, _, c| changes.push((i, c)));
        assert_eq!(changes, vec![(imu, Change::Stale)]);
        assert_eq!(l.stale_count(), 1);
        changes.clear();
        l.check(1_200_000_000, |i, _, c| changes.push((i, c)));
        assert_eq!(changes, vec![(gnss, Change::Stale)], "1 s interval + 100 ms");
        // Flagged once, not again.
        changes.clear();
        l.check(9_000_000_000, |i, _, c| changes.push((i, c)));
        assert!(changes.is_empty());
        assert!(matches!(
            l.seen(imu, 9_000_000_000, 9_000_000_000),
            Some(Change::Resumed { .. })
        ));
        assert_eq!(l.stale_count(), 1);
        assert!(
            (l.inputs()[imu].interval_ns() - 5e6).abs() < 1e3,
            "the gap did not teach a longer interval"
        );
    }

    #[test]
    fn gone_publisher_is_stale_at_once_until_the_next_sample() {
        let mut l = Liveness::default();
        let gnss = l.add("gnss_0", 1_000_000_000);
        let pps = l.add("pps_0", 1_000_000_000);
        // Never seen: its driver may not be up yet.
        assert_eq!(l.gone(gnss, 5), None);
        assert!(!l.inputs()[gnss].is_gone());
        l.seen(gnss, 0, 10);
        l.seen(pps, 0, 10);
        // 20 ms after the last fix, far before interval + margin.
        assert_eq!(l.gone(gnss, 20_000_010), Some(Change::Stale));
        assert_eq!(l.inputs()[gnss].stale_since_ns(), Some(20_000_010));
        assert!(l.inputs()[gnss].is_gone());
        // Once only; no deadline while stale.
        assert_eq!(l.gone(gnss, 30_000_000), None);
        assert_eq!(l.next_deadline(), Some(10 + 1_000_000_000 + STALE_MARGIN_NS));
        // Already stale from silence: marked gone, not declared again.
        let mut changes = Vec::new();
        l.check(2_000_000_000, |i, _, c| changes.push((i, c)));
        assert_eq!(changes, vec![(pps, Change::Stale)]);
        assert_eq!(l.gone(pps, 2_100_000_000), None);
        assert!(l.inputs()[pps].is_gone());
        // The restarted driver's first sample brings it back.
        assert_eq!(
            l.seen(gnss, 3_000_000_000, 3_000_000_000),
            Some(Change::Resumed {
                stale_ns: 3_000_000_000 - 20_000_010
            })
        );
        assert!(!l.inputs()[gnss].is_gone());
        assert_eq!(l.stale_count(), 1);
    }
}
