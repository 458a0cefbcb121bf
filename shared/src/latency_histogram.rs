//! A fixed-size latency histogram with 1 µs buckets up to 10 ms (no allocation after
//! construction): p50/p99/p99.9/max of per-sample latencies for health reports and benchmarks.

/// Buckets: [0, 1) µs … [9999, 10000) µs, then one overflow bucket.
const BUCKETS: usize = 10_001;

/// Latency histogram, ns resolution for the maximum, 1 µs for the percentiles.
#[derive(Debug, Clone)]
pub struct LatencyHistogram {
    counts: Box<[u64]>,
    n: u64,
    max_ns: i64,
    sum_ns: i128,
}

impl Default for LatencyHistogram {
    fn default() -> Self {
        Self {
            counts: vec![0; BUCKETS].into_boxed_slice(),
            n: 0,
            max_ns: 0,
            sum_ns: 0,
        }
    }
}

impl LatencyHistogram {
    /// Records one latency, ns (negative values count as 0).
    pub fn record(&mut self, ns: i64) {
        let ns = ns.max(0);
        let b = ((ns / 1000) as usize).min(BUCKETS - 1);
        self.counts[b] += 1;
        self.n += 1;
        self.max_ns = self.max_ns.max(ns);
        self.sum_ns += ns as i128;
    }

    /// Number of recorded latencies.
    pub fn count(&self) -> u64 {
        self.n
    }

    /// Largest latency, ns.
    pub fn max_ns(&self) -> i64 {
        self.max_ns
    }

    /// Mean latency, ns.
    pub fn mean_ns(&self) -> f64 {
        if self.n == 0 {
            0.0
        } else {
            self.sum_ns as f64 / self.n as f64
        }
    }

    /// Upper edge of the bucket holding quantile `q` (0..=1), µs; the overflow bucket reports 10 000.
    pub fn quantile_us(&self, q: f64) -> f64 {
        if self.n == 0 {
            return 0.0;
        }
        let rank = ((q * self.n as f64).ceil() as u64).clamp(1, self.n);
        let mut seen = 0;
        for (i, c) in self.counts.iter().enumerate() {
            seen += c;
            if seen >= rank {
                return (i + 1) as f64;
            }
        }
        BUCKETS as f64
    }

    /// Forgets everything.
    pub fn clear(&mut self) {
        self.counts.iter_mut().for_each(|c| *c = 0);
        self.n = 0;
        self.max_ns = 0;
        self.sum_ns = 0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_and_max() {
        let mut h = LatencyHistogram::default();
        for us in 1..=1000 {
            h.record(us * 1000 - 500);
        }
        h.record(50_000_000);
        assert_eq!(h.count(), 1001);
        assert_eq!(h.quantile_us(0.5), 501.0);
        assert_eq!(h.quantile_us(0.99), 991.0);
        assert_eq!(h.quantile_us(1.0), 10_001.0);
        assert_eq!(h.max_ns(), 50_000_000);
        h.clear();
        assert_eq!(h.quantile_us(0.99), 0.0);
    }
}
