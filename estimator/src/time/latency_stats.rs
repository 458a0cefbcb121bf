//! Distribution of the receiver's output latency d0 (first NMEA byte minus its PPS edge),
//! what the literature measured with an oscilloscope, measured here on every epoch.

/// Epochs kept for the statistics (10 minutes at 1 Hz, 1 minute at 10 Hz).
pub const LATENCY_WINDOW: usize = 600;

/// Rolling window of latencies with order statistics; fixed memory, no allocation.
#[derive(Debug, Clone)]
pub struct LatencyStats {
    ring: [f64; LATENCY_WINDOW],
    scratch: [f64; LATENCY_WINDOW],
    len: usize,
    next: usize,
    total: u64,
}

/// Order statistics of the window, s.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LatencySummary {
    /// Minimum, s.
    pub min_s: f64,
    /// Median, s.
    pub median_s: f64,
    /// 99th percentile (nearest rank), s.
    pub p99_s: f64,
    /// Maximum, s.
    pub max_s: f64,
    /// Epochs measured since start.
    pub count: u64,
}

impl Default for LatencyStats {
    fn default() -> Self {
        Self {
            ring: [0.0; LATENCY_WINDOW],
            scratch: [0.0; LATENCY_WINDOW],
            len: 0,
            next: 0,
            total: 0,
        }
    }
}

impl LatencyStats {
    /// Adds one epoch's latency, s.
    pub fn push(&mut self, latency_s: f64) {
        self.ring[self.next] = latency_s;
        self.next = (self.next + 1) % LATENCY_WINDOW;
        self.len = (self.len + 1).min(LATENCY_WINDOW);
        self.total += 1;
    }

    /// Order statistics over the window, `None` before the first epoch.
    pub fn summary(&mut self) -> Option<LatencySummary> {
        if self.len == 0 {
            return None;
        }
        let v = &mut self.scratch[..self.len];
        v.copy_from_slice(&self.ring[..self.len]);
        v.sort_unstable_by(f64::total_cmp);
        let rank = |q: f64| v[((q * self.len as f64).ceil() as usize).clamp(1, self.len) - 1];
        Some(LatencySummary {
            min_s: v[0],
            median_s: rank(0.5),
            p99_s: rank(0.99),
            max_s: v[self.len - 1],
            count: self.total,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn order_statistics() {
        let mut s = LatencyStats::default();
        assert!(s.summary().is_none());
        for i in (1..=100).rev() {
            s.push(i as f64 * 0.01);
        }
        let m = s.summary().unwrap();
        assert_eq!(
            (m.min_s, m.median_s, m.p99_s, m.max_s, m.count),
            (0.01, 0.5, 0.99, 1.0, 100)
        );
        for _ in 0..LATENCY_WINDOW {
            s.push(0.6);
        }
        let m = s.summary().unwrap();
        assert_eq!((m.min_s, m.max_s), (0.6, 0.6));
    }
}
