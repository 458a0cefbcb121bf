//! Shared by the data-fault tests (`faults_pps_silence.rs`, `faults_imu_samples.rs`,
//! `faults_gnss_jump.rs`): the simulated default drive through the estimator pipeline in the
//! live input order ([`InputOrder`], as `navsync estimator` and `replay --estimate` consume it),
//! with a hook that edits the published samples (the fault), and errors of the navigation
//! states against the simulator's truth.
//!
//! Deterministic: the same scenario, seed and edits give the same figures on every machine and
//! in debug builds (what CI's `cargo test --workspace` runs; dependencies are optimised there
//! too, and a 260 s drive takes about a second either way).

#![allow(dead_code)]

use navsync_estimator::input_order::{Input, InputOrder};
use navsync_estimator::pipeline::Pipeline;
use navsync_estimator::settings::Settings;
use navsync_sim::imu_errors::ImuPreset;
use navsync_sim::published::PublishedStream;
use navsync_sim::scenario::SimConfig;
use navsync_sim::world::World;
use navsync_wire::earth;
use navsync_wire::samples::{AnySample, GnssFix, NavState, NavStatus, SimTruth};

/// Host time (`CLOCK_MONOTONIC`, ns) of scenario time 0.
pub const HOST0: i64 = 3_000_000_000;
/// UTC at scenario time 0, ns.
pub const UTC0: i64 = 1_790_000_000_000_000_000;

/// Scenario time of a host time stamp, s.
pub fn t_s(host_ns: i64) -> f64 {
    (host_ns - HOST0) as f64 * 1e-9
}

/// The default drive (40 s standing, then driving) with one industrial IMU at 200 Hz, 1 Hz
/// GNSS (1.5 m, 0.05 m/s), PPS with 1 µs jitter, host clock +0.5 ppm with random-walk FM.
pub fn scenario() -> SimConfig {
    let mut cfg = SimConfig::default_drive();
    cfg.set_imu_count(1);
    cfg.set_imu_preset(ImuPreset::Industrial);
    cfg.set_clock_ppm(0.5);
    cfg.set_pps_jitter_s(1e-6);
    cfg
}

/// The estimator of `navsync estimator` for [`scenario`]: hardware sync, industrial IMU model,
/// Δ estimated, the simulated receiver's velocity noise.
pub fn estimator_args() -> Settings {
    let mut s = Settings::default();
    s.imu.imu_model = ImuPreset::Industrial;
    s.gnss.gnss_vel_std_mps = 0.05;
    s
}

/// What the test sees of a run.
pub enum Event<'a> {
    /// The navigation state of a reference-IMU sample, right after the pipeline made it.
    Nav(&'a NavState),
    /// A truth instant, after the pipeline has consumed every input ordered before it.
    Truth(&'a SimTruth),
}

/// Runs `cfg` through a [`Pipeline`] built from `args` until `end_s` of scenario time.
/// `edit` gets every published sample in delivery order and pushes what the estimator shall
/// receive instead (nothing, the sample, a changed sample, extra samples); `observe` sees the
/// navigation states and truth instants with the pipeline. Returns the pipeline (counters).
pub fn drive(
    cfg: &SimConfig,
    args: &Settings,
    end_s: f64,
    mut edit: impl FnMut(AnySample, &mut Vec<AnySample>),
    mut observe: impl FnMut(&mut Pipeline, Event<'_>),
) -> Pipeline {
    let world = World::new(cfg, HOST0, UTC0).expect("world");
    let mut p = Pipeline::new(args.pipeline_config());
    let mut order: InputOrder = InputOrder::new(args.inputs.imus.first().map(String::as_str));
    let end_ns = HOST0 + (end_s * 1e9) as i64;
    let mut consume = |p: &mut Pipeline, s: Input| match s {
        Input::Imu(x) => {
            if let Some(n) = p.on_imu(&x) {
                observe(p, Event::Nav(&n));
            }
        }
        Input::PpsEdge(e) => {
            p.on_pps(&e);
        }
        Input::GnssFix(f) => {
            p.on_fix(&f);
        }
        Input::Truth(t) => observe(p, Event::Truth(&t)),
        _ => {}
    };
    let mut edited = Vec::with_capacity(4);
    for item in PublishedStream::new(world) {
        if item.delivered_ns > end_ns {
            break;
        }
        edit(item.sample, &mut edited);
        for s in edited.drain(..) {
            order.push(s, ());
            while let Some((s, ())) = order.pop() {
                consume(&mut p, s);
            }
        }
    }
    while let Some((s, ())) = order.pop_any() {
        consume(&mut p, s);
    }
    p
}

/// Passes every sample through unchanged.
pub fn unchanged(s: AnySample, out: &mut Vec<AnySample>) {
    out.push(s);
}

/// Error of a navigation state against the truth at one instant.
#[derive(Debug, Clone, Copy)]
pub struct NavError {
    /// Scenario time of the truth instant, s.
    pub t_s: f64,
    /// Horizontal position error, m.
    pub h_m: f64,
    /// Position error north, east, down (estimate − truth), m.
    pub ned_m: [f64; 3],
    /// Velocity error magnitude, m/s.
    pub vel_mps: f64,
    /// Yaw error, degrees (−180…180).
    pub yaw_deg: f64,
    /// The state's `NavStatus` as `u8`.
    pub status: u8,
}

/// Compares the latest navigation state with each truth instant (10 Hz).
#[derive(Default)]
pub struct ErrorTrack {
    last: Option<NavState>,
    /// One entry per truth instant after alignment.
    pub errors: Vec<NavError>,
    /// Navigation states seen after alignment.
    pub states: u64,
    /// The first aligned state with a non-finite field, if any.
    pub non_finite: Option<(f64, &'static str)>,
    /// Truth instants minus a displacement (north, east), m, from this scenario time on: the
    /// truth a shifted GNSS (a receiver reset, a spoofer) describes.
    pub shift_from: Option<(f64, [f64; 2])>,
}

impl ErrorTrack {
    /// Feeds one event of [`drive`].
    pub fn on(&mut self, e: &Event<'_>) {
        match e {
            Event::Nav(n) => {
                if n.status != NavStatus::Aligning as u8 {
                    self.states += 1;
                    if self.non_finite.is_none()
                        && let Some(field) = non_finite_field(n)
                    {
                        self.non_finite = Some((t_s(n.host_ns), field));
                    }
                }
                self.last = Some(**n);
            }
            Event::Truth(t) => {
                let Some(n) = self.last.filter(|n| n.status != NavStatus::Aligning as u8) else {
                    return;
                };
                // The state is for the IMU sample at or just before the truth instant.
                if t.host_ns < n.host_ns || t.host_ns - n.host_ns > 20_000_000 {
                    return;
                }
                let mut truth = **t;
                if let Some((from, [dn, de])) = self.shift_from
                    && t_s(t.host_ns) >= from
                {
                    (truth.lat_deg, truth.lon_deg) = displaced(truth.lat_deg, truth.lon_deg, truth.height_m, dn, de);
                }
                self.errors.push(nav_error(&n, &truth));
            }
        }
    }

    /// Errors with `from_s <= t < to_s`.
    pub fn window(&self, from_s: f64, to_s: f64) -> impl Iterator<Item = &NavError> {
        self.errors.iter().filter(move |e| e.t_s >= from_s && e.t_s < to_s)
    }

    /// (horizontal RMS, horizontal max, velocity RMS, count) over `from_s <= t < to_s`.
    pub fn stats(&self, from_s: f64, to_s: f64) -> Stats {
        let mut s = Stats::default();
        for e in self.window(from_s, to_s) {
            s.n += 1;
            s.h_rms_m += e.h_m * e.h_m;
            s.h_max_m = s.h_max_m.max(e.h_m);
            s.vel_rms_mps += e.vel_mps * e.vel_mps;
            s.yaw_max_deg = s.yaw_max_deg.max(e.yaw_deg.abs());
        }
        let n = s.n.max(1) as f64;
        s.h_rms_m = (s.h_rms_m / n).sqrt();
        s.vel_rms_mps = (s.vel_rms_mps / n).sqrt();
        s
    }
}

/// Error statistics over a window of truth instants.
#[derive(Debug, Clone, Copy, Default)]
pub struct Stats {
    /// Horizontal position RMS, m.
    pub h_rms_m: f64,
    /// Horizontal position maximum, m.
    pub h_max_m: f64,
    /// Velocity RMS (magnitude of the vector error), m/s.
    pub vel_rms_mps: f64,
    /// Largest yaw error, degrees.
    pub yaw_max_deg: f64,
    /// Truth instants compared.
    pub n: usize,
}

impl std::fmt::Display for Stats {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "horizontal RMS {:.3} m, max {:.3} m, velocity RMS {:.3} m/s, yaw max {:.2}° ({} instants)",
            self.h_rms_m, self.h_max_m, self.vel_rms_mps, self.yaw_max_deg, self.n
        )
    }
}

/// The name of the first non-finite navigation field of an aligned state, if any.
pub fn non_finite_field(n: &NavState) -> Option<&'static str> {
    let fields: [(&'static str, &[f64]); 11] = [
        ("lat_deg", &[n.lat_deg]),
        ("lon_deg", &[n.lon_deg]),
        ("height_m", &[n.height_m]),
        ("vel_ned_mps", &n.vel_ned_mps),
        ("rpy_rad", &n.rpy_rad),
        ("q_nb", &n.q_nb),
        ("gyro_body_rps", &n.gyro_body_rps),
        ("accel_body_mps2", &n.accel_body_mps2),
        ("pos_std_ned_m", &n.pos_std_ned_m),
        ("gyro_bias_rps", &n.gyro_bias_rps),
        ("accel_bias_mps2", &n.accel_bias_mps2),
    ];
    fields
        .into_iter()
        .find(|(_, v)| v.iter().any(|x| !x.is_finite()))
        .map(|(name, _)| name)
}

/// The error of state `n` against truth `t` (a truth instant at most one IMU period after the
/// state: the state's position is carried to it along its velocity).
pub fn nav_error(n: &NavState, t: &SimTruth) -> NavError {
    let dt = (t.host_ns - n.host_ns) as f64 * 1e-9;
    let (lat, lon, h) = (n.lat_deg.to_radians(), n.lon_deg.to_radians(), n.height_m);
    let (rm, rn) = earth::radii(lat);
    let lat = lat + n.vel_ned_mps[0] * dt / (rm + h);
    let lon = lon + n.vel_ned_mps[1] * dt / ((rn + h) * lat.cos());
    let h = h - n.vel_ned_mps[2] * dt;
    let d = earth::ned_between(t.lat_deg.to_radians(), t.lon_deg.to_radians(), t.height_m, lat, lon, h);
    let dv = (0..3)
        .map(|k| (n.vel_ned_mps[k] - t.vel_ned_mps[k]).powi(2))
        .sum::<f64>();
    let yaw = (n.rpy_rad[2] + n.gyro_body_rps[2] * dt - t.rpy_rad[2]).to_degrees();
    NavError {
        t_s: t_s(t.host_ns),
        h_m: d[0].hypot(d[1]),
        ned_m: d,
        vel_mps: dv.sqrt(),
        yaw_deg: (yaw + 180.0).rem_euclid(360.0) - 180.0,
        status: n.status,
    }
}

/// (lat, lon) in degrees moved by `north_m`, `east_m` at height `h_m`.
pub fn displaced(lat_deg: f64, lon_deg: f64, h_m: f64, north_m: f64, east_m: f64) -> (f64, f64) {
    let lat = lat_deg.to_radians();
    let (rm, rn) = earth::radii(lat);
    (
        lat_deg + (north_m / (rm + h_m)).to_degrees(),
        lon_deg + (east_m / ((rn + h_m) * lat.cos())).to_degrees(),
    )
}

/// A fix moved by `north_m`, `east_m` (its velocity, time and accuracy unchanged).
pub fn displace_fix(f: &GnssFix, north_m: f64, east_m: f64) -> GnssFix {
    let mut g = *f;
    let h = f.alt_msl_m + if f.geoid_sep_m.is_finite() { f.geoid_sep_m } else { 0.0 };
    (g.lat_deg, g.lon_deg) = displaced(f.lat_deg, f.lon_deg, h, north_m, east_m);
    g
}
