//! The estimator allocates nothing per sample in steady state: with a counting global
//! allocator, feeding one simulated minute of IMU samples, PPS edges and GNSS fixes to an
//! aligned estimator performs zero heap allocations (buffers are sized once, at start).
//!
//! The allocator counts per thread: the estimator is a functional core without threads, so the
//! allocations of this test's thread are the estimator's, and the other tests of this binary,
//! running on other threads meanwhile, are not counted.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use navsync_estimator::pipeline::Pipeline;
use navsync_estimator::settings::Settings;
use navsync_sim::imu_errors::ImuPreset;
use navsync_sim::published::PublishedStream;
use navsync_sim::scenario::SimConfig;
use navsync_sim::world::World;
use navsync_wire::samples::{AnySample, NavStatus};

struct Counting;

thread_local! {
    /// Allocations and reallocations of this thread (const-initialised, no destructor: usable
    /// inside the allocator).
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
}

// SAFETY: forwards to the system allocator; only counts.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.set(ALLOCATIONS.get() + 1);
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.set(ALLOCATIONS.get() + 1);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn no_heap_allocation_per_sample_in_steady_state() {
    let mut cfg = SimConfig::default_drive();
    cfg.set_imu_count(1);
    cfg.set_imu_preset(ImuPreset::Industrial);
    let host0 = 2_000_000_000i64;
    let world = World::new(&cfg, host0, 1_790_000_000_000_000_000).expect("world");
    // Produce the samples first: the simulator allocates (NMEA bursts); the estimator must not.
    let samples: Vec<AnySample> = PublishedStream::new(world)
        .take_while(|p| p.delivered_ns - host0 < 180_000_000_000)
        .map(|p| p.sample)
        .collect();
    let mut p = Pipeline::new(Settings::default().pipeline_config());
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
    assert_eq!(
        last_status,
        Some(NavStatus::Aligned as u8),
        "aligned and aided before measuring"
    );
    let (mut imu, mut fixes) = (0, 0);
    let before = ALLOCATIONS.get();
    for s in &samples[split..] {
        match s {
            AnySample::Imu(_) => imu += 1,
            AnySample::GnssFix(_) => fixes += 1,
            _ => {}
        }
        feed(&mut p, s);
    }
    let allocations = ALLOCATIONS.get() - before;
    assert!(imu > 10_000 && fixes > 50, "{imu} IMU samples, {fixes} fixes");
    assert_eq!(
        allocations, 0,
        "{allocations} heap allocations over {imu} IMU samples and {fixes} fixes"
    );
}
