//! One simulated IMU: its sample grid, true averaged outputs, sensor errors and host stamps.
//!
//! Sample k (seq = k) carries the sensor-frame averages over [t_{k−1}, t_k] of scenario time,
//! t_k = (phase + (k + 1)·T) / (1 + y), T = 1/rate, y the frequency error of the crystal the
//! IMU samples on (0 unless IMUs sample on their own clocks: `imu.device_clocks`), as
//! increment / T (the nominal period, as a device reports it), with the intervals tiling
//! time exactly (sample k's interval starts at t_{k−1} as computed for sample k − 1). An IMU
//! on the GNSS receiver's oscillator (`imu.unit[i].receiver_clock`) instead ends sample k
//! when the receiver's clock reads R_k = R + (k + 1)·T (R the first multiple of T at or
//! after its reading at the start, plus the phase): t_k solves t + b(t) = R_k
//! ([`ReceiverClock::tau_at_reading`]), and R_k is the stamp's device time. Each sample is
//! stamped at host(t_k + Td) + N(0, σ²): stamps
//! are late by the IMU's offset Td (its delay relative to true time; IMU 0 is the reference
//! with Td = 0 by default). A stamp is never earlier than the previous one of the same IMU.
//! Producing a sample does not allocate.

use nalgebra::Vector3;
use navsync_shared::samples::{IMU_FLAG_RECEIVER_CLOCK, IMU_FLAG_SATURATED, ImuSample, Stamp, StampSource};

use super::gps::ReceiverClock;
use super::imu_errors::ImuErrorState;
use super::inverse_mechanization::{ImuMount, SAMPLE_RULE, increments};
use super::oscillator::Oscillator;
use super::rng::{Rng, streams};
use super::scenario::ResolvedImu;
use super::trajectory::Trajectory;

/// One IMU's generator state.
#[derive(Debug, Clone)]
pub struct ImuStream {
    index: usize,
    id: [u8; 8],
    cfg: ResolvedImu,
    period_s: f64,
    mount: ImuMount,
    errors: ImuErrorState,
    error_rng: Rng,
    stamp_rng: Rng,
    k: u64,
    end_s: f64,
    last_host_ns: i64,
    /// The receiver's clock and R, its reading at the start of sample 0 (the first multiple
    /// of T at or after its reading at the scenario start, plus the phase), ns, when the IMU
    /// samples on it.
    receiver: Option<(ReceiverClock, i64)>,
}

impl ImuStream {
    /// IMU `index` of a world with seed `seed` lasting `duration_s`; `receiver_clock` is the
    /// GNSS receiver's oscillator, which it samples on when `cfg.receiver_clock`.
    pub fn new(
        index: usize,
        cfg: ResolvedImu,
        seed: u64,
        duration_s: f64,
        receiver_clock: Option<&ReceiverClock>,
    ) -> Self {
        let period_s = 1.0 / cfg.rate_hz;
        let receiver = receiver_clock.filter(|_| cfg.receiver_clock).map(|c| {
            let period_ns = (period_s * 1e9).round() as i64;
            let first = (c.reading_ns(0.0) + period_ns - 1).div_euclid(period_ns) * period_ns
                + (cfg.phase_s * 1e9).round() as i64;
            (c.clone(), first)
        });
        let mut error_rng = Rng::stream(seed, streams::IMU_ERRORS + index as u64);
        let errors = ImuErrorState::new(&cfg.preset.spec(), period_s, &mut error_rng);
        Self {
            index,
            id: imu_id(index),
            cfg,
            period_s,
            mount: ImuMount::new(cfg.mount_rpy_rad, cfg.lever_arm_m),
            errors,
            error_rng,
            stamp_rng: Rng::stream(seed, streams::IMU_STAMPS + index as u64),
            k: 0,
            end_s: duration_s,
            last_host_ns: i64::MIN,
            receiver,
        }
    }

    /// Index of this IMU in the array.
    pub fn index(&self) -> usize {
        self.index
    }

    /// The resolved configuration.
    pub fn config(&self) -> &ResolvedImu {
        &self.cfg
    }

    /// The drawn constant errors and current bias state (for evaluation).
    pub fn errors(&self) -> &ImuErrorState {
        &self.errors
    }

    /// The mount (rotation and lever arm).
    pub fn mount(&self) -> &ImuMount {
        &self.mount
    }

    /// Scenario time of the end of sample `k`'s interval, s.
    pub fn sample_time_s(&self, k: u64) -> f64 {
        match &self.receiver {
            Some((clock, _)) => clock.tau_at_reading(self.receiver_reading_ns(k)),
            None => (self.cfg.phase_s + (k + 1) as f64 * self.period_s) / (1.0 + self.cfg.clock_freq_error),
        }
    }

    /// What the receiver's clock reads at the end of sample `k` (ns since the GPS epoch),
    /// when the IMU samples on it; else 0.
    pub fn receiver_reading_ns(&self, k: u64) -> i64 {
        self.receiver.as_ref().map_or(0, |(_, first)| {
            first + (k as i64 + 1) * (self.period_s * 1e9).round() as i64
        })
    }

    /// The next sample, `None` once its interval would end after the scenario.
    pub fn next_sample(&mut self, traj: &Trajectory, osc: &Oscillator) -> Option<ImuSample> {
        let k = self.k;
        let t = self.sample_time_s(k);
        if t > self.end_s {
            return None;
        }
        self.k += 1;
        let t_start = match (&self.receiver, k) {
            (Some((clock, first)), 0) => clock.tau_at_reading(*first),
            (None, 0) => self.cfg.phase_s / (1.0 + self.cfg.clock_freq_error),
            _ => self.sample_time_s(k - 1),
        };
        let (dth, dv) = increments(traj, &self.mount, t_start, t, SAMPLE_RULE);
        let (w, f) = (dth.map(|x| x / self.period_s), dv.map(|x| x / self.period_s));
        let (gyro, sat_g) = self.errors.gyro.apply(w, &mut self.error_rng);
        let (accel, sat_a) = self.errors.accel.apply(f, &mut self.error_rng);
        let jitter_ns = (self.stamp_rng.gaussian(self.cfg.stamp_jitter_s) * 1e9).round() as i64;
        let host_ns = (osc.host_ns_at_tau(t + self.cfg.offset_s) + jitter_ns).max(self.last_host_ns);
        self.last_host_ns = host_ns;
        let mut stamp = Stamp::host(host_ns, k, StampSource::Simulated);
        let mut flags = if sat_g || sat_a { IMU_FLAG_SATURATED } else { 0 };
        if self.receiver.is_some() {
            stamp.device_ns = self.receiver_reading_ns(k);
            stamp.has_device_time = 1;
            flags |= IMU_FLAG_RECEIVER_CLOCK;
        }
        Some(ImuSample {
            stamp,
            gyro_rps: gyro,
            accel_mps2: accel,
            dt_s: self.period_s,
            temperature_c: self.errors.temperature_c,
            imu_id: self.id,
            flags,
            reserved: 0,
        })
    }

    /// Lever arm of this IMU, body axes, m.
    pub fn lever_arm_b(&self) -> Vector3<f64> {
        self.mount.lever_arm_b
    }
}

/// The NUL-padded ASCII id of IMU `index` ("0", "1", …).
pub fn imu_id(index: usize) -> [u8; 8] {
    let mut id = [0u8; 8];
    let text = index.to_string();
    for (d, s) in id.iter_mut().zip(text.bytes()) {
        *d = s;
    }
    id
}
