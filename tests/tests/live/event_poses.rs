//! Events with their pose (issue 39, `estimator/src/events.rs`): the simulator's camera marks
//! its exposures on the receiver's EXTINT (UBX TIM-TM2, `navsync/gnss/0/event`) and a simulated
//! trigger input stamps its edges on the host (`navsync trigger --source sim:5 --id cam0`,
//! `navsync/trigger/cam0/event`); the estimator publishes each with its pose
//! (`navsync/event/{0,cam0}/pose`) once its delayed filter has fused past it. Each pose equals
//! the history's answer for the event's time bit for bit (`state_at` of the mark's UTC,
//! `state_at_host` of the trigger's host time), and the camera's poses are within their σ of
//! the simulator's truth at the exposure.

use std::time::{Duration, Instant};

use navsync_shared::history::{History, Source};
use navsync_shared::samples::{EventPose, SimTruth};
use navsync_shared::services;
use navsync_tests::TestEnv;

use crate::clients_common::{start_live_with, wait_ready};
use crate::history::{error_ned, truth_at};

#[test]
fn camera_marks_and_trigger_edges_get_the_pose_the_history_gives() {
    let mut env = TestEnv::new("evpose");
    // UBX: the simulated camera marks 1 exposure a second (the default with UBX).
    start_live_with(&mut env, "ubx", &["--triggers", "cam0"]);
    env.spawn("trigger", &["trigger", "--source", "sim:5", "--id", "cam0"]);
    let node = env.node("observer");
    let marks = node.subscriber::<EventPose>(&services::event_pose("0")).unwrap();
    let trig = node.subscriber::<EventPose>(&services::event_pose("cam0")).unwrap();
    let truth_sub = node.subscriber::<SimTruth>(services::SIM_TRUTH).unwrap();
    wait_ready(&mut env, &node, true, Duration::from_secs(90));
    while marks.receive().unwrap().is_some() {}
    while trig.receive().unwrap().is_some() {}
    let h = History::open_prefix(&env.prefix).unwrap_or_else(|e| panic!("{e}\n{}", env.log("estimator")));
    let (mut truth, mut got_marks, mut got_trig) = (Vec::new(), Vec::new(), Vec::new());
    let mut early_unposed = 0;
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_secs(8) {
        while let Some(t) = truth_sub.receive().unwrap() {
            truth.push(t);
        }
        // Each pose against the history at once (it holds the last 10 s). An event whose
        // instant precedes the filter's first fused state (it aligned just before `ready`,
        // the receiver reports a mark up to a second after its edge) goes out without a pose,
        // as the estimator documents; the history has no fused state around it either.
        let unfused = |q: Result<navsync_shared::history::Interpolated, _>| {
            q.map_or(true, |q| q.sources != [Some(Source::Fused); 2])
        };
        while let Some(p) = marks.receive().unwrap() {
            if got_marks.is_empty() && p.source == 0 {
                assert!(
                    unfused(h.state_at(p.utc_ns)),
                    "the history has fused states around {p:?}"
                );
                early_unposed += 1;
                continue;
            }
            let q = h.state_at(p.utc_ns).unwrap_or_else(|e| panic!("{e}: {p:?}"));
            got_marks.push((p, q));
        }
        while let Some(p) = trig.receive().unwrap() {
            if got_trig.is_empty() && p.source == 0 {
                assert!(
                    unfused(h.state_at_host(p.host_ns)),
                    "the history has fused states around {p:?}"
                );
                early_unposed += 1;
                continue;
            }
            let q = h.state_at_host(p.host_ns).unwrap_or_else(|e| panic!("{e}: {p:?}"));
            got_trig.push((p, q));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    env.assert_running();
    println!(
        "{} camera marks and {} trigger edges posed in 8 s ({early_unposed} before the first fused state, without a pose)",
        got_marks.len(),
        got_trig.len()
    );
    // At most the events of the second before the filter's first fused state.
    assert!(early_unposed <= 6, "{early_unposed} events without a pose at the start");
    // 1 exposure a second (rising and falling edge each), 5 trigger edges a second.
    assert!(got_marks.len() >= 10, "{} camera marks", got_marks.len());
    assert!(got_trig.len() >= 30, "{} trigger edges", got_trig.len());
    for (p, q) in got_marks.iter().chain(&got_trig) {
        assert_eq!(p.source, Source::Fused as u8, "{p:?}");
        assert_eq!(q.sources, [Some(Source::Fused); 2], "{p:?}");
        assert_eq!(
            (
                p.lat_deg,
                p.lon_deg,
                p.height_m,
                p.q_nb,
                p.pos_std_ned_m,
                p.host_ns,
                p.utc_ns
            ),
            (
                q.pose.lat_deg,
                q.pose.lon_deg,
                q.pose.height_m,
                q.pose.q_nb,
                q.pose.pos_std_ned_m,
                q.host_ns,
                q.utc_ns
            ),
            "the pose differs from the history's"
        );
    }
    for (p, _) in &got_trig {
        assert_eq!(p.gps_ns, i64::MIN);
        assert_eq!(p.host_ns % 200_000_000, 0, "sim:5 edges are on a 200 ms grid");
    }
    // Against the truth: horizontal error within 3σ (the mark's host time is the truth's).
    let mut checked = 0;
    for (p, _) in &got_marks {
        let Some(want) = truth_at(&truth, p.host_ns) else {
            continue;
        };
        let e = error_ned(&want, p.lat_deg, p.lon_deg, p.height_m);
        let (eh, sh) = (e[0].hypot(e[1]), p.pos_std_ned_m[0].hypot(p.pos_std_ned_m[1]));
        assert!(eh <= 3.0 * sh, "{eh} m against σ {sh} m: {p:?}");
        checked += 1;
    }
    assert!(checked >= 5, "{checked} marks within the truth");
    drop((marks, trig, truth_sub, node));
    env.finish();
}
