//! Validation of raw 1 PPS edges before they are published: missing, duplicated, early and
//! late edges are detected and counted, and the stamp jitter of the source is measured.
//!
//! Pure state machine: fed with raw edges (host time, source counter), no clocks or I/O.
//!
//! Model. A receiver emits one assert edge per GNSS second; on the host clock consecutive
//! edges are P = 1 s·(1 + y) apart (y the host clock's fractional frequency error, |y| ≤ 1e−4
//! for any crystal) plus the stamp jitter. For an edge stamped d after the last accepted one,
//! n = round(d / P) seconds have passed and the residual r = d − n·P must be within the gate
//! `gate_ns + freq_tolerance·|d|`:
//!
//! - n = 0 and |d| within the gate, or the same non-zero source counter: a **duplicate**
//!   (the same edge delivered twice); rejected;
//! - r outside the gate (including n = 0 with d beyond the gate, and time going backwards):
//!   **early/late** (a spurious edge, a glitch, a stamp taken at the wrong moment); rejected,
//!   the reference stays on the last good edge;
//! - n ≥ 2: n − 1 edges are **missing**; the edge is accepted.
//!
//! After [`ValidatorConfig::resync_after`] consecutive early/late edges the reference itself
//! is taken to be wrong (the first edge was spurious, or the receiver restarted its time
//! base) and the validator re-anchors on the current edge (counted as a resync).
//!
//! The period P is learned from accepted one-second intervals (running mean over the last
//! ~[`PERIOD_WINDOW`] intervals), and so is the jitter: for white stamp noise of σ on each
//! edge the one-second interval residuals have variance 2σ², so σ̂ = √(mean r² / 2).

/// Intervals averaged for the period and jitter estimates (exponential window length).
pub const PERIOD_WINDOW: f64 = 64.0;
/// Intervals needed before the learned period replaces the nominal tolerance.
const LEARNED_AFTER: u32 = 8;

/// Settings of the validator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ValidatorConfig {
    /// Nominal edge period, ns (1 PPS: 1e9).
    pub nominal_period_ns: f64,
    /// Fixed part of the early/late gate, ns (default 1 ms: far above any stamp jitter,
    /// far below the spacing of a spurious edge; the clock model gates finely).
    pub gate_ns: f64,
    /// Frequency tolerance before the period is learned (default 1e−4, any crystal).
    pub freq_tolerance: f64,
    /// Frequency tolerance once the period is learned (default 1e−5: wander over long gaps).
    pub learned_freq_tolerance: f64,
    /// Consecutive early/late edges after which the validator re-anchors (default 3).
    pub resync_after: u32,
}

impl Default for ValidatorConfig {
    fn default() -> Self {
        Self {
            nominal_period_ns: 1e9,
            gate_ns: 1e6,
            freq_tolerance: 1e-4,
            learned_freq_tolerance: 1e-5,
            resync_after: 3,
        }
    }
}

/// A raw edge as a source delivers it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RawEdge {
    /// Host time of the edge, `CLOCK_MONOTONIC` ns.
    pub host_ns: i64,
    /// The source's own edge counter (kernel `assert_sequence`, serial DCD count), 0 if none.
    pub source_seq: u64,
    /// True for the assert (leading) edge.
    pub assert: bool,
}

/// What the validator decided about one edge.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Verdict {
    /// A good edge. `index` counts seconds since the first accepted edge (a gap in it is a
    /// missing edge); `missing` edges were skipped just before this one.
    Accepted {
        /// Seconds since the first accepted edge.
        index: u64,
        /// Edges missing between the previous accepted edge and this one.
        missing: u64,
        /// Residual against the learned period, ns (0 for the first edge).
        residual_ns: f64,
    },
    /// The validator re-anchored on this edge after persistent early/late edges; it is
    /// accepted and starts a new index sequence continuing from the previous one.
    Resynced {
        /// Index given to this edge.
        index: u64,
    },
    /// The same edge again.
    Duplicate,
    /// Not on the one-second grid of the previous good edges; residual in ns.
    EarlyLate(f64),
    /// A clear (trailing) edge; not used.
    Clear,
}

/// Counters of the validator (all since creation).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ValidatorCounters {
    /// Assert edges seen.
    pub edges: u64,
    /// Edges accepted (including resync anchors).
    pub accepted: u64,
    /// Edges missing (inferred from gaps of two or more seconds).
    pub missing: u64,
    /// Duplicates rejected.
    pub duplicate: u64,
    /// Early/late edges rejected.
    pub early_late: u64,
    /// Re-anchorings after persistent early/late edges.
    pub resyncs: u64,
    /// Clear edges ignored.
    pub clear: u64,
}

impl ValidatorCounters {
    /// The counters with names for a `Health` report.
    pub fn named(&self) -> [(&'static str, u64); 7] {
        [
            ("pps_edges", self.edges),
            ("pps_accepted", self.accepted),
            ("pps_missing", self.missing),
            ("pps_duplicate", self.duplicate),
            ("pps_early_late", self.early_late),
            ("pps_resyncs", self.resyncs),
            ("pps_clear_edges", self.clear),
        ]
    }
}

#[derive(Debug, Clone, Copy)]
struct Anchor {
    host_ns: i64,
    source_seq: u64,
    index: u64,
}

/// The PPS edge validator.
#[derive(Debug, Clone)]
pub struct EdgeValidator {
    cfg: ValidatorConfig,
    last: Option<Anchor>,
    period_ns: f64,
    intervals: u32,
    /// Running mean of the squared one-second residuals, ns².
    mean_r2: f64,
    consecutive_rejects: u32,
    counters: ValidatorCounters,
}

impl EdgeValidator {
    /// A validator that has seen nothing.
    pub fn new(cfg: ValidatorConfig) -> Self {
        Self {
            cfg,
            last: None,
            period_ns: cfg.nominal_period_ns,
            intervals: 0,
            mean_r2: 0.0,
            consecutive_rejects: 0,
            counters: ValidatorCounters::default(),
        }
    }

    /// Counters so far.
    pub fn counters(&self) -> &ValidatorCounters {
        &self.counters
    }

    /// Learned edge period, ns (the nominal one until edges were seen).
    pub fn period_ns(&self) -> f64 {
        self.period_ns
    }

    /// Measured 1-sigma stamp jitter, ns, once at least 8 (`LEARNED_AFTER`) one-second intervals
    /// were seen.
    pub fn measured_jitter_ns(&self) -> Option<f64> {
        (self.intervals >= LEARNED_AFTER).then(|| (self.mean_r2 / 2.0).sqrt())
    }

    fn gate_ns(&self, d: f64) -> f64 {
        let tol = if self.intervals >= LEARNED_AFTER {
            self.cfg.learned_freq_tolerance
        } else {
            self.cfg.freq_tolerance
        };
        self.cfg.gate_ns + tol * d.abs()
    }

    /// Judges one raw edge.
    pub fn push(&mut self, edge: &RawEdge) -> Verdict {
        if !edge.assert {
            self.counters.clear += 1;
            return Verdict::Clear;
        }
        self.counters.edges += 1;
        let Some(last) = self.last else {
            self.anchor(edge, 0);
            self.counters.accepted += 1;
            return Verdict::Accepted {
                index: 0,
                missing: 0,
                residual_ns: 0.0,
            };
        };
        let d = edge.host_ns.saturating_sub(last.host_ns) as f64;
        let gate = self.gate_ns(d);
        let same_counter = edge.source_seq != 0 && edge.source_seq == last.source_seq;
        if same_counter || d.abs() <= gate.min(self.period_ns / 2.0) {
            self.counters.duplicate += 1;
            return Verdict::Duplicate;
        }
        let n = (d / self.period_ns).round();
        let residual = d - n * self.period_ns;
        if n < 1.0 || residual.abs() > gate {
            self.counters.early_late += 1;
            self.consecutive_rejects += 1;
            if self.consecutive_rejects >= self.cfg.resync_after {
                self.counters.resyncs += 1;
                self.counters.accepted += 1;
                let index = last.index.saturating_add(n.max(1.0) as u64);
                self.anchor(edge, index);
                return Verdict::Resynced { index };
            }
            return Verdict::EarlyLate(residual);
        }
        let n = n as u64;
        if n == 1 {
            self.learn(d, residual);
        }
        let missing = n - 1;
        self.counters.missing = self.counters.missing.saturating_add(missing);
        self.counters.accepted += 1;
        let index = last.index.saturating_add(n);
        self.anchor(edge, index);
        Verdict::Accepted {
            index,
            missing,
            residual_ns: residual,
        }
    }

    fn anchor(&mut self, edge: &RawEdge, index: u64) {
        self.last = Some(Anchor {
            host_ns: edge.host_ns,
            source_seq: edge.source_seq,
            index,
        });
        self.consecutive_rejects = 0;
    }

    fn learn(&mut self, interval_ns: f64, residual_ns: f64) {
        self.intervals = self.intervals.saturating_add(1);
        let w = 1.0 / (self.intervals as f64).min(PERIOD_WINDOW);
        self.period_ns += w * (interval_ns - self.period_ns);
        self.mean_r2 += w * (residual_ns * residual_ns - self.mean_r2);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn edge(host_ns: i64, source_seq: u64) -> RawEdge {
        RawEdge {
            host_ns,
            source_seq,
            assert: true,
        }
    }

    /// Deterministic approximately Gaussian noise (sum of 12 uniforms).
    fn gauss(state: &mut u64) -> f64 {
        let mut s = 0.0;
        for _ in 0..12 {
            *state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            s += (*state >> 11) as f64 / (1u64 << 53) as f64;
        }
        s - 6.0
    }

    const P: i64 = 1_000_000_500; // host 0.5 ppm fast

    #[test]
    fn clean_edges_are_accepted_with_consecutive_indices() {
        let mut v = EdgeValidator::new(ValidatorConfig::default());
        for k in 0..20 {
            match v.push(&edge(5_000_000_000 + k * P, k as u64 + 1)) {
                Verdict::Accepted { index, missing, .. } => assert_eq!((index, missing), (k as u64, 0)),
                other => panic!("edge {k}: {other:?}"),
            }
        }
        assert!((v.period_ns() - P as f64).abs() < 1.0);
        assert_eq!(v.counters().accepted, 20);
    }

    #[test]
    fn missing_duplicate_early_and_late_edges_are_counted() {
        let mut v = EdgeValidator::new(ValidatorConfig::default());
        let t = |k: i64| 1_000_000_000 + k * P;
        for k in 0..10 {
            v.push(&edge(t(k), k as u64 + 1));
        }
        // The same edge twice (same counter), and again with no counter.
        assert_eq!(v.push(&edge(t(9), 10)), Verdict::Duplicate);
        assert_eq!(v.push(&edge(t(9) + 3_000, 0)), Verdict::Duplicate);
        // A spurious edge 0.3 s after a good one; a glitch 5 ms late.
        assert!(matches!(v.push(&edge(t(9) + 300_000_000, 0)), Verdict::EarlyLate(_)));
        assert!(matches!(v.push(&edge(t(10) + 5_000_000, 0)), Verdict::EarlyLate(_)));
        // The good edge of second 10 is still accepted; then three are lost.
        assert!(matches!(
            v.push(&edge(t(10), 11)),
            Verdict::Accepted {
                index: 10,
                missing: 0,
                ..
            }
        ));
        assert!(matches!(
            v.push(&edge(t(14), 15)),
            Verdict::Accepted {
                index: 14,
                missing: 3,
                ..
            }
        ));
        // Time going backwards is early.
        assert!(matches!(v.push(&edge(t(12), 0)), Verdict::EarlyLate(_)));
        let c = *v.counters();
        assert_eq!((c.duplicate, c.early_late, c.missing, c.accepted), (2, 3, 3, 12));
        // Clear edges are ignored.
        let clear = RawEdge {
            assert: false,
            ..edge(t(14) + 100_000_000, 0)
        };
        assert_eq!(v.push(&clear), Verdict::Clear);
    }

    #[test]
    fn a_spurious_first_edge_is_abandoned_after_three_rejections() {
        let mut v = EdgeValidator::new(ValidatorConfig::default());
        v.push(&edge(400_000_000, 0)); // spurious
        let t = |k: i64| 1_000_000_000 + k * P;
        assert!(matches!(v.push(&edge(t(0), 0)), Verdict::EarlyLate(_)));
        assert!(matches!(v.push(&edge(t(1), 0)), Verdict::EarlyLate(_)));
        assert!(matches!(v.push(&edge(t(2), 0)), Verdict::Resynced { .. }));
        assert!(matches!(v.push(&edge(t(3), 0)), Verdict::Accepted { missing: 0, .. }));
        assert_eq!(v.counters().resyncs, 1);
    }

    #[test]
    fn measures_the_stamp_jitter() {
        let mut v = EdgeValidator::new(ValidatorConfig::default());
        let mut rng = 11u64;
        for k in 0..2000 {
            let h = 1_000_000_000 + k * P + (gauss(&mut rng) * 30_000.0) as i64;
            assert!(
                matches!(v.push(&edge(h, 0)), Verdict::Accepted { missing: 0, .. }),
                "{k}"
            );
        }
        let j = v.measured_jitter_ns().expect("learned");
        // Exponential window of 64 intervals: ±~15 % statistical spread.
        assert!((j / 30_000.0 - 1.0).abs() < 0.35, "jitter {j}");
    }

    #[test]
    fn never_panics_on_extreme_stamps() {
        let mut v = EdgeValidator::new(ValidatorConfig::default());
        for h in [i64::MIN, i64::MAX, 0, -1, i64::MAX, i64::MIN + 1, 1_000_000_000] {
            let _ = v.push(&edge(h, 0));
        }
        assert_eq!(v.counters().edges, 7);
    }
}
