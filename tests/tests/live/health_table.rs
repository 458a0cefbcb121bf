//! The health report's counter table: every process registers its counters by name; a table
//! that is full or a name that is too long is an error, never a silently shared or truncated
//! slot, and what was registered is what a subscriber reads.

use navsync_shared::health_reporter::{HealthError, HealthReporter, MAX_NAME_LEN};
use navsync_shared::samples::{Health, MAX_COUNTERS, MAX_RATES};
use navsync_shared::services;
use navsync_tests::TestEnv;

#[test]
fn a_full_table_is_an_error_and_every_registered_counter_arrives() {
    let env = TestEnv::new("healthtbl");
    {
        let node = env.node("tbl");
        let sub = node.subscriber::<Health>(&services::health("tbl")).unwrap();
        let mut h = HealthReporter::new(&node, "tbl").unwrap();
        // The estimator with 8 IMUs, 2 receivers and 2 PPS sources registers 21 + 12 counters;
        // a GNSS driver with two protocols' decoders about 40: both fit.
        let ids: Vec<_> = (0..MAX_COUNTERS)
            .map(|i| h.counter(&format!("counter_{i}")).unwrap())
            .collect();
        // Registering a name again finds its slot.
        assert_eq!(h.counter("counter_7").unwrap(), ids[7]);
        match h.counter("one_too_many") {
            Err(HealthError::Full { name, capacity, .. }) => {
                assert_eq!((name.as_str(), capacity), ("one_too_many", MAX_COUNTERS));
            }
            other => panic!("{other:?}"),
        }
        assert!(h.set_named("another_one", 1).is_err());
        let long = "x".repeat(MAX_NAME_LEN + 1);
        assert!(matches!(
            HealthReporter::new(&node, "tbl2").unwrap().counter(&long),
            Err(HealthError::NameTooLong { .. })
        ));
        for i in 0..MAX_RATES {
            h.rate(&format!("rate_{i}")).unwrap();
        }
        assert!(h.rate("rate_x").is_err());
        for (i, id) in ids.iter().enumerate() {
            h.set(*id, i as u64 * 10);
        }
        h.publish_now(1).unwrap();
        let got = sub.receive().unwrap().expect("a report");
        for i in 0..MAX_COUNTERS {
            assert_eq!(got.counter(&format!("counter_{i}")), Some(i as u64 * 10), "counter_{i}");
        }
        assert_eq!(got.counter("one_too_many"), None);
    }
    env.finish();
}
