//! Process shells: each wires a functional core to its iceoryx2 services, or is a client of
//! the live services.

pub mod bridge;
pub mod demo;
pub mod echo;
pub mod estimator;
pub mod feed;
pub mod foxglove;
pub mod gnss;
pub mod gnss_seconds;
pub mod gpsd_server;
pub mod imu;
pub mod liveness;
pub mod network_time;
pub mod nmea_out;
pub mod ntpshm;
pub mod pps;
pub mod pps_out;
pub mod reclaimer;
pub mod record;
pub mod replay;
pub mod sim;
pub mod status;
pub mod trigger;
pub mod web;

/// Puts the calling thread (and the threads it starts afterwards, which inherit it) under
/// `SCHED_IDLE`: it runs only on CPU time no other task wants, and any other wake-up preempts
/// it (sched(7)). For the processes and threads that watch the pipeline without being part of
/// it (`navsync web`, the dead-node reclaimer): they never take a core from a driver or the
/// estimator. Lowering a policy needs no privilege; a refusal is logged and the thread runs on
/// at the policy it had.
pub(crate) fn run_as_observer(what: &str) {
    let param = libc::sched_param { sched_priority: 0 };
    // SAFETY: sched_setscheduler on the calling thread with a valid sched_param.
    if unsafe { libc::sched_setscheduler(0, libc::SCHED_IDLE, &param) } != 0 {
        tracing::warn!(
            "{what}: SCHED_IDLE refused ({}); runs at the process's policy",
            std::io::Error::last_os_error()
        );
    }
}
