//! The history of states allocates nothing per write or per query (issue 39): with a counting
//! global allocator, 20 000 states appended to a history of 10 000 and 20 000 queries by host
//! time and by UTC (inside it, and outside on either side) perform zero heap allocations.

use navsync_shared::history::{History, HistoryError, HistoryWriter, Source};
use navsync_shared::reflect::Reflect;
use navsync_shared::samples::NavState;

#[test]
fn no_heap_allocation_per_write_or_query() {
    if !navsync_tests::in_own_process!() {
        return;
    }
    let env = navsync_tests::TestEnv::new("histalloc");
    let mut w = HistoryWriter::create(&env.prefix, 10_000).expect("history");
    let h = History::open_prefix(&env.prefix).expect("open");
    let mut s = NavState::zeroed();
    s.q_nb = [1.0, 0.0, 0.0, 0.0];
    s.lat_deg = 48.0;
    s.lon_deg = 11.0;
    s.vel_ned_mps = [10.0, 0.0, 0.0];
    let (mut ok, mut outside) = (0u64, 0u64);
    // Whatever happens once (the first write, the first answer and error of each kind) is not
    // per write or per query: done before counting.
    for k in 0..3i64 {
        s.host_ns = k * 1_000_000;
        s.utc_ns = 1_700_000_000_000_000_000 + s.host_ns;
        w.append(&s, Source::Predicted);
    }
    for t in [-1_000_000_000, 500_000, 1_000_000_000] {
        let _ = h.state_at_host(t);
        let _ = h.state_at(1_700_000_000_000_000_000 + t);
    }
    // This thread's: the writer and the queries run on it (the harness's threads do not count).
    let before = navsync_tests::thread_allocations();
    for k in 0..20_000i64 {
        s.host_ns = 1_000_000_000 + k * 1_000_000;
        s.utc_ns = 1_700_000_000_000_000_000 + s.host_ns;
        s.lat_deg += 1e-7;
        w.append(&s, Source::Predicted);
        if k >= 2 {
            let t = s.host_ns - (k % 12_000) * 1_000_000 + 500_000;
            match h.state_at_host(t) {
                Ok(_) => ok += 1,
                Err(HistoryError::TooOld { .. } | HistoryError::TooNew { .. }) => outside += 1,
                Err(e) => panic!("{e}"),
            }
            match h.state_at(1_700_000_000_000_000_000 + t) {
                Ok(_) => ok += 1,
                Err(HistoryError::TooOld { .. } | HistoryError::TooNew { .. }) => outside += 1,
                Err(e) => panic!("{e}"),
            }
        }
    }
    let allocations = navsync_tests::thread_allocations() - before;
    println!(
        "{} states written, {ok} answers, {outside} outside: {allocations} allocations",
        w.written()
    );
    assert!(ok > 10_000 && outside > 1_000, "{ok} {outside}");
    assert_eq!(allocations, 0, "{allocations} heap allocations");
    drop((h, w));
    env.finish();
}
