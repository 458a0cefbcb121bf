//! IIO records: a device description (`navsync_fuzz::split_iio`: scan elements with scale and
//! offset) → `RecordDecoder`, then every record of the input's binary part → `ImuRecord`, as
//! the IIO driver decodes `/dev/iio:deviceN` reads (the last, short record included).
//!
//! Checks: no panic; `read_raw` of every integer element agrees with a reference decoder
//! (byte order, shift, mask, sign extension); decoded rates and accelerations are finite for
//! integer channels with a finite, moderate scale and offset; a full record of a device with
//! an integer timestamp channel has a timestamp.
#![no_main]

use libfuzzer_sys::fuzz_target;
use navsync_drivers::imu::iio::record::{Conversion, Raw, RecordDecoder, Slot, layout, read_raw};
use navsync_drivers::imu::iio::scan::{Endian, Repr, ScanElement, ScanType};
use navsync_fuzz::split_iio;

/// Integer element `element` of `slot` in `record`, decoded independently of `read_raw`.
fn reference(record: &[u8], slot: &Slot, element: usize) -> Option<i64> {
    let n = slot.ty.element_bytes();
    let b = record.get(slot.offset + element * n..slot.offset + (element + 1) * n)?;
    let mut word: u128 = 0;
    for i in 0..n {
        let byte = match slot.ty.endian {
            Endian::Big => b[i],
            Endian::Little => b[n - 1 - i],
        };
        word = (word << 8) | u128::from(byte);
    }
    let bits = u32::from(slot.ty.bits);
    let v = (word >> slot.ty.shift) & ((1u128 << bits) - 1);
    Some(match slot.ty.repr {
        Repr::Signed if v >> (bits - 1) & 1 == 1 => (v as i128 - (1i128 << bits)) as i64,
        _ => v as i64,
    })
}

fn num(s: Option<&str>, default: f64) -> f64 {
    s.and_then(|s| s.parse().ok()).unwrap_or(default)
}

fn moderate(c: &Conversion) -> bool {
    c.scale.is_finite() && c.offset.is_finite() && c.scale.abs() < 1e100 && c.offset.abs() < 1e100
}

fuzz_target!(|data: &[u8]| {
    let (lines, records) = split_iio(data);
    let mut elements = Vec::new();
    let mut conversions = Vec::new();
    for l in &lines {
        let (Ok(ty), Ok(index)) = (l.ty.parse::<ScanType>(), l.index.parse::<u32>()) else {
            continue;
        };
        elements.push(ScanElement {
            name: l.name.to_string(),
            index,
            ty,
        });
        let c = Conversion {
            scale: num(l.scale, 1.0),
            offset: num(l.offset, 0.0),
        };
        conversions.push((l.name.to_string(), c));
    }
    let lay = layout(&elements);
    let conv_of = |name: &str| {
        conversions.iter().find(|(n, _)| n == name).map_or(
            Conversion {
                scale: 1.0,
                offset: 0.0,
            },
            |(_, c)| *c,
        )
    };

    // Every element of every slot, against the reference.
    if lay.record_bytes > 0 {
        for record in records.chunks(lay.record_bytes).take(64) {
            for (_, slot) in &lay.slots {
                for e in 0..usize::from(slot.ty.repeat) {
                    let raw = read_raw(record, slot, e);
                    match (raw, slot.ty.repr, reference(record, slot, e)) {
                        (Raw::Int(v), Repr::Signed | Repr::Unsigned, Some(r)) => assert_eq!(v, r, "{slot:?}"),
                        (Raw::Float(_), Repr::Float, Some(_)) => {}
                        (Raw::Float(v), _, None) => assert!(v.is_nan(), "short record"),
                        other => panic!("{slot:?} element {e}: {other:?}"),
                    }
                }
            }
        }
    }

    let Ok(decoder) = RecordDecoder::new(&lay, |name, _| conv_of(name)) else {
        return;
    };
    assert_eq!(decoder.record_bytes(), lay.record_bytes);
    assert!(
        decoder.record_bytes() > 0,
        "a device with a triad has a non-empty record"
    );
    assert!(decoder.has_gyro() || decoder.has_accel());
    let finite_triad = |kind: &str| {
        ["x", "y", "z"].iter().all(|a| {
            let name = format!("{kind}_{a}");
            lay.slot(&name).is_some_and(|s| s.ty.repr != Repr::Float) && moderate(&conv_of(&name))
        })
    };
    let gyro_finite = finite_triad("anglvel");
    let accel_finite = finite_triad("accel");
    let int_timestamp = lay.slot("timestamp").is_some_and(|s| s.ty.repr != Repr::Float);
    for record in records.chunks(decoder.record_bytes()).take(256) {
        let r = decoder.decode(record);
        assert_eq!(r.gyro_rps.is_some(), decoder.has_gyro());
        assert_eq!(r.accel_mps2.is_some(), decoder.has_accel());
        if record.len() == decoder.record_bytes() {
            if gyro_finite {
                assert!(r.gyro_rps.is_some_and(|g| g.iter().all(|x| x.is_finite())), "{r:?}");
            }
            if accel_finite {
                assert!(r.accel_mps2.is_some_and(|a| a.iter().all(|x| x.is_finite())), "{r:?}");
            }
            assert_eq!(r.timestamp_ns.is_some(), int_timestamp, "{r:?}");
        }
    }
});
