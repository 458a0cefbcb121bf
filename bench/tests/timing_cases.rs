//! Time mapping from simulated PPS (host oscillator +0.5 ppm with random-walk frequency noise,
//! 1 µs edge jitter), labelled by the NMEA that follows each edge: after 30 s the mapped host
//! time of every truth instant is within 5 µs of the true UTC, and the reported 1-sigma is
//! honest (the error stays within 4 sigma).

use navsync_estimator::pipeline::Pipeline;
use navsync_estimator::settings::Settings;
use navsync_shared::samples::{AnySample, TimeStatus};
use navsync_sim::imu_errors::ImuPreset;
use navsync_sim::published::PublishedStream;
use navsync_sim::scenario::SimConfig;
use navsync_sim::world::World;

#[test]
fn pps_time_mapping_is_within_5_us_after_30_s() {
    let mut cfg = SimConfig::default_drive();
    cfg.set_imu_count(1);
    cfg.set_clock_ppm(0.5);
    cfg.set_pps_jitter_s(1e-6);
    let host0 = 7_000_000_000i64;
    let world = World::new(&cfg, host0, 1_790_000_000_000_000_000).expect("world");
    let args = Settings {
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

/// The README's timing table (`navsync-bench timing`), asserted: simulated oscillator 0.5 ppm
/// with a random-walk frequency (Allan deviation 1e−10 at 1 s), PPS jitter 1 µs (kernel-like)
/// and 30 µs (user space): mapped-time RMS error ≤ 1 µs and ≤ 10 µs; holdover error 60 s after
/// the PPS and GNSS are lost ≤ 10 µs; the reported 2σ covers the actual error ≥ 95 % of the
/// time; the PPS coming back moves the mapping by less than 2σ of its holdover uncertainty;
/// labels stay right with d0 = 0.9 s ± 20 ms; d0 measured within 5 µs of the simulated latency.
#[test]
fn timing_benchmark_meets_the_issue_bounds() {
    use navsync_bench::timing::{TimingCase, run_case};
    for case in TimingCase::standard() {
        let r = run_case(&case).expect("case runs");
        println!("{}: {r:?}", case.name);
        let bound_ns = if case.pps_jitter_s > 10e-6 { 10_000.0 } else { 1_000.0 };
        assert!(r.instants > 20_000, "{}: {} instants", case.name, r.instants);
        assert!(r.rms_ns <= bound_ns, "{}: RMS {} ns > {bound_ns}", case.name, r.rms_ns);
        assert!(
            r.coverage_2sigma >= 0.95,
            "{}: 2σ covers {}",
            case.name,
            r.coverage_2sigma
        );
        if case.outage.is_some() {
            let h = r.holdover_60s_ns.expect("holdover measured");
            assert!(h.abs() <= 10_000.0, "{}: holdover error {h} ns", case.name);
            let (jump, sigma) = (
                r.recovery_jump_ns.expect("recovered"),
                r.recovery_sigma_ns.expect("σ before recovery"),
            );
            assert!(
                jump <= 2.0 * sigma,
                "{}: recovery jump {jump} ns vs σ {sigma} ns",
                case.name
            );
        }
        if case.latency_s.1 == 0.0 {
            assert!(
                r.d0_median_error_s.abs() <= 5e-6,
                "{}: d0 off by {} s",
                case.name,
                r.d0_median_error_s
            );
        }
        assert!(r.pps_used > 200, "{}: {} edges used", case.name, r.pps_used);
    }
}
