//! Host ↔ GNSS time synchronisation: labels PPS edges with their GNSS second, drives the
//! [`ClockModel`], measures the receiver latency d0 and decides the [`TimeStatus`].
//!
//! Labelling. A receiver emits its PPS edge at the start of GNSS second T and the message that
//! describes an epoch some d0 later (0.1–0.9 s typically). Before the clock is locked, an edge
//! at host time e is labelled by the first fix received within one second after it, whatever
//! its epoch grid (whole seconds, 10 Hz, 4 Hz, epochs a few ms off the grid like a u-blox's
//! x.999): a fix of epoch u received at r is that epoch's output d0 = (r − e) − (u − T) ≥ 0
//! after it, and the smallest such d0 gives T = ⌈u − (r − e)⌉ (so d0 must be below 1 s while
//! acquiring, as before). Once locked, every edge is labelled by rounding the mapped time to
//! the nearest second, which stays unambiguous for any d0 as long as the mapping error is far
//! below 0.5 s; an edge mapping more than [`EDGE_GATE_NS`] from a whole second is rejected as
//! early/late.
//!
//! Software sync (no PPS): the host clock is mapped through the latest fix, received at r with
//! epoch u: UTC(h) = u + (h − (r − Δ̂)), with Δ̂ the navigation filter's GNSS delay (the
//! receiver's output latency as the IMU's clock sees it; 0 before the filter has one).
//!
//! Network time (a host without a receiver, `--time-source chrony|system`): each
//! [`NetworkTime`] reading is a measurement of UTC − host at its host time with the service's
//! own σ, fused by the same clock model while no PPS keeps the mapping locked; the status is
//! `network`, and holdover when readings stop for [`NETWORK_HOLDOVER_AFTER_NS`]. A network
//! service's successive readings are not independent (chrony filters its own measurements), so
//! the published σ never falls below the latest reading's own.
//!
//! Trust. An edge counts only if the receiver reported a valid fix (or, from a receiver that
//! sends no fixes, a raw measurement epoch) in the last [`FIX_TRUST_NS`]; without one, the
//! edge is rejected and the mapping goes into holdover.
//!
//! Pure state machine: fed with samples, no clocks or IPC inside.

use navsync_wire::samples::{GnssFix, GnssTimePulse, NetworkTime, PpsEdge, TimeState, TimeStatus};
use navsync_wire::time::{NS_PER_S, gps_minus_utc_s};

use super::clock_model::{ClockModel, ClockUpdate, OscillatorNoise};
use super::latency_stats::LatencyStats;
use crate::declare::checks::positive;

/// An edge farther than this from a whole mapped second is early/late, ns.
pub const EDGE_GATE_NS: i64 = 100_000_000;
/// A fix older than this no longer vouches for the PPS, ns.
pub const FIX_TRUST_NS: i64 = 2_500_000_000;
/// No accepted edge for this long: holdover, ns.
pub const HOLDOVER_AFTER_NS: i64 = 1_500_000_000;
/// No network time reading accepted for this long: holdover, ns (readings come about once a
/// second).
pub const NETWORK_HOLDOVER_AFTER_NS: i64 = 5_000_000_000;
/// Rate-error 1-sigma the mapping starts with from a first network reading: any crystal.
const NETWORK_INITIAL_RATE_SIGMA: f64 = 1e-4;
/// Updates needed before the mapping is declared locked.
const LOCK_UPDATES: u64 = 3;
/// Offset 1-sigma below which the mapping is declared locked, ns.
const LOCK_SIGMA_NS: f64 = 100_000.0;

crate::settings_group! {
    /// Configuration of the time synchronisation.
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub struct TimeSyncConfig {
        /// Host oscillator: Allan deviation at 1 s of its white frequency noise (a TCXO's by
        /// default).
        pub oscillator_white_fm_adev_1s: f64 = 1e-10, file "timing", check positive;
        /// Host oscillator: Allan deviation at 1 s of its random-walk frequency noise.
        pub oscillator_random_walk_fm_adev_1s: f64 = 1e-10, file "timing", check positive;
        /// Edge stamp noise used when the source does not state its own, ns.
        pub default_edge_sigma_ns: f64 = 30_000.0;
        /// Ignore PPS: stamp fixes by the receipt of their first byte (software sync, ms-level
        /// time).
        pub software_sync: bool = false, file "timing", switch "software-sync" => true;
        /// The input's own exact time axis (an imported file's time tags): every output is
        /// labelled on it instead of through the clock model; declared by the recording.
        pub time_axis: Option<TimeAxis> = None;
    }
}

/// An exact time axis an input declares: the host clock of its samples is GPS time shifted by
/// a constant (`gps = host_ns − host_ns₀ + gps_ns₀`), as an import of files whose time tags are
/// GPS seconds writes it. Outputs keep that axis: the state of an IMU sample is labelled with
/// the sample's own tag.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct TimeAxis {
    /// A host time, ns of the recording's `CLOCK_MONOTONIC`.
    pub host_ns: i64,
    /// The GPS time at `host_ns`, ns since the GPS epoch (1980-01-06).
    pub gps_ns: i64,
}

impl TimeAxis {
    /// The UTC time on this axis at host time `host_ns`, ns since the Unix epoch.
    pub fn utc_ns_at(&self, host_ns: i64) -> i64 {
        navsync_wire::time::utc_ns_from_gps_ns(self.gps_ns + (host_ns - self.host_ns))
    }

    /// The host time at UTC time `utc_ns` on this axis.
    pub fn host_ns_at(&self, utc_ns: i64) -> i64 {
        navsync_wire::time::gps_ns_from_utc_ns(utc_ns) - self.gps_ns + self.host_ns
    }
}

impl TimeSyncConfig {
    /// The host oscillator's process noise ([`OscillatorNoise::from_allan`]).
    pub fn noise(&self) -> OscillatorNoise {
        OscillatorNoise::from_allan(self.oscillator_white_fm_adev_1s, self.oscillator_random_walk_fm_adev_1s)
    }
}

/// Counters of edges and labels.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TimeSyncCounters {
    /// Edges used by the clock model.
    pub pps_used: u64,
    /// Edges arriving less than half a second after the previous one.
    pub pps_duplicate: u64,
    /// Edges whose mapped time is not close to a whole second, or rejected by the filter gate.
    pub pps_early_late: u64,
    /// Edges without a recent valid fix.
    pub pps_no_fix: u64,
    /// Edges that no fix labelled while acquiring.
    pub pps_unlabelled: u64,
    /// Edges labelled by the receiver's own report of the pulse (UBX TIM-TP), qErr applied.
    pub pps_labelled_by_receiver: u64,
    /// Times the mapping was re-initialised after persistent rejections.
    pub resyncs: u64,
    /// Times the status went from locked to holdover (no accepted edge for
    /// [`HOLDOVER_AFTER_NS`]: the PPS went silent or untrusted).
    pub holdovers: u64,
    /// Times the status came back to locked after a holdover (edges accepted again).
    pub relocks: u64,
    /// Network time readings fused.
    pub network_used: u64,
    /// Network time readings not fused: the service not synchronised, its σ not finite, or
    /// beyond the clock model's gate.
    pub network_rejected: u64,
    /// Network time readings left aside because PPS keeps the mapping locked.
    pub network_ignored: u64,
}

impl TimeSyncCounters {
    /// All rejected edges.
    pub fn rejected(&self) -> u64 {
        self.pps_duplicate + self.pps_early_late + self.pps_no_fix + self.pps_unlabelled
    }
}

#[derive(Debug, Clone, Copy)]
struct Edge {
    host_ns: i64,
    sigma_ns: f64,
}

/// The time-synchronisation state machine.
#[derive(Debug, Clone)]
pub struct TimeSync {
    cfg: TimeSyncConfig,
    clock: ClockModel,
    /// Edges waiting for a label while acquiring (most recent last).
    pending: [Option<Edge>; 4],
    last_edge_host_ns: Option<i64>,
    last_used_host_ns: Option<i64>,
    last_valid_fix_host_ns: Option<i64>,
    /// Host time of the last raw epoch that labelled the edges ([`Self::on_raw_epoch`]).
    last_raw_label_host_ns: Option<i64>,
    consecutive_rejects: u32,
    /// A holdover began and the mapping has not been locked since (a relock is pending).
    relock_pending: bool,
    latency: LatencyStats,
    counters: TimeSyncCounters,
    status: TimeStatus,
    leap_s: i16,
    seq: u64,
    /// Software-sync mapping: receipt host time and UTC epoch of the last fix.
    last_fix_label: Option<(i64, i64)>,
    /// Externally estimated GNSS delay (the navigation filter's Δ), s and 1-sigma s.
    gnss_delay: (f64, f64),
    /// The receiver's report of its next time pulse, waiting for the edge it labels.
    next_pulse: Option<NextPulse>,
    /// Host time and σ (ns) of the last network time reading fused.
    last_network: Option<(i64, f64)>,
}

/// What a receiver said about its next time pulse (UBX TIM-TP).
#[derive(Debug, Clone, Copy, PartialEq)]
struct NextPulse {
    /// Host time the report was received, ns.
    received_host_ns: i64,
    /// UTC of the pulse, ns.
    utc_ns: i64,
    /// Quantisation error of the pulse, ns (the pulse came this much after the ideal instant).
    q_err_ns: f64,
}

/// A time-pulse report labels the first edge within this long after its receipt, ns.
const TIME_PULSE_WINDOW_NS: i64 = 1_500_000_000;

impl TimeSync {
    /// A synchroniser with nothing known.
    pub fn new(cfg: TimeSyncConfig) -> Self {
        Self {
            cfg,
            clock: ClockModel::new(cfg.noise()),
            pending: [None; 4],
            last_edge_host_ns: None,
            last_used_host_ns: None,
            last_valid_fix_host_ns: None,
            last_raw_label_host_ns: None,
            consecutive_rejects: 0,
            relock_pending: false,
            latency: LatencyStats::default(),
            counters: TimeSyncCounters::default(),
            status: TimeStatus::None,
            leap_s: 18,
            seq: 0,
            last_fix_label: None,
            gnss_delay: (f64::NAN, f64::NAN),
            next_pulse: None,
            last_network: None,
        }
    }

    /// Feeds one reading of the network time service (module docs). Returns true when the
    /// mapping was updated.
    pub fn on_network_time(&mut self, t: &NetworkTime) -> bool {
        if self.status == TimeStatus::Locked {
            self.counters.network_ignored += 1;
            return false;
        }
        let sigma = t.std_ns;
        if t.synchronised == 0 || !sigma.is_finite() || sigma <= 0.0 || t.utc_ns == i64::MIN {
            self.counters.network_rejected += 1;
            return false;
        }
        if !self.clock.is_initialized() {
            self.clock.init(t.host_ns, t.utc_ns, sigma, NETWORK_INITIAL_RATE_SIGMA);
        } else if let ClockUpdate::Rejected(_) = self.clock.update(t.host_ns, t.utc_ns, sigma) {
            self.counters.network_rejected += 1;
            // The same rule as for edges: a persistent disagreement starts over.
            self.reject_edge();
            return false;
        }
        self.counters.network_used += 1;
        self.consecutive_rejects = 0;
        self.last_network = Some((t.host_ns, sigma));
        self.leap_s = gps_minus_utc_s(t.utc_ns);
        self.status = TimeStatus::Network;
        self.pending = [None; 4];
        true
    }

    /// Feeds the receiver's report of its next time pulse (UBX TIM-TP): the next PPS edge is
    /// labelled with its UTC directly (no inference from the fixes' epochs, any receiver
    /// latency), and its stamp corrected by the pulse's quantisation error (the sawtooth
    /// correction: the ideal second's host time is the stamp minus qErr).
    pub fn on_time_pulse(&mut self, tp: &GnssTimePulse) {
        if tp.pulse_utc_ns == i64::MIN {
            return;
        }
        let q_err_ns = if tp.q_err_ps == i32::MIN {
            0.0
        } else {
            f64::from(tp.q_err_ps) * 1e-3
        };
        self.next_pulse = Some(NextPulse {
            received_host_ns: tp.stamp.host_ns,
            utc_ns: tp.pulse_utc_ns,
            q_err_ns,
        });
    }

    /// The time-pulse report that labels an edge stamped at `host_ns`, if any (consumed).
    fn pulse_for(&mut self, host_ns: i64) -> Option<NextPulse> {
        let p = self.next_pulse?;
        if host_ns < p.received_host_ns {
            return None;
        }
        self.next_pulse = None;
        (host_ns - p.received_host_ns <= TIME_PULSE_WINDOW_NS).then_some(p)
    }

    /// Counters so far.
    pub fn counters(&self) -> &TimeSyncCounters {
        &self.counters
    }

    /// Current status.
    pub fn status(&self) -> TimeStatus {
        self.status
    }

    /// The clock filter.
    pub fn clock(&self) -> &ClockModel {
        &self.clock
    }

    /// Records the navigation filter's estimate of the GNSS delay Δ, s.
    pub fn set_gnss_delay(&mut self, delay_s: f64, std_s: f64) {
        self.gnss_delay = (delay_s, std_s);
    }

    fn edge_sigma(&self, edge: &PpsEdge) -> f64 {
        if edge.jitter_ns > 0.0 {
            edge.jitter_ns
        } else {
            self.cfg.default_edge_sigma_ns
        }
    }

    fn fix_trusted(&self, host_ns: i64) -> bool {
        self.last_valid_fix_host_ns.is_some_and(|f| host_ns - f <= FIX_TRUST_NS)
    }

    /// Feeds one PPS edge. Returns true when the mapping was updated.
    pub fn on_pps(&mut self, edge: &PpsEdge) -> bool {
        if self.cfg.software_sync || edge.assert_edge == 0 {
            return false;
        }
        let h = edge.stamp.host_ns;
        if self.last_edge_host_ns.is_some_and(|prev| h - prev < NS_PER_S / 2) {
            self.counters.pps_duplicate += 1;
            return false;
        }
        self.last_edge_host_ns = Some(h);
        let sigma = self.edge_sigma(edge);
        if let Some(p) = self.pulse_for(h) {
            return self.on_labelled_edge(h, p, sigma);
        }
        if !self.clock.is_initialized() || self.status == TimeStatus::Acquiring && self.clock.updates() < 2 {
            if self.pending.iter().flatten().any(|e| e.host_ns == h) {
                return false;
            }
            if self.pending[0].is_some() {
                self.counters.pps_unlabelled += 1;
            }
            self.pending.rotate_left(1);
            self.pending[3] = Some(Edge {
                host_ns: h,
                sigma_ns: sigma,
            });
            return false;
        }
        if !self.fix_trusted(h) {
            self.counters.pps_no_fix += 1;
            return false;
        }
        let mapped = self.clock.utc_ns_at(h);
        let label = (mapped + NS_PER_S / 2).div_euclid(NS_PER_S) * NS_PER_S;
        if (mapped - label).abs() > EDGE_GATE_NS {
            self.reject_edge();
            return false;
        }
        match self.clock.update(h, label, sigma) {
            ClockUpdate::Accepted(_) => {
                self.accept_edge(h);
                true
            }
            ClockUpdate::Rejected(_) => {
                self.reject_edge();
                false
            }
        }
    }

    /// An edge the receiver labelled itself (TIM-TP): its ideal second's host time is the stamp
    /// minus the quantisation error. Used while a recent fix says the receiver has GNSS time.
    fn on_labelled_edge(&mut self, h: i64, p: NextPulse, sigma: f64) -> bool {
        if !self.fix_trusted(h) {
            self.counters.pps_no_fix += 1;
            return false;
        }
        let ideal = h - p.q_err_ns.round() as i64;
        self.counters.pps_labelled_by_receiver += 1;
        if !self.clock.is_initialized() {
            self.clock.init(ideal, p.utc_ns, sigma, 1e-4);
            self.counters.pps_used += 1;
            self.last_used_host_ns = Some(ideal);
            self.status = TimeStatus::Acquiring;
            self.pending = [None; 4];
            return true;
        }
        if self.clock.updates() >= 2 && (self.clock.utc_ns_at(ideal) - p.utc_ns).abs() > EDGE_GATE_NS {
            self.reject_edge();
            return false;
        }
        match self.clock.update(ideal, p.utc_ns, sigma) {
            ClockUpdate::Accepted(_) => {
                self.accept_edge(ideal);
                self.pending = [None; 4];
                true
            }
            ClockUpdate::Rejected(_) => {
                self.reject_edge();
                false
            }
        }
    }

    fn accept_edge(&mut self, host_ns: i64) {
        self.counters.pps_used += 1;
        self.consecutive_rejects = 0;
        self.last_used_host_ns = Some(host_ns);
        let p = self.clock.covariance();
        if self.clock.updates() >= LOCK_UPDATES && p[(0, 0)].sqrt() < LOCK_SIGMA_NS {
            self.status = TimeStatus::Locked;
            if self.relock_pending {
                self.relock_pending = false;
                self.counters.relocks += 1;
            }
        } else if self.status != TimeStatus::Locked {
            self.status = TimeStatus::Acquiring;
        }
    }

    fn reject_edge(&mut self) {
        self.counters.pps_early_late += 1;
        self.consecutive_rejects += 1;
        // A persistent disagreement means the time base jumped (receiver reset, wrong label):
        // start over rather than hold a wrong mapping forever.
        if self.consecutive_rejects >= 5 {
            self.counters.resyncs += 1;
            self.clock = ClockModel::new(self.cfg.noise());
            self.pending = [None; 4];
            self.consecutive_rejects = 0;
            self.status = TimeStatus::None;
        }
    }

    /// Feeds one GNSS epoch. Returns true when the mapping was updated.
    pub fn on_fix(&mut self, fix: &GnssFix) -> bool {
        let valid = fix.has_position() && fix.utc_ns != i64::MIN;
        valid && self.on_epoch(fix.stamp.host_ns, fix.utc_ns)
    }

    /// Feeds the time of a raw measurement epoch (UBX RXM-RAWX: the receiver's time, within
    /// its clock's bias, a millisecond at most, of GPS time) received at host `host_ns`: a
    /// receiver that sends raw measurements and no fixes (a logger's RAWX + SFRBX) labels the
    /// PPS edges with it as with a fix's time. Ignored while a fix is trusted ([`FIX_TRUST_NS`]):
    /// one receiver, one source of labels. Returns true when the mapping was updated.
    pub fn on_raw_epoch(&mut self, host_ns: i64, utc_ns: i64) -> bool {
        if self.fix_trusted(host_ns) && self.last_raw_label_host_ns != self.last_valid_fix_host_ns {
            return false;
        }
        let updated = self.on_epoch(host_ns, utc_ns);
        self.last_raw_label_host_ns = Some(host_ns);
        updated
    }

    /// A GNSS epoch of valid time `utc_ns` received at host `h`: labels the pending PPS edge.
    fn on_epoch(&mut self, h: i64, utc_ns: i64) -> bool {
        self.last_valid_fix_host_ns = Some(h);
        self.leap_s = gps_minus_utc_s(utc_ns);
        self.last_fix_label = Some((h, utc_ns));
        let mut updated = false;
        if self.cfg.software_sync {
            self.status = TimeStatus::Software;
            return true;
        }
        if !self.clock.is_initialized() || self.clock.updates() < 2 {
            // Acquisition: the latest pending edge within one second before the fix.
            let found = self
                .pending
                .iter()
                .rev()
                .flatten()
                .find(|e| e.host_ns <= h && h - e.host_ns < NS_PER_S)
                .copied();
            if let Some(edge) = found {
                // The edge's second: the latest whole second ≤ the epoch, counted back by the
                // time from the edge to the receipt (module docs).
                let label = (utc_ns - (h - edge.host_ns)).div_euclid(NS_PER_S) * NS_PER_S;
                let label = if label < utc_ns - (h - edge.host_ns) {
                    label + NS_PER_S
                } else {
                    label
                };
                if self.clock.is_initialized() {
                    if let ClockUpdate::Accepted(_) = self.clock.update(edge.host_ns, label, edge.sigma_ns) {
                        self.accept_edge(edge.host_ns);
                        updated = true;
                    }
                } else {
                    // Rate unknown to 100 ppm: any crystal.
                    self.clock.init(edge.host_ns, label, edge.sigma_ns, 1e-4);
                    self.counters.pps_used += 1;
                    self.last_used_host_ns = Some(edge.host_ns);
                    self.status = TimeStatus::Acquiring;
                    updated = true;
                }
                self.pending = [None; 4];
            }
        }
        if self.clock.is_initialized() && self.status.is_clock_mapped() {
            // Receiver output latency: first byte minus the host time of the epoch's PPS.
            let epoch_host = self.clock_host_ns_at(utc_ns);
            self.latency.push((h - epoch_host) as f64 * 1e-9);
        }
        updated
    }

    /// Host time at which UTC read `utc_ns` by the current mapping (the inverse of
    /// [`utc_ns_at_host`](Self::utc_ns_at_host)); `None` without one.
    pub fn host_ns_at_utc(&self, utc_ns: i64) -> Option<i64> {
        if self.clock.is_initialized() && self.status.is_clock_mapped() {
            return Some(self.clock_host_ns_at(utc_ns));
        }
        if self.status == TimeStatus::Software
            && let Some((rx, utc)) = self.last_fix_label
        {
            return Some(rx + (utc_ns - utc) - (self.software_latency_s() * 1e9).round() as i64);
        }
        None
    }

    /// The receipt latency of the fixes under software sync, s: the GNSS delay estimate, 0
    /// before there is one.
    fn software_latency_s(&self) -> f64 {
        if self.gnss_delay.0.is_finite() {
            self.gnss_delay.0
        } else {
            0.0
        }
    }

    /// UTC at host time `host_ns` by the current mapping: PPS-based (locked or in holdover), or
    /// under software sync through the latest fix and the GNSS delay (module docs).
    pub fn utc_ns_at_host(&self, host_ns: i64) -> Option<i64> {
        if self.clock.is_initialized() && self.status.is_clock_mapped() {
            return Some(self.clock.utc_ns_at(host_ns));
        }
        if self.status == TimeStatus::Software
            && let Some((rx, utc)) = self.last_fix_label
        {
            return Some(utc + host_ns - rx + (self.software_latency_s() * 1e9).round() as i64);
        }
        None
    }

    fn clock_host_ns_at(&self, utc_ns: i64) -> i64 {
        // Invert utc(h) = h + base + x0 + x1·(h − h_s): one fixed-point step is exact to < 1 ns.
        let guess = utc_ns - (self.clock.utc_ns_at(self.clock.host_ns()) - self.clock.host_ns());
        guess - (self.clock.utc_ns_at(guess) - utc_ns)
    }

    /// Advances the status with the passage of host time (holdover when edges stop).
    pub fn tick(&mut self, now_host_ns: i64) {
        if self.status == TimeStatus::Network
            && self
                .last_network
                .is_some_and(|(h, _)| now_host_ns - h > NETWORK_HOLDOVER_AFTER_NS)
        {
            self.status = TimeStatus::Holdover;
            self.counters.holdovers += 1;
        }
        if self.status == TimeStatus::Locked
            && self
                .last_used_host_ns
                .is_some_and(|h| now_host_ns - h > HOLDOVER_AFTER_NS)
        {
            self.status = TimeStatus::Holdover;
            self.counters.holdovers += 1;
            self.relock_pending = true;
        }
        if self.status == TimeStatus::None && !self.clock.is_initialized() && self.last_fix_label.is_some() {
            let last_edge_recent = self.last_edge_host_ns.is_some_and(|e| now_host_ns - e < 3 * NS_PER_S);
            if !last_edge_recent {
                self.status = TimeStatus::Software;
            }
        }
        if self.status == TimeStatus::Software && !self.cfg.software_sync && self.clock.is_initialized() {
            self.status = TimeStatus::Acquiring;
        }
    }

    /// The published time state at host time `now_host_ns`.
    pub fn time_state(&mut self, now_host_ns: i64) -> TimeState {
        let mut s = TimeState::unknown();
        self.seq += 1;
        s.seq = self.seq;
        s.computed_host_ns = now_host_ns;
        s.status = self.status as u8;
        s.leap_s = self.leap_s;
        s.pps_used = self.counters.pps_used;
        s.pps_rejected = self.counters.rejected();
        s.last_pps_host_ns = self.last_used_host_ns.unwrap_or(0);
        s.gnss_delay_s = self.gnss_delay.0;
        s.gnss_delay_std_s = self.gnss_delay.1;
        let noise = self.clock.noise();
        s.q_offset_ns2_per_s = noise.q_offset_ns2_per_s;
        s.q_rate_per_s = noise.q_rate_per_s;
        if self.clock.is_initialized() && self.status != TimeStatus::Software {
            let p = self.clock.covariance();
            s.ref_host_ns = self.clock.host_ns();
            s.ref_utc_ns = self.clock.utc_ns_at_state();
            s.rate_error = self.clock.rate_error();
            s.offset_std_ns = p[(0, 0)].max(0.0).sqrt();
            if let Some((_, floor)) = self.last_network.filter(|_| self.status != TimeStatus::Locked) {
                // Correlated readings: never more confident than the service itself.
                s.offset_std_ns = s.offset_std_ns.max(floor);
            }
            s.rate_std = p[(1, 1)].max(0.0).sqrt();
            s.offset_rate_cov_ns = p[(0, 1)];
        } else if let Some((h, utc)) = self.last_fix_label {
            // Software sync: receipt time minus the best latency estimate we have.
            let (lat_s, lat_std_s) = self.software_latency();
            s.ref_host_ns = h - (lat_s * 1e9) as i64;
            s.ref_utc_ns = utc;
            s.rate_error = 0.0;
            s.offset_std_ns = lat_std_s * 1e9;
            s.rate_std = 1e-4;
        }
        if let Some(l) = self.latency.summary() {
            s.latency_min_s = l.min_s;
            s.latency_median_s = l.median_s;
            s.latency_p99_s = l.p99_s;
            s.latency_max_s = l.max_s;
            s.latency_count = l.count;
        }
        s
    }

    /// Latency to subtract in software sync and its 1-sigma, s: the navigation filter's Δ when
    /// it has one, else the measured median d0, else 0 ± 0.5 s.
    fn software_latency(&mut self) -> (f64, f64) {
        if self.gnss_delay.0.is_finite() {
            return self.gnss_delay;
        }
        match self.latency.summary() {
            Some(l) => (l.median_s, (l.max_s - l.min_s).max(1e-3)),
            None => (0.0, 0.5),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use navsync_wire::reflect::Reflect;
    use navsync_wire::samples::{FixMode, Stamp, StampSource};

    const U0: i64 = 1_790_000_000 * NS_PER_S;
    const H0: i64 = 5 * NS_PER_S;

    /// The receiver's pulse error at second `s`, ns: a 20.8 ns sawtooth.
    fn q_ns(s: i64) -> f64 {
        (s as f64 * 313.7).rem_euclid(20.8) - 10.4
    }

    /// Worst mapping error (ns) at the ideal seconds 20..40 s, with or without TIM-TP reports.
    fn run(time_pulses: bool) -> (f64, u64) {
        let mut ts = TimeSync::new(TimeSyncConfig {
            default_edge_sigma_ns: 10.0,
            ..Default::default()
        });
        let host_of = |utc: i64| H0 + (utc - U0);
        let mut worst: f64 = 0.0;
        for k in 1..40i64 {
            let second = U0 / NS_PER_S + k;
            let ideal = second * NS_PER_S;
            let mut edge = PpsEdge::zeroed();
            edge.stamp = Stamp::host(
                host_of(ideal) + q_ns(second).round() as i64,
                k as u64,
                StampSource::KernelPps,
            );
            edge.assert_edge = 1;
            edge.jitter_ns = 10.0;
            ts.on_pps(&edge);
            let mut fix = GnssFix::empty(Stamp::host(
                host_of(ideal) + 600_000_000,
                k as u64,
                StampSource::Receipt,
            ));
            (fix.utc_ns, fix.lat_deg, fix.lon_deg, fix.alt_msl_m, fix.mode) =
                (ideal, 48.0, 11.0, 500.0, FixMode::Fix3d as u8);
            ts.on_fix(&fix);
            if time_pulses {
                let mut tp = GnssTimePulse::zeroed();
                tp.stamp = Stamp::host(host_of(ideal) + 700_000_000, k as u64, StampSource::Receipt);
                tp.pulse_utc_ns = ideal + NS_PER_S;
                tp.q_err_ps = (q_ns(second + 1) * 1e3).round() as i32;
                ts.on_time_pulse(&tp);
            }
            if k >= 20 {
                let err = (ts.clock.utc_ns_at(host_of(ideal)) - ideal) as f64;
                worst = worst.max(err.abs());
            }
        }
        (worst, ts.counters().pps_labelled_by_receiver)
    }

    #[test]
    fn time_pulse_reports_label_the_edges_and_remove_the_sawtooth() {
        let (without, n0) = run(false);
        let (with, n1) = run(true);
        println!("worst mapping error at the ideal seconds: {without:.2} ns without qErr, {with:.2} ns with");
        assert_eq!(n0, 0);
        assert!(n1 >= 35, "{n1} edges labelled by the receiver");
        assert!(without > 2.0, "the sawtooth shows without qErr: {without} ns");
        assert!(with < 1.5, "with qErr applied: {with} ns");
    }

    /// Edges once a second and, 60 ms after each, a raw epoch whose receiver time is 0.3 ms
    /// off GPS; from second `fixes_from` on also a fix. The mapping's error at the ideal
    /// seconds 20..40, the status, and the edges used.
    fn run_raw(fixes_from: i64) -> (f64, TimeStatus, u64) {
        let mut ts = TimeSync::new(TimeSyncConfig::default());
        let host_of = |utc: i64| H0 + (utc - U0);
        let mut worst: f64 = 0.0;
        for k in 1..40i64 {
            let ideal = U0 + k * NS_PER_S;
            let mut edge = PpsEdge::zeroed();
            edge.stamp = Stamp::host(host_of(ideal), k as u64, StampSource::KernelPps);
            edge.assert_edge = 1;
            ts.on_pps(&edge);
            if k >= fixes_from {
                let mut fix = GnssFix::empty(Stamp::host(host_of(ideal) + 50_000_000, k as u64, StampSource::Receipt));
                (fix.utc_ns, fix.lat_deg, fix.lon_deg, fix.alt_msl_m, fix.mode) =
                    (ideal, 48.0, 11.0, 500.0, FixMode::Fix3d as u8);
                ts.on_fix(&fix);
            }
            ts.on_raw_epoch(host_of(ideal) + 60_000_000, ideal + 300_000);
            ts.tick(host_of(ideal) + 60_000_000);
            if k >= 20 {
                let err = (ts.clock.utc_ns_at(host_of(ideal)) - ideal) as f64;
                worst = worst.max(err.abs());
            }
        }
        (worst, ts.status, ts.counters.pps_used)
    }

    #[test]
    fn raw_epochs_label_the_edges_of_a_receiver_without_fixes_and_give_way_to_its_fixes() {
        // Raw epochs alone: locked, each edge on its own second (the 0.3 ms of the receiver's
        // clock does not move the label).
        let (err, status, used) = run_raw(i64::MAX);
        assert_eq!(status, TimeStatus::Locked);
        assert!(used >= 35, "{used} edges used");
        assert!(err < 100.0, "mapping error {err} ns");
        // With fixes from second 10 on: the same mapping (the fixes label the same seconds).
        let (err_fixes, status, used_fixes) = run_raw(10);
        assert_eq!(status, TimeStatus::Locked);
        assert_eq!(used_fixes, used);
        assert!(err_fixes < 100.0, "mapping error {err_fixes} ns");
        // A fix trusted: a raw epoch labels nothing.
        let mut ts = TimeSync::new(TimeSyncConfig::default());
        let mut fix = GnssFix::empty(Stamp::host(H0, 1, StampSource::Receipt));
        (fix.utc_ns, fix.lat_deg, fix.lon_deg, fix.alt_msl_m, fix.mode) = (U0, 48.0, 11.0, 500.0, FixMode::Fix3d as u8);
        ts.on_fix(&fix);
        assert!(ts.fix_trusted(H0 + NS_PER_S));
        let before = ts.last_fix_label;
        ts.on_raw_epoch(H0 + NS_PER_S, U0 + 7 * NS_PER_S);
        assert_eq!(
            ts.last_fix_label, before,
            "a raw epoch relabelled while a fix is trusted"
        );
    }

    fn reading(host_ns: i64, utc_ns: i64, std_ns: f64) -> NetworkTime {
        let mut t = NetworkTime::zeroed();
        (t.host_ns, t.utc_ns, t.std_ns, t.synchronised) = (host_ns, utc_ns, std_ns, 1);
        t
    }

    #[test]
    fn network_time_maps_the_host_clock_with_its_own_sigma_and_holds_over_when_it_stops() {
        let mut ts = TimeSync::new(TimeSyncConfig::default());
        // A host 3 ppm fast; readings once a second with σ 20 µs and errors within ±5 µs.
        let utc_of = |h: i64| U0 + ((h - H0) as f64 / (1.0 + 3e-6)).round() as i64;
        for k in 0..60i64 {
            let h = H0 + k * NS_PER_S;
            let noise = ((k * 7919) % 11 - 5) * 1000;
            assert!(ts.on_network_time(&reading(h, utc_of(h) + noise, 20_000.0)));
            ts.tick(h);
        }
        assert_eq!(ts.status(), TimeStatus::Network);
        let h = H0 + 59 * NS_PER_S + NS_PER_S / 2;
        let s = ts.time_state(h);
        let err = (s.utc_ns_at(h) - utc_of(h)) as f64;
        // Never more confident than one reading (they are not independent).
        assert!(s.offset_std_ns >= 20_000.0, "σ {}", s.offset_std_ns);
        assert!(err.abs() < 10_000.0, "error {err} ns");
        // An unsynchronised service is not fused; silence means holdover.
        let mut unsync = reading(h, utc_of(h), 20_000.0);
        unsync.synchronised = 0;
        assert!(!ts.on_network_time(&unsync));
        assert_eq!(ts.counters().network_rejected, 1);
        ts.tick(H0 + 59 * NS_PER_S + NETWORK_HOLDOVER_AFTER_NS + 1);
        assert_eq!(ts.status(), TimeStatus::Holdover);
        // Readings again: network.
        let h = H0 + 70 * NS_PER_S;
        assert!(ts.on_network_time(&reading(h, utc_of(h), 20_000.0)));
        assert_eq!(ts.status(), TimeStatus::Network);
    }
}
