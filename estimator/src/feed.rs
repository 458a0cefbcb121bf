//! The one input path: samples go into the canonical order ([`InputOrder`]), come out as the
//! order releases them, and go through [`Pipeline::on_input`]; the caller publishes what comes
//! back (the live `navsync estimator`) or writes and evaluates it (the offline runs,
//! [`crate::offline`]), then hands the step back with [`Feed::finish`], which counts the state
//! ([`OutputCheck`]), lets the pipeline catch up and follows a handover of the reference IMU.
//! The live shell and the offline runs share this type, so a replay consumes the same samples
//! in the same order as the live process did and gives the same states bit for bit.

use std::borrow::BorrowMut;

use navsync_wire::samples::NavState;

use crate::input_order::{Input, InputOrder};
use crate::output_check::OutputCheck;
use crate::pipeline::{Pipeline, PipelineConfig};

/// One input released by the order and fed to the pipeline, with what it produced.
#[derive(Debug)]
#[must_use = "hand the step back with Feed::finish after publishing its state"]
pub struct Step<T> {
    /// The input.
    pub input: Input,
    /// Its tag (e.g. its recording time).
    pub tag: T,
    /// The navigation state, for a sample of the reference IMU (the caller may mark it before
    /// publishing; [`Feed::finish`] counts it as published).
    pub nav: Option<NavState>,
    /// The time mapping changed: a new time state is due.
    pub time_changed: bool,
}

/// The reference IMU went stale and another one drives the output now.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Handover {
    /// The IMU id that drove the output.
    pub from: [u8; 8],
    /// The IMU id that drives it now.
    pub to: [u8; 8],
}

/// The pipeline (owned, or borrowed: `P = &mut Pipeline`) behind its input order.
pub struct Feed<T = (), P: BorrowMut<Pipeline> = Pipeline> {
    pipeline: P,
    order: InputOrder<T>,
    check: OutputCheck,
}

impl<T> Feed<T> {
    /// A pipeline built from `cfg`, its inputs released by its reference IMU.
    pub fn new(cfg: PipelineConfig) -> Self {
        let reference = cfg.reference_imu.clone();
        Self::with(Pipeline::new(cfg), Some(&reference))
    }
}

impl<T, P: BorrowMut<Pipeline>> Feed<T, P> {
    /// `pipeline` behind an order released by IMU `reference_imu` (`None`: any IMU).
    pub fn with(pipeline: P, reference_imu: Option<&str>) -> Self {
        Self {
            pipeline,
            order: InputOrder::new(reference_imu),
            check: OutputCheck::default(),
        }
    }

    /// Queues a sample with its tag.
    pub fn push(&mut self, sample: impl Into<Input>, tag: T) {
        self.order.push(sample, tag);
    }

    /// The next input the order releases (with `all`, any waiting one: at the end of a
    /// recording, or when the reference IMU is silent), fed to the pipeline.
    pub fn next(&mut self, all: bool) -> Option<Step<T>> {
        let (input, tag) = if all { self.order.pop_any() } else { self.order.pop() }?;
        let out = self.pipeline.borrow_mut().on_input(&input);
        Some(Step {
            input,
            tag,
            nav: out.nav,
            time_changed: out.time_changed,
        })
    }

    /// After the caller has published `step`'s state: counts it, lets the pipeline catch up
    /// (the work deferred past the output, [`Pipeline::catch_up`]) and, after an IMU sample,
    /// tells the order the IMU that drives the output now. Returns the handover when the
    /// reference moved.
    pub fn finish(&mut self, step: &Step<T>) -> Option<Handover> {
        if let Some(n) = &step.nav {
            let moving = self.pipeline.borrow().nav().motion_seen();
            self.check.add(n, moving);
            self.pipeline.borrow_mut().catch_up();
        }
        if !matches!(step.input, Input::Imu(_)) {
            return None;
        }
        let to = self.pipeline.borrow().reference_imu_id();
        self.order.set_reference(to).map(|from| Handover { from, to })
    }

    /// The pipeline.
    pub fn pipeline(&self) -> &Pipeline {
        self.pipeline.borrow()
    }

    /// The pipeline, to compute time states and to give it ephemerides from elsewhere.
    pub fn pipeline_mut(&mut self) -> &mut Pipeline {
        self.pipeline.borrow_mut()
    }

    /// The input order (its counters; whether it stalled).
    pub fn order(&mut self) -> &mut InputOrder<T> {
        &mut self.order
    }

    /// The states produced and how many were usable.
    pub fn check(&self) -> &OutputCheck {
        &self.check
    }

    /// Why the output is not usable, if it is not (see [`OutputCheck::problem`]).
    pub fn problem(&self) -> Option<String> {
        self.check.problem(&self.pipeline.borrow().inputs_seen())
    }
}
