//! GNSS jumping 10 km (issue 8), offline and deterministic on the simulated default drive
//! (1 Hz fixes): a short burst of displaced fixes is rejected by the innovation gate and the
//! state does not move; a permanent 10 km step (a receiver reset or a spoofer) is rejected
//! [`RESET_AFTER_REJECTS`] − 1 times, then the position is reset to GNSS at the
//! [`RESET_AFTER_REJECTS`]th fix (counted in `gnss_resets`; the fixes' velocity still agrees,
//! so velocity, attitude and sensor errors are kept) and the filter carries on from the new,
//! consistent position with its normal accuracy; a burst longer than that is followed and then
//! left the same way. Errors are measured against the simulator's truth (shifted by 10 km
//! where the fixes are) and compared with the same drive without the fault.

use crate::fault_drive::{ErrorTrack, Event, UTC0, displace_fix, drive, estimator_args, scenario, t_s};
use navsync_estimator::nav::navigator::RESET_AFTER_REJECTS;
use navsync_wire::samples::{AnySample, NavStatus};
use navsync_wire::time::NS_PER_S;
use std::sync::OnceLock;

/// The displacement, m north and east (10 km).
const JUMP_NE_M: [f64; 2] = [8_000.0, 6_000.0];

/// Epoch (s of scenario time) of a fix.
fn epoch_s(f: &navsync_wire::samples::GnssFix) -> f64 {
    (f.utc_ns - UTC0) as f64 / NS_PER_S as f64
}

/// End of every drive, s of scenario time.
fn end_s() -> f64 {
    260.0
}

/// The drive without faults (once per test binary).
fn clean() -> &'static Run {
    static CLEAN: OnceLock<Run> = OnceLock::new();
    CLEAN.get_or_init(|| run(f64::INFINITY, f64::INFINITY, end_s()))
}

/// The drive whose fixes are displaced by [`JUMP_NE_M`] from the start (once per test binary).
fn shifted_all_along() -> &'static Run {
    static SHIFTED: OnceLock<Run> = OnceLock::new();
    SHIFTED.get_or_init(|| run(0.0, f64::INFINITY, end_s()))
}

struct Run {
    track: ErrorTrack,
    /// (scenario time, fixes used, fixes rejected, gnss resets, status) at every NavState.
    timeline: Vec<(f64, u64, u64, u64, u8)>,
    displaced: u64,
    first_displaced_s: f64,
    /// Resets that also replaced the velocity (the filter judged itself inconsistent).
    full_resets: u64,
}

/// The drive with the fixes of epochs in `[from_s, to_s)` displaced by [`JUMP_NE_M`].
fn run(from_s: f64, to_s: f64, end_s: f64) -> Run {
    let mut track = ErrorTrack::default();
    if to_s > end_s {
        // A permanent step: from then on the fixes describe the shifted world.
        track.shift_from = Some((from_s, JUMP_NE_M));
    }
    let mut timeline = Vec::new();
    let (mut displaced, mut first) = (0u64, f64::NAN);
    let p = drive(
        &scenario(),
        &estimator_args(),
        end_s,
        |s, out| match s {
            AnySample::GnssFix(f) if (from_s..to_s).contains(&epoch_s(&f)) => {
                displaced += 1;
                if first.is_nan() {
                    first = epoch_s(&f);
                }
                out.push(AnySample::GnssFix(displace_fix(&f, JUMP_NE_M[0], JUMP_NE_M[1])));
            }
            _ => out.push(s),
        },
        |p, e| {
            track.on(&e);
            if let Event::Nav(n) = e {
                let c = p.nav().counters();
                let row = (t_s(n.host_ns), c.fixes_used, c.fixes_rejected, c.gnss_resets, n.status);
                if timeline.last().is_none_or(|l: &(f64, u64, u64, u64, u8)| {
                    (l.1, l.2, l.3, l.4) != (row.1, row.2, row.3, row.4) || row.0 - l.0 >= 0.1
                }) {
                    timeline.push(row);
                }
            }
        },
    );
    Run {
        track,
        timeline,
        displaced,
        first_displaced_s: first,
        full_resets: p.nav().counters().gnss_resets_full,
    }
}

impl Run {
    /// Counters at scenario time `t`: (fixes used, rejected, resets).
    fn at(&self, t: f64) -> (u64, u64, u64) {
        let r = self.timeline.iter().rfind(|r| r.0 <= t).expect("a state before t");
        (r.1, r.2, r.3)
    }

    /// First time at or after `from` when `pred` holds.
    fn first(&self, from: f64, pred: impl Fn(&(f64, u64, u64, u64, u8)) -> bool) -> Option<f64> {
        self.timeline.iter().find(|r| r.0 >= from && pred(r)).map(|r| r.0)
    }

    fn degraded_between(&self, from: f64, to: f64) -> bool {
        self.timeline
            .iter()
            .any(|r| r.0 >= from && r.0 < to && r.4 == NavStatus::Degraded as u8)
    }
}

#[test]
fn a_burst_of_jumped_fixes_is_rejected_and_the_state_does_not_move() {
    // The longest burst the filter rides through: one fix short of the reset.
    let n = u64::from(RESET_AFTER_REJECTS - 1);
    let (from, end) = (110.0, end_s());
    let r = run(from, from + n as f64, end);
    let c = clean();
    let (before, after) = (r.at(from), r.at(end));
    let clean_rejected = c.at(end).1 - c.at(from).1;
    let windows = [
        ("during the burst (+3 s)", from, from + n as f64 + 3.0),
        ("after it", from + n as f64 + 3.0, end),
    ];
    println!(
        "{} fixes displaced by 10 km from epoch {:.0} s: used/rejected/resets {before:?} before, {after:?} at the end (clean run: {clean_rejected} rejected)",
        r.displaced, r.first_displaced_s
    );
    let back = r
        .first(from + n as f64, |x| x.4 == NavStatus::Aligned as u8)
        .expect("aligned again");
    println!("status degraded from the 3rd rejection, aligned again at {back:.2} s");
    assert_eq!(r.displaced, n);
    assert_eq!(
        after.1 - before.1,
        n + clean_rejected,
        "every displaced fix rejected, nothing else"
    );
    assert_eq!(after.2, 0, "no reset for a burst of {n}");
    assert!(
        r.degraded_between(from, from + n as f64 + 3.0),
        "status degraded flagged"
    );
    assert!(back < from + n as f64 + 3.0, "aligned again at {back} s");
    // The state did not move: the error is the clean run's while GNSS was jumping and after.
    for (name, a, b) in windows {
        let (f, k) = (r.track.stats(a, b), c.track.stats(a, b));
        println!("{name}:\n  clean {k}\n  burst {f}");
        assert!(
            f.h_max_m <= k.h_max_m + 0.5 && f.h_rms_m <= k.h_rms_m + 0.2,
            "{name}: {f} vs clean {k}"
        );
        assert!(f.vel_rms_mps <= k.vel_rms_mps + 0.05, "{name}: {f} vs clean {k}");
    }
    assert!(r.track.non_finite.is_none());
}

#[test]
fn a_permanent_10_km_step_is_reset_to_after_the_documented_fixes() {
    let (from, end) = (120.0, end_s());
    let r = run(from, f64::INFINITY, end);
    let c = clean();
    let k = u64::from(RESET_AFTER_REJECTS);
    let before = r.at(from);
    let reset_at = r.first(from, |x| x.3 == 1).expect("a reset");
    let at_reset = r.at(reset_at);
    let end_counts = r.at(end);
    let kth_epoch = r.first_displaced_s + (k - 1) as f64;
    // Errors against the shifted truth (what the fixes now describe).
    let err_at = |t: f64| r.track.window(t, f64::INFINITY).next().map_or(f64::NAN, |e| e.h_m);
    let before_reset = r.track.stats(from, reset_at - 0.1);
    println!(
        "step of 10 km at epoch {:.0} s: {} fixes rejected, reset at {reset_at:.2} s (the {k}th displaced fix has epoch {kth_epoch:.0} s; the filter fuses 1.5 s behind the present); used/rejected/resets before {before:?}, after the reset {at_reset:?}, at the end {end_counts:?}; full resets {}",
        r.first_displaced_s,
        at_reset.1 - before.1,
        r.full_resets
    );
    println!(
        "error vs the shifted truth: {:.0} m just before the reset, {:.3} m at +1 s, {:.3} m at +5 s, {:.3} m at +10 s",
        err_at(reset_at - 0.3),
        err_at(reset_at + 1.0),
        err_at(reset_at + 5.0),
        err_at(reset_at + 10.0)
    );
    println!("between the step and the reset: {before_reset}");
    // Rejected K − 1 times, reset at the K-th: K rejections, one position-only reset.
    assert_eq!(at_reset.1 - before.1, k, "rejections up to the reset");
    assert_eq!((at_reset.2, r.full_resets), (1, 0), "one reset, of the position only");
    assert!(
        reset_at > kth_epoch && reset_at < kth_epoch + 2.5,
        "reset at {reset_at} s, {k}th displaced fix at {kth_epoch} s"
    );
    assert!(r.degraded_between(from, reset_at), "status degraded before the reset");
    // The state did not follow the first K − 1 fixes: still 10 km from the shifted truth.
    assert!(before_reset.n > 30 && before_reset.h_rms_m > 9_900.0, "{before_reset}");
    // On the new position at once, and as good as without the step from then on; no more
    // rejections than the clean run's.
    assert!(
        err_at(reset_at + 1.0) < 2.0,
        "{} m 1 s after the reset",
        err_at(reset_at + 1.0)
    );
    // From 20 s after the reset on, the reference is the same drive whose fixes described
    // the shifted world from the start: 10 km away the local vertical is 0.07° from the one
    // the IMU measures (a 1.2 mg horizontal specific force the filter must carry, with or
    // without the step); what the step itself may cost is the reset's transient.
    let shifted = shifted_all_along();
    for (name, a, b, slack_m, k_run) in [
        ("first 20 s after the reset", reset_at + 0.2, reset_at + 20.0, 1.0, c),
        ("from 20 s after the reset", reset_at + 20.0, end, 0.3, shifted),
    ] {
        let (f, k) = (r.track.stats(a, b), k_run.track.stats(a, b));
        println!("{name}:\n  clean {k}\n  step  {f}");
        assert!(f.n > 150, "{name}: {f}");
        assert!(
            f.h_max_m <= k.h_max_m + slack_m && f.h_rms_m <= k.h_rms_m + slack_m / 2.0,
            "{name}: {f} vs clean {k}"
        );
        assert!(f.vel_rms_mps <= k.vel_rms_mps + 0.05, "{name}: {f} vs clean {k}");
        assert!(f.yaw_max_deg <= k.yaw_max_deg + 0.3, "{name}: {f} vs clean {k}");
    }
    let (after, clean_after) = (end_counts.1 - at_reset.1, c.at(end).1 - c.at(reset_at).1);
    assert!(
        after <= clean_after && end_counts.2 == 1,
        "after the reset: {after} rejections (clean run {clean_after}), {} resets",
        end_counts.2
    );
    assert!(r.track.non_finite.is_none());
}

#[test]
fn a_burst_longer_than_the_reset_is_followed_and_then_left() {
    let n = 10u64;
    let (from, end) = (110.0, end_s());
    let r = run(from, from + n as f64, end);
    let c = clean();
    let k = u64::from(RESET_AFTER_REJECTS);
    let before = r.at(from);
    let first_reset = r.first(from, |x| x.3 == 1).expect("reset into the jump");
    let second_reset = r.first(from, |x| x.3 == 2).expect("reset back");
    let end_counts = r.at(end);
    let err_at = |t: f64| r.track.window(t, f64::INFINITY).next().map_or(f64::NAN, |e| e.h_m);
    println!(
        "burst of {n} displaced fixes from epoch {from:.0} s: resets at {first_reset:.2} s and {second_reset:.2} s (full: {}); used/rejected/resets before {before:?}, at the end {end_counts:?}",
        r.full_resets
    );
    println!(
        "error vs the truth: {:.0} m between the resets, {:.3} m 1 s after the second, {:.3} m at +5 s",
        err_at(first_reset + 1.0),
        err_at(second_reset + 1.0),
        err_at(second_reset + 5.0)
    );
    assert_eq!(
        (end_counts.2, r.full_resets),
        (2, 0),
        "two position resets: into the jump, and back"
    );
    assert_eq!(
        end_counts.1 - before.1,
        2 * k + (c.at(end).1 - c.at(from).1),
        "{k} rejections before each reset"
    );
    assert!((second_reset - first_reset - n as f64).abs() < 0.5);
    assert!(err_at(first_reset + 1.0) > 9_900.0);
    assert!(err_at(second_reset + 1.0) < 2.0);
    for (name, a, b, slack_m) in [
        (
            "first 20 s after the second reset",
            second_reset + 0.2,
            second_reset + 20.0,
            1.0,
        ),
        ("from 20 s after it", second_reset + 20.0, end, 0.3),
    ] {
        let (f, k) = (r.track.stats(a, b), c.track.stats(a, b));
        println!("{name}:\n  clean {k}\n  burst {f}");
        assert!(
            f.h_max_m <= k.h_max_m + slack_m && f.h_rms_m <= k.h_rms_m + slack_m / 2.0,
            "{name}: {f} vs clean {k}"
        );
        assert!(f.vel_rms_mps <= k.vel_rms_mps + 0.05, "{name}: {f} vs clean {k}");
        assert!(f.yaw_max_deg <= k.yaw_max_deg + 0.3, "{name}: {f} vs clean {k}");
    }
    assert!(r.track.non_finite.is_none());
}
