//! The host oscillator: host time (CLOCK_MONOTONIC) as an exact, invertible function of true
//! time (UTC, which the GNSS receiver realises).
//!
//! The host clock's fractional frequency error y(τ) = d(host)/d(true) − 1 starts at the
//! configured y₀ and wanders as a random walk in frequency (RWFM): on a grid of 1 s nodes
//! y_{j+1} = y_j + √(q·Δ)·ξ_j, linear between nodes. For RWFM the Allan variance is
//! σ_y²(τ) = q·τ/3 (Riley, NIST SP 1065, Table 5; IEEE Std 1139), so the configured Allan
//! deviation at 1 s gives q = 3·σ_y(1 s)². The default 1e-10 at 1 s is a TCXO-like wander:
//! over 10 min the frequency moves by ~2.5e-9 (σ) and the time by ~1.5 µs.
//!
//! Host time is host(τ) = host₀ + (τ + X(τ))·1e9 rounded to ns, with X(τ) = ∫₀^τ y ds, a
//! piecewise quadratic (exact). Its inverse is found by Newton iteration on the same
//! function, so `utc_ns_at_host(host_ns_at_utc(u))` is within 1 ns of u. Outside the table
//! (before the start, after the end of the simulated span) y is held constant.

use super::rng::Rng;

/// Spacing of the frequency random-walk nodes, s.
pub const NODE_SPACING_S: f64 = 1.0;

/// The host clock against true time. τ is true time in s since the scenario start.
#[derive(Debug, Clone)]
pub struct Oscillator {
    start_host_ns: i64,
    start_utc_ns: i64,
    /// y at the nodes τ_j = j·Δ (at least two nodes, so `locate` always indexes a node).
    y: Vec<f64>,
    /// X(τ_j) = ∫₀^{τ_j} y ds, s.
    x: Vec<f64>,
}

impl Oscillator {
    /// An oscillator with initial fractional frequency error `y0` (e.g. 0.5e-6), random-walk
    /// Allan deviation `rw_adev_1s` at 1 s, covering true times [0, `span_s`] exactly.
    pub fn new(start_host_ns: i64, start_utc_ns: i64, y0: f64, rw_adev_1s: f64, span_s: f64, rng: &mut Rng) -> Self {
        let nodes = (span_s / NODE_SPACING_S).ceil().max(1.0) as usize + 1;
        let step_sigma = (3.0 * rw_adev_1s * rw_adev_1s * NODE_SPACING_S).sqrt();
        let mut y = Vec::with_capacity(nodes);
        let mut x = Vec::with_capacity(nodes);
        let (mut yj, mut xj) = (y0, 0.0);
        for _ in 0..nodes {
            y.push(yj);
            x.push(xj);
            let next = yj + rng.gaussian(step_sigma);
            xj += 0.5 * (yj + next) * NODE_SPACING_S;
            yj = next;
        }
        Self {
            start_host_ns,
            start_utc_ns,
            y,
            x,
        }
    }

    /// Host time at the scenario start, ns.
    pub fn start_host_ns(&self) -> i64 {
        self.start_host_ns
    }

    /// UTC at the scenario start, ns.
    pub fn start_utc_ns(&self) -> i64 {
        self.start_utc_ns
    }

    /// Scenario time τ of a UTC instant, s.
    pub fn tau_of_utc(&self, utc_ns: i64) -> f64 {
        (utc_ns - self.start_utc_ns) as f64 * 1e-9
    }

    /// UTC of scenario time τ, ns (rounded).
    pub fn utc_of_tau(&self, tau: f64) -> i64 {
        self.start_utc_ns + (tau * 1e9).round() as i64
    }

    /// Fractional frequency error y(τ) = d(host)/d(true) − 1.
    pub fn freq_error(&self, tau: f64) -> f64 {
        let (j, u) = self.locate(tau);
        let y0 = self.y[j];
        match self.y.get(j + 1) {
            Some(&y1) if tau >= 0.0 => y0 + (y1 - y0) * u / NODE_SPACING_S,
            _ => y0,
        }
    }

    /// Accumulated host-minus-true time X(τ) = ∫₀^τ y ds, s.
    pub fn offset_s(&self, tau: f64) -> f64 {
        let (j, u) = self.locate(tau);
        let y0 = self.y[j];
        let y1 = self.y.get(j + 1).copied().unwrap_or(y0);
        let slope = if tau >= 0.0 { (y1 - y0) / NODE_SPACING_S } else { 0.0 };
        self.x[j] + y0 * u + 0.5 * slope * u * u
    }

    /// Node index and time since that node; beyond the table the last node, before 0 node 0.
    fn locate(&self, tau: f64) -> (usize, f64) {
        if tau < 0.0 {
            return (0, tau);
        }
        let last = self.y.len() - 1;
        let j = ((tau / NODE_SPACING_S).floor() as usize).min(last);
        (j, tau - j as f64 * NODE_SPACING_S)
    }

    /// Host time at scenario time τ, ns (exact function, rounded to the ns).
    pub fn host_ns_at_tau(&self, tau: f64) -> i64 {
        self.start_host_ns + ((tau + self.offset_s(tau)) * 1e9).round() as i64
    }

    /// Host time of a UTC instant, ns.
    pub fn host_ns_at_utc(&self, utc_ns: i64) -> i64 {
        self.host_ns_at_tau(self.tau_of_utc(utc_ns))
    }

    /// Scenario time τ at which the host clock reads `host_ns`, s (Newton iteration on
    /// τ + X(τ) = H; converges to < 1e-15 s in ≤ 3 iterations since |y| ≪ 1).
    pub fn tau_at_host(&self, host_ns: i64) -> f64 {
        let target = (host_ns - self.start_host_ns) as f64 * 1e-9;
        let mut tau = target / (1.0 + self.y[0]);
        for _ in 0..6 {
            let r = tau + self.offset_s(tau) - target;
            tau -= r / (1.0 + self.freq_error(tau));
            if r.abs() < 1e-13 {
                break;
            }
        }
        tau
    }

    /// UTC at which the host clock reads `host_ns`, ns.
    pub fn utc_ns_at_host(&self, host_ns: i64) -> i64 {
        self.utc_of_tau(self.tau_at_host(host_ns))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const H0: i64 = 123_456_789_000_000;
    const U0: i64 = 1_790_000_000_123_456_789;

    #[test]
    fn constant_frequency_error_gains_half_a_microsecond_per_second() {
        let osc = Oscillator::new(H0, U0, 0.5e-6, 0.0, 700.0, &mut Rng::new(1));
        assert_eq!(osc.host_ns_at_utc(U0), H0);
        assert_eq!(osc.host_ns_at_utc(U0 + 1_000_000_000), H0 + 1_000_000_500);
        assert_eq!(osc.host_ns_at_utc(U0 + 600_000_000_000), H0 + 600_000_300_000);
        // Beyond the table the rate is held.
        assert_eq!(osc.host_ns_at_utc(U0 + 1_000_000_000_000), H0 + 1_000_000_500_000);
    }

    #[test]
    fn mapping_is_invertible_and_monotonic() {
        let osc = Oscillator::new(H0, U0, 0.5e-6, 1e-9, 700.0, &mut Rng::new(2));
        let mut prev = i64::MIN;
        for i in 0..70_000 {
            let u = U0 + i * 10_000_037;
            let h = osc.host_ns_at_utc(u);
            assert!(h > prev);
            prev = h;
            let back = osc.utc_ns_at_host(h);
            assert!((back - u).abs() <= 1, "{u} → {h} → {back}");
        }
    }

    #[test]
    fn offset_is_the_integral_of_the_frequency() {
        let osc = Oscillator::new(H0, U0, 0.5e-6, 1e-9, 100.0, &mut Rng::new(3));
        let h = 1e-3;
        for i in 1..900 {
            let tau = i as f64 * 0.1013;
            if (tau - tau.round()).abs() < 2.0 * h {
                continue; // y has a kink at the nodes
            }
            let fd = (osc.offset_s(tau + h) - osc.offset_s(tau - h)) / (2.0 * h);
            assert!((fd - osc.freq_error(tau)).abs() < 1e-14, "τ={tau}");
        }
        // Continuity at the nodes.
        for j in 1..50 {
            let t = j as f64;
            assert!((osc.offset_s(t - 1e-12) - osc.offset_s(t + 1e-12)).abs() < 1e-18);
        }
    }

    #[test]
    fn random_walk_allan_deviation() {
        // Frequency increments over τ = 10 s across many seeds: for RWFM with diffusion q the
        // increment variance is q·τ = 3σ_y(1 s)²·τ.
        let adev = 1e-10;
        let (mut s2, mut n) = (0.0, 0usize);
        for seed in 0..200 {
            let osc = Oscillator::new(0, 0, 0.0, adev, 1000.0, &mut Rng::new(seed));
            for k in 0..99 {
                let d = osc.freq_error((k + 1) as f64 * 10.0) - osc.freq_error(k as f64 * 10.0);
                s2 += d * d;
                n += 1;
            }
        }
        let var = s2 / n as f64;
        let expected = 3.0 * adev * adev * 10.0;
        assert!((var / expected - 1.0).abs() < 0.05, "{var} vs {expected}");
    }
}
