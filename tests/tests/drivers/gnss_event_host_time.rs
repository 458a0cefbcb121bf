//! TIM-TM2 time marks (a camera's exposure pulse on the receiver's EXTINT pin) reach other
//! processes on `navsync/gnss/{id}/event` with their GNSS time and, through the estimator's
//! host → GNSS time mapping (`navsync/time/state`), their host `CLOCK_MONOTONIC` time: this
//! test plays a u-blox receiver on a pseudo-terminal and the estimator's time state on
//! iceoryx2, and checks that a live `navsync gnss --protocol ubx` publishes each mark with
//! host times equal to the mapping's inverse at the mark's UTC (GPS − leap seconds); marks
//! that arrive before any usable mapping are published with unknown host times and counted
//! (`events_unmapped`).

use std::time::{Duration, Instant};

use navsync_drivers::gnss::ubx::framer::ubx_frame;
use navsync_drivers::pty::Pty;
use navsync_shared::samples::{GnssEvent, Health, TimeState, TimeStatus};
use navsync_shared::services;
use navsync_shared::time::{monotonic_now_ns, utc_ns_from_gps_ns};
use navsync_tests::TestEnv;

/// GPS week of the marks (2026-11-29 .. 2026-12-05).
const WEEK: u16 = 2412;

/// UBX-TIM-TM2 with a new rising and falling edge on EXTINT0, GNSS time base, time valid.
fn tim_tm2(count: u16, tow_ms: u32, sub_ns: u32) -> Vec<u8> {
    let mut p = Vec::with_capacity(28);
    p.push(0); // ch
    p.push(0x80 | 0x40 | 0x04 | (1 << 3) | 0x01); // newRisingEdge, time valid, newFallingEdge, GNSS, running
    p.extend(count.to_le_bytes());
    p.extend(WEEK.to_le_bytes());
    p.extend(WEEK.to_le_bytes());
    p.extend(tow_ms.to_le_bytes());
    p.extend(sub_ns.to_le_bytes());
    p.extend((tow_ms + 2).to_le_bytes()); // falling edge 2 ms later
    p.extend(sub_ns.to_le_bytes());
    p.extend(25u32.to_le_bytes()); // accEst, ns
    ubx_frame(0x0D, 0x03, &p)
}

fn gps_ns(tow_ms: u32, sub_ns: u32) -> i64 {
    i64::from(WEEK) * 604_800_000_000_000 + i64::from(tow_ms) * 1_000_000 + i64::from(sub_ns)
}

#[test]
fn time_marks_carry_gnss_and_host_times() {
    let mut env = TestEnv::new("gnssevent");
    let node = env.node("observer");
    let events = node.subscriber::<GnssEvent>(&services::gnss_event("cam")).unwrap();
    let health = node.subscriber::<Health>(&services::health("gnss-cam")).unwrap();
    let link = env.dir.join("rx");
    let mut pty = Pty::open(Some(&link)).unwrap();
    let link_s = link.display().to_string();
    env.spawn(
        "gnss",
        &[
            "gnss",
            "--port",
            &link_s,
            "--baud",
            "115200",
            "--protocol",
            "ubx",
            "--id",
            "cam",
        ],
    );

    let base_tow_ms = 345_600_000u32; // Wednesday 00:00 GPS
    let tow = |k: u16| base_tow_ms + u32::from(k) * 100;
    // Writes mark `k` (again every second: the driver may not have the port open yet) until
    // its event is published.
    let next_mark = |pty: &mut Pty, env: &mut TestEnv, writes: &mut u64, k: u16| -> GnssEvent {
        let t0 = Instant::now();
        let mut written = None::<Instant>;
        loop {
            env.assert_running();
            assert!(
                t0.elapsed() < Duration::from_secs(20),
                "mark {k} not published:\n{}",
                env.log("gnss")
            );
            if written.is_none_or(|w| w.elapsed() > Duration::from_secs(1)) {
                pty.write(&tim_tm2(k, tow(k), 123_457)).unwrap();
                *writes += 1;
                written = Some(Instant::now());
            }
            std::thread::sleep(Duration::from_millis(20));
            let mut got = None;
            events.for_each(|e| got = got.or((e.count == k).then_some(*e))).unwrap();
            if let Some(e) = got {
                return e;
            }
        }
    };

    // 1. No time mapping yet: the mark goes out with its GNSS time only.
    let mut writes = 0u64;
    let first = next_mark(&mut pty, &mut env, &mut writes, 0);
    assert_eq!(first.rising_gps_ns, gps_ns(tow(0), 123_457));
    assert_eq!(first.falling_gps_ns, gps_ns(tow(0) + 2, 123_457));
    assert_eq!((first.rising_host_ns, first.falling_host_ns), (i64::MIN, i64::MIN));
    assert_eq!((first.channel, first.count, first.accuracy_ns), (0, 0, 25));

    // 2. The estimator's mapping appears (a host clock 3.5 ppm fast, 40 s since the reference).
    let mut ts = TimeState::unknown();
    ts.status = TimeStatus::Locked as u8;
    ts.ref_host_ns = monotonic_now_ns() - 40_000_000_000;
    ts.ref_utc_ns = utc_ns_from_gps_ns(gps_ns(base_tow_ms, 0)) - 35_000_000_000;
    ts.rate_error = -3.5e-6;
    ts.leap_s = 18;
    let mut publisher = node.publisher::<TimeState>(services::TIME_STATE).unwrap();
    publisher.publish(&ts).unwrap();
    let mut unmapped = 1u64;
    let mut k = 1u16;
    let (e, written_unmapped) = loop {
        let e = next_mark(&mut pty, &mut env, &mut writes, k);
        k += 1;
        if e.rising_host_ns != i64::MIN {
            // At most every write but the last went out unmapped.
            break (e, writes - 1);
        }
        unmapped += 1;
        assert!(k < 50, "marks never mapped to host time");
        publisher.publish(&ts).unwrap();
    };
    let utc_rising = utc_ns_from_gps_ns(e.rising_gps_ns);
    assert_eq!(
        e.rising_gps_ns - (utc_rising - 315_964_800_000_000_000),
        18_000_000_000,
        "GPS - UTC"
    );
    assert_eq!(e.rising_host_ns, ts.host_ns_at(utc_rising));
    assert_eq!(e.falling_host_ns, ts.host_ns_at(utc_ns_from_gps_ns(e.falling_gps_ns)));
    // The mapping at work: 2 ms of GNSS time between the edges are 2 ms + 7 ns on this host.
    assert_eq!(e.falling_host_ns - e.rising_host_ns, 2_000_007);
    // Mapped forward again, the host time gives the mark's UTC.
    assert!((ts.utc_ns_at(e.rising_host_ns) - utc_rising).abs() <= 1);

    // The unmapped marks were counted (each mark once, unless it had to be written again).
    let t0 = Instant::now();
    loop {
        let mut latest = None;
        health.for_each(|h| latest = Some(*h)).unwrap();
        if let Some(v) = latest.and_then(|h| h.counter("events_unmapped"))
            && v >= unmapped
        {
            assert!(
                v <= written_unmapped,
                "events_unmapped {v}, only {written_unmapped} marks written"
            );
            break;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(15),
            "no health report with events_unmapped = {unmapped}"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    drop((events, health, publisher, node));
    env.finish();
}
