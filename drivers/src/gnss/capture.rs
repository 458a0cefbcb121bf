//! Offline decoding of a recorded receiver capture, exactly as the live driver decodes a
//! port (through the same [`Decoder`]).
//!
//! Used by `navsync decode FILE|-` (one JSON object per epoch) and by the gpsd conformance
//! tests. Lines starting with `#` are gpsd log comments (receiver name, location), not
//! receiver output, and are skipped; a `# Delay-Cookie: <c> …` header makes `<c>` a read
//! boundary rather than data, as gpsd's test player `gpsfake` treats it. In a text (NMEA)
//! capture every such line is a comment; in a binary one (`ubx`, `auto`) only the leading
//! ones are (gpsfake skips the header, then frames the rest), since a `#` after a newline
//! byte inside a binary message is data.

use navsync_shared::samples::{FIX_GEOID_MODEL, FixMode, GnssFix};
use navsync_shared::time::format_rfc3339_ms;
use serde_json::{Map, Value};

use super::nmea::NmeaDecoder;
use super::ubx::UbxDecoder;
use super::{Decoder, GnssDecoder, GnssExtra, Protocol};

/// Bytes per replayed read of a binary capture (a serial driver's typical read).
pub const REPLAY_READ_BYTES: usize = 64;

/// Line rate assumed when replaying a capture: 9600 Bd, 10 bits per character, so that
/// replayed stamps are spaced as on a real serial line (`host_ns` = byte offset × this).
pub const REPLAY_NS_PER_BYTE: i64 = 1_000_000_000 * 10 / 9600;

/// A decoded capture.
#[derive(Debug, Clone)]
pub struct Capture {
    /// The fixes, one per epoch, in order (what `navsync/gnss/{id}/fix` would carry).
    pub fixes: Vec<GnssFix>,
    /// The receiver's high-rate fused fixes (UBX HNR-PVT), in order: what
    /// `navsync/gnss/{id}/hnr` would carry.
    pub hnr: Vec<GnssFix>,
    /// The decoder after the whole capture (its counters: framing, checks, epochs).
    pub decoder: Decoder,
    /// `#` comment lines skipped.
    pub comment_lines: u64,
}

impl Capture {
    /// The NMEA decoder, when the capture was decoded as NMEA (or `auto`: the decoder of the
    /// port's NMEA sentences).
    pub fn nmea(&self) -> Option<&NmeaDecoder> {
        match &self.decoder {
            Decoder::Nmea(d) => Some(d),
            Decoder::Auto(d) => Some(d.nmea()),
            // Another protocol has no NMEA decoder.
            _ => None,
        }
    }

    /// The UBX decoder, when the capture was decoded as `ubx` or `auto`.
    pub fn ubx(&self) -> Option<&UbxDecoder> {
        match &self.decoder {
            Decoder::Ubx(d) => Some(d),
            Decoder::Auto(d) => Some(d.ubx()),
            // Another protocol has no UBX decoder.
            _ => None,
        }
    }

    /// The decoder's counters by name.
    pub fn counters(&self) -> Vec<(&'static str, u64)> {
        let mut v = Vec::new();
        self.decoder.each_counter(&mut |n, c| v.push((n, c)));
        v.push(("comment_lines", self.comment_lines));
        v
    }
}

/// Decodes a whole capture as `protocol`, stamped as if the capture had arrived at
/// [`REPLAY_NS_PER_BYTE`] from host time 0 (each byte's stamp is that of its arrival,
/// however the capture is cut into reads); the decoder is flushed at the end, as the live
/// driver does when the line goes idle.
///
/// NMEA: every line not starting with `#` (split at the delay cookie, if the log declares
/// one) goes through the [`Decoder`] as one read. `ubx`/`auto`: after the leading `#` lines,
/// the bytes go through in reads of [`REPLAY_READ_BYTES`].
pub fn decode_capture(bytes: &[u8], protocol: Protocol) -> Capture {
    if protocol != Protocol::Nmea {
        return decode_binary(bytes, protocol);
    }
    let mut decoder = Decoder::new(protocol);
    let mut fixes = Vec::new();
    let mut comment_lines = 0;
    let mut cookie = None;
    let mut offset = 0usize;
    for line in bytes.split_inclusive(|&b| b == b'\n') {
        if line.first() == Some(&b'#') {
            offset += line.len();
            comment_lines += 1;
            cookie = cookie.or_else(|| delay_cookie(line));
            continue;
        }
        // Between delay cookies gpsfake writes separately: replay them as separate reads.
        for chunk in line.split(|&b| Some(b) == cookie) {
            offset += chunk.len();
            let read_ns = i64::try_from(offset)
                .unwrap_or(i64::MAX)
                .saturating_mul(REPLAY_NS_PER_BYTE);
            decoder.push(chunk, read_ns, REPLAY_NS_PER_BYTE, &mut |fix| fixes.push(*fix));
        }
    }
    decoder.flush(&mut |fix| fixes.push(*fix));
    Capture {
        fixes,
        hnr: Vec::new(),
        decoder,
        comment_lines,
    }
}

/// The leading gpsd header of a binary capture (its `#` comment lines, not receiver output):
/// its length in bytes and lines.
pub fn gpsd_header(bytes: &[u8]) -> (usize, u64) {
    let (mut len, mut lines) = (0usize, 0u64);
    while bytes.get(len) == Some(&b'#') {
        let rest = bytes.get(len..).unwrap_or(&[]);
        len += rest.iter().position(|&b| b == b'\n').map_or(rest.len(), |i| i + 1);
        lines += 1;
    }
    (len, lines)
}

/// [`decode_capture`] of a binary capture: the leading `#` lines are gpsd's header.
fn decode_binary(bytes: &[u8], protocol: Protocol) -> Capture {
    let mut decoder = Decoder::new(protocol);
    let mut fixes = Vec::new();
    let mut hnr = Vec::new();
    let (mut offset, comment_lines) = gpsd_header(bytes);
    // A delay cookie declared in the header is a write boundary, not data, in a binary
    // capture too (gpsfake splits the whole log at it).
    let cookie = bytes
        .get(..offset)
        .unwrap_or(&[])
        .split_inclusive(|&b| b == b'\n')
        .find_map(delay_cookie);
    let rest = bytes.get(offset..).unwrap_or(&[]);
    let pieces: Vec<&[u8]> = match cookie {
        Some(c) => rest.split(|&b| b == c).collect(),
        None => vec![rest],
    };
    for chunk in pieces.iter().flat_map(|p| p.chunks(REPLAY_READ_BYTES)) {
        offset += chunk.len();
        let read_ns = i64::try_from(offset)
            .unwrap_or(i64::MAX)
            .saturating_mul(REPLAY_NS_PER_BYTE);
        decoder.push_extras(
            chunk,
            read_ns,
            REPLAY_NS_PER_BYTE,
            &mut |fix| fixes.push(*fix),
            &mut |x| {
                if let GnssExtra::Hnr(h) = x {
                    hnr.push(*h);
                }
            },
        );
    }
    decoder.flush(&mut |fix| fixes.push(*fix));
    Capture {
        fixes,
        hnr,
        decoder,
        comment_lines,
    }
}

/// What the bytes of a capture are, whatever protocol it was decoded as: for the message of
/// `navsync decode` when nothing decoded.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Seen {
    /// UBX frames whose checksum passed.
    pub ubx_frames: u64,
    /// Of those, navigation solutions (NAV-PVT, NAV-SOL, NAV-POSLLH, HNR-PVT).
    pub ubx_solutions: u64,
    /// NMEA sentences whose checksum passed.
    pub nmea_sentences: u64,
    /// RTCM3 frames whose CRC passed.
    pub rtcm3_frames: u64,
    /// Bytes in none of these.
    pub noise_bytes: u64,
}

impl Seen {
    /// The bytes after gpsd's leading header, framed as a u-blox port (UBX, NMEA, RTCM3).
    pub fn of(bytes: &[u8]) -> Self {
        use super::ubx::framer::{Frame, UbxFramer};
        use super::ubx::messages::{Message, decode};
        let (header, _) = gpsd_header(bytes);
        let mut framer = UbxFramer::new();
        let mut solutions = 0;
        framer.push(bytes.get(header..).unwrap_or(&[]), 0, 0, &mut |f| {
            if let Frame::Ubx { class, id, payload, .. } = f
                && matches!(
                    decode(class, id, payload),
                    Ok(Message::NavPvt(_) | Message::NavSol(_) | Message::NavPosllh(_) | Message::HnrPvt(_))
                )
            {
                solutions += 1;
            }
        });
        let c = framer.counters();
        Self {
            ubx_frames: c.ubx_frames,
            ubx_solutions: solutions,
            nmea_sentences: c.nmea_sentences,
            rtcm3_frames: c.rtcm3_frames,
            noise_bytes: c.noise_bytes,
        }
    }

    /// The protocol the bytes say they are: `ubx` (shown as `auto`, which also takes the NMEA
    /// of the port) when they carry UBX navigation, `nmea` when they carry NMEA sentences;
    /// `None` when neither.
    pub fn protocol(&self) -> Option<Protocol> {
        if self.ubx_solutions > 0 {
            Some(Protocol::Auto)
        } else if self.nmea_sentences > 0 {
            Some(Protocol::Nmea)
        } else {
            None
        }
    }

    /// Why `protocol` decoded no epoch from these bytes, and what to do.
    pub fn explain(&self, protocol: Protocol) -> String {
        let what = format!(
            "seen {} UBX frames ({} navigation solutions), {} NMEA sentences, {} RTCM3 frames, {} bytes of neither",
            self.ubx_frames, self.ubx_solutions, self.nmea_sentences, self.rtcm3_frames, self.noise_bytes
        );
        let hint = match (self.protocol(), protocol) {
            (Some(Protocol::Auto), Protocol::Nmea) => {
                "the capture is u-blox UBX: use --protocol auto (the default) or ubx".to_owned()
            }
            (Some(Protocol::Nmea), Protocol::Ubx) => {
                "the capture is NMEA without UBX navigation: use --protocol auto (the default) or nmea".to_owned()
            }
            (Some(_), _) => "the messages carry no epoch with data (no fix, no time)".to_owned(),
            (None, _) if self.ubx_frames > 0 => {
                "its UBX frames carry no navigation solution (NAV-PVT, NAV-SOL, NAV-POSLLH, HNR-PVT)".to_owned()
            }
            (None, _) => "no receiver protocol recognised: not receiver output, or a wrong line rate".to_owned(),
        };
        format!("{what}; {hint}")
    }
}

/// The write-boundary character declared by a gpsd log header `# Delay-Cookie: <c> <s>`:
/// gpsfake splits the following data at `<c>` (dropping it) and pauses `<s>` seconds between
/// the pieces, so `<c>` is not receiver output.
fn delay_cookie(comment: &[u8]) -> Option<u8> {
    let text = core::str::from_utf8(comment).ok()?;
    let rest = text
        .trim_start_matches('#')
        .trim_start()
        .strip_prefix("Delay-Cookie:")?;
    match rest.trim_start().as_bytes() {
        [c, ..] if !c.is_ascii_whitespace() => Some(*c),
        _ => None,
    }
}

/// A float as JSON, `null` when not known (NaN).
fn num(v: f64) -> Value {
    serde_json::Number::from_f64(v).map_or(Value::Null, Value::Number)
}

/// One epoch as a JSON object: `time` (RFC 3339 UTC with milliseconds, as gpsd prints it;
/// the decoders put UBX epochs on their millisecond already), `lat`/`lon` (degrees), `alt_msl`
/// (m above mean sea level) with `alt_msl_source` (`receiver`, or `egm96` where the receiver
/// reported only an ellipsoidal height), `alt_hae` (m above the WGS-84 ellipsoid, the
/// receiver's), `speed_mps`, `track_deg` (degrees true), `mode` (0 unknown, 1 no fix, 2 2D,
/// 3 3D), `sats_used`, `hdop`; `null` where the epoch had no such field.
pub fn epoch_json(fix: &GnssFix) -> Value {
    let mut m = Map::new();
    let time = if fix.utc_ns == i64::MIN {
        Value::Null
    } else {
        Value::String(format_rfc3339_ms(fix.utc_ns))
    };
    m.insert("time".into(), time);
    m.insert("lat".into(), num(fix.lat_deg));
    m.insert("lon".into(), num(fix.lon_deg));
    m.insert("alt_msl".into(), num(fix.alt_msl_m));
    // The ellipsoidal height is the receiver's; where the receiver sent no height above sea
    // level, `alt_msl` is navsync's geoid model's, and `alt_msl_source` says so.
    m.insert(
        "alt_hae".into(),
        num(if fix.alt_msl_m.is_finite() {
            fix.height_m()
        } else {
            f64::NAN
        }),
    );
    if fix.alt_msl_m.is_finite() {
        let source = if fix.sentences & FIX_GEOID_MODEL != 0 {
            "egm96"
        } else {
            "receiver"
        };
        m.insert("alt_msl_source".into(), Value::from(source));
    }
    m.insert("speed_mps".into(), num(fix.speed_mps));
    m.insert("track_deg".into(), num(fix.track_deg));
    let mode = if fix.mode <= FixMode::Fix3d as u8 {
        fix.mode
    } else {
        FixMode::Unknown as u8
    };
    m.insert("mode".into(), Value::from(mode));
    let sats = if fix.sats_used == u16::MAX {
        Value::Null
    } else {
        Value::from(fix.sats_used)
    };
    m.insert("sats_used".into(), sats);
    m.insert("hdop".into(), num(fix.hdop));
    // The receiver's own accuracy estimates, where its protocol reports them (UBX).
    for (key, v) in [
        ("h_acc_m", fix.h_acc_m),
        ("v_acc_m", fix.v_acc_m),
        ("s_acc_mps", fix.s_acc_mps),
        ("vel_d_mps", fix.vel_d_mps),
    ] {
        if v.is_finite() {
            m.insert(key.into(), num(v));
        }
    }
    Value::Object(m)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn comments_are_skipped_and_json_has_nulls() {
        let cap = b"# Name: test\n$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47\r\n";
        let c = decode_capture(cap, Protocol::Nmea);
        let fixes = &c.fixes;
        assert_eq!(c.comment_lines, 1);
        assert_eq!(c.nmea().unwrap().counters().framer.noise_bytes, 0);
        assert_eq!(fixes.len(), 1);
        let j = epoch_json(&fixes[0]);
        assert_eq!(j["time"], Value::Null, "no date sentence yet");
        assert_eq!(j["mode"], 3);
        assert_eq!(j["sats_used"], 8);
        assert_eq!(j["speed_mps"], Value::Null);
        assert!((j["lat"].as_f64().unwrap_or(0.0) - 48.1173).abs() < 1e-9);
        assert!((j["alt_msl"].as_f64().unwrap_or(0.0) - 545.4).abs() < 1e-9);
        // The `$` is byte 13 of the file (0-based); byte k has fully arrived k + 1 character
        // times after the replay started.
        assert_eq!(fixes[0].stamp.host_ns, 14 * REPLAY_NS_PER_BYTE);
    }

    #[test]
    fn delay_cookie_splits_reads_and_is_not_data() {
        let cap = b"# Delay-Cookie: | 0.01\n$GPGGA,|12351|9,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47\n";
        for protocol in [Protocol::Nmea, Protocol::Auto] {
            let c = decode_capture(cap, protocol);
            let fixes = &c.fixes;
            assert_eq!(c.nmea().unwrap().counters().epochs.bad_checksum, 0, "{protocol}");
            assert_eq!(fixes.len(), 1);
            assert_eq!(fixes[0].alt_msl_m, 545.4, "{protocol}: the cookie is not data");
        }
        assert_eq!(delay_cookie(b"# Date: 2013-11-03\n"), None);
    }

    #[test]
    fn binary_capture_skips_only_the_leading_comments() {
        use crate::gnss::ubx::framer::ubx_frame;
        use navsync_shared::samples::UBX_MSG_NAV_EOE;
        let mut cap = b"# Name: test\n# more\n".to_vec();
        let header = cap.len();
        // NAV-TIMEGPS and NAV-EOE of iTOW 8970 ms, whose bytes start with "\n#": data, not a
        // comment. Week 2048, 18 leap seconds, all valid.
        let itow = [b'\n', b'#', 0, 0];
        let mut timegps = itow.to_vec();
        timegps.extend([0, 0, 0, 0, 0x00, 0x08, 18, 0x07, 0, 0, 0, 0]);
        cap.extend(ubx_frame(1, 0x20, &timegps));
        cap.extend(ubx_frame(1, 0x61, &itow));
        for protocol in [Protocol::Ubx, Protocol::Auto] {
            let c = decode_capture(&cap, protocol);
            assert_eq!(c.comment_lines, 2);
            assert_eq!(c.ubx().map(|u| u.counters().framer.noise_bytes), Some(0));
            assert_eq!(c.fixes.len(), 1);
            assert_eq!(c.fixes[0].stamp.host_ns, (header as i64 + 1) * REPLAY_NS_PER_BYTE);
            assert_ne!(c.fixes[0].sentences & UBX_MSG_NAV_EOE, 0);
            assert_eq!(format_rfc3339_ms(c.fixes[0].utc_ns), "2019-04-06T23:59:50.970Z");
        }
        assert!(decode_capture(&cap, Protocol::Ubx).nmea().is_none());
        assert!(decode_capture(&cap, Protocol::Auto).nmea().is_some());
    }

    #[test]
    fn json_time_is_rfc3339_ms() {
        let cap = b"$GPRMC,225446.33,A,4916.45,N,12311.12,W,000.5,054.7,191194,020.3,E*46\r\n";
        let fixes = decode_capture(cap, Protocol::Nmea).fixes;
        assert_eq!(fixes.len(), 1);
        let j = epoch_json(&fixes[0]);
        assert_eq!(j["time"], "1994-11-19T22:54:46.330Z");
        assert_eq!(j["mode"], 2);
        assert!((j["speed_mps"].as_f64().unwrap_or(0.0) - 0.5 * 1852.0 / 3600.0).abs() < 1e-12);
        assert_eq!(j["track_deg"], 54.7);
    }
    #[test]
    fn a_ubx_capture_decoded_as_nmea_says_what_it_is() {
        use crate::gnss::ubx::framer::ubx_frame;
        use crate::gnss::ubx::nav::tests::pvt_at;
        let mut cap = b"# u-blox\n".to_vec();
        for k in 1..=3u32 {
            cap.extend(ubx_frame(1, 7, &pvt_at(k * 1000, 3, 1)));
        }
        assert!(decode_capture(&cap, Protocol::Nmea).fixes.is_empty());
        let seen = Seen::of(&cap);
        assert_eq!((seen.ubx_frames, seen.ubx_solutions, seen.nmea_sentences), (3, 3, 0));
        assert_eq!(seen.protocol(), Some(Protocol::Auto));
        let why = seen.explain(Protocol::Nmea);
        assert!(
            why.contains("3 UBX frames (3 navigation solutions)") && why.contains("--protocol auto"),
            "{why}"
        );
        // The default protocol decodes it.
        assert_eq!(decode_capture(&cap, Protocol::default()).fixes.len(), 3);
        // Noise says so.
        let why = Seen::of(b"\x01\x02\x03").explain(Protocol::Auto);
        assert!(why.contains("no receiver protocol recognised"), "{why}");
        let nmea = b"$GPRMC,225446.33,A,4916.45,N,12311.12,W,000.5,054.7,191194,020.3,E*46\r\n";
        assert_eq!(Seen::of(nmea).protocol(), Some(Protocol::Nmea));
        assert!(Seen::of(nmea).explain(Protocol::Ubx).contains("--protocol auto"));
    }
}
