//! The filter's integrity monitor: never confidently wrong.
//!
//! After the delayed filter has stepped and fused what was due, [`check`] looks at it as an
//! outsider would, against what the configured IMU model and the filter's own statistics make
//! possible, and names the first fault it finds ([`Fault`]):
//!
//! - a state or covariance entry that is not finite, or a covariance that is not symmetric
//!   positive definite (its Cholesky factor fails): the filter's arithmetic broke down;
//! - a sensor error outside what the IMU model allows: a gyro or accelerometer bias beyond
//!   [`IntegrityConfig::bias_sigmas`] times its turn-on σ (widened by its instability), a scale
//!   factor beyond [`IntegrityConfig::max_scale`]: the filter explains its innovations with
//!   sensor errors no such IMU has;
//! - innovations inconsistent with the covariance: the running NIS per component of the GNSS
//!   updates above [`IntegrityConfig::max_nis_average`] (a consistent filter keeps it near 1;
//!   the bound is the 99.9 % χ² quantile of the average over its window).
//!
//! The navigator acts on the fault ([`super::navigator::Navigator`]): a breakdown resets the
//! filter and it aligns again (its outputs say "aligning", not a number); sensor errors beyond
//! the configured model but within an IMU of unknown class widen the model (once: the
//! estimates kept, their σ reopened), beyond that they are cleared and re-learnt from their
//! turn-on σ (the states flagged as recovering either way); an
//! inconsistency inflates the covariance so the σ it publishes covers the error, widens an IMU
//! model the data contradict, and flags the states ([`INTEGRITY_INCONSISTENT`]) until the
//! innovations agree again. Every fault is counted by kind.

use super::config::IntegrityConfig;
use super::error_state::{BA, BG, N, ProcessNoise, SA, SG, StateMat};
use super::filter::DelayedFilter;

pub use navsync_wire::samples::{INTEGRITY_HEADING_UNKNOWN, INTEGRITY_INCONSISTENT, INTEGRITY_RECOVERING};

/// What is wrong with the filter.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fault {
    /// A state or covariance entry is NaN or infinite.
    NonFinite,
    /// The covariance is not symmetric positive definite.
    NotPositiveDefinite,
    /// A sensor-error estimate outside what the IMU model allows.
    Implausible,
    /// The innovations are far larger than the covariance predicts.
    Inconsistent,
}

/// Counts of the faults found, by kind.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct IntegrityCounters {
    /// Non-finite states or covariances.
    pub non_finite: u64,
    /// Covariances not positive definite.
    pub not_positive_definite: u64,
    /// Implausible sensor-error estimates.
    pub implausible: u64,
    /// Inconsistency episodes (the covariance was inflated).
    pub inconsistent: u64,
    /// Resets of the filter (it aligned again).
    pub resets: u64,
    /// Resets of the GNSS delay Δ to its prior: its estimate left what is physical (a fix
    /// received before its epoch) or reached the filter's bound ([`super::navigator::Navigator`]).
    pub delay_resets: u64,
}

impl IntegrityCounters {
    /// Counts `fault`.
    pub fn count(&mut self, fault: Fault) {
        match fault {
            Fault::NonFinite => self.non_finite += 1,
            Fault::NotPositiveDefinite => self.not_positive_definite += 1,
            Fault::Implausible => self.implausible += 1,
            Fault::Inconsistent => self.inconsistent += 1,
        }
    }

    /// Every counter by its health-report name.
    pub fn each(&self, out: &mut dyn FnMut(&'static str, u64)) {
        out("integrity_non_finite", self.non_finite);
        out("integrity_not_pd", self.not_positive_definite);
        out("integrity_implausible", self.implausible);
        out("integrity_inconsistent", self.inconsistent);
        out("integrity_resets", self.resets);
        out("integrity_delay_resets", self.delay_resets);
    }
}

/// Whether every entry of the state and its covariance is finite.
fn finite(f: &DelayedFilter) -> bool {
    let p = &f.pva;
    let q = p.q_nb.quaternion();
    [p.lat_rad, p.lon_rad, p.h_m, q.w, q.i, q.j, q.k, f.delay_s]
        .iter()
        .chain(p.vel_ned_mps.iter())
        .chain(f.bias_g.iter())
        .chain(f.bias_a.iter())
        .chain(f.scale_g.iter())
        .chain(f.scale_a.iter())
        .all(|x| x.is_finite())
        && all_finite(f.eskf.p.as_slice())
}

/// Whether every entry is finite (its exponent bits not all set), with no early exit: the
/// check runs after every IMU interval, and the loop over the covariance's N² entries
/// vectorises.
fn all_finite(xs: &[f64]) -> bool {
    const EXPONENT: u64 = 0x7ff0_0000_0000_0000;
    !xs.iter()
        .fold(false, |bad, x| bad | (x.to_bits() & EXPONENT == EXPONENT))
}

/// Whether `a` and `b` hold the same bits (the memo's key: the same matrix gives the same
/// answer), with no early exit, so the comparison vectorises.
fn same_bits(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u64, |d, (x, y)| d | (x.to_bits() ^ y.to_bits())) == 0
}

/// Whether `p` is symmetric (to rounding) and positive definite on the states that are live
/// (a frozen state's row and column are zero).
fn positive_definite(p: &StateMat) -> bool {
    let mut m = *p;
    for i in 0..N {
        if p[(i, i)] == 0.0 {
            // A frozen state (no scale factors, loosely coupled clock): unit variance for the test.
            if (0..N).any(|j| p[(i, j)] != 0.0) {
                return false;
            }
            m[(i, i)] = 1.0;
        }
    }
    let scale = p.diagonal().abs().max().max(1e-300);
    (0..N).all(|i| (0..i).all(|j| (m[(i, j)] - m[(j, i)]).abs() <= 1e-9 * scale)) && m.cholesky().is_some()
}

/// Whether the sensor-error estimates are within what the model allows.
pub fn plausible(f: &DelayedFilter, noise: &ProcessNoise, cfg: &IntegrityConfig) -> bool {
    let k = cfg.bias_sigmas;
    let bound = |init: f64, instab: f64, floor: f64| k * init.hypot(instab).max(floor);
    (0..3).all(|i| {
        f.bias_g[i].abs() <= bound(noise.gyro_bias_init_std[i], noise.gyro_bias_std[i], 1e-4)
            && f.bias_a[i].abs() <= bound(noise.accel_bias_init_std[i], noise.accel_bias_std[i], 1e-2)
            && f.scale_g[i].abs() <= cfg.max_scale
            && f.scale_a[i].abs() <= cfg.max_scale
    })
}

/// The first fault of the filter `f`, if any, given the IMU model `noise` and the running NIS
/// per component of its GNSS updates (`nis_average`, 1 when consistent).
pub fn check(
    f: &DelayedFilter,
    noise: &ProcessNoise,
    nis_average: f64,
    cfg: &IntegrityConfig,
    memo: &mut PdMemo,
) -> Option<Fault> {
    if !finite(f) {
        return Some(Fault::NonFinite);
    }
    if !memo.positive_definite(&f.eskf.p) {
        return Some(Fault::NotPositiveDefinite);
    }
    if !plausible(f, noise, cfg) {
        return Some(Fault::Implausible);
    }
    if nis_average > cfg.max_nis_average {
        return Some(Fault::Inconsistent);
    }
    None
}

/// The last covariance found positive definite: the check runs after every IMU interval, but
/// the covariance changes only when it is propagated (every `cov_step_s`) or updated, and the
/// same matrix needs no new factorisation (a comparison instead of a Cholesky factorisation
/// of N × N; the answer is the same).
#[derive(Debug, Clone, Default)]
pub struct PdMemo(Option<Box<StateMat>>);

impl PdMemo {
    /// Whether `p` is positive definite ([`positive_definite`]), remembered for the same `p`.
    pub fn positive_definite(&mut self, p: &StateMat) -> bool {
        if self.0.as_deref().is_some_and(|m| same_bits(m.as_slice(), p.as_slice())) {
            return true;
        }
        let ok = positive_definite(p);
        if ok {
            match &mut self.0 {
                Some(b) => **b = *p,
                None => self.0 = Some(Box::new(*p)),
            }
        }
        ok
    }
}

/// The bias and scale-factor states' indices (a reset of the sensor errors clears them).
pub const SENSOR_ERROR_STATES: [usize; 4] = [BG, BA, SG, SA];

#[cfg(test)]
mod tests {
    use nalgebra::Vector3;

    use super::*;
    use crate::nav::eskf::Eskf;
    use crate::nav::mechanization::Pva;
    use navsync_wire::imu_spec::ImuPreset;

    fn filter() -> DelayedFilter {
        let pva = Pva {
            lat_rad: 0.8,
            lon_rad: 0.2,
            h_m: 100.0,
            vel_ned_mps: Vector3::new(1.0, 0.0, 0.0),
            q_nb: nalgebra::UnitQuaternion::identity(),
        };
        let mut p = StateMat::identity() * 1e-4;
        p[(SG, SG)] = 0.0;
        DelayedFilter::new(pva, 0, Eskf::new(p), Vector3::zeros(), 0.0)
    }

    #[test]
    fn each_kind_of_fault_is_named() {
        let noise = ProcessNoise::from_imu_noise(&ImuPreset::Consumer.noise());
        let cfg = IntegrityConfig::default();
        assert_eq!(check(&filter(), &noise, 1.0, &cfg, &mut PdMemo::default()), None);
        let mut f = filter();
        f.pva.vel_ned_mps.y = f64::NAN;
        assert_eq!(
            check(&f, &noise, 1.0, &cfg, &mut PdMemo::default()),
            Some(Fault::NonFinite)
        );
        let mut f = filter();
        f.eskf.p[(3, 3)] = -1.0;
        assert_eq!(
            check(&f, &noise, 1.0, &cfg, &mut PdMemo::default()),
            Some(Fault::NotPositiveDefinite)
        );
        let mut f = filter();
        f.bias_g.z = 1.0; // 57 °/s
        assert_eq!(
            check(&f, &noise, 1.0, &cfg, &mut PdMemo::default()),
            Some(Fault::Implausible)
        );
        assert_eq!(
            check(&filter(), &noise, 50.0, &cfg, &mut PdMemo::default()),
            Some(Fault::Inconsistent)
        );
    }
}
