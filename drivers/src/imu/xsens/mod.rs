//! `navsync imu --source xsens:PORT[:BAUD]`: the process shell around an Xsens MTi in
//! measurement mode, sending MTData2.
//!
//! read (serialport, raw) → frame ([`XbusFramer`], pure; each message stamped with the host
//! time of its last byte) → decode ([`decode_mtdata2`], pure) → axis map → checks and publish
//! ([`SampleOutput`]).
//!
//! The device is expected to be configured already (MT Manager or the Xsens SDK) to send at
//! least PacketCounter, SampleTimeFine, and Acceleration + RateOfTurn (or DeltaV + DeltaQ);
//! Temperature and StatusWord are used when present. The driver never writes to the device.
//!
//! # Time stamps and the device clock
//!
//! Each sample is published with two times:
//!
//! - `stamp.host_ns`: the receipt time of the message's last byte (`StampSource::Receipt`),
//!   back-dated by the line rate for messages that were already waiting when the read
//!   returned, and never earlier than the previous sample's. This is what a serial port
//!   gives: the device's processing and output latency, the transmission time of the
//!   message (≈ 4.7 ms for 54 bytes at 115200 Bd), the USB-serial adapter's latency timer
//!   (1–16 ms on FTDI chips) and the scheduler all lie between the physical sample and this
//!   stamp, and they jitter.
//! - `stamp.device_ns`: SampleTimeFine, the device's own 10 kHz clock at the sample,
//!   unwrapped across its 2³² wrap (every 119.3 h) and converted with the nominal 100 µs per
//!   tick. It is exact in the device's time scale but that scale drifts against the host
//!   clock (crystal tolerance, tens of ppm, and temperature).
//!
//! The estimator's device clock model (`navsync_estimator::time::device_clock`) is made to map
//! device time to GNSS time: a two-state Kalman filter of the device clock's
//! offset and fractional frequency against GNSS time (the same model as the host clock's,
//! process noise from the device oscillator's Allan deviation), fed with (device time,
//! receipt stamp mapped through the host → GNSS `TimeState`) pairs whose noise is the
//! receipt jitter, or with PPS captures where the device latches them (SyncIn). The
//! frequency is estimated, not assumed zero: over 10 minutes a 20 ppm crystal drifts 12 ms
//! against the host. The mapped device time then stamps each sample with the device's
//! sample-to-sample precision (µs) instead of the receipt's jitter (ms on USB); a constant
//! transport latency left in the pairs is absorbed by the IMU's time-offset estimation.
//! Until the filter has converged the receipt stamp is the fallback, which is why it is
//! published as the host stamp.
//!
//! Sequence numbers come from PacketCounter (wrapping at 2¹⁶): a counter step of n means
//! n − 1 lost messages. Without PacketCounter, samples are numbered consecutively.

pub mod frame;
pub mod sim_device;

use std::io::{ErrorKind, Read};
use std::time::Duration;

use navsync_shared::ipc::IpcNode;
use navsync_shared::samples::StampSource;
use navsync_shared::time::monotonic_now_ns;
use serialport::{ClearBuffer, SerialPort, TTYPort};
use tracing::{info, warn};

use self::frame::{
    MID_MTDATA2, Message, MtData2, NS_PER_SAMPLE_TIME_FINE_TICK, STATUS_CLIP_ACC, STATUS_CLIP_GYR, XbusFramer,
    decode_mtdata2,
};
use super::axes::AxisMap;
use super::output::{Extras, SampleOutput};
use super::sample_checks::{Candidate, CounterReading, RESYNC_AFTER, Sequence};

/// Default Xsens line rate (the MTi factory setting).
pub const DEFAULT_BAUD: u32 = 115_200;
/// Gyroscope range of Xsens devices when none is configured (MTi 1-, 600-series: ±2000 °/s).
pub const GYRO_RANGE_DPS: f64 = 2000.0;
/// Accelerometer range of Xsens devices when none is configured (MTi 1-series: ±16 g).
pub const ACCEL_RANGE_G: f64 = 16.0;

/// Read timeout (the idle wake-up to check for termination and publish health).
const READ_TIMEOUT: Duration = Duration::from_millis(100);
/// Xbus message id of an error report from the device.
const MID_ERROR: u8 = 0x42;

/// Settings of the Xsens driver.
#[derive(Debug, Clone)]
pub struct XsensArgs {
    /// Serial device.
    pub port: String,
    /// Line rate.
    pub baud: u32,
    /// Device (sensor frame S) axes → published axes.
    pub axes: AxisMap,
    /// Nominal output rate, Hz, if known (otherwise learnt from SampleTimeFine).
    pub rate_hz: Option<f64>,
}

/// Counters of the message layer (besides the framer's and the checks').
#[derive(Debug, Default, Clone, Copy)]
struct Counters {
    opens: u64,
    open_failures: u64,
    reopens: u64,
    mtdata2: u64,
    bad_items: u64,
    no_inertial: u64,
    other_messages: u64,
    device_errors: u64,
}

impl Counters {
    fn named(&self) -> [(&'static str, u64); 8] {
        [
            ("device_opens", self.opens),
            ("device_open_failures", self.open_failures),
            ("device_reopens", self.reopens),
            ("mtdata2_messages", self.mtdata2),
            ("mtdata2_bad_items", self.bad_items),
            ("mtdata2_no_inertial", self.no_inertial),
            ("xbus_other_messages", self.other_messages),
            ("xbus_device_errors", self.device_errors),
        ]
    }
}

/// The decoding state that lives across messages.
struct Decoder {
    axes: AxisMap,
    nominal_dt_s: Option<f64>,
    prev_stf: Option<u32>,
    prev_pc: Option<u16>,
    /// Consecutive messages whose SampleTimeFine lies behind `prev_stf`.
    stf_back_run: u32,
    last_host_ns: i64,
    c: Counters,
}

impl Decoder {
    /// A decoder with nothing received yet.
    fn new(axes: AxisMap, nominal_dt_s: Option<f64>) -> Self {
        Self {
            axes,
            nominal_dt_s,
            prev_stf: None,
            prev_pc: None,
            stf_back_run: 0,
            last_host_ns: i64::MIN,
            c: Counters::default(),
        }
    }

    /// Turns one message into a sample offered to `out`.
    fn on_message(&mut self, msg: Message<'_>, out: &mut SampleOutput) {
        if let Some((candidate, extras)) = self.decode(msg) {
            let _ = out.offer(&candidate, &extras);
        }
    }

    /// Turns one message into a candidate sample for the checks (pure: no I/O), or counts
    /// why it carries none.
    fn decode(&mut self, msg: Message<'_>) -> Option<(Candidate, Extras)> {
        if msg.mid != MID_MTDATA2 {
            self.c.other_messages += 1;
            if msg.mid == MID_ERROR {
                self.c.device_errors += 1;
            }
            return None;
        }
        self.c.mtdata2 += 1;
        let m = match decode_mtdata2(msg.data) {
            Ok(m) => m,
            Err(_) => {
                self.c.bad_items += 1;
                return None;
            }
        };
        // The interval this message covers: from the device clock if it has one.
        // The interval this message covers, from the device clock if it has one (divided by
        // the packet-counter step when messages were lost in between).
        let step = match (m.packet_counter, self.prev_pc) {
            (Some(now), Some(before)) => u32::from(now.wrapping_sub(before)),
            _ => 1,
        };
        let stf_dt_s = match (m.sample_time_fine, self.prev_stf) {
            (Some(now), Some(before)) if (1..1000).contains(&step) => {
                let ticks = now.wrapping_sub(before);
                let ok = ticks > 0 && ticks < 10_000 * step;
                ok.then(|| f64::from(ticks) / f64::from(step) * NS_PER_SAMPLE_TIME_FINE_TICK as f64 * 1e-9)
            }
            _ => None,
        };
        // A message whose device time lies behind the previous one (corrupt, or the device
        // restarted) is not the start of the next interval until that persists (as in the
        // sample checks): otherwise the sample after one bad message would get a wrong
        // interval, and with increments (DeltaQ/DeltaV) wrong rates.
        let stf_backwards = match (m.sample_time_fine, self.prev_stf) {
            (Some(now), Some(before)) => now.wrapping_sub(before) > u32::MAX / 2,
            _ => false,
        };
        self.stf_back_run = if stf_backwards { self.stf_back_run + 1 } else { 0 };
        if !stf_backwards || self.stf_back_run >= RESYNC_AFTER {
            self.stf_back_run = 0;
            if m.sample_time_fine.is_some() {
                self.prev_stf = m.sample_time_fine;
            }
            if m.packet_counter.is_some() {
                self.prev_pc = m.packet_counter;
            }
        }
        let Some((gyro, accel)) = inertial(&m, stf_dt_s.or(self.nominal_dt_s)) else {
            self.c.no_inertial += 1;
            return None;
        };
        let host_ns = msg.host_ns.max(self.last_host_ns);
        self.last_host_ns = host_ns;
        let status = m.status_word.unwrap_or(0);
        let clipped = STATUS_CLIP_ACC
            .iter()
            .chain(STATUS_CLIP_GYR.iter())
            .any(|b| status & b != 0);
        let candidate = Candidate {
            host_ns,
            device: m.sample_time_fine.map(|t| CounterReading {
                ticks: u64::from(t),
                modulus: 1 << 32,
                ns_per_tick: NS_PER_SAMPLE_TIME_FINE_TICK,
            }),
            sequence: match m.packet_counter {
                Some(pc) => Sequence::Counter {
                    value: u64::from(pc),
                    modulus: 1 << 16,
                },
                None => Sequence::Consecutive,
            },
            gyro_rps: self.axes.apply(gyro),
            accel_mps2: self.axes.apply(accel),
        };
        let extras = Extras {
            source: StampSource::Receipt,
            temperature_c: m.temperature_c.unwrap_or(f64::NAN),
            saturated: clipped,
            dt_s: None,
        };
        Some((candidate, extras))
    }
}

/// Rate of turn and specific force in sensor axes: the calibrated outputs, or the SDI
/// increments divided by the interval `dt_s` they cover.
fn inertial(m: &MtData2, dt_s: Option<f64>) -> Option<([f64; 3], [f64; 3])> {
    let gyro = match (m.rate_of_turn, m.delta_q, dt_s) {
        (Some(w), _, _) => w,
        (None, Some(q), Some(dt)) => rotation_vector(q).map(|v| v / dt),
        _ => return None,
    };
    let accel = match (m.acceleration, m.delta_v, dt_s) {
        (Some(a), _, _) => a,
        (None, Some(v), Some(dt)) => v.map(|x| x / dt),
        _ => return None,
    };
    Some((gyro, accel))
}

/// The rotation vector (axis × angle, rad) of a unit quaternion (w, x, y, z).
pub fn rotation_vector(q: [f64; 4]) -> [f64; 3] {
    let [w, x, y, z] = if q[0] < 0.0 { q.map(|v| -v) } else { q };
    let s = (x * x + y * y + z * z).sqrt();
    if s < 1e-12 {
        // Small angle: 2·(x, y, z) to first order.
        return [2.0 * x, 2.0 * y, 2.0 * z];
    }
    let angle = 2.0 * s.atan2(w);
    [x / s * angle, y / s * angle, z / s * angle]
}

/// Runs the driver until SIGINT/SIGTERM.
pub fn run(node: &IpcNode, args: &XsensArgs, out: &mut SampleOutput) {
    let mut framer = XbusFramer::new();
    let mut dec = Decoder::new(args.axes, args.rate_hz.map(|f| 1.0 / f));
    let ns_per_byte = 10_000_000_000 / i64::from(args.baud.max(1));
    let mut backoff = Duration::from_millis(100);
    let mut warned_open = false;
    let tick = |out: &mut SampleOutput, framer: &XbusFramer, dec: &Decoder| {
        out.tick(framer.counters().named().into_iter().chain(dec.c.named()));
    };
    while !node.termination_requested() {
        let mut port = match open(&args.port, args.baud) {
            Ok(p) => p,
            Err(e) => {
                dec.c.open_failures += 1;
                if !warned_open {
                    warn!("cannot open {}: {e}; retrying with backoff", args.port);
                    warned_open = true;
                }
                tick(out, &framer, &dec);
                if !node.sleep(backoff) {
                    break;
                }
                backoff = (backoff * 2).min(Duration::from_secs(5));
                continue;
            }
        };
        if warned_open {
            info!("port is back");
        }
        warned_open = false;
        dec.c.opens += 1;
        info!(baud = args.baud, "port open");
        let mut buf = [0u8; 1024];
        loop {
            if node.termination_requested() {
                break;
            }
            match port.read(&mut buf) {
                Ok(0) => {
                    warn!("{} closed; reopening", args.port);
                    break;
                }
                Ok(n) => {
                    backoff = Duration::from_millis(100);
                    let t = monotonic_now_ns();
                    framer.push(&buf[..n], t, ns_per_byte, &mut |msg| dec.on_message(msg, out));
                }
                Err(e) if e.kind() == ErrorKind::TimedOut || e.kind() == ErrorKind::Interrupted => {}
                Err(e) => {
                    warn!("read from {} failed: {e}; reopening", args.port);
                    break;
                }
            }
            tick(out, &framer, &dec);
        }
        framer.reset();
        if node.termination_requested() {
            break;
        }
        dec.c.reopens += 1;
        tick(out, &framer, &dec);
        if !node.sleep(backoff) {
            break;
        }
        backoff = (backoff * 2).min(Duration::from_secs(5));
    }
    tick(out, &framer, &dec);
}

/// Opens the port raw with a short read timeout and discards stale input.
fn open(path: &str, baud: u32) -> Result<TTYPort, serialport::Error> {
    let mut port = serialport::new(path, baud).timeout(READ_TIMEOUT).open_native()?;
    let _ = port.set_exclusive(false);
    port.clear(ClearBuffer::Input)?;
    Ok(port)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotation_vector_of_quaternions() {
        let a: f64 = 0.3;
        let q = [(a / 2.0).cos(), 0.0, 0.0, (a / 2.0).sin()];
        let v = rotation_vector(q);
        assert!((v[2] - a).abs() < 1e-15 && v[0] == 0.0 && v[1] == 0.0);
        // The same rotation with the opposite sign convention.
        let v = rotation_vector(q.map(|x| -x));
        assert!((v[2] - a).abs() < 1e-15);
        assert_eq!(rotation_vector([1.0, 0.0, 0.0, 0.0]), [0.0; 3]);
    }

    #[test]
    fn increments_become_rates() {
        let m = MtData2 {
            delta_v: Some([0.01, 0.0, -0.049]),
            delta_q: Some([(0.001f64).cos(), (0.001f64).sin(), 0.0, 0.0]),
            ..Default::default()
        };
        assert_eq!(inertial(&m, None), None, "no interval, no rate");
        let (g, a) = inertial(&m, Some(0.005)).unwrap();
        assert!((g[0] - 0.4).abs() < 1e-12, "{g:?}");
        assert!((a[0] - 2.0).abs() < 1e-12 && (a[2] + 9.8).abs() < 1e-12, "{a:?}");
    }

    /// A 200 Hz MTData2 stream carrying NaN, infinite, full-scale, clipped, out-of-range,
    /// time-reversed and repeated samples, as bytes through the framer, the decoder and the
    /// sample checks, in both output formats (calibrated rates, and increments with `--rate`):
    /// every bad sample is rejected and counted by kind, a full-scale or clipped one is kept
    /// and flagged saturated, the good ones come through unchanged and numbered by the packet
    /// counter (the rejected ones are gaps), and the sample after a time-reversed one gets its
    /// true interval.
    #[test]
    fn bad_samples_in_the_byte_stream_are_rejected_flagged_and_counted() {
        use super::super::sample_checks::{Limits, Rejection, SampleChecks};
        use super::frame::{RealFormat, encode_mtdata2};
        use super::{ACCEL_RANGE_G, GYRO_RANGE_DPS};

        const DT_S: f64 = 0.005;
        let fs = GYRO_RANGE_DPS.to_radians();
        let limits = Limits {
            gyro_rps: fs,
            accel_mps2: ACCEL_RANGE_G * navsync_shared::imu_spec::G0,
        };
        let good_w = [0.1, -0.2, 0.3];
        let good_a = [0.5, -0.4, 9.8];
        // (what is wrong, rate, specific force, status word, SampleTimeFine shift in ticks).
        type Msg = (&'static str, [f64; 3], [f64; 3], u32, i64);
        let ok: Msg = ("good", good_w, good_a, 0, 0);
        let script: [Msg; 16] = [
            ok,
            ok,
            ok,
            ok,
            ("nan", [0.1, f64::NAN, 0.3], good_a, 0, 0),
            ("inf", good_w, [0.5, -0.4, f64::INFINITY], 0, 0),
            ("full scale", [fs, -0.2, 0.3], good_a, 0, 0),
            ("clipped", good_w, good_a, STATUS_CLIP_ACC[2], 0),
            ("beyond range", [0.1, -0.2, 1.3 * fs], good_a, 0, 0),
            ("time reversed", good_w, good_a, 0, -1000),
            ok,
            ("repeated", good_w, good_a, 0, 0),
            ok,
            ok,
            ok,
            ok,
        ];
        for increments in [false, true] {
            let mut dec = Decoder::new(AxisMap::IDENTITY, increments.then_some(DT_S));
            let mut framer = XbusFramer::new();
            let mut checks = SampleChecks::new(limits);
            let mut bytes = Vec::new();
            let mut got = Vec::new();
            let stf0: u32 = 4_294_960_000; // wraps within the stream
            for (i, (what, w, a, status, shift)) in script.iter().enumerate() {
                // The repeated message is the previous one again.
                let k = if *what == "repeated" { i - 1 } else { i };
                let stf = stf0.wrapping_add(50 * k as u32).wrapping_add(*shift as u32);
                let mut m = MtData2 {
                    packet_counter: Some(k as u16),
                    sample_time_fine: Some(stf),
                    status_word: Some(*status),
                    ..Default::default()
                };
                if increments {
                    let angle = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt() * DT_S;
                    let axis = w.map(|x| x * DT_S / angle);
                    let (c, s) = ((angle / 2.0).cos(), (angle / 2.0).sin());
                    m.delta_q = Some([c, axis[0] * s, axis[1] * s, axis[2] * s]);
                    m.delta_v = Some(a.map(|x| x * DT_S));
                } else {
                    m.rate_of_turn = Some(*w);
                    m.acceleration = Some(*a);
                }
                encode_mtdata2(&m, RealFormat::Float32, &mut bytes);
                let t = 1_000_000_000 + i as i64 * 5_000_000;
                framer.push(&bytes, t, 1_000, &mut |msg| {
                    let (c, x) = dec.decode(msg).expect("a sample");
                    got.push((i, c, x, checks.check(&c)));
                });
            }
            let mode = if increments { "increments" } else { "rates" };
            assert_eq!(got.len(), script.len(), "{mode}: every message decoded");
            for (i, c, x, r) in &got {
                let (what, w, a, ..) = script[*i];
                match (what, r) {
                    ("good", Ok(acc)) => {
                        assert_eq!(acc.seq, *i as u64, "{mode} #{i}: numbered by the counter");
                        assert!(!acc.at_range && !x.saturated, "{mode} #{i}");
                        for k in 0..3 {
                            assert!(
                                (c.gyro_rps[k] - w[k]).abs() < 1e-5,
                                "{mode} #{i}: rate {:?}",
                                c.gyro_rps
                            );
                            assert!((c.accel_mps2[k] - a[k]).abs() < 1e-5, "{mode} #{i}: {:?}", c.accel_mps2);
                        }
                        assert_eq!(acc.device_interval_ns, (*i > 0).then_some(5_000_000), "{mode} #{i}");
                    }
                    ("full scale", Ok(acc)) => assert!(acc.at_range, "{mode}: full scale flagged"),
                    ("clipped", Ok(acc)) => assert!(x.saturated && !acc.at_range, "{mode}: clip flag"),
                    ("nan" | "inf", Err(e)) => assert_eq!(*e, Rejection::NotFinite, "{mode} #{i}"),
                    ("beyond range", Err(e)) => assert_eq!(*e, Rejection::OutOfRange, "{mode}"),
                    ("time reversed", Err(e)) => assert_eq!(*e, Rejection::DeviceTimeBackwards, "{mode}"),
                    ("repeated", Err(e)) => assert_eq!(*e, Rejection::Duplicate, "{mode}"),
                    _ => panic!("{mode} #{i} ({what}): {r:?}"),
                }
            }
            let k = checks.counters();
            println!("{mode}: {k:?}");
            assert_eq!(
                (
                    k.accepted,
                    k.rejected_not_finite,
                    k.rejected_range,
                    k.rejected_device_back,
                    k.rejected_duplicate,
                    k.at_range
                ),
                (11, 2, 1, 1, 1, 1),
                "{mode}"
            );
            // The rejected messages are gaps in the published numbering: 4 and 5, 8 and 9, 11.
            assert_eq!((k.dropped, k.gaps, k.resyncs), (5, 3, 0), "{mode}");
            assert_eq!((dec.c.bad_items, dec.c.no_inertial), (0, 0), "{mode}");
        }
    }
}
