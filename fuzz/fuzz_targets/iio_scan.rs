//! IIO scan elements: `in_<channel>_type` text → `ScanType`, channel names → `ChannelRole`, and the
//! enabled elements → the kernel's record layout (`iio_record::layout`). Input: the text
//! description of `navsync_fuzz::split_iio` (records, if any, are ignored).
//!
//! Checks: no panic; a parsed type is one the decoder can read (1 ≤ bits, bits + shift ≤
//! storage bits ∈ {8, 16, 32, 64}, repeat ≥ 1, floats 32/64 bits unshifted) and parses back
//! from its canonical form; roles match their names; in the layout every slot lies inside the
//! record, no two slots overlap, power-of-two slots are aligned to their size, and the record
//! is padded to a multiple of the largest power-of-two slot.
#![no_main]

use libfuzzer_sys::fuzz_target;
use navsync_drivers::imu::iio::record::layout;
use navsync_drivers::imu::iio::scan::{Endian, Repr, ChannelRole, ScanElement, ScanType};
use navsync_fuzz::split_iio;

fn canonical(t: &ScanType) -> String {
    let endian = match t.endian {
        Endian::Little => "le",
        Endian::Big => "be",
    };
    let repr = match t.repr {
        Repr::Signed => 's',
        Repr::Unsigned => 'u',
        Repr::Float => 'f',
    };
    format!("{endian}:{repr}{}/{}X{}>>{}", t.bits, t.storage_bits, t.repeat, t.shift)
}

fn check_type(text: &str) -> Option<ScanType> {
    let t = match text.parse::<ScanType>() {
        Ok(t) => t,
        Err(e) => {
            assert!(!e.to_string().is_empty());
            return None;
        }
    };
    assert!(matches!(t.storage_bits, 8 | 16 | 32 | 64), "{text:?}: {t:?}");
    assert!(
        t.bits >= 1 && u32::from(t.bits) + u32::from(t.shift) <= u32::from(t.storage_bits),
        "{text:?}: {t:?}"
    );
    assert!(t.repeat >= 1);
    if t.repr == Repr::Float {
        assert!(
            t.bits == t.storage_bits && matches!(t.bits, 32 | 64) && t.shift == 0,
            "{text:?}: {t:?}"
        );
    }
    assert_eq!(t.element_bytes() * 8, usize::from(t.storage_bits));
    assert_eq!(t.storage_bytes(), t.element_bytes() * usize::from(t.repeat));
    let c = canonical(&t);
    assert_eq!(c.parse::<ScanType>().as_ref(), Ok(&t), "{text:?} → {c}");
    Some(t)
}

fn check_role(name: &str) {
    let axes = ["x", "y", "z"];
    match ChannelRole::of(name) {
        Some(ChannelRole::Gyro(i)) => assert_eq!(name, format!("anglvel_{}", axes[i])),
        Some(ChannelRole::Accel(i)) => assert_eq!(name, format!("accel_{}", axes[i])),
        Some(ChannelRole::Timestamp) => assert_eq!(name, "timestamp"),
        Some(ChannelRole::Temp) => assert!(name.starts_with("temp")),
        None => {}
    }
    if let Some(r) = ChannelRole::of(name) {
        assert!(name.starts_with(r.type_name()));
    }
}

fuzz_target!(|data: &[u8]| {
    let (lines, _) = split_iio(data);
    let mut elements = Vec::new();
    for l in &lines {
        // Any text as a type attribute, then the line's own type field.
        check_type(l.text);
        check_role(l.name);
        let (Some(ty), Ok(index)) = (check_type(l.ty), l.index.parse::<u32>()) else {
            continue;
        };
        elements.push(ScanElement {
            name: l.name.to_string(),
            index,
            ty,
        });
    }
    let lay = layout(&elements);
    assert_eq!(lay.slots.len(), elements.len());
    let mut spans: Vec<(usize, usize)> = Vec::new();
    let mut largest_pow2 = 1;
    for (name, slot) in &lay.slots {
        let n = slot.ty.storage_bytes();
        assert!(
            slot.offset + n <= lay.record_bytes,
            "{name}: {slot:?} past {}",
            lay.record_bytes
        );
        if n.is_power_of_two() {
            assert_eq!(slot.offset % n, 0, "{name}: {slot:?} misaligned");
            largest_pow2 = largest_pow2.max(n);
        }
        spans.push((slot.offset, slot.offset + n));
        assert!(lay.slot(name).is_some());
    }
    spans.sort_unstable();
    for w in spans.windows(2) {
        assert!(w[0].1 <= w[1].0, "overlapping slots {w:?}");
    }
    let largest = lay.slots.iter().map(|(_, s)| s.ty.storage_bytes()).max().unwrap_or(0);
    if largest.is_power_of_two() {
        assert_eq!(
            lay.record_bytes % largest_pow2,
            0,
            "record of {} bytes",
            lay.record_bytes
        );
    }
});
