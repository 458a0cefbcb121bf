//! Never silent: counts the navigation states that are usable (aligned, with a GNSS time) and,
//! when there are none or far fewer than the states themselves, says why in words a user can
//! act on. Used by the offline runs (the summary's `problem`; offline commands exit non-zero)
//! and by the live estimator (`Health` counter `nav_usable` and a warning).

use navsync_wire::samples::{INTEGRITY_INCONSISTENT, NavState, NavStatus};

/// Fewer usable states than this share of the states since the platform first moved is a
/// problem (before that the heading may not be observable: a stationary start waits).
pub const MIN_USABLE_SHARE: f64 = 0.5;
/// A run whose aligned states the integrity monitor flags inconsistent this often (nearly
/// throughout: a filter that does not follow its fixes) is reported as not trustworthy; a
/// flag now and then (after a GNSS outage, a bias step) is what the flag is for.
pub const MAX_INCONSISTENT_SHARE: f64 = 0.9;
/// More of the fixes than this share arriving behind the delayed filter (later than the fusion
/// horizon allows, so never fused) is a problem: the states coast on the IMU between the fixes
/// that do arrive in time, with no word about it otherwise.
pub const MAX_TOO_OLD_SHARE: f64 = 0.1;
/// Fixes needed before the share of late ones is judged.
const MIN_FIXES_FOR_SHARE: u64 = 10;

/// What the pipeline saw, for the diagnosis.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct InputsSeen {
    /// GNSS fixes that reached the estimator.
    pub fixes: u64,
    /// Fixes fused by the filter.
    pub fixes_used: u64,
    /// Fixes whose time could not be labelled (no PPS lock, no software mapping).
    pub fixes_unlabelled: u64,
    /// PPS edges used by the time synchroniser.
    pub pps_used: u64,
    /// A known initial state was configured (no self-alignment).
    pub initial_state: bool,
    /// GNSS speed from which a fix counts as moving for the alignment, m/s.
    pub align_min_speed_mps: f64,
    /// Heading banks started (the alignment's search for the heading).
    pub heading_banks: u64,
    /// Resets of the filter by the integrity monitor.
    pub integrity_resets: u64,
    /// Fixes that arrived behind the delayed filter and were not fused.
    pub fixes_too_old: u64,
    /// The fusion horizon, s.
    pub fusion_horizon_s: f64,
    /// Tightly coupled (each satellite's measurements fused).
    pub tight: bool,
    /// Raw measurement epochs that reached the estimator.
    pub raw_epochs: u64,
    /// Pseudoranges fused (tightly coupled).
    pub ranges_used: u64,
    /// Raw measurements left out for want of an ephemeris.
    pub raw_no_ephemeris: u64,
}

/// Counts of navigation states by usability.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct OutputCheck {
    /// Navigation states produced.
    pub states: u64,
    /// Of those, aligned (position, velocity and attitude estimated).
    pub aligned: u64,
    /// Of those, with a GNSS/UTC time: usable by a subscriber or an export.
    pub usable: u64,
    /// States not aligned before any fix showed the platform moving (the stationary start).
    pub waiting_for_motion: u64,
    /// Aligned states the integrity monitor flagged inconsistent (not usable).
    pub inconsistent: u64,
}

impl OutputCheck {
    /// Counts one navigation state (`moving`: a fix has shown the platform moving by now).
    pub fn add(&mut self, s: &NavState, moving: bool) {
        self.states += 1;
        if s.status == NavStatus::Aligning as u8 && !moving {
            self.waiting_for_motion += 1;
        }
        if s.status != NavStatus::Aligning as u8 {
            self.aligned += 1;
            if s.integrity & INTEGRITY_INCONSISTENT != 0 {
                // The integrity monitor finds its innovations inconsistent with its σ (the
                // state is published with its σ inflated and the flag).
                self.inconsistent += 1;
            }
            if s.utc_ns != i64::MIN {
                self.usable += 1;
            }
        }
    }

    /// Why there are no usable states, or far fewer than states (below
    /// [`MIN_USABLE_SHARE`]); `None` when the output is as expected.
    pub fn problem(&self, seen: &InputsSeen) -> Option<String> {
        if let Some(p) = self.usability(seen) {
            return Some(p);
        }
        if seen.fixes >= MIN_FIXES_FOR_SHARE && seen.fixes_too_old as f64 > MAX_TOO_OLD_SHARE * seen.fixes as f64 {
            return Some(format!(
                "{} of {} fixes arrived later than the fusion horizon ({:.1} s) allows and were not fused: the \
                 receiver's output latency (or the GNSS delay) exceeds it, and the states coast on the IMU \
                 between the fixes that came in time; raise --horizon ([estimator] fusion_horizon_s)",
                seen.fixes_too_old, seen.fixes, seen.fusion_horizon_s
            ));
        }
        if seen.tight && seen.raw_epochs > 0 && seen.ranges_used == 0 && self.aligned > 0 {
            let why = if seen.raw_no_ephemeris > 0 {
                format!(
                    "{} measurements of {} raw epochs had no ephemeris (no navigation data, UBX RXM-SFRBX, in \
                     the input, or none complete yet)",
                    seen.raw_no_ephemeris, seen.raw_epochs
                )
            } else {
                format!(
                    "none of the {} raw epochs had a measurement it could use (the summary's raw_* counters say \
                     what they left out: other signals, invalid ranges)",
                    seen.raw_epochs
                )
            };
            return Some(format!(
                "tightly coupled, and no satellite was fused: {why}; the states coast on the IMU from the \
                 alignment (their σ says how far); record the receiver's navigation data, or use --coupling loose"
            ));
        }
        (seen.integrity_resets > 0).then(|| {
            format!(
                "the integrity monitor reset the filter {} time(s) (a non-finite, not positive definite or \
                 implausible state: the integrity_* counters say which): the states before each reset are \
                 not trustworthy",
                seen.integrity_resets
            )
        })
    }

    /// Why there are no usable states, or far fewer than states; `None` when they are usable.
    fn usability(&self, seen: &InputsSeen) -> Option<String> {
        if self.states == 0 {
            return Some(
                "no navigation state: no sample of the reference IMU reached the estimator (check the IMU ids, \
                 e.g. --imus, against the recording's or the drivers' services)"
                    .into(),
            );
        }
        let expected = self.states - self.waiting_for_motion;
        let consistent = (self.inconsistent as f64) < MAX_INCONSISTENT_SHARE * self.aligned as f64;
        if self.usable > 0 && self.usable as f64 >= MIN_USABLE_SHARE * expected as f64 && consistent {
            return None;
        }
        if self.usable > 0 && !consistent {
            return Some(format!(
                "the integrity monitor found the filter inconsistent with its fixes in {} of {} aligned states \
                 (fixes rejected, its covariance inflated): its estimates are not trustworthy (a wrong time \
                 synchronisation, a receiver latency beyond the fusion horizon, or an IMU model far off)",
                self.inconsistent, self.aligned
            ));
        }
        let share = if expected == 0 {
            format!(
                "no navigation state is usable: no fix showed the platform moving ({} states)",
                self.waiting_for_motion
            )
        } else {
            format!(
                "only {} of {} navigation states are usable (aligned, with a GNSS time; {} more before the \
                 platform moved)",
                self.usable, expected, self.waiting_for_motion
            )
        };
        let why = if self.aligned * 2 < expected || self.aligned == 0 {
            if seen.fixes == 0 {
                "the filter is not aligned: no GNSS fix reached the estimator (check the receiver's service \
                 and driver, e.g. --gnss)"
                    .to_string()
            } else if seen.initial_state {
                "the filter is not aligned: the configured initial state's time was not reached or could not \
                 be mapped to host time (is it within the data? under hardware sync the PPS must lock first)"
                    .to_string()
            } else if seen.heading_banks == 0 {
                format!(
                    "the filter is not aligned: it starts after a static levelling or on the first fix moving \
                     at {:.1} m/s or more, and neither came ({} fixes seen); give an initial state \
                     ([estimator.initial_state]) or a lower --align-speed",
                    seen.align_min_speed_mps, seen.fixes
                )
            } else {
                format!(
                    "the filter is not aligned: the heading was not observable ({} fixes seen): a vehicle that \
                     stands still or moves straight at constant speed does not show it; it is decided once the \
                     motion does (turns, speed changes), or give an initial state ([estimator.initial_state])",
                    seen.fixes
                )
            }
        } else if seen.pps_used == 0 && seen.fixes_used == 0 {
            format!(
                "the states have no GNSS time: no PPS edge was used and no fix could be labelled ({} of {} \
                 fixes unlabelled); without PPS use --software-sync",
                seen.fixes_unlabelled, seen.fixes
            )
        } else {
            format!(
                "the states have no GNSS time for long stretches: the PPS lock or the fixes' labels came late \
                 or were lost ({} PPS edges used, {} of {} fixes unlabelled)",
                seen.pps_used, seen.fixes_unlabelled, seen.fixes
            )
        };
        Some(format!("{share}: {why}"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use navsync_wire::reflect::Reflect;

    fn state(status: NavStatus, utc_ns: i64) -> NavState {
        let mut s = NavState::zeroed();
        s.status = status as u8;
        s.utc_ns = utc_ns;
        s
    }

    #[test]
    fn says_why_when_states_are_unusable() {
        let seen = InputsSeen {
            fixes: 10,
            align_min_speed_mps: 0.3,
            ..Default::default()
        };
        assert!(
            OutputCheck::default()
                .problem(&seen)
                .unwrap()
                .contains("no navigation state")
        );
        let mut c = OutputCheck::default();
        (0..10).for_each(|_| c.add(&state(NavStatus::Aligning, i64::MIN), false));
        assert!(c.problem(&seen).unwrap().contains("moving at 0.3 m/s"));
        let searching = InputsSeen {
            heading_banks: 1,
            ..seen
        };
        assert!(c.problem(&searching).unwrap().contains("heading was not observable"));
        let mut c = OutputCheck::default();
        (0..10).for_each(|_| c.add(&state(NavStatus::Aligned, i64::MIN), true));
        assert!(c.problem(&seen).unwrap().contains("--software-sync"));
        (0..10).for_each(|_| c.add(&state(NavStatus::Aligned, 1), true));
        assert_eq!(c.usable, 10);
        assert_eq!(c.problem(&seen), None, "half usable is enough");
        let reset = InputsSeen {
            integrity_resets: 2,
            ..seen
        };
        assert!(c.problem(&reset).unwrap().contains("reset the filter 2 time(s)"));
        // A long stationary start waits for the motion; what follows it counts.
        let mut c = OutputCheck::default();
        (0..80).for_each(|_| c.add(&state(NavStatus::Aligning, i64::MIN), false));
        (0..5).for_each(|_| c.add(&state(NavStatus::Aligning, i64::MIN), true));
        (0..15).for_each(|_| c.add(&state(NavStatus::Aligned, 1), true));
        assert_eq!(c.problem(&seen), None, "{c:?}");
        // Never moved, never aligned: no usable state is a problem.
        let mut c = OutputCheck::default();
        (0..80).for_each(|_| c.add(&state(NavStatus::Aligning, i64::MIN), false));
        assert!(
            c.problem(&searching).unwrap().contains("heading was not observable"),
            "{c:?}"
        );
    }

    #[test]
    fn fixes_behind_the_horizon_are_a_problem() {
        let mut c = OutputCheck::default();
        (0..100).for_each(|_| c.add(&state(NavStatus::Aligned, 1), true));
        let seen = InputsSeen {
            fixes: 100,
            fixes_used: 80,
            fixes_too_old: 20,
            fusion_horizon_s: 1.5,
            ..Default::default()
        };
        let p = c.problem(&seen).expect("20 % of the fixes never fused");
        assert!(p.contains("20 of 100 fixes") && p.contains("--horizon"), "{p}");
        let few = InputsSeen {
            fixes_too_old: 5,
            ..seen
        };
        assert_eq!(c.problem(&few), None);
    }

    #[test]
    fn tightly_coupled_without_a_fused_satellite_is_a_problem() {
        let mut c = OutputCheck::default();
        (0..100).for_each(|_| c.add(&state(NavStatus::Aligned, 1), true));
        let seen = InputsSeen {
            fixes: 100,
            tight: true,
            raw_epochs: 100,
            raw_no_ephemeris: 2000,
            ..Default::default()
        };
        let p = c.problem(&seen).expect("no satellite fused");
        assert!(
            p.contains("2000 measurements of 100 raw epochs had no ephemeris"),
            "{p}"
        );
        // Measurements left out for other reasons: said so.
        let p = c
            .problem(&InputsSeen {
                raw_no_ephemeris: 0,
                ..seen
            })
            .expect("no satellite fused");
        assert!(p.contains("none of the 100 raw epochs had a measurement"), "{p}");
        // One range fused, or loosely coupled: no such problem.
        assert_eq!(c.problem(&InputsSeen { ranges_used: 1, ..seen }), None);
        assert_eq!(c.problem(&InputsSeen { tight: false, ..seen }), None);
    }
}
