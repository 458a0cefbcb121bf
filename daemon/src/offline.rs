//! Runs the estimator over a stream of recorded or simulated samples as fast as the CPU allows,
//! in delivery order, and evaluates it against the truth in the stream.

use std::time::{Duration, Instant};

use navsync_shared::samples::{AnySample, NavState};

use crate::estimator::pipeline::Pipeline;
use crate::evaluation::{DelayTruth, Evaluator, Summary};

/// What an offline run produced.
pub struct OfflineRun {
    /// The accuracy summary.
    pub summary: Summary,
}

/// Feeds `samples` (in delivery order) to `pipeline`; every navigation state goes to `on_nav`.
pub fn run<I: IntoIterator<Item = AnySample>>(
    pipeline: &mut Pipeline,
    samples: I,
    delay_truth: DelayTruth,
    mut on_nav: impl FnMut(&NavState),
) -> OfflineRun {
    let t0 = Instant::now();
    let mut eval = Evaluator::default();
    let (mut imu, mut fixes) = (0u64, 0u64);
    // Time spent inside the estimator only (not producing or decoding the samples).
    let mut in_estimator = Duration::ZERO;
    for s in samples {
        match &s {
            AnySample::Imu(x) => {
                imu += 1;
                let t = Instant::now();
                let out = pipeline.on_imu(x);
                in_estimator += t.elapsed();
                if let Some(n) = out {
                    eval.add_nav(&n);
                    on_nav(&n);
                }
            }
            AnySample::GnssFix(f) => {
                fixes += 1;
                let t = Instant::now();
                pipeline.on_fix(f);
                in_estimator += t.elapsed();
            }
            AnySample::PpsEdge(e) => {
                let t = Instant::now();
                pipeline.on_pps(e);
                in_estimator += t.elapsed();
            }
            AnySample::Truth(t) => eval.add_truth(t),
            AnySample::Time(_) | AnySample::Nav(_) | AnySample::Health(_) => {}
        }
    }
    let wall = t0.elapsed().as_secs_f64();
    let rejected = pipeline.nav().counters().fixes_rejected;
    OfflineRun { summary: eval.summary((imu, fixes, rejected), wall, in_estimator.as_secs_f64(), delay_truth) }
}
