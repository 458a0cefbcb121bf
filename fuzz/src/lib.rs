//! Input formats and checks shared by the fuzz targets.
//!
//! The IIO targets take a device description in text, as the driver reads it from sysfs, then
//! (after the first empty line) binary records:
//!
//! ```text
//! # comment
//! anglvel_x 1 be:s32/32>>0 0.0001          <name> <index> <type> [<scale> [<offset>]]
//! timestamp 8 le:s64/64>>0
//!
//! <records: any bytes>
//! ```
//!
//! `<type>` is the `in_<name>_type` attribute, `<scale>`/`<offset>` the `in_<name>_scale` /
//! `_offset` attributes (default 1 and 0).

/// One description line.
#[derive(Debug, Clone, PartialEq)]
pub struct IioLine<'a> {
    /// The whole line, trimmed.
    pub text: &'a str,
    /// Channel name.
    pub name: &'a str,
    /// `_index` text.
    pub index: &'a str,
    /// `_type` text.
    pub ty: &'a str,
    /// `_scale` text, if given.
    pub scale: Option<&'a str>,
    /// `_offset` text, if given.
    pub offset: Option<&'a str>,
}

/// Splits an IIO input into its description lines (comments and blank-free lines only; lines
/// that are not UTF-8 are skipped) and the record bytes after the first empty line.
pub fn split_iio(data: &[u8]) -> (Vec<IioLine<'_>>, &[u8]) {
    let (head, records) = match data.windows(2).position(|w| w == b"\n\n") {
        Some(p) => (&data[..p], &data[p + 2..]),
        None => (data, &data[data.len()..]),
    };
    let lines = head
        .split(|&b| b == b'\n')
        .filter_map(|l| core::str::from_utf8(l).ok())
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .map(|text| {
            let mut w = text.split_ascii_whitespace();
            IioLine {
                text,
                name: w.next().unwrap_or(""),
                index: w.next().unwrap_or(""),
                ty: w.next().unwrap_or(""),
                scale: w.next(),
                offset: w.next(),
            }
        })
        .collect();
    (lines, records)
}

/// What every emitted fix must satisfy, whatever the protocol: mode 0..=3, |lat| ≤ 90°,
/// |lon| ≤ 180°, no infinite value (NaN is "not reported").
pub fn check_fix_plausible(f: &navsync_shared::samples::GnssFix) {
    use navsync_shared::samples::FixMode;
    assert!(f.mode <= FixMode::Fix3d as u8, "mode {}", f.mode);
    assert!(f.lat_deg.is_nan() || f.lat_deg.abs() <= 90.0, "lat {}", f.lat_deg);
    assert!(f.lon_deg.is_nan() || f.lon_deg.abs() <= 180.0, "lon {}", f.lon_deg);
    for (name, v) in [
        ("lat", f.lat_deg),
        ("lon", f.lon_deg),
        ("alt", f.alt_msl_m),
        ("geoid", f.geoid_sep_m),
        ("vel_n", f.vel_n_mps),
        ("vel_e", f.vel_e_mps),
        ("vel_d", f.vel_d_mps),
        ("speed", f.speed_mps),
        ("track", f.track_deg),
        ("hdop", f.hdop),
        ("vdop", f.vdop),
        ("pdop", f.pdop),
        ("h_acc", f.h_acc_m),
        ("v_acc", f.v_acc_m),
        ("s_acc", f.s_acc_mps),
        ("std_lat", f.std_lat_m),
        ("std_lon", f.std_lon_m),
        ("std_alt", f.std_alt_m),
    ] {
        assert!(!v.is_infinite(), "{name} is {v}");
    }
}

/// The epoch properties of one output of a receiver (the fixes of `navsync/gnss/{id}/fix`, or
/// the HNR-PVT fixes of `…/hnr`), as `drivers/tests/conformance/epoch_properties.rs` states them: each
/// timed epoch is after the one before (so none is published twice) except where the decoder
/// counted a reset of the receiver's time line (`resets`: the `*_time_resets` counters). On
/// arbitrary input the time line may jump back and forth: across a reset a time may recur,
/// never within the stretch between two resets, and never twice in a row.
pub fn check_epoch_order(fixes: &[navsync_shared::samples::GnssFix], resets: u64) {
    let times: Vec<i64> = fixes.iter().map(|f| f.utc_ns).filter(|&t| t != i64::MIN).collect();
    for w in times.windows(2) {
        assert_ne!(w[0], w[1], "epoch {} published twice in a row", w[0]);
    }
    let back = times.windows(2).filter(|w| w[1] < w[0]).count() as u64;
    assert!(back <= resets, "{back} steps back in time, {resets} resets counted");
}

/// The sum of a decoder's `*_time_resets` counters.
pub fn time_resets(d: &impl navsync_drivers::gnss::GnssDecoder) -> u64 {
    let mut n = 0;
    d.each_counter(&mut |name, v| {
        if name.ends_with("time_resets") {
            n += v;
        }
    });
    n
}
