//! Deterministic vehicle body vibration, superposed analytically on the smooth path.
//!
//! # Model
//!
//! The car body (the FRD body frame of the trajectory) rolls, pitches and heaves about the
//! smooth segment motion of [`trajectory`](super::trajectory):
//!
//! ```text
//! roll  φ(t) = e(t)·Σ_k A_k^φ sin(ω_k^φ t + ϕ_k^φ)             rad
//! pitch θ(t) = θ_path(t) + e(t)·Σ_k A_k^θ sin(ω_k^θ t + ϕ_k^θ)   rad
//! heave z(t) = e(t)·Σ_k A_k^z sin(ω_k^z t + ϕ_k^z)             m, up (added to the height)
//! e(t)       = g(v(t)/v_ref)                                     speed envelope
//! ```
//!
//! Each axis is a sum of a few sinusoids ("spectral lines") at fixed frequencies in the 1–20 Hz
//! band, with phases ϕ drawn uniformly in [0, 2π) from the scenario seed (stream
//! [`VIBRATION_STREAM`]). The relative line amplitudes are the built-in spectra below; they are
//! scaled so that the RMS of the angle (displacement) of each axis at the reference speed
//! equals the configured figure ([`VibrationConfig`]). Everything is closed-form, so the
//! trajectory's attitude, body rate ω_nb^b, its derivative, velocity and acceleration stay
//! exact (first and second time derivatives by the product rule below), and the inverse
//! mechanization of [`inverse_mechanization`](super::inverse_mechanization) stays exact.
//!
//! The lines are the body's response to a broadband road input concentrated at the car's
//! modes (a deterministic stand-in for a narrow-band random process; two close lines per body
//! mode beat, so the envelope of the motion wanders with a 2–4 s period):
//!
//! | axis  | lines, Hz                     | what                                          |
//! |-------|-------------------------------|-----------------------------------------------|
//! | heave | 1.15, 1.40 / 11.5, 13.0 / 18.5 | body bounce / front and rear wheel hop / road texture and engine |
//! | pitch | 1.6, 1.9 / 12.0 / 16.0         | body pitch mode / wheel hop / texture          |
//! | roll  | 1.8, 2.3 / 13.5 / 17.0         | body roll mode / wheel hop (left ≠ right) / texture |
//!
//! Sources for the frequencies: body (sprung-mass) bounce and pitch modes of passenger cars at
//! 1–1.5 Hz (up to ≈ 2 Hz) and wheel hop (unsprung-mass) at 10–15 Hz (Gillespie,
//! *Fundamentals of Vehicle Dynamics*, SAE 1992, ch. 5 "Ride"; Wong, *Theory of Ground
//! Vehicles*, 4th ed. 2008, ch. 7; TRL report SR 12 UC measured body heave at ≈ 1.75 Hz and
//! wheel hop at 10–15 Hz on cars crossing road discontinuities above 30 km/h).
//!
//! # Magnitudes (defaults, at the reference speed 20 m/s = 72 km/h)
//!
//! | axis  | angle / displacement RMS | rate RMS      | acceleration RMS     |
//! |-------|--------------------------|---------------|----------------------|
//! | heave | 3.0 mm                   | 0.023 m/s     | 0.25 m/s²            |
//! | pitch | 0.080°                   | 0.91 °/s      | 28 °/s² (0.48 rad/s²) |
//! | roll  | 0.065°                   | 0.89 °/s      | 38 °/s² (0.67 rad/s²) |
//!
//! (The rate and acceleration columns follow from the spectra; [`Vibration::rms_at_speed`]
//! computes them and the tests check them against the simulated truth.) A vertical body
//! acceleration of a few tenths of m/s² RMS is what a passenger car shows on a good road
//! (ISO 8608:2016 class A–B, G_d(n₀) = 16–64·10⁻⁶ m³ at n₀ = 0.1 cycle/m): ISO 2631-1:1997
//! Annex C rates < 0.315 m/s² "not uncomfortable" and 0.315–0.63 m/s² "a little
//! uncomfortable"; a bounce of 1.5 Hz with a peak acceleration of ≈ 0.23 m/s² is the
//! textbook "typical" value (a displacement of 2.6 mm). The angular figures, body pitch and
//! roll angles of a few hundredths to a tenth of a degree and rates of order 0.5–2 °/s RMS,
//! are consistent with a half-car model on the same road class (the pitch angle is roughly
//! the front–rear height difference over a 2.7 m wheelbase). Yaw vibration and the
//! longitudinal and lateral body translations are not modelled (small in a car).
//!
//! # Speed envelope
//!
//! With the ISO 8608 displacement PSD G_d(n) = G_d(n₀)(n/n₀)⁻² (waviness 2), the road input
//! at a fixed temporal frequency f = n·v has the PSD G_d(n₀) n₀² v / f², so the response of a
//! mode grows like √v. The envelope is that law made smooth at standstill:
//!
//! ```text
//! g(u) = K u (u² + κ²)^(−1/4),   K = (1 + κ²)^(1/4),   u = v / v_ref,   κ = ENVELOPE_KNEE
//! g(0) = 0, g(1) = 1, g(u) ≈ √u·K for u ≫ κ, g(u) ≈ K u/√κ for u ≪ κ
//! g′(u) = K (u²/2 + κ²)(u² + κ²)^(−5/4)
//! g″(u) = −K u (u²/4 + 3κ²/2)(u² + κ²)^(−9/4)
//! ```
//!
//! g is analytic in v, so with the C² speed profile of the segments the perturbations are C²
//! in time and the accelerations (and ω̇_nb^b) continuous. With p(t) = e(t) x(t), x the sum of
//! sinusoids:
//!
//! ```text
//! ė = g′(u) v̇ / v_ref,   ë = g″(u) (v̇ / v_ref)² + g′(u) v̈ / v_ref
//! ṗ = ė x + e ẋ,          p̈ = ë x + 2 ė ẋ + e ẍ
//! ```

use std::f64::consts::TAU;

use super::jet::Jet;
use super::rng::Rng;
use super::scenario::VibrationConfig;

/// Stream tag of the vibration phases (see [`super::rng::streams`]; kept apart from the
/// sensor-noise streams so that switching the vibration off does not change the noise).
pub const VIBRATION_STREAM: u64 = 0x300;

/// Knee of the speed envelope as a fraction of the reference speed (κ above): below ≈ κ·v_ref
/// the envelope is linear in speed instead of √v.
pub const ENVELOPE_KNEE: f64 = 0.2;

/// Heave lines: (frequency Hz, relative amplitude of the vertical *acceleration*). Body
/// bounce (two lines), front and rear wheel hop, road texture / engine.
pub const HEAVE_SPECTRUM: [(f64, f64); 5] = [(1.15, 0.20), (1.40, 0.20), (11.5, 0.20), (13.0, 0.15), (18.5, 0.10)];

/// Pitch lines: (frequency Hz, relative amplitude of the pitch *rate*). Body pitch mode (two
/// lines), wheel hop, road texture.
pub const PITCH_SPECTRUM: [(f64, f64); 4] = [(1.6, 1.0), (1.9, 0.8), (12.0, 0.4), (16.0, 0.25)];

/// Roll lines: (frequency Hz, relative amplitude of the roll *rate*). Body roll mode (two
/// lines), wheel hop, road texture.
pub const ROLL_SPECTRUM: [(f64, f64); 4] = [(1.8, 0.9), (2.3, 0.7), (13.5, 0.5), (17.0, 0.3)];

/// Highest line frequency of the built-in spectra, Hz.
pub const MAX_FREQUENCY_HZ: f64 = 18.5;

/// One sinusoid A sin(ω t + ϕ).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Line {
    /// Amplitude A at envelope 1, rad or m.
    pub amplitude: f64,
    /// Angular frequency ω, rad/s.
    pub omega_rps: f64,
    /// Phase ϕ, rad.
    pub phase_rad: f64,
}

/// The perturbations at one instant: roll and pitch (rad) and heave (m, up), each with its
/// first and second time derivatives.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct VibrationState {
    /// Body roll φ, rad, rad/s, rad/s².
    pub roll: Jet,
    /// Body pitch perturbation added to the flight-path angle, rad, rad/s, rad/s².
    pub pitch: Jet,
    /// Vertical displacement of the body origin, up, m, m/s, m/s².
    pub heave: Jet,
}

/// Stationary RMS values of one axis at a constant speed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisRms {
    /// RMS of the angle (rad) or displacement (m).
    pub value: f64,
    /// RMS of its first time derivative (rad/s, m/s).
    pub rate: f64,
    /// RMS of its second time derivative (rad/s², m/s²).
    pub acceleration: f64,
}

/// Stationary RMS values of the three axes at a constant speed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VibrationRms {
    /// Roll.
    pub roll: AxisRms,
    /// Pitch.
    pub pitch: AxisRms,
    /// Heave.
    pub heave: AxisRms,
}

/// The vibration of one scenario: the drawn lines of each axis and the envelope scale.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Vibration {
    reference_speed_mps: f64,
    roll: Vec<Line>,
    pitch: Vec<Line>,
    heave: Vec<Line>,
}

impl Vibration {
    /// No vibration (every perturbation identically 0).
    pub fn none() -> Self {
        Self::default()
    }

    /// The vibration of a validated configuration and seed ([`Vibration::none`] when disabled).
    pub fn new(cfg: &VibrationConfig, seed: u64) -> Self {
        // (A NaN or non-positive reference speed, never from a validated scenario: no vibration.)
        if !cfg.enabled || cfg.reference_speed_mps.is_nan() || cfg.reference_speed_mps <= 0.0 {
            return Self::none();
        }
        let mut rng = Rng::stream(seed, VIBRATION_STREAM);
        // Draw every phase in a fixed order whatever the amplitudes, so that changing one
        // axis' figure does not change the others' phases.
        let heave = lines(&HEAVE_SPECTRUM, 2, cfg.heave_rms_m, &mut rng);
        let pitch = lines(&PITCH_SPECTRUM, 1, cfg.pitch_rms_deg.to_radians(), &mut rng);
        let roll = lines(&ROLL_SPECTRUM, 1, cfg.roll_rms_deg.to_radians(), &mut rng);
        Self {
            reference_speed_mps: cfg.reference_speed_mps,
            roll,
            pitch,
            heave,
        }
    }

    /// Whether any axis vibrates.
    pub fn is_enabled(&self) -> bool {
        [&self.roll, &self.pitch, &self.heave]
            .iter()
            .any(|l| l.iter().any(|c| c.amplitude != 0.0))
    }

    /// The lines of (roll, pitch, heave).
    pub fn lines(&self) -> (&[Line], &[Line], &[Line]) {
        (&self.roll, &self.pitch, &self.heave)
    }

    /// Speed envelope e and its first two time derivatives for the speed jet `speed`
    /// (m/s, m/s², m/s³): [`speed_envelope`] through the chain rule.
    pub fn envelope(&self, speed: Jet) -> Jet {
        if self.reference_speed_mps <= 0.0 {
            return [0.0; 3];
        }
        let r = 1.0 / self.reference_speed_mps;
        let [g, g1, g2] = speed_envelope(speed[0] * r);
        let du = speed[1] * r;
        [g, g1 * du, g2 * du * du + g1 * speed[2] * r]
    }

    /// The perturbations at scenario time `t_s` for the speed jet `speed` there.
    pub fn state(&self, t_s: f64, speed: Jet) -> VibrationState {
        let e = self.envelope(speed);
        if e == [0.0; 3] {
            return VibrationState::default();
        }
        VibrationState {
            roll: modulate(e, oscillation(&self.roll, t_s)),
            pitch: modulate(e, oscillation(&self.pitch, t_s)),
            heave: modulate(e, oscillation(&self.heave, t_s)),
        }
    }

    /// The heave jet alone (m, m/s, m/s², up) at `t_s` for the speed jet `speed`.
    pub fn heave(&self, t_s: f64, speed: Jet) -> Jet {
        let e = self.envelope(speed);
        if e == [0.0; 3] {
            return [0.0; 3];
        }
        modulate(e, oscillation(&self.heave, t_s))
    }

    /// Stationary RMS of the perturbations and their derivatives at the constant speed
    /// `speed_mps` (distinct line frequencies: the mean squares add; a finite record
    /// differs by the beat terms, O(1/(2π Δf T)) of the mean square).
    pub fn rms_at_speed(&self, speed_mps: f64) -> VibrationRms {
        let [e, ..] = self.envelope([speed_mps, 0.0, 0.0]);
        let axis = |lines: &[Line]| {
            let ms = |p: i32| {
                lines
                    .iter()
                    .map(|c| 0.5 * (c.amplitude * c.omega_rps.powi(p)).powi(2))
                    .sum::<f64>()
            };
            AxisRms {
                value: e * ms(0).sqrt(),
                rate: e * ms(1).sqrt(),
                acceleration: e * ms(2).sqrt(),
            }
        };
        VibrationRms {
            roll: axis(&self.roll),
            pitch: axis(&self.pitch),
            heave: axis(&self.heave),
        }
    }
}

/// The lines of one axis: amplitudes from the spectrum's relative amplitudes of the
/// `order`-th derivative (A ∝ a_k/ω_k^order), scaled to the RMS `rms` of the perturbation
/// itself; phases drawn from `rng`.
fn lines(spectrum: &[(f64, f64)], order: i32, rms: f64, rng: &mut Rng) -> Vec<Line> {
    let mut out: Vec<Line> = spectrum
        .iter()
        .map(|&(f, rel)| {
            let omega = TAU * f;
            Line {
                amplitude: rel / omega.powi(order),
                omega_rps: omega,
                phase_rad: TAU * rng.uniform(),
            }
        })
        .collect();
    let ms: f64 = out.iter().map(|c| 0.5 * c.amplitude * c.amplitude).sum();
    let scale = if ms > 0.0 { rms / ms.sqrt() } else { 0.0 };
    for c in &mut out {
        c.amplitude *= scale;
    }
    out
}

/// The speed envelope g(u) and its first two derivatives w.r.t. u = v/v_ref (module docs).
pub fn speed_envelope(u: f64) -> [f64; 3] {
    let c = ENVELOPE_KNEE * ENVELOPE_KNEE;
    let k = (1.0 + c).powf(0.25);
    let q = u * u + c;
    let q14 = q.powf(-0.25);
    let q54 = q14 / q;
    let q94 = q54 / q;
    [
        k * u * q14,
        k * (0.5 * u * u + c) * q54,
        -k * u * (0.25 * u * u + 1.5 * c) * q94,
    ]
}

/// Σ A sin(ωt + ϕ) and its first two time derivatives.
fn oscillation(lines: &[Line], t: f64) -> Jet {
    let mut x = [0.0; 3];
    for c in lines {
        let (s, co) = (c.omega_rps * t + c.phase_rad).sin_cos();
        let aw = c.amplitude * c.omega_rps;
        x[0] += c.amplitude * s;
        x[1] += aw * co;
        x[2] -= aw * c.omega_rps * s;
    }
    x
}

/// p = e·x and its first two derivatives (product rule).
fn modulate(e: Jet, x: Jet) -> Jet {
    [
        e[0] * x[0],
        e[1] * x[0] + e[0] * x[1],
        e[2] * x[0] + 2.0 * e[1] * x[1] + e[0] * x[2],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn nominal() -> Vibration {
        Vibration::new(&VibrationConfig::default(), 1)
    }

    /// 4th-order central difference of a jet component.
    fn fd4(f: impl Fn(f64) -> f64, t: f64, h: f64) -> f64 {
        (-f(t + 2.0 * h) + 8.0 * f(t + h) - 8.0 * f(t - h) + f(t - 2.0 * h)) / (12.0 * h)
    }

    #[test]
    fn envelope_values_and_derivatives() {
        assert_eq!(speed_envelope(0.0)[0], 0.0);
        assert!((speed_envelope(1.0)[0] - 1.0).abs() < 1e-15);
        // √u law above the knee: within 4 % of √u·K from 0.5 on, 1 % from 1 on.
        let k = (1.0 + ENVELOPE_KNEE * ENVELOPE_KNEE).powf(0.25);
        for (u, tol) in [(0.5, 0.04), (1.0, 0.01), (2.0, 0.01), (4.0, 0.01)] {
            let g = speed_envelope(u)[0];
            assert!((g / (k * u.sqrt()) - 1.0).abs() < tol, "u={u}: {g}");
        }
        let h = 1e-4;
        for u in [0.0, 0.03, 0.2, 0.7, 1.0, 3.0] {
            let d1 = fd4(|x| speed_envelope(x)[0], u, h);
            let d2 = fd4(|x| speed_envelope(x)[1], u, h);
            assert!((d1 - speed_envelope(u)[1]).abs() < 1e-10, "g′ at {u}");
            assert!((d2 - speed_envelope(u)[2]).abs() < 1e-9, "g″ at {u}");
        }
    }

    #[test]
    fn state_derivatives_match_finite_differences() {
        let vib = nominal();
        // A speed profile with non-zero first and second derivatives: v = 12 + 3 sin(0.4 t).
        let speed = |t: f64| {
            [
                12.0 + 3.0 * (0.4 * t).sin(),
                1.2 * (0.4 * t).cos(),
                -0.48 * (0.4 * t).sin(),
            ]
        };
        let h = 1e-4;
        for i in 0..400 {
            let t = 0.737 * i as f64 + 0.01;
            let s = vib.state(t, speed(t));
            for (axis, get) in [
                ("roll", (|s: &VibrationState| s.roll) as fn(&VibrationState) -> Jet),
                ("pitch", |s| s.pitch),
                ("heave", |s| s.heave),
            ] {
                let j = get(&s);
                let d1 = fd4(|x| get(&vib.state(x, speed(x)))[0], t, h);
                let d2 = fd4(|x| get(&vib.state(x, speed(x)))[1], t, h);
                // Truncation h⁴ω⁶A/30 < 1e-9 at 18.5 Hz; rounding ~1e-13.
                assert!((d1 - j[1]).abs() < 1e-10, "{axis} rate t={t}: {d1} vs {}", j[1]);
                assert!((d2 - j[2]).abs() < 1e-8, "{axis} accel t={t}: {d2} vs {}", j[2]);
            }
            let hv = vib.heave(t, speed(t));
            assert_eq!(hv, s.heave);
        }
    }

    #[test]
    fn zero_at_standstill_and_when_disabled() {
        let vib = nominal();
        assert!(vib.is_enabled());
        for t in [0.0, 1.234, 100.0, 5000.5] {
            assert_eq!(vib.state(t, [0.0; 3]), VibrationState::default());
        }
        let off = Vibration::new(
            &VibrationConfig {
                enabled: false,
                ..VibrationConfig::default()
            },
            1,
        );
        assert!(!off.is_enabled());
        assert_eq!(off.state(3.0, [20.0, 1.0, 0.1]), VibrationState::default());
        // Just above standstill the motion is small: 1 cm/s gives < 0.2 % of the nominal.
        let e = vib.envelope([0.01, 0.0, 0.0])[0];
        assert!(e > 0.0 && e < 2e-3, "{e}");
    }

    #[test]
    fn rms_figures_match_the_configuration_and_the_literature_band() {
        let cfg = VibrationConfig::default();
        let vib = nominal();
        let r = vib.rms_at_speed(cfg.reference_speed_mps);
        assert!((r.roll.value - cfg.roll_rms_deg.to_radians()).abs() < 1e-15);
        assert!((r.pitch.value - cfg.pitch_rms_deg.to_radians()).abs() < 1e-15);
        assert!((r.heave.value - cfg.heave_rms_m).abs() < 1e-15);
        println!(
            "at {} m/s: roll {:.3}° {:.2}°/s {:.1}°/s², pitch {:.3}° {:.2}°/s {:.1}°/s², heave {:.2} mm {:.3} m/s {:.3} m/s²",
            cfg.reference_speed_mps,
            r.roll.value.to_degrees(),
            r.roll.rate.to_degrees(),
            r.roll.acceleration.to_degrees(),
            r.pitch.value.to_degrees(),
            r.pitch.rate.to_degrees(),
            r.pitch.acceleration.to_degrees(),
            r.heave.value * 1e3,
            r.heave.rate,
            r.heave.acceleration
        );
        // Angular rate RMS of order 0.5–2 °/s, vertical acceleration a few tenths of m/s².
        for rate in [r.roll.rate, r.pitch.rate] {
            assert!((0.5..2.0).contains(&rate.to_degrees()), "{}", rate.to_degrees());
        }
        assert!((0.15..0.5).contains(&r.heave.acceleration), "{}", r.heave.acceleration);
        // Frequencies within the 1–20 Hz band, the highest as documented.
        let (ro, pi, he) = vib.lines();
        let fmax = ro
            .iter()
            .chain(pi)
            .chain(he)
            .map(|c| c.omega_rps / TAU)
            .fold(0.0, f64::max);
        let fmin = ro
            .iter()
            .chain(pi)
            .chain(he)
            .map(|c| c.omega_rps / TAU)
            .fold(f64::MAX, f64::min);
        assert!(fmin >= 1.0 && (fmax - MAX_FREQUENCY_HZ).abs() < 1e-12, "{fmin} {fmax}");
        // The √v law: twice the speed, √2 the RMS (within the knee's 1 %).
        let r2 = vib.rms_at_speed(2.0 * cfg.reference_speed_mps);
        assert!((r2.heave.value / r.heave.value / 2f64.sqrt() - 1.0).abs() < 0.01);
    }

    #[test]
    fn same_seed_same_phases_other_seed_other_phases() {
        let cfg = VibrationConfig::default();
        let (a, b, c) = (
            Vibration::new(&cfg, 7),
            Vibration::new(&cfg, 7),
            Vibration::new(&cfg, 8),
        );
        assert_eq!(a, b);
        assert_ne!(a, c);
        assert_eq!(a.state(12.3, [15.0, 0.2, 0.0]), b.state(12.3, [15.0, 0.2, 0.0]));
        assert_ne!(a.state(12.3, [15.0, 0.2, 0.0]), c.state(12.3, [15.0, 0.2, 0.0]));
        // Amplitudes depend on the configuration only, not on the seed.
        assert_eq!(a.rms_at_speed(20.0), c.rms_at_speed(20.0));
    }
}
