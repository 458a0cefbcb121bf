//! UBX front end: serial bytes → `UbxFramer` (UBX, NMEA and RTCM3 separated) → message
//! decoders → epoch assembly → `GnssFix` and the receiver's other products, as the live driver
//! (`--protocol ubx|auto`) and `navsync decode FILE` run it.
//!
//! Checks: no panic and no stall; framing and decoding do not depend on how the stream is cut
//! into reads (the same frames, counters and fixes, stamps included, for one read and for
//! odd-sized reads); every byte is counted; no frame is longer than the framer's limit;
//! every emitted fix is plausible (mode 0..=3, |lat| ≤ 90°, |lon| ≤ 180°, no infinite value,
//! sequence numbers counting up from 0); on each output (the GNSS epochs and the HNR-PVT
//! fixes, `navsync_fuzz::check_epoch_order`) every epoch is published once and times
//! strictly increase except across a counted reset of the receiver's time line.
#![no_main]

use libfuzzer_sys::fuzz_target;
use navsync_drivers::gnss::capture::decode_capture;
use navsync_drivers::gnss::ubx::framer::{Frame, MAX_UBX_PAYLOAD, UbxFramer};
use navsync_drivers::gnss::ubx::messages;
use navsync_drivers::gnss::{Decoder, GnssDecoder, GnssExtra, Protocol};
use navsync_fuzz::{check_epoch_order, check_fix_plausible, time_resets};
use navsync_shared::samples::GnssFix;

/// Nanoseconds per byte of the emulated line (115200 baud, 10 bits a byte).
const NS_PER_BYTE: i64 = 86_806;

/// Frames (as text, host stamps included) and counters of `data` cut into reads of `chunk`
/// bytes, each read stamped at the arrival of its last byte.
fn frame(data: &[u8], chunk: usize) -> (Vec<String>, String) {
    let mut framer = UbxFramer::new();
    let mut out = Vec::new();
    let mut offset = 0i64;
    for c in data.chunks(chunk.max(1)) {
        offset += c.len() as i64;
        framer.push(c, offset * NS_PER_BYTE, NS_PER_BYTE, &mut |f| {
            if let Frame::Ubx { class, id, payload, .. } = f {
                assert!(payload.len() <= MAX_UBX_PAYLOAD);
                // Every decoder on every frame: an error is fine, a panic is not.
                let _ = messages::decode(class, id, payload);
            }
            out.push(format!("{f:?}"));
        });
    }
    assert_eq!(framer.counters().bytes, data.len() as u64);
    (out, format!("{:?}", framer.counters()))
}

/// Fixes and other products (as text) of the whole decoder on `data` in reads of `chunk`.
fn decode(data: &[u8], chunk: usize, protocol: Protocol) -> (Vec<String>, usize) {
    let mut d = Decoder::new(protocol);
    let mut fixes: Vec<GnssFix> = Vec::new();
    let mut hnr: Vec<GnssFix> = Vec::new();
    let mut extras = 0usize;
    let mut offset = 0i64;
    for c in data.chunks(chunk.max(1)) {
        offset += c.len() as i64;
        d.push_extras(
            c,
            offset * NS_PER_BYTE,
            NS_PER_BYTE,
            &mut |f| fixes.push(*f),
            &mut |x| {
                extras += 1;
                match x {
                    GnssExtra::Imu(s) => {
                        assert!(s.gyro_rps.iter().chain(&s.accel_mps2).all(|v| !v.is_infinite()));
                    }
                    GnssExtra::Hnr(f) => hnr.push(*f),
                    _ => {}
                }
            },
        );
    }
    d.flush(&mut |f| fixes.push(*f));
    for (i, f) in fixes.iter().enumerate() {
        check_fix_plausible(f);
        assert_eq!(f.stamp.seq, i as u64, "sequence numbers count emissions");
    }
    for (i, f) in hnr.iter().enumerate() {
        check_fix_plausible(f);
        assert_eq!(f.stamp.seq, i as u64, "HNR sequence numbers of their own");
    }
    let resets = time_resets(&d);
    check_epoch_order(&fixes, resets);
    check_epoch_order(&hnr, resets);
    assert_eq!(d.bytes(), data.len() as u64);
    (fixes.iter().map(|f| format!("{f:?}")).collect(), extras)
}

fuzz_target!(|data: &[u8]| {
    let odd = 1 + data.len() % 13;
    assert_eq!(frame(data, data.len()), frame(data, odd), "framing in reads of {odd} bytes");
    for protocol in [Protocol::Ubx, Protocol::Auto] {
        assert_eq!(
            decode(data, data.len(), protocol),
            decode(data, odd, protocol),
            "{protocol:?} decoding in reads of {odd} bytes"
        );
    }
    // The offline decoder (gpsd header skipped, fixed-size reads, flushed at the end).
    for f in &decode_capture(data, Protocol::Ubx).fixes {
        check_fix_plausible(f);
    }
});
