//! NMEA 0183 sentence generation for the simulated receiver: RMC, VTG, GGA, GSA, GST, ZDA
//! (NMEA 0183 v4.10 field layouts without the optional v4.10 system-id fields), full
//! precision: latitude/longitude as ddmm.mmmmmmm (1e-7 arc-minute ≈ 0.2 mm), altitude in mm,
//! speed in knots and km/h with 4 decimals, time tags hhmmss.ss. At full precision GGA and RMC
//! can exceed NMEA's nominal 82 characters (like u-blox high-precision output); they stay
//! within 100, below the `nmea` crate's 102-character limit. Every sentence ends with
//! `*hh` (XOR of the bytes between `$` and `*`, upper-case hex) and CR LF.

use std::fmt::Write as _;

use navsync_shared::time::civil_from_utc_ns;

/// Knots per m/s (1 kn = 1852 m/h).
pub const KNOTS_PER_MPS: f64 = 3600.0 / 1852.0;

/// What one epoch reports when the receiver has a fix.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FixReport {
    /// Latitude, degrees north.
    pub lat_deg: f64,
    /// Longitude, degrees east.
    pub lon_deg: f64,
    /// Altitude above mean sea level, m.
    pub alt_msl_m: f64,
    /// Geoid separation (ellipsoid − MSL), m.
    pub geoid_sep_m: f64,
    /// Velocity north, m/s.
    pub vel_n_mps: f64,
    /// Velocity east, m/s.
    pub vel_e_mps: f64,
    /// Velocity down, m/s (UBX reports it; NMEA does not).
    pub vel_d_mps: f64,
}

/// Everything the sentences of one epoch carry.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EpochReport {
    /// Epoch time, UTC ns since 1970.
    pub utc_ns: i64,
    /// The fix, `None` during an outage.
    pub fix: Option<FixReport>,
    /// Satellites used.
    pub sats_used: u8,
    /// Dilutions of precision (HDOP, VDOP).
    pub hdop: f64,
    /// Vertical DOP.
    pub vdop: f64,
    /// 1-σ latitude, longitude, altitude errors reported by GST, m.
    pub sigma_lat_lon_alt_m: [f64; 3],
}

/// Appends the burst of one epoch (RMC, VTG, GGA, GSA, GST, ZDA) to `out`.
pub fn write_burst(talker: &str, e: &EpochReport, out: &mut Vec<u8>) {
    let c = civil_from_utc_ns(e.utc_ns);
    let time = format!(
        "{:02}{:02}{:02}.{:02}",
        c.hour,
        c.minute,
        c.second,
        c.nanos / 10_000_000
    );
    let date = format!("{:02}{:02}{:02}", c.day, c.month, c.year.rem_euclid(100));
    let mut body = String::with_capacity(96);
    for kind in [
        Sentence::Rmc,
        Sentence::Vtg,
        Sentence::Gga,
        Sentence::Gsa,
        Sentence::Gst,
        Sentence::Zda,
    ] {
        body.clear();
        let _ = write!(body, "{talker}");
        match kind {
            Sentence::Rmc => rmc(&mut body, &time, &date, e),
            Sentence::Vtg => vtg(&mut body, e),
            Sentence::Gga => gga(&mut body, &time, e),
            Sentence::Gsa => gsa(&mut body, e),
            Sentence::Gst => gst(&mut body, &time, e),
            Sentence::Zda => {
                let _ = write!(body, "ZDA,{time},{:02},{:02},{:04},00,00", c.day, c.month, c.year);
            }
        }
        frame(&body, out);
    }
}

#[derive(Clone, Copy)]
enum Sentence {
    Rmc,
    Vtg,
    Gga,
    Gsa,
    Gst,
    Zda,
}

/// Frames `body` (talker + type + fields) as `$body*hh\r\n`.
pub fn frame(body: &str, out: &mut Vec<u8>) {
    out.push(b'$');
    out.extend_from_slice(body.as_bytes());
    let cs = checksum(body.as_bytes());
    out.push(b'*');
    out.extend_from_slice(format!("{cs:02X}").as_bytes());
    out.extend_from_slice(b"\r\n");
}

/// XOR of all bytes (the NMEA checksum of the text between `$` and `*`).
pub fn checksum(body: &[u8]) -> u8 {
    body.iter().fold(0, |a, b| a ^ b)
}

/// Speed over ground, m/s, and course over ground, degrees in [0, 360).
fn speed_course(f: &FixReport) -> (f64, f64) {
    let speed = f.vel_n_mps.hypot(f.vel_e_mps);
    let course = f.vel_e_mps.atan2(f.vel_n_mps).to_degrees().rem_euclid(360.0);
    // rem_euclid can return 360.0 for tiny negative inputs; 4-decimal printing needs < 360.
    (speed, if course >= 359.999_95 { 0.0 } else { course })
}

fn rmc(s: &mut String, time: &str, date: &str, e: &EpochReport) {
    match &e.fix {
        Some(f) => {
            let (speed, course) = speed_course(f);
            let _ = write!(
                s,
                "RMC,{time},A,{},{},{:.4},{:.4},{date},,,A",
                format_lat(f.lat_deg),
                format_lon(f.lon_deg),
                speed * KNOTS_PER_MPS,
                course
            );
        }
        None => {
            let _ = write!(s, "RMC,{time},V,,,,,,,{date},,,N");
        }
    }
}

fn vtg(s: &mut String, e: &EpochReport) {
    match &e.fix {
        Some(f) => {
            let (speed, course) = speed_course(f);
            let _ = write!(
                s,
                "VTG,{course:.4},T,,M,{:.4},N,{:.4},K,A",
                speed * KNOTS_PER_MPS,
                speed * 3.6
            );
        }
        None => {
            let _ = write!(s, "VTG,,T,,M,,N,,K,N");
        }
    }
}

fn gga(s: &mut String, time: &str, e: &EpochReport) {
    match &e.fix {
        Some(f) => {
            let _ = write!(
                s,
                "GGA,{time},{},{},1,{:02},{:.2},{:.3},M,{:.3},M,,",
                format_lat(f.lat_deg),
                format_lon(f.lon_deg),
                e.sats_used,
                e.hdop,
                f.alt_msl_m,
                f.geoid_sep_m
            );
        }
        None => {
            let _ = write!(s, "GGA,{time},,,,,0,00,99.99,,M,,M,,");
        }
    }
}

fn gsa(s: &mut String, e: &EpochReport) {
    match &e.fix {
        Some(_) => {
            let _ = write!(s, "GSA,A,3");
            for prn in 1..=12u8 {
                if prn <= e.sats_used {
                    let _ = write!(s, ",{:02}", 2 * prn);
                } else {
                    s.push(',');
                }
            }
            let pdop = e.hdop.hypot(e.vdop);
            let _ = write!(s, ",{pdop:.2},{:.2},{:.2}", e.hdop, e.vdop);
        }
        None => {
            let _ = write!(s, "GSA,A,1,,,,,,,,,,,,,99.99,99.99,99.99");
        }
    }
}

fn gst(s: &mut String, time: &str, e: &EpochReport) {
    match &e.fix {
        Some(_) => {
            let [sn, se, sd] = e.sigma_lat_lon_alt_m;
            let rms = sn.hypot(se);
            let (major, minor) = (sn.max(se), sn.min(se));
            let orient = if se > sn { 90.0 } else { 0.0 };
            let _ = write!(
                s,
                "GST,{time},{rms:.3},{major:.3},{minor:.3},{orient:.1},{sn:.3},{se:.3},{sd:.3}"
            );
        }
        None => {
            let _ = write!(s, "GST,{time},,,,,,,");
        }
    }
}

/// Latitude as `ddmm.mmmmmmm,N|S` (exact rounding to 1e-7 arc-minute, no 60-minute carry).
pub fn format_lat(lat_deg: f64) -> String {
    let (d, m, frac) = split_minutes(lat_deg.abs());
    format!("{d:02}{m:02}.{frac:07},{}", if lat_deg < 0.0 { 'S' } else { 'N' })
}

/// Longitude as `dddmm.mmmmmmm,E|W`.
pub fn format_lon(lon_deg: f64) -> String {
    let (d, m, frac) = split_minutes(lon_deg.abs());
    format!("{d:03}{m:02}.{frac:07},{}", if lon_deg < 0.0 { 'W' } else { 'E' })
}

/// Whole degrees, whole minutes and 1e-7 minutes of a non-negative angle in degrees.
fn split_minutes(deg: f64) -> (u64, u64, u64) {
    let units = (deg * 60.0 * 1e7).round() as u64;
    let per_deg = 60 * 10_000_000;
    (units / per_deg, units % per_deg / 10_000_000, units % 10_000_000)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// Splits a burst into sentences, checking framing and checksums; returns the fields of
    /// each sentence (first field = talker + type).
    pub(crate) fn parse_burst(bytes: &[u8]) -> Vec<Vec<String>> {
        let text = std::str::from_utf8(bytes).expect("ASCII");
        assert!(text.ends_with("\r\n"));
        text.split_terminator("\r\n")
            .map(|line| {
                assert!(line.starts_with('$'), "{line}");
                let (body, cs) = line[1..].rsplit_once('*').expect("checksum");
                assert_eq!(
                    u8::from_str_radix(cs, 16).expect("hex"),
                    checksum(body.as_bytes()),
                    "{line}"
                );
                assert_eq!(cs.len(), 2);
                // Full precision exceeds NMEA's nominal 82 characters (as u-blox high-precision
                // mode does); the `nmea` crate accepts up to 102.
                assert!(line.len() <= 100, "sentence too long: {line}");
                nmea::parse_str(line).unwrap_or_else(|e| panic!("nmea crate rejects {line}: {e:?}"));
                body.split(',').map(str::to_owned).collect()
            })
            .collect()
    }

    /// Parses `ddmm.mmmmmmm` + hemisphere back to degrees.
    pub(crate) fn parse_angle(v: &str, hemi: &str, deg_digits: usize) -> f64 {
        let d: f64 = v[..deg_digits].parse().expect("deg");
        let m: f64 = v[deg_digits..].parse().expect("min");
        let a = d + m / 60.0;
        if hemi == "S" || hemi == "W" { -a } else { a }
    }

    #[test]
    fn known_checksum() {
        // A classic example sentence with a published checksum.
        let body = "GPGGA,092750.000,5321.6802,N,00630.3372,W,1,8,1.03,61.7,M,55.2,M,,";
        assert_eq!(checksum(body.as_bytes()), 0x76);
    }

    #[test]
    fn angle_formatting_round_trips_and_never_carries() {
        assert_eq!(format_lat(47.5), "4730.0000000,N");
        assert_eq!(format_lon(-8.25), "00815.0000000,W");
        assert_eq!(format_lat(12.999_999_999_999), "1300.0000000,N");
        for x in [0.0, 1e-9, 33.123_456_789, 89.999_999_99, 47.397_742_123] {
            let s = format_lat(x);
            let (v, h) = s.split_once(',').expect("comma");
            // Resolution 1e-7 arc-minute: half of it is the rounding bound.
            assert!((parse_angle(v, h, 2) - x).abs() <= 0.5e-7 / 60.0 + 1e-14, "{x} {s}");
        }
    }

    #[test]
    fn burst_with_fix_and_without() {
        let fix = FixReport {
            lat_deg: 48.1,
            lon_deg: 11.6,
            alt_msl_m: 512.3456,
            geoid_sep_m: 47.0,
            vel_n_mps: 3.0,
            vel_e_mps: -4.0,
            vel_d_mps: 0.0,
        };
        let utc = navsync_shared::time::utc_ns_from_civil(&navsync_shared::time::Civil {
            year: 2026,
            month: 3,
            day: 9,
            hour: 14,
            minute: 5,
            second: 7,
            nanos: 100_000_000,
        });
        let mut e = EpochReport {
            utc_ns: utc,
            fix: Some(fix),
            sats_used: 12,
            hdop: 0.8,
            vdop: 1.2,
            sigma_lat_lon_alt_m: [1.06, 1.06, 3.0],
        };
        let mut out = Vec::new();
        write_burst("GN", &e, &mut out);
        let s = parse_burst(&out);
        let types: Vec<&str> = s.iter().map(|f| f[0].as_str()).collect();
        assert_eq!(types, ["GNRMC", "GNVTG", "GNGGA", "GNGSA", "GNGST", "GNZDA"]);
        assert_eq!(s[0][1], "140507.10");
        assert_eq!(s[0][9], "090326");
        assert_eq!(s[0][7], format!("{:.4}", 5.0 * KNOTS_PER_MPS));
        assert!((s[0][8].parse::<f64>().expect("course") - (360.0 - 53.130_102_354)).abs() < 1e-4);
        assert_eq!(s[2][6], "1");
        assert_eq!(s[2][9], "512.346");
        assert_eq!(s[4][8], "3.000");
        assert_eq!(&s[5][2..5], ["09", "03", "2026"]);
        e.fix = None;
        out.clear();
        write_burst("GP", &e, &mut out);
        let s = parse_burst(&out);
        assert_eq!(s[0][0], "GPRMC");
        assert_eq!(s[0][2], "V");
        assert_eq!(s[2][6], "0");
        assert!(s[2][2].is_empty());
        assert_eq!(s[3][2], "1");
    }
}
