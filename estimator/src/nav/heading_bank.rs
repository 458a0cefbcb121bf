//! Alignment of the heading at any speed: a bank of hypotheses finds it, one filter refines it.
//!
//! Once the levelling is done (or a fix shows motion, ≥ `align_min_speed_mps`), the heading is
//! not taken to be the course over ground: a person carries the IMU at any angle to the
//! walking direction, a robot may drive backwards, and at walking speed the course itself is
//! noisy. Instead [`HYPOTHESES`] delayed filters start from the same position, velocity,
//! roll and pitch with headings spaced evenly around the circle (the first one on the course,
//! when moving), each with a heading σ that covers its sector. Every fix is fused into each of
//! them without a gate, and each accumulates the log-likelihood of its innovations: the
//! weights of a Gaussian-sum filter (Alspach & Sorenson 1972; the multiple-hypothesis heading
//! alignment of Groves 2013 §14.4.4). Hypotheses whose weight falls below [`PRUNE_WEIGHT`] of
//! the best are dropped. The heading is decided when the hypotheses that agree with the best
//! one (their headings within [`AGREE_SIGMAS`] of its σ) hold [`DECIDE_WEIGHT`] of the weight,
//! after at least [`MIN_FIXES`] fixes, and the heading is known to [`MAX_DECIDED_STD_RAD`]: by
//! the best filter's σ and by the weights themselves. For consistent components a hypothesis δ
//! from the best is less likely by ½(δ/σ)² in log-likelihood once the data know the heading to
//! σ; one only `dll` less likely says they know it no better than δ/√(−2·dll), whatever σ the
//! linearised filters claim (far from the truth they all shrink alike: hypotheses 30° apart were
//! seen within a few log-units of each other while each claimed 1°: 99 % of the weight is no
//! decision there). A live hypothesis 30° away implies at least 30°/√(−2 ln PRUNE_WEIGHT) =
//! 5.7°: in effect the heading is decided once every hypothesis outside the agreeing ones has
//! been dropped. While the heading is not observable (no horizontal acceleration: standing, or
//! moving straight at constant speed) the weights stay even and nothing is decided: no heading
//! is claimed that the data do not show.
//!
//! A hypothesis that started tens of degrees off is linearised far from the truth: its states
//! carry what that cost, and a filter with little process noise never forgets it. So the bank
//! only finds the heading: once it decides, one filter starts again from the bank's start with
//! the winner's initial heading refined by every correction the winner received
//! ([`BankStep::Decided`]), a heading σ of [`REFINED_STD_FACTOR`] times the winner's (at least
//! [`MIN_REFINED_STD_RAD`]), and runs over the same data ([`HeadingBank::log`]): the fine
//! alignment. The data the bank keeps are bounded ([`MAX_LOGGED_RECORDS`]); a bank that would
//! exceed them starts again.

use nalgebra::{UnitQuaternion, Vector3};
use navsync_wire::earth;

use super::config::NavConfig;
use super::error_state::{ATT, BG, DELAY, POS};
use super::filter::DelayedFilter;
use super::imu_buffer::ImuRecord;
use super::measurements::Measurement;
use super::measurements::gnss::{GnssObservation, fuse_weighed};
use super::mechanization::skew;

/// Headings tried, evenly spaced (30° apart).
pub const HYPOTHESES: usize = 12;
/// A hypothesis whose weight falls below this share of the best one's is dropped.
pub const PRUNE_WEIGHT: f64 = 1e-6;
/// The heading is decided when the hypotheses agreeing with the best hold this share.
pub const DECIDE_WEIGHT: f64 = 0.99;
/// Fixes fused into the bank before a decision.
pub const MIN_FIXES: u32 = 5;
/// Hypotheses whose headings lie within this many σ of the best one's agree with it.
pub const AGREE_SIGMAS: f64 = 3.0;
/// The heading is decided only once the best hypothesis knows it to this 1-sigma, rad (5°):
/// the single filter of the fine alignment starts with at most twice that, where its
/// linearisation holds.
pub const MAX_DECIDED_STD_RAD: f64 = 0.087_266_462_599_716_48;
/// The refined initial heading's σ is this factor times the winner's σ at the decision (its
/// σ there is the linearised one of a filter that started far off: doubled).
pub const REFINED_STD_FACTOR: f64 = 2.0;
/// The refined initial heading's σ is at least this, rad (1°).
pub const MIN_REFINED_STD_RAD: f64 = 0.017_453_292_519_943_295;
/// IMU records the bank keeps for the fine alignment (10 min at 100 Hz); a longer bank starts
/// again.
pub const MAX_LOGGED_RECORDS: usize = 60_000;
/// Fixes the bank keeps for the fine alignment.
pub const MAX_LOGGED_FIXES: usize = 8_192;
/// Fixes waiting for the bank to reach their epochs: the default 2 s horizon and the input
/// order's 0.2 s hold of a 20 Hz receiver (more are dropped, the oldest first).
const PENDING: usize = 48;

/// One heading hypothesis.
#[derive(Debug, Clone)]
struct Hypothesis {
    filt: DelayedFilter,
    /// Its heading at the bank's start, rad.
    yaw0: f64,
    /// The heading corrections its updates applied, rad.
    yaw_shift: f64,
    /// Sum of the log-likelihoods of its innovations.
    log_lik: f64,
    alive: bool,
}

/// What a step of the bank came to.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BankStep {
    /// Still undecided.
    Pending,
    /// Decided: the heading at the bank's start (rad) and its σ (rad) for the fine alignment.
    Decided {
        /// The refined initial heading, rad.
        yaw0: f64,
        /// Its 1-sigma, rad.
        yaw_std: f64,
    },
    /// Every hypothesis failed (diverged), or the bank outgrew its log: the alignment starts
    /// again.
    Failed,
}

/// The bank of heading hypotheses (module docs).
#[derive(Debug, Clone)]
pub struct HeadingBank {
    /// The filter the alignment gave (its heading on the course, or 0 when standing).
    base: DelayedFilter,
    hyps: Vec<Hypothesis>,
    pending: [Option<GnssObservation>; PENDING],
    fixes: u32,
    /// The IMU records the bank stepped over, for the fine alignment.
    records: Vec<ImuRecord>,
    /// The fixes it fused, in order.
    fused: Vec<GnssObservation>,
}

/// `a` in (−π, π].
fn wrap(a: f64) -> f64 {
    let a = a.rem_euclid(2.0 * std::f64::consts::PI);
    if a > std::f64::consts::PI {
        a - 2.0 * std::f64::consts::PI
    } else {
        a
    }
}

/// `base` (its position the GNSS antenna's, as the alignment takes it from a fix) turned to
/// heading `yaw` with heading σ `yaw_std` (rad), its position moved to the navigation point,
/// `lever_b` (body FRD, m, antenna − navigation point) behind the antenna at that heading: a
/// lever arm of a metre is a metre of error against cm-level fixes otherwise, which the
/// hypotheses' weights would read as evidence about the heading. The position's covariance
/// takes what the attitude's uncertainty turns the lever arm by (δr = δr_antenna − [l^n×]·φ,
/// the measurement model of [`super::measurements::gnss::position_terms`] inverted). Also the
/// gyro bias of a static start re-referred to the heading (the earth rate seen in the body
/// frame turns with it), and the bias σ widened by what a heading off by σ leaves of the earth
/// rate in it.
pub fn with_heading(base: &DelayedFilter, yaw: f64, yaw_std: f64, lever_b: &Vector3<f64>) -> DelayedFilter {
    let mut filt = base.clone();
    let (roll, pitch, _) = base.pva.q_nb.euler_angles();
    let q = UnitQuaternion::from_euler_angles(roll, pitch, yaw);
    let w_ie_n = Vector3::from(earth::omega_ie_n(base.pva.lat_rad));
    filt.bias_g += base.pva.q_nb.inverse() * w_ie_n - q.inverse() * w_ie_n;
    filt.pva.q_nb = q;
    filt.eskf.p[(ATT + 2, ATT + 2)] = yaw_std * yaw_std;
    let w_h = w_ie_n.x.hypot(w_ie_n.y);
    for i in 0..3 {
        filt.eskf.p[(BG + i, BG + i)] += (w_h * yaw_std).powi(2);
    }
    let lever_n = q * lever_b;
    let (rm, rn) = earth::radii(filt.pva.lat_rad);
    let p = &mut filt.pva;
    p.lat_rad -= lever_n.x / (rm + p.h_m);
    p.lon_rad -= lever_n.y / ((rn + p.h_m) * p.lat_rad.cos());
    p.h_m += lever_n.z;
    let s = skew(&lever_n);
    let p_att = filt.eskf.p.fixed_view::<3, 3>(ATT, ATT).into_owned();
    let p_pos_att = -s * p_att;
    let pos_add = s * p_att * s.transpose();
    let cov = &mut filt.eskf.p;
    let pos_pos = cov.fixed_view::<3, 3>(POS, POS) + pos_add;
    cov.fixed_view_mut::<3, 3>(POS, POS).copy_from(&pos_pos);
    cov.fixed_view_mut::<3, 3>(POS, ATT).copy_from(&p_pos_att);
    cov.fixed_view_mut::<3, 3>(ATT, POS).copy_from(&p_pos_att.transpose());
    filt
}

impl HeadingBank {
    /// The hypotheses made from `base` (the filter the alignment gives): its heading turned by
    /// k·360°/[`HYPOTHESES`], with a heading σ covering the sector between two hypotheses.
    pub fn new(base: &DelayedFilter, lever_b: &Vector3<f64>) -> Self {
        let sector = 2.0 * std::f64::consts::PI / HYPOTHESES as f64;
        // Half the sector is 1.7σ: neighbouring hypotheses overlap.
        let yaw_std = 0.6 * sector;
        let course = base.pva.q_nb.euler_angles().2;
        let hyps = (0..HYPOTHESES)
            .map(|k| {
                let yaw0 = course + k as f64 * sector;
                Hypothesis {
                    filt: with_heading(base, yaw0, yaw_std, lever_b),
                    yaw0,
                    yaw_shift: 0.0,
                    log_lik: 0.0,
                    alive: true,
                }
            })
            .collect();
        Self {
            base: base.clone(),
            hyps,
            pending: [None; PENDING],
            fixes: 0,
            records: Vec::with_capacity(4096),
            fused: Vec::with_capacity(256),
        }
    }

    /// Queues a fix; the oldest waiting one is dropped when the queue is full.
    pub fn queue(&mut self, obs: GnssObservation) {
        let slot = match self.pending.iter().position(Option::is_none) {
            Some(i) => i,
            None => (0..PENDING)
                .min_by_key(|&i| self.pending[i].map_or(i64::MIN, |o| o.stamp_host_ns))
                .unwrap_or(0),
        };
        self.pending[slot] = Some(obs);
    }

    /// Sets the GNSS delay of every hypothesis (and of the fine alignment's start) to
    /// `delay_s` ± `std_s`, uncorrelated (the motion onset's first estimate of it).
    pub fn reset_delay(&mut self, delay_s: f64, std_s: f64) {
        for f in self.hyps.iter_mut().map(|h| &mut h.filt).chain([&mut self.base]) {
            f.delay_s = delay_s;
            f.eskf.reopen(DELAY, std_s * std_s);
        }
    }

    /// The GNSS delay Δ and its 1-sigma of each live hypothesis, s.
    pub fn delays(&self) -> impl Iterator<Item = (f64, f64)> + '_ {
        self.hyps
            .iter()
            .filter(|h| h.alive)
            .map(|h| (h.filt.delay_s, h.filt.eskf.std(DELAY)))
    }

    /// Live hypotheses.
    pub fn alive(&self) -> usize {
        self.hyps.iter().filter(|h| h.alive).count()
    }

    /// Steps every live hypothesis over IMU record `r`, then fuses each fix whose epoch they
    /// reached, and decides when the weights allow.
    pub fn step(&mut self, r: &ImuRecord, cfg: &NavConfig) -> BankStep {
        if r.host_ns <= self.base.t_ns {
            return BankStep::Pending;
        }
        if self.records.len() >= MAX_LOGGED_RECORDS || self.fused.len() >= MAX_LOGGED_FIXES {
            return BankStep::Failed;
        }
        self.records.push(*r);
        let mut t = i64::MIN;
        let mut delay = 0.0;
        for h in self.hyps.iter_mut().filter(|h| h.alive) {
            h.filt.step(r, cfg);
            (t, delay) = (h.filt.t_ns, h.filt.delay_s);
        }
        if t == i64::MIN {
            return BankStep::Failed;
        }
        let mut decided = BankStep::Pending;
        while let Some(i) = (0..PENDING)
            .filter(|&i| self.pending[i].is_some_and(|o| o.epoch_ns(delay) <= t))
            .min_by_key(|&i| self.pending[i].map_or(i64::MAX, |o| o.stamp_host_ns))
        {
            let Some(obs) = self.pending[i].take() else { break };
            for h in self.hyps.iter_mut().filter(|h| h.alive) {
                h.filt.propagate_covariance(cfg);
                let eps = ((h.filt.t_ns - obs.epoch_ns(h.filt.delay_s)) as f64 * 1e-9).max(0.0);
                match fuse_weighed(&obs, &mut h.filt, eps, cfg) {
                    Some((ll, dyaw)) => {
                        h.log_lik += ll;
                        h.yaw_shift += dyaw;
                    }
                    None => h.alive = false,
                }
            }
            self.fused.push(obs);
            self.fixes += 1;
            decided = self.decide();
            if decided != BankStep::Pending {
                break;
            }
        }
        decided
    }

    /// Prunes the unlikely hypotheses and decides when the agreeing ones hold the weight.
    fn decide(&mut self) -> BankStep {
        let Some(best) = (0..self.hyps.len())
            .filter(|&i| self.hyps[i].alive && self.hyps[i].log_lik.is_finite())
            .max_by(|&a, &b| self.hyps[a].log_lik.total_cmp(&self.hyps[b].log_lik))
        else {
            return BankStep::Failed;
        };
        let top = self.hyps[best].log_lik;
        let yaw_best = self.hyps[best].filt.pva.q_nb.euler_angles().2;
        for h in &mut self.hyps {
            // NaN compares false: such a hypothesis is dropped too.
            let keep = h.log_lik - top >= PRUNE_WEIGHT.ln();
            h.alive &= keep;
        }
        let b = &self.hyps[best];
        let yaw_std = b.filt.eskf.std(ATT + 2);
        let reach = AGREE_SIGMAS * yaw_std;
        let (mut agree, mut all) = (0.0, 0.0);
        // The heading σ the weights themselves imply: for consistent components a hypothesis
        // δ from the best is less likely by ½(δ/σ)² in log-likelihood, so one that is only
        // `dll` less likely says the data know the heading no better than δ/√(−2·dll),
        // whatever σ the linearised filters claim (they all shrink alike, wrong ones too).
        let mut implied_std: f64 = 0.0;
        for h in self.hyps.iter().filter(|h| h.alive) {
            let w = (h.log_lik - top).exp();
            all += w;
            let delta = wrap(h.filt.pva.q_nb.euler_angles().2 - yaw_best).abs();
            if delta <= reach {
                agree += w;
            } else {
                let dll = (h.log_lik - top).min(0.0);
                implied_std = implied_std.max(if dll < 0.0 {
                    delta / (-2.0 * dll).sqrt()
                } else {
                    f64::INFINITY
                });
            }
        }
        let yaw_std = yaw_std.max(implied_std);
        if self.fixes >= MIN_FIXES && agree >= DECIDE_WEIGHT * all && yaw_std <= MAX_DECIDED_STD_RAD {
            return BankStep::Decided {
                yaw0: wrap(b.yaw0 + b.yaw_shift),
                yaw_std: (REFINED_STD_FACTOR * yaw_std).max(MIN_REFINED_STD_RAD),
            };
        }
        BankStep::Pending
    }

    /// The filter the alignment gave, at the bank's start.
    pub fn base(&self) -> &DelayedFilter {
        &self.base
    }

    /// The IMU records and fixes the bank went through, in order, and the fixes still waiting
    /// (their epochs not reached): what the fine alignment runs over.
    pub fn log(
        &mut self,
    ) -> (
        &[ImuRecord],
        &[GnssObservation],
        impl Iterator<Item = GnssObservation> + '_,
    ) {
        (
            &self.records,
            &self.fused,
            self.pending.iter_mut().filter_map(Option::take),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wrap_is_the_shortest_angle() {
        assert!((wrap(3.5) - (3.5 - 2.0 * std::f64::consts::PI)).abs() < 1e-12);
        assert!((wrap(-0.1) + 0.1).abs() < 1e-12);
    }
}
