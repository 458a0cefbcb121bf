//! The simulator's IMUs as Xsens MTi devices: what `navsync sim --imu-output xsens` writes
//! into one pseudo-terminal per IMU, and where (`navsync imu --source sim[:DIR]` reads it).
//!
//! Each simulated IMU gets its own 10 kHz SampleTimeFine clock, the crystal it samples on
//! (as an MTi does: `--imu-output xsens` sets the scenario's `imu.device_clocks`): it starts at
//! [`clock_start_ticks`] (close to the 2³² wrap, so a run of a minute crosses it) and runs
//! with a constant fractional frequency error y
//! ([`imu_crystal_freq_error`](crate::scenario::imu_crystal_freq_error), tens of ppm) against
//! true time. Sample k ends when that clock reads phase + (k+1)·T (true time
//! (phase + (k+1)·T)/(1 + y), see `crate::imu_stream`), so its SampleTimeFine is
//! `start + round((phase + (k+1)·T) · 10⁴)` modulo 2³²: exact whenever phase and T are
//! whole ticks. The stamp delay and jitter of the simulated host stamp are not in it: the
//! device clock marks the physical sample, the host receipt comes later, as with real
//! hardware.
//!
//! The message is written when the world says the sample is stamped (its `host_ns`), with
//! PacketCounter = seq (mod 2¹⁶), StatusWord clipping bits when the simulated sensor
//! saturated, Temperature, Acceleration and RateOfTurn as float32 in the Xsens sensor frame
//! (z up: the published forward-right-down axes mapped back with
//! [`AxisMap::Z_UP_TO_FRD`]).

use std::path::Path;
use std::str::FromStr;

use navsync_drivers::imu::axes::AxisMap;
use navsync_drivers::imu::xsens::frame::{
    MtData2, RealFormat, SAMPLE_TIME_FINE_HZ, STATUS_CLIP_ACC, STATUS_CLIP_GYR, encode_mtdata2,
};
use navsync_drivers::imu::xsens::sim_device::{default_sim_dir, sim_port};
use navsync_drivers::pty::Pty;
use navsync_shared::ipc::{IpcError, IpcNode, Publisher};
use navsync_shared::samples::{IMU_FLAG_SATURATED, ImuSample};
use navsync_shared::services;

use crate::scenario::SimConfig;

/// How the simulator delivers IMU samples.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum SimImuOutput {
    /// Published straight into `navsync/imu/{i}/sample` (no driver involved).
    #[default]
    Direct,
    /// Xsens MTData2 messages into one pseudo-terminal per IMU, read by `navsync imu`.
    Xsens,
}

impl FromStr for SimImuOutput {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "direct" => Ok(Self::Direct),
            "xsens" => Ok(Self::Xsens),
            _ => Err(format!("`{s}` is not an IMU output: expected `direct` or `xsens`")),
        }
    }
}

/// SampleTimeFine of simulated IMU `index` at scenario time 0: 2³² − (20 + 10·index) s of
/// ticks, so the counter wraps 20, 30, 40, … s into the run.
pub fn clock_start_ticks(index: usize) -> u32 {
    let before_wrap = SAMPLE_TIME_FINE_HZ as u64 * (20 + 10 * index as u64);
    ((1u64 << 32) - before_wrap % (1u64 << 32)) as u32
}

/// One simulated IMU seen as an Xsens MTi.
#[derive(Debug, Clone)]
pub struct SimXsensImu {
    phase_s: f64,
    period_s: f64,
    start_ticks: u32,
    buf: Vec<u8>,
}

impl SimXsensImu {
    /// IMU `index` with sample-grid phase `phase_s` and rate `rate_hz`.
    pub fn new(index: usize, phase_s: f64, rate_hz: f64) -> Self {
        Self {
            phase_s,
            period_s: 1.0 / rate_hz,
            start_ticks: clock_start_ticks(index),
            buf: Vec::with_capacity(96),
        }
    }

    /// SampleTimeFine at the end of sample `k`'s interval.
    pub fn sample_time_fine(&self, k: u64) -> u32 {
        let device_s = self.phase_s + (k + 1) as f64 * self.period_s;
        let ticks = (device_s * SAMPLE_TIME_FINE_HZ as f64).round() as i64;
        self.start_ticks.wrapping_add(ticks as u32)
    }

    /// The MTData2 message for `sample` (valid until the next call; no allocation once warm).
    pub fn message(&mut self, sample: &ImuSample) -> &[u8] {
        let saturated = sample.flags & IMU_FLAG_SATURATED != 0;
        let clip = STATUS_CLIP_ACC
            .iter()
            .chain(STATUS_CLIP_GYR.iter())
            .fold(0, |a, b| a | b);
        let m = MtData2 {
            sample_time_fine: Some(self.sample_time_fine(sample.stamp.seq)),
            packet_counter: Some(sample.stamp.seq as u16),
            acceleration: Some(AxisMap::Z_UP_TO_FRD.invert(sample.accel_mps2)),
            rate_of_turn: Some(AxisMap::Z_UP_TO_FRD.invert(sample.gyro_rps)),
            temperature_c: sample.temperature_c.is_finite().then_some(sample.temperature_c),
            status_word: Some(if saturated { clip } else { 0 }),
            ..Default::default()
        };
        encode_mtdata2(&m, RealFormat::Float32, &mut self.buf);
        &self.buf
    }
}

/// Where the simulator delivers its IMU samples.
pub enum SimImuSink {
    /// Straight into `navsync/imu/{i}/sample`.
    Direct(Vec<Publisher<ImuSample>>),
    /// As MTData2 into one pseudo-terminal per IMU.
    Xsens(Vec<(SimXsensImu, Pty)>),
}

/// Why the IMU outputs could not be set up.
#[derive(Debug, thiserror::Error)]
pub enum SimImuSinkError {
    /// IPC failure.
    #[error(transparent)]
    Ipc(#[from] IpcError),
    /// A pseudo-terminal could not be created.
    #[error("creating the pseudo-terminal of IMU {index}: {source}")]
    Pty {
        /// The IMU.
        index: usize,
        /// The error.
        source: std::io::Error,
    },
    /// The directory of the links is not safe to use.
    #[error("the IMU pseudo-terminals' directory")]
    Dir(#[from] navsync_shared::runtime_dir::RuntimeDirError),
}

impl SimImuSink {
    /// The outputs of `cfg`'s IMUs; for [`SimImuOutput::Xsens`] one pseudo-terminal per IMU
    /// with its link `dir/imu{i}` (default [`default_sim_dir`], created owner-only or checked),
    /// announced on stdout.
    pub fn open(
        node: &IpcNode,
        cfg: &SimConfig,
        output: SimImuOutput,
        dir: Option<&Path>,
    ) -> Result<Self, SimImuSinkError> {
        match output {
            SimImuOutput::Direct => Ok(Self::Direct(
                (0..cfg.imu.count)
                    .map(|i| node.publisher(&services::imu_sample(&i.to_string())))
                    .collect::<Result<_, _>>()?,
            )),
            SimImuOutput::Xsens => {
                let dir = match dir {
                    Some(d) => d.to_path_buf(),
                    None => default_sim_dir(),
                };
                navsync_shared::runtime_dir::ensure(&dir, navsync_shared::runtime_dir::HINT)?;
                let dir = dir.as_path();
                let mut out = Vec::with_capacity(cfg.imu.count);
                for i in 0..cfg.imu.count {
                    let unit = cfg.imu_unit(i);
                    let pty = Pty::open(Some(&sim_port(dir, i)))
                        .map_err(|source| SimImuSinkError::Pty { index: i, source })?;
                    println!(
                        "navsync sim: IMU {i} (Xsens MTData2) on {} (link {})",
                        pty.path().display(),
                        sim_port(dir, i).display()
                    );
                    out.push((SimXsensImu::new(i, unit.phase_s, unit.rate_hz), pty));
                }
                Ok(Self::Xsens(out))
            }
        }
    }

    /// Delivers a sample of IMU `index` (a pseudo-terminal nobody reads drops the bytes, as a
    /// serial line without a listener would).
    pub fn deliver(&mut self, index: usize, sample: &ImuSample) -> Result<(), IpcError> {
        match self {
            Self::Direct(pubs) => match pubs.get_mut(index) {
                Some(p) => p.publish(sample),
                None => Ok(()),
            },
            Self::Xsens(devs) => {
                if let Some((dev, pty)) = devs.get_mut(index) {
                    let msg = dev.message(sample);
                    // A failed write is a dropped message; the driver sees the counter gap.
                    let _ = pty.write(msg);
                }
                Ok(())
            }
        }
    }

    /// Bytes dropped because nobody read an IMU's pseudo-terminal.
    pub fn dropped_bytes(&self) -> u64 {
        match self {
            Self::Direct(_) => 0,
            Self::Xsens(devs) => devs.iter().map(|(_, p)| p.dropped_bytes()).sum(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use navsync_drivers::imu::xsens::frame::{XbusFramer, decode_mtdata2};
    use navsync_shared::samples::{Stamp, StampSource};

    #[test]
    fn counter_model() {
        let imu = SimXsensImu::new(1, 0.0011, 200.0);
        // 200 Hz sampled on the 10 kHz clock: exactly 50 ticks per sample.
        let d: Vec<u32> = (0..1000)
            .map(|k| imu.sample_time_fine(k + 1).wrapping_sub(imu.sample_time_fine(k)))
            .collect();
        assert!(d.iter().all(|&x| x == 50), "{:?}", &d[..10]);
        // It wraps 30 s into the run.
        let k_wrap = (0..20_000u64).find(|&k| imu.sample_time_fine(k + 1) < imu.sample_time_fine(k));
        assert!(k_wrap.is_some_and(|k| (5990..6010).contains(&k)), "{k_wrap:?}");
    }

    #[test]
    fn messages_carry_the_sample() {
        let mut imu = SimXsensImu::new(0, 0.0, 200.0);
        let s = ImuSample {
            stamp: Stamp::host(123, 70_000, StampSource::Simulated),
            gyro_rps: [0.01, -0.02, 0.5],
            accel_mps2: [0.1, 0.2, -9.8],
            dt_s: 0.005,
            temperature_c: 30.0,
            imu_id: [b'0', 0, 0, 0, 0, 0, 0, 0],
            flags: IMU_FLAG_SATURATED,
            reserved: 0,
        };
        let bytes = imu.message(&s).to_vec();
        let mut f = XbusFramer::new();
        let mut got = None;
        f.push(&bytes, 0, 0, &mut |m| got = Some(decode_mtdata2(m.data).unwrap()));
        let m = got.unwrap();
        assert_eq!(m.packet_counter, Some((70_000 % 65_536) as u16));
        assert_eq!(m.sample_time_fine, Some(imu.sample_time_fine(70_000)));
        assert_eq!(m.acceleration.unwrap().map(|v| v as f32), [0.1f32, -0.2, 9.8]);
        assert_eq!(m.rate_of_turn.unwrap().map(|v| v as f32), [0.01f32, 0.02, -0.5]);
        assert!(m.status_word.unwrap() & STATUS_CLIP_GYR[0] != 0);
        assert_eq!(m.temperature_c, Some(30.0));
        assert_eq!("xsens".parse::<SimImuOutput>(), Ok(SimImuOutput::Xsens));
        assert!(
            "udp"
                .parse::<SimImuOutput>()
                .unwrap_err()
                .contains("`direct` or `xsens`")
        );
    }
}
