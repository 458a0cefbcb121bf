//! CDR codec for every sample type, driven by its [`Reflect`] field table: the binary message
//! encoding of ROS 2 (`cdr` in rosbag2 and MCAP), so navsync's recordings are ROS 2 bags and
//! the messages decode with the `navsync_msgs` definitions of [`ros2msg`](crate::ros2msg).
//!
//! Rules (OMG DDS-XTypes 1.3 §7.4.3 "XCDR version 1", little endian, as rmw_fastrtps and
//! rosbag2 write it): a 4-byte encapsulation header `00 01 00 00` (CDR_LE), then the fields in
//! declaration order, each primitive aligned to its own size counted from the byte after the
//! header (8 for `int64`/`float64`), a `string` as a `uint32` length including the NUL, the
//! bytes and the NUL, fixed-size arrays as their elements without a length, nested messages
//! inline. `reserved` fields are not part of the messages (they are always zero).
//!
//! Floats are copied as their bit patterns, so a sample survives the round trip bit for bit,
//! NaNs included. Encoding and decoding allocate nothing beyond the output buffer's growth.

use crate::reflect::{Field, FieldType, Reflect};

/// The encapsulation header of little-endian plain CDR (RTPS 2.3 §10.2 `CDR_LE`).
pub const CDR_LE: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// A payload that is not a CDR message of the expected type.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("CDR byte {at}: {problem}")]
pub struct CdrError {
    /// Byte offset in the payload (header included).
    pub at: usize,
    /// What was wrong.
    pub problem: String,
}

/// Encodes `value` as a CDR message into `out` (cleared first; its capacity is reused).
pub fn encode<T: Reflect>(value: &T, out: &mut Vec<u8>) {
    out.clear();
    out.extend_from_slice(&CDR_LE);
    // SAFETY: the field table was generated from T's own declaration (offset_of!), so every
    // read below is of the declared type at an in-bounds offset.
    unsafe { encode_fields(T::FIELDS, (value as *const T).cast::<u8>(), out) }
}

fn align(out: &mut Vec<u8>, to: usize) {
    let pos = out.len() - CDR_LE.len();
    let pad = (to - pos % to) % to;
    out.extend_from_slice(&[0u8; 8][..pad]);
}

unsafe fn encode_fields(fields: &[Field], base: *const u8, out: &mut Vec<u8>) {
    for f in fields {
        if f.name == "reserved" {
            continue;
        }
        unsafe { encode_value(&f.ty, base.add(f.offset), out) };
    }
}

unsafe fn encode_value(ty: &FieldType, p: *const u8, out: &mut Vec<u8>) {
    macro_rules! prim {
        ($t:ty) => {{
            align(out, core::mem::size_of::<$t>());
            out.extend_from_slice(&p.cast::<$t>().read_unaligned().to_le_bytes());
        }};
    }
    unsafe {
        match ty {
            FieldType::I64 => prim!(i64),
            FieldType::U64 => prim!(u64),
            FieldType::I32 => prim!(i32),
            FieldType::U32 => prim!(u32),
            FieldType::I16 => prim!(i16),
            FieldType::U16 => prim!(u16),
            FieldType::U8 => out.push(p.read()),
            FieldType::F64 => prim!(f64),
            FieldType::F32 => prim!(f32),
            FieldType::Str(n) => {
                let bytes = core::slice::from_raw_parts(p, *n);
                let len = bytes.iter().position(|&b| b == 0).unwrap_or(*n);
                align(out, 4);
                out.extend_from_slice(&(len as u32 + 1).to_le_bytes());
                out.extend_from_slice(&bytes[..len]);
                out.push(0);
            }
            FieldType::Array(t, n) => {
                let sz = t.size();
                for i in 0..*n {
                    encode_value(t, p.add(i * sz), out);
                }
            }
            FieldType::Struct(_, fields) => encode_fields(fields, p, out),
        }
    }
}

/// Writes a CDR message field by field, for messages without a [`Reflect`] table (the
/// standard ROS 2 messages): the same rules as [`encode`].
pub struct Writer<'a> {
    out: &'a mut Vec<u8>,
}

impl<'a> Writer<'a> {
    /// Starts a message in `out` (cleared first) with the CDR_LE header.
    pub fn new(out: &'a mut Vec<u8>) -> Self {
        out.clear();
        out.extend_from_slice(&CDR_LE);
        Self { out }
    }
    /// `int8`.
    pub fn i8(&mut self, v: i8) -> &mut Self {
        self.out.push(v as u8);
        self
    }
    /// `uint8`.
    pub fn u8(&mut self, v: u8) -> &mut Self {
        self.out.push(v);
        self
    }
    /// `uint16`.
    pub fn u16(&mut self, v: u16) -> &mut Self {
        align(self.out, 2);
        self.out.extend_from_slice(&v.to_le_bytes());
        self
    }
    /// `int32`.
    pub fn i32(&mut self, v: i32) -> &mut Self {
        align(self.out, 4);
        self.out.extend_from_slice(&v.to_le_bytes());
        self
    }
    /// `uint32`.
    pub fn u32(&mut self, v: u32) -> &mut Self {
        align(self.out, 4);
        self.out.extend_from_slice(&v.to_le_bytes());
        self
    }
    /// `float64`.
    pub fn f64(&mut self, v: f64) -> &mut Self {
        align(self.out, 8);
        self.out.extend_from_slice(&v.to_le_bytes());
        self
    }
    /// `float64[N]`.
    pub fn f64s(&mut self, v: &[f64]) -> &mut Self {
        for x in v {
            self.f64(*x);
        }
        self
    }
    /// `string` (UTF-8, without NULs).
    pub fn str(&mut self, v: &str) -> &mut Self {
        align(self.out, 4);
        self.out.extend_from_slice(&(v.len() as u32 + 1).to_le_bytes());
        self.out.extend_from_slice(v.as_bytes());
        self.out.push(0);
        self
    }
}

/// Decodes a CDR message written by [`encode`] (or by any ROS 2 writer of the same
/// definition). Extra bytes after the last field (alignment padding) are allowed.
pub fn decode<T: Reflect>(data: &[u8]) -> Result<T, CdrError> {
    if data.len() < CDR_LE.len() {
        return Err(CdrError {
            at: 0,
            problem: "shorter than the encapsulation header".into(),
        });
    }
    if data[..2] != CDR_LE[..2] {
        return Err(CdrError {
            at: 0,
            problem: format!(
                "encapsulation {:02x}{:02x}, expected 0001 (little-endian plain CDR)",
                data[0], data[1]
            ),
        });
    }
    let mut out = T::zeroed();
    let mut r = Reader {
        body: &data[CDR_LE.len()..],
        pos: 0,
    };
    // SAFETY: as in `encode`; writes are of the declared type at in-bounds offsets of `out`.
    unsafe { decode_fields(T::FIELDS, (&mut out as *mut T).cast::<u8>(), &mut r)? };
    Ok(out)
}

struct Reader<'a> {
    body: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    fn err(&self, problem: impl Into<String>) -> CdrError {
        CdrError {
            at: self.pos + CDR_LE.len(),
            problem: problem.into(),
        }
    }

    fn take(&mut self, n: usize, align: usize) -> Result<&'a [u8], CdrError> {
        let start = self.pos.next_multiple_of(align);
        let end = start.checked_add(n).filter(|e| *e <= self.body.len());
        let Some(end) = end else {
            return Err(self.err(format!("needs {n} more bytes, the message ends")));
        };
        self.pos = end;
        Ok(&self.body[start..end])
    }
}

unsafe fn decode_fields(fields: &[Field], base: *mut u8, r: &mut Reader<'_>) -> Result<(), CdrError> {
    for f in fields {
        if f.name == "reserved" {
            continue;
        }
        unsafe { decode_value(&f.ty, base.add(f.offset), r)? };
    }
    Ok(())
}

unsafe fn decode_value(ty: &FieldType, p: *mut u8, r: &mut Reader<'_>) -> Result<(), CdrError> {
    macro_rules! prim {
        ($t:ty) => {{
            const N: usize = core::mem::size_of::<$t>();
            let b = r.take(N, N)?;
            let mut a = [0u8; N];
            a.copy_from_slice(b);
            p.cast::<$t>().write_unaligned(<$t>::from_le_bytes(a));
        }};
    }
    unsafe {
        match ty {
            FieldType::I64 => prim!(i64),
            FieldType::U64 => prim!(u64),
            FieldType::I32 => prim!(i32),
            FieldType::U32 => prim!(u32),
            FieldType::I16 => prim!(i16),
            FieldType::U16 => prim!(u16),
            FieldType::U8 => p.write(r.take(1, 1)?[0]),
            FieldType::F64 => prim!(f64),
            FieldType::F32 => prim!(f32),
            FieldType::Str(n) => {
                let len = u32::from_le_bytes(r.take(4, 4)?.try_into().unwrap_or([0; 4])) as usize;
                if len == 0 {
                    return Err(r.err("a string of length 0 (the NUL is counted)"));
                }
                if len - 1 > *n {
                    return Err(r.err(format!("a string of {} bytes, at most {n} fit", len - 1)));
                }
                let s = r.take(len, 1)?;
                let dst = core::slice::from_raw_parts_mut(p, *n);
                dst.fill(0);
                dst[..len - 1].copy_from_slice(&s[..len - 1]);
            }
            FieldType::Array(t, n) => {
                let sz = t.size();
                for i in 0..*n {
                    decode_value(t, p.add(i * sz), r)?;
                }
            }
            FieldType::Struct(_, fields) => decode_fields(fields, p, r)?,
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::samples::{GnssRaw, Health, ImuSample, NavState, Stamp, StampSource, TimeState};

    fn xorshift(seed: u64) -> impl FnMut() -> u64 {
        let mut x = seed;
        move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        }
    }

    /// Every byte of a value except `reserved` fields and padding, field by field.
    fn fill_random<T: Reflect>(next: &mut impl FnMut() -> u64) -> T {
        let mut v = T::zeroed();
        // Random bit patterns in every non-reserved numeric field; strings short ASCII.
        unsafe fn fill(fields: &[Field], base: *mut u8, next: &mut dyn FnMut() -> u64) {
            for f in fields {
                if f.name != "reserved" {
                    unsafe { fill_value(&f.ty, base.add(f.offset), next) };
                }
            }
        }
        unsafe fn fill_value(ty: &FieldType, p: *mut u8, next: &mut dyn FnMut() -> u64) {
            unsafe {
                match ty {
                    FieldType::Str(n) => {
                        let len = (next() as usize) % (n + 1);
                        for i in 0..len {
                            p.add(i).write(b'a' + (next() % 26) as u8);
                        }
                    }
                    FieldType::Array(t, n) => {
                        for i in 0..*n {
                            fill_value(t, p.add(i * t.size()), next);
                        }
                    }
                    FieldType::Struct(_, fields) => fill(fields, p, next),
                    t => {
                        let bytes = next().to_le_bytes();
                        core::ptr::copy_nonoverlapping(bytes.as_ptr(), p, t.size());
                    }
                }
            }
        }
        unsafe { fill(T::FIELDS, (&mut v as *mut T).cast::<u8>(), next) };
        v
    }

    fn same_bits<T: Reflect>(a: &T, b: &T) -> bool {
        let mut ea = Vec::new();
        let mut eb = Vec::new();
        encode(a, &mut ea);
        encode(b, &mut eb);
        ea == eb && crate::json::to_json(a) == crate::json::to_json(b)
    }

    fn round_trip<T: Reflect + core::fmt::Debug>(seed: u64) {
        let mut next = xorshift(seed);
        let mut buf = Vec::new();
        for _ in 0..500 {
            let v: T = fill_random(&mut next);
            encode(&v, &mut buf);
            let back: T = decode(&buf).unwrap();
            assert!(same_bits(&v, &back), "{}", T::TYPE_NAME);
            // Every truncation is an error, never a panic.
            for cut in [0, 3, 4, buf.len() / 2, buf.len() - 1] {
                assert!(decode::<T>(&buf[..cut]).is_err());
            }
        }
    }

    #[test]
    fn every_type_round_trips_bit_for_bit() {
        round_trip::<ImuSample>(1);
        round_trip::<NavState>(2);
        round_trip::<TimeState>(3);
        round_trip::<Health>(4);
        round_trip::<GnssRaw>(5);
    }

    #[test]
    fn an_imu_sample_is_laid_out_as_ros_2_writes_it() {
        let mut imu = ImuSample::zeroed();
        imu.stamp = Stamp::host(-2, 7, StampSource::Simulated);
        imu.gyro_rps = [1.0, f64::NAN, -0.0];
        let mut buf = Vec::new();
        encode(&imu, &mut buf);
        assert_eq!(&buf[..4], &CDR_LE);
        // Stamp: host_ns int64 at 0, device_ns at 8, seq uint64 at 16, source and
        // has_device_time uint8 at 24 and 25; then gyro_rps float64[3] aligned to 32.
        assert_eq!(&buf[4..12], &(-2i64).to_le_bytes());
        assert_eq!(&buf[20..28], &7u64.to_le_bytes());
        assert_eq!(buf[28], StampSource::Simulated as u8);
        assert_eq!(&buf[30..36], &[0; 6], "padding to 8");
        assert_eq!(&buf[36..44], &1.0f64.to_le_bytes());
        assert_eq!(&buf[44..52], &f64::NAN.to_le_bytes());
        let back: ImuSample = decode(&buf).unwrap();
        assert!(back.gyro_rps[1].is_nan() && back.gyro_rps[2].is_sign_negative());
    }

    #[test]
    fn a_string_too_long_or_big_endian_is_refused() {
        let imu = ImuSample::zeroed();
        let mut buf = Vec::new();
        encode(&imu, &mut buf);
        let mut be = buf.clone();
        be[1] = 0;
        assert!(decode::<ImuSample>(&be).unwrap_err().problem.contains("encapsulation"));
        // The imu_id string length follows the stamp (32 bytes), gyro_rps, accel_mps2, dt_s
        // and temperature_c (8 float64): body offset 96, after the 4-byte header.
        let at = 4 + 96;
        assert_eq!(&buf[at..at + 4], &1u32.to_le_bytes(), "empty imu_id");
        buf[at] = 200;
        assert!(decode::<ImuSample>(&buf).is_err());
    }
}
