//! Errors of one trajectory against another (both on GPS time): the statistics of
//! `navsync eval` and of the report's error plots.
//!
//! The truth is interpolated linearly to every solution point inside its span (roll, pitch
//! and yaw along the shorter arc); the errors are solution minus truth: position in metres
//! north/east/down at the truth point (through ECEF, [`earth::ned_between`]), velocity NED,
//! roll/pitch/yaw wrapped to ±180°. When either trajectory lacks the GPS week, both are
//! compared on seconds of week.

use navsync_wire::earth;
use navsync_wire::time::NS_PER_S;
use serde::Serialize;

use super::{lerp_angle_deg, wrap_deg};

/// One GPS week, ns.
const WEEK_NS: i64 = 604_800 * NS_PER_S;

/// A point of a trajectory on GPS time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackPoint {
    /// GPS time, s (since 1980-01-06; or seconds of week when the week is unknown).
    pub t_s: f64,
    /// Latitude, deg.
    pub lat_deg: f64,
    /// Longitude, deg.
    pub lon_deg: f64,
    /// Ellipsoidal height, m.
    pub height_m: f64,
    /// Velocity NED, m/s.
    pub vel_ned_mps: [f64; 3],
    /// Roll, pitch, yaw, deg.
    pub rpy_deg: [f64; 3],
}

/// A trajectory as sampled points (a recording, a KF-GINS file) and whether their times carry
/// the week.
#[derive(Debug, Clone, Default)]
pub struct Track {
    /// The points in time order.
    pub points: Vec<TrackPoint>,
    /// False when the times are seconds of week only.
    pub week_known: bool,
    /// Where it came from (for messages).
    pub source: String,
}

impl Track {
    /// Drops the weeks (seconds of week only).
    pub fn convert_to_sow(&mut self) {
        if self.week_known {
            let w = WEEK_NS as f64 * 1e-9;
            for p in &mut self.points {
                p.t_s = p.t_s.rem_euclid(w);
            }
            self.week_known = false;
        }
    }
}

/// The error of one solution point.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct ErrorPoint {
    /// Time, s (as the trajectories).
    pub t_s: f64,
    /// Position error north, east, down, m.
    pub pos_ned_m: [f64; 3],
    /// Velocity error NED, m/s.
    pub vel_ned_mps: [f64; 3],
    /// Roll, pitch, yaw error, deg.
    pub att_deg: [f64; 3],
}

/// The solution's errors against the truth at every solution point inside the truth's span
/// (truth gaps over `max_gap_s` are not bridged).
pub fn errors(truth: &Track, solution: &Track, max_gap_s: f64) -> Vec<ErrorPoint> {
    let (mut truth, mut solution) = (truth.clone(), solution.clone());
    if !(truth.week_known && solution.week_known) {
        truth.convert_to_sow();
        solution.convert_to_sow();
    }
    let tp = &truth.points;
    let mut out = Vec::new();
    let mut j = 0;
    for s in &solution.points {
        while j + 1 < tp.len() && tp[j + 1].t_s < s.t_s {
            j += 1;
        }
        if j + 1 >= tp.len() || tp[j].t_s > s.t_s {
            continue;
        }
        let (a, b) = (&tp[j], &tp[j + 1]);
        let span = b.t_s - a.t_s;
        if span > max_gap_s || span <= 0.0 {
            continue;
        }
        let w = (s.t_s - a.t_s) / span;
        let lerp = |x: f64, y: f64| x + (y - x) * w;
        let lat = lerp(a.lat_deg, b.lat_deg);
        let lon = lerp(a.lon_deg, b.lon_deg);
        let h = lerp(a.height_m, b.height_m);
        let pos = earth::ned_between(
            lat.to_radians(),
            lon.to_radians(),
            h,
            s.lat_deg.to_radians(),
            s.lon_deg.to_radians(),
            s.height_m,
        );
        let mut vel = [0.0; 3];
        let mut att = [0.0; 3];
        for k in 0..3 {
            vel[k] = s.vel_ned_mps[k] - lerp(a.vel_ned_mps[k], b.vel_ned_mps[k]);
            att[k] = wrap_deg(s.rpy_deg[k] - lerp_angle_deg(a.rpy_deg[k], b.rpy_deg[k], w));
        }
        out.push(ErrorPoint {
            t_s: s.t_s,
            pos_ned_m: pos,
            vel_ned_mps: vel,
            att_deg: att,
        });
    }
    out
}

/// Statistics of one error component.
#[derive(Debug, Clone, Copy, Default, Serialize, PartialEq)]
pub struct Stat {
    /// Mean.
    pub mean: f64,
    /// Standard deviation.
    pub std: f64,
    /// Root mean square.
    pub rms: f64,
    /// Largest absolute value.
    pub max_abs: f64,
}

impl Stat {
    fn of(v: impl Iterator<Item = f64> + Clone) -> Self {
        let n = v.clone().count().max(1) as f64;
        let mean = v.clone().sum::<f64>() / n;
        let ms = v.clone().map(|x| x * x).sum::<f64>() / n;
        Self {
            mean,
            std: (ms - mean * mean).max(0.0).sqrt(),
            rms: ms.sqrt(),
            max_abs: v.fold(0.0, |m, x| m.max(x.abs())),
        }
    }
}

/// The report of `navsync eval` (its JSON keys).
#[derive(Debug, Clone, Serialize)]
pub struct EvalReport {
    /// The truth file.
    pub truth: String,
    /// The solution file.
    pub solution: String,
    /// Points compared.
    pub compared: usize,
    /// Solution points not inside the truth's span (or skipped).
    pub not_compared: usize,
    /// Span of the compared points, s.
    pub span_s: f64,
    /// Position error north, east, down, m.
    pub pos_ned_m: [Stat; 3],
    /// Horizontal position error, m (mean/rms/max of the magnitude).
    pub horizontal_m: Stat,
    /// 3-D position error, m.
    pub pos_3d_m: Stat,
    /// Velocity error NED, m/s.
    pub vel_ned_mps: [Stat; 3],
    /// 3-D velocity error, m/s.
    pub vel_3d_mps: Stat,
    /// Roll, pitch, yaw error, deg.
    pub att_deg: [Stat; 3],
}

/// Statistics of error points.
pub fn statistics(truth: &str, solution: &str, errs: &[ErrorPoint], total: usize) -> EvalReport {
    let c3 = |f: &dyn Fn(&ErrorPoint) -> [f64; 3]| -> [Stat; 3] {
        [0, 1, 2].map(|k| Stat::of(errs.iter().map(move |e| f(e)[k])))
    };
    EvalReport {
        truth: truth.to_string(),
        solution: solution.to_string(),
        compared: errs.len(),
        not_compared: total - errs.len(),
        span_s: errs.last().map_or(0.0, |l| l.t_s - errs[0].t_s),
        pos_ned_m: c3(&|e| e.pos_ned_m),
        horizontal_m: Stat::of(errs.iter().map(|e| e.pos_ned_m[0].hypot(e.pos_ned_m[1]))),
        pos_3d_m: Stat::of(
            errs.iter()
                .map(|e| e.pos_ned_m.iter().map(|x| x * x).sum::<f64>().sqrt()),
        ),
        vel_ned_mps: c3(&|e| e.vel_ned_mps),
        vel_3d_mps: Stat::of(
            errs.iter()
                .map(|e| e.vel_ned_mps.iter().map(|x| x * x).sum::<f64>().sqrt()),
        ),
        att_deg: c3(&|e| e.att_deg),
    }
}

impl EvalReport {
    /// The report as a text table.
    pub fn table(&self) -> String {
        let mut s = format!(
            "truth     {}\nsolution  {}\ncompared  {} points over {:.1} s ({} not compared)\n\n",
            self.truth, self.solution, self.compared, self.span_s, self.not_compared
        );
        s.push_str(&format!(
            "{:<18} {:>12} {:>12} {:>12} {:>12}\n",
            "error", "mean", "std", "rms", "max |e|"
        ));
        let mut row = |name: &str, st: &Stat| {
            s.push_str(&format!(
                "{name:<18} {:>12.4} {:>12.4} {:>12.4} {:>12.4}\n",
                st.mean, st.std, st.rms, st.max_abs
            ));
        };
        for (n, st) in ["north (m)", "east (m)", "down (m)"].iter().zip(&self.pos_ned_m) {
            row(n, st);
        }
        row("horizontal (m)", &self.horizontal_m);
        row("3-D (m)", &self.pos_3d_m);
        for (n, st) in ["v north (m/s)", "v east (m/s)", "v down (m/s)"]
            .iter()
            .zip(&self.vel_ned_mps)
        {
            row(n, st);
        }
        row("v 3-D (m/s)", &self.vel_3d_mps);
        for (n, st) in ["roll (deg)", "pitch (deg)", "yaw (deg)"].iter().zip(&self.att_deg) {
            row(n, st);
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn traj(offset: [f64; 3], week_known: bool) -> Track {
        let (rm, rn) = earth::radii(30f64.to_radians());
        let points = (0..100)
            .map(|i| {
                let t = i as f64 * 0.1;
                TrackPoint {
                    t_s: if week_known { 2200.0 * 604_800.0 } else { 0.0 } + 1000.0 + t,
                    lat_deg: 30.0 + (10.0 * t + offset[0]).to_degrees() / rm,
                    lon_deg: 114.0 + offset[1].to_degrees() / (rn * 30f64.to_radians().cos()),
                    height_m: 20.0 - offset[2],
                    vel_ned_mps: [10.0, offset[1], 0.0],
                    rpy_deg: [0.0, 0.0, 179.9 + offset[0]],
                }
            })
            .collect();
        Track {
            points,
            week_known,
            source: String::new(),
        }
    }

    #[test]
    fn known_offsets_come_out_as_errors() {
        let truth = traj([0.0; 3], false);
        let sol = traj([0.5, 2.0, 1.0], true);
        let errs = errors(&truth, &sol, 2.0);
        assert_eq!(errs.len(), 99); // the last point has no truth after it
        let r = statistics("t", "s", &errs, 100);
        assert!((r.pos_ned_m[0].mean - 0.5).abs() < 1e-3, "{r:?}");
        assert!((r.pos_ned_m[1].rms - 2.0).abs() < 1e-3, "{r:?}");
        assert!((r.pos_ned_m[2].max_abs - 1.0).abs() < 1e-3, "{r:?}");
        assert!((r.vel_ned_mps[1].mean - 2.0).abs() < 1e-9);
        // Yaw 179.9 + 0.5 wraps to −179.6: still a +0.5° error.
        assert!((r.att_deg[2].mean - 0.5).abs() < 1e-9, "{:?}", r.att_deg);
        assert!(r.pos_ned_m[0].std < 1e-6);
        assert!(r.table().contains("horizontal (m)"));
    }
}
