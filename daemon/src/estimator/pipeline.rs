//! The whole estimator as one synchronous state machine: time synchronisation plus the
//! navigation filter, fed sample by sample. The `navsync estimator` process and
//! `navsync replay --estimate` both drive exactly this type, so a replay reproduces the live
//! results bit for bit when fed the same samples in the same order.
//!
//! Time stamps of the fixes. Under hardware sync (PPS locked or in holdover) a fix is stamped
//! with the host time of its epoch through the clock model; otherwise (software sync, or no
//! PPS) with the receipt time of its first byte, and the navigation filter's Δ state absorbs
//! the receiver latency. When the stamping switches, Δ is re-initialised to the new mode's prior.

use nalgebra::Vector3;
use navsync_shared::reflect::Reflect;
use navsync_shared::samples::{GnssFix, ImuSample, NavState, PpsEdge, TimeState, TimeStatus};

use super::gnss_fusion::{self, GnssAccuracy};
use super::navigator::{NavConfig, Navigator};
use super::time_sync::{TimeSync, TimeSyncConfig};

/// Settings of the whole estimator.
#[derive(Debug, Clone)]
pub struct PipelineConfig {
    /// Time synchronisation.
    pub time: TimeSyncConfig,
    /// Navigation filter.
    pub nav: NavConfig,
    /// Default GNSS accuracy.
    pub gnss: GnssAccuracy,
    /// Id of the IMU that drives the filter.
    pub reference_imu: String,
    /// Prior of Δ under software sync, s, and its 1-sigma.
    pub software_delay_prior: (f64, f64),
    /// Prior of Δ under hardware sync, s, and its 1-sigma.
    pub hardware_delay_prior: (f64, f64),
}

/// How fix stamps are currently obtained.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FixStamping {
    /// Epoch mapped to host time through the PPS clock model.
    Epoch,
    /// Receipt time of the first byte.
    Receipt,
}

/// Counters of the pipeline itself.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PipelineCounters {
    /// IMU samples of the reference IMU fed to the filter.
    pub imu_used: u64,
    /// IMU samples of other IMUs (not fused yet).
    pub imu_other: u64,
    /// Fixes held back while the PPS clock was acquiring.
    pub fixes_waiting_for_time: u64,
    /// IMU samples with non-finite values (rejected).
    pub imu_invalid: u64,
}

/// The estimator.
#[derive(Debug, Clone)]
pub struct Pipeline {
    cfg: PipelineConfig,
    time: TimeSync,
    nav: Navigator,
    stamping: Option<FixStamping>,
    counters: PipelineCounters,
    nav_seq: u64,
}

impl Pipeline {
    /// A fresh estimator.
    pub fn new(cfg: PipelineConfig) -> Self {
        let time = TimeSync::new(cfg.time);
        let nav = Navigator::new(cfg.nav);
        Self {
            cfg,
            time,
            nav,
            stamping: None,
            counters: PipelineCounters::default(),
            nav_seq: 0,
        }
    }

    /// The time synchroniser.
    pub fn time(&self) -> &TimeSync {
        &self.time
    }

    /// The navigation filter.
    pub fn nav(&self) -> &Navigator {
        &self.nav
    }

    /// Pipeline counters.
    pub fn counters(&self) -> &PipelineCounters {
        &self.counters
    }

    /// Feeds a PPS edge; true when the time mapping changed.
    pub fn on_pps(&mut self, edge: &PpsEdge) -> bool {
        self.time.on_pps(edge)
    }

    /// Feeds a GNSS fix; true when the time mapping changed.
    pub fn on_fix(&mut self, fix: &GnssFix) -> bool {
        let changed = self.time.on_fix(fix);
        self.time.tick(fix.stamp.host_ns);
        let stamping = match self.time.status() {
            TimeStatus::Locked | TimeStatus::Holdover if !self.cfg.time.software_sync => FixStamping::Epoch,
            TimeStatus::Software => FixStamping::Receipt,
            _ if self.cfg.time.software_sync => FixStamping::Receipt,
            _ => {
                self.counters.fixes_waiting_for_time += 1;
                return changed;
            }
        };
        if self.stamping != Some(stamping) {
            let (prior, std) = match stamping {
                FixStamping::Epoch => self.cfg.hardware_delay_prior,
                FixStamping::Receipt => self.cfg.software_delay_prior,
            };
            self.nav.reset_delay(prior, std);
            self.stamping = Some(stamping);
        }
        let stamp = match stamping {
            FixStamping::Epoch => match self.time.host_ns_at_utc(fix.utc_ns) {
                Some(h) if fix.utc_ns != i64::MIN => h,
                _ => return changed,
            },
            FixStamping::Receipt => fix.stamp.host_ns,
        };
        if let Some(obs) = gnss_fusion::observation(fix, stamp, &self.cfg.gnss) {
            self.nav.on_gnss(obs, fix.stamp.host_ns);
        }
        changed
    }

    /// Feeds an IMU sample; returns the navigation state for it when it is the reference IMU.
    pub fn on_imu(&mut self, s: &ImuSample) -> Option<NavState> {
        if navsync_shared::reflect::str_of(&s.imu_id) != self.cfg.reference_imu {
            self.counters.imu_other += 1;
            return None;
        }
        let g = Vector3::from(s.gyro_rps);
        let a = Vector3::from(s.accel_mps2);
        if !(g.iter().chain(a.iter()).all(|v| v.is_finite()) && s.dt_s > 0.0 && s.dt_s < 1.0) {
            self.counters.imu_invalid += 1;
            return None;
        }
        self.counters.imu_used += 1;
        self.time.tick(s.stamp.host_ns);
        self.nav.on_imu(s.stamp.host_ns, s.dt_s, g, a);
        Some(self.nav_state(s.stamp.host_ns))
    }

    /// The navigation state for host time `now_ns` (the latest IMU sample's).
    pub fn nav_state(&mut self, now_ns: i64) -> NavState {
        let mut s = NavState::zeroed();
        self.nav.fill(&mut s, now_ns);
        self.nav_seq += 1;
        s.seq = self.nav_seq;
        s.utc_ns = self.time.utc_ns_at_host(now_ns).unwrap_or(i64::MIN);
        s.time_status = self.time.status() as u8;
        s
    }

    /// The time state at host time `now_ns`, with the filter's Δ estimate.
    pub fn time_state(&mut self, now_ns: i64) -> TimeState {
        let (d, ds) = self.nav.gnss_delay();
        self.time.set_gnss_delay(d, ds);
        self.time.time_state(now_ns)
    }
}
