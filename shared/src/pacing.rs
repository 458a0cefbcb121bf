//! Real-time pacing on the host clock: absolute sleeps on `CLOCK_MONOTONIC`, so that delays do
//! not accumulate over thousands of waits (the simulator's event loop, `navsync replay`).

use std::str::FromStr;

use crate::time::{NS_PER_S, monotonic_now_ns};

/// How fast recorded or captured data is played back (`navsync replay --speed`,
/// `navsync feed --speed`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Speed {
    /// The recorded spacing divided by this factor (1: real time).
    Factor(f64),
    /// As fast as possible (as fast as the reader takes it).
    Max,
}

impl FromStr for Speed {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "realtime" => Ok(Self::Factor(1.0)),
            "max" => Ok(Self::Max),
            _ => s
                .parse::<f64>()
                .ok()
                .filter(|f| f.is_finite() && *f > 0.0)
                .map(Self::Factor)
                .ok_or_else(|| {
                    format!("`{s}` is not a speed: expected `realtime` (= 1), `max` or a positive factor such as 10")
                }),
        }
    }
}

/// Sleeps until host time `target_ns` (`CLOCK_MONOTONIC`, ns) with an absolute
/// `clock_nanosleep`, waking `spin_ns` early and spinning the rest (for wake-ups accurate to
/// µs despite timer slack; 0 to not spin). Returns early, before `target_ns`, when a signal
/// interrupts the sleep, so callers can check for a termination request; callers that must
/// not wake early loop until `monotonic_now_ns() >= target_ns`.
pub fn sleep_until(target_ns: i64, spin_ns: i64) {
    let coarse = target_ns - spin_ns.max(0);
    if coarse > monotonic_now_ns() {
        let ts = libc::timespec {
            tv_sec: coarse / NS_PER_S,
            tv_nsec: coarse % NS_PER_S,
        };
        // SAFETY: absolute sleep on CLOCK_MONOTONIC with a valid timespec and no remainder.
        let rc =
            unsafe { libc::clock_nanosleep(libc::CLOCK_MONOTONIC, libc::TIMER_ABSTIME, &ts, std::ptr::null_mut()) };
        if rc == libc::EINTR {
            return;
        }
    }
    while monotonic_now_ns() < target_ns {
        std::hint::spin_loop();
    }
}

/// Sets the calling thread's timer slack to 1 ns (`PR_SET_TIMERSLACK`; the kernel's default is
/// 50 µs), so that its timed sleeps wake within µs of the requested time; threads it starts
/// afterwards inherit it. Best effort: a kernel that refuses leaves the default.
pub fn minimal_timer_slack() {
    // SAFETY: prctl on the calling thread with an integer argument.
    unsafe { libc::prctl(libc::PR_SET_TIMERSLACK, 1 as libc::c_ulong) };
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wakes_after_the_target() {
        for spin in [0, 200_000] {
            let target = monotonic_now_ns() + 5_000_000;
            sleep_until(target, spin);
            assert!(monotonic_now_ns() >= target);
        }
        // A target in the past returns at once.
        sleep_until(monotonic_now_ns() - NS_PER_S, 0);
    }
}
