//! The tightly coupled estimator allocates nothing per sample in steady state (issue 17): with
//! a counting global allocator, one simulated minute of the default drive on the simulator's
//! GPS sky — IMU samples (on the receiver's crystal, so the one-crystal timing runs too), PPS
//! edges, fixes, RXM-RAWX epochs with their per-satellite updates and RXM-SFRBX subframes —
//! fed to an aligned `--coupling tight` estimator performs zero heap allocations.

use navsync_estimator::pipeline::Pipeline;
use navsync_estimator::settings::{Coupling, Settings};
use navsync_shared::samples::{AnySample, NavStatus};
use navsync_sim::gps;
use navsync_sim::imu_errors::ImuPreset;
use navsync_sim::published::PublishedStream;
use navsync_sim::scenario::{ImuUnitConfig, OutputProtocol, SimConfig};
use navsync_sim::world::World;

#[test]
fn no_heap_allocation_per_sample_tightly_coupled() {
    if !navsync_tests::in_own_process!() {
        return;
    }
    let mut cfg = SimConfig::default_drive();
    cfg.set_imu_count(1);
    cfg.set_imu_preset(ImuPreset::Industrial);
    cfg.imu.units = vec![ImuUnitConfig {
        receiver_clock: true,
        ..ImuUnitConfig::default()
    }];
    cfg.gnss.protocol = OutputProtocol::Ubx;
    cfg.gnss.sky.almanac = Some("m8t".into());
    cfg.gnss.sky.constellation = gps::parse_yuma(&navsync_tests::m8t_yuma()).expect("YUMA");
    let host0 = 2_000_000_000i64;
    let world = World::new(&cfg, host0, 1_796_083_200_000_000_000).expect("world");
    // Produce the samples first: the simulator allocates (UBX frames); the estimator must not.
    let samples: Vec<AnySample> = PublishedStream::new(world)
        .take_while(|p| p.delivered_ns - host0 < 180_000_000_000)
        .map(|p| p.sample)
        .collect();
    let settings = {
        let mut s = Settings::default();
        s.nav.coupling = Coupling::Tight;
        s.imu.imu_model = ImuPreset::Industrial;
        s
    };
    let mut p = Pipeline::new(settings.pipeline_config());
    let feed = |p: &mut Pipeline, s: &AnySample| match s {
        AnySample::Imu(x) => p.on_imu(x).map(|n| n.status),
        AnySample::GnssFix(f) => {
            p.on_fix(f);
            None
        }
        AnySample::PpsEdge(e) => {
            p.on_pps(e);
            None
        }
        AnySample::Raw(r) => {
            p.on_raw(r);
            None
        }
        AnySample::NavData(d) => {
            p.on_nav_data(d);
            None
        }
        AnySample::TimePulse(t) => {
            p.on_time_pulse(t);
            None
        }
        _ => None,
    };
    let split = samples
        .iter()
        .position(|s| s.host_ns() - host0 > 120_000_000_000)
        .expect("two minutes");
    let mut last_status = None;
    for s in &samples[..split] {
        last_status = feed(&mut p, s).or(last_status);
    }
    assert_eq!(last_status, Some(NavStatus::Aligned as u8), "aligned before measuring");
    let counter = |p: &Pipeline, name: &str| {
        let mut v = 0;
        p.nav().measurement_states().each_counter(&mut |n, x| {
            if n == name {
                v = x;
            }
        });
        p.each_raw_counter(&mut |n, x| {
            if n == name {
                v = x;
            }
        });
        v
    };
    let (ranges0, timed0) = (counter(&p, "ranges_used"), counter(&p, "rx_clock_imu"));
    let (mut imu, mut raw, mut nav_data) = (0, 0, 0);
    let before = navsync_tests::allocations();
    for s in &samples[split..] {
        match s {
            AnySample::Imu(_) => imu += 1,
            AnySample::Raw(_) => raw += 1,
            AnySample::NavData(_) => nav_data += 1,
            _ => {}
        }
        feed(&mut p, s);
    }
    let allocations = navsync_tests::allocations() - before;
    let (ranges, timed) = (
        counter(&p, "ranges_used") - ranges0,
        counter(&p, "rx_clock_imu") - timed0,
    );
    println!(
        "{imu} IMU samples ({timed} timed by the receiver clock), {raw} raw epochs ({ranges} pseudoranges fused), {nav_data} subframes: {allocations} allocations"
    );
    assert!(
        imu > 10_000 && raw > 50 && nav_data > 10,
        "{imu} IMU, {raw} raw, {nav_data} subframes"
    );
    assert!(
        ranges > 4 * 50 && timed > 10_000,
        "{ranges} ranges fused, {timed} IMU samples timed"
    );
    assert_eq!(allocations, 0, "{allocations} heap allocations");
}
