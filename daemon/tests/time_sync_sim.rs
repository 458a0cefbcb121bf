//! Time mapping from simulated PPS (host oscillator +0.5 ppm with random-walk frequency noise,
//! 1 µs edge jitter), labelled by the NMEA that follows each edge: after 30 s the mapped host
//! time of every truth instant is within 5 µs of the true UTC, and the reported 1-sigma is
//! honest (the error stays within 4 sigma).

use navsync::estimator::pipeline::Pipeline;
use navsync::roles::estimator::EstimatorArgs;
use navsync_drivers::sim::imu_errors::ImuPreset;
use navsync_drivers::sim::published::PublishedStream;
use navsync_drivers::sim::scenario::SimConfig;
use navsync_drivers::sim::world::World;
use navsync_shared::samples::{AnySample, TimeStatus};

#[test]
fn pps_time_mapping_is_within_5_us_after_30_s() {
    let mut cfg = SimConfig::default_drive();
    cfg.set_imu_count(1);
    cfg.set_clock_ppm(0.5);
    cfg.set_pps_jitter_s(1e-6);
    let host0 = 7_000_000_000i64;
    let world = World::new(&cfg, host0, 1_790_000_000_000_000_000).expect("world");
    let args = EstimatorArgs {
        gnss_ids: vec!["0".into()],
        pps_ids: vec!["0".into()],
        imu_ids: vec!["0".into()],
        software_sync: false,
        imu_model: ImuPreset::Industrial,
        estimate_delay: true,
        ..Default::default()
    };
    let mut p = Pipeline::new(args.pipeline_config());
    let (mut checked, mut worst, mut worst_sigmas) = (0u64, 0.0f64, 0.0f64);
    for item in PublishedStream::new(world) {
        let t = item.delivered_ns - host0;
        if t > 60_000_000_000 {
            break;
        }
        match item.sample {
            AnySample::PpsEdge(e) => {
                p.on_pps(&e);
            }
            AnySample::GnssFix(f) => {
                p.on_fix(&f);
            }
            AnySample::Imu(s) => {
                p.on_imu(&s);
            }
            AnySample::Truth(tr) if t > 30_000_000_000 => {
                let state = p.time_state(tr.host_ns);
                assert_eq!(state.status(), TimeStatus::Locked, "at {} s", t as f64 * 1e-9);
                let err = (state.utc_ns_at(tr.host_ns) - tr.utc_ns) as f64;
                worst = worst.max(err.abs());
                worst_sigmas = worst_sigmas.max(err.abs() / state.utc_std_ns_at(tr.host_ns));
                checked += 1;
            }
            _ => {}
        }
    }
    println!("{checked} instants after 30 s: worst error {worst:.0} ns, worst {worst_sigmas:.2} sigma");
    assert!(checked > 2000, "{checked}");
    assert!(worst < 5_000.0, "mapping error {worst} ns");
    assert!(
        worst_sigmas < 4.0,
        "error {worst_sigmas} sigma: the reported uncertainty is not honest"
    );
}
