//! The order in which the estimator consumes its inputs, made a function of the samples alone.
//!
//! # Why
//!
//! The estimator's results depend on the order of its inputs across services: a PPS edge
//! consumed before or after an IMU sample changes that sample's `NavState.utc_ns`; a fix
//! consumed before or after it changes the alignment, the time-status transitions and the
//! GNSS-outage status. Across iceoryx2 services there is no arrival order: a process that wakes
//! up finds samples on several services and drains them in some order, and which samples one
//! wake-up finds depends on scheduling. The simulator publishes PPS edges at the same instant
//! as IMU samples (both on the whole second), so the live estimator and a recorder beside it
//! disagreed about that order about once a second, and `navsync replay --estimate` of a live
//! recording could not reproduce the live `NavState`s bit for bit.
//!
//! # The rule
//!
//! Every sample gets a key: its stamp plus a hold that covers the time its publisher needs
//! to publish it after the stamp (host time, ns):
//!
//! | sample | key |
//! |---|---|
//! | reference IMU (the one that drives the filter), other IMUs, truth | `stamp.host_ns` |
//! | PPS edge | `stamp.host_ns + PPS_HOLD_NS` (a driver republishes it µs–ms later) |
//! | GNSS fix | `stamp.host_ns + FIX_HOLD_NS` (stamped at its first byte, published after the whole burst and the driver's idle flush) |
//!
//! and a sample is consumed once a reference-IMU sample with a key at least as large has
//! arrived, in key order. So a PPS edge or a fix is applied right before the first reference
//! IMU sample stamped `hold` after it, whenever it happened to arrive. The live process
//! (`navsync estimator`, the daemon's `live::estimator`) and the offline runner ([`crate::offline`], used by
//! `navsync replay --estimate` and `navsync sim --fast --estimate`) both go through
//! [`InputOrder`], so they consume any recording of the same samples in the same order,
//! whatever order it was recorded in.
//!
//! The live process drains the IMU services before PPS and GNSS on each wake-up: a PPS edge
//! or fix published before the IMU sample that releases it is then always among the drained
//! samples.
//!
//! What it costs: fixes reach the filter [`FIX_HOLD_NS`] later (they are fused at their epoch
//! in the delayed filter, which runs `horizon_s` (at most 2 s by default) behind, so fusion itself is
//! unchanged as long as the receiver latency plus the hold stays below the horizon: d0 up to
//! ~1.25 s); alignment and status changes happen that much later; PPS edges update the time
//! mapping [`PPS_HOLD_NS`] later. `NavState`s are not delayed at all.
//!
//! Other IMUs of an array have no hold: their samples go in in stamp order, which is the
//! order the simulator publishes them in. IMUs read by separate driver processes can be
//! published out of that order by a scheduling hiccup of a millisecond; such a sample is late.
//!
//! What it cannot do: a sample that arrives after its slot has passed (a fix published more
//! than [`FIX_HOLD_NS`] after its first byte: a 9600-baud receiver with long bursts, or a
//! driver stalled that long; a non-reference IMU sample published after a later reference
//! sample) is consumed at once and counted in [`InputOrder::late`] (health counter
//! `inputs_late` of the estimator); its effect then depends on when it arrived, as before.
//! When the reference IMU is silent for [`STALL_NS`] of wall time the live process consumes
//! what waits (time sync without IMUs).
//!
//! A reference IMU that stops while others go on (its driver died): once another IMU's
//! samples are [`REFERENCE_SILENT_NS`] ahead of the last reference sample, samples are due up
//! to that lag behind the newest IMU sample, so the estimator sees the reference go stale and
//! hands the reference over to a live IMU ([`crate::array::imu_array`]); the consumer then
//! tells the order the new reference ([`InputOrder::set_reference`]) and it releases samples
//! with no lag again. Both rules depend on the samples only.

use std::cmp::{Ordering, Reverse};
use std::collections::BinaryHeap;

use navsync_wire::reflect::fixed_str;
use navsync_wire::samples::{
    AnySample, GnssEvent, GnssFix, GnssNavData, GnssRaw, GnssTimePulse, ImuSample, NetworkTime, PpsEdge, SimTruth,
};

/// Hold of PPS edges after their stamp, ns.
pub const PPS_HOLD_NS: i64 = 50_000_000;
/// Hold of GNSS fixes after their stamp (first byte), ns.
pub const FIX_HOLD_NS: i64 = 200_000_000;
/// Wall time without a new reference-IMU sample after which a live process consumes the
/// waiting samples anyway, ns.
pub const STALL_NS: i64 = 500_000_000;
/// Lead of another IMU over the reference (host ns of their newest samples) after which
/// samples are released without the reference, ns.
pub const REFERENCE_SILENT_NS: i64 = 100_000_000;

/// Position of a sample in the canonical order: key time, then kind, then the source's own
/// sequence number.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub struct OrderKey {
    /// Stamp plus hold, host ns.
    pub at_ns: i64,
    rank: u8,
    id: [u8; 8],
    seq: u64,
}

/// The key of a sample.
pub fn order_key(s: &AnySample) -> OrderKey {
    let (at_ns, rank, id, seq) = match s {
        AnySample::PpsEdge(e) => (e.stamp.host_ns.saturating_add(PPS_HOLD_NS), 0, [0; 8], e.stamp.seq),
        AnySample::GnssFix(f) => (f.stamp.host_ns.saturating_add(FIX_HOLD_NS), 1, [0; 8], f.stamp.seq),
        AnySample::Imu(x) => (x.stamp.host_ns, 2, x.imu_id, x.stamp.seq),
        AnySample::Truth(t) => (t.host_ns, 3, [0; 8], t.seq),
        AnySample::Nav(n) => (n.host_ns, 4, [0; 8], n.seq),
        AnySample::Time(t) => (t.computed_host_ns, 5, [0; 8], t.seq),
        AnySample::Health(h) => (h.host_ns, 6, [0; 8], 0),
        // A time pulse report comes before the edge it labels: held like an edge.
        AnySample::TimePulse(t) => (t.stamp.host_ns.saturating_add(PPS_HOLD_NS), 0, [0; 8], t.stamp.seq),
        AnySample::Event(e) => (e.stamp.host_ns, 7, [0; 8], e.stamp.seq),
        // Raw measurements are held like the fix of their epoch (the time mapping needs the
        // epoch's PPS edge first).
        AnySample::Raw(r) => (r.stamp.host_ns.saturating_add(FIX_HOLD_NS), 1, [1; 8], r.stamp.seq),
        AnySample::NavData(d) => (d.stamp.host_ns, 7, [2; 8], d.stamp.seq),
        AnySample::Settings(x) => (x.host_ns, 6, [1; 8], x.seq),
        // A reading of the network time service: at its own host time, before the IMU sample
        // of the same instant (like an edge, without the hold: it is complete when published).
        AnySample::NetworkTime(t) => (t.host_ns, 0, [3; 8], t.seq),
        // The receiver's sky (not an input of the filter): at its stamp, with the other reports.
        AnySample::Sky(s) => (s.stamp.host_ns, 7, [3; 8], s.stamp.seq),
        // An output of the estimator, as its navigation states.
        AnySample::EventPose(e) => (e.host_ns, 4, [1; 8], e.seq),
    };
    OrderKey { at_ns, rank, id, seq }
}

/// A sample as the order keeps it: the kinds the estimator consumes, and only the key of any
/// other (an [`AnySample`] is 2.6 KiB for the sake of raw measurements and health; an IMU
/// sample is 112 B, and every sample is moved several times on its way to the filter: the
/// raw measurements, one epoch a second, are boxed).
#[derive(Debug, Clone)]
pub enum Input {
    /// An IMU sample.
    Imu(ImuSample),
    /// A PPS edge.
    PpsEdge(PpsEdge),
    /// A GNSS fix.
    GnssFix(GnssFix),
    /// A receiver's time-pulse report.
    TimePulse(GnssTimePulse),
    /// A receiver's raw measurements of one epoch.
    Raw(Box<GnssRaw>),
    /// A receiver's navigation data (one subframe).
    NavData(GnssNavData),
    /// The simulator's truth (offline evaluation).
    Truth(SimTruth),
    /// A reading of the network time service.
    NetworkTime(NetworkTime),
    /// A receiver's time mark of an external event, with the receiver's id (NUL-padded; the
    /// service's `{id}`, which the sample does not hold).
    Event(GnssEvent, [u8; 8]),
    /// Any other sample: only its place in the order.
    Other(OrderKey),
}

impl From<AnySample> for Input {
    fn from(s: AnySample) -> Self {
        match s {
            AnySample::Imu(x) => Self::Imu(x),
            AnySample::PpsEdge(x) => Self::PpsEdge(x),
            AnySample::GnssFix(x) => Self::GnssFix(x),
            AnySample::TimePulse(x) => Self::TimePulse(x),
            AnySample::Truth(x) => Self::Truth(x),
            AnySample::Raw(x) => Self::Raw(Box::new(x)),
            AnySample::NavData(x) => Self::NavData(x),
            AnySample::NetworkTime(x) => Self::NetworkTime(x),
            AnySample::Event(x) => Self::Event(x, [0; 8]),
            other => Self::Other(order_key(&other)),
        }
    }
}

impl Input {
    /// The input of `sample` from service `service`: an event carries the receiver's id.
    pub fn from_service(sample: AnySample, service: &str) -> Self {
        match sample {
            AnySample::Event(e) => {
                let id = service.split('/').nth(2).unwrap_or("");
                Self::Event(e, fixed_str(id))
            }
            other => Self::from(other),
        }
    }

    /// Its place in the canonical order (the same as [`order_key`] of the sample; an event's
    /// with the id of the device that marked it, which the sample alone does not hold).
    pub fn key(&self) -> OrderKey {
        match self {
            Self::PpsEdge(e) => OrderKey {
                at_ns: e.stamp.host_ns.saturating_add(PPS_HOLD_NS),
                rank: 0,
                id: [0; 8],
                seq: e.stamp.seq,
            },
            Self::GnssFix(f) => OrderKey {
                at_ns: f.stamp.host_ns.saturating_add(FIX_HOLD_NS),
                rank: 1,
                id: [0; 8],
                seq: f.stamp.seq,
            },
            Self::Imu(x) => OrderKey {
                at_ns: x.stamp.host_ns,
                rank: 2,
                id: x.imu_id,
                seq: x.stamp.seq,
            },
            Self::Truth(t) => OrderKey {
                at_ns: t.host_ns,
                rank: 3,
                id: [0; 8],
                seq: t.seq,
            },
            Self::TimePulse(t) => OrderKey {
                at_ns: t.stamp.host_ns.saturating_add(PPS_HOLD_NS),
                rank: 0,
                id: [0; 8],
                seq: t.stamp.seq,
            },
            Self::Raw(r) => OrderKey {
                at_ns: r.stamp.host_ns.saturating_add(FIX_HOLD_NS),
                rank: 1,
                id: [1; 8],
                seq: r.stamp.seq,
            },
            Self::NavData(d) => OrderKey {
                at_ns: d.stamp.host_ns,
                rank: 7,
                id: [2; 8],
                seq: d.stamp.seq,
            },
            Self::NetworkTime(t) => OrderKey {
                at_ns: t.host_ns,
                rank: 0,
                id: [3; 8],
                seq: t.seq,
            },
            // The device's id orders two devices' events of one instant (their own sequences
            // may coincide).
            Self::Event(e, id) => OrderKey {
                at_ns: e.stamp.host_ns,
                rank: 7,
                id: *id,
                seq: e.stamp.seq,
            },
            Self::Other(k) => *k,
        }
    }
}

/// A waiting sample's place in the heap: its key, and its slot in [`InputOrder::slots`]
/// (samples are a few KiB: the heap moves only these small entries).
#[derive(Clone, Copy)]
struct Entry {
    key: OrderKey,
    /// Arrival number: orders exact duplicates.
    arrival: u64,
    slot: usize,
}

impl PartialEq for Entry {
    fn eq(&self, o: &Self) -> bool {
        (self.key, self.arrival) == (o.key, o.arrival)
    }
}
impl Eq for Entry {}
impl PartialOrd for Entry {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Entry {
    fn cmp(&self, o: &Self) -> Ordering {
        (self.key, self.arrival).cmp(&(o.key, o.arrival))
    }
}

/// Puts samples into the canonical order (see the module docs). `T` is carried along with
/// each sample (e.g. its recording time).
pub struct InputOrder<T = ()> {
    reference_imu: Option<[u8; 8]>,
    heap: BinaryHeap<Reverse<Entry>>,
    /// The waiting samples; `None` slots are free (listed in `free`). Both keep their
    /// capacity, so a steady state allocates nothing.
    slots: Vec<Option<(Input, T)>>,
    free: Vec<usize>,
    watermark: i64,
    /// Newest stamp of any IMU, host ns.
    newest_imu_ns: i64,
    arrivals: u64,
    last_popped: Option<OrderKey>,
    late: u64,
    seen_watermark: i64,
    progress_at_ns: Option<i64>,
}

impl<T> InputOrder<T> {
    /// An empty order released by the IMU with id `reference_imu`; with `None` every sample is
    /// due at once (no IMU: nothing to order against).
    pub fn new(reference_imu: Option<&str>) -> Self {
        Self {
            reference_imu: reference_imu.map(fixed_str::<8>),
            heap: BinaryHeap::new(),
            slots: Vec::new(),
            free: Vec::new(),
            watermark: i64::MIN,
            newest_imu_ns: i64::MIN,
            arrivals: 0,
            last_popped: None,
            late: 0,
            seen_watermark: i64::MIN,
            progress_at_ns: None,
        }
    }

    /// Adds a sample.
    pub fn push(&mut self, sample: impl Into<Input>, tag: T) {
        let sample: Input = sample.into();
        if let Input::Imu(x) = &sample {
            self.newest_imu_ns = self.newest_imu_ns.max(x.stamp.host_ns);
            if self.reference_imu.is_some_and(|r| x.imu_id == r) {
                self.watermark = self.watermark.max(x.stamp.host_ns);
            }
        }
        let key = sample.key();
        self.arrivals += 1;
        let slot = match self.free.pop() {
            Some(i) => {
                self.slots[i] = Some((sample, tag));
                i
            }
            None => {
                self.slots.push(Some((sample, tag)));
                self.slots.len() - 1
            }
        };
        self.heap.push(Reverse(Entry {
            key,
            arrival: self.arrivals,
            slot,
        }));
    }

    /// The next sample whose turn has come, in order.
    pub fn pop(&mut self) -> Option<(Input, T)> {
        let due = match self.heap.peek() {
            Some(Reverse(e)) => {
                self.reference_imu.is_none()
                    || e.key.at_ns
                        <= self
                            .watermark
                            .max(self.newest_imu_ns.saturating_sub(REFERENCE_SILENT_NS))
            }
            None => false,
        };
        if due { self.pop_any() } else { None }
    }

    /// The next sample in order, due or not (end of a stream, or a stalled reference IMU).
    pub fn pop_any(&mut self) -> Option<(Input, T)> {
        let Reverse(e) = self.heap.pop()?;
        let (sample, tag) = self.slots[e.slot].take()?;
        self.free.push(e.slot);
        if self.last_popped.is_some_and(|k| e.key < k) {
            let counts = match &sample {
                Input::PpsEdge(_) | Input::GnssFix(_) | Input::Raw(_) => true,
                Input::Imu(x) => self.reference_imu.is_none_or(|r| x.imu_id != r),
                _ => false,
            };
            if counts {
                self.late += 1;
            }
        } else {
            self.last_popped = Some(e.key);
        }
        Some((sample, tag))
    }

    /// The consumer's reference IMU changed (handover): its samples release the others from
    /// now on. Returns the previous reference when it changed (`None`: already the reference,
    /// or no reference).
    pub fn set_reference(&mut self, id: [u8; 8]) -> Option<[u8; 8]> {
        let r = self.reference_imu.as_mut()?;
        if *r == id {
            return None;
        }
        let previous = *r;
        *r = id;
        // The new reference's newest sample so far (waiting, or consumed) is the watermark.
        let waiting = self.slots.iter().flatten().filter_map(|(s, _)| match s {
            Input::Imu(x) if x.imu_id == id => Some(x.stamp.host_ns),
            _ => None,
        });
        let consumed = self.last_popped.map_or(i64::MIN, |k| k.at_ns);
        self.watermark = waiting.fold(self.watermark.max(consumed), i64::max);
        Some(previous)
    }

    /// Live processes, once per wake-up with the host clock (ns): true when samples wait and
    /// the reference IMU has not advanced for [`STALL_NS`]; then consume them with
    /// [`pop_any`](Self::pop_any).
    pub fn stalled(&mut self, now_ns: i64) -> bool {
        if self.heap.is_empty() || self.watermark != self.seen_watermark || self.progress_at_ns.is_none() {
            self.seen_watermark = self.watermark;
            self.progress_at_ns = Some(now_ns);
            return false;
        }
        self.progress_at_ns.is_some_and(|t| now_ns - t > STALL_NS)
    }

    /// PPS edges, fixes and samples of non-reference IMUs that arrived after their slot
    /// (consumed out of order).
    pub fn late(&self) -> u64 {
        self.late
    }

    /// Samples waiting.
    pub fn len(&self) -> usize {
        self.heap.len()
    }

    /// True when no sample waits.
    pub fn is_empty(&self) -> bool {
        self.heap.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use navsync_wire::reflect::Reflect;
    use navsync_wire::samples::{GnssFix, ImuSample, PpsEdge, Stamp, StampSource};

    use super::*;

    const MS: i64 = 1_000_000;

    fn imu(id: &str, t_ms: i64) -> AnySample {
        let mut s = ImuSample::zeroed();
        s.stamp = Stamp::host(t_ms * MS, t_ms as u64, StampSource::Simulated);
        s.imu_id = fixed_str(id);
        AnySample::Imu(s)
    }
    fn pps(t_ms: i64) -> AnySample {
        let mut e = PpsEdge::zeroed();
        e.stamp = Stamp::host(t_ms * MS, 0, StampSource::Simulated);
        AnySample::PpsEdge(e)
    }
    fn fix(t_ms: i64) -> AnySample {
        AnySample::GnssFix(GnssFix::empty(Stamp::host(t_ms * MS, 0, StampSource::Receipt)))
    }
    fn name(s: &Input) -> String {
        match s {
            Input::Imu(x) => format!(
                "imu{}@{}",
                navsync_wire::reflect::str_of(&x.imu_id),
                x.stamp.host_ns / MS
            ),
            Input::PpsEdge(e) => format!("pps@{}", e.stamp.host_ns / MS),
            Input::GnssFix(f) => format!("fix@{}", f.stamp.host_ns / MS),
            _ => "?".into(),
        }
    }

    /// Consumes `batches` (each pushed at once, then drained) and returns the order.
    #[test]
    fn an_input_keeps_the_key_of_its_sample() {
        use navsync_wire::reflect::Reflect;
        use navsync_wire::samples::{Health, NavState, Stamp, StampSource};
        let st = Stamp::host(123_456_789, 42, StampSource::Simulated);
        let mut fix = GnssFix::empty(st);
        fix.stamp.seq = 3;
        let mut tp = GnssTimePulse::zeroed();
        tp.stamp = st;
        let mut truth = SimTruth::zeroed();
        truth.host_ns = 99;
        truth.seq = 7;
        let mut nav = NavState::zeroed();
        nav.host_ns = 5;
        nav.seq = 9;
        let mut h = Health::zeroed();
        h.host_ns = 8;
        for s in [
            imu("3", 17),
            AnySample::GnssFix(fix),
            AnySample::TimePulse(tp),
            AnySample::Truth(truth),
            AnySample::Nav(nav),
            AnySample::Health(h),
        ] {
            assert_eq!(Input::from(s).key(), order_key(&s), "{s:?}");
        }
        let mut e = PpsEdge::zeroed();
        e.stamp = st;
        assert_eq!(
            Input::from(AnySample::PpsEdge(e)).key(),
            order_key(&AnySample::PpsEdge(e))
        );
        assert!(size_of::<Input>() < size_of::<AnySample>() / 8);
    }

    fn consume(batches: &[Vec<AnySample>]) -> (Vec<String>, u64) {
        let mut o = InputOrder::new(Some("0"));
        let mut out = Vec::new();
        for b in batches {
            for s in b {
                o.push(*s, ());
            }
            while let Some((s, ())) = o.pop() {
                out.push(name(&s));
            }
        }
        while let Some((s, ())) = o.pop_any() {
            out.push(name(&s));
        }
        (out, o.late())
    }

    #[test]
    fn the_order_does_not_depend_on_how_samples_were_batched() {
        // IMU every 5 ms, a PPS edge at 1000 ms (with the IMU sample of the same instant), a
        // fix stamped at 600 ms and published at 690 ms.
        let mut published: Vec<AnySample> = Vec::new();
        for t in (900..1300).step_by(5) {
            if t == 1000 {
                published.push(pps(1000));
            }
            if t == 690 + 300 {
                published.push(fix(600 + 300));
            }
            published.push(imu("0", t));
            published.push(imu("1", t + 2));
        }
        let one_by_one: Vec<Vec<AnySample>> = published.iter().map(|s| vec![*s]).collect();
        let (reference, late) = consume(&one_by_one);
        assert_eq!(late, 0);
        // The edge right before the first IMU sample at or after 1050 ms; the fix before 1100 ms.
        let at = |n: &str| reference.iter().position(|x| x == n).unwrap();
        assert_eq!(at("pps@1000") + 1, at("imu0@1050"));
        assert_eq!(at("fix@900") + 1, at("imu0@1100"));
        // Any batching of the same publication order, and any drain order within a batch
        // (IMU services first, as the live process does, or reversed), gives the same order.
        for size in [2, 3, 7, 20, 64, 500] {
            for reversed in [false, true] {
                let batches: Vec<Vec<AnySample>> = published
                    .chunks(size)
                    .map(|c| {
                        let mut v = c.to_vec();
                        v.sort_by_key(|s| !matches!(s, AnySample::Imu(_)));
                        if reversed {
                            v.reverse();
                        }
                        v
                    })
                    .collect();
                assert_eq!(consume(&batches), (reference.clone(), 0), "batches of {size}");
            }
        }
    }

    #[test]
    fn late_samples_are_counted_and_stalls_detected() {
        let mut o = InputOrder::new(Some("0"));
        o.push(imu("0", 1000), ());
        while o.pop().is_some() {}
        o.push(fix(500), ()); // due at 700 ms, arrives after 1000 ms was consumed
        assert!(o.pop().is_some());
        assert_eq!(o.late(), 1);
        o.push(pps(1100), ());
        assert!(o.pop().is_none(), "waits for the IMU");
        assert!(!o.stalled(0));
        assert!(!o.stalled(STALL_NS));
        assert!(o.stalled(STALL_NS + 1));
        assert!(o.pop_any().is_some());
        // Without a reference IMU everything is due at once.
        let mut o = InputOrder::new(None);
        o.push(fix(5), ());
        assert!(o.pop().is_some());
    }

    #[test]
    fn a_silent_reference_releases_the_others_after_a_lag_and_a_new_one_without() {
        let mut o = InputOrder::new(Some("0"));
        let mut out = Vec::new();
        let drain = |o: &mut InputOrder, out: &mut Vec<String>| {
            while let Some((s, ())) = o.pop() {
                out.push(name(&s));
            }
        };
        // Both IMUs every 5 ms up to 1000 ms; then only IMU 1.
        for t in (900..=1000).step_by(5) {
            o.push(imu("0", t), ());
            o.push(imu("1", t + 1), ());
            drain(&mut o, &mut out);
        }
        assert_eq!(out.last().map(String::as_str), Some("imu0@1000"), "{out:?}");
        for t in (1005..1100).step_by(5) {
            o.push(imu("1", t + 1), ());
            drain(&mut o, &mut out);
        }
        assert_eq!(
            out.last().map(String::as_str),
            Some("imu0@1000"),
            "waits while the lead is short"
        );
        o.push(imu("1", 1151), ());
        drain(&mut o, &mut out);
        // Everything up to 100 ms behind IMU 1's newest sample is due.
        assert_eq!(out.last().map(String::as_str), Some("imu1@1051"), "{out:?}");
        // The consumer hands over to IMU 1: no lag from then on.
        assert_eq!(o.set_reference(fixed_str("1")), Some(fixed_str("0")));
        drain(&mut o, &mut out);
        assert_eq!(out.last().map(String::as_str), Some("imu1@1151"));
        o.push(pps(1110), ());
        o.push(imu("1", 1156), ());
        o.push(imu("1", 1161), ());
        drain(&mut o, &mut out);
        assert_eq!(
            out[out.len() - 3..],
            ["imu1@1156", "pps@1110", "imu1@1161"].map(String::from)
        );
        assert_eq!(o.late(), 0);
    }
}
