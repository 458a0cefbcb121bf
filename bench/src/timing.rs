//! `navsync-bench timing`: the time synchronisation against the simulated host oscillator,
//! offline and deterministic (same seed, same numbers): the simulated world's PPS edges and
//! NMEA (decoded by the GPS driver's own code, receipt-stamped as a UART would) are fed to
//! [`TimeSync`] in delivery order; the `TimeState` a subscriber would hold (republished on
//! every mapping change and at least once per second, as `navsync estimator` does) is compared
//! with the truth at every 10 ms truth instant.
//!
//! Figures per case: RMS and maximum of the mapped-time error after a 30 s warm-up, the share
//! of instants whose error is within the reported 2σ, the holdover error 60 s after the PPS
//! and GNSS are lost (with its reported σ), the jump of the mapping when the PPS comes back
//! (with the σ just before), and the measured receiver latency d0 against the simulated one.

use navsync_shared::samples::{AnySample, TimeState, TimeStatus};
use navsync_shared::time::NS_PER_S;
use navsync_sim::error::SimError;
use navsync_sim::published::PublishedStream;
use navsync_sim::scenario::{OutageConfig, SimConfig};
use navsync_sim::world::World;

use navsync_estimator::time::time_sync::{TimeSync, TimeSyncConfig};

/// One benchmark case.
#[derive(Debug, Clone)]
pub struct TimingCase {
    /// Short name.
    pub name: &'static str,
    /// 1-sigma PPS stamp jitter, s.
    pub pps_jitter_s: f64,
    /// Initial host clock frequency error, ppm.
    pub clock_ppm: f64,
    /// Random-walk FM Allan deviation at 1 s of the host oscillator.
    pub rw_adev_1s: f64,
    /// Receiver latency d0, s, and its per-epoch 1-sigma jitter, s.
    pub latency_s: (f64, f64),
    /// PPS and GNSS outage (start, duration), s of scenario time.
    pub outage: Option<(f64, f64)>,
    /// Simulated seconds.
    pub duration_s: f64,
    /// Seed.
    pub seed: u64,
}

impl TimingCase {
    /// The cases of the table in docs/benchmarks/timing.md.
    pub fn standard() -> Vec<TimingCase> {
        let base = TimingCase {
            name: "kernel PPS, 1 µs jitter",
            pps_jitter_s: 1e-6,
            clock_ppm: 0.5,
            rw_adev_1s: 1e-10,
            latency_s: (0.6, 0.0),
            outage: None,
            duration_s: 600.0,
            seed: 1,
        };
        vec![
            base.clone(),
            TimingCase {
                name: "user-space PPS, 30 µs jitter",
                pps_jitter_s: 30e-6,
                ..base.clone()
            },
            TimingCase {
                name: "holdover: 1 µs, 90 s PPS+GNSS outage",
                outage: Some((240.0, 90.0)),
                duration_s: 420.0,
                ..base.clone()
            },
            TimingCase {
                name: "holdover: 30 µs, 90 s PPS+GNSS outage",
                pps_jitter_s: 30e-6,
                outage: Some((240.0, 90.0)),
                duration_s: 420.0,
                ..base.clone()
            },
            TimingCase {
                name: "labelling: d0 = 0.9 s ± 20 ms",
                latency_s: (0.9, 0.02),
                duration_s: 300.0,
                ..base
            },
        ]
    }
}

/// What a case measured.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TimingResult {
    /// Truth instants compared (after warm-up, mapping usable).
    pub instants: u64,
    /// RMS of the mapped-time error while locked, ns.
    pub rms_ns: f64,
    /// Largest error while locked, ns.
    pub max_ns: f64,
    /// Share of instants (locked or holdover) with |error| ≤ 2σ reported.
    pub coverage_2sigma: f64,
    /// Error 60 s after the outage began, ns (holdover cases).
    pub holdover_60s_ns: Option<f64>,
    /// Reported 1-sigma at that instant, ns.
    pub holdover_60s_sigma_ns: Option<f64>,
    /// Largest change of the mapping at the first edges after the outage, ns.
    pub recovery_jump_ns: Option<f64>,
    /// Reported 1-sigma just before that change, ns.
    pub recovery_sigma_ns: Option<f64>,
    /// Measured median d0 minus the simulated d0, s.
    pub d0_median_error_s: f64,
    /// PPS edges used and rejected.
    pub pps_used: u64,
    /// PPS edges rejected.
    pub pps_rejected: u64,
}

/// Warm-up before errors are counted, s.
pub const WARM_UP_S: f64 = 30.0;

/// Runs one case.
pub fn run_case(case: &TimingCase) -> Result<TimingResult, SimError> {
    let mut cfg = SimConfig::default_drive();
    cfg.set_seed(case.seed);
    cfg.set_imu_count(1);
    cfg.set_imu_rate_hz(20.0);
    cfg.set_clock_ppm(case.clock_ppm);
    cfg.set_clock_rw_adev_1s(case.rw_adev_1s);
    cfg.set_pps_jitter_s(case.pps_jitter_s);
    cfg.set_nmea_latency_s(case.latency_s.0);
    cfg.gnss.latency_jitter_s = case.latency_s.1;
    cfg.clear_gnss_outages();
    if let Some((start_s, duration_s)) = case.outage {
        cfg.gnss.outages.push(OutageConfig {
            start_s,
            duration_s,
            pps_continues: false,
        });
    }
    let host0 = 1_000_000_000_000i64;
    let utc0 = 1_790_000_000 * NS_PER_S;
    let world = World::new(&cfg, host0, utc0)?;
    let mut ts = TimeSync::new(TimeSyncConfig {
        // The oscillator's stability figures, as a configuration would state them.
        oscillator_white_fm_adev_1s: 1e-10,
        oscillator_random_walk_fm_adev_1s: case.rw_adev_1s.max(1e-12),
        ..Default::default()
    });
    let mut published: Option<TimeState> = None;
    let mut last_publish = i64::MIN;
    let (mut n_locked, mut sum_sq, mut max_abs) = (0u64, 0.0f64, 0.0f64);
    let (mut n_cov, mut covered) = (0u64, 0u64);
    let mut out = TimingResult::default();
    let outage = case.outage.map(|(s, d)| (s, s + d));
    let mut seen_recovery_edges = 0u32;
    for item in PublishedStream::new(world) {
        let now = item.delivered_ns;
        let tau = (now - host0) as f64 * 1e-9;
        if tau > case.duration_s {
            break;
        }
        let changed = match &item.sample {
            AnySample::PpsEdge(e) => {
                let before = published;
                let changed = ts.on_pps(e);
                if changed
                    && let (Some((_, end)), Some(prev)) = (outage, before)
                    && tau > end
                    && seen_recovery_edges < 3
                {
                    // How far the mapping moves at the edge when the PPS comes back.
                    seen_recovery_edges += 1;
                    let after = ts.time_state(e.stamp.host_ns);
                    let jump = (after.utc_ns_at(e.stamp.host_ns) - prev.utc_ns_at(e.stamp.host_ns)) as f64;
                    if seen_recovery_edges == 1 {
                        out.recovery_sigma_ns = Some(prev.utc_std_ns_at(e.stamp.host_ns));
                    }
                    let j = out.recovery_jump_ns.get_or_insert(0.0);
                    *j = j.max(jump.abs());
                }
                changed
            }
            AnySample::GnssFix(f) => ts.on_fix(f),
            AnySample::Truth(tr) => {
                if let Some(state) = &published
                    && tau > WARM_UP_S
                    && state.is_valid()
                {
                    let err = (state.utc_ns_at(tr.host_ns) - tr.utc_ns) as f64;
                    let sigma = state.utc_std_ns_at(tr.host_ns);
                    n_cov += 1;
                    covered += u64::from(err.abs() <= 2.0 * sigma);
                    if state.status() == TimeStatus::Locked {
                        n_locked += 1;
                        sum_sq += err * err;
                        max_abs = max_abs.max(err.abs());
                    }
                    if let Some((start, _)) = outage
                        && out.holdover_60s_ns.is_none()
                        && tau >= start + 60.0
                    {
                        out.holdover_60s_ns = Some(err);
                        out.holdover_60s_sigma_ns = Some(sigma);
                    }
                }
                false
            }
            _ => false,
        };
        ts.tick(now);
        if changed || now.saturating_sub(last_publish) >= NS_PER_S {
            published = Some(ts.time_state(now));
            last_publish = now;
        }
    }
    let last = ts.time_state(last_publish.max(host0));
    out.instants = n_cov;
    out.rms_ns = if n_locked > 0 {
        (sum_sq / n_locked as f64).sqrt()
    } else {
        f64::NAN
    };
    out.max_ns = max_abs;
    out.coverage_2sigma = if n_cov > 0 {
        covered as f64 / n_cov as f64
    } else {
        f64::NAN
    };
    out.d0_median_error_s = last.latency_median_s - case.latency_s.0;
    out.pps_used = last.pps_used;
    out.pps_rejected = last.pps_rejected;
    Ok(out)
}

fn us(v: Option<f64>) -> String {
    v.map_or_else(|| "-".into(), |x| format!("{:.2}", x * 1e-3))
}

/// The table of all standard cases (Markdown).
pub fn table() -> Result<String, SimError> {
    let mut s = String::from(
        "| case | RMS error | max error | within 2σ | holdover error at 60 s (σ) | jump on recovery (σ before) | d0 median − true |\n\
         |---|---|---|---|---|---|---|\n",
    );
    for case in TimingCase::standard() {
        let r = run_case(&case)?;
        s.push_str(&format!(
            "| {} | {:.3} µs | {:.3} µs | {:.1} % | {} µs ({} µs) | {} µs ({} µs) | {:+.1} µs |\n",
            case.name,
            r.rms_ns * 1e-3,
            r.max_ns * 1e-3,
            r.coverage_2sigma * 100.0,
            us(r.holdover_60s_ns),
            us(r.holdover_60s_sigma_ns),
            us(r.recovery_jump_ns),
            us(r.recovery_sigma_ns),
            r.d0_median_error_s * 1e6,
        ));
    }
    Ok(s)
}

/// Runs `navsync-bench timing` and prints its table.
pub fn run() -> Result<(), SimError> {
    println!("{}", table()?);
    Ok(())
}
