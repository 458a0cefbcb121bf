//! A PPS source going silent for 60 s while GNSS and the IMU carry on (issue 8), offline and
//! deterministic on the simulated default drive (host clock +0.5 ppm with random-walk FM,
//! 1 µs edge jitter): the time synchroniser detects it (status `holdover` 1.5 s after the last
//! edge, counted in `holdovers`), keeps mapping host time to UTC in holdover with an honest,
//! growing uncertainty, the navigation filter keeps fusing fixes stamped through that mapping,
//! and when the edges return the mapping re-locks at once (counted in `relocks`) with its error
//! back within the locked bound.

use crate::fault_drive::{ErrorTrack, Event, drive, estimator_args, scenario, t_s};
use navsync_wire::samples::{AnySample, TimeStatus};

/// PPS edges stamped in [GAP_FROM_S, GAP_TO_S) of scenario time are not delivered.
const GAP_FROM_S: f64 = 80.0;
const GAP_TO_S: f64 = 140.0;

/// One truth instant's time mapping against the truth.
#[derive(Debug, Clone, Copy)]
struct Mapped {
    t_s: f64,
    status: TimeStatus,
    /// Mapped UTC minus true UTC, ns.
    err_ns: f64,
    /// The published 1σ of the mapping at that instant, ns.
    sigma_ns: f64,
    last_pps_host_ns: i64,
}

#[test]
fn pps_silence_is_held_over_flagged_and_relocked() {
    let end_s = 200.0;
    let cfg = scenario();
    let args = estimator_args();
    let (mut last_edge_before, mut first_edge_after, mut dropped) = (None, None, 0u32);
    let mut mapped = Vec::new();
    let mut track = ErrorTrack::default();
    let (mut holdover_states, mut holdover_states_without_utc) = (0u64, 0u64);
    let mut fixes_at = Vec::new();
    let p = drive(
        &cfg,
        &args,
        end_s,
        |s, out| {
            if let AnySample::PpsEdge(e) = &s {
                let t = t_s(e.stamp.host_ns);
                if (GAP_FROM_S..GAP_TO_S).contains(&t) {
                    dropped += 1;
                    return;
                }
                if t < GAP_FROM_S {
                    last_edge_before = Some(e.stamp.host_ns);
                } else {
                    first_edge_after.get_or_insert(e.stamp.host_ns);
                }
            }
            out.push(s);
        },
        |p, e| {
            track.on(&e);
            match e {
                Event::Nav(n) => {
                    if n.time_status == TimeStatus::Holdover as u8 {
                        holdover_states += 1;
                        holdover_states_without_utc += u64::from(n.utc_ns == i64::MIN);
                    }
                }
                Event::Truth(tr) => {
                    let t = t_s(tr.host_ns);
                    if (t * 10.0).round() as i64 % 10 == 0 {
                        let c = p.nav().counters();
                        fixes_at.push((t, c.fixes_used, c.fixes_rejected));
                    }
                    if t < 30.0 {
                        return;
                    }
                    let ts = p.time_state(tr.host_ns);
                    mapped.push(Mapped {
                        t_s: t,
                        status: ts.status(),
                        err_ns: (ts.utc_ns_at(tr.host_ns) - tr.utc_ns) as f64,
                        sigma_ns: ts.utc_std_ns_at(tr.host_ns),
                        last_pps_host_ns: ts.last_pps_host_ns,
                    });
                }
            }
        },
    );
    let last_edge = last_edge_before.expect("edges before the gap");
    let back = first_edge_after.expect("edges after the gap");
    let (t_last, t_back) = (t_s(last_edge), t_s(back));
    let first = |from: f64, st: TimeStatus| mapped.iter().find(|m| m.t_s >= from && m.status == st).copied();
    let detected = first(t_last, TimeStatus::Holdover).expect("holdover declared");
    let relocked = first(t_back, TimeStatus::Locked).expect("locked again");
    let in_holdover: Vec<_> = mapped
        .iter()
        .filter(|m| m.t_s >= detected.t_s && m.t_s < t_back)
        .copied()
        .collect();
    let worst_sigmas = in_holdover
        .iter()
        .map(|m| m.err_ns.abs() / m.sigma_ns)
        .fold(0.0, f64::max);
    let end_of_holdover = *in_holdover.last().expect("instants in holdover");
    let before_back = mapped.iter().rfind(|m| m.t_s < t_back).copied().unwrap();
    let after_back = mapped.iter().find(|m| m.t_s >= relocked.t_s).copied().unwrap();
    let locked_stats = |from: f64, to: f64| {
        let v: Vec<f64> = mapped
            .iter()
            .filter(|m| m.t_s >= from && m.t_s < to)
            .map(|m| m.err_ns)
            .collect();
        let rms = (v.iter().map(|e| e * e).sum::<f64>() / v.len().max(1) as f64).sqrt();
        (rms, v.iter().fold(0.0f64, |a, e| a.max(e.abs())), v.len())
    };
    let (rms_before, max_before, n_before) = locked_stats(30.0, t_last);
    let (rms_after, max_after, n_after) = locked_stats(relocked.t_s + 10.0, end_s);
    let tc = *p.time().counters();
    let fixes = |t: f64| fixes_at.iter().rfind(|f| f.0 <= t).copied().unwrap();
    let (f0, f1) = (fixes(GAP_FROM_S + 2.0), fixes(GAP_TO_S));
    let nav_gap = track.stats(GAP_FROM_S, GAP_TO_S);
    let nav_before = track.stats(50.0, GAP_FROM_S);

    println!("PPS edges dropped: {dropped} (scenario time {GAP_FROM_S}–{GAP_TO_S} s)");
    println!(
        "holdover declared {:.2} s after the last edge (t = {:.1} s); re-locked {:.2} s after the first edge back (t = {:.1} s)",
        detected.t_s - t_last,
        detected.t_s,
        relocked.t_s - t_back,
        relocked.t_s
    );
    println!(
        "holdover: error {:+.0} ns ± {:.0} ns (1σ) after {:.1} s; worst {:.2} σ over {} instants",
        end_of_holdover.err_ns,
        end_of_holdover.sigma_ns,
        end_of_holdover.t_s - t_last,
        worst_sigmas,
        in_holdover.len()
    );
    println!(
        "recovery: error {:+.0} ns ± {:.0} ns just before, {:+.0} ns just after the relock",
        before_back.err_ns, before_back.sigma_ns, after_back.err_ns
    );
    println!(
        "locked: RMS {rms_before:.0} ns, max {max_before:.0} ns before ({n_before} instants); RMS {rms_after:.0} ns, max {max_after:.0} ns from 10 s after the relock ({n_after})"
    );
    println!("time counters: {tc:?}");
    println!(
        "navigation during the silence: {} of {} fixes used, {} rejected; {nav_gap} (before: {nav_before}); {holdover_states} states in holdover",
        f1.1 - f0.1,
        (f1.0 - f0.0).round(),
        f1.2 - f0.2
    );

    // Detected and flagged.
    assert!(dropped >= 59, "{dropped} edges dropped");
    let detect_s = detected.t_s - t_last;
    assert!(
        (1.5..=1.7).contains(&detect_s),
        "holdover after {detect_s} s (rule: 1.5 s without an accepted edge)"
    );
    assert_eq!(tc.holdovers, 1, "holdover entries");
    assert!(in_holdover.iter().all(|m| m.status == TimeStatus::Holdover));
    assert!(
        in_holdover.iter().all(|m| m.last_pps_host_ns == last_edge),
        "last_pps_host_ns must stay on the last edge"
    );
    assert!(holdover_states > 10_000, "{holdover_states} NavStates flagged holdover");
    assert_eq!(holdover_states_without_utc, 0, "NavStates in holdover without UTC");
    // Held over: the bound (10 µs after 60 s), and an honest uncertainty.
    assert!(end_of_holdover.t_s - t_last > 59.0, "{}", end_of_holdover.t_s - t_last);
    assert!(
        end_of_holdover.err_ns.abs() <= 10_000.0,
        "holdover error {} ns",
        end_of_holdover.err_ns
    );
    assert!(
        worst_sigmas <= 4.0,
        "holdover error {worst_sigmas} σ: the published uncertainty is not honest"
    );
    // The navigation filter keeps fusing fixes stamped through the holdover mapping.
    assert!(f1.1 - f0.1 >= 55, "{} fixes used during the silence", f1.1 - f0.1);
    assert_eq!(f1.2, f0.2, "fixes rejected during the silence");
    assert!(nav_gap.h_rms_m < 1.0 && nav_gap.vel_rms_mps < 0.15, "{nav_gap}");
    assert!(track.non_finite.is_none(), "{:?}", track.non_finite);
    // Recovered: locked at the first edge back, without a resync, the error back in bounds.
    assert!(
        relocked.t_s - t_back <= 0.2,
        "relocked {} s after the edges returned",
        relocked.t_s - t_back
    );
    assert_eq!(tc.relocks, 1, "relocks");
    assert_eq!(tc.resyncs, 0, "the mapping must not be restarted");
    assert!(
        (after_back.err_ns - before_back.err_ns).abs() <= 2.0 * before_back.sigma_ns + 1_000.0,
        "recovery jump {} ns vs σ {} ns",
        after_back.err_ns - before_back.err_ns,
        before_back.sigma_ns
    );
    assert!(n_before > 400 && n_after > 150, "{n_before} / {n_after} instants");
    assert!(max_before <= 5_000.0 && rms_before <= 1_000.0);
    assert!(
        max_after <= 5_000.0 && rms_after <= 1_000.0,
        "after the relock: RMS {rms_after} ns, max {max_after} ns"
    );
    assert!(
        mapped
            .iter()
            .filter(|m| m.t_s >= relocked.t_s)
            .all(|m| m.status == TimeStatus::Locked)
    );
}
