//! Runs the estimator over a stream of recorded or simulated samples as fast as the CPU allows,
//! and evaluates it against the truth in the stream.
//!
//! The samples go through the [`Feed`] exactly as in the live process, so the estimator
//! consumes them in the same order as the live `navsync estimator` would have, whatever order
//! they come in (delivery order from the simulator, receipt order from a recording): the
//! navigation states are bit-identical to the live ones for the same samples.

use std::borrow::BorrowMut;
use std::time::{Duration, Instant};

use navsync_wire::samples::{AnySample, EventPose, NavState, NavStatus, SimTruth, TimeState};
use navsync_wire::time::NS_PER_S;

use crate::evaluation::{DelayTruth, Evaluator, Summary};
use crate::feed::Feed;
use crate::input_order::Input;
use crate::nav::error_state::{ATT, BA, BG, DELAY, POS, VEL};
use crate::nav::filter::{DelayDoubt, published_pos_std_ned_m};
use crate::nav::smoother::Smoothed;
use crate::pipeline::Pipeline;
use crate::settings::Settings;

/// What an offline run produced.
pub struct OfflineRun {
    /// The accuracy summary.
    pub summary: Summary,
    /// Which Δ the filter had to find (the receiver latency when the fixes were stamped on
    /// receipt).
    pub delay_truth: DelayTruth,
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
    /// The delayed filter's state at an instant it has fused past ([`Pipeline::drain_fused`]).
    Fused(&'a NavState),
    /// An event with its pose ([`crate::events`]).
    Event(&'a EventPose),
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

/// As [`estimate`], but every navigation state the delayed filter passed through is replaced
/// by its smoothed one ([`crate::nav::smoother`]: the best estimate of each instant, from the
/// data before and after it), and the accuracy is that of the smoothed states. The outputs come
/// after the whole run, in their order. States the filter never reached (before its alignment,
/// the last horizon of the data) are the real-time ones.
pub fn estimate_smoothed<T: Clone, S: Into<Input>, I: IntoIterator<Item = (S, T)>>(
    settings: &Settings,
    samples: I,
    time_states: bool,
    mut on_output: impl FnMut(Output<'_>, &T),
) -> OfflineRun {
    let cfg = settings.pipeline_config();
    let reference = cfg.reference_imu.clone();
    let mut pipeline = Pipeline::new(cfg);
    pipeline.enable_smoothing();
    let mut navs: Vec<(NavState, T)> = Vec::new();
    // Time states with the number of navigation states before them (their place in the order).
    let mut times: Vec<(usize, TimeState, T)> = Vec::new();
    let mut truths: Vec<SimTruth> = Vec::new();
    // Event poses (from the delayed filter's states, not the smoothed ones), after the states.
    let mut events: Vec<(EventPose, T)> = Vec::new();
    let samples = samples.into_iter().map(|(s, t)| {
        let s: Input = s.into();
        if let Input::Truth(x) = &s {
            truths.push(*x);
        }
        (s, t)
    });
    let (mut run, feed) = run_feed(
        Feed::with(pipeline, Some(&reference)),
        samples,
        settings.delay_truth(),
        time_states,
        |o, tag: &T| match o {
            Output::Nav(n) => navs.push((*n, tag.clone())),
            Output::Time(t) => times.push((navs.len(), *t, tag.clone())),
            Output::Event(e) => events.push((*e, tag.clone())),
            Output::Fused(_) => {}
        },
    );
    let smoothed = feed.pipeline().nav().smoother().map(|l| l.smooth()).unwrap_or_default();
    let mut j = 0;
    for (n, _) in &mut navs {
        while j < smoothed.len() && smoothed[j].state.t_ns < n.host_ns {
            j += 1;
        }
        if let Some(s) = smoothed.get(j).filter(|s| s.state.t_ns == n.host_ns)
            && n.status != NavStatus::Aligning as u8
        {
            apply_smoothed(n, s);
        }
    }
    // The accuracy of the smoothed states: the evaluator sees them and the truth in time order.
    let mut eval = Evaluator::default();
    let mut t = truths.iter().peekable();
    for (n, _) in &navs {
        while let Some(x) = t.next_if(|x| x.host_ns < n.host_ns) {
            eval.add_truth(x);
        }
        eval.add_nav(n);
    }
    t.for_each(|x| eval.add_truth(x));
    let f = &run.summary;
    let mut summary = eval.summary(
        (f.imu_samples, f.gnss_fixes, f.rejected_fixes),
        f.wall_s,
        f.estimator_s,
        run.delay_truth,
    );
    summary.measurement_counters = std::mem::take(&mut run.summary.measurement_counters);
    summary.nav_states = run.summary.nav_states;
    summary.usable_states = run.summary.usable_states;
    summary.problem = run.summary.problem.take();
    let mut ti = times.into_iter().peekable();
    for (i, (n, tag)) in navs.iter().enumerate() {
        while let Some((_, ts, tt)) = ti.next_if(|x| x.0 <= i) {
            on_output(Output::Time(&ts), &tt);
        }
        on_output(Output::Nav(n), tag);
    }
    for (_, ts, tt) in ti {
        on_output(Output::Time(&ts), &tt);
    }
    for (e, tag) in &events {
        on_output(Output::Event(e), tag);
    }
    OfflineRun {
        summary,
        delay_truth: run.delay_truth,
    }
}

/// Writes a smoothed state into a navigation state: position, velocity, attitude, their σ (times
/// the filter's [`crate::nav::filter::DelayedFilter::sigma_scale`] at that instant, the
/// position's at least its floor), the sensor errors and Δ.
fn apply_smoothed(n: &mut NavState, s: &Smoothed) {
    let p = &s.state.pva;
    n.lat_deg = p.lat_rad.to_degrees();
    n.lon_deg = p.lon_rad.to_degrees();
    n.height_m = p.h_m;
    n.vel_ned_mps = p.vel_ned_mps.into();
    n.rpy_rad = p.rpy_rad().into();
    let q = p.q_nb.quaternion();
    n.q_nb = [q.w, q.i, q.j, q.k];
    let std3 = |i: usize| [s.std[i], s.std[i + 1], s.std[i + 2]];
    let scaled = |i: usize| std3(i).map(|x| x * s.state.sigma_scale);
    let doubt = &s.state.delay_doubt;
    n.pos_std_ned_m = published_pos_std_ned_m(std3(POS), s.state.sigma_scale, &s.state.pos_floor_std_ned_m, doubt);
    n.vel_std_ned_mps = DelayDoubt::widen(scaled(VEL), &doubt.vel_m2ps2);
    n.att_std_rad = DelayDoubt::widen(scaled(ATT), &doubt.att_rad2);
    n.gyro_bias_rps = s.state.bias_g.into();
    n.accel_bias_mps2 = s.state.bias_a.into();
    n.gyro_bias_std_rps = std3(BG);
    n.accel_bias_std_mps2 = std3(BA);
    if n.gnss_delay_s.is_finite() {
        n.gnss_delay_s = s.state.delay_s;
        n.gnss_delay_std_s = s.state.delay_doubt.delay_std_s(s.std[DELAY]);
    }
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
        if all && feed.order().is_empty() {
            // The end of the stream: the events still waiting go out (posed where the fused
            // states reach them), with the last sample's tag.
            feed.pipeline_mut().flush_events();
        }
        feed.pipeline_mut()
            .drain_fused(&mut |s| on_output(Output::Fused(s), &step.tag));
        feed.pipeline_mut()
            .drain_event_poses(&mut |e| on_output(Output::Event(e), &step.tag));
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
    // Fixes stamped on receipt (software sync, asked for or fallen back to without PPS): the
    // Δ to find is the receiver latency, whatever the caller expected.
    let delay_truth = if pipeline.fixes_stamped_on_receipt() {
        DelayTruth::ReceiverLatency
    } else {
        delay_truth
    };
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
    (OfflineRun { summary, delay_truth }, feed)
}
