//! Splits a u-blox serial byte stream into UBX frames, NMEA sentences and RTCM3 frames.
//!
//! A u-blox port interleaves three framings (u-blox 8 / M8 Receiver Description incl.
//! Protocol Specification, UBX-13003221, "UBX Frame Structure", "UBX Checksum"; RTCM
//! 10403.x, "Transport Layer"):
//!
//! - **UBX**: `0xB5 0x62`, class, id, little-endian u16 payload length, payload, and the
//!   8-bit Fletcher checksum `CK_A CK_B` over class..payload. Payloads longer than
//!   [`MAX_UBX_PAYLOAD`] are taken for garbage (the longest real messages, RXM-RAWX with 255
//!   measurements, are 8176 bytes).
//! - **NMEA 0183**: `$`, printable ASCII, `*hh`, CR/LF; at most [`MAX_SENTENCE_LEN`]
//!   characters. Only sentences whose checksum verifies are delivered.
//! - **RTCM3**: `0xD3`, 6 reserved bits (zero) and a 10-bit length, payload, CRC-24Q.
//!
//! A candidate frame whose checksum fails or whose length is implausible is counted and the
//! scan resumes at the byte after its first byte, so a frame following a corrupt one is not
//! lost even when the corrupt frame's length field was garbage. Bytes belonging to no frame
//! are counted as noise (CR/LF between sentences excepted).
//!
//! Pure and fixed-size: bytes wait in an internal window of [`WINDOW`] bytes (one frame of
//! the largest size), no allocation. Each frame carries the host time of its first byte
//! under the same back-dating rule as the NMEA framer (the last byte of a read arrived when
//! the read returned, each earlier one `ns_per_byte` before its successor).

use crate::gnss::nmea::framer::MAX_SENTENCE_LEN;

/// Largest UBX payload accepted, bytes; a length field above it is a framing error.
pub const MAX_UBX_PAYLOAD: usize = 8192;

/// UBX frame overhead: sync (2), class, id, length (2), checksum (2).
pub const UBX_OVERHEAD: usize = 8;

/// Largest RTCM3 payload (10-bit length field), bytes.
pub const MAX_RTCM3_PAYLOAD: usize = 1023;

/// Bytes the framer can hold: one UBX frame of the largest accepted size.
pub const WINDOW: usize = MAX_UBX_PAYLOAD + UBX_OVERHEAD;

/// Reads remembered for time-stamping the bytes still in the window (a byte older than all of
/// them is dated by the oldest read's rate, an approximation that only arises after more
/// than this many reads within one frame).
const READS: usize = 32;

/// UBX sync characters.
const SYNC1: u8 = 0xB5;
const SYNC2: u8 = 0x62;
/// RTCM3 preamble.
const RTCM3_PREAMBLE: u8 = 0xD3;

/// One frame delivered by [`UbxFramer::push`], stamped with the host time of its first byte
/// (`CLOCK_MONOTONIC`, ns).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Frame<'a> {
    /// A UBX frame whose checksum verified.
    Ubx {
        /// Message class.
        class: u8,
        /// Message id within the class.
        id: u8,
        /// The payload (without header and checksum).
        payload: &'a [u8],
        /// Host time of the frame's first byte (the 0xB5), ns.
        host_ns: i64,
    },
    /// An NMEA sentence whose checksum verified.
    Nmea {
        /// From the `$` up to (not including) CR/LF, with its `*hh`.
        text: &'a [u8],
        /// Host time of the `$`, ns.
        host_ns: i64,
    },
    /// An RTCM3 frame whose CRC-24Q verified.
    Rtcm3 {
        /// RTCM message number (the first 12 bits of the payload; 0 for an empty payload).
        message_type: u16,
        /// The payload (without the 3-byte header and the CRC).
        payload: &'a [u8],
        /// Host time of the 0xD3, ns.
        host_ns: i64,
    },
}

/// What the framer has delivered and dropped since it was created.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FramerCounters {
    /// Bytes pushed.
    pub bytes: u64,
    /// UBX frames delivered.
    pub ubx_frames: u64,
    /// UBX candidates whose checksum failed; skipped.
    pub ubx_bad_checksum: u64,
    /// UBX candidates with a length above [`MAX_UBX_PAYLOAD`]; skipped.
    pub ubx_bad_length: u64,
    /// NMEA sentences delivered.
    pub nmea_sentences: u64,
    /// NMEA sentences with a wrong or missing checksum; dropped.
    pub nmea_bad_checksum: u64,
    /// RTCM3 frames delivered.
    pub rtcm3_frames: u64,
    /// RTCM3 candidates whose CRC failed; skipped.
    pub rtcm3_bad_crc: u64,
    /// Bytes outside every delivered frame (those of failed candidates included), other than
    /// CR/LF.
    pub noise_bytes: u64,
}

impl FramerCounters {
    /// The counters with short names for a `Health` report (names ≤ 23 bytes).
    pub fn named(&self) -> [(&'static str, u64); 9] {
        [
            ("ubx_bytes", self.bytes),
            ("ubx_frames", self.ubx_frames),
            ("ubx_bad_checksum", self.ubx_bad_checksum),
            ("ubx_bad_length", self.ubx_bad_length),
            ("ubx_nmea_sentences", self.nmea_sentences),
            ("ubx_nmea_bad_checksum", self.nmea_bad_checksum),
            ("ubx_rtcm3_frames", self.rtcm3_frames),
            ("ubx_rtcm3_bad_crc", self.rtcm3_bad_crc),
            ("ubx_noise_bytes", self.noise_bytes),
        ]
    }

    /// Frames of any framing that verified (bytes at the right line rate).
    pub fn valid_frames(&self) -> u64 {
        self.ubx_frames + self.nmea_sentences + self.rtcm3_frames
    }
}

/// One read: the stream offset just past its last byte, when it returned, the line rate.
#[derive(Debug, Clone, Copy, Default)]
struct Read {
    end: u64,
    host_ns: i64,
    ns_per_byte: i64,
}

/// What the window's first byte starts.
enum Scan {
    /// A complete frame of this many bytes; `kind` tells which.
    Frame(usize, Kind),
    /// Not a frame start, or a failed candidate (which check failed): skip one byte, counted
    /// as noise unless CR/LF.
    Skip(Option<Bad>),
    /// A candidate that needs more bytes.
    Wait,
}

/// A failed frame candidate.
#[derive(Clone, Copy)]
enum Bad {
    UbxLength,
    UbxChecksum,
    NmeaChecksum,
    Rtcm3Crc,
}

#[derive(Clone, Copy)]
enum Kind {
    Ubx,
    Nmea,
    Rtcm3,
}

/// Byte stream → UBX frames, NMEA sentences and RTCM3 frames, each stamped with the host time
/// of its first byte. Feed it whatever `read()` returned, in order.
#[derive(Debug, Clone)]
pub struct UbxFramer {
    buf: [u8; WINDOW],
    /// Window: `buf[start..end]` are bytes not yet consumed.
    start: usize,
    end: usize,
    /// Stream offset of `buf[0]`.
    base: u64,
    reads: [Read; READS],
    /// Next slot of `reads` (ring).
    next_read: usize,
    counters: FramerCounters,
}

impl Default for UbxFramer {
    fn default() -> Self {
        Self::new()
    }
}

impl UbxFramer {
    /// A framer at the start of a stream.
    pub fn new() -> Self {
        Self {
            buf: [0; WINDOW],
            start: 0,
            end: 0,
            base: 0,
            reads: [Read::default(); READS],
            next_read: 0,
            counters: FramerCounters::default(),
        }
    }

    /// Counters since creation.
    pub fn counters(&self) -> &FramerCounters {
        &self.counters
    }

    /// Drops the bytes of a partly received frame (the port was reopened, its rate changed).
    pub fn reset(&mut self) {
        self.base += self.end as u64;
        self.start = 0;
        self.end = 0;
    }

    /// Consumes the bytes of one read and calls `out` for every frame they complete.
    ///
    /// `read_host_ns`: host time (`CLOCK_MONOTONIC`, ns) at which the read returned, taken as
    /// the arrival of its last byte; `ns_per_byte`: duration of one character on the line
    /// (10 bits: `10e9 / baud`), 0 on a pseudo-terminal. A frame's time is that of its first
    /// byte: `read_host_ns − (bytes after it in its read) × ns_per_byte`, from the read that
    /// brought that byte.
    pub fn push(&mut self, bytes: &[u8], read_host_ns: i64, ns_per_byte: i64, out: &mut impl FnMut(Frame<'_>)) {
        self.counters.bytes += bytes.len() as u64;
        let end = self.base + self.end as u64 + bytes.len() as u64;
        self.reads[self.next_read] = Read {
            end,
            host_ns: read_host_ns,
            ns_per_byte,
        };
        self.next_read = (self.next_read + 1) % READS;
        let mut rest = bytes;
        while !rest.is_empty() {
            if self.start > 0 {
                self.buf.copy_within(self.start..self.end, 0);
                self.base += self.start as u64;
                self.end -= self.start;
                self.start = 0;
            }
            let n = rest.len().min(WINDOW - self.end);
            if let (Some(dst), Some(src)) = (self.buf.get_mut(self.end..self.end + n), rest.get(..n)) {
                dst.copy_from_slice(src);
            }
            self.end += n;
            rest = rest.get(n..).unwrap_or(&[]);
            self.scan(out);
        }
    }

    /// Host time of the byte at stream offset `at`, from the read that brought it.
    fn time_of(&self, at: u64) -> i64 {
        let mut best: Option<Read> = None;
        for r in self.reads.iter().filter(|r| r.end > at) {
            // The read containing `at` is the earliest one ending after it.
            if best.is_none_or(|b| r.end < b.end) {
                best = Some(*r);
            }
        }
        let r = best.unwrap_or_default();
        let after = i64::try_from(r.end.saturating_sub(at + 1)).unwrap_or(i64::MAX);
        r.host_ns.saturating_sub(after.saturating_mul(r.ns_per_byte))
    }

    /// Delivers every complete frame in the window; stops at a candidate that needs more bytes.
    fn scan(&mut self, out: &mut impl FnMut(Frame<'_>)) {
        while self.start < self.end {
            let w = self.buf.get(self.start..self.end).unwrap_or(&[]);
            match classify(w) {
                Scan::Wait => {
                    // Only a window too small for the candidate could make it wait forever;
                    // WINDOW holds the largest accepted frame of every framing.
                    if self.start == 0 && self.end == WINDOW {
                        self.skip();
                    } else {
                        return;
                    }
                }
                Scan::Skip(bad) => {
                    let c = &mut self.counters;
                    match bad {
                        Some(Bad::UbxLength) => c.ubx_bad_length += 1,
                        Some(Bad::UbxChecksum) => c.ubx_bad_checksum += 1,
                        Some(Bad::NmeaChecksum) => c.nmea_bad_checksum += 1,
                        Some(Bad::Rtcm3Crc) => c.rtcm3_bad_crc += 1,
                        None => {}
                    }
                    self.skip();
                }
                Scan::Frame(len, kind) => {
                    let host_ns = self.time_of(self.base + self.start as u64);
                    let frame = self.buf.get(self.start..self.start + len).unwrap_or(&[]);
                    match kind {
                        Kind::Ubx => {
                            self.counters.ubx_frames += 1;
                            out(Frame::Ubx {
                                class: frame.get(2).copied().unwrap_or(0),
                                id: frame.get(3).copied().unwrap_or(0),
                                payload: frame.get(6..len - 2).unwrap_or(&[]),
                                host_ns,
                            });
                        }
                        Kind::Nmea => {
                            self.counters.nmea_sentences += 1;
                            let text_len = frame.iter().position(|&b| b == b'\r' || b == b'\n').unwrap_or(len);
                            out(Frame::Nmea {
                                text: frame.get(..text_len).unwrap_or(&[]),
                                host_ns,
                            });
                        }
                        Kind::Rtcm3 => {
                            self.counters.rtcm3_frames += 1;
                            let payload = frame.get(3..len - 3).unwrap_or(&[]);
                            let message_type = match payload {
                                [a, b, ..] => (u16::from(*a) << 4) | (u16::from(*b) >> 4),
                                _ => 0,
                            };
                            out(Frame::Rtcm3 {
                                message_type,
                                payload,
                                host_ns,
                            });
                        }
                    }
                    self.start += len;
                }
            }
        }
    }

    /// Skips the window's first byte (noise unless a line terminator).
    fn skip(&mut self) {
        if let Some(&b) = self.buf.get(self.start)
            && b != b'\r'
            && b != b'\n'
        {
            self.counters.noise_bytes += 1;
        }
        self.start += 1;
    }
}

/// What the window `w` (non-empty) starts with (and which check a failed candidate failed).
fn classify(w: &[u8]) -> Scan {
    match w.first() {
        Some(&SYNC1) => classify_ubx(w),
        Some(&b'$') => classify_nmea(w),
        Some(&RTCM3_PREAMBLE) => classify_rtcm3(w),
        _ => Scan::Skip(None),
    }
}

fn classify_ubx(w: &[u8]) -> Scan {
    match w.get(1) {
        None => return Scan::Wait,
        Some(&SYNC2) => {}
        Some(_) => return Scan::Skip(None),
    }
    let Some(&[lo, hi]) = w.get(4..6) else {
        return Scan::Wait;
    };
    let len = usize::from(u16::from_le_bytes([lo, hi]));
    if len > MAX_UBX_PAYLOAD {
        return Scan::Skip(Some(Bad::UbxLength));
    }
    let total = len + UBX_OVERHEAD;
    let Some(frame) = w.get(..total) else {
        return Scan::Wait;
    };
    let (ck_a, ck_b) = ubx_checksum(frame.get(2..total - 2).unwrap_or(&[]));
    if frame.get(total - 2..) == Some(&[ck_a, ck_b][..]) {
        Scan::Frame(total, Kind::Ubx)
    } else {
        Scan::Skip(Some(Bad::UbxChecksum))
    }
}

fn classify_nmea(w: &[u8]) -> Scan {
    // Printable ASCII up to CR/LF, at most MAX_SENTENCE_LEN characters before it.
    for (i, &b) in w.iter().enumerate() {
        match b {
            b'\r' | b'\n' => {
                let text = w.get(..i).unwrap_or(&[]);
                // Swallow the terminator pair (CR LF) with the sentence.
                let mut len = i + 1;
                // (An LF still on its way is skipped later as a terminator.)
                if b == b'\r' && w.get(i + 1) == Some(&b'\n') {
                    len += 1;
                }
                return if nmea_checksum_ok(text) {
                    Scan::Frame(len, Kind::Nmea)
                } else {
                    Scan::Skip(Some(Bad::NmeaChecksum))
                };
            }
            0x20..=0x7e if i < MAX_SENTENCE_LEN => {}
            _ => return Scan::Skip(None),
        }
    }
    if w.len() > MAX_SENTENCE_LEN {
        Scan::Skip(None)
    } else {
        Scan::Wait
    }
}

fn classify_rtcm3(w: &[u8]) -> Scan {
    let Some(&[b1, b2]) = w.get(1..3) else {
        return Scan::Wait;
    };
    if b1 & 0xFC != 0 {
        return Scan::Skip(None);
    }
    let len = (usize::from(b1 & 0x03) << 8) | usize::from(b2);
    let total = 3 + len + 3;
    let Some(frame) = w.get(..total) else {
        return Scan::Wait;
    };
    let crc = crc24q(frame.get(..3 + len).unwrap_or(&[]));
    let sent = frame
        .get(3 + len..)
        .map_or(u32::MAX, |c| c.iter().fold(0u32, |acc, &b| (acc << 8) | u32::from(b)));
    if crc == sent {
        Scan::Frame(total, Kind::Rtcm3)
    } else {
        Scan::Skip(Some(Bad::Rtcm3Crc))
    }
}

/// The UBX 8-bit Fletcher checksum (`CK_A`, `CK_B`) over `bytes` (class, id, length, payload).
pub fn ubx_checksum(bytes: &[u8]) -> (u8, u8) {
    bytes.iter().fold((0u8, 0u8), |(a, b), &x| {
        let a = a.wrapping_add(x);
        (a, b.wrapping_add(a))
    })
}

/// True when `text` (`$…*hh`) ends with the XOR of the bytes between `$` and `*` as two hex
/// digits (either case).
fn nmea_checksum_ok(text: &[u8]) -> bool {
    let Some(star) = text.iter().rposition(|&b| b == b'*') else {
        return false;
    };
    let (Some(body), Some(hex)) = (text.get(1..star), text.get(star + 1..)) else {
        return false;
    };
    let sum = body.iter().fold(0u8, |c, &b| c ^ b);
    let Ok(hex) = core::str::from_utf8(hex) else {
        return false;
    };
    hex.len() == 2 && u8::from_str_radix(hex, 16) == Ok(sum)
}

/// CRC-24Q (RTCM 10403.x, polynomial 0x1864CFB, initial value 0) over `bytes`.
pub fn crc24q(bytes: &[u8]) -> u32 {
    bytes.iter().fold(0u32, |crc, &b| {
        let i = ((crc >> 16) as u8 ^ b) as usize;
        ((crc << 8) & 0xFF_FFFF) ^ CRC24Q_TABLE[i]
    })
}

const CRC24Q_TABLE: [u32; 256] = crc24q_table();

const fn crc24q_table() -> [u32; 256] {
    let mut t = [0u32; 256];
    let mut i = 0;
    while i < 256 {
        let mut crc = (i as u32) << 16;
        let mut bit = 0;
        while bit < 8 {
            crc <<= 1;
            if crc & 0x100_0000 != 0 {
                crc ^= 0x186_4CFB;
            }
            bit += 1;
        }
        t[i] = crc & 0xFF_FFFF;
        i += 1;
    }
    t
}

/// A complete UBX frame (sync, header, payload, checksum) for `class`/`id`/`payload`; for tests
/// and tools. `payload` longer than 65535 bytes is cut.
pub fn ubx_frame(class: u8, id: u8, payload: &[u8]) -> Vec<u8> {
    let payload = payload.get(..payload.len().min(usize::from(u16::MAX))).unwrap_or(&[]);
    let len = (payload.len() as u16).to_le_bytes();
    let mut f = vec![SYNC1, SYNC2, class, id, len[0], len[1]];
    f.extend_from_slice(payload);
    let (a, b) = ubx_checksum(f.get(2..).unwrap_or(&[]));
    f.extend_from_slice(&[a, b]);
    f
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, PartialEq)]
    enum Got {
        Ubx(u8, u8, Vec<u8>, i64),
        Nmea(String, i64),
        Rtcm3(u16, usize, i64),
    }

    fn run(f: &mut UbxFramer, chunks: &[(&[u8], i64)], ns_per_byte: i64) -> Vec<Got> {
        let mut got = Vec::new();
        for (bytes, t) in chunks {
            f.push(bytes, *t, ns_per_byte, &mut |fr| {
                got.push(match fr {
                    Frame::Ubx {
                        class,
                        id,
                        payload,
                        host_ns,
                    } => Got::Ubx(class, id, payload.to_vec(), host_ns),
                    Frame::Nmea { text, host_ns } => Got::Nmea(String::from_utf8_lossy(text).into_owned(), host_ns),
                    Frame::Rtcm3 {
                        message_type,
                        payload,
                        host_ns,
                    } => Got::Rtcm3(message_type, payload.len(), host_ns),
                })
            });
        }
        got
    }

    fn nmea(body: &str) -> Vec<u8> {
        let sum = body.bytes().fold(0u8, |c, b| c ^ b);
        format!("${body}*{sum:02X}\r\n").into_bytes()
    }

    /// An RTCM3 frame of message type `t` with `n` payload bytes.
    fn rtcm3(t: u16, n: usize) -> Vec<u8> {
        let mut payload = vec![0u8; n.max(2)];
        payload[0] = (t >> 4) as u8;
        payload[1] = ((t & 0xF) << 4) as u8;
        for (i, b) in payload.iter_mut().enumerate().skip(2) {
            *b = (i * 7) as u8;
        }
        let len = payload.len();
        let mut f = vec![0xD3, (len >> 8) as u8, len as u8];
        f.extend_from_slice(&payload);
        let crc = crc24q(&f);
        f.extend_from_slice(&[(crc >> 16) as u8, (crc >> 8) as u8, crc as u8]);
        f
    }

    #[test]
    fn checksums_match_the_references() {
        // UBX-ACK-ACK for CFG-PRT (class 6 id 0): the u-blox manual's example B5 62 05 01 02 00 06 00 0E 37.
        assert_eq!(
            ubx_frame(0x05, 0x01, &[0x06, 0x00]),
            [0xB5, 0x62, 5, 1, 2, 0, 6, 0, 0x0E, 0x37]
        );
        // CRC-24Q check value of "123456789".
        assert_eq!(crc24q(b"123456789"), 0xCD_E703);
    }

    #[test]
    fn frames_are_stamped_at_their_first_byte() {
        let mut f = UbxFramer::new();
        let a = ubx_frame(1, 0x61, &[1, 2, 3, 4]); // 12 bytes
        let b = ubx_frame(1, 0x61, &[5, 6, 7, 8]);
        let mut chunk = a.clone();
        chunk.extend_from_slice(&b);
        let got = run(&mut f, &[(&chunk, 1_000_000)], 100);
        assert_eq!(
            got,
            vec![
                Got::Ubx(1, 0x61, vec![1, 2, 3, 4], 1_000_000 - 23 * 100),
                Got::Ubx(1, 0x61, vec![5, 6, 7, 8], 1_000_000 - 11 * 100),
            ]
        );
        assert_eq!(f.counters().noise_bytes, 0);
    }

    #[test]
    fn frame_split_across_reads_keeps_its_first_read_stamp() {
        let mut f = UbxFramer::new();
        let a = ubx_frame(1, 7, &[9; 92]);
        let (x, y) = a.split_at(5);
        let mut first = b"zz".to_vec();
        first.extend_from_slice(x);
        let got = run(&mut f, &[(&first, 5_000), (y, 9_000)], 10);
        assert_eq!(got, vec![Got::Ubx(1, 7, vec![9; 92], 5_000 - 4 * 10)]);
        assert_eq!(f.counters().noise_bytes, 2);
        // Split at every possible point, one byte per read.
        let mut f = UbxFramer::new();
        let chunks: Vec<(&[u8], i64)> = a
            .iter()
            .enumerate()
            .map(|(i, b)| (core::slice::from_ref(b), i as i64))
            .collect();
        let got = run(&mut f, &chunks, 1);
        assert_eq!(got, vec![Got::Ubx(1, 7, vec![9; 92], 0)]);
    }

    #[test]
    fn garbage_is_skipped_and_resynchronised() {
        let mut f = UbxFramer::new();
        let mut s = vec![0x00, 0xB5, 0x11, 0x62, 0xB5, 0xFF, 0x24, 0xD3, 0xFF];
        s.extend_from_slice(&ubx_frame(1, 3, &[0; 16]));
        let got = run(&mut f, &[(&s, 0)], 0);
        assert_eq!(got, vec![Got::Ubx(1, 3, vec![0; 16], 0)]);
        assert_eq!(f.counters().noise_bytes, 9);
    }

    #[test]
    fn bad_checksum_and_bad_length_do_not_lose_the_next_frame() {
        let mut f = UbxFramer::new();
        let mut bad = ubx_frame(1, 7, &[1; 20]);
        let n = bad.len();
        bad[n - 1] ^= 0xFF;
        // A sync with a huge length, then (inside what it claims) a good frame.
        let mut s = vec![0xB5, 0x62, 1, 2, 0xFF, 0xFF];
        s.extend_from_slice(&bad);
        s.extend_from_slice(&ubx_frame(1, 0x21, &[2; 20]));
        // A corrupt frame claiming 100 bytes, cut off by a good one.
        s.extend_from_slice(&[0xB5, 0x62, 1, 2, 100, 0, 1, 2, 3]);
        s.extend_from_slice(&ubx_frame(1, 0x61, &[3; 4]));
        s.extend_from_slice(&[0; 100]);
        let got = run(&mut f, &[(&s, 0)], 0);
        assert_eq!(
            got,
            vec![Got::Ubx(1, 0x21, vec![2; 20], 0), Got::Ubx(1, 0x61, vec![3; 4], 0)]
        );
        let c = f.counters();
        assert_eq!((c.ubx_bad_length, c.ubx_bad_checksum), (1, 2));
    }

    #[test]
    fn truncated_frame_is_dropped_once_the_rest_arrives() {
        let mut f = UbxFramer::new();
        let a = ubx_frame(1, 7, &[7; 92]);
        let b = ubx_frame(1, 0x61, &[1; 4]);
        let mut s = a[..50].to_vec();
        s.extend_from_slice(&b);
        let got = run(&mut f, &[(&s, 0)], 0);
        assert!(got.is_empty(), "waits for the 100 bytes the header announced");
        // More stream: the truncated candidate fails, the frame inside it is found.
        let got = run(&mut f, &[(&[0u8; 64], 0)], 0);
        assert_eq!(got, vec![Got::Ubx(1, 0x61, vec![1; 4], 0)]);
        assert_eq!(f.counters().ubx_bad_checksum, 1);
    }

    #[test]
    fn nmea_and_rtcm3_are_separated_out() {
        let mut f = UbxFramer::new();
        let mut s = nmea("GNGGA,120000.00,4807.0381,N,01131.0004,E,1,08,0.9,545.4,M,46.9,M,,");
        s.extend_from_slice(&ubx_frame(1, 7, &[1; 92]));
        s.extend_from_slice(&rtcm3(1005, 19));
        s.extend_from_slice(b"$GPTXT,bad*00\r\n");
        s.extend_from_slice(&rtcm3(1077, 200));
        s.extend_from_slice(&nmea("GPZDA,120000.00,01,01,2025,00,00"));
        let got = run(&mut f, &[(&s, 0)], 0);
        assert_eq!(got.len(), 5);
        assert!(matches!(&got[0], Got::Nmea(t, _) if t.starts_with("$GNGGA") && t.ends_with(",,*7C")));
        assert!(matches!(&got[1], Got::Ubx(1, 7, p, _) if p.len() == 92));
        assert_eq!(got[2], Got::Rtcm3(1005, 19, 0));
        assert_eq!(got[3], Got::Rtcm3(1077, 200, 0));
        assert!(matches!(&got[4], Got::Nmea(t, _) if t.starts_with("$GPZDA")));
        let c = f.counters();
        assert_eq!(
            (c.nmea_sentences, c.rtcm3_frames, c.ubx_frames, c.nmea_bad_checksum),
            (2, 2, 1, 1)
        );
        // The bad sentence's bytes (but for CR/LF) are skipped one by one: a `$` in it could
        // start a good sentence.
        assert_eq!(c.noise_bytes, b"$GPTXT,bad*00".len() as u64);
        assert_eq!(c.valid_frames(), 5);
    }

    #[test]
    fn binary_inside_a_sentence_is_not_a_sentence() {
        let mut f = UbxFramer::new();
        let mut s = b"$GPGGA,1".to_vec();
        s.extend_from_slice(&ubx_frame(1, 0x61, &[0; 4]));
        s.extend_from_slice(b"*00\r\n");
        let got = run(&mut f, &[(&s, 0)], 0);
        assert_eq!(got, vec![Got::Ubx(1, 0x61, vec![0; 4], 0)]);
    }

    #[test]
    fn rtcm3_with_bad_crc_is_counted() {
        let mut f = UbxFramer::new();
        let mut r = rtcm3(1005, 19);
        r[10] ^= 1;
        r.extend_from_slice(&ubx_frame(1, 0x61, &[0; 4]));
        let got = run(&mut f, &[(&r, 0)], 0);
        assert_eq!(got, vec![Got::Ubx(1, 0x61, vec![0; 4], 0)]);
        assert_eq!(f.counters().rtcm3_bad_crc, 1);
    }

    #[test]
    fn largest_frame_fits_and_reset_drops_partial_frames() {
        let mut f = UbxFramer::new();
        let big = ubx_frame(2, 0x15, &vec![0x55; MAX_UBX_PAYLOAD]);
        let got = run(&mut f, &[(&big[..4000], 0), (&big[4000..], 0)], 0);
        assert!(matches!(&got[..], [Got::Ubx(2, 0x15, p, 0)] if p.len() == MAX_UBX_PAYLOAD));
        let got = run(&mut f, &[(&big[..4000], 0)], 0);
        assert!(got.is_empty());
        f.reset();
        let got = run(&mut f, &[(&big[4000..], 0), (&ubx_frame(1, 0x61, &[0; 4]), 0)], 0);
        assert_eq!(got, vec![Got::Ubx(1, 0x61, vec![0; 4], 0)]);
    }

    #[test]
    fn random_bytes_never_panic() {
        let mut f = UbxFramer::new();
        let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
        let mut chunk = [0u8; 61];
        let alphabet = [0xB5, 0x62, 0xD3, b'$', b'*', b'\r', b'\n', 0, 1, 2];
        let mut n = 0u64;
        for round in 0..20_000 {
            for b in chunk.iter_mut() {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                *b = if x.is_multiple_of(3) {
                    alphabet[(x >> 8) as usize % alphabet.len()]
                } else {
                    (x >> 24) as u8
                };
            }
            f.push(&chunk, round, 1, &mut |_| n += 1);
        }
        assert_eq!(n, f.counters().valid_frames());
        assert_eq!(f.counters().bytes, 20_000 * 61);
    }
}
