//! `navsync analyze gnss-delay RECORDING [--segments a:b,c:d …]`: the offline method of the
//! GPS/SINS time-synchronisation literature, next to the online estimate.
//!
//! If a fix stamped at its receipt time t_r is really the epoch t_r − Δ, the velocity difference
//! INS − GNSS at the fix is ΔV = ΔV₀ + a·Δ per axis (a the vehicle's acceleration, ΔV₀ the
//! INS's own slowly varying error). Over a segment of the drive, a least-squares line through
//! (a_E, ΔV_E) and through (a_N, ΔV_N) gives Δ from east and from north data: the paper's
//! Table 1. The INS velocity and acceleration come from the estimator run over the recording
//! in software sync (fixes stamped at receipt), evaluated at each fix's receipt time; the
//! online estimate Δ̂ ± σ it reaches by the end of each segment is printed beside.

use std::path::PathBuf;

use navsync_recording::sample_file::SampleReader;
use navsync_shared::samples::AnySample;
use navsync_shared::services;

use navsync_estimator::offline::{self, Output};
use navsync_estimator::settings::Settings;

use crate::config::Loaded;
use crate::config::estimator::EstimatorFlags;

/// `navsync analyze`: offline analyses of a recording.
#[derive(clap::Subcommand, Debug)]
pub enum Command {
    /// The GNSS delay by least squares per segment (ΔV = ΔV₀ + a·Δ, east and north) beside the
    /// online estimate, like Table 1 of the GPS/SINS time-synchronisation literature.
    GnssDelay {
        /// The recording (MCAP).
        recording: PathBuf,
        /// Segments START:END in seconds since the first sample, comma-separated (default: all).
        #[arg(long, value_delimiter = ',', value_parser = parse_segment)]
        segments: Vec<(f64, f64)>,
        /// The estimator's settings (software sync is forced).
        #[command(flatten)]
        est: EstimatorFlags,
    },
}

/// `START:END`, two numbers of seconds.
fn parse_segment(s: &str) -> Result<(f64, f64), String> {
    let (a, b) = s
        .split_once(':')
        .ok_or_else(|| format!("`{s}`: expected START:END, two numbers of seconds"))?;
    let num = |x: &str| {
        x.trim()
            .parse::<f64>()
            .map_err(|_| format!("`{x}` is not a number of seconds"))
    };
    Ok((num(a)?, num(b)?))
}

/// Runs `navsync analyze …` and prints its table.
pub fn main(cmd: Command, cfg: &Loaded) -> anyhow::Result<()> {
    use anyhow::Context;
    let Command::GnssDelay {
        recording,
        segments,
        est,
    } = cmd;
    let args = GnssDelayArgs {
        recording: recording.clone(),
        segments,
        est: est.settings(cfg)?,
    };
    let rows = gnss_delay(&args).with_context(|| format!("analysing {}", recording.display()))?;
    print!("{}", table(&rows));
    Ok(())
}

/// Settings of `navsync analyze gnss-delay`.
#[derive(Debug, Clone)]
pub struct GnssDelayArgs {
    /// The recording.
    pub recording: PathBuf,
    /// Segments (start, end) in seconds since the first sample; empty: the whole recording.
    pub segments: Vec<(f64, f64)>,
    /// Estimator settings (software sync is forced).
    pub est: Settings,
}

/// Errors of the analysis.
#[derive(Debug, thiserror::Error)]
pub enum AnalyzeError {
    /// The recording could not be read.
    #[error(transparent)]
    Recording(#[from] navsync_recording::RecordingError),
    /// Nothing to analyse.
    #[error("{0}")]
    Empty(String),
}

/// One segment's result.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SegmentDelay {
    /// Segment start and end, s since the first sample.
    pub span_s: (f64, f64),
    /// Fixes in the segment.
    pub fixes: usize,
    /// Δ from east data and its 1-sigma, s.
    pub from_east: (f64, f64),
    /// Δ from north data and its 1-sigma, s.
    pub from_north: (f64, f64),
    /// The online estimate at the segment's end and its 1-sigma, s.
    pub online: (f64, f64),
}

/// Least-squares line y = c + a·Δ; returns (Δ, σ_Δ) or NaN when `a` does not vary.
pub fn fit_delay(a: &[f64], y: &[f64]) -> (f64, f64) {
    let n = a.len() as f64;
    if a.len() < 3 {
        return (f64::NAN, f64::NAN);
    }
    let (ma, my) = (a.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let saa: f64 = a.iter().map(|x| (x - ma).powi(2)).sum();
    let say: f64 = a.iter().zip(y).map(|(x, v)| (x - ma) * (v - my)).sum();
    if saa <= 1e-12 {
        return (f64::NAN, f64::NAN);
    }
    let d = say / saa;
    let c = my - d * ma;
    let s2 = a.iter().zip(y).map(|(x, v)| (v - c - d * x).powi(2)).sum::<f64>() / (n - 2.0);
    (d, (s2 / saa).sqrt())
}

/// Runs the analysis and returns one row per segment.
pub fn gnss_delay(args: &GnssDelayArgs) -> Result<Vec<SegmentDelay>, AnalyzeError> {
    let mut est = args.est.clone();
    est.time.software_sync = true;
    let mut reader = SampleReader::open(&args.recording)?;
    let mut wanted: Vec<String> = est.inputs.gnss.iter().map(|id| services::gnss_fix(id)).collect();
    wanted.extend(est.inputs.imus.iter().map(|id| services::imu_sample(id)));
    // (receipt host ns, vN, vE) of every fix; (host ns, vN, vE, Δ̂, σ) of every nav state.
    let mut fixes: Vec<(i64, f64, f64)> = Vec::new();
    let mut navs: Vec<(i64, f64, f64, f64, f64)> = Vec::new();
    let mut first_ns = None;
    let mut read_err = None;
    let samples = std::iter::from_fn(|| {
        loop {
            match reader.next_sample() {
                Ok(Some(m)) if wanted.iter().any(|w| w == m.service) => {
                    let s = m.sample;
                    first_ns.get_or_insert(s.host_ns());
                    if let AnySample::GnssFix(f) = &s
                        && f.has_position()
                        && f.vel_n_mps.is_finite()
                    {
                        fixes.push((f.stamp.host_ns, f.vel_n_mps, f.vel_e_mps));
                    }
                    return Some((s, ()));
                }
                Ok(Some(_)) => {}
                Ok(None) => return None,
                Err(e) => {
                    read_err = Some(e);
                    return None;
                }
            }
        }
    });
    offline::estimate(&est, samples, false, |o, _| {
        if let Output::Nav(n) = o
            && n.lat_deg.is_finite()
        {
            navs.push((
                n.host_ns,
                n.vel_ned_mps[0],
                n.vel_ned_mps[1],
                n.gnss_delay_s,
                n.gnss_delay_std_s,
            ));
        }
    });
    if let Some(e) = read_err {
        return Err(e.into());
    }
    let first_ns = first_ns.ok_or_else(|| AnalyzeError::Empty("the recording has no samples".into()))?;
    if navs.len() < 100 || fixes.len() < 3 {
        return Err(AnalyzeError::Empty(format!(
            "{}: not enough aligned navigation ({} states) or fixes ({})",
            args.recording.display(),
            navs.len(),
            fixes.len()
        )));
    }
    // INS velocity at a host time (linear between states) and acceleration over ±0.1 s.
    let vel_at = |t: i64| -> Option<(f64, f64)> {
        let i = navs.partition_point(|n| n.0 < t);
        if i == 0 || i >= navs.len() {
            return None;
        }
        let (a, b) = (navs[i - 1], navs[i]);
        let w = (t - a.0) as f64 / (b.0 - a.0).max(1) as f64;
        Some((a.1 + (b.1 - a.1) * w, a.2 + (b.2 - a.2) * w))
    };
    let span = |t: i64| (t - first_ns) as f64 * 1e-9;
    let segments = if args.segments.is_empty() {
        vec![(0.0, span(navs[navs.len() - 1].0))]
    } else {
        args.segments.clone()
    };
    let mut rows = Vec::new();
    for (s0, s1) in segments {
        let (mut ae, mut ye, mut an, mut yn) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for &(t, vn, ve) in fixes.iter().filter(|f| (s0..s1).contains(&span(f.0))) {
            let (Some(v), Some(vp), Some(vm)) = (vel_at(t), vel_at(t + 100_000_000), vel_at(t - 100_000_000)) else {
                continue;
            };
            an.push((vp.0 - vm.0) / 0.2);
            ae.push((vp.1 - vm.1) / 0.2);
            yn.push(v.0 - vn);
            ye.push(v.1 - ve);
        }
        let end = navs
            .iter()
            .rev()
            .find(|n| span(n.0) <= s1)
            .copied()
            .unwrap_or(navs[navs.len() - 1]);
        rows.push(SegmentDelay {
            span_s: (s0, s1),
            fixes: ae.len(),
            from_east: fit_delay(&ae, &ye),
            from_north: fit_delay(&an, &yn),
            online: (end.3, end.4),
        });
    }
    Ok(rows)
}

/// The rows as a table like the paper's Table 1.
pub fn table(rows: &[SegmentDelay]) -> String {
    let mut s = String::from("segment (s)        fixes   Δ from east (s)     Δ from north (s)    online Δ̂ (s)\n");
    for r in rows {
        s.push_str(&format!(
            "{:>7.1} – {:<7.1} {:>5}   {:>7.4} ± {:<7.4}   {:>7.4} ± {:<7.4}   {:>7.4} ± {:.4}\n",
            r.span_s.0,
            r.span_s.1,
            r.fixes,
            r.from_east.0,
            r.from_east.1,
            r.from_north.0,
            r.from_north.1,
            r.online.0,
            r.online.1
        ));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fits_a_known_delay() {
        let a: Vec<f64> = (0..50).map(|i| (i as f64 * 0.37).sin() * 2.0).collect();
        let y: Vec<f64> = a
            .iter()
            .enumerate()
            .map(|(i, x)| 0.03 + 0.6 * x + 0.01 * ((i * 7919) % 13) as f64 / 13.0)
            .collect();
        let (d, sd) = fit_delay(&a, &y);
        assert!((d - 0.6).abs() < 3.0 * sd && sd < 0.01, "{d} ± {sd}");
        assert!(fit_delay(&[1.0, 1.0, 1.0], &[0.0, 1.0, 2.0]).0.is_nan());
    }
}
