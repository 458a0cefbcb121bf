//! The drivers' per-sample path allocates nothing in steady state. With a counting global
//! allocator, after a warm-up:
//!
//! * IMU (Xsens): bytes of MTData2 messages → [`XbusFramer`] → [`decode_mtdata2`] → a checked,
//!   stamped sample ([`SampleOutput::offer`]: checks, stamp, iceoryx2 publish, health tick);
//! * GNSS (NMEA): bytes of epoch bursts (RMC, VTG, GGA, GSA, GST, ZDA) → the GNSS driver's
//!   [`Decoder`] (line framer → epoch assembler) → an iceoryx2 publish of the `GnssFix`;
//!
//! each with a subscriber attached in the same process that takes every sample (the publish
//! then really delivers), allocate nothing at all. iceoryx2 0.10 creates one small
//! reference-counted state per loan (`Publisher::loan_uninit` → `ChunkMutSharedState::new` →
//! `ArcSyncPolicy::new`), which its stock service types allocate on the heap; navsync's service
//! type recycles it (`navsync_shared::ipc::pooled`). Each test first measures a bare publisher
//! (navsync's thin wrapper) in the same process — no allocation per publish — and then the
//! driver path: none either. The input bytes are produced before counting (the simulator's encoders allocate; the
//! drivers must not). The driver's own glue between `decode_mtdata2` and `offer` (interval from
//! the device clock, axis map) is plain arithmetic on the stack and is not reproduced here.

use navsync_drivers::gnss::{Decoder, GnssDecoder, Protocol};
use navsync_drivers::imu::output::{Extras, SampleOutput};
use navsync_drivers::imu::sample_checks::{Candidate, CounterReading, Limits, Sequence};
use navsync_drivers::imu::xsens::frame::{NS_PER_SAMPLE_TIME_FINE_TICK, XbusFramer, decode_mtdata2};
use navsync_shared::reflect::Reflect;
use navsync_shared::samples::{GnssFix, ImuSample, StampSource};
use navsync_shared::services;
use navsync_sim::nmea::{EpochReport, FixReport, write_burst};
use navsync_sim::xsens_imus::SimXsensImu;
use navsync_tests::TestEnv;

/// The allocation counter is process-wide: the tests take turns.
static SERIAL: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Heap allocations per `publish` of a bare iceoryx2 publisher (navsync's thin wrapper) of
/// sample type `$t` with a subscriber taking every sample, in steady state: asserted to be 0.
macro_rules! iceoryx2_allocations_per_publish {
    ($env:expr, $t:ty, $service:expr) => {{
        let node = $env.node("baseline");
        let mut publisher = node.publisher::<$t>($service).unwrap();
        let sub = node.subscriber::<$t>($service).unwrap();
        let value = <$t>::zeroed();
        let mut cycle = |n: usize| {
            for _ in 0..n {
                publisher.publish(&value).unwrap();
                while sub.receive().unwrap().is_some() {}
            }
        };
        cycle(100);
        let before = navsync_tests::allocations();
        cycle(1000);
        let per_publish = (navsync_tests::allocations() - before) as f64 / 1000.0;
        assert_eq!(per_publish, 0.0, "heap allocations per publish of a bare publisher");
        per_publish
    }};
}

/// 1 kHz IMU, its bytes at 921 600 Bd (10 bits per byte).
const IMU_RATE_HZ: f64 = 1000.0;
const NS_PER_BYTE_921600: i64 = 10_851;

/// The Xsens messages of `n` samples of a gently rotating, accelerating IMU.
fn xsens_stream(n: usize) -> Vec<Vec<u8>> {
    let mut dev = SimXsensImu::new(0, 0.0, IMU_RATE_HZ);
    (0..n)
        .map(|k| {
            let t = k as f64 / IMU_RATE_HZ;
            let mut s = ImuSample::zeroed();
            s.gyro_rps = [0.01 * t.sin(), 0.02, 0.1 * (0.5 * t).cos()];
            s.accel_mps2 = [0.5 * t.cos(), 0.1, -9.81];
            s.dt_s = 1.0 / IMU_RATE_HZ;
            s.temperature_c = 30.0;
            s.stamp.seq = k as u64;
            dev.message(&s).to_vec()
        })
        .collect()
}

#[test]
fn xsens_bytes_to_published_sample_allocate_nothing() {
    if !navsync_tests::in_own_process!() {
        return;
    }
    let _turn = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let env = TestEnv::new("noallocimu");
    let per_publish = iceoryx2_allocations_per_publish!(env, ImuSample, &services::imu_sample("9"));
    let node = env.node("imu-0");
    let reader = env.node("reader");
    let sub = reader.subscriber::<ImuSample>(&services::imu_sample("0")).unwrap();
    let limits = Limits {
        gyro_rps: 35.0,
        accel_mps2: 160.0,
    };
    let mut out = SampleOutput::new(&node, "0", "imu-0", limits, Some(1.0 / IMU_RATE_HZ)).unwrap();
    let (warm, measured) = (2_000, 20_000);
    let frames = xsens_stream(warm + measured);
    let mut framer = XbusFramer::new();
    let mut host_ns = 1_000_000_000i64;
    let mut received = 0u64;
    let mut run = |frames: &[Vec<u8>], out: &mut SampleOutput| {
        for f in frames {
            host_ns += 1_000_000;
            framer.push(f, host_ns, NS_PER_BYTE_921600, &mut |msg| {
                let m = decode_mtdata2(msg.data).expect("valid MTData2");
                let stf = m.sample_time_fine.expect("SampleTimeFine");
                let c = Candidate {
                    host_ns: msg.host_ns,
                    device: Some(CounterReading {
                        ticks: u64::from(stf),
                        modulus: 1 << 32,
                        ns_per_tick: NS_PER_SAMPLE_TIME_FINE_TICK,
                    }),
                    sequence: Sequence::Counter {
                        value: u64::from(m.packet_counter.expect("PacketCounter")),
                        modulus: 1 << 16,
                    },
                    gyro_rps: m.rate_of_turn.expect("RateOfTurn"),
                    accel_mps2: m.acceleration.expect("Acceleration"),
                };
                let x = Extras {
                    source: StampSource::Receipt,
                    temperature_c: m.temperature_c.unwrap_or(f64::NAN),
                    saturated: false,
                    dt_s: None,
                };
                out.offer(&c, &x).expect("a good sample is accepted");
            });
            while sub.receive().unwrap().is_some() {
                received += 1;
            }
        }
    };
    run(&frames[..warm], &mut out);
    let (before, published0) = (navsync_tests::allocations(), out.published());
    run(&frames[warm..], &mut out);
    let allocations = navsync_tests::allocations() - before;
    let published = out.published() - published0;
    println!(
        "xsens → publish: {measured} samples, {allocations} heap allocations for {published} published \
         ({received} received); iceoryx2 alone: {per_publish} per publish"
    );
    assert_eq!(out.published(), (warm + measured) as u64, "every sample was published");
    assert!(received >= out.published() - 1, "the subscriber got them ({received})");
    assert_eq!(
        allocations as f64,
        published as f64 * per_publish,
        "heap allocations on the IMU publish path"
    );
    drop((out, sub, reader, node));
    env.finish();
}

#[test]
fn nmea_bytes_to_published_fix_allocate_nothing() {
    if !navsync_tests::in_own_process!() {
        return;
    }
    let _turn = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let env = TestEnv::new("noallocgps");
    let per_publish = iceoryx2_allocations_per_publish!(env, GnssFix, &services::gnss_fix("9"));
    let node = env.node("gnss-0");
    let reader = env.node("reader");
    let mut publisher = node.publisher::<GnssFix>(&services::gnss_fix("0")).unwrap();
    let sub = reader.subscriber::<GnssFix>(&services::gnss_fix("0")).unwrap();
    let (warm, measured) = (20usize, 600usize);
    let t0_utc_ns = 1_790_000_000_000_000_000i64;
    let bursts: Vec<Vec<u8>> = (0..warm + measured)
        .map(|k| {
            let e = EpochReport {
                utc_ns: t0_utc_ns + k as i64 * 1_000_000_000,
                fix: Some(FixReport {
                    lat_deg: 48.137 + 1e-5 * k as f64,
                    lon_deg: 11.576,
                    alt_msl_m: 520.0,
                    geoid_sep_m: 47.0,
                    vel_n_mps: 1.1,
                    vel_e_mps: 0.0,
                    vel_d_mps: 0.0,
                }),
                sats_used: 9,
                hdop: 0.9,
                vdop: 1.4,
                sigma_lat_lon_alt_m: [1.1, 1.0, 2.2],
            };
            let mut out = Vec::new();
            write_burst("GP", &e, &mut out);
            out
        })
        .collect();
    let mut decoder = Decoder::new(Protocol::Nmea);
    let mut host_ns = 5_000_000_000i64;
    let (published, received) = (std::cell::Cell::new(0u64), std::cell::Cell::new(0u64));
    let mut run = |bursts: &[Vec<u8>]| {
        for b in bursts {
            host_ns += 1_000_000_000;
            // 115 200 Bd: 86 806 ns per byte.
            decoder.push(b, host_ns, 86_806, &mut |fix| {
                publisher.publish(fix).expect("publish");
                published.set(published.get() + 1);
            });
            while sub.receive().unwrap().is_some() {
                received.set(received.get() + 1);
            }
        }
    };
    run(&bursts[..warm]);
    let (before, published0) = (navsync_tests::allocations(), published.get());
    run(&bursts[warm..]);
    let allocations = navsync_tests::allocations() - before;
    let (published, received) = (published.get(), received.get());
    let in_window = published - published0;
    println!(
        "nmea → publish: {measured} epochs, {allocations} heap allocations for {in_window} fixes published ({received} received); iceoryx2 alone: {per_publish} per publish"
    );
    // Each epoch is emitted when the next one starts (or its cycle ender arrives).
    assert!(
        published as usize >= warm + measured - 2,
        "fixes published: {published}"
    );
    assert!(received + 1 >= published, "the subscriber got them ({received})");
    assert_eq!(
        allocations as f64,
        in_window as f64 * per_publish,
        "heap allocations on the NMEA publish path"
    );
    drop((publisher, sub, reader, node));
    env.finish();
}
