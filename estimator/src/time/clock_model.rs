//! Kalman filter of the host clock against GNSS time.
//!
//! State x = [θ, y]: θ = UTC − host (ns) at the state's host time, y = fractional frequency
//! error of the host clock (d UTC / d host − 1). Two-state clock model of Brown & Hwang,
//! *Introduction to Random Signals and Applied Kalman Filtering* (4th ed., §9.3):
//!
//! θ(k+1) = θ(k) + y(k)·Δ,  y(k+1) = y(k)  (Δ = host-time step in ns), with
//! Q(Δt) = [[q_φ·Δt + q_f·Δt³/3, q_f·Δt²/2], [q_f·Δt²/2, q_f·Δt]] (Δt in s, scaled to ns),
//! where q_φ (ns²/s) is white frequency noise and q_f (1/s) random-walk frequency noise.
//! For an oscillator with Allan deviation σ_y(τ): white FM gives σ_y²(τ) = q_φ/τ and
//! random-walk FM σ_y²(τ) = q_f·τ/3 (Van Dierendonck et al. 1984).
//!
//! A measurement is a PPS edge at host time h labelled with its UTC second T: z = T − h.
//! θ is huge (UTC since 1970 minus boot time), so it is kept as an integer base plus an f64
//! residual; the filter only ever sees the residual.

use nalgebra::{Matrix2, Vector2};

/// Oscillator stability figures (process noise).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OscillatorNoise {
    /// White-frequency-noise intensity q_φ, ns²/s (σ_y(1 s) = 1e−10 → 1e−2).
    pub q_offset_ns2_per_s: f64,
    /// Random-walk-frequency intensity q_f, 1/s (σ_y(1 s) = 1e−10 → 3e−20).
    pub q_rate_per_s: f64,
}

impl OscillatorNoise {
    /// Process noise from the oscillator's Allan deviations at τ = 1 s of its white-FM and
    /// random-walk-FM components (a data sheet's or a measured Allan plot's figures):
    /// σ_y²(τ) = q_φ/τ (white FM) and σ_y²(τ) = q_f·τ/3 (random-walk FM), so
    /// q_φ = σ_wfm(1 s)²·1 s (in ns²/s: ×1e18) and q_f = 3·σ_rwfm(1 s)²/s.
    pub fn from_allan(white_fm_adev_1s: f64, random_walk_fm_adev_1s: f64) -> Self {
        Self {
            q_offset_ns2_per_s: white_fm_adev_1s * white_fm_adev_1s * 1e18,
            q_rate_per_s: 3.0 * random_walk_fm_adev_1s * random_walk_fm_adev_1s,
        }
    }
}

impl OscillatorNoise {
    /// A GNSS receiver's temperature-compensated crystal oscillator: Brown & Hwang,
    /// *Introduction to Random Signals and Applied Kalman Filtering*, 4th ed., Table 9.1
    /// "typical TCXO" (h₀ = 2·10⁻¹⁹ s, h₋₂ = 2·10⁻²⁰ /s, flicker left out), i.e. white FM
    /// σ_y(1 s) = √(h₀/2) = 3.2·10⁻¹⁰ and random-walk FM σ_y(1 s) = √(2π²h₋₂/3) = 3.6·10⁻¹⁰.
    pub fn tcxo() -> Self {
        Self::from_allan(3.2e-10, 3.6e-10)
    }

    /// A plain (uncompensated) 0.5 ppm crystal, navsync's figures: three times the TCXO's
    /// white FM and ten times its random-walk FM (its frequency follows the temperature).
    pub fn crystal() -> Self {
        Self::from_allan(1.0e-9, 3.6e-9)
    }

    /// The same oscillator with its random-walk FM intensity times `scale` (a clock that
    /// proved less stable than its model: [`crate::nav::measurements::ranges::ClockWatch`]).
    pub fn with_random_walk_fm_scaled(self, scale: f64) -> Self {
        Self {
            q_rate_per_s: self.q_rate_per_s * scale,
            ..self
        }
    }

    /// Allan deviation of the model at averaging time `tau_s`:
    /// σ_y²(τ) = q_φ/τ + q_f·τ/3.
    pub fn allan_deviation(&self, tau_s: f64) -> f64 {
        (self.q_offset_ns2_per_s * 1e-18 / tau_s + self.q_rate_per_s * tau_s / 3.0).sqrt()
    }

    /// Discrete process noise over `dt_s` of the clock as a range, (c·δt, c·δṫ) in m and m/s
    /// (Brown & Hwang eq. 9.3.11; Groves, *Principles of GNSS, Inertial, and Multisensor
    /// Integrated Navigation Systems*, 2nd ed., eq. 9.152):
    /// Q = c²·[[q_φ·Δt + q_f·Δt³/3, q_f·Δt²/2], [q_f·Δt²/2, q_f·Δt]] with q_φ in s²/s.
    pub fn process_noise_m(&self, dt_s: f64) -> Matrix2<f64> {
        const C_M_S: f64 = 299_792_458.0;
        let (q1, q2) = (self.q_offset_ns2_per_s * 1e-18, self.q_rate_per_s);
        let (t, t2, t3) = (dt_s, dt_s * dt_s, dt_s * dt_s * dt_s);
        Matrix2::new(q1 * t + q2 * t3 / 3.0, q2 * t2 / 2.0, q2 * t2 / 2.0, q2 * t) * (C_M_S * C_M_S)
    }
}

impl Default for OscillatorNoise {
    /// A TCXO-class host oscillator: white FM σ_y(1 s) = 1e−10 and random-walk FM
    /// σ_y(1 s) = 1e−10 (the simulator's default oscillator, `[clock] freq_rw_adev_1s`).
    fn default() -> Self {
        Self::from_allan(1e-10, 1e-10)
    }
}

/// Result of feeding one labelled edge.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ClockUpdate {
    /// Used; innovation in ns.
    Accepted(f64),
    /// Innovation beyond the gate; not used. Innovation in ns.
    Rejected(f64),
}

/// The clock filter. `None`-like until [`init`](Self::init) is called.
#[derive(Debug, Clone)]
pub struct ClockModel {
    noise: OscillatorNoise,
    base_ns: i64,
    x: Vector2<f64>,
    p: Matrix2<f64>,
    host_ns: i64,
    initialized: bool,
    updates: u64,
}

/// Innovation gate in standard deviations.
const GATE_SIGMA: f64 = 5.0;

impl ClockModel {
    /// An uninitialised filter with the given oscillator noise.
    pub fn new(noise: OscillatorNoise) -> Self {
        Self {
            noise,
            base_ns: 0,
            x: Vector2::zeros(),
            p: Matrix2::zeros(),
            host_ns: 0,
            initialized: false,
            updates: 0,
        }
    }

    /// True after [`init`](Self::init).
    pub fn is_initialized(&self) -> bool {
        self.initialized
    }

    /// Measurements used since the last init.
    pub fn updates(&self) -> u64 {
        self.updates
    }

    /// Oscillator noise in use.
    pub fn noise(&self) -> OscillatorNoise {
        self.noise
    }

    /// Starts the filter from one labelled edge: offset known to `sigma_ns`, rate error
    /// unknown to `rate_sigma` (e.g. 1e−4 for an uncalibrated crystal).
    pub fn init(&mut self, host_ns: i64, utc_ns: i64, sigma_ns: f64, rate_sigma: f64) {
        self.base_ns = utc_ns - host_ns;
        self.x = Vector2::zeros();
        self.p = Matrix2::new(sigma_ns * sigma_ns, 0.0, 0.0, rate_sigma * rate_sigma);
        self.host_ns = host_ns;
        self.initialized = true;
        self.updates = 1;
    }

    /// Propagates the state to `host_ns` (eq. in the module docs). Going backwards is a no-op.
    pub fn predict_to(&mut self, host_ns: i64) {
        let d_ns = host_ns - self.host_ns;
        if !self.initialized || d_ns <= 0 {
            return;
        }
        let d = d_ns as f64;
        let dt = d * 1e-9;
        let f = Matrix2::new(1.0, d, 0.0, 1.0);
        let (q1, q2) = (self.noise.q_offset_ns2_per_s, self.noise.q_rate_per_s);
        let q = Matrix2::new(
            q1 * dt + q2 * 1e18 * dt * dt * dt / 3.0,
            q2 * 1e9 * dt * dt / 2.0,
            q2 * 1e9 * dt * dt / 2.0,
            q2 * dt,
        );
        self.x = f * self.x;
        self.p = f * self.p * f.transpose() + q;
        self.host_ns = host_ns;
        // Keep the residual small: fold whole nanoseconds into the integer base.
        let whole = self.x[0].trunc();
        self.base_ns += whole as i64;
        self.x[0] -= whole;
    }

    /// Fuses an edge at `host_ns` known to mark UTC `utc_ns`, with stamp noise `sigma_ns`.
    pub fn update(&mut self, host_ns: i64, utc_ns: i64, sigma_ns: f64) -> ClockUpdate {
        self.predict_to(host_ns);
        // z − Hx with H = [1, 0]; computed in i64 first to keep precision.
        let innovation = ((utc_ns - host_ns) - self.base_ns) as f64 - self.x[0];
        let s = self.p[(0, 0)] + sigma_ns * sigma_ns;
        if innovation.abs() > GATE_SIGMA * s.sqrt() {
            return ClockUpdate::Rejected(innovation);
        }
        let k = Vector2::new(self.p[(0, 0)], self.p[(1, 0)]) / s;
        self.x += k * innovation;
        // Joseph form keeps P symmetric positive definite: P = (I−KH)P(I−KH)ᵀ + K R Kᵀ.
        let i_kh = Matrix2::new(1.0 - k[0], 0.0, -k[1], 1.0);
        self.p = i_kh * self.p * i_kh.transpose() + k * k.transpose() * (sigma_ns * sigma_ns);
        self.updates += 1;
        ClockUpdate::Accepted(innovation)
    }

    /// Host time of the current state, ns.
    pub fn host_ns(&self) -> i64 {
        self.host_ns
    }

    /// Estimated UTC at the state's host time, ns.
    pub fn utc_ns_at_state(&self) -> i64 {
        self.host_ns + self.base_ns + self.x[0].round() as i64
    }

    /// Estimated UTC at any host time (extrapolated with the estimated rate), ns.
    pub fn utc_ns_at(&self, host_ns: i64) -> i64 {
        let d = (host_ns - self.host_ns) as f64;
        host_ns + self.base_ns + (self.x[0] + self.x[1] * d).round() as i64
    }

    /// Estimated fractional frequency error of the host clock.
    pub fn rate_error(&self) -> f64 {
        self.x[1]
    }

    /// Covariance [[ns², ns], [ns, 1]] at the state's host time.
    pub fn covariance(&self) -> Matrix2<f64> {
        self.p
    }

    /// 1-sigma of [`utc_ns_at`](Self::utc_ns_at) at `host_ns`, ns: P propagated over
    /// Δ = |host_ns − state time| with the process noise (the same expression as
    /// `TimeState::utc_std_ns_at`), without changing the filter.
    pub fn std_ns_at(&self, host_ns: i64) -> f64 {
        let d = host_ns.saturating_sub(self.host_ns).unsigned_abs() as f64;
        let dt = d * 1e-9;
        let (q1, q2) = (self.noise.q_offset_ns2_per_s, self.noise.q_rate_per_s);
        let var = self.p[(0, 0)]
            + 2.0 * d * self.p[(0, 1)]
            + d * d * self.p[(1, 1)]
            + q1 * dt
            + q2 * 1e18 * dt * dt * dt / 3.0;
        var.max(0.0).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_noise::gauss;

    #[test]
    fn receiver_oscillator_presets_match_their_allan_coefficients() {
        // Brown & Hwang's TCXO: σ_y²(τ) = h₀/(2τ) + (2π²/3)·h₋₂·τ.
        let adev = |h0: f64, hm2: f64, tau: f64| {
            (h0 / (2.0 * tau) + 2.0 * std::f64::consts::PI.powi(2) / 3.0 * hm2 * tau).sqrt()
        };
        let tcxo = OscillatorNoise::tcxo();
        for tau in [1.0, 10.0, 100.0] {
            let want = adev(2e-19, 2e-20, tau);
            assert!((tcxo.allan_deviation(tau) / want - 1.0).abs() < 0.02, "τ {tau}");
        }
        assert!(OscillatorNoise::crystal().allan_deviation(100.0) > 5.0 * tcxo.allan_deviation(100.0));
        // The drift's σ after 60 s of holdover is c·√(q_f·60 s).
        let q = tcxo.process_noise_m(60.0);
        let want = 299_792_458.0 * (tcxo.q_rate_per_s * 60.0).sqrt();
        assert!((q[(1, 1)].sqrt() / want - 1.0).abs() < 1e-12);
        assert!(q.determinant() > 0.0);
    }

    #[test]
    fn tracks_offset_and_drift_of_a_fast_oscillator() {
        // Host runs 0.5 ppm fast: host(T) = h0 + T·(1 + 5e−7), 1 µs edge jitter.
        let h0: i64 = 12_345_678_901_234;
        let utc0: i64 = 1_790_000_000 * 1_000_000_000;
        let mut rng = 7u64;
        let mut m = ClockModel::new(OscillatorNoise::default());
        let mut worst_late = 0.0f64;
        for k in 0..120i64 {
            let true_host = h0 + k * 1_000_000_000 + k * 500;
            let stamped = true_host + (gauss(&mut rng) * 1000.0) as i64;
            let utc = utc0 + k * 1_000_000_000;
            if m.is_initialized() {
                assert!(matches!(m.update(stamped, utc, 1000.0), ClockUpdate::Accepted(_)));
            } else {
                m.init(stamped, utc, 1000.0, 1e-4);
            }
            if k >= 30 {
                // Mapping error at a mid-second instant against the truth.
                let h = true_host + 500_000_000;
                let truth = utc + (500_000_000.0 / (1.0 + 5e-7)) as i64;
                worst_late = worst_late.max((m.utc_ns_at(h) - truth).abs() as f64);
            }
        }
        assert!(worst_late < 1000.0, "mapping error {worst_late} ns");
        assert!((m.rate_error() + 5e-7).abs() < 2e-9, "rate {}", m.rate_error());
    }

    #[test]
    fn rejects_an_edge_a_millisecond_off() {
        let mut m = ClockModel::new(OscillatorNoise::default());
        m.init(0, 1_000_000_000, 1000.0, 1e-6);
        for k in 1..10 {
            m.update(k * 1_000_000_000, (k + 1) * 1_000_000_000, 1000.0);
        }
        assert!(matches!(
            m.update(10_001_000_000, 11_000_000_000, 1000.0),
            ClockUpdate::Rejected(_)
        ));
    }
}
