//! Scan elements of a Linux IIO buffered device: the channel descriptions in sysfs
//! `scan_elements/` (`in_<channel>_en`, `in_<channel>_index`, `in_<channel>_type`) parsed
//! into plain values.
//!
//! The `_type` attribute (kernel `Documentation/ABI/testing/sysfs-bus-iio`,
//! `Documentation/iio/iio_devbuf.rst`) reads `[be|le]:[f|s|u]bits/storagebits[Xrepeat][>>shift]`:
//! byte order, float/signed/unsigned, the number of meaningful bits, the bits the value
//! occupies in the record (which is also its alignment), how many such values follow each
//! other (repeat, usually absent = 1), and the right shift to apply before masking to `bits`.
//! Examples: `le:s16/16>>0`, `be:s32/32>>0`, `le:s12/16>>4`, `le:s64/64>>0` (the timestamp).

use std::str::FromStr;

/// Byte order of a stored value.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Endian {
    /// `le`
    Little,
    /// `be`
    Big,
}

/// Representation of a stored value.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Repr {
    /// `s`: two's complement.
    Signed,
    /// `u`: unsigned.
    Unsigned,
    /// `f`: IEEE-754 binary (32 or 64 bits).
    Float,
}

/// A parsed `in_<channel>_type`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ScanType {
    /// Byte order.
    pub endian: Endian,
    /// Signedness / float.
    pub repr: Repr,
    /// Meaningful bits.
    pub bits: u8,
    /// Bits occupied in the record (8, 16, 32 or 64).
    pub storage_bits: u8,
    /// Values stored one after the other (≥ 1).
    pub repeat: u8,
    /// Right shift before masking.
    pub shift: u8,
}

/// A `_type` string that is not of the documented form.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "scan element type `{text}`: {reason} (expected `[be|le]:[f|s|u]bits/storagebits[Xrepeat][>>shift]`, e.g. `le:s16/16>>0`)"
)]
pub struct ScanTypeError {
    /// The text as read.
    pub text: String,
    /// What is wrong with it.
    pub reason: &'static str,
}

impl ScanType {
    /// Bytes of one stored value.
    pub fn element_bytes(&self) -> usize {
        usize::from(self.storage_bits / 8)
    }

    /// Bytes the channel occupies in a record (all repeats), which is also its alignment in
    /// the kernel's layout (`iio_storage_bytes_for_si`).
    pub fn storage_bytes(&self) -> usize {
        self.element_bytes() * usize::from(self.repeat.max(1))
    }
}

impl FromStr for ScanType {
    type Err = ScanTypeError;

    fn from_str(s: &str) -> Result<Self, ScanTypeError> {
        let text = s.trim();
        let err = |reason| ScanTypeError {
            text: text.to_string(),
            reason,
        };
        let (endian, rest) = text.split_once(':').ok_or_else(|| err("no `:` after the byte order"))?;
        let endian = match endian {
            "le" => Endian::Little,
            "be" => Endian::Big,
            _ => return Err(err("byte order is not `le` or `be`")),
        };
        let mut chars = rest.chars();
        let repr = match chars.next() {
            Some('s') => Repr::Signed,
            Some('u') => Repr::Unsigned,
            Some('f') => Repr::Float,
            _ => return Err(err("representation is not `s`, `u` or `f`")),
        };
        let rest = chars.as_str();
        let (sizes, shift) = match rest.split_once(">>") {
            Some((a, b)) => (a, b.parse::<u8>().map_err(|_| err("shift is not a number"))?),
            None => (rest, 0),
        };
        let (sizes, repeat) = match sizes.split_once('X') {
            Some((a, b)) => (a, b.parse::<u8>().map_err(|_| err("repeat is not a number"))?),
            None => (sizes, 1),
        };
        let (bits, storage) = sizes
            .split_once('/')
            .ok_or_else(|| err("no `/` between bits and storage bits"))?;
        let bits = bits.parse::<u8>().map_err(|_| err("bits is not a number"))?;
        let storage_bits = storage.parse::<u8>().map_err(|_| err("storage bits is not a number"))?;
        if !matches!(storage_bits, 8 | 16 | 32 | 64) {
            return Err(err("storage bits must be 8, 16, 32 or 64"));
        }
        if bits == 0 || u32::from(bits) + u32::from(shift) > u32::from(storage_bits) {
            return Err(err(
                "bits must be at least 1 and bits + shift must not exceed the storage bits",
            ));
        }
        if repr == Repr::Float && !(bits == storage_bits && matches!(bits, 32 | 64)) {
            return Err(err("only 32- and 64-bit unshifted floats are supported"));
        }
        Ok(Self {
            endian,
            repr,
            bits,
            storage_bits,
            repeat: repeat.max(1),
            shift,
        })
    }
}

/// One scan element of a device.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ScanElement {
    /// Channel name without `in_` and the attribute suffix, e.g. `anglvel_x`, `temp0`,
    /// `timestamp`.
    pub name: String,
    /// Position in the scan (`_index`): records hold the enabled channels in ascending index.
    pub index: u32,
    /// Storage description.
    pub ty: ScanType,
}

/// What a channel measures, as far as an IMU driver is concerned.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ChannelRole {
    /// Angular rate, axis 0..2 (x, y, z).
    Gyro(usize),
    /// Acceleration, axis 0..2.
    Accel(usize),
    /// Temperature.
    Temp,
    /// The per-sample kernel time stamp.
    Timestamp,
}

impl ChannelRole {
    /// The role of a channel name, `None` for channels the driver does not use (magnetometer,
    /// pressure, delta angles, …).
    pub fn of(name: &str) -> Option<Self> {
        let axis = |s: &str| match s {
            "x" => Some(0),
            "y" => Some(1),
            "z" => Some(2),
            _ => None,
        };
        if let Some(a) = name.strip_prefix("anglvel_") {
            return axis(a).map(ChannelRole::Gyro);
        }
        if let Some(a) = name.strip_prefix("accel_") {
            return axis(a).map(ChannelRole::Accel);
        }
        if name == "timestamp" {
            return Some(ChannelRole::Timestamp);
        }
        match name.strip_prefix("temp") {
            Some(rest) if rest.chars().all(|c| c.is_ascii_digit()) => Some(ChannelRole::Temp),
            _ => None,
        }
    }

    /// The channel type prefix whose shared `in_<type>_scale` applies (`anglvel`, `accel`, `temp`).
    pub fn type_name(self) -> &'static str {
        match self {
            ChannelRole::Gyro(_) => "anglvel",
            ChannelRole::Accel(_) => "accel",
            ChannelRole::Temp => "temp",
            ChannelRole::Timestamp => "timestamp",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_the_documented_forms() {
        let t: ScanType = "le:s16/16>>0".parse().unwrap();
        assert_eq!(
            t,
            ScanType {
                endian: Endian::Little,
                repr: Repr::Signed,
                bits: 16,
                storage_bits: 16,
                repeat: 1,
                shift: 0
            }
        );
        let t: ScanType = "be:s12/16>>4\n".parse().unwrap();
        assert_eq!((t.endian, t.bits, t.storage_bits, t.shift), (Endian::Big, 12, 16, 4));
        let t: ScanType = "le:u10/16X3>>2".parse().unwrap();
        assert_eq!(
            (t.repr, t.repeat, t.shift, t.storage_bytes()),
            (Repr::Unsigned, 3, 2, 6)
        );
        let t: ScanType = "be:s48/64".parse().unwrap();
        assert_eq!((t.bits, t.shift), (48, 0));
        let t: ScanType = "le:f32/32>>0".parse().unwrap();
        assert_eq!(t.repr, Repr::Float);
    }

    #[test]
    fn rejects_what_it_cannot_decode_with_a_reason() {
        for (s, why) in [
            ("s16/16>>0", "no `:`"),
            ("me:s16/16>>0", "byte order"),
            ("le:x16/16>>0", "representation"),
            ("le:s16/12>>0", "storage bits must be"),
            ("le:s16/16>>4", "exceed"),
            ("le:s0/16", "exceed"),
            ("le:f16/16", "floats"),
            ("le:s16-16", "no `/`"),
        ] {
            let e = s.parse::<ScanType>().unwrap_err();
            assert!(e.to_string().contains(why), "{s}: {e}");
            assert!(e.to_string().contains("expected `[be|le]"), "{e}");
        }
    }

    #[test]
    fn roles() {
        assert_eq!(ChannelRole::of("anglvel_z"), Some(ChannelRole::Gyro(2)));
        assert_eq!(ChannelRole::of("accel_x"), Some(ChannelRole::Accel(0)));
        assert_eq!(ChannelRole::of("temp"), Some(ChannelRole::Temp));
        assert_eq!(ChannelRole::of("temp0"), Some(ChannelRole::Temp));
        assert_eq!(ChannelRole::of("timestamp"), Some(ChannelRole::Timestamp));
        assert_eq!(ChannelRole::of("magn_x"), None);
        assert_eq!(ChannelRole::of("anglvel_w"), None);
        assert_eq!(ChannelRole::of("deltaangl_x"), None);
    }
}
