//! The white noise an IMU of unknown class can have, measured from its own signal.
//!
//! The generic model ([`navsync_wire::imu_spec::ImuPreset::Generic`]) is an IMU as it behaves in
//! use: a hand-held or vehicle-mounted MEMS unit whose vibration makes its effective noise ten
//! times its data sheet's. A quieter IMU shows it in its signal: the second difference of its
//! increments summed over [`STRIDE_S`] leaves only what varies faster than the motion (white
//! noise of density N: variance 6·N²·T for sums over T; motion: its second derivative × T³,
//! negligible at 20 ms for a vehicle, a walking hand's gait is not). So the signal's
//! high-frequency content bounds its white noise from above (the 20 ms stride is beyond the
//! digital low-pass filters that correlate a sensor's successive samples; measured on the
//! rtklibexplorer walk at rest: 0.06 °/√h per sample, 0.10–0.11 °/√h at 2, 5 and 10 samples).
//! [`NoiseMeter`] reports that bound per block of [`BLOCK_S`], as the largest of the last
//! [`WINDOW_S`] (vibration returns at once, leaves only after the window), from the first full
//! window on.
//!
//! Measured at 20 ms (2 s windows, °/√h and m/s/√h, median in motion): the walk 12 and 1.4,
//! drive0708 12 and 1.8 (both above the generic model's 2 and 0.75, which they keep while they
//! move), the simulated consumer IMU of the sweep 0.30 and 0.20, its industrial one 0.10 and
//! 0.10 (docs/benchmarks/sweep.md).

use nalgebra::Vector3;

/// Length of the sums whose second differences are taken, s.
pub const STRIDE_S: f64 = 0.02;
/// One estimate per block of this length, s.
pub const BLOCK_S: f64 = 0.5;
/// The reported density is the largest of the blocks of this last span, s.
pub const WINDOW_S: f64 = 10.0;
const WINDOW_BLOCKS: usize = 20;
const _: () = assert!((WINDOW_S / BLOCK_S) as usize == WINDOW_BLOCKS);

/// White-noise densities bounded from a stretch of the signal.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeasuredNoise {
    /// Gyroscope white-noise density (angle random walk), rad/√s, RMS over the axes.
    pub arw_rad_sqrt_s: f64,
    /// Accelerometer white-noise density (velocity random walk), m/s/√s, RMS over the axes.
    pub vrw_mps_sqrt_s: f64,
}

/// The running measurement (allocation-free: a fixed ring of blocks).
#[derive(Debug, Clone)]
pub struct NoiseMeter {
    /// Samples per stride, from the first sample's nominal interval.
    per_stride: usize,
    stride_s: f64,
    strides_per_block: usize,
    /// The stride being summed: samples in it, angle (rad) and velocity (m/s) increments.
    in_stride: usize,
    sum: (Vector3<f64>, Vector3<f64>),
    /// The two previous strides' sums.
    prev: [(Vector3<f64>, Vector3<f64>); 2],
    strides: usize,
    /// The block being accumulated: Σ d² over its second differences (gyro, accel) and their
    /// count.
    block: (f64, f64, usize),
    /// Finished blocks' densities², ring.
    ring: [(f64, f64); WINDOW_BLOCKS],
    filled: usize,
    next: usize,
}

impl NoiseMeter {
    /// A meter for samples `nominal_dt_s` apart.
    pub fn new(nominal_dt_s: f64) -> Self {
        let dt = if nominal_dt_s.is_finite() && nominal_dt_s > 0.0 {
            nominal_dt_s
        } else {
            0.01
        };
        let per_stride = ((STRIDE_S / dt).round() as usize).max(1);
        let stride_s = per_stride as f64 * dt;
        Self {
            per_stride,
            stride_s,
            strides_per_block: ((BLOCK_S / stride_s).round() as usize).max(3),
            in_stride: 0,
            sum: (Vector3::zeros(), Vector3::zeros()),
            prev: [(Vector3::zeros(), Vector3::zeros()); 2],
            strides: 0,
            block: (0.0, 0.0, 0),
            ring: [(0.0, 0.0); WINDOW_BLOCKS],
            filled: 0,
            next: 0,
        }
    }

    /// One sample (body rates, rad/s and m/s², over its nominal interval); at the end of each
    /// block once a whole window is seen, the largest densities of the window.
    pub fn push(
        &mut self,
        nominal_dt_s: f64,
        gyro_rps: &Vector3<f64>,
        accel_mps2: &Vector3<f64>,
    ) -> Option<MeasuredNoise> {
        if !(gyro_rps.iter().chain(accel_mps2.iter()).all(|x| x.is_finite()) && nominal_dt_s.is_finite()) {
            return None;
        }
        self.sum.0 += gyro_rps * nominal_dt_s;
        self.sum.1 += accel_mps2 * nominal_dt_s;
        self.in_stride += 1;
        if self.in_stride < self.per_stride {
            return None;
        }
        let s = std::mem::replace(&mut self.sum, (Vector3::zeros(), Vector3::zeros()));
        self.in_stride = 0;
        self.strides += 1;
        if self.strides >= 3 {
            let d2g = s.0 - 2.0 * self.prev[1].0 + self.prev[0].0;
            let d2a = s.1 - 2.0 * self.prev[1].1 + self.prev[0].1;
            self.block.0 += d2g.norm_squared();
            self.block.1 += d2a.norm_squared();
            self.block.2 += 1;
        }
        self.prev = [self.prev[1], s];
        if self.block.2 < self.strides_per_block {
            return None;
        }
        // Density² per axis: E[d²] = 6·N²·T, three axes summed.
        let n = 18.0 * self.stride_s * self.block.2 as f64;
        self.ring[self.next] = (self.block.0 / n, self.block.1 / n);
        self.next = (self.next + 1) % WINDOW_BLOCKS;
        self.filled = (self.filled + 1).min(WINDOW_BLOCKS);
        self.block = (0.0, 0.0, 0);
        if self.filled < WINDOW_BLOCKS {
            return None;
        }
        let (g, a) = self
            .ring
            .iter()
            .fold((0.0f64, 0.0f64), |m, b| (m.0.max(b.0), m.1.max(b.1)));
        Some(MeasuredNoise {
            arw_rad_sqrt_s: g.sqrt(),
            vrw_mps_sqrt_s: a.sqrt(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_noise::gauss;

    /// White noise of density `n` at `dt` (rate samples of σ = n/√dt), over a smooth motion,
    /// from `t0_s` on.
    #[allow(clippy::too_many_arguments)]
    fn feed(
        meter: &mut NoiseMeter,
        dt: f64,
        t0_s: f64,
        seconds: f64,
        n_g: f64,
        n_a: f64,
        seed: u64,
    ) -> Option<MeasuredNoise> {
        let mut rng = seed;
        let mut last = None;
        let (i0, k) = ((t0_s / dt).round() as usize, (seconds / dt).round() as usize);
        for i in i0..i0 + k {
            let t = i as f64 * dt;
            // A turning, accelerating vehicle: 0.3 rad/s and 2 m/s² at 0.2 Hz.
            let motion_g = Vector3::new(0.0, 0.0, 0.3 * (0.4 * std::f64::consts::PI * t).sin());
            let motion_a = Vector3::new(2.0 * (0.4 * std::f64::consts::PI * t).cos(), 0.0, -9.8);
            let w: Vector3<f64> = Vector3::from_fn(|_, _| gauss(&mut rng)) * (n_g / dt.sqrt());
            let a: Vector3<f64> = Vector3::from_fn(|_, _| gauss(&mut rng)) * (n_a / dt.sqrt());
            if let Some(m) = meter.push(dt, &(motion_g + w), &(motion_a + a)) {
                last = Some(m);
            }
        }
        last
    }

    #[test]
    fn white_noise_under_smooth_motion_is_measured_at_its_density() {
        for (dt, seed) in [(0.005, 1), (0.01, 2), (0.0025, 3)] {
            let (n_g, n_a) = (0.3f64.to_radians() / 60.0, 0.2 / 60.0);
            let mut m = NoiseMeter::new(dt);
            let got = feed(&mut m, dt, 0.0, 30.0, n_g, n_a, seed).expect("a block");
            // The largest of 20 blocks of ≥ 60 squared differences: a few tens of percent above.
            for (g, want) in [(got.arw_rad_sqrt_s, n_g), (got.vrw_mps_sqrt_s, n_a)] {
                assert!(g > 0.95 * want && g < 1.4 * want, "dt {dt}: {g} for {want}");
            }
        }
    }

    #[test]
    fn vibration_is_seen_at_once_and_left_after_the_window() {
        let dt = 0.005;
        let mut m = NoiseMeter::new(dt);
        let quiet = (0.1f64.to_radians() / 60.0, 0.05 / 60.0);
        let loud = (5.0f64.to_radians() / 60.0, 1.0 / 60.0);
        assert!(
            feed(&mut m, dt, 0.0, WINDOW_S - 1.0, quiet.0, quiet.1, 3).is_none(),
            "before a whole window"
        );
        let a = feed(&mut m, dt, WINDOW_S - 1.0, 13.0 - WINDOW_S, quiet.0, quiet.1, 4).unwrap();
        let b = feed(&mut m, dt, 12.0, 1.0, loud.0, loud.1, 5).unwrap();
        let c = feed(&mut m, dt, 13.0, WINDOW_S - 1.0, quiet.0, quiet.1, 6).unwrap();
        let d = feed(&mut m, dt, 12.0 + WINDOW_S, 1.5, quiet.0, quiet.1, 7).unwrap();
        assert!(a.arw_rad_sqrt_s < 1.5 * quiet.0);
        assert!(
            b.arw_rad_sqrt_s > 0.8 * loud.0 && b.vrw_mps_sqrt_s > 0.8 * loud.1,
            "{b:?}"
        );
        assert!(c.arw_rad_sqrt_s > 0.8 * loud.0, "still within the window: {c:?}");
        assert!(d.arw_rad_sqrt_s < 1.5 * quiet.0, "the window passed: {d:?}");
    }

    #[test]
    fn non_finite_samples_are_left_out() {
        let mut m = NoiseMeter::new(0.01);
        for _ in 0..2000 {
            assert!(
                m.push(0.01, &Vector3::new(f64::NAN, 0.0, 0.0), &Vector3::zeros())
                    .is_none()
            );
        }
        let got = feed(&mut m, 0.01, 0.0, WINDOW_S + 1.0, 1e-4, 1e-3, 8).unwrap();
        assert!(got.arw_rad_sqrt_s.is_finite() && got.vrw_mps_sqrt_s.is_finite());
    }
}
