//! Runs the estimator over a stream of recorded or simulated samples as fast as the CPU allows,
//! and evaluates it against the truth in the stream.
//!
//! The samples go through the [`Feed`] exactly as in the live process, so the estimator
//! consumes them in the same order as the live `navsync estimator` would have, whatever order
//! they come in (delivery order from the simulator, receipt order from a recording): the
//! navigation states are bit-identical to the live ones for the same samples.

use std::borrow::BorrowMut;
use std::time::{Duration, Instant};

use navsync_wire::samples::{AnySample, NavState, TimeState};
use navsync_wire::time::NS_PER_S;

use crate::evaluation::{DelayTruth, Evaluator, Summary};
use crate::feed::Feed;
use crate::input_order::Input;
use crate::pipeline::Pipeline;
use crate::settings::Settings;

/// What an offline run produced.
pub struct OfflineRun {
    /// The accuracy summary.
    pub summary: Summary,
}

/// An output of the estimator.
#[derive(Debug, Clone, Copy)]
pub enum Output<'a> {
    /// The navigation state for a reference-IMU sample.
    Nav(&'a NavState),
    /// The time state, after a PPS edge or fix changed the mapping and at least once per
    /// second of sample time. Offline its `computed_host_ns` is the latest IMU sample's host
    /// time (live: the host clock when published), so time states differ from the live ones
    /// in that field and in how many there are; navigation states do not.
    Time(&'a TimeState),
}

/// Builds the estimator `settings` describe and runs it over `samples` (each with a tag `T`,
/// e.g. its recording time) in the canonical input order of its reference IMU: the one entry
/// point of every offline tool. Outputs as for [`run_feed`].
pub fn estimate<T, S: Into<Input>, I: IntoIterator<Item = (S, T)>>(
    settings: &Settings,
    samples: I,
    time_states: bool,
    on_output: impl FnMut(Output<'_>, &T),
) -> OfflineRun {
    run_feed(
        Feed::new(settings.pipeline_config()),
        samples,
        settings.delay_truth(),
        time_states,
        on_output,
    )
    .0
}

/// Feeds `samples` to `pipeline`; every navigation state goes to `on_nav`. The reference
/// IMU is not known here, so every IMU sample releases the waiting PPS edges and fixes (the
/// same order as the live process's for IMU stamp offsets below the holds of
/// [`crate::input_order`]); [`run_ordered`] takes it explicitly.
pub fn run<I: IntoIterator<Item = AnySample>>(
    pipeline: &mut Pipeline,
    samples: I,
    delay_truth: DelayTruth,
    mut on_nav: impl FnMut(&NavState),
) -> OfflineRun {
    run_ordered(
        pipeline,
        None,
        samples.into_iter().map(|s| (s, ())),
        delay_truth,
        false,
        |o, _| {
            if let Output::Nav(n) = o {
                on_nav(n);
            }
        },
    )
}

/// Feeds `samples` (each with a tag `T`) to `pipeline` in the canonical input order released
/// by the IMU `reference_imu` (the pipeline's reference IMU; `None`: any IMU). Outputs as for
/// [`run_feed`].
pub fn run_ordered<T, S: Into<Input>, I: IntoIterator<Item = (S, T)>>(
    pipeline: &mut Pipeline,
    reference_imu: Option<&str>,
    samples: I,
    delay_truth: DelayTruth,
    time_states: bool,
    on_output: impl FnMut(Output<'_>, &T),
) -> OfflineRun {
    run_feed(
        Feed::with(pipeline, reference_imu),
        samples,
        delay_truth,
        time_states,
        on_output,
    )
    .0
}

/// Feeds `samples`, each with a tag `T` (e.g. its recording time), through `feed` (the one
/// input path, [`Feed`]). Every output goes to `on_output` with the tag of the sample that
/// produced it (for a time state: of the PPS edge, fix or IMU sample after which it was
/// computed); time states only with `time_states`, after a PPS edge or fix changed the mapping
/// and at least once per second of sample time.
pub fn run_feed<T, P: BorrowMut<Pipeline>, S: Into<Input>, I: IntoIterator<Item = (S, T)>>(
    mut feed: Feed<T, P>,
    samples: I,
    delay_truth: DelayTruth,
    time_states: bool,
    mut on_output: impl FnMut(Output<'_>, &T),
) -> (OfflineRun, Feed<T, P>) {
    let t0 = Instant::now();
    let mut eval = Evaluator::default();
    let (mut imu, mut fixes) = (0u64, 0u64);
    // Time spent inside the estimator only (not producing or decoding the samples, nor
    // writing the outputs).
    let mut in_estimator = Duration::ZERO;
    let mut latest_host_ns = i64::MIN;
    let mut last_time_ns = i64::MIN;
    let mut drain = |feed: &mut Feed<T, P>, all: bool| loop {
        let t = Instant::now();
        let Some(step) = feed.next(all) else { break };
        in_estimator += t.elapsed();
        match &step.input {
            Input::Imu(x) => {
                imu += 1;
                latest_host_ns = latest_host_ns.max(x.stamp.host_ns);
            }
            Input::GnssFix(_) => fixes += 1,
            Input::Truth(t) => eval.add_truth(t),
            _ => {}
        }
        if let Some(n) = &step.nav {
            eval.add_nav(n);
            on_output(Output::Nav(n), &step.tag);
        }
        let t = Instant::now();
        let _ = feed.finish(&step);
        in_estimator += t.elapsed();
        // Computing a time state does not change the navigation states (it only reads the
        // filter's Δ into the time synchroniser's report).
        if time_states
            && latest_host_ns != i64::MIN
            && (step.time_changed || latest_host_ns.saturating_sub(last_time_ns) >= NS_PER_S)
        {
            let ts = feed.pipeline_mut().time_state(latest_host_ns);
            on_output(Output::Time(&ts), &step.tag);
            last_time_ns = latest_host_ns;
        }
    };
    for (s, tag) in samples {
        feed.push(s, tag);
        drain(&mut feed, false);
    }
    drain(&mut feed, true);
    let wall = t0.elapsed().as_secs_f64();
    let pipeline = feed.pipeline();
    let rejected = pipeline.nav().counters().fixes_rejected;
    let mut summary = eval.summary((imu, fixes, rejected), wall, in_estimator.as_secs_f64(), delay_truth);
    pipeline.nav().measurement_states().each_counter(&mut |name, v| {
        summary.measurement_counters.insert(name.to_string(), v);
    });
    pipeline.nav().integrity().each(&mut |name, v| {
        summary.measurement_counters.insert(name.to_string(), v);
    });
    if pipeline.nav().is_tight() {
        pipeline.each_raw_counter(&mut |name, v| {
            summary.measurement_counters.insert(name.to_string(), v);
        });
    }
    summary.nav_states = feed.check().states;
    summary.usable_states = feed.check().usable;
    summary.problem = feed.problem();
    (OfflineRun { summary }, feed)
}
