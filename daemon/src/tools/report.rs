//! `navsync report REC.mcap -o report.html`: one self-contained HTML page with SVG plots of a
//! recording (no script, no network, no library: the SVG is written here).
//!
//! Plots: the trajectory (GNSS fixes, the fused track, the truth where present); position,
//! velocity and attitude errors against the truth with the filter's ±2σ; the GNSS delay Δ and
//! the IMU offsets Td converging with their ±2σ bands (and the true values when the recording
//! has them); the clock mapping (its error against the truth, or its offset change) and the
//! host clock's drift with ±2σ; a histogram of the receiver latency d0 (first NMEA byte minus
//! its PPS edge, per epoch, from the recorded samples).
//!
//! When the recording has no `NavState`s (a simulator or sensor recording), the estimator runs
//! over it first, exactly as `navsync replay --estimate` with the same flags.

use navsync_recording::output::{Overwrite, check_target, write_file};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use navsync_recording::{RecordingError, SampleReader};
use navsync_shared::earth;
use navsync_shared::reflect::str_of;
use navsync_shared::samples::*;

use navsync_estimator::evaluation::track::{self, Track, TrackPoint};
use navsync_estimator::offline::{self, Output};
use navsync_estimator::settings::Settings;

use super::estimate::{RecordedInputs, warn_if_truncated};
use crate::config::Loaded;
use crate::config::estimator::EstimatorFlags;

/// `navsync report`: one self-contained HTML page with SVG plots of a recording: trajectory,
/// errors against the truth, GNSS delay and IMU offsets with ±2σ, clock offset and drift,
/// receiver latency.
#[derive(clap::Args, Debug)]
pub struct Options {
    /// The recording (MCAP).
    pub input: PathBuf,
    /// The HTML file (default: the recording's name with .html).
    #[arg(short, long)]
    pub out: Option<PathBuf>,
    /// Run the estimator over the recording even when it has navigation states.
    #[arg(long)]
    pub estimate: bool,
    /// Replace an existing recording at --out (never the input itself).
    #[arg(long)]
    pub force: bool,
    /// The estimator's settings (when it runs).
    #[command(flatten)]
    pub est: EstimatorFlags,
}

/// Runs `navsync report` as the options say; prints where the page went.
pub fn main(opts: Options, cfg: &Loaded) -> anyhow::Result<()> {
    use anyhow::Context;
    let out = opts.out.unwrap_or_else(|| default_out(&opts.input));
    let reader = navsync_recording::SampleReader::open(&opts.input)?;
    let args = ReportArgs {
        input: opts.input.clone(),
        out: out.clone(),
        estimate: opts.estimate,
        force: opts.force,
        est: super::estimate::settings_for_recording(&opts.est, cfg, &reader)?,
    };
    drop(reader);
    let plots = run(&args).with_context(|| format!("report of {}", opts.input.display()))?;
    eprintln!("{}: {plots} plots", out.display());
    Ok(())
}

/// Settings of a report.
#[derive(Debug, Clone)]
pub struct ReportArgs {
    /// The recording.
    pub input: PathBuf,
    /// The HTML file to write.
    pub out: PathBuf,
    /// Run the estimator even when the recording has navigation states.
    pub estimate: bool,
    /// Replace an existing recording at `out` (never the input).
    pub force: bool,
    /// Estimator settings when it runs.
    pub est: Settings,
}

/// Errors of `navsync report`.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// Reading the recording.
    #[error(transparent)]
    Recording(#[from] RecordingError),
    /// Writing the page.
    #[error("writing {0}: {1}")]
    Io(String, std::io::Error),
    /// Nothing to show.
    #[error("{0}")]
    Empty(String),
    /// The page was written, but the estimator produced no usable states or far fewer than
    /// expected (the reason is on the page too).
    #[error("{path}: written, but {problem}")]
    Unusable {
        /// The page.
        path: String,
        /// Why.
        problem: String,
    },
}

/// What the page is made of, decimated to the plots' needs.
#[derive(Default)]
struct Data {
    fixes: Vec<GnssFix>,
    pps: Vec<i64>,
    truth: Vec<SimTruth>,
    nav: Vec<NavState>,
    time: Vec<TimeState>,
    counts: BTreeMap<String, u64>,
    first_host: Option<i64>,
    estimated: bool,
    /// Why the estimator's states were unusable (estimated here only).
    problem: Option<String>,
}

/// Keeps navigation states at most every this often (host time).
const NAV_EVERY_NS: i64 = 100_000_000;

impl Data {
    fn push_nav(&mut self, n: &NavState) {
        if self.nav.last().is_none_or(|l| n.host_ns - l.host_ns >= NAV_EVERY_NS) {
            self.nav.push(*n);
        }
    }
}

fn read(args: &ReportArgs) -> Result<Data, ReportError> {
    let mut d = Data::default();
    let mut reader = SampleReader::open(&args.input)?;
    let mut has_nav = false;
    while let Some(m) = reader.next_sample()? {
        *d.counts.entry(m.service.to_string()).or_insert(0) += 1;
        let h = m.sample.host_ns();
        if !matches!(m.sample, AnySample::Health(_)) {
            d.first_host = Some(d.first_host.map_or(h, |f: i64| f.min(h)));
        }
        match m.sample {
            AnySample::GnssFix(f) => d.fixes.push(f),
            AnySample::PpsEdge(e) if m.service.ends_with("/edge") => d.pps.push(e.stamp.host_ns),
            AnySample::Truth(t) => d.truth.push(t),
            AnySample::Nav(n) if !args.estimate => {
                has_nav = true;
                d.push_nav(&n);
            }
            AnySample::Time(t) if !args.estimate => d.time.push(t),
            _ => {}
        }
    }
    super::estimate::warn_skipped_chunks(&reader, &args.input);
    if !has_nav {
        // Run the estimator over the recording, as `replay --estimate` does.
        d.nav.clear();
        d.time.clear();
        d.estimated = true;
        let reader = SampleReader::open(&args.input)?;
        let mut inputs = RecordedInputs::new(reader, &args.est);
        let mut nav = Vec::new();
        let mut time = Vec::new();
        let run = offline::estimate(&args.est, inputs.by_ref(), true, |o, _| match o {
            Output::Nav(n) => {
                if nav
                    .last()
                    .is_none_or(|l: &NavState| n.host_ns - l.host_ns >= NAV_EVERY_NS)
                {
                    nav.push(*n);
                }
            }
            Output::Time(t) => time.push(*t),
            Output::Fused(_) | Output::Event(_) => {}
        });
        let (reader, read_err) = inputs.finish();
        if let Some(e) = read_err {
            return Err(e.into());
        }
        if let Some(reader) = &reader {
            warn_if_truncated(reader, &args.input);
        }
        d.problem = run.summary.problem;
        d.nav = nav;
        d.time = time;
    }
    Ok(d)
}

// ---------------------------------------------------------------------------------------------
// SVG plotting

/// How a series is drawn.
enum Kind {
    Line,
    Dots,
    /// A filled band between the points and `lower` (same x).
    Band(Vec<(f64, f64)>),
}

struct Series {
    name: String,
    color: &'static str,
    points: Vec<(f64, f64)>,
    kind: Kind,
}

impl Series {
    fn line(name: &str, color: &'static str, points: Vec<(f64, f64)>) -> Self {
        Self {
            name: name.into(),
            color,
            points,
            kind: Kind::Line,
        }
    }
    fn dots(name: &str, color: &'static str, points: Vec<(f64, f64)>) -> Self {
        Self {
            name: name.into(),
            color,
            points,
            kind: Kind::Dots,
        }
    }
    /// A ±band: upper = mid + w, lower = mid − w.
    fn band(name: &str, color: &'static str, mid_w: &[(f64, f64, f64)]) -> Self {
        Self {
            name: name.into(),
            color,
            points: mid_w.iter().map(|&(x, m, w)| (x, m + w)).collect(),
            kind: Kind::Band(mid_w.iter().map(|&(x, m, w)| (x, m - w)).collect()),
        }
    }
}

const COLORS: [&str; 6] = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#17becf"];

/// A "nice" step of about `span / n`.
fn nice_step(span: f64, n: f64) -> f64 {
    let raw = (span / n).max(f64::MIN_POSITIVE);
    let mag = 10f64.powf(raw.log10().floor());
    let f = raw / mag;
    mag * if f < 1.5 {
        1.0
    } else if f < 3.0 {
        2.0
    } else if f < 7.0 {
        5.0
    } else {
        10.0
    }
}

fn fmt_tick(v: f64, step: f64) -> String {
    let decimals = (-step.log10() - 1e-9).ceil().max(0.0) as usize;
    let s = format!("{v:.decimals$}");
    if s == "-0" { "0".into() } else { s }
}

/// Keeps at most `max` points (every k-th, and the last).
fn decimate(p: &[(f64, f64)], max: usize) -> Vec<(f64, f64)> {
    if p.len() <= max {
        return p.to_vec();
    }
    let k = p.len().div_ceil(max);
    let mut out: Vec<(f64, f64)> = p.iter().step_by(k).copied().collect();
    if let Some(l) = p.last()
        && out.last() != Some(l)
    {
        out.push(*l);
    }
    out
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;")
}

/// One plot as an `<svg>` element.
fn plot(title: &str, xlabel: &str, ylabel: &str, series: &[Series], equal_aspect: bool) -> String {
    let (w, h) = (880.0, if equal_aspect { 560.0 } else { 300.0 });
    let (ml, mr, mt, mb) = (70.0, 20.0, 30.0, 45.0);
    let (pw, ph) = (w - ml - mr, h - mt - mb);
    let all = series.iter().flat_map(|s| {
        let lower: &[(f64, f64)] = match &s.kind {
            Kind::Band(l) => l,
            _ => &[],
        };
        s.points.iter().chain(lower.iter())
    });
    let (mut x0, mut x1, mut y0, mut y1) = (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
    for &(x, y) in all {
        if x.is_finite() && y.is_finite() {
            x0 = x0.min(x);
            x1 = x1.max(x);
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
    }
    let n_points: usize = series.iter().map(|s| s.points.len()).sum();
    let mut s = String::new();
    let _ = write!(
        s,
        r#"<svg class="plot" xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}" data-title="{}" data-points="{n_points}">"#,
        esc(title)
    );
    let _ = write!(
        s,
        r#"<rect x="0" y="0" width="{w}" height="{h}" fill="white"/><text x="{}" y="18" font-size="14" font-weight="bold" text-anchor="middle">{}</text>"#,
        w / 2.0,
        esc(title)
    );
    if !x0.is_finite() {
        let _ = write!(
            s,
            r##"<text x="{}" y="{}" font-size="13" text-anchor="middle" fill="#888">no data</text></svg>"##,
            w / 2.0,
            h / 2.0
        );
        return s;
    }
    if x1 - x0 < 1e-12 {
        x0 -= 0.5;
        x1 += 0.5;
    }
    if y1 - y0 < 1e-12 {
        y0 -= 0.5;
        y1 += 0.5;
    }
    let pad = (y1 - y0) * 0.05;
    y0 -= pad;
    y1 += pad;
    if equal_aspect {
        // Same metres per pixel on both axes.
        let (sx, sy) = ((x1 - x0) / pw, (y1 - y0) / ph);
        if sx > sy {
            let c = (y0 + y1) / 2.0;
            y0 = c - sx * ph / 2.0;
            y1 = c + sx * ph / 2.0;
        } else {
            let c = (x0 + x1) / 2.0;
            x0 = c - sy * pw / 2.0;
            x1 = c + sy * pw / 2.0;
        }
    }
    let px = |x: f64| ml + (x - x0) / (x1 - x0) * pw;
    let py = |y: f64| mt + ph - (y - y0) / (y1 - y0) * ph;
    // Grid and ticks.
    let xs = nice_step(x1 - x0, 8.0);
    let ys = nice_step(y1 - y0, if equal_aspect { 8.0 } else { 5.0 });
    let mut t = (x0 / xs).ceil() * xs;
    while t <= x1 + 1e-9 * xs {
        let _ = write!(
            s,
            r##"<line x1="{0:.1}" y1="{1}" x2="{0:.1}" y2="{2}" stroke="#e5e5e5"/><text x="{0:.1}" y="{3}" font-size="11" text-anchor="middle">{4}</text>"##,
            px(t),
            mt,
            mt + ph,
            mt + ph + 15.0,
            fmt_tick(t, xs)
        );
        t += xs;
    }
    let mut t = (y0 / ys).ceil() * ys;
    while t <= y1 + 1e-9 * ys {
        let _ = write!(
            s,
            r##"<line x1="{0}" y1="{1:.1}" x2="{2}" y2="{1:.1}" stroke="#e5e5e5"/><text x="{3}" y="{4:.1}" font-size="11" text-anchor="end">{5}</text>"##,
            ml,
            py(t),
            ml + pw,
            ml - 5.0,
            py(t) + 4.0,
            fmt_tick(t, ys)
        );
        t += ys;
    }
    let _ = write!(
        s,
        r##"<rect x="{ml}" y="{mt}" width="{pw}" height="{ph}" fill="none" stroke="#444"/><text x="{}" y="{}" font-size="12" text-anchor="middle">{}</text><text x="14" y="{}" font-size="12" text-anchor="middle" transform="rotate(-90 14 {})">{}</text>"##,
        ml + pw / 2.0,
        h - 8.0,
        esc(xlabel),
        mt + ph / 2.0,
        mt + ph / 2.0,
        esc(ylabel)
    );
    let _ = write!(
        s,
        r#"<clipPath id="c{0}"><rect x="{ml}" y="{mt}" width="{pw}" height="{ph}"/></clipPath><g clip-path="url(#c{0})">"#,
        title.len() * 7919 + n_points
    );
    // Bands first, then lines and dots.
    let segments = |p: &[(f64, f64)]| -> Vec<Vec<(f64, f64)>> {
        let mut out = vec![Vec::new()];
        for &(x, y) in p {
            if x.is_finite() && y.is_finite() {
                out.last_mut().expect("one segment").push((x, y));
            } else if !out.last().expect("one segment").is_empty() {
                out.push(Vec::new());
            }
        }
        out.retain(|v| !v.is_empty());
        out
    };
    for se in series {
        if let Kind::Band(lower) = &se.kind {
            let up = decimate(&se.points, 1500);
            let lo = decimate(lower, 1500);
            let pts: Vec<String> = up
                .iter()
                .chain(lo.iter().rev())
                .filter(|(x, y)| x.is_finite() && y.is_finite())
                .map(|&(x, y)| format!("{:.1},{:.1}", px(x), py(y)))
                .collect();
            let _ = write!(
                s,
                r#"<polygon class="band" data-points="{}" points="{}" fill="{}" fill-opacity="0.18" stroke="none"/>"#,
                pts.len(),
                pts.join(" "),
                se.color
            );
        }
    }
    for se in series {
        match se.kind {
            Kind::Line => {
                for seg in segments(&decimate(&se.points, 3000)) {
                    let pts: Vec<String> = seg.iter().map(|&(x, y)| format!("{:.1},{:.1}", px(x), py(y))).collect();
                    let _ = write!(
                        s,
                        r#"<polyline class="series" data-points="{}" points="{}" fill="none" stroke="{}" stroke-width="1.4"/>"#,
                        pts.len(),
                        pts.join(" "),
                        se.color
                    );
                }
            }
            Kind::Dots => {
                let _ = write!(s, r#"<g class="series" fill="{}">"#, se.color);
                for &(x, y) in decimate(&se.points, 3000)
                    .iter()
                    .filter(|(x, y)| x.is_finite() && y.is_finite())
                {
                    let _ = write!(s, r#"<circle cx="{:.1}" cy="{:.1}" r="2.2"/>"#, px(x), py(y));
                }
                s.push_str("</g>");
            }
            Kind::Band(_) => {}
        }
    }
    s.push_str("</g>");
    // Legend.
    let mut lx = ml + 10.0;
    for se in series {
        let _ = write!(
            s,
            r#"<rect x="{lx}" y="{}" width="12" height="8" fill="{}" fill-opacity="{}"/><text x="{}" y="{}" font-size="11">{}</text>"#,
            mt + 8.0,
            se.color,
            if matches!(se.kind, Kind::Band(_)) { 0.3 } else { 1.0 },
            lx + 16.0,
            mt + 16.0,
            esc(&se.name)
        );
        lx += 24.0 + 6.5 * se.name.chars().count() as f64;
    }
    s.push_str("</svg>");
    s
}

/// A histogram as an `<svg>` element.
fn histogram(title: &str, xlabel: &str, values: &[f64]) -> String {
    let (w, h) = (880.0, 300.0);
    let (ml, mr, mt, mb) = (70.0, 20.0, 30.0, 45.0);
    let (pw, ph) = (w - ml - mr, h - mt - mb);
    let v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    let mut s = format!(
        r#"<svg class="plot histogram" xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}" data-title="{}" data-points="{}"><rect x="0" y="0" width="{w}" height="{h}" fill="white"/><text x="{}" y="18" font-size="14" font-weight="bold" text-anchor="middle">{}</text>"#,
        esc(title),
        v.len(),
        w / 2.0,
        esc(title)
    );
    if v.is_empty() {
        let _ = write!(
            s,
            r##"<text x="{}" y="{}" font-size="13" text-anchor="middle" fill="#888">no data</text></svg>"##,
            w / 2.0,
            h / 2.0
        );
        return s;
    }
    let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let bins = ((v.len() as f64).sqrt().ceil() as usize).clamp(5, 40);
    let width = ((hi - lo) / bins as f64).max(1e-9);
    let mut counts = vec![0u64; bins];
    for x in &v {
        counts[(((x - lo) / width) as usize).min(bins - 1)] += 1;
    }
    let cmax = *counts.iter().max().unwrap_or(&1) as f64;
    let bw = pw / bins as f64;
    for (i, c) in counts.iter().enumerate() {
        let bh = *c as f64 / cmax * (ph - 10.0);
        let _ = write!(
            s,
            r##"<rect class="bar" x="{:.1}" y="{:.1}" width="{:.1}" height="{:.1}" fill="#1f77b4" data-count="{c}"/>"##,
            ml + i as f64 * bw + 0.5,
            mt + ph - bh,
            (bw - 1.0).max(0.5),
            bh
        );
    }
    // The y axis: counts per bin.
    let ystep = nice_step(cmax, 5.0).max(1.0);
    let mut c = 0.0;
    while c <= cmax + 1e-9 {
        let y = mt + ph - c / cmax * (ph - 10.0);
        let _ = write!(
            s,
            r##"<line x1="{}" y1="{y:.1}" x2="{ml}" y2="{y:.1}" stroke="#444"/><text x="{}" y="{:.1}" font-size="11" text-anchor="end">{}</text>"##,
            ml - 4.0,
            ml - 6.0,
            y + 4.0,
            fmt_tick(c, ystep)
        );
        c += ystep;
    }
    let _ = write!(
        s,
        r#"<text x="16" y="{:.1}" font-size="12" text-anchor="middle" transform="rotate(-90 16 {:.1})">epochs per bin</text>"#,
        mt + ph / 2.0,
        mt + ph / 2.0
    );
    let step = nice_step(hi - lo + width, 8.0);
    let mut t = (lo / step).ceil() * step;
    while t <= hi + width {
        let x = ml + (t - lo) / (width * bins as f64) * pw;
        if x <= ml + pw + 0.1 {
            let _ = write!(
                s,
                r#"<text x="{x:.1}" y="{}" font-size="11" text-anchor="middle">{}</text>"#,
                mt + ph + 15.0,
                fmt_tick(t, step)
            );
        }
        t += step;
    }
    let _ = write!(
        s,
        r##"<rect x="{ml}" y="{mt}" width="{pw}" height="{ph}" fill="none" stroke="#444"/><text x="{}" y="{}" font-size="12" text-anchor="middle">{}</text><text x="{}" y="{}" font-size="11" text-anchor="end">{} epochs, max bin {}</text></svg>"##,
        ml + pw / 2.0,
        h - 8.0,
        esc(xlabel),
        ml + pw - 6.0,
        mt + 14.0,
        v.len(),
        cmax
    );
    s
}

// ---------------------------------------------------------------------------------------------
// The page

fn t_of(d: &Data, host_ns: i64) -> f64 {
    (host_ns - d.first_host.unwrap_or(0)) as f64 * 1e-9
}

/// Receiver latency d0 per epoch: first byte of the fix minus the PPS edge of its second;
/// without PPS, the receipt mapped to UTC with the time states minus the fix's epoch.
fn receiver_latencies(d: &Data) -> Vec<f64> {
    let mut out = Vec::new();
    if !d.pps.is_empty() {
        let mut pps = d.pps.clone();
        pps.sort_unstable();
        for f in d
            .fixes
            .iter()
            .filter(|f| f.utc_ns != i64::MIN && f.utc_ns % 1_000_000_000 == 0)
        {
            let i = pps.partition_point(|&p| p <= f.stamp.host_ns);
            if i > 0 {
                let d0 = (f.stamp.host_ns - pps[i - 1]) as f64 * 1e-9;
                if d0 < 1.0 {
                    out.push(d0);
                }
            }
        }
    } else {
        for f in d.fixes.iter().filter(|f| f.utc_ns != i64::MIN) {
            let i = d.time.partition_point(|t| t.computed_host_ns <= f.stamp.host_ns);
            if let Some(t) = i.checked_sub(1).map(|i| &d.time[i]).filter(|t| t.is_valid()) {
                out.push((t.utc_ns_at(f.stamp.host_ns) - f.utc_ns) as f64 * 1e-9);
            }
        }
    }
    out
}

fn html_table(rows: &[(String, String)]) -> String {
    let mut s = String::from("<table>");
    for (k, v) in rows {
        let _ = write!(s, "<tr><th>{}</th><td>{}</td></tr>", esc(k), esc(v));
    }
    s.push_str("</table>");
    s
}

/// Renders the page.
fn render(args: &ReportArgs, d: &Data) -> String {
    let mut body = String::new();
    let mut summary: Vec<(String, String)> = vec![
        ("recording".into(), args.input.display().to_string()),
        (
            "navigation states".into(),
            if d.estimated {
                "computed by the estimator over the recording (replay --estimate)".into()
            } else {
                "as recorded".into()
            },
        ),
    ];
    if let Some(p) = &d.problem {
        summary.push(("WARNING".into(), p.clone()));
    }
    // The sample counts go below the figures: the accuracy comes first.
    let counts: Vec<(String, String)> = d
        .counts
        .iter()
        .map(|(service, n)| (service.clone(), format!("{n} samples")))
        .collect();
    // Local frame: metres north/east of the first position.
    let origin = d
        .truth
        .first()
        .map(|t| (t.lat_deg, t.lon_deg, t.height_m))
        .or_else(|| {
            d.nav
                .iter()
                .find(|n| n.status != 0)
                .map(|n| (n.lat_deg, n.lon_deg, n.height_m))
        })
        .or_else(|| {
            d.fixes
                .iter()
                .find(|f| f.has_position())
                .map(|f| (f.lat_deg, f.lon_deg, f.height_m()))
        });
    let ne = |lat: f64, lon: f64| -> (f64, f64) {
        let Some((la, lo, h)) = origin else {
            return (f64::NAN, f64::NAN);
        };
        let v = earth::ned_between(
            la.to_radians(),
            lo.to_radians(),
            h,
            lat.to_radians(),
            lon.to_radians(),
            h,
        );
        (v[1], v[0])
    };
    let aligned: Vec<&NavState> = d.nav.iter().filter(|n| n.status != NavStatus::Aligning as u8).collect();
    let mut traj = Vec::new();
    if !d.truth.is_empty() {
        traj.push(Series::line(
            "truth",
            "#999999",
            d.truth.iter().map(|t| ne(t.lat_deg, t.lon_deg)).collect(),
        ));
    }
    traj.push(Series::dots(
        "GNSS fixes",
        "#d62728",
        d.fixes
            .iter()
            .filter(|f| f.has_position())
            .map(|f| ne(f.lat_deg, f.lon_deg))
            .collect(),
    ));
    traj.push(Series::line(
        "fused track",
        "#1f77b4",
        aligned.iter().map(|n| ne(n.lat_deg, n.lon_deg)).collect(),
    ));
    body.push_str("<h2>Trajectory</h2>");
    body.push_str(&plot("Trajectory", "east (m)", "north (m)", &traj, true));

    // Errors against the truth.
    if !d.truth.is_empty() && !aligned.is_empty() {
        let tr = Track {
            points: d
                .truth
                .iter()
                .map(|t| TrackPoint {
                    t_s: t_of(d, t.host_ns),
                    lat_deg: t.lat_deg,
                    lon_deg: t.lon_deg,
                    height_m: t.height_m,
                    vel_ned_mps: t.vel_ned_mps,
                    rpy_deg: t.rpy_rad.map(f64::to_degrees),
                })
                .collect(),
            week_known: true,
            source: "truth".into(),
        };
        let so = Track {
            points: aligned
                .iter()
                .map(|n| TrackPoint {
                    t_s: t_of(d, n.host_ns),
                    lat_deg: n.lat_deg,
                    lon_deg: n.lon_deg,
                    height_m: n.height_m,
                    vel_ned_mps: n.vel_ned_mps,
                    rpy_deg: n.rpy_rad.map(f64::to_degrees),
                })
                .collect(),
            week_known: true,
            source: "solution".into(),
        };
        let errs = track::errors(&tr, &so, 2.0);
        let stats = track::statistics("truth", "solution", &errs, so.points.len());
        summary.push((
            "horizontal position error".into(),
            format!(
                "RMS {:.3} m, max {:.3} m",
                stats.horizontal_m.rms, stats.horizontal_m.max_abs
            ),
        ));
        summary.push((
            "velocity error (3-D)".into(),
            format!("RMS {:.3} m/s", stats.vel_3d_mps.rms),
        ));
        summary.push((
            "attitude error RMS".into(),
            format!(
                "roll {:.3}°, pitch {:.3}°, yaw {:.3}°",
                stats.att_deg[0].rms, stats.att_deg[1].rms, stats.att_deg[2].rms
            ),
        ));
        // The filter's 2σ at the same epochs.
        let sigma: BTreeMap<i64, &NavState> = aligned
            .iter()
            .map(|n| ((t_of(d, n.host_ns) * 1e6) as i64, *n))
            .collect();
        let sig_at = |t: f64| sigma.get(&((t * 1e6) as i64)).copied();
        let names = [
            ["north", "east", "down"],
            ["north", "east", "down"],
            ["roll", "pitch", "yaw"],
        ];
        let titles = [
            ("Position error against the truth", "m"),
            ("Velocity error against the truth", "m/s"),
            ("Attitude error against the truth", "deg"),
        ];
        for (k, (title, unit)) in titles.iter().enumerate() {
            let mut series = Vec::new();
            for (c, name) in names[k].iter().enumerate() {
                let color = COLORS[c];
                let band: Vec<(f64, f64, f64)> = errs
                    .iter()
                    .filter_map(|e| {
                        let n = sig_at(e.t_s)?;
                        let s = match k {
                            0 => n.pos_std_ned_m[c],
                            1 => n.vel_std_ned_mps[c],
                            _ => n.att_std_rad[c].to_degrees(),
                        };
                        Some((e.t_s, 0.0, 2.0 * s))
                    })
                    .collect();
                series.push(Series::band(&format!("±2σ {name}"), color, &band));
                series.push(Series::line(
                    name,
                    color,
                    errs.iter()
                        .map(|e| {
                            let v = match k {
                                0 => e.pos_ned_m[c],
                                1 => e.vel_ned_mps[c],
                                _ => e.att_deg[c],
                            };
                            (e.t_s, v)
                        })
                        .collect(),
                ));
            }
            body.push_str(&format!("<h2>{}</h2>", esc(title)));
            body.push_str(&plot(title, "time (s)", &format!("error ({unit})"), &series, false));
        }
    }

    // GNSS delay.
    let delay: Vec<(f64, f64, f64)> = aligned
        .iter()
        .filter(|n| n.gnss_delay_s.is_finite())
        .map(|n| (t_of(d, n.host_ns), n.gnss_delay_s * 1e3, 2.0 * n.gnss_delay_std_s * 1e3))
        .collect();
    let mut series = vec![
        Series::band("±2σ", COLORS[0], &delay),
        Series::line("Δ estimate", COLORS[0], delay.iter().map(|&(t, m, _)| (t, m)).collect()),
    ];
    if let (Some(t), Some(n)) = (d.truth.last(), aligned.last()) {
        let truth_ms = if n.time_status == TimeStatus::Software as u8 {
            t.gnss_latency_s * 1e3
        } else {
            0.0
        };
        let (a, b) = (delay.first().map_or(0.0, |p| p.0), delay.last().map_or(0.0, |p| p.0));
        series.push(Series::line("true Δ", "#333333", vec![(a, truth_ms), (b, truth_ms)]));
    }
    if let Some(&(_, m, w)) = delay.last() {
        summary.push(("GNSS delay Δ (final)".into(), format!("{m:.2} ± {:.2} ms (2σ)", w)));
    }
    body.push_str("<h2>GNSS delay Δ</h2>");
    body.push_str(&plot("GNSS delay estimate Δ", "time (s)", "Δ (ms)", &series, false));

    // IMU offsets.
    let mut series = Vec::new();
    let imu_count = aligned.last().map_or(0, |n| usize::from(n.imu_count).min(MAX_IMUS));
    for i in 1..imu_count {
        let color = COLORS[(i - 1) % COLORS.len()];
        let id = str_of(&aligned.last().map_or([0; 8], |n| n.imu[i].imu_id)).to_string();
        let band: Vec<(f64, f64, f64)> = aligned
            .iter()
            .filter(|n| n.imu[i].offset_s.is_finite())
            .map(|n| {
                (
                    t_of(d, n.host_ns),
                    n.imu[i].offset_s * 1e3,
                    2.0 * n.imu[i].offset_std_s.max(0.0) * 1e3,
                )
            })
            .collect();
        series.push(Series::band(&format!("±2σ IMU {id}"), color, &band));
        series.push(Series::line(
            &format!("IMU {id}"),
            color,
            band.iter().map(|&(t, m, _)| (t, m)).collect(),
        ));
        if let Some(t) = d.truth.last().filter(|t| usize::from(t.imu_count) > i) {
            let (a, b) = (band.first().map_or(0.0, |p| p.0), band.last().map_or(0.0, |p| p.0));
            let v = t.imu_offset_s[i] * 1e3;
            series.push(Series::line(&format!("true {id}"), "#333333", vec![(a, v), (b, v)]));
        }
        if let Some(&(_, m, w)) = band.last() {
            summary.push((
                format!("IMU {id} offset Td (final)"),
                format!("{m:.3} ± {w:.3} ms (2σ)"),
            ));
        }
    }
    body.push_str("<h2>IMU offsets Td</h2>");
    if imu_count > 1 {
        body.push_str(&plot(
            "IMU time offsets Td relative to the reference IMU",
            "time (s)",
            "Td (ms)",
            &series,
            false,
        ));
    } else {
        body.push_str("<p>One IMU: no offsets to estimate.</p>");
    }

    // Clock.
    let valid: Vec<&TimeState> = d.time.iter().filter(|t| t.is_valid()).collect();
    if !d.truth.is_empty() && !valid.is_empty() {
        let mut pts = Vec::new();
        for tr in &d.truth {
            let i = valid.partition_point(|t| t.computed_host_ns <= tr.host_ns);
            if let Some(ts) = i.checked_sub(1).map(|i| valid[i]) {
                let err_us = (ts.utc_ns_at(tr.host_ns) - tr.utc_ns) as f64 * 1e-3;
                pts.push((t_of(d, tr.host_ns), err_us, 2.0 * ts.utc_std_ns_at(tr.host_ns) * 1e-3));
            }
        }
        let rms = (pts.iter().map(|p| p.1 * p.1).sum::<f64>() / pts.len().max(1) as f64).sqrt();
        summary.push(("clock mapping error".into(), format!("RMS {rms:.3} µs")));
        body.push_str("<h2>Clock</h2>");
        body.push_str(&plot(
            "Clock offset: mapped GNSS time minus the truth",
            "time (s)",
            "error (µs)",
            &[
                Series::band("±2σ", COLORS[0], &pts),
                Series::line("mapping error", COLORS[0], pts.iter().map(|p| (p.0, p.1)).collect()),
            ],
            false,
        ));
    } else if let Some(first) = valid.first() {
        let base = first.ref_utc_ns - first.ref_host_ns;
        let pts: Vec<(f64, f64, f64)> = valid
            .iter()
            .map(|t| {
                let h = t.computed_host_ns;
                (
                    t_of(d, h),
                    ((t.utc_ns_at(h) - h) - base) as f64 * 1e-3,
                    2.0 * t.utc_std_ns_at(h) * 1e-3,
                )
            })
            .collect();
        body.push_str("<h2>Clock</h2>");
        body.push_str(&plot(
            "Clock offset: GNSS time minus host time, change since the first mapping",
            "time (s)",
            "offset change (µs)",
            &[
                Series::band("±2σ", COLORS[0], &pts),
                Series::line("offset", COLORS[0], pts.iter().map(|p| (p.0, p.1)).collect()),
            ],
            false,
        ));
    } else {
        body.push_str("<h2>Clock</h2><p>No valid time mapping in the recording.</p>");
    }
    let drift: Vec<(f64, f64, f64)> = valid
        .iter()
        .map(|t| (t_of(d, t.computed_host_ns), t.rate_error * 1e6, 2.0 * t.rate_std * 1e6))
        .collect();
    let mut series = vec![
        Series::band("±2σ", COLORS[1], &drift),
        Series::line("drift estimate", COLORS[1], drift.iter().map(|p| (p.0, p.1)).collect()),
    ];
    if !d.truth.is_empty() {
        series.push(Series::line(
            "true drift",
            "#333333",
            d.truth
                .iter()
                .map(|t| (t_of(d, t.host_ns), t.rate_error * 1e6))
                .collect(),
        ));
    }
    if let Some(&(_, m, w)) = drift.last() {
        summary.push(("host clock drift (final)".into(), format!("{m:.4} ± {w:.4} ppm (2σ)")));
    }
    body.push_str(&plot(
        "Host clock drift (fractional frequency error)",
        "time (s)",
        "drift (ppm)",
        &series,
        false,
    ));

    // Receiver latency.
    let d0: Vec<f64> = receiver_latencies(d).iter().map(|x| x * 1e3).collect();
    if !d0.is_empty() {
        let mut sorted = d0.clone();
        sorted.sort_by(f64::total_cmp);
        summary.push((
            "receiver latency d0".into(),
            format!(
                "median {:.3} ms, min {:.3} ms, max {:.3} ms ({} epochs)",
                sorted[sorted.len() / 2],
                sorted[0],
                sorted[sorted.len() - 1],
                sorted.len()
            ),
        ));
    }
    body.push_str("<h2>Receiver latency d0</h2>");
    body.push_str(&histogram(
        "Receiver latency d0: first NMEA byte minus its PPS edge",
        "d0 (ms)",
        &d0,
    ));
    body.push_str("<h2>Samples</h2>");
    body.push_str(&html_table(&counts));

    format!(
        r#"<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>navsync report: {title}</title>
<style>
body {{ font-family: sans-serif; margin: 24px; color: #222; max-width: 920px; }}
h1 {{ font-size: 22px; }} h2 {{ font-size: 17px; margin-top: 28px; }}
table {{ border-collapse: collapse; font-size: 13px; }}
th, td {{ border: 1px solid #ccc; padding: 3px 8px; text-align: left; }}
th {{ background: #f3f3f3; font-weight: normal; }}
svg.plot {{ display: block; margin: 8px 0; border: 1px solid #ddd; }}
</style></head><body>
<h1>navsync report: {title}</h1>
{table}
{body}
<p style="font-size:12px;color:#777">Written by navsync {version} (navsync report). Self-contained: no scripts, no external resources.</p>
</body></html>
"#,
        title = esc(&args
            .input
            .file_name()
            .map_or(String::new(), |f| f.to_string_lossy().to_string())),
        table = html_table(&summary),
        version = env!("CARGO_PKG_VERSION"),
    )
}

/// Runs `navsync report`; returns the number of plots written.
pub fn run(args: &ReportArgs) -> Result<usize, ReportError> {
    // The page goes to a temporary file renamed over `out` (navsync_recording::output): never
    // over the recording it is made of, nor over another recording without --force. Checked
    // first, so a refusal costs no reading.
    let inputs = [args.input.as_path()];
    let rules = Overwrite::new(&inputs, args.force);
    check_target(&args.out, &rules)?;
    let d = read(args)?;
    if d.counts.is_empty() {
        return Err(ReportError::Empty(format!("{}: no samples", args.input.display())));
    }
    let page = render(args, &d);
    write_file(&args.out, &rules, page.as_bytes())?;
    if let Some(problem) = d.problem {
        return Err(ReportError::Unusable {
            path: args.out.display().to_string(),
            problem,
        });
    }
    Ok(page.matches("<svg class=\"plot").count())
}

/// The default output path next to the recording (`REC.html`).
pub fn default_out(input: &Path) -> PathBuf {
    input.with_extension("html")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plots_have_ticks_series_and_bands() {
        let pts: Vec<(f64, f64)> = (0..500).map(|i| (i as f64 * 0.1, (i as f64 * 0.05).sin())).collect();
        let band: Vec<(f64, f64, f64)> = pts.iter().map(|&(x, y)| (x, y, 0.2)).collect();
        let svg = plot(
            "t",
            "x",
            "y",
            &[Series::band("b", COLORS[0], &band), Series::line("l", COLORS[0], pts)],
            false,
        );
        assert!(svg.contains(r#"<polyline class="series" data-points="500""#), "{svg}");
        assert!(svg.contains(r#"<polygon class="band" data-points="1000""#));
        assert!(svg.contains(">0.5<") && svg.contains(">-0.5<"), "y ticks");
        let h = histogram("h", "x", &[1.0, 1.1, 1.2, 2.0, 2.0, 3.5]);
        assert_eq!(h.matches("class=\"bar\"").count(), 5);
        assert!(
            h.contains("epochs per bin") && h.contains(">0<") && h.contains(">3<"),
            "y axis: {h}"
        );
        assert!(plot("e", "x", "y", &[], false).contains("no data"));
        assert_eq!(nice_step(10.0, 5.0), 2.0);
        assert_eq!(nice_step(0.7, 8.0), 0.1);
    }
}
