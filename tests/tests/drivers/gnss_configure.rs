//! `navsync gnss --protocol ubx --configure` on a pseudo-terminal whose other end this test
//! plays as a u-blox M8 receiver (no real receiver here): the driver polls MON-VER, sends one
//! CFG-MSG per output message and a CFG-TP5, each after the previous one's ACK (the
//! "receiver" NAKs RXM-RAWX, as a plain M8N does: optional, reported, not a failure), then reads
//! the receiver's NAV-PVT epochs as fixes. A port that answers no UBX (an NMEA-only receiver)
//! makes `--configure` a clear error and the driver exits.

use std::time::{Duration, Instant};

use navsync_drivers::gnss::ubx::framer::{Frame, UbxFramer, ubx_frame};
use navsync_drivers::pty::Pty;
use navsync_shared::samples::{GNSS_PROTOCOL_UBX, GnssFix, Health};
use navsync_shared::services;
use navsync_sim::nmea::{EpochReport, FixReport};
use navsync_sim::ubx::{UbxExtras, write_epoch};
use navsync_tests::TestEnv;

/// UBX-MON-VER of an M8 (protocol 18).
fn mon_ver() -> Vec<u8> {
    let mut p = vec![0u8; 40 + 30];
    for (at, text) in [
        (0, &b"ROM CORE 3.01 (107888)"[..]),
        (30, b"00080000"),
        (40, b"PROTVER=18.00"),
    ] {
        p[at..at + text.len()].copy_from_slice(text);
    }
    ubx_frame(0x0A, 0x04, &p)
}

fn epoch(k: i64) -> Vec<u8> {
    let e = EpochReport {
        utc_ns: 1_790_000_000_000_000_000 + k * 1_000_000_000,
        fix: Some(FixReport {
            lat_deg: 48.1,
            lon_deg: 11.5,
            alt_msl_m: 520.0,
            geoid_sep_m: 47.0,
            vel_n_mps: 1.0,
            vel_e_mps: 0.0,
            vel_d_mps: 0.0,
        }),
        sats_used: 12,
        hdop: 0.8,
        vdop: 1.2,
        sigma_lat_lon_alt_m: [0.5, 0.5, 1.0],
    };
    let x = UbxExtras {
        h_acc_m: 0.7,
        v_acc_m: 1.0,
        s_acc_mps: 0.07,
        next_pulse_q_err_ps: 0,
    };
    let mut out = Vec::new();
    write_epoch(&e, &x, &mut out);
    out
}

#[test]
fn configure_sets_up_an_m8_and_the_fixes_follow() {
    let mut env = TestEnv::new("gnsscfg");
    let node = env.node("observer");
    let fixes = node.subscriber::<GnssFix>(&services::gnss_fix("0")).unwrap();
    let health = node.subscriber::<Health>(&services::health("gnss-0")).unwrap();
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
            "--configure",
            "--id",
            "0",
        ],
    );
    // The receiver: answer the poll and every configuration command.
    let mut framer = UbxFramer::new();
    let mut commands: Vec<(u8, u8, Vec<u8>)> = Vec::new();
    let mut buf = [0u8; 1024];
    let t0 = Instant::now();
    while commands.len() < 9 {
        assert!(
            t0.elapsed() < Duration::from_secs(30),
            "only {} commands: {commands:?}\n{}",
            commands.len(),
            env.log("gnss")
        );
        let n = pty.read(&mut buf).unwrap();
        if n == 0 {
            std::thread::sleep(Duration::from_millis(5));
            continue;
        }
        let mut replies = Vec::new();
        framer.push(&buf[..n], 0, 0, &mut |f| {
            if let Frame::Ubx { class, id, payload, .. } = f {
                match (class, id) {
                    (0x0A, 0x04) if payload.is_empty() => replies.extend(mon_ver()),
                    (0x06, _) => {
                        commands.push((class, id, payload.to_vec()));
                        // A plain M8N has no raw measurements: NAK enabling RXM-RAWX.
                        let nak = payload == [0x02, 0x15, 1];
                        replies.extend(ubx_frame(0x05, u8::from(!nak), &[class, id]));
                    }
                    _ => {}
                }
            }
        });
        pty.write(&replies).unwrap();
    }
    let msgs: Vec<[u8; 2]> = commands
        .iter()
        .filter(|(_, id, _)| *id == 0x01)
        .map(|(_, _, p)| [p[0], p[1]])
        .collect();
    assert_eq!(
        msgs,
        [
            [1, 7],
            [1, 0x61],
            [1, 0x35],
            [0x0D, 1],
            [0x0D, 3],
            [2, 0x15],
            [2, 0x13],
            [0x10, 2]
        ],
        "CFG-MSG for NAV-PVT, NAV-EOE, NAV-SAT, TIM-TP, TIM-TM2, RXM-RAWX, RXM-SFRBX, ESF-MEAS"
    );
    assert!(commands.iter().all(|(_, _, p)| p.len() == 3 || p.len() == 32));
    assert_eq!(commands.last().map(|c| c.1), Some(0x31), "CFG-TP5 last");

    // Then the receiver navigates.
    let mut got = Vec::new();
    for k in 0..40 {
        pty.write(&epoch(k)).unwrap();
        std::thread::sleep(Duration::from_millis(50));
        fixes.for_each(|f| got.push(*f)).unwrap();
        if got.len() >= 5 {
            break;
        }
    }
    assert!(got.len() >= 5, "{} fixes\n{}", got.len(), env.log("gnss"));
    assert!(got.iter().all(|f| f.protocol == GNSS_PROTOCOL_UBX && f.h_acc_m == 0.7));
    let mut acked = None;
    let t1 = Instant::now();
    while acked.is_none() && t1.elapsed() < Duration::from_secs(10) {
        health
            .for_each(|h| acked = Some((h.counter("configure_acked"), h.counter("configure_failed"))))
            .unwrap();
        std::thread::sleep(Duration::from_millis(50));
    }
    assert_eq!(acked, Some((Some(8), Some(0))), "8 of 9 acknowledged, the NAK optional");
    drop((fixes, health, node));
    env.finish();
}

#[test]
fn configure_refuses_an_nmea_only_receiver() {
    let mut env = TestEnv::new("gnsscfgnmea");
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
            "auto",
            "--configure",
            "--id",
            "0",
        ],
    );
    let t0 = Instant::now();
    while env.is_running("gnss") {
        assert!(
            t0.elapsed() < Duration::from_secs(20),
            "still running:\n{}",
            env.log("gnss")
        );
        // NMEA only: the receiver ignores the UBX poll.
        let _ = pty.write(b"$GPGGA,120000,4807.0381,N,01131.0004,E,1,08,0.9,545.4,M,46.9,M,,*47\r\n");
        std::thread::sleep(Duration::from_millis(200));
    }
    let log = env.log("gnss");
    assert!(
        log.contains("--configure") && log.contains("NMEA-only receiver cannot"),
        "{log}"
    );
}
