//! Events with their pose: each edge a receiver marked (UBX TIM-TM2, a camera's exposure on
//! EXTINT; at its GPS time) or a trigger input stamped on the host (`navsync trigger`, a GPIO
//! line's kernel stamp; at its host time) becomes an [`EventPose`] once the delayed filter has
//! fused past its instant, from
//! the fused states around it with the interpolation of the history of states
//! ([`navsync_wire::interpolation`]): the same two states and the same formula as the
//! history's `state_at` (`state_at_host` for a host-stamped edge) of the event's time, so both
//! answers are equal bit for bit.
//!
//! Pure and deterministic: what comes out depends only on the events and the fused states,
//! in their order. Bounded: the fused states of the last [`KEEP_NS`], at most
//! [`MAX_PENDING`] events waiting; an event no fused state will reach (older than the states
//! kept, or waiting longer than [`GIVE_UP_NS`]) goes out without a pose (`source` 0), so a
//! subscriber still learns of it.

use std::collections::VecDeque;

use navsync_wire::interpolation::{Record, Source, at_utc, bracket_index, interpolate};
use navsync_wire::samples::{EVENT_EDGE_FALLING, EVENT_EDGE_RISING, EventPose, GnssEvent, NavState, StampSource};
use navsync_wire::time::utc_ns_from_gps_ns;

/// How long fused states are kept for events that arrive after the filter passed them, ns.
pub const KEEP_NS: i64 = 5_000_000_000;
/// Events waiting for the fused states to reach them, at most.
pub const MAX_PENDING: usize = 64;
/// Waiting longer than this (host time of the newest fused state past the event's report)
/// without a fused state past its instant, an event goes out without a pose, ns.
pub const GIVE_UP_NS: i64 = 10_000_000_000;
/// Event poses kept for a caller that has not taken them, at most.
const MAX_UNDRAINED: usize = 1024;

/// Counters of the events.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct EventCounters {
    /// Edges received (a report may carry a rising and a falling edge).
    pub edges: u64,
    /// Event poses made from fused states.
    pub posed: u64,
    /// Events given out without a pose (before the states kept, no time, waited too long, or
    /// too many waiting).
    pub without_pose: u64,
}

/// The instant of an edge: a receiver's mark in GNSS time (as UTC), or a host-stamped
/// trigger's host time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Instant {
    /// UTC, ns since 1970.
    Utc(i64),
    /// Host time (`CLOCK_MONOTONIC`), ns.
    Host(i64),
}

/// One edge waiting for its pose.
#[derive(Debug, Clone, Copy)]
struct Pending {
    at: Instant,
    pose: EventPose,
}

/// The events waiting for the fused states, and the fused states they are posed from.
#[derive(Debug, Clone, Default)]
pub struct EventPoses {
    fused: VecDeque<Record>,
    pending: VecDeque<Pending>,
    out: Vec<EventPose>,
    seq: u64,
    counters: EventCounters,
}

impl EventPoses {
    /// What happened so far.
    pub fn counters(&self) -> EventCounters {
        self.counters
    }

    /// Takes an event report from device `device_id`: each new edge waits for its pose. A
    /// receiver's edge (TIM-TM2) is at its GPS time; a host-stamped trigger's (no GPS time) at
    /// its host time.
    pub fn on_event(&mut self, e: &GnssEvent, device_id: [u8; 8]) {
        for (gps_ns, host_ns, edge) in [
            (e.rising_gps_ns, e.rising_host_ns, EVENT_EDGE_RISING),
            (e.falling_gps_ns, e.falling_host_ns, EVENT_EDGE_FALLING),
        ] {
            let at = if gps_ns != i64::MIN {
                Instant::Utc(utc_ns_from_gps_ns(gps_ns))
            } else if host_ns != i64::MIN && e.stamp.source == StampSource::KernelEvent as u8 {
                Instant::Host(host_ns)
            } else {
                continue;
            };
            self.counters.edges += 1;
            let mut pose = unposed();
            pose.gps_ns = gps_ns;
            match at {
                Instant::Utc(u) => pose.utc_ns = u,
                Instant::Host(h) => pose.host_ns = h,
            }
            pose.report_host_ns = e.stamp.host_ns;
            pose.time_std_ns = f64::from(e.accuracy_ns);
            pose.device_id = device_id;
            pose.count = e.count;
            pose.channel = e.channel;
            pose.edge = edge;
            if self.pending.len() >= MAX_PENDING
                && let Some(old) = self.pending.pop_front()
            {
                self.give_out(old.pose);
            }
            self.pending.push_back(Pending { at, pose });
        }
        self.resolve();
    }

    /// Takes a fused state (finite, later than the previous one in host time and UTC; the
    /// caller checks) and poses the events it reaches.
    pub fn on_fused(&mut self, s: &NavState) {
        let r = Record::of(s, Source::Fused);
        while self.fused.front().is_some_and(|f| f.host_ns < r.host_ns - KEEP_NS) {
            self.fused.pop_front();
        }
        self.fused.push_back(r);
        self.resolve();
    }

    /// Poses the waiting events the fused states reach; gives out those they never will.
    fn resolve(&mut self) {
        let Some(newest) = self.fused.back().copied() else {
            return;
        };
        let mut i = 0;
        while i < self.pending.len() {
            let p = self.pending[i];
            let waited_too_long = newest.host_ns.saturating_sub(p.pose.report_host_ns) > GIVE_UP_NS;
            let reached = match p.at {
                Instant::Utc(u) => newest.utc_ns != i64::MIN && u <= newest.utc_ns,
                Instant::Host(h) => h <= newest.host_ns,
            };
            if reached {
                self.pending.remove(i);
                let fused = &self.fused;
                // As the history's `state_at` and `state_at_host` find and interpolate them.
                let x = match p.at {
                    Instant::Utc(u) => bracket_index(fused.len(), |k| fused[k].utc_ns, u)
                        .filter(|&(a, _)| fused[a].utc_ns != i64::MIN)
                        .map(|(a, b)| (a, at_utc(&fused[a], &fused[b], u))),
                    Instant::Host(h) => bracket_index(fused.len(), |k| fused[k].host_ns, h)
                        .map(|(a, b)| (a, interpolate(&fused[a], &fused[b], h))),
                };
                match x {
                    Some((a, x)) => {
                        let mut pose = p.pose;
                        pose.host_ns = x.host_ns;
                        pose.utc_ns = x.utc_ns;
                        pose.lat_deg = x.pose.lat_deg;
                        pose.lon_deg = x.pose.lon_deg;
                        pose.height_m = x.pose.height_m;
                        pose.vel_ned_mps = x.pose.vel_ned_mps;
                        pose.q_nb = x.pose.q_nb;
                        pose.rpy_rad = x.pose.rpy_rad;
                        pose.pos_std_ned_m = x.pose.pos_std_ned_m;
                        pose.vel_std_ned_mps = x.pose.vel_std_ned_mps;
                        pose.att_std_rad = x.pose.att_std_rad;
                        pose.source = Source::Fused as u8;
                        pose.status = fused[a].status;
                        pose.time_status = fused[a].time_status;
                        pose.integrity = fused[a].integrity;
                        self.counters.posed += 1;
                        self.push(pose);
                    }
                    None => self.give_out(p.pose),
                }
            } else if waited_too_long {
                self.pending.remove(i);
                self.give_out(p.pose);
            } else {
                i += 1;
            }
        }
    }

    /// Gives every waiting event out as it stands (at the end of a stream): posed where the
    /// fused states reach, else without a pose.
    pub fn flush(&mut self) {
        self.resolve();
        while let Some(p) = self.pending.pop_front() {
            self.give_out(p.pose);
        }
    }

    fn give_out(&mut self, pose: EventPose) {
        self.counters.without_pose += 1;
        self.push(pose);
    }

    fn push(&mut self, mut pose: EventPose) {
        if self.out.len() >= MAX_UNDRAINED {
            // A caller that never takes them: bounded.
            self.out.clear();
        }
        self.seq += 1;
        pose.seq = self.seq;
        self.out.push(pose);
    }

    /// Hands the event poses made since the last call to `f`, in the order they were made.
    pub fn drain(&mut self, f: &mut dyn FnMut(&EventPose)) {
        for p in &self.out {
            f(p);
        }
        self.out.clear();
    }
}

/// An event pose with no pose yet: NaN numbers, no times, source 0.
fn unposed() -> EventPose {
    let mut p = <EventPose as navsync_wire::reflect::Reflect>::zeroed();
    p.host_ns = i64::MIN;
    p.utc_ns = i64::MIN;
    p.gps_ns = i64::MIN;
    p.report_host_ns = i64::MIN;
    p.lat_deg = f64::NAN;
    p.lon_deg = f64::NAN;
    p.height_m = f64::NAN;
    p.vel_ned_mps = [f64::NAN; 3];
    p.q_nb = [f64::NAN; 4];
    p.rpy_rad = [f64::NAN; 3];
    p.pos_std_ned_m = [f64::NAN; 3];
    p.vel_std_ned_mps = [f64::NAN; 3];
    p.att_std_rad = [f64::NAN; 3];
    p.time_std_ns = f64::NAN;
    p
}

#[cfg(test)]
mod tests {
    use super::*;
    use navsync_wire::reflect::Reflect;
    use navsync_wire::time::gps_ns_from_utc_ns;

    const UTC0: i64 = 1_700_000_000_000_000_000;

    /// A fused state at `t` s moving north at 10 m/s, its UTC 0.25 s after the host time.
    fn state(t: f64) -> NavState {
        let mut s = NavState::zeroed();
        s.host_ns = (t * 1e9) as i64;
        s.utc_ns = UTC0 + s.host_ns + 250_000_000;
        s.lat_deg = 48.0 + (t * 10.0 / 6.37e6).to_degrees();
        s.lon_deg = 11.0;
        s.height_m = 500.0;
        s.vel_ned_mps = [10.0, 0.0, 0.0];
        s.q_nb = [1.0, 0.0, 0.0, 0.0];
        s.pos_std_ned_m = [0.1; 3];
        s.vel_std_ned_mps = [0.01; 3];
        s.att_std_rad = [0.001; 3];
        s
    }

    fn event(utc_ns: i64, report_host_ns: i64, count: u16) -> GnssEvent {
        let mut e = GnssEvent::zeroed();
        e.stamp.host_ns = report_host_ns;
        e.rising_gps_ns = gps_ns_from_utc_ns(utc_ns);
        e.falling_gps_ns = i64::MIN;
        e.accuracy_ns = 20;
        e.count = count;
        e
    }

    #[test]
    fn an_event_is_posed_once_the_fused_states_pass_it_as_the_history_would() {
        let mut ev = EventPoses::default();
        let id = navsync_wire::reflect::fixed_str("0");
        for k in 0..100 {
            ev.on_fused(&state(1.0 + k as f64 * 0.01));
        }
        // At 2.505 s host: not reached yet (the newest fused state is at 1.99 s).
        let t_utc = UTC0 + 2_505_000_000 + 250_000_000;
        ev.on_event(&event(t_utc, 2_600_000_000, 7), id);
        // Before the states kept (KEEP_NS): no pose, said so.
        ev.on_event(&event(UTC0 - 10_000_000_000, 2_600_000_000, 8), id);
        let mut out = Vec::new();
        ev.drain(&mut |p| out.push(*p));
        assert_eq!(out.len(), 1);
        assert_eq!((out[0].count, out[0].source), (8, 0));
        assert!(out[0].lat_deg.is_nan());
        for k in 100..200 {
            ev.on_fused(&state(1.0 + k as f64 * 0.01));
        }
        ev.drain(&mut |p| out.push(*p));
        assert_eq!(out.len(), 2);
        let p = out[1];
        assert_eq!((p.count, p.source, p.device_id), (7, Source::Fused as u8, id));
        assert_eq!(p.host_ns, 2_505_000_000);
        assert_eq!(p.utc_ns, t_utc);
        assert_eq!(p.time_std_ns, 20.0);
        let recs: Vec<Record> = (100..200)
            .map(|k| Record::of(&state(1.0 + k as f64 * 0.01), Source::Fused))
            .collect();
        let (a, b) = bracket_index(recs.len(), |k| recs[k].utc_ns, t_utc).unwrap();
        assert_eq!(p.lat_deg, at_utc(&recs[a], &recs[b], t_utc).pose.lat_deg);
        assert_eq!(
            ev.counters(),
            EventCounters {
                edges: 2,
                posed: 1,
                without_pose: 1
            }
        );
    }

    #[test]
    fn a_host_stamped_trigger_is_posed_at_its_host_time() {
        let mut ev = EventPoses::default();
        for k in 0..100 {
            ev.on_fused(&state(1.0 + k as f64 * 0.01));
        }
        let mut e = GnssEvent::zeroed();
        (e.rising_gps_ns, e.falling_gps_ns, e.falling_host_ns) = (i64::MIN, i64::MIN, i64::MIN);
        e.rising_host_ns = 1_504_000_000;
        e.stamp.host_ns = e.rising_host_ns;
        e.stamp.source = StampSource::KernelEvent as u8;
        ev.on_event(&e, [b'c'; 8]);
        let mut out = Vec::new();
        ev.drain(&mut |p| out.push(*p));
        assert_eq!(out.len(), 1);
        let recs: Vec<Record> = (0..100)
            .map(|k| Record::of(&state(1.0 + k as f64 * 0.01), Source::Fused))
            .collect();
        let (a, b) = bracket_index(recs.len(), |k| recs[k].host_ns, e.rising_host_ns).unwrap();
        let want = interpolate(&recs[a], &recs[b], e.rising_host_ns);
        let p = out[0];
        assert_eq!(
            (p.host_ns, p.gps_ns, p.source),
            (1_504_000_000, i64::MIN, Source::Fused as u8)
        );
        assert_eq!((p.lat_deg, p.utc_ns), (want.pose.lat_deg, want.utc_ns));
        assert_eq!(p.utc_ns, UTC0 + 1_504_000_000 + 250_000_000);
        // A host time without a kernel stamp (a receiver's report mapped by its driver) is not
        // taken as the instant.
        e.stamp.source = StampSource::Receipt as u8;
        ev.on_event(&e, [b'c'; 8]);
        assert_eq!(ev.counters().edges, 1);
    }

    #[test]
    fn an_event_no_state_reaches_goes_out_without_a_pose_at_the_end() {
        let mut ev = EventPoses::default();
        ev.on_fused(&state(1.0));
        ev.on_fused(&state(1.01));
        ev.on_event(&event(UTC0 + 5_000_000_000, 1_100_000_000, 1), [0; 8]);
        let mut n = 0;
        ev.drain(&mut |_| n += 1);
        assert_eq!(n, 0, "waits");
        ev.flush();
        let mut out = Vec::new();
        ev.drain(&mut |p| out.push(*p));
        assert_eq!((out.len(), out[0].source), (1, 0));
    }
}
