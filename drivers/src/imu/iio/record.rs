//! Records of an IIO buffer (`/dev/iio:deviceN`): where each enabled channel sits in a
//! record, and how a record becomes an IMU sample in SI units. Pure functions on bytes.
//!
//! Layout (kernel `drivers/iio/industrialio-buffer.c`, `iio_compute_scan_bytes`): the enabled
//! channels follow each other in ascending scan index, each aligned to its own storage size
//! (all repeats), and the record is padded to a multiple of the largest storage size, so
//! that the next record's channels are aligned too. The timestamp is an ordinary (last)
//! channel, `le:s64/64>>0`, so it sits at an 8-byte boundary.
//!
//! Values: `(raw + offset) × scale` with the device's `in_<channel>_scale`/`_offset` (or the
//! shared `in_<type>_scale`), giving rad/s for `anglvel`, m/s² for `accel` and milli-°C
//! for `temp` (kernel `sysfs-bus-iio`); the timestamp is ns of the clock chosen in
//! `current_timestamp_clock`.

use super::scan::{ChannelRole, Endian, Repr, ScanElement, ScanType};

/// Where one channel is in a record.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Slot {
    /// Byte offset of the channel's first value in the record.
    pub offset: usize,
    /// Its storage description.
    pub ty: ScanType,
}

/// The layout of one record.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RecordLayout {
    /// Bytes per record (including the final padding).
    pub record_bytes: usize,
    /// The enabled channels in record order, by name.
    pub slots: Vec<(String, Slot)>,
}

impl RecordLayout {
    /// The slot of a channel by name.
    pub fn slot(&self, name: &str) -> Option<Slot> {
        self.slots.iter().find(|(n, _)| n == name).map(|(_, s)| *s)
    }
}

/// `ALIGN(x, a)` exactly as the kernel computes it (`(x + a − 1) & ~(a − 1)`; the storage
/// sizes are powers of two except for odd repeat counts, where the kernel's result is kept).
fn kernel_align(x: usize, a: usize) -> usize {
    if a == 0 {
        return x;
    }
    (x + a - 1) & !(a - 1)
}

/// The record layout of the enabled `elements` (any order; they are sorted by index).
pub fn layout(elements: &[ScanElement]) -> RecordLayout {
    let mut sorted: Vec<&ScanElement> = elements.iter().collect();
    sorted.sort_by_key(|e| e.index);
    let mut bytes = 0;
    let mut largest = 0;
    let mut slots = Vec::with_capacity(sorted.len());
    for e in sorted {
        let length = e.ty.storage_bytes();
        bytes = kernel_align(bytes, length);
        slots.push((
            e.name.clone(),
            Slot {
                offset: bytes,
                ty: e.ty,
            },
        ));
        bytes += length;
        largest = largest.max(length);
    }
    RecordLayout {
        record_bytes: kernel_align(bytes, largest),
        slots,
    }
}

/// A raw channel value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Raw {
    /// An integer after shift, mask and sign extension.
    Int(i64),
    /// A float channel.
    Float(f64),
}

impl Raw {
    /// As a float.
    pub fn as_f64(self) -> f64 {
        match self {
            Raw::Int(v) => v as f64,
            Raw::Float(v) => v,
        }
    }
}

/// Value `element` (0 for channels without repeat) of `slot` in `record`. The record must be
/// at least as long as its layout says (the caller reads whole records).
pub fn read_raw(record: &[u8], slot: &Slot, element: usize) -> Raw {
    let n = slot.ty.element_bytes();
    let start = slot.offset + element * n;
    let Some(b) = record.get(start..start + n) else {
        return Raw::Float(f64::NAN);
    };
    let mut word: u64 = 0;
    match slot.ty.endian {
        Endian::Big => b.iter().for_each(|&x| word = word << 8 | u64::from(x)),
        Endian::Little => b.iter().rev().for_each(|&x| word = word << 8 | u64::from(x)),
    }
    if slot.ty.repr == Repr::Float {
        return Raw::Float(match n {
            4 => f64::from(f32::from_bits(word as u32)),
            _ => f64::from_bits(word),
        });
    }
    let bits = u32::from(slot.ty.bits);
    let v = word >> slot.ty.shift;
    let v = if bits >= 64 { v } else { v & ((1u64 << bits) - 1) };
    match slot.ty.repr {
        Repr::Signed if bits < 64 => {
            // Sign-extend from `bits`.
            let s = 64 - bits;
            Raw::Int(((v << s) as i64) >> s)
        }
        _ => Raw::Int(v as i64),
    }
}

/// True when an integer raw value is the smallest or largest its bits can hold: a sensor
/// whose output sits there has reached (at least) its range.
pub fn at_full_scale(raw: Raw, ty: &ScanType) -> bool {
    let Raw::Int(v) = raw else { return false };
    let bits = u32::from(ty.bits);
    if bits >= 63 {
        return false;
    }
    match ty.repr {
        Repr::Signed => v == (1i64 << (bits - 1)) - 1 || v == -(1i64 << (bits - 1)),
        Repr::Unsigned => v == 0 || v == (1i64 << bits) - 1,
        Repr::Float => false,
    }
}

/// `physical = (raw + offset) × scale`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Conversion {
    /// Scale, SI units per LSB (°C per LSB for temperature).
    pub scale: f64,
    /// Offset, LSB.
    pub offset: f64,
}

impl Conversion {
    /// Applies the conversion.
    pub fn apply(&self, raw: Raw) -> f64 {
        (raw.as_f64() + self.offset) * self.scale
    }
}

/// A record converted to physical values, in the device's axes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IioSample {
    /// Angular rate, rad/s (`None` when the device has no gyroscope channels).
    pub gyro_rps: Option<[f64; 3]>,
    /// Acceleration, m/s² (`None` when the device has no accelerometer channels).
    pub accel_mps2: Option<[f64; 3]>,
    /// Temperature, °C (NaN without a temperature channel).
    pub temperature_c: f64,
    /// The kernel time stamp, ns (`None` without a timestamp channel).
    pub timestamp_ns: Option<i64>,
    /// A gyro or accel axis sits at the end of its integer range.
    pub at_full_scale: bool,
}

/// A channel the driver needs is not enabled in the layout.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("channel `in_{0}` is not in the scan (an IMU device needs anglvel_x/y/z and/or accel_x/y/z)")]
pub struct MissingChannel(pub String);

type Triad = [(Slot, Conversion); 3];

/// Decodes records of one layout.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordDecoder {
    record_bytes: usize,
    gyro: Option<Triad>,
    accel: Option<Triad>,
    temp: Option<(Slot, Conversion)>,
    timestamp: Option<Slot>,
}

impl RecordDecoder {
    /// A decoder for `layout`; `conversion(name, role)` gives each channel's scale and offset
    /// (temperature already in °C per LSB). A triad (gyroscope or accelerometer) is used when
    /// any of its axes is in the scan, and then all three must be; at least one triad must be.
    pub fn new(
        layout: &RecordLayout,
        mut conversion: impl FnMut(&str, ChannelRole) -> Conversion,
    ) -> Result<Self, MissingChannel> {
        let mut triad = |kind: &str, role: fn(usize) -> ChannelRole| -> Result<Option<Triad>, MissingChannel> {
            let names = ["x", "y", "z"].map(|a| format!("{kind}_{a}"));
            if names.iter().all(|n| layout.slot(n).is_none()) {
                return Ok(None);
            }
            let mut out = Vec::with_capacity(3);
            for (i, n) in names.iter().enumerate() {
                let slot = layout.slot(n).ok_or_else(|| MissingChannel(n.clone()))?;
                out.push((slot, conversion(n, role(i))));
            }
            Ok(Some([out[0], out[1], out[2]]))
        };
        let gyro = triad("anglvel", ChannelRole::Gyro)?;
        let accel = triad("accel", ChannelRole::Accel)?;
        if gyro.is_none() && accel.is_none() {
            return Err(MissingChannel("anglvel_x".into()));
        }
        let temp = layout
            .slots
            .iter()
            .find(|(n, _)| ChannelRole::of(n) == Some(ChannelRole::Temp))
            .map(|(n, s)| (*s, conversion(n, ChannelRole::Temp)));
        Ok(Self {
            record_bytes: layout.record_bytes,
            gyro,
            accel,
            temp,
            timestamp: layout.slot("timestamp"),
        })
    }

    /// Bytes per record.
    pub fn record_bytes(&self) -> usize {
        self.record_bytes
    }

    /// True when the records carry the kernel time stamp.
    pub fn has_timestamp(&self) -> bool {
        self.timestamp.is_some()
    }

    /// True when the records carry angular rate.
    pub fn has_gyro(&self) -> bool {
        self.gyro.is_some()
    }

    /// True when the records carry acceleration.
    pub fn has_accel(&self) -> bool {
        self.accel.is_some()
    }

    /// Converts one record (exactly [`record_bytes`](Self::record_bytes) long).
    pub fn decode(&self, record: &[u8]) -> IioSample {
        let mut full = false;
        let mut triad = |t: &Triad| {
            t.map(|(slot, conv)| {
                let raw = read_raw(record, &slot, 0);
                full |= at_full_scale(raw, &slot.ty);
                conv.apply(raw)
            })
        };
        let gyro_rps = self.gyro.as_ref().map(&mut triad);
        let accel_mps2 = self.accel.as_ref().map(&mut triad);
        let temperature_c = self
            .temp
            .as_ref()
            .map_or(f64::NAN, |(slot, conv)| conv.apply(read_raw(record, slot, 0)));
        let timestamp_ns = self
            .timestamp
            .as_ref()
            .and_then(|slot| match read_raw(record, slot, 0) {
                Raw::Int(v) => Some(v),
                Raw::Float(_) => None,
            });
        IioSample {
            gyro_rps,
            accel_mps2,
            temperature_c,
            timestamp_ns,
            at_full_scale: full,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn el(name: &str, index: u32, ty: &str) -> ScanElement {
        ScanElement {
            name: name.into(),
            index,
            ty: ty.parse().unwrap(),
        }
    }

    #[test]
    fn alignment_follows_the_kernel() {
        // u8, s32 (aligned to 4), s16, s64 timestamp (aligned to 8), padded to 8.
        let l = layout(&[
            el("timestamp", 9, "le:s64/64>>0"),
            el("a", 0, "le:u8/8>>0"),
            el("b", 1, "be:s32/32>>0"),
            el("c", 2, "le:s16/16>>0"),
        ]);
        let offs: Vec<(&str, usize)> = l.slots.iter().map(|(n, s)| (n.as_str(), s.offset)).collect();
        assert_eq!(offs, vec![("a", 0), ("b", 4), ("c", 8), ("timestamp", 16)]);
        assert_eq!(l.record_bytes, 24);
        // Six 16-bit channels and no timestamp: 12 bytes, padded to 2 → 12.
        let six: Vec<_> = (0..6).map(|i| el(&format!("c{i}"), i, "le:s16/16>>0")).collect();
        assert_eq!(layout(&six).record_bytes, 12);
        // The record is padded to its largest element: s32 then s16 → 8, not 6.
        let l = layout(&[el("a", 0, "le:s32/32>>0"), el("b", 1, "le:s16/16>>0")]);
        assert_eq!(l.record_bytes, 8);
        // A repeated channel counts with all its repeats (6 bytes), as the kernel does.
        let l = layout(&[el("a", 0, "le:u8/8>>0"), el("q", 1, "le:s16/16X3>>0")]);
        assert_eq!(l.slots[1].1.offset, kernel_align(1, 6));
    }

    #[test]
    fn raw_values_shift_mask_sign() {
        let ty: ScanType = "le:s12/16>>4".parse().unwrap();
        let slot = Slot { offset: 1, ty };
        // −5 in 12 bits is 0xFFB; shifted left 4 with junk in the low nibble: 0xFFB7.
        let rec = [0xAA, 0xB7, 0xFF];
        assert_eq!(read_raw(&rec, &slot, 0), Raw::Int(-5));
        let ty: ScanType = "be:u10/16>>0".parse().unwrap();
        assert_eq!(read_raw(&[0xFC, 0x05], &Slot { offset: 0, ty }, 0), Raw::Int(5));
        let ty: ScanType = "be:s32/32>>0".parse().unwrap();
        assert_eq!(
            read_raw(&[0xFF, 0xFF, 0xFF, 0xFE], &Slot { offset: 0, ty }, 0),
            Raw::Int(-2)
        );
        let ty: ScanType = "le:s64/64>>0".parse().unwrap();
        let t = 1_234_567_890_123_456_789i64;
        assert_eq!(read_raw(&t.to_le_bytes(), &Slot { offset: 0, ty }, 0), Raw::Int(t));
        let ty: ScanType = "le:f32/32>>0".parse().unwrap();
        assert_eq!(
            read_raw(&1.5f32.to_le_bytes(), &Slot { offset: 0, ty }, 0),
            Raw::Float(1.5)
        );
        let ty: ScanType = "le:s16/16X3>>0".parse().unwrap();
        let rec = [1, 0, 2, 0, 0xFD, 0xFF];
        assert_eq!(read_raw(&rec, &Slot { offset: 0, ty }, 2), Raw::Int(-3));
        // Short records give NaN instead of panicking.
        assert!(read_raw(&rec, &Slot { offset: 5, ty }, 0).as_f64().is_nan());
    }

    #[test]
    fn full_scale() {
        let ty: ScanType = "le:s16/16>>0".parse().unwrap();
        assert!(at_full_scale(Raw::Int(32_767), &ty));
        assert!(at_full_scale(Raw::Int(-32_768), &ty));
        assert!(!at_full_scale(Raw::Int(-32_767), &ty));
    }

    #[test]
    fn decodes_an_imu_record() {
        let l = layout(&[
            el("temp0", 0, "le:s16/16>>0"),
            el("anglvel_x", 1, "be:s32/32>>0"),
            el("anglvel_y", 2, "be:s32/32>>0"),
            el("anglvel_z", 3, "be:s32/32>>0"),
            el("accel_x", 4, "le:s16/16>>0"),
            el("accel_y", 5, "le:s16/16>>0"),
            el("accel_z", 6, "le:s16/16>>0"),
            el("timestamp", 7, "le:s64/64>>0"),
        ]);
        assert_eq!(l.record_bytes, 32);
        let d = RecordDecoder::new(&l, |_, role| match role {
            ChannelRole::Gyro(_) => Conversion {
                scale: 1e-6,
                offset: 0.0,
            },
            ChannelRole::Accel(_) => Conversion {
                scale: 0.01,
                offset: 0.0,
            },
            _ => Conversion {
                scale: 0.5,
                offset: 10.0,
            },
        })
        .unwrap();
        let mut rec = [0u8; 32];
        rec[0..2].copy_from_slice(&40i16.to_le_bytes());
        rec[4..8].copy_from_slice(&1_000_000i32.to_be_bytes());
        rec[8..12].copy_from_slice(&(-2_000_000i32).to_be_bytes());
        rec[12..16].copy_from_slice(&i32::MAX.to_be_bytes());
        rec[16..18].copy_from_slice(&100i16.to_le_bytes());
        rec[18..20].copy_from_slice(&(-50i16).to_le_bytes());
        rec[20..22].copy_from_slice(&(-981i16).to_le_bytes());
        rec[24..32].copy_from_slice(&77_000i64.to_le_bytes());
        let r = d.decode(&rec);
        assert_eq!(r.gyro_rps.unwrap()[..2], [1.0, -2.0]);
        assert_eq!(r.accel_mps2, Some([1.0, -0.5, -9.81]));
        assert_eq!(r.temperature_c, 25.0);
        assert_eq!(r.timestamp_ns, Some(77_000));
        assert!(r.at_full_scale, "gyro z at i32::MAX");
    }

    #[test]
    fn a_missing_axis_is_named_and_one_triad_is_enough() {
        let unit = |_: &str, _| Conversion {
            scale: 1.0,
            offset: 0.0,
        };
        let l = layout(&[el("anglvel_x", 0, "le:s16/16>>0")]);
        let e = RecordDecoder::new(&l, unit).unwrap_err();
        assert_eq!(e, MissingChannel("anglvel_y".into()));
        assert!(e.to_string().contains("in_anglvel_y"));
        let e = RecordDecoder::new(&layout(&[el("temp", 0, "le:s16/16>>0")]), unit).unwrap_err();
        assert!(e.to_string().contains("and/or accel"), "{e}");
        // An accelerometer-only device (one half of a split IMU).
        let l = layout(&[
            el("accel_x", 0, "le:s16/16>>0"),
            el("accel_y", 1, "le:s16/16>>0"),
            el("accel_z", 2, "le:s16/16>>0"),
        ]);
        let d = RecordDecoder::new(&l, unit).unwrap();
        assert!(d.has_accel() && !d.has_gyro() && !d.has_timestamp());
        let r = d.decode(&[1, 0, 2, 0, 3, 0]);
        assert_eq!((r.gyro_rps, r.accel_mps2), (None, Some([1.0, 2.0, 3.0])));
    }
}
