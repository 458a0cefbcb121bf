//! The simulated GNSS receiver: one fix per epoch (true antenna position and velocity plus
//! noise), output as an NMEA burst that leaves the receiver at host(T + d0).
//!
//! - Epochs at every multiple of 1/rate of UTC within the scenario.
//! - Antenna: p_a = p_b + C_b^n l (NED offset converted to φ, λ, h to first order: the error is
//!   l²/R, < 4e-7 m for l < 1.5 m), v_a = v_b + C_b^n (ω_ib^b × l) − ω_ie^n × (C_b^n l)
//!   (the lever-arm transformation of Groves 2013 §2.5.5, in NED form, as used for GNSS/INS
//!   lever-arm compensation in §14.2).
//! - Position noise: σ_N = σ_E = horizontal_rms/√2, σ_D = vertical σ, white or first-order
//!   Gauss–Markov with the configured correlation time (stationary from the first epoch);
//!   velocity noise white, σ per NED axis. Noise is drawn for every epoch, including outages,
//!   so an outage does not shift the noise sequence of later epochs.
//! - Outages: no fix (GGA quality 0, RMC status V, empty position fields); time tags and
//!   dates continue.
//! - Latency: d = d0 + N(0, jitter) (clamped at 0); a burst never leaves before the previous one.
//! - UBX: the time marks of the camera on EXTINT0 ([`crate::camera`]) in TIM-TM2 after the
//!   epoch's NAV-EOE (and TIM-TP), for the edges up to the epoch.

use nalgebra::Vector3;
use navsync_shared::earth;

use super::camera::{Camera, TimeMarks};
use super::gps::Sky;
use super::inverse_mechanization::inertial_state;
use super::nmea::{self, EpochReport, FixReport};
use super::oscillator::Oscillator;
use super::rng::{Rng, streams};
use super::scenario::{GnssConfig, OutputProtocol};
use super::trajectory::{Trajectory, wrap_pi};
use super::ubx;

/// One epoch's output.
#[derive(Debug, Clone, PartialEq)]
pub struct NmeaBurst {
    /// Host time at which the first byte leaves the receiver, ns.
    pub host_ns: i64,
    /// The epoch, UTC ns.
    pub epoch_utc_ns: i64,
    /// The sentences, CR LF terminated.
    pub bytes: Vec<u8>,
    /// The true latency d of this burst after the epoch, s.
    pub latency_s: f64,
}

/// True antenna position (φ rad, λ rad, h m) and NED velocity (m/s) at scenario time `tau`.
pub fn antenna_truth(traj: &Trajectory, lever_arm_b: &Vector3<f64>, tau: f64) -> ([f64; 3], Vector3<f64>) {
    let k = traj.kinematics(tau);
    let s = inertial_state(&k);
    let l_n = k.c_b_n * lever_arm_b;
    let (rm, rn) = earth::radii(k.lat_rad);
    let h = k.height_m;
    let p = [
        k.lat_rad + l_n[0] / (rm + h),
        k.lon_rad + l_n[1] / ((rn + h) * k.lat_rad.cos()),
        h - l_n[2],
    ];
    let v = k.v_ned + k.c_b_n * s.omega_ib_b.cross(lever_arm_b) - s.omega_ie_n.cross(&l_n);
    (p, v)
}

/// The receiver's state between epochs.
#[derive(Debug, Clone)]
pub struct GnssReceiver {
    cfg: GnssConfig,
    lever_arm_b: Vector3<f64>,
    period_ns: i64,
    next_epoch_utc_ns: i64,
    end_utc_ns: i64,
    sigma_pos: [f64; 3],
    phi: f64,
    pos_noise: [f64; 3],
    started: bool,
    noise_rng: Rng,
    latency_rng: Rng,
    last_host_ns: i64,
    sky: Option<Sky>,
    marks: Option<TimeMarks>,
}

impl GnssReceiver {
    /// A receiver for a validated configuration; epochs from the first multiple of the epoch
    /// period at or after `start_utc_ns` up to `start_utc_ns + duration_s`.
    pub fn new(cfg: &GnssConfig, seed: u64, start_utc_ns: i64, duration_s: f64) -> Self {
        let period_ns = 1_000_000_000 / i64::from(cfg.rate_hz.max(1));
        let sh = cfg.horizontal_rms_m / std::f64::consts::SQRT_2;
        let phi = if cfg.position_correlation_s > 0.0 {
            (-(period_ns as f64 * 1e-9) / cfg.position_correlation_s).exp()
        } else {
            0.0
        };
        Self {
            cfg: cfg.clone(),
            lever_arm_b: Vector3::from(cfg.antenna_lever_arm_m),
            period_ns,
            next_epoch_utc_ns: ceil_to(start_utc_ns, period_ns),
            end_utc_ns: start_utc_ns + (duration_s * 1e9).round() as i64,
            sigma_pos: [sh, sh, cfg.vertical_sigma_m],
            phi,
            pos_noise: [0.0; 3],
            started: false,
            noise_rng: Rng::stream(seed, streams::GNSS_NOISE),
            latency_rng: Rng::stream(seed, streams::NMEA_LATENCY),
            last_host_ns: i64::MIN,
            sky: Sky::new(&cfg.sky, seed, start_utc_ns, duration_s),
            marks: Camera::new(cfg, seed, start_utc_ns, duration_s)
                .filter(|_| cfg.protocol == OutputProtocol::Ubx)
                .map(|c| TimeMarks::new(c, cfg.timepulse_quantization_ns)),
        }
    }

    /// The camera on EXTINT0 (UBX with a camera rate > 0).
    pub fn camera(&self) -> Option<&Camera> {
        self.marks.as_ref().map(TimeMarks::camera)
    }

    /// The serial baud rate of the receiver's port.
    pub fn baud(&self) -> u32 {
        self.cfg.baud
    }

    /// Whether scenario time `tau` is inside a configured outage.
    pub fn in_outage(&self, tau: f64) -> bool {
        self.cfg
            .outages
            .iter()
            .any(|o| tau >= o.start_s && tau < o.start_s + o.duration_s)
    }

    /// The next epoch's burst, `None` after the scenario's last epoch.
    pub fn next_burst(&mut self, traj: &Trajectory, osc: &Oscillator) -> Option<NmeaBurst> {
        let utc = self.next_epoch_utc_ns;
        if utc > self.end_utc_ns {
            return None;
        }
        self.next_epoch_utc_ns += self.period_ns;
        let tau = osc.tau_of_utc(utc);
        let (dpos, dvel) = self.draw_noise();
        let mut bytes = Vec::with_capacity(512);
        // The raw side first (a u-blox receiver sends RXM messages before the navigation
        // solution); with it, no fix while fewer than four satellites are tracked.
        // The receiver's own solution replaces the configured fix noise.
        let sky = self.sky.as_mut().map(|sky| {
            let (p, v) = antenna_truth(traj, &self.lever_arm_b, tau);
            let c = traj.kinematics(tau).c_b_n;
            let heading = c[(1, 0)].atan2(c[(0, 0)]);
            sky.write_epoch(utc, tau, p, v, heading, &mut bytes)
        });
        let solved = sky.and_then(|s| s.fix);
        let (dpos, dvel, sigma_pos) = match solved {
            Some(f) => {
                let sh = f.h_acc_m / std::f64::consts::SQRT_2;
                (f.pos_err_ned_m, f.vel_err_ned_mps, [sh, sh, f.v_acc_m])
            }
            None => (dpos, dvel, self.sigma_pos),
        };
        let fix = (!self.in_outage(tau) && sky.is_none_or(|s| s.fix.is_some()))
            .then(|| self.fix_report(traj, tau, dpos, dvel));
        let report = EpochReport {
            utc_ns: utc,
            fix,
            sats_used: sky.map_or(self.cfg.sats_used, |s| s.tracked as u8),
            hdop: self.cfg.hdop,
            vdop: self.cfg.vdop,
            sigma_lat_lon_alt_m: sigma_pos,
        };
        match self.cfg.protocol {
            OutputProtocol::Nmea => nmea::write_burst(self.cfg.talker.as_str(), &report, &mut bytes),
            OutputProtocol::Ubx => {
                // The receiver's accuracy estimates are its noise model: hAcc the horizontal
                // RMS, vAcc the 1-σ vertical error, sAcc √2 × the per-axis velocity σ (the
                // estimator takes sAcc/√2 per axis); with a sky, its solution's covariance.
                let x = ubx::UbxExtras {
                    h_acc_m: solved.map_or(self.cfg.horizontal_rms_m, |f| f.h_acc_m),
                    v_acc_m: solved.map_or(self.cfg.vertical_sigma_m, |f| f.v_acc_m),
                    s_acc_mps: solved.map_or(self.cfg.velocity_sigma_mps * std::f64::consts::SQRT_2, |f| f.s_acc_mps),
                    next_pulse_q_err_ps: ubx::timepulse_q_err_ps(
                        self.cfg.timepulse_quantization_ns,
                        utc.div_euclid(1_000_000_000) + 1,
                    ),
                };
                ubx::write_epoch(&report, &x, &mut bytes);
                if let Some(mark) = self.marks.as_mut().and_then(|m| m.report(utc)) {
                    ubx::frame(0x0D, 0x03, &ubx::tim_tm2(&mark), &mut bytes);
                }
            }
        }
        let latency_s = (self.cfg.latency_s + self.latency_rng.gaussian(self.cfg.latency_jitter_s)).max(0.0);
        let host_ns = osc.host_ns_at_tau(tau + latency_s).max(self.last_host_ns);
        self.last_host_ns = host_ns;
        Some(NmeaBurst {
            host_ns,
            epoch_utc_ns: utc,
            bytes,
            latency_s,
        })
    }

    /// Draws this epoch's position (NED, m) and velocity (NED, m/s) errors.
    fn draw_noise(&mut self) -> ([f64; 3], [f64; 3]) {
        let fresh = self.noise_rng.gaussian3(self.sigma_pos);
        if self.started {
            let drive = (1.0 - self.phi * self.phi).sqrt();
            for (n, w) in self.pos_noise.iter_mut().zip(fresh) {
                *n = self.phi * *n + drive * w;
            }
        } else {
            self.pos_noise = fresh;
            self.started = true;
        }
        let dvel = self.noise_rng.gaussian3([self.cfg.velocity_sigma_mps; 3]);
        (self.pos_noise, dvel)
    }

    fn fix_report(&self, traj: &Trajectory, tau: f64, dpos: [f64; 3], dvel: [f64; 3]) -> FixReport {
        let (p, v) = antenna_truth(traj, &self.lever_arm_b, tau);
        let (rm, rn) = earth::radii(p[0]);
        let lat = p[0] + dpos[0] / (rm + p[2]);
        let lon = p[1] + dpos[1] / ((rn + p[2]) * p[0].cos());
        let h = p[2] - dpos[2];
        FixReport {
            lat_deg: lat.to_degrees(),
            lon_deg: wrap_pi(lon).to_degrees(),
            alt_msl_m: h - self.cfg.geoid_separation_m,
            geoid_sep_m: self.cfg.geoid_separation_m,
            vel_n_mps: v[0] + dvel[0],
            vel_e_mps: v[1] + dvel[1],
            vel_d_mps: v[2] + dvel[2],
        }
    }
}

/// Smallest multiple of `step` ≥ `x` (step > 0).
fn ceil_to(x: i64, step: i64) -> i64 {
    x.div_euclid(step) * step + if x.rem_euclid(step) == 0 { 0 } else { step }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nmea::tests::{parse_angle, parse_burst};
    use crate::scenario::{OutageConfig, SimConfig};
    use crate::trajectory::tests::default_traj;

    const U0: i64 = 1_790_000_000_250_000_000;

    #[test]
    fn epochs_on_the_utc_grid_with_latency() {
        let cfg = SimConfig::default_drive();
        let traj = default_traj();
        let osc = Oscillator::new(0, U0, 0.5e-6, 0.0, 700.0, &mut Rng::new(1));
        let mut rx = GnssReceiver::new(&cfg.gnss, 1, U0, traj.duration_s());
        let b = rx.next_burst(&traj, &osc).expect("epoch");
        assert_eq!(b.epoch_utc_ns, 1_790_000_001_000_000_000);
        let tau = 0.75;
        assert_eq!(b.host_ns, osc.host_ns_at_tau(tau + 0.6));
        let mut n = 1;
        while let Some(next) = rx.next_burst(&traj, &osc) {
            assert_eq!(next.epoch_utc_ns % 1_000_000_000, 0);
            n += 1;
        }
        assert_eq!(n as f64, (traj.duration_s() - tau).floor() + 1.0);
    }

    /// Parse the sentences back and compare with the truth: errors must look like the
    /// configured noise (σ_N = σ_E = 1.5/√2 m, σ_D = 3 m, σ_v = 0.05 m/s).
    #[test]
    fn nmea_parses_back_to_truth_within_noise() {
        let cfg = SimConfig::default_drive();
        let traj = default_traj();
        let osc = Oscillator::new(0, U0, 0.0, 0.0, 700.0, &mut Rng::new(1));
        let mut rx = GnssReceiver::new(&cfg.gnss, 7, U0, traj.duration_s());
        let (mut sn, mut se, mut sd, mut sv, mut n) = (0.0, 0.0, 0.0, 0.0, 0);
        while let Some(b) = rx.next_burst(&traj, &osc) {
            let s = parse_burst(&b.bytes);
            let gga = &s[2];
            let lat = parse_angle(&gga[2], &gga[3], 2).to_radians();
            let lon = parse_angle(&gga[4], &gga[5], 3).to_radians();
            let h: f64 = gga[9].parse::<f64>().expect("alt") + gga[11].parse::<f64>().expect("sep");
            let tau = osc.tau_of_utc(b.epoch_utc_ns);
            let (p, v) = antenna_truth(&traj, &Vector3::zeros(), tau);
            let d = earth::ned_between(p[0], p[1], p[2], lat, lon, h);
            sn += d[0] * d[0];
            se += d[1] * d[1];
            sd += d[2] * d[2];
            let rmc = &s[0];
            let speed = rmc[7].parse::<f64>().expect("speed") / nmea::KNOTS_PER_MPS;
            let course = rmc[8].parse::<f64>().expect("course").to_radians();
            let (vn, ve) = (speed * course.cos(), speed * course.sin());
            sv += (vn - v[0]).powi(2) + (ve - v[1]).powi(2);
            n += 1;
        }
        let nf = n as f64;
        let (rn, re, rd, rv) = (
            (sn / nf).sqrt(),
            (se / nf).sqrt(),
            (sd / nf).sqrt(),
            (sv / (2.0 * nf)).sqrt(),
        );
        let sh = 1.5 / 2f64.sqrt();
        // With ~600 samples a σ estimate is good to ~3 % (1σ); allow 15 %.
        assert!((rn / sh - 1.0).abs() < 0.15, "north {rn}");
        assert!((re / sh - 1.0).abs() < 0.15, "east {re}");
        assert!((rd / 3.0 - 1.0).abs() < 0.15, "down {rd}");
        assert!((rv / 0.05 - 1.0).abs() < 0.15, "vel {rv}");
    }

    #[test]
    fn noise_free_fix_is_exact_to_print_precision() {
        let mut cfg = SimConfig::default_drive();
        cfg.set_noise_free();
        cfg.gnss.antenna_lever_arm_m = [1.0, -0.5, -1.2];
        let traj = default_traj();
        let osc = Oscillator::new(0, U0, 0.0, 0.0, 700.0, &mut Rng::new(1));
        let mut rx = GnssReceiver::new(&cfg.gnss, 7, U0, traj.duration_s());
        let lever = Vector3::new(1.0, -0.5, -1.2);
        while let Some(b) = rx.next_burst(&traj, &osc) {
            let s = parse_burst(&b.bytes);
            let gga = &s[2];
            let lat = parse_angle(&gga[2], &gga[3], 2).to_radians();
            let lon = parse_angle(&gga[4], &gga[5], 3).to_radians();
            let h: f64 = gga[9].parse::<f64>().expect("alt") + gga[11].parse::<f64>().expect("sep");
            let (p, _) = antenna_truth(&traj, &lever, osc.tau_of_utc(b.epoch_utc_ns));
            let d = earth::ned_between(p[0], p[1], p[2], lat, lon, h);
            assert!(d[0].abs() < 2e-4 && d[1].abs() < 2e-4 && d[2].abs() < 6e-4, "{d:?}");
        }
    }

    #[test]
    fn antenna_lever_arm_velocity_matches_position_derivative() {
        let traj = default_traj();
        let lever = Vector3::new(1.5, 0.3, -1.0);
        let hh = 1e-3;
        for i in 0..300 {
            let t = 1.0 + 2.0 * i as f64;
            if t + hh > traj.duration_s() {
                break;
            }
            let (pm, _) = antenna_truth(&traj, &lever, t - hh);
            let (pp, _) = antenna_truth(&traj, &lever, t + hh);
            let (_, v) = antenna_truth(&traj, &lever, t);
            let d = earth::ned_between(pm[0], pm[1], pm[2], pp[0], pp[1], pp[2]);
            let fd = Vector3::new(d[0], d[1], d[2]) / (2.0 * hh);
            assert!((fd - v).norm() < 1e-5, "t={t}: {fd} vs {v}");
        }
    }

    #[test]
    fn outage_reports_no_fix() {
        let mut cfg = SimConfig::default_drive();
        cfg.gnss.outages = vec![OutageConfig {
            start_s: 100.0,
            duration_s: 10.0,
            pps_continues: true,
        }];
        let traj = default_traj();
        let osc = Oscillator::new(0, U0, 0.0, 0.0, 700.0, &mut Rng::new(1));
        let mut rx = GnssReceiver::new(&cfg.gnss, 7, U0, traj.duration_s());
        let mut no_fix = 0;
        while let Some(b) = rx.next_burst(&traj, &osc) {
            let tau = osc.tau_of_utc(b.epoch_utc_ns);
            let s = parse_burst(&b.bytes);
            let out = (100.0..110.0).contains(&tau);
            assert_eq!(s[2][6], if out { "0" } else { "1" }, "τ={tau}");
            assert_eq!(s[0][2], if out { "V" } else { "A" });
            no_fix += usize::from(out);
        }
        assert_eq!(no_fix, 10);
    }

    #[test]
    fn ceil_to_grid() {
        assert_eq!(ceil_to(1000, 100), 1000);
        assert_eq!(ceil_to(1001, 100), 1100);
        assert_eq!(ceil_to(-50, 100), 0);
    }
}
