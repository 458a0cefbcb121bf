//! The history of states any process can query (issue 39, `shared/src/history.rs`): the live
//! set of `clients_common` (sim, gps, pps, estimator), the history opened from this process,
//! `state_at_host` at random instants against the simulator's truth (`navsync/sim/truth`, 10 Hz,
//! interpolated between its samples with the same cubic Hermite and slerp), and a reader
//! stopped with SIGSTOP in the middle of its reads: the estimator keeps writing and other
//! readers keep reading. The Python reader (`shared/python/navsync_history.py`) answers as Rust.

use std::time::{Duration, Instant};

use navsync_shared::earth;
use navsync_shared::history::{self, History, HistoryError, Record, Source};
use navsync_shared::reflect::Reflect;
use navsync_shared::samples::{NavState, SimTruth};
use navsync_shared::services;
use navsync_shared::time::monotonic_now_ns;
use navsync_tests::TestEnv;

use crate::clients_common::{command_in, repo_root, start_live, wait_ready};

/// A truth sample as a history record (the interpolation's input).
pub(crate) fn truth_record(t: &SimTruth) -> Record {
    let mut s = NavState::zeroed();
    (s.host_ns, s.utc_ns, s.lat_deg, s.lon_deg, s.height_m) = (t.host_ns, t.utc_ns, t.lat_deg, t.lon_deg, t.height_m);
    s.vel_ned_mps = t.vel_ned_mps;
    let [r, p, y] = t.rpy_rad.map(|a| a / 2.0);
    let (sr, cr, sp, cp, sy, cy) = (r.sin(), r.cos(), p.sin(), p.cos(), y.sin(), y.cos());
    s.q_nb = [
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    ];
    Record::of(&s, Source::Predicted)
}

/// The truth at `host_ns` (between its 10 Hz samples).
pub(crate) fn truth_at(truth: &[SimTruth], host_ns: i64) -> Option<history::Interpolated> {
    let k = truth.partition_point(|t| t.host_ns <= host_ns);
    (k > 0 && k < truth.len())
        .then(|| history::interpolate(&truth_record(&truth[k - 1]), &truth_record(&truth[k]), host_ns))
}

/// NED error of (lat, lon, h) against the truth, m.
pub(crate) fn error_ned(truth: &history::Interpolated, lat: f64, lon: f64, h: f64) -> [f64; 3] {
    earth::ned_between(
        truth.pose.lat_deg.to_radians(),
        truth.pose.lon_deg.to_radians(),
        truth.pose.height_m,
        lat.to_radians(),
        lon.to_radians(),
        h,
    )
}

#[test]
fn states_at_any_instant_against_the_truth_and_a_stopped_reader_blocks_nobody() {
    let mut env = TestEnv::new("history");
    start_live(&mut env);
    let node = env.node("observer");
    let truth_sub = node.subscriber::<SimTruth>(services::SIM_TRUTH).unwrap();
    wait_ready(&mut env, &node, true, Duration::from_secs(90));
    // Aligned: 8 s of states and truth from here.
    while truth_sub.receive().unwrap().is_some() {}
    let mut truth = Vec::new();
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_secs(8) {
        while let Some(t) = truth_sub.receive().unwrap() {
            truth.push(t);
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let path = history::path_for(&env.prefix);
    let h = History::open_prefix(&env.prefix).unwrap_or_else(|e| panic!("{e}\n{}", env.log("estimator")));
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(&path).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o640, "{}", path.display());
    }
    assert_eq!(h.writer_pid(), env.pid("estimator").unwrap());
    let newest = h.newest().unwrap();
    // Inside the truth by more than a state's interval, so that the nearest state has a truth too.
    let span = (
        truth[0].host_ns + 20_000_000,
        (truth.last().unwrap().host_ns - 20_000_000).min(newest.host_ns),
    );
    println!(
        "history: {} records written, capacity {}, truth {} samples over {:.1} s",
        h.write_index(),
        h.capacity(),
        truth.len(),
        (span.1 - span.0) as f64 * 1e-9
    );
    assert!(span.1 - span.0 > 5_000_000_000, "too little overlap: {span:?}");

    // Random instants (a fixed LCG), each against the truth there; the nearest stored state
    // against the truth at its own instant.
    let mut x = 0x2545_f491_4f6c_dd1du64;
    let n = 2000;
    let (mut within_axis, mut within_h) = ([0usize; 3], 0usize);
    // Horizontal error within 2σ and 3σ of the horizontal σ.
    let (mut within_h2, mut within_h3) = (0usize, 0usize);
    let (mut sq_interp, mut sq_nearest) = (0.0f64, 0.0f64);
    let mut max_h_interp = 0.0f64;
    // Queries whose 3-D error is at most 1.05 × the nearest stored state's own (+ 1 mm).
    let mut within_nearest = 0usize;
    let mut fused = 0usize;
    for _ in 0..n {
        x = x
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        let t = span.0 + ((x >> 11) % (span.1 - span.0) as u64) as i64;
        let got = h.state_at_host(t).unwrap_or_else(|e| panic!("{t}: {e}"));
        // Two states of one ring: the fused ones where they reach, else the predicted ones.
        assert!(
            got.sources == [Some(Source::Fused); 2] || got.sources == [Some(Source::Predicted); 2],
            "{t}: {:?}",
            got.sources
        );
        fused += usize::from(got.sources[0] == Some(Source::Fused));
        let want = truth_at(&truth, t).unwrap();
        let e = error_ned(&want, got.pose.lat_deg, got.pose.lon_deg, got.pose.height_m);
        for i in 0..3 {
            within_axis[i] += usize::from(e[i].abs() <= got.pose.pos_std_ned_m[i]);
        }
        let eh = e[0].hypot(e[1]);
        let sh = got.pose.pos_std_ned_m[0].hypot(got.pose.pos_std_ned_m[1]);
        within_h += usize::from(eh <= sh);
        within_h2 += usize::from(eh <= 2.0 * sh);
        within_h3 += usize::from(eh <= 3.0 * sh);
        max_h_interp = max_h_interp.max(eh);
        sq_interp += e.iter().map(|v| v * v).sum::<f64>();
        // The two stored states around the instant, each against the truth at its own time.
        let stored_error = |at: i64| {
            let s = h.state_at_host(at).unwrap();
            error_ned(
                &truth_at(&truth, at).unwrap(),
                s.pose.lat_deg,
                s.pose.lon_deg,
                s.pose.height_m,
            )
        };
        let norm = |v: [f64; 3]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
        let (ea, eb) = (
            stored_error(got.bracket_host_ns[0]),
            stored_error(got.bracket_host_ns[1]),
        );
        let en = if got.fraction <= 0.5 { ea } else { eb };
        sq_nearest += en.iter().map(|v| v * v).sum::<f64>();
        within_nearest += usize::from(norm(e) <= 1.05 * norm(en) + 1e-3);
        // Never worse than the worse of the two (a filter update between them is a step).
        assert!(
            norm(e) <= 1.05 * norm(ea).max(norm(eb)) + 1e-3,
            "{t}: {e:?} against the stored states' {ea:?} and {eb:?}"
        );
    }
    let pct = |k: usize| 100.0 * k as f64 / n as f64;
    println!(
        "{:.1} % of the queries answered from the delayed filter's fused states ({} fused records written)",
        pct(fused),
        h.write_index_of(Source::Fused)
    );
    // The instants the delayed filter has passed (all but the last fusion horizon, ≤ 1.5 s, of
    // the 8 s and more) answer from its states.
    assert!(pct(fused) >= 50.0, "only {:.1} % from fused states", pct(fused));
    // An instant 0.5 s or more old at a fused state's own time: that state, as the delayed
    // filter had it.
    let nf = h.write_index_of(Source::Fused);
    let newest_fused = h.record_of(Source::Fused, nf - 1).unwrap().unwrap();
    let mut checked = 0;
    for i in (nf.saturating_sub(h.capacity() / 2)..nf).step_by(23) {
        let Some(r) = h.record_of(Source::Fused, i).unwrap() else {
            continue;
        };
        if r.host_ns > newest_fused.host_ns - 500_000_000 {
            continue;
        }
        let got = h.state_at_host(r.host_ns).unwrap();
        assert_eq!(got.sources[0], Some(Source::Fused));
        assert!(
            (got.pose.lat_deg - r.pose.lat_deg).abs() < 1e-12
                && (got.pose.lon_deg - r.pose.lon_deg).abs() < 1e-12
                && (got.pose.height_m - r.pose.height_m).abs() < 1e-9
                && got.pose.pos_std_ned_m == r.pose.pos_std_ned_m,
            "{}: {got:?} against the fused state {r:?}",
            r.host_ns
        );
        checked += 1;
    }
    assert!(checked >= 10, "only {checked} fused states checked");
    let (rms_i, rms_n) = ((sq_interp / n as f64).sqrt(), (sq_nearest / n as f64).sqrt());
    println!(
        "{n} queries: |error| ≤ σ north {:.1} %, east {:.1} %, down {:.1} %, horizontal {:.1} % (2σ {:.1} %, 3σ {:.1} %); \
         3-D RMS interpolated {rms_i:.3} m, nearest stored state {rms_n:.3} m (ratio {:.4}), ≤ 1.05 × the nearest state's own in {:.1} %, max horizontal {max_h_interp:.3} m",
        pct(within_axis[0]),
        pct(within_axis[1]),
        pct(within_axis[2]),
        pct(within_h),
        pct(within_h2),
        pct(within_h3),
        rms_i / rms_n,
        pct(within_nearest)
    );
    assert!(
        pct(within_h2) >= 95.0,
        "horizontal error within 2σ in only {:.1} %",
        pct(within_h2)
    );
    assert!(
        rms_i <= 1.05 * rms_n,
        "interpolated {rms_i} m against the nearest state's {rms_n} m"
    );
    // Not all: between two states with a filter update the nearer may be the better one.
    assert!(
        pct(within_nearest) >= 99.0,
        "{within_nearest} queries within 1.05 × the nearest state's error"
    );
    // Outside: which side.
    assert!(matches!(
        h.state_at_host(monotonic_now_ns() + 10_000_000_000),
        Err(HistoryError::TooNew { .. })
    ));
    assert!(matches!(h.state_at_host(1), Err(HistoryError::TooOld { .. })));
    // By UTC: the same state as by host time.
    let mid = h.state_at_host((span.0 + span.1) / 2).unwrap();
    let by_utc = h.state_at(mid.utc_ns).unwrap();
    assert!(
        (by_utc.host_ns - mid.host_ns).abs() <= 1,
        "{} {}",
        by_utc.host_ns,
        mid.host_ns
    );

    // The Python reader (standard library only) gives the same answer.
    let t = (span.0 + span.1) / 2 + 1_234_567;
    let want = h.state_at_host(t).unwrap();
    let o = command_in(&env, "python3")
        .arg(repo_root().join("shared/python/navsync_history.py"))
        .arg(t.to_string())
        .output()
        .expect("python3");
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{out}{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_str(out.trim()).unwrap_or_else(|e| panic!("{e}: {out}"));
    for (k, x) in [
        ("lat_deg", want.pose.lat_deg),
        ("lon_deg", want.pose.lon_deg),
        ("height_m", want.pose.height_m),
    ] {
        let y = v[k].as_f64().unwrap();
        assert!((x - y).abs() < 1e-9, "{k}: Rust {x}, Python {y}");
    }
    assert!((v["rpy_rad"][2].as_f64().unwrap() - want.pose.rpy_rad[2]).abs() < 1e-9);

    stopped_reader_blocks_nobody(&h);
    drop((truth_sub, node));
    env.finish();
    assert!(!path.exists(), "{} left behind", path.display());
}

/// A child process reading the history in a loop is stopped with SIGSTOP (in the middle of a
/// read, where it spends its time): the write index keeps advancing and this process's
/// queries keep succeeding; then SIGCONT (it reads on) and SIGKILL.
fn stopped_reader_blocks_nobody(h: &History) {
    // A counter the child increments after each query, in memory shared with it.
    // SAFETY: an anonymous shared mapping of one page, unmapped below.
    let page = unsafe {
        libc::mmap(
            std::ptr::null_mut(),
            4096,
            libc::PROT_READ | libc::PROT_WRITE,
            libc::MAP_SHARED | libc::MAP_ANONYMOUS,
            -1,
            0,
        )
    };
    assert_ne!(page, libc::MAP_FAILED);
    // SAFETY: page-aligned, 4096 bytes, shared with the child only through this atomic.
    let reads = unsafe { &*(page as *const std::sync::atomic::AtomicU64) };
    // SAFETY: the child only reads the mapped history (atomic loads, no allocation, no lock),
    // counts and never returns; it is killed below.
    let pid = unsafe { libc::fork() };
    assert!(pid >= 0, "fork failed");
    if pid == 0 {
        loop {
            let t = monotonic_now_ns() - 100_000_000;
            if h.state_at_host(t).is_ok() {
                reads.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            }
        }
    }
    let count = || reads.load(std::sync::atomic::Ordering::Relaxed);
    let t0 = Instant::now();
    while count() < 1000 {
        assert!(
            t0.elapsed() < Duration::from_secs(10),
            "the child reader made no queries"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    // SAFETY: signalling our own child.
    unsafe { libc::kill(pid, libc::SIGSTOP) };
    std::thread::sleep(Duration::from_millis(100));
    let (r0, w0) = (count(), h.write_index());
    let mut ours = 0;
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_secs(2) {
        h.state_at_host(monotonic_now_ns() - 100_000_000)
            .unwrap_or_else(|e| panic!("a query while the other reader is stopped: {e}"));
        ours += 1;
        std::thread::sleep(Duration::from_millis(1));
    }
    let (r1, w1) = (count(), h.write_index());
    println!(
        "reader stopped after {r0} queries: the estimator wrote {} records in 2 s, this process made {ours} queries",
        w1 - w0
    );
    assert_eq!(r0, r1, "the stopped child went on reading");
    assert!(
        w1 - w0 >= 150,
        "the estimator wrote {} records in 2 s while a reader was stopped",
        w1 - w0
    );
    // SAFETY: signalling our own child.
    unsafe { libc::kill(pid, libc::SIGCONT) };
    let t0 = Instant::now();
    while count() == r1 {
        assert!(
            t0.elapsed() < Duration::from_secs(5),
            "the continued reader made no query"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    // SAFETY: killing and reaping our own child; then unmapping the page.
    unsafe {
        libc::kill(pid, libc::SIGKILL);
        libc::waitpid(pid, std::ptr::null_mut(), 0);
        libc::munmap(page, 4096);
    }
}
