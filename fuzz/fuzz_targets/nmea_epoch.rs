//! NMEA front end: serial bytes → `LineFramer` → `EpochAssembler` → `GnssFix`, as the live
//! driver and `navsync decode FILE` run it (`capture::decode_capture`), plus the framer fed in
//! odd-sized reads and the assembler fed raw lines (any bytes) that did not go through the
//! framer.
//!
//! Checks: no panic; framing does not depend on how the stream is cut into reads; every
//! emitted fix is plausible (mode 0..=3, |lat| ≤ 90°, |lon| ≤ 180°, no infinite value, time
//! of day within a day plus a leap second, UTC consistent with the time of day, sequence
//! numbers counting up from 0; every epoch published once, times strictly increasing except
//! across a counted reset of the receiver's time line: `navsync_fuzz::check_epoch_order`).
#![no_main]

use libfuzzer_sys::fuzz_target;
use navsync_drivers::gnss::Protocol;
use navsync_drivers::gnss::capture::decode_capture;
use navsync_drivers::gnss::nmea::epoch::EpochAssembler;
use navsync_drivers::gnss::nmea::framer::{LineFramer, MAX_SENTENCE_LEN};
use navsync_fuzz::{check_epoch_order, check_fix_plausible, time_resets};
use navsync_shared::samples::GnssFix;

const NS_PER_DAY: i64 = 86_400_000_000_000;

fn check_fix(f: &GnssFix) {
    check_fix_plausible(f);
    for (name, dop) in [("hdop", f.hdop), ("vdop", f.vdop), ("pdop", f.pdop)] {
        assert!(dop.is_nan() || (0.0..99.0).contains(&dop), "{name} {dop}");
    }
    // hhmmss.sss with ss ≤ 60 (leap second).
    assert!(
        f.tod_ns == -1 || (0..NS_PER_DAY + 1_000_000_000).contains(&f.tod_ns),
        "tod {}",
        f.tod_ns
    );
    if f.utc_ns != i64::MIN {
        assert!(f.tod_ns >= 0, "a date without a time of day");
        assert_eq!(
            (f.utc_ns - f.tod_ns).rem_euclid(NS_PER_DAY),
            0,
            "utc {} tod {}",
            f.utc_ns,
            f.tod_ns
        );
        assert_ne!(f.gps_ns, i64::MIN, "UTC known but GPS time not");
    }
}

fn check_fixes(fixes: &[GnssFix]) {
    for (i, f) in fixes.iter().enumerate() {
        check_fix(f);
        assert_eq!(f.stamp.seq, i as u64, "sequence numbers count emissions");
    }
}

/// Sentences (text only) framed from `data` cut into reads of `chunk` bytes.
fn frame(data: &[u8], chunk: usize) -> Vec<Vec<u8>> {
    let mut framer = LineFramer::new();
    let mut out = Vec::new();
    for c in data.chunks(chunk.max(1)) {
        framer.push(c, 0, 0, &mut |s| {
            assert!(s.text.len() <= MAX_SENTENCE_LEN);
            assert!(matches!(s.text.first(), Some(b'$' | b'!')));
            assert!(s.text.iter().all(|b| (0x20..=0x7e).contains(b)));
            out.push(s.text.to_vec());
        });
    }
    assert_eq!(framer.counters().bytes, data.len() as u64);
    assert_eq!(framer.counters().sentences, out.len() as u64);
    out
}

fuzz_target!(|data: &[u8]| {
    // The offline decoder: comments, delay cookies, one read per line, flush at the end.
    let decoded = decode_capture(data, Protocol::Nmea);
    let (fixes, counters) = (decoded.fixes.clone(), decoded.nmea().expect("NMEA").counters());
    check_fixes(&fixes);
    check_epoch_order(&fixes, time_resets(&decoded.decoder));
    assert_eq!(counters.epochs.epochs, fixes.len() as u64);

    // Framing is independent of read boundaries.
    let odd = 1 + data.len() % 13;
    assert_eq!(frame(data, data.len()), frame(data, odd), "reads of {odd} bytes");

    // The assembler on raw lines (any bytes: it must check them itself).
    let mut assembler = EpochAssembler::new();
    let mut fixes = Vec::new();
    for (i, line) in data.split(|&b| b == b'\n').enumerate() {
        assembler.push(line, i as i64, &mut |f| fixes.push(*f));
    }
    assembler.flush(&mut |f| fixes.push(*f));
    check_fixes(&fixes);
    check_epoch_order(&fixes, assembler.counters().time_resets);
});
