//! The navigator's one measurement queue: every aiding source is a [`Measurement`] with its own
//! epoch, model, noise, gate and counters, fused by the delayed filter when it reaches that
//! epoch on the fusion horizon (so a measurement that arrives late — a GNSS fix 0.1–1.2 s after
//! its epoch — is still fused where it belongs, and the output is never held back).
//!
//! Adding a kind of measurement: one file with a type implementing [`Measurement`] (its
//! settings, its state, how it is fused, and, for measurements the IMU data itself produces,
//! [`Measurement::on_step`]), and one line in the `measurement_kinds!` registry below. The
//! queue, the settings ([`MeasurementConfig`]`::<kind>`), the state and the health counters of
//! every kind follow from that line.

use super::config::NavConfig;
use super::filter::DelayedFilter;
use super::imu_buffer::ImuRecord;

/// One kind of measurement.
pub trait Measurement: Copy + Into<Queued> {
    /// Settings of this kind (`MeasurementConfig::<kind>`).
    type Config: Copy + Default + PartialEq + std::fmt::Debug;
    /// What this kind keeps between measurements (detectors, counters).
    type State: Clone + Default + std::fmt::Debug;

    /// Host time (ns) of the instant it measures, given the GNSS delay estimate Δ̂ (s).
    fn epoch_ns(&self, delay_s: f64) -> i64;

    /// Fuses it into the filter, which stands `eps_s` (s, ≥ 0) after [`Self::epoch_ns`],
    /// counting what became of it in its `state`. Returns true when the state was corrected.
    fn fuse(
        &self,
        f: &mut DelayedFilter,
        eps_s: f64,
        cfg: &NavConfig,
        own: &Self::Config,
        state: &mut Self::State,
    ) -> bool;

    /// After each step of the delayed filter over IMU record `rec`: a measurement this kind
    /// makes from the IMU data at the filter's time, if any (default: none).
    fn on_step(
        _rec: &ImuRecord,
        _f: &DelayedFilter,
        _cfg: &NavConfig,
        _own: &Self::Config,
        _state: &mut Self::State,
    ) -> Option<Self> {
        None
    }

    /// The health counters of this kind, by name.
    fn counters(_state: &Self::State, _out: &mut dyn FnMut(&'static str, u64)) {}
}

/// Defines the registry: for each line `kind: Variant(kind::Type)`, the module `kind` (the
/// file `measurements/kind.rs`), the variant of the queued enum, and the fields of the
/// settings and the states.
macro_rules! measurement_kinds {
    ($($(#[$doc:meta])* $field:ident: $variant:ident($t:ty),)*) => {
        $(pub mod $field;)*

        /// A measurement of any kind, waiting in the queue for its epoch. Its size is the
        /// largest kind's (a receiver epoch's satellites, ~1.5 KiB): the queue's fixed slots
        /// hold them without allocating.
        #[derive(Debug, Clone, Copy, PartialEq)]
        #[allow(clippy::large_enum_variant)]
        pub enum Queued {
            $($(#[$doc])* $variant($t),)*
        }

        $(impl From<$t> for Queued {
            fn from(m: $t) -> Self {
                Self::$variant(m)
            }
        })*

        /// The settings of every kind of measurement.
        #[derive(Debug, Clone, Copy, Default, PartialEq)]
        pub struct MeasurementConfig {
            $($(#[$doc])* pub $field: <$t as Measurement>::Config,)*
        }

        /// The state of every kind of measurement.
        #[derive(Debug, Clone, Default)]
        pub struct MeasurementStates {
            $($(#[$doc])* pub $field: <$t as Measurement>::State,)*
            /// Measurements of each kind dropped because the queue was full.
            pub queue_full: QueueFull,
        }

        /// Measurements of each kind dropped because the queue was full.
        #[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
        pub struct QueueFull {
            $($(#[$doc])* pub $field: u64,)*
        }

        impl Queued {
            fn epoch_ns(&self, delay_s: f64) -> i64 {
                match self {
                    $(Self::$variant(m) => m.epoch_ns(delay_s),)*
                }
            }

            fn fuse(
                &self,
                f: &mut DelayedFilter,
                eps_s: f64,
                cfg: &NavConfig,
                kinds: &MeasurementConfig,
                states: &mut MeasurementStates,
            ) -> bool {
                match self {
                    $(Self::$variant(m) => m.fuse(f, eps_s, cfg, &kinds.$field, &mut states.$field),)*
                }
            }
        }

        impl MeasurementStates {
            /// Every kind's [`Measurement::on_step`] after a step of the delayed filter; what
            /// they measure goes into `queue`.
            pub(crate) fn on_step(
                &mut self,
                rec: &ImuRecord,
                f: &DelayedFilter,
                cfg: &NavConfig,
                kinds: &MeasurementConfig,
                queue: &mut MeasurementQueue,
            ) {
                $(if let Some(m) = <$t as Measurement>::on_step(rec, f, cfg, &kinds.$field, &mut self.$field) {
                    self.queue(queue, m.into());
                })*
            }

            /// Queues `m`; a full queue drops it, counted for its kind.
            pub(crate) fn queue(&mut self, queue: &mut MeasurementQueue, m: Queued) {
                let full = match &m {
                    $(Queued::$variant(_) => &mut self.queue_full.$field,)*
                };
                if !queue.push(m) {
                    *full += 1;
                }
            }

            /// The health counters of every kind, by name.
            pub fn each_counter(&self, out: &mut dyn FnMut(&'static str, u64)) {
                $(<$t as Measurement>::counters(&self.$field, out);)*
                $(out(concat!(stringify!($field), "_queue_full"), self.queue_full.$field);)*
            }
        }
    };
}

measurement_kinds! {
    /// GNSS fixes: antenna position and horizontal velocity ([`gnss`]).
    gnss: Gnss(gnss::GnssObservation),
    /// Zero velocity and zero angular rate while the vehicle stands still ([`zupt`]).
    zupt: Zupt(zupt::Zupt),
    /// Pseudoranges and Doppler of each satellite, tightly coupled ([`ranges`]).
    ranges: Ranges(crate::gnss::ranges::RangeEpoch),
}

/// Measurements waiting for the delayed filter to reach their epochs. Fixed capacity, no
/// allocation: 32 slots hold a 2 s horizon of 10 Hz fixes (or raw epochs) and the
/// standstill updates.
#[derive(Debug, Clone, Default)]
pub struct MeasurementQueue {
    slots: [Option<Queued>; 32],
}

impl MeasurementQueue {
    /// Queues `m`; false when the queue is full (`m` is dropped).
    pub fn push(&mut self, m: Queued) -> bool {
        match self.slots.iter_mut().find(|s| s.is_none()) {
            Some(slot) => {
                *slot = Some(m);
                true
            }
            None => false,
        }
    }

    /// Whether a queued measurement's epoch has been reached.
    pub fn has_due(&self, f: &DelayedFilter) -> bool {
        self.slots.iter().flatten().any(|m| m.epoch_ns(f.delay_s) <= f.t_ns)
    }

    /// Fuses, in epoch order, every queued measurement whose epoch the filter has reached.
    /// Returns true when the state was corrected.
    pub fn fuse_due(
        &mut self,
        f: &mut DelayedFilter,
        cfg: &NavConfig,
        kinds: &MeasurementConfig,
        states: &mut MeasurementStates,
    ) -> bool {
        let mut corrected = false;
        loop {
            // The epoch of a GNSS fix moves with Δ̂, which each fusion may change: look again.
            let due = self
                .slots
                .iter()
                .enumerate()
                .filter_map(|(i, m)| m.map(|m| (i, m.epoch_ns(f.delay_s))))
                .filter(|(_, t)| *t <= f.t_ns)
                .min_by_key(|(_, t)| *t);
            let Some((i, t)) = due else { break };
            let Some(m) = self.slots[i].take() else { break };
            f.propagate_covariance(cfg);
            let eps_s = (f.t_ns - t) as f64 * 1e-9;
            corrected |= m.fuse(f, eps_s, cfg, kinds, states);
        }
        corrected
    }
}
