//! Accuracy of a navigation run: against the simulated truth while it runs (this module: the
//! numbers of the accuracy report of `navsync replay --estimate --summary-json`, `sim --fast
//! --estimate` and the end of `navsync demo`), and one trajectory against another afterwards
//! ([`track`]: `navsync eval`, the report's error plots). One set of angle helpers.
//!
//! Each `NavState` is compared with the truth interpolated linearly to its host time (truth
//! arrives at 100–200 Hz; the interpolation error is below 0.1 mm and 1e−5 m/s for car
//! dynamics). Only states after alignment count. Position errors are NED metres through ECEF
//! ([`earth::ned_between`]); attitude errors are differences of roll, pitch and yaw wrapped to ±180°.

pub mod track;

use std::collections::{BTreeMap, VecDeque};

use navsync_wire::earth;
use navsync_wire::reflect::str_of;
use navsync_wire::samples::{ImuSync, MAX_IMUS, NavState, NavStatus, SimTruth};
use serde::Serialize;

/// Which delay the filter should find: under software sync the fixes are stamped at receipt,
/// so Δ equals the receiver latency; under hardware sync Δ should be 0.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DelayTruth {
    /// Δ_true = the simulated NMEA latency d0.
    ReceiverLatency,
    /// Δ_true = 0.
    Zero,
}

/// One point of the 1 Hz error series.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct SeriesPoint {
    /// Seconds since the first navigation state.
    pub t_s: f64,
    /// Horizontal position error, m.
    pub h_err_m: f64,
    /// Estimated GNSS delay, s.
    pub delay_s: f64,
    /// Its 1-sigma, s.
    pub delay_std_s: f64,
    /// Filter status.
    pub status: u8,
}

/// The summary of a run (field names are the report's JSON keys).
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    /// Span of the navigation states, s.
    pub duration_s: f64,
    /// IMU samples fed to the estimator.
    pub imu_samples: u64,
    /// GNSS fixes fed to the estimator.
    pub gnss_fixes: u64,
    /// Horizontal position RMS, m (null without truth).
    pub pos_rms_m: Option<f64>,
    /// Largest horizontal position error, m.
    pub pos_max_m: Option<f64>,
    /// The fraction of the compared states whose north and east errors both lie within 2σ
    /// of their own published σ (`pos_std_ned_m`): whether the σ covers the error (about 0.9
    /// for Gaussian errors and a true σ, 0.95 per axis).
    pub pos_within_2sigma: Option<f64>,
    /// Altitude RMS, m.
    pub alt_rms_m: Option<f64>,
    /// Velocity RMS (3D), m/s.
    pub vel_rms_mps: Option<f64>,
    /// Velocity RMS per axis N, E, D, m/s.
    pub vel_rms_ned_mps: Option<[f64; 3]>,
    /// Roll, pitch, yaw RMS, degrees.
    pub att_rms_deg: Option<[f64; 3]>,
    /// Final estimate of the GNSS delay Δ, s.
    pub gnss_delay_est_s: Option<f64>,
    /// Its 1-sigma, s.
    pub gnss_delay_std_s: Option<f64>,
    /// The true Δ, s.
    pub gnss_delay_true_s: Option<f64>,
    /// Fixes rejected by the innovation gate.
    pub rejected_fixes: u64,
    /// Wall-clock time of the run, s (including producing or decoding the samples).
    pub wall_s: f64,
    /// Wall-clock time spent inside the estimator, s.
    pub estimator_s: f64,
    /// IMU samples per second of estimator time (single thread).
    pub imu_samples_per_s: f64,
    /// Navigation states compared with the truth.
    pub compared_states: u64,
    /// Horizontal error at the end of each GNSS outage (the last INS-only state), m.
    pub outage_end_h_err_m: Vec<f64>,
    /// Final estimated IMU offsets Td relative to the reference IMU, s, by IMU id.
    pub imu_offset_est_s: BTreeMap<String, f64>,
    /// Their 1-sigma, s.
    pub imu_offset_std_s: BTreeMap<String, f64>,
    /// The true offsets, s (empty without truth).
    pub imu_offset_true_s: BTreeMap<String, f64>,
    /// The counters of each kind of measurement (`zupt_used`, …).
    pub measurement_counters: BTreeMap<String, u64>,
    /// Navigation states produced.
    pub nav_states: u64,
    /// Of those, usable: aligned, with a GNSS time.
    pub usable_states: u64,
    /// Why there were no usable states, or far fewer than states (null when as expected;
    /// offline commands then exit non-zero).
    pub problem: Option<String>,
    /// 1 Hz error series.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub series: Vec<SeriesPoint>,
}

/// Accumulates errors of navigation states against the truth.
#[derive(Debug)]
pub struct Evaluator {
    truth: VecDeque<SimTruth>,
    pending: VecDeque<NavState>,
    n: u64,
    sum_h2: f64,
    /// Compared states whose N and E errors lie within 2σ.
    within_2sigma: u64,
    max_h: f64,
    sum_alt2: f64,
    sum_v2: [f64; 3],
    sum_att2: [f64; 3],
    first_ns: Option<i64>,
    last_ns: i64,
    last_series_ns: i64,
    series: Vec<SeriesPoint>,
    last_delay: (f64, f64),
    true_latency_s: Option<f64>,
    outage_last_err: Option<f64>,
    outage_end_errs: Vec<f64>,
    last_imu_table: Option<([ImuSync; MAX_IMUS], u8)>,
    true_imu_offsets: Option<([f64; MAX_IMUS], u8)>,
}

impl Default for Evaluator {
    fn default() -> Self {
        Self {
            truth: VecDeque::new(),
            pending: VecDeque::new(),
            n: 0,
            sum_h2: 0.0,
            within_2sigma: 0,
            max_h: 0.0,
            sum_alt2: 0.0,
            sum_v2: [0.0; 3],
            sum_att2: [0.0; 3],
            first_ns: None,
            last_ns: 0,
            last_series_ns: 0,
            series: Vec::new(),
            last_delay: (f64::NAN, f64::NAN),
            true_latency_s: None,
            outage_last_err: None,
            outage_end_errs: Vec::new(),
            last_imu_table: None,
            true_imu_offsets: None,
        }
    }
}

/// `a` wrapped to [−period/2, period/2) (an angle difference, period 360° or 2π).
fn wrap(a: f64, period: f64) -> f64 {
    (a + 0.5 * period).rem_euclid(period) - 0.5 * period
}

/// An angle difference wrapped to [−180°, 180°), deg.
pub fn wrap_deg(a: f64) -> f64 {
    wrap(a, 360.0)
}

/// From angle `a` towards `b` by the fraction `w` along the shorter arc, deg.
pub fn lerp_angle_deg(a: f64, b: f64, w: f64) -> f64 {
    a + wrap_deg(b - a) * w
}

fn lerp(a: f64, b: f64, w: f64) -> f64 {
    a + (b - a) * w
}

/// From angle `a` towards `b` by the fraction `w` along the shorter arc, rad.
fn lerp_angle(a: f64, b: f64, w: f64) -> f64 {
    a + wrap(b - a, 2.0 * std::f64::consts::PI) * w
}

impl Evaluator {
    /// Adds a truth sample (in host-time order).
    pub fn add_truth(&mut self, t: &SimTruth) {
        self.true_latency_s = Some(t.gnss_latency_s);
        self.true_imu_offsets = Some((t.imu_offset_s, t.imu_count));
        self.truth.push_back(*t);
        while self.truth.len() > 2 && self.truth[1].host_ns <= self.pending.front().map_or(t.host_ns, |n| n.host_ns) {
            self.truth.pop_front();
        }
        self.drain();
    }

    /// Adds a navigation state (compared once the truth after it has arrived).
    pub fn add_nav(&mut self, s: &NavState) {
        self.first_ns.get_or_insert(s.host_ns);
        self.last_imu_table = Some((s.imu, s.imu_count));
        self.last_ns = s.host_ns;
        if s.gnss_delay_s.is_finite() {
            self.last_delay = (s.gnss_delay_s, s.gnss_delay_std_s);
        }
        if s.status != NavStatus::Aligning as u8 {
            self.pending.push_back(*s);
            // Bounded: without truth nothing is compared.
            if self.pending.len() > 4096 {
                self.pending.pop_front();
            }
        }
        self.drain();
    }

    fn drain(&mut self) {
        while let Some(s) = self.pending.front().copied() {
            let Some(last) = self.truth.back() else { return };
            if last.host_ns < s.host_ns {
                return;
            }
            self.pending.pop_front();
            let Some(i) = self.truth.iter().position(|t| t.host_ns >= s.host_ns) else {
                continue;
            };
            if i == 0 {
                continue; // before the first truth sample
            }
            let (a, b) = (self.truth[i - 1], self.truth[i]);
            let w = (s.host_ns - a.host_ns) as f64 / (b.host_ns - a.host_ns).max(1) as f64;
            self.compare(&s, &a, &b, w);
        }
    }

    fn compare(&mut self, s: &NavState, a: &SimTruth, b: &SimTruth, w: f64) {
        let lat = lerp(a.lat_deg, b.lat_deg, w).to_radians();
        let lon = lerp(a.lon_deg, b.lon_deg, w).to_radians();
        let h = lerp(a.height_m, b.height_m, w);
        let d = earth::ned_between(lat, lon, h, s.lat_deg.to_radians(), s.lon_deg.to_radians(), s.height_m);
        let h_err = (d[0] * d[0] + d[1] * d[1]).sqrt();
        if s.status == NavStatus::InsOnly as u8 {
            self.outage_last_err = Some(h_err);
        } else if let Some(e) = self.outage_last_err.take() {
            self.outage_end_errs.push(e);
        }
        self.n += 1;
        self.sum_h2 += h_err * h_err;
        // A NaN σ never covers.
        if d[0].abs() <= 2.0 * s.pos_std_ned_m[0] && d[1].abs() <= 2.0 * s.pos_std_ned_m[1] {
            self.within_2sigma += 1;
        }
        self.max_h = self.max_h.max(h_err);
        self.sum_alt2 += d[2] * d[2];
        for k in 0..3 {
            let v = lerp(a.vel_ned_mps[k], b.vel_ned_mps[k], w);
            self.sum_v2[k] += (s.vel_ned_mps[k] - v).powi(2);
            let t = lerp_angle(a.rpy_rad[k], b.rpy_rad[k], w);
            self.sum_att2[k] += wrap_deg((s.rpy_rad[k] - t).to_degrees()).powi(2);
        }
        if s.host_ns - self.last_series_ns >= 1_000_000_000 {
            self.last_series_ns = s.host_ns;
            self.series.push(SeriesPoint {
                t_s: (s.host_ns - self.first_ns.unwrap_or(s.host_ns)) as f64 * 1e-9,
                h_err_m: h_err,
                delay_s: s.gnss_delay_s,
                delay_std_s: s.gnss_delay_std_s,
                status: s.status,
            });
        }
    }

    /// The summary; `counts` = (IMU samples, fixes, rejected fixes), `wall_s` the run's wall
    /// time and `estimator_s` the part of it spent inside the estimator.
    pub fn summary(&self, counts: (u64, u64, u64), wall_s: f64, estimator_s: f64, delay_truth: DelayTruth) -> Summary {
        let have = self.n > 0;
        let n = self.n.max(1) as f64;
        let rms = |s: f64| have.then(|| (s / n).sqrt());
        Summary {
            duration_s: (self.last_ns - self.first_ns.unwrap_or(self.last_ns)) as f64 * 1e-9,
            imu_samples: counts.0,
            gnss_fixes: counts.1,
            pos_rms_m: rms(self.sum_h2),
            pos_max_m: have.then_some(self.max_h),
            pos_within_2sigma: have.then(|| self.within_2sigma as f64 / n),
            alt_rms_m: rms(self.sum_alt2),
            vel_rms_mps: rms(self.sum_v2.iter().sum()),
            vel_rms_ned_mps: have.then(|| self.sum_v2.map(|s| (s / n).sqrt())),
            att_rms_deg: have.then(|| self.sum_att2.map(|s| (s / n).sqrt())),
            gnss_delay_est_s: self.last_delay.0.is_finite().then_some(self.last_delay.0),
            gnss_delay_std_s: self.last_delay.1.is_finite().then_some(self.last_delay.1),
            // A truth that does not know the latency (an import of receipt tags) gives none.
            gnss_delay_true_s: self
                .true_latency_s
                .filter(|l| l.is_finite())
                .map(|l| match delay_truth {
                    DelayTruth::ReceiverLatency => l,
                    DelayTruth::Zero => 0.0,
                }),
            rejected_fixes: counts.2,
            wall_s,
            estimator_s,
            imu_samples_per_s: if estimator_s > 0.0 {
                counts.0 as f64 / estimator_s
            } else {
                0.0
            },
            compared_states: self.n,
            outage_end_h_err_m: self
                .outage_end_errs
                .iter()
                .copied()
                .chain(self.outage_last_err)
                .collect(),
            imu_offset_est_s: self.imu_map(|e| e.offset_s),
            imu_offset_std_s: self.imu_map(|e| e.offset_std_s),
            imu_offset_true_s: match (&self.last_imu_table, &self.true_imu_offsets) {
                (Some((t, n)), Some((truth, m))) => t[..(*n).min(*m) as usize]
                    .iter()
                    .zip(truth)
                    .map(|(e, v)| (str_of(&e.imu_id).to_string(), *v))
                    .collect(),
                _ => BTreeMap::new(),
            },
            measurement_counters: BTreeMap::new(),
            nav_states: 0,
            usable_states: 0,
            problem: None,
            series: self.series.clone(),
        }
    }
}

impl Evaluator {
    fn imu_map(&self, f: impl Fn(&ImuSync) -> f64) -> BTreeMap<String, f64> {
        self.last_imu_table
            .as_ref()
            .map(|(t, n)| {
                t[..*n as usize]
                    .iter()
                    .map(|e| (str_of(&e.imu_id).to_string(), f(e)))
                    .collect()
            })
            .unwrap_or_default()
    }
}

impl Summary {
    /// The summary as a small text table.
    pub fn table(&self) -> String {
        let f = |v: Option<f64>, unit: &str| v.map_or("n/a".to_string(), |x| format!("{x:.4} {unit}"));
        let mut s = String::new();
        s.push_str(&format!("duration            {:.1} s\n", self.duration_s));
        s.push_str(&format!("IMU samples         {}\n", self.imu_samples));
        s.push_str(&format!(
            "GNSS fixes          {} ({} rejected)\n",
            self.gnss_fixes, self.rejected_fixes
        ));
        s.push_str(&format!(
            "position RMS (hor.) {}  (max {})\n",
            f(self.pos_rms_m, "m"),
            f(self.pos_max_m, "m")
        ));
        if let Some(c) = self.pos_within_2sigma {
            s.push_str(&format!("N and E within 2σ   {:.1} % of the states\n", 100.0 * c));
        }
        s.push_str(&format!("altitude RMS        {}\n", f(self.alt_rms_m, "m")));
        s.push_str(&format!("velocity RMS        {}", f(self.vel_rms_mps, "m/s")));
        if let Some(v) = self.vel_rms_ned_mps {
            s.push_str(&format!("  (N {:.4}, E {:.4}, D {:.4})", v[0], v[1], v[2]));
        }
        s.push('\n');
        match self.att_rms_deg {
            Some(a) => s.push_str(&format!(
                "attitude RMS        roll {:.4}°, pitch {:.4}°, yaw {:.4}°\n",
                a[0], a[1], a[2]
            )),
            None => s.push_str("attitude RMS        n/a\n"),
        }
        s.push_str(&format!(
            "GNSS delay Δ        {} ± {} (true {})\n",
            f(self.gnss_delay_est_s, "s"),
            f(self.gnss_delay_std_s, "s"),
            f(self.gnss_delay_true_s, "s")
        ));
        for (i, e) in self.outage_end_h_err_m.iter().enumerate() {
            s.push_str(&format!(
                "GNSS outage {}       horizontal error at its end {e:.2} m\n",
                i + 1
            ));
        }
        for (id, est) in &self.imu_offset_est_s {
            let sd = self.imu_offset_std_s.get(id).copied().unwrap_or(f64::NAN);
            let truth = self
                .imu_offset_true_s
                .get(id)
                .map_or("n/a".to_string(), |t| format!("{:.4} ms", t * 1e3));
            s.push_str(&format!(
                "IMU {id:<3} offset Td   {:.4} ± {:.4} ms (true {truth})\n",
                est * 1e3,
                sd * 1e3
            ));
        }
        if let Some(p) = &self.problem {
            s.push_str(&format!("WARNING             {p}\n"));
        }
        if !self.measurement_counters.is_empty() {
            let list: Vec<String> = self
                .measurement_counters
                .iter()
                .map(|(k, v)| format!("{k} {v}"))
                .collect();
            s.push_str(&format!("measurements        {}\n", list.join(", ")));
        }
        if self.estimator_s > 0.0 {
            s.push_str(&format!(
                "throughput          {:.0} IMU samples/s in the estimator ({:.2} s of {:.2} s wall)\n",
                self.imu_samples_per_s, self.estimator_s, self.wall_s
            ));
        }
        s
    }
}
