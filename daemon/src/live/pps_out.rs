//! `navsync pps-out --output SPEC [--width-ms MS] [--max-std-us US]`: a PPS for sensors. A
//! pulse whose leading edge is at each whole GNSS second (UTC by navsync's time mapping,
//! `navsync/time/state`), for LiDARs, cameras and loggers that take a PPS or trigger input
//! beside their NMEA time (`nmea-out`).
//!
//! Outputs (`navsync_drivers::pulse_out`):
//! - `gpio:/dev/gpiochipN:LINE` and `sim:FILE` are software-timed: the process computes the
//!   host time of the next whole second with the mapping (`TimeState::host_ns_at`, its rate
//!   error included), sleeps until 2 ms before it, spins to it, raises the line, reads the
//!   edge's host time, and lowers the line `--width-ms` later. An edge that could not be raised
//!   within 1 ms of its second (the process was not scheduled) is not raised: a sensor takes a
//!   late edge for the second itself, a missing one it bridges with its own clock.
//! - `phc:/dev/ptpN:CHANNEL[:PIN]` is hardware-timed: the PHC's periodic output is programmed
//!   once at start (1 s period from a whole second of the PHC's time) and the NIC times every
//!   edge, not navsync, so no process scheduling enters them; phc2sys keeps the PHC on the
//!   disciplined system clock. The process then only checks, once per GNSS second, how far the
//!   PHC's seconds are from GNSS time by the mapping, and reports it; it stops the output when
//!   it stops.
//!
//! No edge is raised while the mapping may not be handed on (`ntpshm::exportable_std_ns`:
//! acquiring, unknown, stale for 5 s, or 1σ over `--max-std-us`): a sensor then keeps its own
//! clock rather than take a wrong second. Counters in `navsync/health/pps-out`.

use crate::live::gnss_seconds::{SecondPacer, Tick};
use navsync_drivers::pulse_out::phc::phase_error_ns;
use navsync_drivers::pulse_out::{Output, OutputSpec, PhcPeriodic, PulseOutError, PulseOutput};
use navsync_shared::health_reporter::HealthReporter;
use navsync_shared::ipc::IpcNode;
use navsync_shared::latency_histogram::LatencyHistogram;
use navsync_shared::pacing::{minimal_timer_slack, sleep_until};
use navsync_shared::time::{NS_PER_S, monotonic_now_ns};
use tracing::{info, info_span, warn};

/// How long before an edge the process stops sleeping and spins, ns: more than a loaded
/// machine's usual wake-up latency.
const SPIN_NS: i64 = 2_000_000;
/// An edge later than this after its second is not raised, ns.
const LATE_LIMIT_NS: i64 = 1_000_000;

/// `navsync pps-out`.
#[derive(Debug, Clone, clap::Args)]
pub struct PpsOutArgs {
    /// Where the pulses go: gpio:/dev/gpiochipN:LINE (a GPIO line, software-timed),
    /// phc:/dev/ptpN:CHANNEL[:PIN] (a PTP hardware clock's periodic output, hardware-timed;
    /// PIN routes the channel to a programmable pin first) or sim:FILE (one line per edge, for
    /// tests). A device without a `/` is under /dev (gpio:gpiochip0:17).
    #[arg(long, value_name = "SPEC")]
    pub output: OutputSpec,
    /// Pulse width, ms: the line is high from the second's beginning for this long.
    #[arg(long, default_value_t = 100, value_name = "MS", value_parser = clap::value_parser!(u32).range(1..=900))]
    pub width_ms: u32,
    /// Raise no edge while the time mapping's 1σ exceeds this many µs.
    #[arg(long, default_value_t = 1000.0, value_name = "US", value_parser = crate::live::ntpshm::positive_us)]
    pub max_std_us: f64,
}

/// Errors of `navsync pps-out`.
#[derive(Debug, thiserror::Error)]
pub enum PpsOutError {
    /// The output could not be opened or programmed.
    #[error(transparent)]
    Output(#[from] PulseOutError),
    /// IPC failure.
    #[error(transparent)]
    Ipc(#[from] navsync_shared::ipc::IpcError),
    /// A health counter could not be registered.
    #[error(transparent)]
    Health(#[from] navsync_shared::health_reporter::HealthError),
}

/// Runs `navsync pps-out` until SIGINT/SIGTERM.
pub fn run(args: &PpsOutArgs) -> Result<(), PpsOutError> {
    let _span = info_span!("pps-out", output = %args.output).entered();
    // The device first: a machine without it fails before anything else is set up.
    let output = args.output.open()?;
    let node = IpcNode::new("pps-out")?;
    let mut health = HealthReporter::new(&node, "pps-out")?;
    let max_std_ns = args.max_std_us * 1e3;
    let width_ns = i64::from(args.width_ms) * 1_000_000;
    match output {
        Output::Line(mut line) => {
            minimal_timer_slack();
            let pacer = SecondPacer::new(&node, max_std_ns, SPIN_NS)?;
            drive(line.as_mut(), &node, pacer, &mut health, width_ns)?;
        }
        Output::Periodic(mut phc) => {
            let pacer = SecondPacer::new(&node, max_std_ns, 0)?;
            watch(&mut phc, &node, pacer, &mut health, width_ns, max_std_ns)?;
        }
    }
    navsync_shared::sd_notify::stopping();
    let _ = health.publish_final();
    info!("pps-out stopped");
    Ok(())
}

/// The edge-lateness gauges of `late`, µs: p50, p99 (the upper edges of 1 µs buckets) and the
/// maximum (rounded up). Pure.
fn late_gauges(late: &LatencyHistogram) -> [u64; 3] {
    [
        late.quantile_us(0.5) as u64,
        late.quantile_us(0.99) as u64,
        (late.max_ns() as u64).div_ceil(1000),
    ]
}

/// True once per host second (`CLOCK_MONOTONIC`): counts seconds, not the 200 ms waits, of an
/// unusable mapping. `last` is the second counted last.
fn new_host_second(last: &mut Option<i64>) -> bool {
    let s = monotonic_now_ns().div_euclid(NS_PER_S);
    let new = *last != Some(s);
    *last = Some(s);
    new
}

/// A software-timed line: one pulse per usable GNSS second.
fn drive(
    line: &mut dyn PulseOutput,
    node: &IpcNode,
    mut pacer: SecondPacer,
    health: &mut HealthReporter,
    width_ns: i64,
) -> Result<(), PpsOutError> {
    let c_pulses = health.counter("pulses")?;
    let c_skipped = health.counter("pulses_not_written")?;
    let c_late = health.counter("pulses_late")?;
    let c_failed = health.counter("set_failed")?;
    let late_ids = [
        health.counter("edge_late_p50_us")?,
        health.counter("edge_late_p99_us")?,
        health.counter("edge_late_max_us")?,
    ];
    let mut late = LatencyHistogram::default();
    let mut unusable_s = None;
    info!(output = %line.describe(), "pps-out running");
    navsync_shared::sd_notify::ready(&format!("pps-out running: {}", line.describe()));
    while !node.termination_requested() {
        navsync_shared::sd_notify::watchdog();
        match pacer.next(node)? {
            Tick::Pending => continue,
            Tick::Unusable => {
                if new_host_second(&mut unusable_s) {
                    health.add(c_skipped, 1);
                }
            }
            Tick::Second { at, .. } if monotonic_now_ns() - at > LATE_LIMIT_NS => {
                health.add(c_late, 1);
                warn!(
                    late_us = (monotonic_now_ns() - at) / 1000,
                    "not scheduled in time for the edge: none raised"
                );
            }
            Tick::Second { at, .. } => match line.set(true) {
                Ok(edge) => {
                    late.record(edge - at);
                    health.add(c_pulses, 1);
                    for (id, v) in late_ids.iter().zip(late_gauges(&late)) {
                        health.set(*id, v);
                    }
                    // A stop request cuts the pulse short: the line is left low.
                    sleep_until(edge + width_ns, 0);
                    if let Err(e) = line.set(false) {
                        health.add(c_failed, 1);
                        warn!("{e}");
                    }
                }
                Err(e) => {
                    health.add(c_failed, 1);
                    warn!("{e}");
                }
            },
        }
        let _ = health.maybe_publish(monotonic_now_ns());
    }
    Ok(())
}

/// A PHC's periodic output: programmed once; then, once per usable GNSS second, the PHC's
/// phase against GNSS time by the mapping.
fn watch(
    phc: &mut PhcPeriodic,
    node: &IpcNode,
    mut pacer: SecondPacer,
    health: &mut HealthReporter,
    width_ns: i64,
    max_std_ns: f64,
) -> Result<(), PpsOutError> {
    let c_phase = health.counter("phc_phase_us")?;
    let c_phase_max = health.counter("phc_phase_max_us")?;
    let c_over = health.counter("phc_phase_over_bound")?;
    let c_unchecked = health.counter("phc_not_checked")?;
    let c_failed = health.counter("phc_read_failed")?;
    let programmed = phc.program(width_ns)?;
    match programmed.width_ns {
        Some(w) => info!(start_s = programmed.start_s, width_ns = w, output = %phc.describe(), "pps-out programmed"),
        None => warn!(
            start_s = programmed.start_s,
            output = %phc.describe(),
            "pps-out programmed; the driver has no pulse width control (its own width)"
        ),
    }
    navsync_shared::sd_notify::ready(&format!("pps-out programmed: {}", phc.describe()));
    let (mut phase_max_us, mut warned, mut unusable_s) = (0u64, false, None);
    while !node.termination_requested() {
        navsync_shared::sd_notify::watchdog();
        match pacer.next(node)? {
            Tick::Pending => continue,
            Tick::Unusable => {
                if new_host_second(&mut unusable_s) {
                    health.add(c_unchecked, 1);
                }
            }
            Tick::Second { .. } => match (phc.read_against_host(), pacer.mapping()) {
                (Ok((host_ns, phc_ns)), Some(t)) => {
                    let phase = phase_error_ns(phc_ns, t.utc_ns_at(host_ns));
                    let us = phase.unsigned_abs() / 1000;
                    phase_max_us = phase_max_us.max(us);
                    health.set(c_phase, us);
                    health.set(c_phase_max, phase_max_us);
                    if phase.unsigned_abs() as f64 > max_std_ns {
                        health.add(c_over, 1);
                        if !warned {
                            warn!(
                                phase_ns = phase,
                                "the PHC's seconds are off GNSS time (is phc2sys running?)"
                            );
                            warned = true;
                        }
                    }
                }
                (Err(e), _) => {
                    health.add(c_failed, 1);
                    warn!("{e}");
                }
                (Ok(_), None) => {}
            },
        }
        let _ = health.maybe_publish(monotonic_now_ns());
    }
    // Dropping the output stops it; say so first.
    info!("stopping {}", phc.describe());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        args: PpsOutArgs,
    }

    fn parse(args: &[&str]) -> Result<PpsOutArgs, clap::Error> {
        Cli::try_parse_from(std::iter::once("pps-out").chain(args.iter().copied())).map(|c| c.args)
    }

    #[test]
    fn flags_parse_and_are_checked() {
        let a = parse(&["--output", "gpio:gpiochip0:17"]).unwrap();
        assert_eq!(a.output.to_string(), "gpio:/dev/gpiochip0:17");
        assert_eq!((a.width_ms, a.max_std_us), (100, 1000.0));
        let a = parse(&[
            "--output",
            "phc:/dev/ptp0:0:1",
            "--width-ms",
            "20",
            "--max-std-us",
            "50",
        ])
        .unwrap();
        assert_eq!(a.output.to_string(), "phc:/dev/ptp0:0:1");
        assert_eq!((a.width_ms, a.max_std_us), (20, 50.0));
        for bad in [
            &["--output", "gpio:/dev/gpiochip0"][..],
            &["--output", "uart:/dev/ttyS0"],
            &["--output", "sim:x", "--width-ms", "0"],
            &["--output", "sim:x", "--width-ms", "1000"],
            &["--output", "sim:x", "--max-std-us", "0"],
            &[],
        ] {
            assert!(parse(bad).is_err(), "{bad:?} accepted");
        }
        let e = parse(&["--output", "gpio:17"]).unwrap_err().to_string();
        assert!(e.contains("gpio:/dev/gpiochipN:LINE"), "{e}");
    }

    #[test]
    fn lateness_gauges_in_us() {
        let mut late = LatencyHistogram::default();
        assert_eq!(late_gauges(&late), [0, 0, 0]);
        for ns in [3_200, 4_100, 4_900, 250_001] {
            late.record(ns);
        }
        assert_eq!(late_gauges(&late), [5, 251, 251]);
    }
}
