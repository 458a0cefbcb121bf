//! The simulated world: a deterministic, time-ordered stream of sensor events.
//!
//! [`World`] merges the event streams of the IMUs, the PPS output, the GNSS receiver's NMEA
//! bursts and the ground truth by host time. It is a pure function of (configuration, seed,
//! start host time, start UTC): no clocks, threads, I/O or IPC; the process shell paces the
//! events in real time and writes NMEA bytes to a pseudo-terminal at [`World::baud`].
//!
//! Time scales: scenario time τ (s since the start, true time), UTC ns (τ = 0 at
//! `start_utc_ns`; UTC is the true time the GNSS receiver realises) and host ns
//! (CLOCK_MONOTONIC, related to true time by the [`Oscillator`]).

use navsync_shared::samples::{ImuSample, MAX_IMUS, PpsEdge, SimTruth};

use super::error::SimError;
use super::gnss_receiver::{GnssReceiver, NmeaBurst};
use super::imu_stream::ImuStream;
use super::oscillator::Oscillator;
use super::pps::PpsGenerator;
use super::rng::{Rng, streams};
use super::scenario::{OutputProtocol, SimConfig};
use super::trajectory::Trajectory;
use super::truth::{TruthConstants, sim_truth};

pub use super::truth::TruthState;

#[cfg(test)]
#[path = "strapdown_check.rs"]
mod strapdown_check;

/// One event of the simulated world, ordered by host time.
#[derive(Debug, Clone, PartialEq)]
pub enum SimEvent {
    /// A sample of IMU `index` (host time `sample.stamp.host_ns`).
    Imu {
        /// Index of the IMU in the array (0-based; `sample.imu_id` is its ASCII form).
        index: usize,
        /// The sample.
        sample: ImuSample,
    },
    /// A PPS edge (host time `stamp.host_ns`).
    Pps(PpsEdge),
    /// One epoch's NMEA burst; its first byte leaves the receiver at host time `host_ns`; the
    /// shell paces the rest at `baud`.
    Nmea {
        /// Host time of the first byte, ns.
        host_ns: i64,
        /// The epoch the sentences describe, UTC ns.
        epoch_utc_ns: i64,
        /// The sentences, each `$…*hh\r\n`.
        bytes: Vec<u8>,
    },
    /// Ground truth (host time `host_ns`).
    Truth(SimTruth),
}

impl SimEvent {
    /// Host time of the event, ns.
    pub fn host_ns(&self) -> i64 {
        match self {
            Self::Imu { sample, .. } => sample.stamp.host_ns,
            Self::Pps(e) => e.stamp.host_ns,
            Self::Nmea { host_ns, .. } => *host_ns,
            Self::Truth(t) => t.host_ns,
        }
    }
}

/// Which stream an event head belongs to; the declaration order breaks host-time ties.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Source {
    Pps,
    Nmea,
    Imu(usize),
    Truth,
}

/// Ground-truth event generator on a UTC grid.
#[derive(Debug, Clone)]
struct TruthStream {
    period_ns: i64,
    next_k: u64,
    end_utc_ns: i64,
    constants: TruthConstants,
}

/// The simulated sensor world.
#[derive(Debug, Clone)]
pub struct World {
    traj: Trajectory,
    osc: Oscillator,
    imus: Vec<ImuStream>,
    imu_heads: Vec<Option<ImuSample>>,
    pps: PpsGenerator,
    pps_head: Option<PpsEdge>,
    gnss: GnssReceiver,
    nmea_head: Option<NmeaBurst>,
    truth: TruthStream,
    truth_head: Option<SimTruth>,
    start_utc_ns: i64,
    duration_s: f64,
    baud: u32,
    gnss_protocol: OutputProtocol,
}

impl World {
    /// Builds the world of a configuration (validated here) starting at host time
    /// `start_host_ns` and UTC `start_utc_ns` (both ns).
    pub fn new(cfg: &SimConfig, start_host_ns: i64, start_utc_ns: i64) -> Result<Self, SimError> {
        cfg.validate()?;
        let traj = Trajectory::from_config(&cfg.trajectory, cfg.seed);
        let duration_s = traj.duration_s();
        let osc = Oscillator::new(
            start_host_ns,
            start_utc_ns,
            cfg.clock.freq_error_ppm * 1e-6,
            cfg.clock.freq_rw_adev_1s,
            oscillator_span_s(cfg, duration_s),
            &mut Rng::stream(cfg.seed, streams::OSCILLATOR),
        );
        // The GNSS receiver's oscillator, for IMUs sampling on it (the receiver's sky draws the
        // same clock from the same arguments).
        let receiver_clock = crate::gps::ReceiverClock::new(&cfg.gnss.sky, cfg.seed, start_utc_ns, duration_s);
        let imus: Vec<ImuStream> = (0..cfg.imu.count)
            .map(|i| ImuStream::new(i, cfg.imu_unit(i), cfg.seed, duration_s, Some(&receiver_clock)))
            .collect();
        let mut imu_offset_s = [0.0; MAX_IMUS];
        for (slot, imu) in imu_offset_s.iter_mut().zip(&imus) {
            *slot = imu.config().offset_s - cfg.imu_unit(0).offset_s;
        }
        let truth = TruthStream {
            period_ns: (1e9 / cfg.truth.rate_hz).round() as i64,
            next_k: 0,
            end_utc_ns: start_utc_ns + (duration_s * 1e9).round() as i64,
            constants: TruthConstants {
                gnss_latency_s: cfg.gnss.latency_s,
                imu_offset_s,
                imu_count: imus.len() as u8,
            },
        };
        let mut world = Self {
            imu_heads: vec![None; imus.len()],
            imus,
            pps: PpsGenerator::new(
                cfg.seed,
                start_utc_ns,
                duration_s,
                cfg.clock.pps_jitter_s,
                cfg.gnss.timepulse_quantization_ns,
                &cfg.gnss.outages,
                &cfg.clock.pps_outages,
            ),
            pps_head: None,
            gnss: GnssReceiver::new(&cfg.gnss, cfg.seed, start_utc_ns, duration_s),
            nmea_head: None,
            truth,
            truth_head: None,
            traj,
            osc,
            start_utc_ns,
            duration_s,
            baud: cfg.gnss.baud,
            gnss_protocol: cfg.gnss.protocol,
        };
        world.prime();
        Ok(world)
    }

    fn prime(&mut self) {
        for i in 0..self.imus.len() {
            self.refill(Source::Imu(i));
        }
        self.refill(Source::Pps);
        self.refill(Source::Nmea);
        self.refill(Source::Truth);
    }

    /// Generates the next head of stream `src`.
    fn refill(&mut self, src: Source) {
        match src {
            Source::Imu(i) => {
                if let (Some(imu), Some(head)) = (self.imus.get_mut(i), self.imu_heads.get_mut(i)) {
                    *head = imu.next_sample(&self.traj, &self.osc);
                }
            }
            Source::Pps => self.pps_head = self.pps.next_edge(&self.osc),
            Source::Nmea => self.nmea_head = self.gnss.next_burst(&self.traj, &self.osc),
            Source::Truth => self.truth_head = self.next_truth(),
        }
    }

    fn next_truth(&mut self) -> Option<SimTruth> {
        let k = self.truth.next_k;
        let utc_grid = self.start_utc_ns + k as i64 * self.truth.period_ns;
        if utc_grid > self.truth.end_utc_ns {
            return None;
        }
        self.truth.next_k += 1;
        let host_ns = self.osc.host_ns_at_utc(utc_grid);
        let utc_ns = self.osc.utc_ns_at_host(host_ns);
        let tau = self.osc.tau_of_utc(utc_ns);
        let state = TruthState::at(&self.traj, utc_ns, tau);
        Some(sim_truth(
            &state,
            host_ns,
            k,
            self.osc.freq_error(tau),
            &self.truth.constants,
        ))
    }

    /// The stream whose head has the smallest host time (ties: PPS, NMEA, IMUs, truth).
    fn earliest(&self) -> Option<Source> {
        let mut best: Option<(i64, Source)> = None;
        let mut consider = |t: i64, s: Source| {
            if best.is_none_or(|(bt, _)| t < bt) {
                best = Some((t, s));
            }
        };
        if let Some(e) = &self.pps_head {
            consider(e.stamp.host_ns, Source::Pps);
        }
        if let Some(b) = &self.nmea_head {
            consider(b.host_ns, Source::Nmea);
        }
        for (i, head) in self.imu_heads.iter().enumerate() {
            if let Some(s) = head {
                consider(s.stamp.host_ns, Source::Imu(i));
            }
        }
        if let Some(t) = &self.truth_head {
            consider(t.host_ns, Source::Truth);
        }
        best.map(|(_, s)| s)
    }

    /// The next event in host-time order (non-decreasing `host_ns`); `None` after the end.
    pub fn next_event(&mut self) -> Option<SimEvent> {
        let src = self.earliest()?;
        let event = match src {
            Source::Imu(i) => {
                let sample = self.imu_heads.get_mut(i)?.take()?;
                SimEvent::Imu { index: i, sample }
            }
            Source::Pps => SimEvent::Pps(self.pps_head.take()?),
            Source::Nmea => {
                let b = self.nmea_head.take()?;
                SimEvent::Nmea {
                    host_ns: b.host_ns,
                    epoch_utc_ns: b.epoch_utc_ns,
                    bytes: b.bytes,
                }
            }
            Source::Truth => SimEvent::Truth(self.truth_head.take()?),
        };
        self.refill(src);
        Some(event)
    }

    /// Scenario length, s of true time.
    pub fn duration_s(&self) -> f64 {
        self.duration_s
    }

    /// UTC at the scenario start, ns.
    pub fn start_utc_ns(&self) -> i64 {
        self.start_utc_ns
    }

    /// UTC at the scenario end, ns.
    pub fn end_utc_ns(&self) -> i64 {
        self.osc.utc_of_tau(self.duration_s)
    }

    /// Exact kinematic and inertial truth at a UTC instant (clamped to the scenario).
    pub fn truth_at_utc(&self, utc_ns: i64) -> TruthState {
        TruthState::at(&self.traj, utc_ns, self.osc.tau_of_utc(utc_ns))
    }

    /// Host time (CLOCK_MONOTONIC ns) of a UTC instant: the true oscillator mapping.
    pub fn host_ns_at_utc(&self, utc_ns: i64) -> i64 {
        self.osc.host_ns_at_utc(utc_ns)
    }

    /// UTC of a host time: the inverse of [`World::host_ns_at_utc`] (to within 1 ns).
    pub fn utc_ns_at_host(&self, host_ns: i64) -> i64 {
        self.osc.utc_ns_at_host(host_ns)
    }

    /// True fractional frequency error y = d(host)/d(UTC) − 1 of the host clock at a UTC instant.
    pub fn host_freq_error_at_utc(&self, utc_ns: i64) -> f64 {
        self.osc.freq_error(self.osc.tau_of_utc(utc_ns))
    }

    /// Serial baud rate at which the shell paces NMEA bytes.
    pub fn baud(&self) -> u32 {
        self.baud
    }

    /// What the simulated receiver writes.
    pub fn gnss_protocol(&self) -> OutputProtocol {
        self.gnss_protocol
    }

    /// Number of IMUs.
    pub fn imu_count(&self) -> usize {
        self.imus.len()
    }

    /// True UTC of the end of IMU `index`'s sample `seq` (its data is the average over the
    /// sample period ending there), ns; `None` for an unknown IMU.
    pub fn imu_sample_utc_ns(&self, index: usize, seq: u64) -> Option<i64> {
        let imu = self.imus.get(index)?;
        Some(self.osc.utc_of_tau(imu.sample_time_s(seq)))
    }

    /// The camera on the receiver's EXTINT0 input (UBX with a camera): its exposures are the
    /// truth of the time marks the receiver reports (TIM-TM2 → `navsync/gnss/0/event`), and
    /// [`World::truth_at_utc`] of an exposure's instant the pose at it.
    pub fn camera(&self) -> Option<&crate::camera::Camera> {
        self.gnss.camera()
    }

    /// IMU `index`'s generator (configuration, mount, drawn errors), for evaluation.
    pub fn imu(&self, index: usize) -> Option<&ImuStream> {
        self.imus.get(index)
    }

    /// The trajectory (closed-form kinematics and position table).
    pub fn trajectory(&self) -> &Trajectory {
        &self.traj
    }

    /// The host oscillator.
    pub fn oscillator(&self) -> &Oscillator {
        &self.osc
    }
}

/// True-time span the oscillator table must cover: every stamp is at most the largest
/// latency or IMU offset after the end.
fn oscillator_span_s(cfg: &SimConfig, duration_s: f64) -> f64 {
    let max_offset = (0..cfg.imu.count).map(|i| cfg.imu_unit(i).offset_s).fold(0.0, f64::max);
    duration_s + cfg.gnss.latency_s + 6.0 * cfg.gnss.latency_jitter_s + max_offset + 2.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::imu_errors::ImuPreset;
    use crate::nmea::tests::parse_burst;
    use nalgebra::Vector3;
    use navsync_shared::earth;
    use navsync_shared::samples::StampSource;

    const H0: i64 = 5_000_000_000_000;
    const U0: i64 = 1_790_000_000_400_000_000;

    /// The default drive cut to its first `seconds` (the last kept segment is shortened).
    fn short_cfg(seconds: f64) -> SimConfig {
        let mut cfg = SimConfig::default_drive();
        let mut t0 = 0.0;
        cfg.trajectory.segments.retain_mut(|s| {
            let keep = t0 < seconds;
            s.duration_s = s.duration_s.min(seconds - t0);
            t0 += s.duration_s;
            keep
        });
        cfg
    }

    #[test]
    fn same_seed_same_events_other_seed_other_noise() {
        let cfg = short_cfg(60.0);
        let mut a = World::new(&cfg, H0, U0).expect("world");
        let mut b = World::new(&cfg, H0, U0).expect("world");
        let mut n = 0;
        loop {
            let (ea, eb) = (a.next_event(), b.next_event());
            assert_eq!(ea, eb);
            if ea.is_none() {
                break;
            }
            n += 1;
        }
        assert!(n > 40_000, "{n} events");
        let mut other = cfg.clone();
        other.set_seed(cfg.seed + 1);
        let mut c = World::new(&other, H0, U0).expect("world");
        let mut a = World::new(&cfg, H0, U0).expect("world");
        let differs = (0..1000).any(|_| a.next_event() != c.next_event());
        assert!(differs);
    }

    #[test]
    fn full_default_drive_is_ordered_and_complete() {
        let cfg = SimConfig::default_drive();
        let mut w = World::new(&cfg, H0, U0).expect("world");
        let d = w.duration_s();
        let mut last = i64::MIN;
        let mut imu_counts = [0usize; MAX_IMUS];
        let mut imu_seq = [0u64; MAX_IMUS];
        let (mut pps, mut nmea, mut truth) = (0, 0, 0);
        while let Some(e) = w.next_event() {
            assert!(e.host_ns() >= last, "host time went back: {e:?}");
            last = e.host_ns();
            match &e {
                SimEvent::Imu { index, sample } => {
                    assert_eq!(sample.stamp.seq, imu_seq[*index]);
                    assert_eq!(sample.stamp.source(), StampSource::Simulated);
                    assert_eq!(sample.imu_id[0], b'0' + *index as u8);
                    assert!((sample.dt_s - 0.005).abs() < 1e-15);
                    imu_seq[*index] += 1;
                    imu_counts[*index] += 1;
                }
                SimEvent::Pps(p) => {
                    assert_eq!(p.stamp.seq, pps as u64);
                    assert_eq!(p.assert_edge, 1);
                    assert!((p.jitter_ns - 1000.0).abs() < 1e-9);
                    pps += 1;
                }
                SimEvent::Nmea { bytes, .. } => {
                    parse_burst(bytes);
                    nmea += 1;
                }
                SimEvent::Truth(t) => {
                    assert_eq!(t.imu_count, 4);
                    assert_eq!(t.imu_offset_s[..4], [0.0, 0.010, 0.015, 0.020]);
                    assert!((t.gnss_latency_s - 0.6).abs() < 1e-15);
                    truth += 1;
                }
            }
        }
        for (i, &c) in imu_counts[..4].iter().enumerate() {
            let expected = ((d - w.imu(i).expect("imu").config().phase_s) * 200.0).floor() as usize;
            assert!(c.abs_diff(expected) <= 1, "IMU {i}: {c} vs {expected}");
        }
        assert_eq!(pps, d.floor() as usize, "one edge per whole UTC second");
        assert_eq!(nmea, pps);
        assert_eq!(truth, (d * 100.0).floor() as usize + 1);
    }

    #[test]
    fn pps_spacing_follows_the_host_frequency_error() {
        let mut cfg = short_cfg(120.0);
        cfg.set_pps_jitter_s(0.0);
        cfg.set_clock_rw_adev_1s(0.0);
        let mut w = World::new(&cfg, H0, U0).expect("world");
        let edges: Vec<i64> = std::iter::from_fn(|| w.next_event())
            .filter_map(|e| {
                if let SimEvent::Pps(p) = e {
                    Some(p.stamp.host_ns)
                } else {
                    None
                }
            })
            .collect();
        for pair in edges.windows(2) {
            let d = pair[1] - pair[0];
            assert!((d - 1_000_000_500).abs() <= 1, "spacing {d}");
        }
        // With the default jitter and frequency wander the mean spacing is still (1 + y)·1 s.
        let cfg = short_cfg(300.0);
        let mut w = World::new(&cfg, H0, U0).expect("world");
        let edges: Vec<i64> = std::iter::from_fn(|| w.next_event())
            .filter_map(|e| {
                if let SimEvent::Pps(p) = e {
                    Some(p.stamp.host_ns)
                } else {
                    None
                }
            })
            .collect();
        let n = edges.len() as f64 - 1.0;
        let mean = (edges[edges.len() - 1] - edges[0]) as f64 / n;
        assert!((mean - 1_000_000_500.0).abs() < 20.0, "mean spacing {mean}");
        // Each edge is at host(T) within a few σ of jitter.
        let first_sec = (U0 / 1_000_000_000 + 1) * 1_000_000_000;
        for (i, h) in edges.iter().enumerate() {
            let t = first_sec + i as i64 * 1_000_000_000;
            assert!((h - w.host_ns_at_utc(t)).abs() < 6_000, "edge {i}");
        }
    }

    #[test]
    fn imu_stamps_are_late_by_their_offsets() {
        let mut cfg = short_cfg(40.0);
        cfg.set_imu_stamp_jitter_s(0.0);
        let mut w = World::new(&cfg, H0, U0).expect("world");
        let mut seen = [false; 4];
        while let Some(e) = w.next_event() {
            if let SimEvent::Imu { index, sample } = e {
                let imu = w.imu(index).expect("imu");
                let t = imu.sample_time_s(sample.stamp.seq);
                let expected = w.oscillator().host_ns_at_tau(t + imu.config().offset_s);
                assert_eq!(sample.stamp.host_ns, expected);
                seen[index] = true;
            }
        }
        assert_eq!(seen, [true; 4]);
    }

    #[test]
    fn perfect_imu_at_rest_reads_gravity_and_earth_rate() {
        let mut cfg = short_cfg(40.0);
        cfg.set_noise_free();
        let mut w = World::new(&cfg, H0, U0).expect("world");
        let start = cfg.trajectory.start.clone();
        let lat = start.lat_deg.to_radians();
        let g = earth::normal_gravity(lat, start.height_m);
        let truth = w.truth_at_utc(U0 + 10_000_000_000);
        let w_ie_b = truth.c_b_n.transpose() * Vector3::from(earth::omega_ie_n(lat));
        let mut n = 0;
        while let Some(e) = w.next_event() {
            if let SimEvent::Imu { sample, .. } = e {
                // Relative tolerance ulp(t)/T ≈ 1e-12 at t = 40 s: the sample intervals are
                // [t_{k−1}, t_k] as rounded in f64 (they tile time exactly, so increments sum
                // to the exact integral, while each average carries that relative rounding).
                let a = sample.accel_mps2;
                assert!(
                    a[0].abs() < 1e-12 && a[1].abs() < 1e-12 && (a[2] + g).abs() < 1e-11,
                    "{a:?}"
                );
                for k in 0..3 {
                    assert!((sample.gyro_rps[k] - w_ie_b[k]).abs() < 1e-12 * earth::OMEGA_IE);
                }
                n += 1;
            }
        }
        assert!(n > 4 * 200 * 30);
    }

    #[test]
    fn consumer_imu_at_rest_averages_to_truth_plus_its_bias() {
        let cfg = short_cfg(40.0);
        assert_eq!(cfg.imu.preset, ImuPreset::Consumer);
        let mut w = World::new(&cfg, H0, U0).expect("world");
        let truth = w.truth_at_utc(U0 + 10_000_000_000);
        let mut sum_a = Vector3::zeros();
        let mut sum_w = Vector3::zeros();
        let mut n = 0.0;
        while let Some(e) = w.next_event() {
            if let SimEvent::Imu { index: 2, sample } = e {
                sum_a += Vector3::from(sample.accel_mps2);
                sum_w += Vector3::from(sample.gyro_rps);
                n += 1.0;
            }
        }
        let errs = w.imu(2).expect("imu").errors();
        for k in 0..3 {
            let sf_a = 1.0 + errs.accel.scale_factor[k];
            let expected_a = sf_a * truth.f_ib_b[k] + errs.accel.bias[k];
            // Noise of the mean: σ·√(1/n) ≈ 0.014/√7800 m/s²; plus the GM bias (≤ ~0.003 m/s²).
            assert!(
                (sum_a[k] / n - expected_a).abs() < 0.004,
                "accel {k}: {} vs {expected_a}",
                sum_a[k] / n
            );
            let expected_w = (1.0 + errs.gyro.scale_factor[k]) * truth.omega_ib_b[k] + errs.gyro.bias[k];
            assert!((sum_w[k] / n - expected_w).abs() < 2e-4, "gyro {k}");
        }
    }

    #[test]
    fn truth_events_and_oscillator_mapping() {
        let cfg = short_cfg(60.0);
        let mut w = World::new(&cfg, H0, U0).expect("world");
        assert_eq!(w.host_ns_at_utc(U0), H0);
        assert_eq!(w.utc_ns_at_host(H0), U0);
        while let Some(e) = w.next_event() {
            if let SimEvent::Truth(t) = e {
                assert!((w.utc_ns_at_host(t.host_ns) - t.utc_ns).abs() <= 1);
                let y = w.host_freq_error_at_utc(t.utc_ns);
                assert!((t.rate_error - (1.0 / (1.0 + y) - 1.0)).abs() < 1e-18);
                assert!((t.rate_error + 0.5e-6).abs() < 1e-8);
                let s = w.truth_at_utc(t.utc_ns);
                assert!((s.lat_rad.to_degrees() - t.lat_deg).abs() < 1e-12);
                assert_eq!(t.vel_ned_mps, [s.v_ned[0], s.v_ned[1], s.v_ned[2]]);
            }
        }
    }

    #[test]
    fn nmea_bursts_leave_after_the_latency() {
        let mut cfg = short_cfg(30.0);
        cfg.set_nmea_latency_s(1.3);
        cfg.set_gnss_rate_hz(10);
        let mut w = World::new(&cfg, H0, U0).expect("world");
        let mut n = 0;
        while let Some(e) = w.next_event() {
            if let SimEvent::Nmea {
                host_ns,
                epoch_utc_ns,
                bytes,
            } = e
            {
                assert_eq!(host_ns, w.host_ns_at_utc(epoch_utc_ns + 1_300_000_000));
                assert_eq!(epoch_utc_ns % 100_000_000, 0);
                let s = parse_burst(&bytes);
                let c = navsync_shared::time::civil_from_utc_ns(epoch_utc_ns);
                assert_eq!(
                    s[2][1],
                    format!(
                        "{:02}{:02}{:02}.{:02}",
                        c.hour,
                        c.minute,
                        c.second,
                        c.nanos / 10_000_000
                    )
                );
                n += 1;
            }
        }
        assert!(n >= 290);
    }

    #[test]
    fn outage_without_pps_silences_edges_and_fix() {
        let mut cfg = short_cfg(100.0);
        cfg.gnss.outages = vec![
            crate::scenario::OutageConfig {
                start_s: 50.0,
                duration_s: 10.0,
                pps_continues: false,
            },
            crate::scenario::OutageConfig {
                start_s: 70.0,
                duration_s: 5.0,
                pps_continues: true,
            },
        ];
        let mut w = World::new(&cfg, H0, U0).expect("world");
        let (mut edges, mut no_fix) = (Vec::new(), 0);
        while let Some(e) = w.next_event() {
            match e {
                SimEvent::Pps(p) => edges.push((p.stamp.seq, w.utc_ns_at_host(p.stamp.host_ns))),
                SimEvent::Nmea { bytes, .. } => no_fix += usize::from(parse_burst(&bytes)[2][6] == "0"),
                _ => {}
            }
        }
        let in_silence = |u: i64| {
            let tau = (u - U0) as f64 * 1e-9;
            (50.0..60.0).contains(&tau)
        };
        assert!(edges.iter().all(|&(_, u)| !in_silence(u)));
        assert_eq!(edges.len(), 100 - 10);
        assert!(
            edges.iter().enumerate().all(|(i, &(s, _))| s == i as u64),
            "seq counts edges"
        );
        assert_eq!(no_fix, 15);
    }

    #[test]
    fn pps_outage_silences_edges_only() {
        let mut cfg = short_cfg(60.0);
        cfg.clock.pps_outages = vec![crate::scenario::PpsOutageConfig {
            start_s: 20.0,
            duration_s: 15.0,
        }];
        let mut w = World::new(&cfg, H0, U0).expect("world");
        let (mut edges, mut no_fix, mut bursts) = (Vec::new(), 0, 0);
        while let Some(e) = w.next_event() {
            match e {
                SimEvent::Pps(p) => edges.push(w.utc_ns_at_host(p.stamp.host_ns)),
                SimEvent::Nmea { bytes, .. } => {
                    bursts += 1;
                    no_fix += usize::from(parse_burst(&bytes)[2][6] == "0");
                }
                _ => {}
            }
        }
        let tau = |u: i64| (u - U0) as f64 * 1e-9;
        assert!(edges.iter().all(|&u| !(20.0..35.0).contains(&tau(u))));
        assert_eq!(edges.len(), 60 - 15);
        assert!(bursts >= 59 && no_fix == 0, "{bursts} bursts, {no_fix} without a fix");
    }

    #[test]
    fn imu_sample_times_and_utc() {
        let w = World::new(&short_cfg(10.0), H0, U0).expect("world");
        // IMU 1: phase 1.1 ms, 200 Hz: sample 0 ends at 6.1 ms.
        assert_eq!(w.imu_sample_utc_ns(1, 0), Some(U0 + 6_100_000));
        assert_eq!(w.imu_sample_utc_ns(9, 0), None);
    }

    #[test]
    fn invalid_config_is_an_error_not_a_panic() {
        let mut cfg = SimConfig::default_drive();
        cfg.set_imu_count(0);
        assert!(World::new(&cfg, H0, U0).is_err());
    }
}
