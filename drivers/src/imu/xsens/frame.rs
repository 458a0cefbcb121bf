//! The Xsens MT binary protocol (Xbus) as pure functions on bytes: the frame layer
//! ([`XbusFramer`], resynchronising on garbage and checking the checksum) and the MTData2
//! message ([`decode_mtdata2`], [`encode_mtdata2`]).
//!
//! # The protocol (sources)
//!
//! Xsens, *MT Low Level Communication Protocol Documentation* (document MT0101P), and the
//! Xsens Device API headers it is implemented by (`xsprotocol.h`, `xsmessage.c`,
//! `xsdataidentifier.h`, `xsstatusflag.h` in `lib/xspublic/xstypes/` of Xsens' ROS driver
//! `xsens_mti_driver`, e.g. <https://github.com/nobleo/xsens_mti_driver>):
//!
//! - A message is `PREAMBLE 0xFA | BID | MID | LEN | DATA[LEN] | CHECKSUM`. `LEN` = 0xFF
//!   announces the extended length: two more bytes `LENH LENL` follow, and the data may be up
//!   to 8185 bytes (`XS_MAXDATALEN` = 8192 − 7); a standard length is at most 254.
//! - The checksum makes the sum of every byte from `BID` to `CHECKSUM` (inclusive, the
//!   preamble excluded) zero modulo 256 (two's complement of the sum of the others).
//! - `BID` is 0xFF (master device) for a stand-alone MTi; MTData2 is `MID` 0x36.
//! - All multi-byte values are big-endian (MTi User Manual MT0605P §5.7.1).
//! - MTData2's data is a sequence of packets `XDI (u16) | size (u8) | data[size]`. The data
//!   identifier's low nibble selects the format of real-valued data:
//!   bits 0–1 ([`RealFormat`]) 0 = IEEE-754 float32, 1 = fixed point 12.20 (i32 / 2²⁰),
//!   2 = fixed point 16.32 (48 bits sent as the 4-byte fraction, then the 2-byte signed
//!   integer part: `XsMessage_getDataFP1632`), 3 = float64; bits 2–3 the coordinate system
//!   of orientation-like outputs (not used for sensor-frame data).
//! - Identifiers used here (`xsdataidentifier.h`, format bits cleared): Temperature 0x0810
//!   (°C), PacketCounter 0x1020 (u16, +1 per MTData2 message, wraps), SampleTimeFine 0x1060
//!   (u32, ticks of the device's 10 kHz clock, wraps), DeltaV 0x4010 (m/s over the output
//!   interval), Acceleration 0x4020 (m/s²), RateOfTurn 0x8020 (rad/s), DeltaQ 0x8030 (the
//!   orientation increment over the output interval as a unit quaternion), StatusWord 0xE020
//!   (u32; bits 8–10 accelerometer x/y/z clipping, 11–13 gyroscope x/y/z clipping).
//! - Calibrated inertial data (and DeltaV/DeltaQ) are expressed in the sensor frame S, a
//!   right-handed frame aligned with the housing with z up (MTi Family Reference Manual
//!   MT1600P §4.2.1; MT0605P §5.2.2), or in the object frame O when a RotSensor alignment is
//!   configured. The driver maps them to forward-right-down with its axis map.
//!
//! Nothing here allocates per message: the framer keeps one fixed buffer, the decoder
//! returns a plain struct, the encoder writes into a caller-owned `Vec` whose capacity is
//! reused.

/// First byte of every message.
pub const PREAMBLE: u8 = 0xFA;
/// Bus identifier of a stand-alone device (the master).
pub const BID_MASTER: u8 = 0xFF;
/// Message identifier of MTData2.
pub const MID_MTDATA2: u8 = 0x36;
/// `LEN` value that announces a two-byte extended length.
pub const EXTENDED_LENGTH: u8 = 0xFF;
/// Longest data field of a message with a standard length byte.
pub const MAX_SHORT_DATA: usize = 254;
/// Longest data field of any message (`XS_MAXDATALEN`).
pub const MAX_DATA: usize = 8192 - 7;
/// Longest message: preamble, BID, MID, 0xFF, LENH, LENL, data, checksum.
pub const MAX_MESSAGE: usize = MAX_DATA + 7;

/// Data identifiers (format bits cleared) of the MTData2 items the driver understands.
pub mod xdi {
    /// Temperature, °C.
    pub const TEMPERATURE: u16 = 0x0810;
    /// Packet counter, u16, incremented with every MTData2 message.
    pub const PACKET_COUNTER: u16 = 0x1020;
    /// Sample time of the device's 10 kHz clock, u32 ticks.
    pub const SAMPLE_TIME_FINE: u16 = 0x1060;
    /// Velocity increment over the output interval, m/s, 3 reals.
    pub const DELTA_V: u16 = 0x4010;
    /// Calibrated acceleration (specific force), m/s², 3 reals.
    pub const ACCELERATION: u16 = 0x4020;
    /// Calibrated rate of turn, rad/s, 3 reals.
    pub const RATE_OF_TURN: u16 = 0x8020;
    /// Orientation increment over the output interval, unit quaternion (w, x, y, z), 4 reals.
    pub const DELTA_Q: u16 = 0x8030;
    /// Status word, u32.
    pub const STATUS_WORD: u16 = 0xE020;
    /// Mask of the identifier without its format nibble (`XDI_FullTypeMask`).
    pub const TYPE_MASK: u16 = 0xFFF0;
    /// Mask of the real-number format bits (`XDI_SubFormatMask`).
    pub const FORMAT_MASK: u16 = 0x0003;
}

/// StatusWord bits: accelerometer x, y, z clipping (`XSF_ClipAccX` …).
pub const STATUS_CLIP_ACC: [u32; 3] = [0x100, 0x200, 0x400];
/// StatusWord bits: gyroscope x, y, z clipping (`XSF_ClipGyrX` …).
pub const STATUS_CLIP_GYR: [u32; 3] = [0x800, 0x1000, 0x2000];

/// Ticks of SampleTimeFine per second.
pub const SAMPLE_TIME_FINE_HZ: i64 = 10_000;
/// Nanoseconds per SampleTimeFine tick.
pub const NS_PER_SAMPLE_TIME_FINE_TICK: i64 = 1_000_000_000 / SAMPLE_TIME_FINE_HZ;

/// How real numbers are encoded (the data identifier's bits 0–1).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RealFormat {
    /// IEEE-754 single precision, 4 bytes.
    Float32,
    /// Signed fixed point 12.20, 4 bytes.
    Fp1220,
    /// Signed fixed point 16.32, 6 bytes (fraction first).
    Fp1632,
    /// IEEE-754 double precision, 8 bytes.
    Float64,
}

impl RealFormat {
    /// The format selected by a data identifier.
    pub fn of_xdi(id: u16) -> Self {
        match id & xdi::FORMAT_MASK {
            0 => Self::Float32,
            1 => Self::Fp1220,
            2 => Self::Fp1632,
            _ => Self::Float64,
        }
    }

    /// The identifier bits of this format.
    pub fn bits(self) -> u16 {
        match self {
            Self::Float32 => 0,
            Self::Fp1220 => 1,
            Self::Fp1632 => 2,
            Self::Float64 => 3,
        }
    }

    /// Bytes per value.
    pub fn size(self) -> usize {
        match self {
            Self::Float32 | Self::Fp1220 => 4,
            Self::Fp1632 => 6,
            Self::Float64 => 8,
        }
    }

    /// Decodes one value from exactly [`size`](Self::size) bytes.
    fn read(self, b: &[u8]) -> f64 {
        match self {
            Self::Float32 => f64::from(f32::from_be_bytes([b[0], b[1], b[2], b[3]])),
            Self::Fp1220 => f64::from(i32::from_be_bytes([b[0], b[1], b[2], b[3]])) / (1u64 << 20) as f64,
            Self::Fp1632 => {
                let frac = u32::from_be_bytes([b[0], b[1], b[2], b[3]]);
                let int = i16::from_be_bytes([b[4], b[5]]);
                ((i64::from(int) << 32) | i64::from(frac)) as f64 / (1u64 << 32) as f64
            }
            Self::Float64 => f64::from_be_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]),
        }
    }

    /// Appends one value (fixed-point values saturate at the format's range).
    fn write(self, v: f64, out: &mut Vec<u8>) {
        match self {
            Self::Float32 => out.extend_from_slice(&(v as f32).to_be_bytes()),
            Self::Fp1220 => {
                let x = (v * (1u64 << 20) as f64)
                    .round()
                    .clamp(i32::MIN as f64, i32::MAX as f64) as i32;
                out.extend_from_slice(&x.to_be_bytes());
            }
            Self::Fp1632 => {
                let max = (1i64 << 47) - 1;
                let x = ((v * (1u64 << 32) as f64).round() as i64).clamp(-max - 1, max);
                out.extend_from_slice(&((x & 0xFFFF_FFFF) as u32).to_be_bytes());
                out.extend_from_slice(&((x >> 32) as i16).to_be_bytes());
            }
            Self::Float64 => out.extend_from_slice(&v.to_be_bytes()),
        }
    }
}

/// One complete, checksum-verified message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Message<'a> {
    /// Bus identifier.
    pub bid: u8,
    /// Message identifier.
    pub mid: u8,
    /// The data field.
    pub data: &'a [u8],
    /// Estimated host time (`CLOCK_MONOTONIC`, ns) at which the message's last byte arrived.
    pub host_ns: i64,
}

/// What the framer has seen and dropped since it was created.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FramerCounters {
    /// Bytes pushed.
    pub bytes: u64,
    /// Messages delivered (checksum correct).
    pub messages: u64,
    /// Bytes skipped while looking for a message start (garbage, line noise).
    pub noise_bytes: u64,
    /// Candidate messages whose checksum did not match; the framer resynchronised on the
    /// next preamble inside them.
    pub bad_checksum: u64,
    /// Candidate messages with a bus id other than 0xFF or an impossible extended length.
    pub bad_header: u64,
    /// Partial messages dropped by [`XbusFramer::reset`] (the port closed mid-message).
    pub truncated: u64,
}

impl FramerCounters {
    /// The counters with short names for a `Health` report.
    pub fn named(&self) -> [(&'static str, u64); 6] {
        [
            ("xbus_bytes", self.bytes),
            ("xbus_messages", self.messages),
            ("xbus_noise_bytes", self.noise_bytes),
            ("xbus_bad_checksum", self.bad_checksum),
            ("xbus_bad_header", self.bad_header),
            ("xbus_truncated", self.truncated),
        ]
    }
}

/// Byte stream → Xbus messages.
///
/// Feed it whatever `read()` returned; messages split across reads are reassembled. A
/// candidate that turns out wrong (bad bus id, impossible length, bad checksum) costs only
/// its first byte: the search for the next preamble restarts inside it, so a message that
/// follows a truncated one is not lost.
#[derive(Debug, Clone)]
pub struct XbusFramer {
    buf: Box<[u8; MAX_MESSAGE]>,
    len: usize,
    counters: FramerCounters,
}

impl Default for XbusFramer {
    fn default() -> Self {
        Self::new()
    }
}

/// Result of looking at the bytes collected so far.
enum Candidate {
    /// More bytes are needed.
    Incomplete,
    /// Not a message start: drop the first byte and search again.
    Invalid,
    /// A complete message of this many bytes (checksum verified or not, see `ok`).
    Complete { total: usize, ok: bool },
}

impl XbusFramer {
    /// A framer looking for a preamble.
    pub fn new() -> Self {
        Self {
            buf: Box::new([0; MAX_MESSAGE]),
            len: 0,
            counters: FramerCounters::default(),
        }
    }

    /// Counters since creation.
    pub fn counters(&self) -> &FramerCounters {
        &self.counters
    }

    /// Drops a partly received message (after the port was closed), counting it as truncated.
    pub fn reset(&mut self) {
        if self.len > 0 {
            self.counters.truncated += 1;
        }
        self.len = 0;
    }

    /// Consumes one chunk of received bytes and calls `out` for every complete message.
    ///
    /// `read_host_ns` is the host time at which the read returned (≈ the chunk's last byte);
    /// `ns_per_byte` the duration of one character on the line (`10e9 / baud`). A message's
    /// `host_ns` is the arrival time of its last byte, `read_host_ns − (bytes after it) ×
    /// ns_per_byte`.
    pub fn push(&mut self, bytes: &[u8], read_host_ns: i64, ns_per_byte: i64, out: &mut impl FnMut(Message<'_>)) {
        self.counters.bytes += bytes.len() as u64;
        for (i, &b) in bytes.iter().enumerate() {
            if self.len == 0 && b != PREAMBLE {
                self.counters.noise_bytes += 1;
                continue;
            }
            self.buf[self.len] = b;
            self.len += 1;
            let after = i64::try_from(bytes.len() - 1 - i).unwrap_or(i64::MAX);
            let host_ns = read_host_ns.saturating_sub(after.saturating_mul(ns_per_byte));
            self.settle(host_ns, out);
        }
    }

    /// Emits or discards whatever the buffer now holds, until it needs more bytes.
    fn settle(&mut self, host_ns: i64, out: &mut impl FnMut(Message<'_>)) {
        loop {
            match self.examine() {
                Candidate::Incomplete => return,
                Candidate::Complete { total, ok: true } => {
                    self.counters.messages += 1;
                    let header = if self.buf[3] == EXTENDED_LENGTH { 6 } else { 4 };
                    out(Message {
                        bid: self.buf[1],
                        mid: self.buf[2],
                        data: &self.buf[header..total - 1],
                        host_ns,
                    });
                    // Normally nothing follows; after a resync, buffered bytes may already
                    // hold further messages.
                    self.buf.copy_within(total..self.len, 0);
                    self.len -= total;
                }
                Candidate::Complete { ok: false, .. } => {
                    self.counters.bad_checksum += 1;
                    self.resync();
                }
                Candidate::Invalid => {
                    self.counters.bad_header += 1;
                    self.resync();
                }
            }
            if self.len == 0 {
                return;
            }
        }
    }

    fn examine(&self) -> Candidate {
        let b = &self.buf[..self.len];
        if b.len() >= 2 && b[1] != BID_MASTER {
            return Candidate::Invalid;
        }
        if b.len() < 4 {
            return Candidate::Incomplete;
        }
        let (header, data_len) = if b[3] == EXTENDED_LENGTH {
            if b.len() < 6 {
                return Candidate::Incomplete;
            }
            let n = usize::from(b[4]) << 8 | usize::from(b[5]);
            if n > MAX_DATA {
                return Candidate::Invalid;
            }
            (6, n)
        } else {
            (4, usize::from(b[3]))
        };
        let total = header + data_len + 1;
        if b.len() < total {
            return Candidate::Incomplete;
        }
        let sum = b[1..total].iter().fold(0u8, |s, &x| s.wrapping_add(x));
        Candidate::Complete { total, ok: sum == 0 }
    }

    /// Drops the first byte of the candidate and restarts at the next preamble inside it.
    fn resync(&mut self) {
        let next = self.buf[1..self.len].iter().position(|&b| b == PREAMBLE).map(|p| p + 1);
        match next {
            Some(p) => {
                self.counters.noise_bytes += p as u64;
                self.buf.copy_within(p..self.len, 0);
                self.len -= p;
            }
            None => {
                self.counters.noise_bytes += self.len as u64;
                self.len = 0;
            }
        }
    }
}

/// The contents of one MTData2 message (the items this driver uses).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct MtData2 {
    /// SampleTimeFine, 10 kHz ticks (wraps at 2³²).
    pub sample_time_fine: Option<u32>,
    /// PacketCounter (wraps at 2¹⁶).
    pub packet_counter: Option<u16>,
    /// Acceleration, m/s², sensor axes.
    pub acceleration: Option<[f64; 3]>,
    /// DeltaV, m/s over the output interval, sensor axes.
    pub delta_v: Option<[f64; 3]>,
    /// RateOfTurn, rad/s, sensor axes.
    pub rate_of_turn: Option<[f64; 3]>,
    /// DeltaQ, unit quaternion (w, x, y, z), sensor axes.
    pub delta_q: Option<[f64; 4]>,
    /// Temperature, °C.
    pub temperature_c: Option<f64>,
    /// StatusWord.
    pub status_word: Option<u32>,
    /// Items with an identifier this decoder does not use (skipped).
    pub other_items: u16,
}

/// A malformed MTData2 data field.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum MtData2Error {
    /// An item's header or data runs past the end of the message.
    #[error("item at byte {offset} runs past the end of the message")]
    Overrun {
        /// Offset of the item's identifier in the data field.
        offset: usize,
    },
    /// A known item has the wrong size for its format.
    #[error("item 0x{xdi:04X} has {size} bytes, expected {expected}")]
    WrongSize {
        /// The item's data identifier.
        xdi: u16,
        /// Its size field.
        size: usize,
        /// The size its type and format need.
        expected: usize,
    },
}

fn reals<const N: usize>(id: u16, data: &[u8]) -> Result<[f64; N], MtData2Error> {
    let f = RealFormat::of_xdi(id);
    let expected = N * f.size();
    if data.len() != expected {
        return Err(MtData2Error::WrongSize {
            xdi: id,
            size: data.len(),
            expected,
        });
    }
    let mut v = [0.0; N];
    for (i, x) in v.iter_mut().enumerate() {
        *x = f.read(&data[i * f.size()..(i + 1) * f.size()]);
    }
    Ok(v)
}

fn fixed<const N: usize>(id: u16, data: &[u8]) -> Result<[u8; N], MtData2Error> {
    data.try_into().map_err(|_| MtData2Error::WrongSize {
        xdi: id,
        size: data.len(),
        expected: N,
    })
}

/// Decodes the data field of an MTData2 message.
pub fn decode_mtdata2(data: &[u8]) -> Result<MtData2, MtData2Error> {
    let mut m = MtData2::default();
    let mut at = 0;
    while at < data.len() {
        let Some(hdr) = data.get(at..at + 3) else {
            return Err(MtData2Error::Overrun { offset: at });
        };
        let id = u16::from_be_bytes([hdr[0], hdr[1]]);
        let size = usize::from(hdr[2]);
        let Some(item) = data.get(at + 3..at + 3 + size) else {
            return Err(MtData2Error::Overrun { offset: at });
        };
        match id & xdi::TYPE_MASK {
            xdi::SAMPLE_TIME_FINE => m.sample_time_fine = Some(u32::from_be_bytes(fixed(id, item)?)),
            xdi::PACKET_COUNTER => m.packet_counter = Some(u16::from_be_bytes(fixed(id, item)?)),
            xdi::STATUS_WORD => m.status_word = Some(u32::from_be_bytes(fixed(id, item)?)),
            xdi::ACCELERATION => m.acceleration = Some(reals::<3>(id, item)?),
            xdi::DELTA_V => m.delta_v = Some(reals::<3>(id, item)?),
            xdi::RATE_OF_TURN => m.rate_of_turn = Some(reals::<3>(id, item)?),
            xdi::DELTA_Q => m.delta_q = Some(reals::<4>(id, item)?),
            xdi::TEMPERATURE => m.temperature_c = Some(reals::<1>(id, item)?[0]),
            _ => m.other_items = m.other_items.saturating_add(1),
        }
        at += 3 + size;
    }
    Ok(m)
}

fn put_item(out: &mut Vec<u8>, id: u16, size: usize) {
    out.extend_from_slice(&id.to_be_bytes());
    out.push(size as u8);
}

fn put_reals(out: &mut Vec<u8>, id: u16, f: RealFormat, v: &[f64]) {
    put_item(out, id | f.bits(), v.len() * f.size());
    for &x in v {
        f.write(x, out);
    }
}

/// Writes a complete MTData2 message (preamble to checksum) into `out` (cleared first; its
/// capacity is reused), real values in `format`. Items are written in the order
/// PacketCounter, SampleTimeFine, StatusWord, Temperature, Acceleration, DeltaV,
/// RateOfTurn, DeltaQ, each only if present. [`decode_mtdata2`] is its inverse (up to the
/// format's precision).
pub fn encode_mtdata2(m: &MtData2, format: RealFormat, out: &mut Vec<u8>) {
    out.clear();
    out.extend_from_slice(&[PREAMBLE, BID_MASTER, MID_MTDATA2, 0]);
    if let Some(pc) = m.packet_counter {
        put_item(out, xdi::PACKET_COUNTER, 2);
        out.extend_from_slice(&pc.to_be_bytes());
    }
    if let Some(t) = m.sample_time_fine {
        put_item(out, xdi::SAMPLE_TIME_FINE, 4);
        out.extend_from_slice(&t.to_be_bytes());
    }
    if let Some(s) = m.status_word {
        put_item(out, xdi::STATUS_WORD, 4);
        out.extend_from_slice(&s.to_be_bytes());
    }
    if let Some(t) = m.temperature_c {
        put_reals(out, xdi::TEMPERATURE, format, &[t]);
    }
    if let Some(a) = &m.acceleration {
        put_reals(out, xdi::ACCELERATION, format, a);
    }
    if let Some(v) = &m.delta_v {
        put_reals(out, xdi::DELTA_V, format, v);
    }
    if let Some(w) = &m.rate_of_turn {
        put_reals(out, xdi::RATE_OF_TURN, format, w);
    }
    if let Some(q) = &m.delta_q {
        put_reals(out, xdi::DELTA_Q, format, q);
    }
    let data_len = out.len() - 4;
    if data_len > MAX_SHORT_DATA {
        // Extended length: LEN = 0xFF followed by the 16-bit length.
        out[3] = EXTENDED_LENGTH;
        let len = (data_len as u16).to_be_bytes();
        out.splice(4..4, len);
    } else {
        out[3] = data_len as u8;
    }
    let sum = out[1..].iter().fold(0u8, |s, &x| s.wrapping_add(x));
    out.push(sum.wrapping_neg());
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frames(framer: &mut XbusFramer, chunks: &[&[u8]]) -> Vec<(u8, Vec<u8>, i64)> {
        let mut got = Vec::new();
        for (k, c) in chunks.iter().enumerate() {
            framer.push(c, 1_000 * (k as i64 + 1), 10, &mut |m| {
                got.push((m.mid, m.data.to_vec(), m.host_ns))
            });
        }
        got
    }

    fn sample() -> MtData2 {
        MtData2 {
            sample_time_fine: Some(4_294_967_000),
            packet_counter: Some(65_535),
            acceleration: Some([0.25, -1.5, 9.80665]),
            rate_of_turn: Some([0.001, -0.5, 3.25]),
            temperature_c: Some(31.5),
            status_word: Some(STATUS_CLIP_GYR[2]),
            ..Default::default()
        }
    }

    /// A message from the MT Low Level Communication Protocol examples: GoToConfig
    /// `FA FF 30 00 D1` (0xFF + 0x30 + 0x00 + 0xD1 = 0x200 ≡ 0).
    #[test]
    fn documented_example_checksum() {
        let mut f = XbusFramer::new();
        let got = frames(&mut f, &[&[0xFA, 0xFF, 0x30, 0x00, 0xD1]]);
        assert_eq!(got, vec![(0x30, vec![], 1_000)]);
    }

    #[test]
    fn encode_then_decode_every_format() {
        for format in [
            RealFormat::Float32,
            RealFormat::Fp1220,
            RealFormat::Fp1632,
            RealFormat::Float64,
        ] {
            let m = sample();
            let mut out = Vec::new();
            encode_mtdata2(&m, format, &mut out);
            let mut f = XbusFramer::new();
            let got = frames(&mut f, &[&out]);
            assert_eq!(got.len(), 1, "{format:?}");
            assert_eq!(got[0].0, MID_MTDATA2);
            let d = decode_mtdata2(&got[0].1).unwrap();
            assert_eq!(d.sample_time_fine, m.sample_time_fine);
            assert_eq!(d.packet_counter, m.packet_counter);
            assert_eq!(d.status_word, m.status_word);
            let tol = match format {
                RealFormat::Float32 => 4e-7 * 10.0,
                RealFormat::Fp1220 => 1e-6,
                RealFormat::Fp1632 => 1e-9,
                RealFormat::Float64 => 0.0,
            };
            for (a, b) in d.acceleration.unwrap().iter().zip(m.acceleration.unwrap()) {
                assert!((a - b).abs() <= tol, "{format:?}: {a} vs {b}");
            }
            for (a, b) in d.rate_of_turn.unwrap().iter().zip(m.rate_of_turn.unwrap()) {
                assert!((a - b).abs() <= tol, "{format:?}: {a} vs {b}");
            }
            assert!((d.temperature_c.unwrap() - 31.5).abs() <= tol);
        }
    }

    #[test]
    fn fixed_point_bytes_as_documented() {
        // 16.32: fraction first, then the signed integer part. −1.5 = 0xFFFF_FFFE.8000_0000.
        let mut out = Vec::new();
        RealFormat::Fp1632.write(-1.5, &mut out);
        assert_eq!(out, [0x80, 0x00, 0x00, 0x00, 0xFF, 0xFE]);
        assert_eq!(RealFormat::Fp1632.read(&out), -1.5);
        out.clear();
        RealFormat::Fp1220.write(1.0, &mut out);
        assert_eq!(out, [0x00, 0x10, 0x00, 0x00]);
        // 9.81 as float32 is 0x411CF5C3 (MT0605P §5.7.1).
        assert!((RealFormat::Float32.read(&[0x41, 0x1C, 0xF5, 0xC3]) - 9.81).abs() < 1e-6);
    }

    #[test]
    fn extended_length_round_trip() {
        // 60 DeltaQ-sized items make the data longer than 254 bytes.
        let mut out = Vec::new();
        let m = MtData2 {
            delta_q: Some([1.0, 0.0, 0.0, 0.0]),
            acceleration: Some([1.0, 2.0, 3.0]),
            ..Default::default()
        };
        encode_mtdata2(&m, RealFormat::Float64, &mut out);
        assert!(out[3] != EXTENDED_LENGTH);
        // Build an extended message by hand: 300 bytes of an unknown item.
        let mut data = vec![0x70, 0x10, 255];
        data.extend(std::iter::repeat_n(0xAB, 255));
        data.extend_from_slice(&[0x10, 0x20, 2, 0x12, 0x34]);
        let mut msg = vec![PREAMBLE, BID_MASTER, MID_MTDATA2, EXTENDED_LENGTH];
        msg.extend_from_slice(&(data.len() as u16).to_be_bytes());
        msg.extend_from_slice(&data);
        let sum = msg[1..].iter().fold(0u8, |s, &x| s.wrapping_add(x));
        msg.push(sum.wrapping_neg());
        let mut f = XbusFramer::new();
        let got = frames(&mut f, &[&msg[..100], &msg[100..]]);
        assert_eq!(got.len(), 1);
        let d = decode_mtdata2(&got[0].1).unwrap();
        assert_eq!(d.packet_counter, Some(0x1234));
        assert_eq!(d.other_items, 1);
    }

    #[test]
    fn resyncs_on_garbage_and_counts_bad_checksums() {
        let mut good = Vec::new();
        encode_mtdata2(&sample(), RealFormat::Float32, &mut good);
        let mut bad = good.clone();
        let n = bad.len();
        bad[n - 2] ^= 0x01;
        // Garbage (with a fake preamble), a corrupted message, a good one split over reads.
        let mut stream = vec![0x00, 0xFA, 0x12, 0x55, 0xFA];
        stream.extend_from_slice(&bad);
        stream.extend_from_slice(&good);
        let (a, b) = stream.split_at(20);
        let mut f = XbusFramer::new();
        let got = frames(&mut f, &[a, b]);
        assert_eq!(got.len(), 1);
        assert_eq!(decode_mtdata2(&got[0].1).unwrap().packet_counter, Some(65_535));
        let c = f.counters();
        assert_eq!(c.messages, 1);
        assert_eq!(c.bad_checksum, 1);
        assert!(c.bad_header >= 2, "{c:?}");
        assert_eq!(c.bytes, stream.len() as u64);
        // Every byte is accounted for: noise or part of the delivered message.
        assert_eq!(c.noise_bytes + good.len() as u64, c.bytes);
    }

    #[test]
    fn truncated_message_does_not_hide_the_next() {
        let mut good = Vec::new();
        encode_mtdata2(&sample(), RealFormat::Float32, &mut good);
        let mut stream = good[..good.len() / 2].to_vec();
        stream.extend_from_slice(&good);
        stream.extend_from_slice(&good);
        let mut f = XbusFramer::new();
        let got = frames(&mut f, &[&stream]);
        assert_eq!(got.len(), 2, "{:?}", f.counters());
        // A cut at the end of the input is kept until more bytes come or the port closes.
        let got = frames(&mut f, &[&good[..7]]);
        assert!(got.is_empty());
        f.reset();
        assert_eq!(f.counters().truncated, 1);
        assert_eq!(frames(&mut f, &[&good]).len(), 1);
    }

    #[test]
    fn stamps_the_last_byte() {
        let mut good = Vec::new();
        encode_mtdata2(&sample(), RealFormat::Float32, &mut good);
        let mut two = good.clone();
        two.extend_from_slice(&good);
        let mut f = XbusFramer::new();
        let mut stamps = Vec::new();
        f.push(&two, 1_000_000, 100, &mut |m| stamps.push(m.host_ns));
        assert_eq!(stamps, vec![1_000_000 - good.len() as i64 * 100, 1_000_000]);
    }

    #[test]
    fn malformed_items_are_errors_not_panics() {
        assert_eq!(decode_mtdata2(&[0x10, 0x20]), Err(MtData2Error::Overrun { offset: 0 }));
        assert_eq!(
            decode_mtdata2(&[0x10, 0x20, 3, 0, 0]),
            Err(MtData2Error::Overrun { offset: 0 })
        );
        assert_eq!(
            decode_mtdata2(&[0x40, 0x20, 4, 0, 0, 0, 0]),
            Err(MtData2Error::WrongSize {
                xdi: 0x4020,
                size: 4,
                expected: 12
            })
        );
        assert_eq!(decode_mtdata2(&[]), Ok(MtData2::default()));
    }

    #[test]
    fn random_bytes_never_panic_and_are_accounted() {
        let mut f = XbusFramer::new();
        let mut x: u64 = 0x2545_F491_4F6C_DD1D;
        let mut chunk = [0u8; 131];
        let mut n = 0u64;
        for round in 0..3_000 {
            for b in chunk.iter_mut() {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                *b = match (x >> 40) as u8 {
                    0..=20 => PREAMBLE,
                    21..=40 => BID_MASTER,
                    v => v,
                };
            }
            f.push(&chunk, round, 1, &mut |m| {
                let _ = decode_mtdata2(m.data);
                n += 1;
            });
        }
        assert_eq!(n, f.counters().messages);
        assert_eq!(f.counters().bytes, 3_000 * 131);
    }
}
