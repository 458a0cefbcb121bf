//! The whole estimator as one synchronous state machine: time synchronisation plus the
//! navigation filter, fed sample by sample. The `navsync estimator` process and
//! `navsync replay --estimate` both drive exactly this type, so a replay reproduces the live
//! results bit for bit when fed the same samples in the same order.
//!
//! Time stamps of the fixes. Under hardware sync (PPS locked or in holdover) a fix is stamped
//! with the host time of its epoch through the clock model; otherwise (software sync, or no
//! PPS) with the receipt time of its first byte, and the navigation filter's Δ state absorbs
//! the receiver latency. When the stamping switches, Δ is re-initialised to the new mode's prior.

use navsync_wire::reflect::Reflect;
use navsync_wire::samples::{
    EventPose, GnssEvent, GnssFix, GnssNavData, GnssRaw, GnssTimePulse, IMU_FLAG_RECEIVER_CLOCK, ImuSample, NavState,
    NetworkTime, PpsEdge, TimeState, TimeStatus,
};

use crate::events::{EventCounters, EventPoses};
use crate::gnss::ranges::{EphemerisStore, RangeBuildCounts, RangeEpoch};
use crate::gnss::spp::{self, SppSettings};
use crate::input_order::Input;
use crate::nav::measurements::MeasurementConfig;
use crate::nav::measurements::ranges::RangingConfig;

use crate::array::imu_array::{ArrayConfig, ImuArray};
use crate::nav::config::Coupling;
use crate::nav::measurements::gnss::{self, GnssAccuracy};
use crate::nav::navigator::{NavConfig, Navigator};
use crate::time::device_timing::{DeviceTiming, DeviceTimingConfig};
use crate::time::time_sync::{TimeSync, TimeSyncConfig};

/// Fused states kept for a caller that has not taken them ([`Pipeline::drain_fused`]), at most.
const MAX_UNDRAINED: usize = 256;

/// Prior of Δ under software sync and its 1-sigma, s: any receiver latency below the fusion
/// horizon.
const SOFTWARE_DELAY_PRIOR_S: (f64, f64) = (0.5, 0.5);
/// Under software sync, the most an IMU sample's receipt may lag its measurement, s: Δ (the
/// fixes' receipt lag less the IMU's) is at least minus this.
const SOFTWARE_IMU_LATENCY_MAX_S: f64 = 0.1;

/// Mechanization steps of the output catch-up after a correction done per `NavState`
/// ([`Pipeline::catch_up`]): a 1.5 s horizon at 1 kHz (1500 steps) reaches the output 8
/// samples after the correction, at ~0.1 ms per sample instead of ~0.6 ms on one.
pub const CATCH_UP_STEPS: usize = 200;

/// Settings of the whole estimator.
#[derive(Debug, Clone)]
pub struct PipelineConfig {
    /// Time synchronisation.
    pub time: TimeSyncConfig,
    /// Navigation filter.
    pub nav: NavConfig,
    /// Each kind of measurement's settings.
    pub measurements: MeasurementConfig,
    /// Default GNSS accuracy.
    pub gnss: GnssAccuracy,
    /// Id of the reference IMU: it defines the array's time grid and drives the output.
    pub reference_imu: String,
    /// The IMUs (one or an array); `array.reference` is set from `reference_imu`.
    pub array: ArrayConfig,
    /// Sample times from the IMUs' own clocks where they carry one.
    pub device_timing: DeviceTimingConfig,
}

/// What one input produced ([`Pipeline::on_input`]).
#[derive(Debug, Clone, Copy, Default)]
pub struct Outputs {
    /// The navigation state, for a sample of the reference IMU: publish it, then let the
    /// pipeline [catch up](Pipeline::catch_up).
    pub nav: Option<NavState>,
    /// The time mapping changed (a PPS edge or a fix): a new time state is due.
    pub time_changed: bool,
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
    /// Fixes that reached the estimator.
    pub fixes: u64,
    /// Fixes (and raw epochs) held back while the PPS clock was acquiring.
    pub fixes_waiting_for_time: u64,
    /// Receiver fixes not fused because navsync's own solution of the raw epochs stands in
    /// for them ([`Coupling::LooseSpp`]).
    pub fixes_unused: u64,
    /// Raw measurement epochs (UBX RXM-RAWX) that reached the estimator.
    pub raw_epochs: u64,
    /// Raw epochs not used: loosely coupled, or before alignment without a single-point
    /// solution (fewer than four satellites with ephemerides).
    pub raw_unused: u64,
    /// Raw epochs without a usable receiver time (time of week outside the week or NaN,
    /// week 0).
    pub raw_invalid: u64,
    /// Navigation-data messages (UBX RXM-SFRBX) that reached the estimator.
    pub nav_data: u64,
    /// IMU samples rejected by the array (non-finite values or interval, time going backwards,
    /// saturated: [`ArrayCounters`](crate::array::imu_array::ArrayCounters) says which). A rejected
    /// sample yields no `NavState`; the next accepted one bridges its interval.
    pub imu_invalid: u64,
}

/// The estimator.
#[derive(Debug, Clone)]
pub struct Pipeline {
    cfg: PipelineConfig,
    time: TimeSync,
    nav: Navigator,
    array: ImuArray,
    stamping: Option<FixStamping>,
    /// The last GNSS time label given to a state, ns (labels never go back).
    last_utc_ns: i64,
    device_timing: DeviceTiming,
    counters: PipelineCounters,
    nav_seq: u64,
    /// A `NavState` was produced and the output catch-up step after it is not done yet.
    catch_up_due: bool,
    /// Broadcast ephemerides for tightly coupled fusion.
    ephemerides: EphemerisStore,
    /// What the raw epochs left out, by reason.
    range_counts: RangeBuildCounts,
    /// The delayed filter's states, labelled, since the caller last took them
    /// ([`Pipeline::drain_fused`]).
    fused: Vec<NavState>,
    /// Host time and GNSS label of the last fused state given out, ns.
    last_fused: (i64, i64),
    /// Fused states left out because a number in them was not finite.
    fused_not_finite: u64,
    /// The events waiting for their pose, and the poses made.
    events: EventPoses,
}

impl Pipeline {
    /// A fresh estimator.
    pub fn new(cfg: PipelineConfig) -> Self {
        let time = TimeSync::new(cfg.time);
        let mut nav = Navigator::with_measurements(cfg.nav, cfg.measurements);
        nav.keep_fused();
        let mut array_cfg = cfg.array.clone();
        array_cfg.reference = array_cfg
            .units
            .iter()
            .position(|u| u.id == cfg.reference_imu)
            .unwrap_or(0);
        let array = ImuArray::new(array_cfg);
        let device_timing = DeviceTiming::new(cfg.device_timing);
        Self {
            cfg,
            time,
            nav,
            array,
            stamping: None,
            last_utc_ns: i64::MIN,
            device_timing,
            counters: PipelineCounters::default(),
            nav_seq: 0,
            catch_up_due: false,
            ephemerides: EphemerisStore::default(),
            range_counts: RangeBuildCounts::default(),
            fused: Vec::with_capacity(MAX_UNDRAINED + crate::nav::navigator::MAX_FUSED_BATCH),
            last_fused: (i64::MIN, i64::MIN),
            fused_not_finite: 0,
            events: EventPoses::default(),
        }
    }

    /// The IMUs' device clocks.
    pub fn device_timing(&self) -> &DeviceTiming {
        &self.device_timing
    }

    /// Keeps what the offline smoother needs ([`crate::nav::smoother`]); offline only: its log
    /// grows with the run.
    pub fn enable_smoothing(&mut self) {
        self.nav.enable_smoothing();
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

    /// The work deferred after a `NavState`: the IMU array fuses the instants now complete
    /// and the delayed filter consumes them (fusing the fixes they reach), then one step of
    /// bringing the latest correction forward to the output ([`CATCH_UP_STEPS`] mechanization
    /// steps). So a `NavState` waits only for its own sample's output step. A live
    /// process calls it right after publishing the `NavState`, so the sample's latency does
    /// not include it; every `on_*` call first does it when it is still due, so the results
    /// are the same whoever calls it (replays stay bit-identical).
    pub fn catch_up(&mut self) {
        if std::mem::take(&mut self.catch_up_due) {
            let nav = &mut self.nav;
            self.array
                .emit(&mut |v| nav.on_filter_imu(v.host_ns, v.dt_s, v.gyro_rps, v.accel_mps2));
            self.nav.catch_up(CATCH_UP_STEPS);
            self.take_fused();
        }
    }

    /// Labels the delayed filter's new states with their GNSS time (as [`Self::nav_state`]
    /// labels the present's), keeps the finite ones in time order for the caller and poses
    /// the events they reach.
    fn take_fused(&mut self) {
        let mut fused = std::mem::take(&mut self.fused);
        if fused.len() >= MAX_UNDRAINED {
            // A caller that never takes them (a test driving the pipeline directly): bounded.
            fused.clear();
        }
        let (d, _) = self.nav.gnss_delay();
        let hardware = self.time.status().is_clock_mapped();
        let time_status = self.time.status() as u8;
        let mut last = self.last_fused;
        let mut not_finite = 0;
        let (time, axis, events) = (&self.time, self.cfg.time.time_axis, &mut self.events);
        self.nav.drain_fused(&mut |s| {
            let finite = [s.lat_deg, s.lon_deg, s.height_m]
                .iter()
                .chain(&s.vel_ned_mps)
                .chain(&s.q_nb)
                .chain(&s.pos_std_ned_m)
                .chain(&s.vel_std_ned_mps)
                .chain(&s.att_std_rad)
                .all(|x| x.is_finite());
            if !finite {
                not_finite += 1;
                return;
            }
            if s.host_ns <= last.0 {
                return;
            }
            let mut s = *s;
            let at_host = match axis {
                Some(axis) => Some(axis.utc_ns_at(s.host_ns)),
                None => time.utc_ns_at_host(s.host_ns),
            };
            s.utc_ns = match at_host {
                Some(u) if hardware && d.is_finite() => u + (d * 1e9).round() as i64,
                Some(u) => u,
                None => i64::MIN,
            };
            // Labels never go back (as the present's).
            if s.utc_ns != i64::MIN {
                let next = last.1.saturating_add(1);
                if s.utc_ns < next && next - s.utc_ns < 1_000_000_000 {
                    s.utc_ns = next;
                }
                last.1 = s.utc_ns;
            }
            last.0 = s.host_ns;
            s.time_status = time_status;
            events.on_fused(&s);
            fused.push(s);
        });
        self.last_fused = last;
        self.fused_not_finite += not_finite;
        self.fused = fused;
    }

    /// Hands each of the delayed filter's states made since the last call to `f`, oldest
    /// first, labelled with its GNSS time: the state of an instant once every measurement up
    /// to it is fused (what the history of states keeps as [`Source::Fused`](navsync_wire::interpolation::Source)).
    pub fn drain_fused(&mut self, f: &mut dyn FnMut(&NavState)) {
        for s in &self.fused {
            f(s);
        }
        self.fused.clear();
    }

    /// Hands each event pose made since the last call to `f` ([`crate::events`]).
    pub fn drain_event_poses(&mut self, f: &mut dyn FnMut(&EventPose)) {
        self.events.drain(f);
    }

    /// Gives every event still waiting out (at the end of a stream): posed where the fused
    /// states reach it, else without a pose.
    pub fn flush_events(&mut self) {
        self.catch_up();
        self.events.flush();
    }

    /// The events' counters.
    pub fn event_counters(&self) -> EventCounters {
        self.events.counters()
    }

    /// Fused states left out because a number in them was not finite.
    pub fn fused_not_finite(&self) -> u64 {
        self.fused_not_finite
    }

    /// Takes a receiver's event report (TIM-TM2) from device `device_id`: each edge gets its
    /// pose once the delayed filter has fused past it ([`Self::drain_event_poses`]).
    pub fn on_event(&mut self, e: &GnssEvent, device_id: [u8; 8]) {
        self.catch_up();
        self.events.on_event(e, device_id);
    }

    /// Feeds one input of any kind: the one dispatch of every input to the `on_*` of its kind,
    /// for the live process and the offline runs alike ([`crate::feed`]). The simulator's
    /// truth and other samples produce nothing.
    pub fn on_input(&mut self, input: &Input) -> Outputs {
        let mut out = Outputs::default();
        match input {
            Input::Imu(x) => out.nav = self.on_imu(x),
            Input::PpsEdge(e) => out.time_changed = self.on_pps(e),
            Input::GnssFix(f) => out.time_changed = self.on_fix(f),
            Input::TimePulse(t) => self.on_time_pulse(t),
            Input::Raw(r) => out.time_changed = self.on_raw(r),
            Input::NavData(d) => self.on_nav_data(d),
            Input::NetworkTime(t) => out.time_changed = self.on_network_time(t),
            Input::Event(e, id) => self.on_event(e, *id),
            Input::Truth(_) | Input::Other(_) => {}
        }
        out
    }

    /// Feeds a PPS edge; true when the time mapping changed.
    pub fn on_pps(&mut self, edge: &PpsEdge) -> bool {
        self.catch_up();
        self.time.on_pps(edge)
    }

    /// Feeds a reading of the network time service (a host without a receiver); true when the
    /// time mapping changed.
    pub fn on_network_time(&mut self, t: &NetworkTime) -> bool {
        self.catch_up();
        let changed = self.time.on_network_time(t);
        self.time.tick(t.host_ns);
        changed
    }

    /// Feeds a receiver's report of its next time pulse (UBX TIM-TP): labels the next edge.
    pub fn on_time_pulse(&mut self, tp: &GnssTimePulse) {
        self.catch_up();
        self.time.on_time_pulse(tp);
    }

    /// Feeds a GNSS fix; true when the time mapping changed.
    pub fn on_fix(&mut self, fix: &GnssFix) -> bool {
        self.catch_up();
        self.counters.fixes += 1;
        let changed = self.time.on_fix(fix);
        self.time.tick(fix.stamp.host_ns);
        let Some(stamp) = self.epoch_stamp(fix.utc_ns, fix.stamp.host_ns) else {
            return changed;
        };
        if self.cfg.nav.initial_state.is_some() && !self.nav.is_aligned() {
            // With a known initial state the filter does not align itself: fixes before its
            // instant are not used.
            return changed;
        }
        if self.cfg.nav.coupling == Coupling::LooseSpp {
            // navsync's own solution of the raw epochs stands in for the receiver's.
            self.counters.fixes_unused += 1;
            return changed;
        }
        if let Some(obs) = gnss::observation(fix, stamp, &self.cfg.gnss) {
            self.nav.on_gnss(obs, fix.stamp.host_ns);
        }
        changed
    }

    /// The host time stamp of a GNSS epoch at `utc_ns` received at `receipt_ns` (see the
    /// module docs), re-initialising Δ when the stamping changes; `None` while the PPS clock
    /// is acquiring or when the epoch's time is unknown.
    fn epoch_stamp(&mut self, utc_ns: i64, receipt_ns: i64) -> Option<i64> {
        let stamping = match self.time.status() {
            st if st.is_clock_mapped() && !self.cfg.time.software_sync => FixStamping::Epoch,
            TimeStatus::Software => FixStamping::Receipt,
            _ if self.cfg.time.software_sync => FixStamping::Receipt,
            _ => {
                self.counters.fixes_waiting_for_time += 1;
                return None;
            }
        };
        if self.stamping != Some(stamping) {
            // Under hardware sync Δ is the IMU-to-GNSS offset left after the PPS mapping.
            let (prior, std) = match stamping {
                FixStamping::Epoch => (0.0, self.cfg.nav.delay_prior_std_s),
                FixStamping::Receipt => SOFTWARE_DELAY_PRIOR_S,
            };
            self.nav.reset_delay(prior, std);
            self.nav.set_delay_floor(match stamping {
                FixStamping::Epoch => f64::NEG_INFINITY,
                // A fix is received after its epoch; the IMU samples' own receipt latency
                // (tens of ms at most) is the only way Δ may fall below zero.
                FixStamping::Receipt => -SOFTWARE_IMU_LATENCY_MAX_S,
            });
            self.stamping = Some(stamping);
        }
        match stamping {
            FixStamping::Epoch if utc_ns != i64::MIN => self.time.host_ns_at_utc(utc_ns),
            FixStamping::Epoch => None,
            FixStamping::Receipt => Some(receipt_ns),
        }
    }

    /// Feeds one navigation-data message (UBX RXM-SFRBX): the broadcast ephemerides and
    /// ionosphere of tightly coupled fusion.
    pub fn on_nav_data(&mut self, d: &GnssNavData) {
        self.catch_up();
        self.counters.nav_data += 1;
        self.ephemerides.on_nav_data(d);
    }

    /// Feeds a receiver's raw measurements of one epoch (UBX RXM-RAWX). Tightly coupled, each
    /// satellite with an ephemeris is fused at the epoch; before alignment, a single-point
    /// solution from them aligns the filter as a fix would. With [`Coupling::LooseSpp`] that
    /// solution is fused as a fix at every epoch. Loosely coupled they are counted and not used.
    /// True when the time mapping changed (from a receiver that sends no fixes, its raw epochs
    /// label the PPS edges: [`TimeSync::on_raw_epoch`]).
    pub fn on_raw(&mut self, raw: &GnssRaw) -> bool {
        self.catch_up();
        self.counters.raw_epochs += 1;
        if !self.cfg.nav.coupling.uses_raw() {
            self.counters.raw_unused += 1;
            return false;
        }
        if !(0.0..navsync_wire::time::SECONDS_PER_WEEK as f64).contains(&raw.rcv_tow_s) || raw.week == 0 {
            // No receiver time (NaN, out of the week, or the week unknown).
            self.time.tick(raw.stamp.host_ns);
            self.counters.raw_invalid += 1;
            return false;
        }
        let gps_ns = (i64::from(raw.week) * navsync_wire::time::SECONDS_PER_WEEK) * 1_000_000_000
            + (raw.rcv_tow_s * 1e9).round() as i64;
        let utc_ns = navsync_wire::time::utc_ns_from_gps_ns(gps_ns);
        // A receiver that sends no fixes: its raw epochs label the PPS edges.
        let changed = self.time.on_raw_epoch(raw.stamp.host_ns, utc_ns);
        self.time.tick(raw.stamp.host_ns);
        let Some(stamp) = self.epoch_stamp(utc_ns, raw.stamp.host_ns) else {
            return changed;
        };
        // The receiver's time runs c·δt_r ahead of GPS time: the epoch is that much earlier
        // (under software sync Δ absorbs it with the receiver's latency).
        let bias_m = self.nav.receiver_clock(stamp).map_or(0.0, |c| c.bias_m);
        let stamp = if self.stamping == Some(FixStamping::Epoch) {
            stamp - (bias_m / spp::C_M_S * 1e9).round() as i64
        } else {
            stamp
        };
        let mut epoch = self.ephemerides.range_epoch(raw, stamp, bias_m, &mut self.range_counts);
        let solution = single_point_observation(&epoch, &self.cfg.measurements.ranges);
        if self.nav.is_aligned() && self.nav.is_tight() {
            if let Some((obs, clock_std_m)) = &solution {
                epoch.pos_floor_std_ned_m = obs.pos_floor_std_m.into();
                epoch.clock_floor_std_m = *clock_std_m;
            }
            self.nav.on_ranges(epoch, raw.stamp.host_ns);
        } else if (self.cfg.nav.initial_state.is_none() || self.nav.is_aligned())
            && let Some((obs, _)) = solution
        {
            self.nav.on_gnss(obs, raw.stamp.host_ns);
        } else {
            self.counters.raw_unused += 1;
        }
        changed
    }

    /// The ephemeris store, to give it orbits from elsewhere than the receiver's navigation
    /// data (another receiver, a file, a simulation).
    pub fn ephemerides_mut(&mut self) -> &mut EphemerisStore {
        &mut self.ephemerides
    }

    /// The counters of the raw-measurement path by name (tightly coupled): epochs in, invalid
    /// and unused; navigation data in, subframes failing parity, ephemerides completed; what
    /// the epochs left out, by reason; and the IMU samples on the receiver's clock, timed by
    /// it or not.
    pub fn each_raw_counter(&self, out: &mut dyn FnMut(&'static str, u64)) {
        let (c, r, e) = (&self.counters, &self.range_counts, &self.ephemerides);
        let d = self.device_timing.counters();
        out("rx_clock_imu", d.receiver_clock);
        out("rx_clock_imu_waiting", d.receiver_clock_waiting);
        out("rx_clock_imu_outliers", d.receiver_clock_outliers);
        out("raw_epochs", c.raw_epochs);
        out("raw_invalid", c.raw_invalid);
        out("raw_unused", c.raw_unused);
        out("fixes_unused", c.fixes_unused);
        out("nav_data", c.nav_data);
        out("nav_data_bad", e.bad_subframes);
        out("ephemerides", e.ephemerides);
        out("raw_other_signals", r.other_signals);
        out("raw_invalid_ranges", r.invalid);
        out("raw_no_ephemeris", r.no_ephemeris);
        out("raw_over_capacity", r.over_capacity);
    }

    /// Feeds an IMU sample of any IMU of the array; returns the navigation state for it when it
    /// is the reference IMU. Its time: its device clock mapped to host time where it carries
    /// one, or, for an IMU on the GNSS receiver's clock once the tightly coupled filter has
    /// the clock, that clock (see [`DeviceTiming`]). A sample of the reference IMU advances
    /// the present-time output at once; the array's fusion into the virtual IMU that drives
    /// the delayed filter follows in [`catch_up`](Self::catch_up), after the `NavState`.
    pub fn on_imu(&mut self, s: &ImuSample) -> Option<NavState> {
        self.catch_up();
        let id = navsync_wire::reflect::str_of(&s.imu_id);
        let Some(index) = self.array.index_of(id) else {
            self.counters.imu_other += 1;
            return None;
        };
        let mut retimed = self.device_timing.retime(index, s);
        if s.flags & IMU_FLAG_RECEIVER_CLOCK != 0 {
            // One crystal: the receiver clock's reading less its bias is GPS time (hardware
            // time mapping only: under software sync the mapping is the fixes' receipt).
            let hardware = !self.cfg.time.software_sync && self.time.status().is_clock_mapped();
            let bias = self
                .nav
                .receiver_clock(s.stamp.host_ns)
                .filter(|_| hardware)
                .map(|c| (c.bias_m / spp::C_M_S * 1e9, c.bias_std_m / spp::C_M_S * 1e9));
            let time = &self.time;
            if let Some(r) = self
                .device_timing
                .retime_on_receiver_clock(s, bias, |utc| time.host_ns_at_utc(utc))
            {
                retimed = r;
            }
        }
        let s = &retimed;
        let reference = self.array.reference();
        let accepted = self.array.accept(index, s);
        if !accepted {
            self.counters.imu_invalid += 1;
            return None;
        }
        if self.array.reference() != reference {
            self.on_handover();
        }
        self.counters.imu_used += 1;
        if index != self.array.reference() {
            return None;
        }
        self.time.tick(s.stamp.host_ns);
        let (host_ns, g, a) = self.array.output_sample(index, s);
        if let Some(init) = &self.cfg.nav.initial_state
            && !self.nav.is_aligned()
            && self.utc_ns_at_host(host_ns).is_some_and(|u| u >= init.utc_ns)
            && let Some(h0) = self.host_ns_at_utc(init.utc_ns)
        {
            self.nav.initialize(init, h0);
        }
        self.nav.on_output_imu(host_ns, s.dt_s, g, a);
        self.catch_up_due = true;
        Some(self.nav_state(host_ns))
    }

    /// The array moved its reference to another IMU (the old one went stale): the navigation
    /// point is now that IMU's position, so the GNSS lever arm (antenna − IMU, body frame) moves
    /// by the difference of the two positions. The position state itself is not shifted: the
    /// few centimetres are taken up by the next GNSS updates.
    fn on_handover(&mut self) {
        let configured = self.array.index_of(&self.cfg.reference_imu).unwrap_or(0);
        let moved_b_m = self.array.lever_b_m(self.array.reference()) - self.array.lever_b_m(configured);
        self.nav
            .set_lever_arm(nalgebra::Vector3::from(self.cfg.nav.gnss_lever_arm_m) - moved_b_m);
    }

    /// Id of the IMU whose samples currently drive the output, as stored in samples (the
    /// configured reference until it goes stale; see [`ImuArray`]'s handover).
    pub fn reference_imu_id(&self) -> [u8; 8] {
        self.array.reference_id()
    }

    /// The IMU array.
    pub fn array(&self) -> &ImuArray {
        &self.array
    }

    /// What the estimator has seen, for [`OutputCheck::problem`](crate::output_check::OutputCheck::problem).
    pub fn inputs_seen(&self) -> crate::output_check::InputsSeen {
        crate::output_check::InputsSeen {
            fixes: self.counters.fixes,
            fixes_used: self.nav.counters().fixes_used,
            fixes_unlabelled: self.counters.fixes_waiting_for_time,
            pps_used: self.time.counters().pps_used,
            initial_state: self.cfg.nav.initial_state.is_some(),
            align_min_speed_mps: self.cfg.nav.align.align_min_speed_mps,
            heading_banks: self.nav.counters().heading_banks,
            integrity_resets: self.nav.integrity().resets,
            fixes_too_old: self.nav.counters().fixes_too_old,
            fusion_horizon_s: self.cfg.nav.fusion_horizon_s,
            tight: self.nav.is_tight(),
            raw_epochs: self.counters.raw_epochs,
            ranges_used: self.nav.measurement_states().ranges.ranges_used,
            raw_no_ephemeris: self.range_counts.no_ephemeris,
        }
    }

    /// Whether the fixes are stamped on receipt (software sync): Δ is then the receiver's
    /// latency rather than a residual offset.
    pub fn fixes_stamped_on_receipt(&self) -> bool {
        self.stamping == Some(FixStamping::Receipt)
    }

    /// The UTC time of host time `host_ns`: on the input's declared time axis, else from the
    /// clock model (`None` while it is not known).
    fn utc_ns_at_host(&self, host_ns: i64) -> Option<i64> {
        match self.cfg.time.time_axis {
            Some(axis) => Some(axis.utc_ns_at(host_ns)),
            None => self.time.utc_ns_at_host(host_ns),
        }
    }

    /// The host time of UTC time `utc_ns` (the inverse of [`Self::utc_ns_at_host`]).
    fn host_ns_at_utc(&self, utc_ns: i64) -> Option<i64> {
        match self.cfg.time.time_axis {
            Some(axis) => Some(axis.host_ns_at(utc_ns)),
            None => self.time.host_ns_at_utc(utc_ns),
        }
    }

    /// The navigation state for host time `now_ns` (the latest IMU sample's).
    pub fn nav_state(&mut self, now_ns: i64) -> NavState {
        let mut s = NavState::zeroed();
        self.nav.fill(&mut s, now_ns);
        self.nav_seq += 1;
        s.seq = self.nav_seq;
        // The state's GNSS time: the IMU sample's host time mapped to GNSS time, on the GNSS
        // side of the estimated delay Δ̂ (under hardware sync Δ̂ is the IMU-to-GNSS offset left
        // after the PPS mapping; under software sync the mapping goes through the fixes'
        // receipt minus Δ̂ already).
        let (d, d_std) = self.nav.gnss_delay();
        self.time.set_gnss_delay(d, d_std);
        let hardware = self.time.status().is_clock_mapped();
        // The sample's time: on the input's exact time axis when it declares one, else from the
        // clock model. With the fixes' epochs known in GNSS time (PPS, or an import's epoch
        // tags) a Δ is the IMU stamps' own offset from GNSS time, and the label is corrected by
        // it; with fixes stamped on receipt Δ is the receiver's latency and the label stays.
        let at_host = match self.cfg.time.time_axis {
            Some(axis) => Some(axis.utc_ns_at(now_ns)),
            None => self.time.utc_ns_at_host(now_ns),
        };
        s.utc_ns = match at_host {
            Some(u) if hardware && d.is_finite() => u + (d * 1e9).round() as i64,
            Some(u) => u,
            None => i64::MIN,
        };
        // A later state never gets an earlier label: while Δ's estimate falls faster than the
        // IMU steps, the labels follow 1 ns apart (within Δ's σ of their times). A step back of
        // a second or more is a new time line (a reset of the mapping) and is kept.
        if s.utc_ns != i64::MIN {
            let next = self.last_utc_ns.saturating_add(1);
            if s.utc_ns < next && next - s.utc_ns < 1_000_000_000 {
                s.utc_ns = next;
            }
            self.last_utc_ns = s.utc_ns;
        }
        s.time_status = self.time.status() as u8;
        (s.imu, s.imu_count) = self.array.table();
        s
    }

    /// The time state at host time `now_ns`, with the filter's Δ estimate and, tightly
    /// coupled, the receiver's clock.
    pub fn time_state(&mut self, now_ns: i64) -> TimeState {
        let (d, ds) = self.nav.gnss_delay();
        self.time.set_gnss_delay(d, ds);
        let mut t = self.time.time_state(now_ns);
        (t.imu, t.imu_count) = self.array.table();
        if let Some(c) = self.nav.receiver_clock(now_ns) {
            t.rx_clock_bias_ns = c.bias_m / spp::C_M_S * 1e9;
            t.rx_clock_bias_std_ns = c.bias_std_m / spp::C_M_S * 1e9;
            t.rx_clock_drift = c.drift_mps / spp::C_M_S;
            t.rx_clock_drift_std = c.drift_std_mps / spp::C_M_S;
            t.rx_clock_last_fused_host_ns = c.last_fused_ns;
        }
        t
    }
}

/// A fix from a raw epoch's single-point solution (position, clock, then Doppler velocity),
/// for the alignment of a tightly coupled filter: its σ from the least-squares covariance
/// rotated into NED, one receiver clock per system; and the σ of its (first system's) clock, m. `None` with fewer than 3 + the systems' count
/// of satellites or without convergence.
fn single_point_observation(e: &RangeEpoch, rc: &RangingConfig) -> Option<(gnss::GnssObservation, f64)> {
    let (pr_std_m, rate_std_mps) = (rc.pseudorange_std_m, rc.range_rate_std_mps);
    let settings = SppSettings {
        elevation_mask_rad: rc.elevation_mask_rad,
        ..SppSettings::default()
    };
    let mut obs = [spp::SystemObservation {
        obs: spp::Observation {
            sv: 0,
            pseudorange_m: 0.0,
            sat_ecef_m: [0.0; 3],
            sat_clock_s: 0.0,
            sigma_zenith_m: pr_std_m,
        },
        gnss_id: 0,
        iono_scale: 1.0,
        noise_gain: 1.0,
    }; crate::gnss::ranges::MAX_RANGE_SATS];
    let mut rates = [spp::RangeRate {
        sv: 0,
        range_rate_mps: 0.0,
        sat_ecef_m: [0.0; 3],
        sat_vel_mps: [0.0; 3],
        sat_clock_drift: 0.0,
        sigma_mps: rate_std_mps,
    }; crate::gnss::ranges::MAX_RANGE_SATS];
    let (mut n, mut m) = (0, 0);
    for s in e.sats() {
        // The satellite clock is already in the measurements (`SatRange`).
        (obs[n].gnss_id, obs[n].iono_scale) = (s.gnss_id, s.iono_scale);
        let o = &mut obs[n].obs;
        o.sv = s.sv;
        o.pseudorange_m = s.pseudorange_m;
        o.sat_ecef_m = s.sat_ecef_m;
        o.sigma_zenith_m = pr_std_m.max(s.pseudorange_std_m);
        n += 1;
        if s.range_rate_mps.is_finite() {
            rates[m].sv = s.sv;
            rates[m].range_rate_mps = s.range_rate_mps;
            rates[m].sat_ecef_m = s.sat_ecef_m;
            rates[m].sat_vel_mps = s.sat_vel_mps;
            rates[m].sigma_mps = rate_std_mps.max(s.range_rate_std_mps);
            m += 1;
        }
    }
    let sol = spp::solve(&obs[..n], e.iono.as_ref(), e.tow_s, [0.0; 3], &settings).ok()?;
    let vel = spp::solve_velocity(&rates[..m], sol.ecef_m, &settings).ok();
    let g = navsync_wire::earth::geodetic_from_ecef(sol.ecef_m[0], sol.ecef_m[1], sol.ecef_m[2])?;
    let (lat, lon) = (g.lat_deg.to_radians(), g.lon_deg.to_radians());
    let c_en = spp::ned_from_ecef(lat, lon);
    let ned_std = |cov: &nalgebra::Matrix4<f64>| {
        let c = c_en * cov.fixed_view::<3, 3>(0, 0) * c_en.transpose();
        nalgebra::Vector3::new(c[(0, 0)].sqrt(), c[(1, 1)].sqrt(), c[(2, 2)].sqrt())
    };
    let (vel_ned, vel_std) = match vel {
        Some(v) => {
            let ned = c_en * nalgebra::Vector3::from(v.vel_ecef_mps);
            let sd = ned_std(&v.cov);
            (ned, (sd.x * sd.x + sd.y * sd.y).sqrt() / std::f64::consts::SQRT_2)
        }
        None => (nalgebra::Vector3::repeat(f64::NAN), f64::NAN),
    };
    let obs = gnss::GnssObservation {
        stamp_host_ns: e.stamp_host_ns,
        lat_rad: lat,
        lon_rad: lon,
        h_m: g.height_m,
        vel_ned_mps: vel_ned,
        pos_std_m: ned_std(&sol.cov),
        vel_std_mps: vel_std,
        speed_mps: vel_ned.x.hypot(vel_ned.y),
        pos_floor_std_m: ned_std(&sol.cov),
        track_rad: vel_ned.y.atan2(vel_ned.x).rem_euclid(2.0 * std::f64::consts::PI),
    };
    Some((obs, sol.cov[(3, 3)].max(0.0).sqrt()))
}
