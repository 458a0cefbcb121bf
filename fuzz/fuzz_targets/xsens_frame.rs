//! Xsens Xbus: serial bytes → `XbusFramer` → MTData2 messages → `decode_mtdata2`, as the Xsens
//! driver runs it, plus `decode_mtdata2` on the raw input.
//!
//! Checks: no panic; framing does not depend on how the stream is cut into reads; every
//! delivered message has the master bus id and a length within the protocol's limit; a decoded MTData2 survives `encode_mtdata2` (float64) → framer →
//! `decode_mtdata2` bit for bit; the rotation vector of a finite DeltaQ is finite.
#![no_main]

use libfuzzer_sys::fuzz_target;
use navsync_drivers::imu::xsens::rotation_vector;
use navsync_drivers::imu::xsens::frame::{
    BID_MASTER, MAX_DATA, MID_MTDATA2, MtData2, RealFormat, XbusFramer, decode_mtdata2, encode_mtdata2,
};

/// (bid, mid, data) of every message framed from `data` cut into reads of `chunk` bytes.
fn frame(data: &[u8], chunk: usize) -> Vec<(u8, u8, Vec<u8>)> {
    let mut framer = XbusFramer::new();
    let mut out = Vec::new();
    for c in data.chunks(chunk.max(1)) {
        framer.push(c, 0, 0, &mut |m| out.push((m.bid, m.mid, m.data.to_vec())));
    }
    assert_eq!(framer.counters().bytes, data.len() as u64);
    assert_eq!(framer.counters().messages, out.len() as u64);
    framer.reset();
    out
}

fn bits<const N: usize>(v: Option<[f64; N]>) -> Option<[u64; N]> {
    v.map(|a| a.map(f64::to_bits))
}

fn same(a: &MtData2, b: &MtData2) -> bool {
    a.sample_time_fine == b.sample_time_fine
        && a.packet_counter == b.packet_counter
        && a.status_word == b.status_word
        && bits(a.acceleration) == bits(b.acceleration)
        && bits(a.delta_v) == bits(b.delta_v)
        && bits(a.rate_of_turn) == bits(b.rate_of_turn)
        && bits(a.delta_q) == bits(b.delta_q)
        && a.temperature_c.map(f64::to_bits) == b.temperature_c.map(f64::to_bits)
}

fn check_mtdata2(data: &[u8]) {
    let Ok(m) = decode_mtdata2(data) else { return };
    let mut enc = Vec::new();
    encode_mtdata2(&m, RealFormat::Float64, &mut enc);
    let again = frame(&enc, enc.len());
    assert_eq!(again.len(), 1, "an encoded MTData2 frames as one message");
    assert_eq!((again[0].0, again[0].1), (BID_MASTER, MID_MTDATA2));
    let back = decode_mtdata2(&again[0].2).expect("an encoded MTData2 decodes");
    assert!(same(&m, &back), "{m:?} → {back:?}");
    if let Some(q) = m.delta_q
        && q.iter().all(|x| x.is_finite())
    {
        let v = rotation_vector(q);
        assert!(v.iter().all(|x| x.is_finite()), "rotation vector of {q:?}: {v:?}");
    }
}

fuzz_target!(|data: &[u8]| {
    let whole = frame(data, data.len());
    let odd = 1 + data.len() % 11;
    assert_eq!(whole, frame(data, odd), "reads of {odd} bytes");
    for (bid, mid, payload) in &whole {
        assert_eq!(*bid, BID_MASTER);
        assert!(payload.len() <= MAX_DATA);
        if *mid == MID_MTDATA2 {
            check_mtdata2(payload);
        }
    }
    check_mtdata2(data);
});
