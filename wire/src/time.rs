//! Time scales and conversions: host monotonic clock, UTC, GPS time, calendar dates.
//!
//! All instants are integer nanoseconds in `i64`:
//! - host time: `CLOCK_MONOTONIC` (what every sample is stamped with);
//! - UTC: since 1970-01-01T00:00:00Z, leap seconds not counted (Unix convention);
//! - GPS time: since 1980-01-06T00:00:00 (GPS), continuous; GPS − UTC is the leap-second count.

/// Nanoseconds per second.
pub const NS_PER_S: i64 = 1_000_000_000;

/// The GPS epoch, 1980-01-06T00:00:00Z, in Unix seconds.
pub const GPS_EPOCH_UNIX_S: i64 = 315_964_800;

/// Seconds in a GPS week.
pub const SECONDS_PER_WEEK: i64 = 604_800;

fn clock_ns(clock: libc::clockid_t) -> i64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `ts` is a valid, writable timespec; clock_gettime only writes it.
    let rc = unsafe { libc::clock_gettime(clock, &mut ts) };
    debug_assert_eq!(rc, 0, "clock_gettime on a standard clock cannot fail");
    ts.tv_sec * NS_PER_S + ts.tv_nsec
}

/// Host time now: `CLOCK_MONOTONIC`, ns.
pub fn monotonic_now_ns() -> i64 {
    clock_ns(libc::CLOCK_MONOTONIC)
}

/// System wall-clock time now: `CLOCK_REALTIME`, ns since 1970 (only for logs and for
/// choosing a simulated start date; never a sample time).
pub fn realtime_now_ns() -> i64 {
    clock_ns(libc::CLOCK_REALTIME)
}

/// Days since 1970-01-01 of a proleptic Gregorian date (H. Hinnant, "chrono-compatible
/// low-level date algorithms", `days_from_civil`).
pub fn days_from_civil(year: i64, month: u32, day: u32) -> i64 {
    let y = if month <= 2 { year - 1 } else { year };
    let era = if y >= 0 { y } else { y - 399 } / 400;
    let yoe = y - era * 400;
    let m = month as i64;
    let doy = (153 * (if m > 2 { m - 3 } else { m + 9 }) + 2) / 5 + day as i64 - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// Proleptic Gregorian date of a day count since 1970-01-01 (Hinnant, `civil_from_days`).
pub fn civil_from_days(days: i64) -> (i64, u32, u32) {
    let z = days + 719_468;
    let era = if z >= 0 { z } else { z - 146_096 } / 146_097;
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let y = yoe + era * 400;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    (if m <= 2 { y + 1 } else { y }, m, d)
}

/// Broken-down UTC time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Civil {
    /// Year, e.g. 2026.
    pub year: i64,
    /// Month 1..=12.
    pub month: u32,
    /// Day 1..=31.
    pub day: u32,
    /// Hour 0..=23.
    pub hour: u32,
    /// Minute 0..=59.
    pub minute: u32,
    /// Second 0..=59.
    pub second: u32,
    /// Nanoseconds 0..1e9.
    pub nanos: u32,
}

/// UTC ns since 1970 of a date and time of day (seconds may carry a fraction via `nanos`).
pub fn utc_ns_from_civil(c: &Civil) -> i64 {
    let days = days_from_civil(c.year, c.month, c.day);
    (days * 86_400 + c.hour as i64 * 3600 + c.minute as i64 * 60 + c.second as i64) * NS_PER_S + c.nanos as i64
}

/// Breaks UTC ns since 1970 into date and time of day.
pub fn civil_from_utc_ns(utc_ns: i64) -> Civil {
    let secs = utc_ns.div_euclid(NS_PER_S);
    let nanos = utc_ns.rem_euclid(NS_PER_S) as u32;
    let days = secs.div_euclid(86_400);
    let sod = secs.rem_euclid(86_400) as u32;
    let (year, month, day) = civil_from_days(days);
    Civil {
        year,
        month,
        day,
        hour: sod / 3600,
        minute: sod / 60 % 60,
        second: sod % 60,
        nanos,
    }
}

/// RFC 3339 UTC text with millisecond precision, as gpsd prints it: `2004-03-04T16:48:43.000Z`.
pub fn format_rfc3339_ms(utc_ns: i64) -> String {
    let c = civil_from_utc_ns(utc_ns);
    format!(
        "{:04}-{:02}-{:02}T{:02}:{:02}:{:02}.{:03}Z",
        c.year,
        c.month,
        c.day,
        c.hour,
        c.minute,
        c.second,
        c.nanos / 1_000_000
    )
}

/// Leap-second table: (date from which it applies, GPS − UTC in s).
const LEAP_TABLE: &[(i64, u32, u32, i16)] = &[
    (1981, 7, 1, 1),
    (1982, 7, 1, 2),
    (1983, 7, 1, 3),
    (1985, 7, 1, 4),
    (1988, 1, 1, 5),
    (1990, 1, 1, 6),
    (1991, 1, 1, 7),
    (1992, 7, 1, 8),
    (1993, 7, 1, 9),
    (1994, 7, 1, 10),
    (1996, 1, 1, 11),
    (1997, 7, 1, 12),
    (1999, 1, 1, 13),
    (2006, 1, 1, 14),
    (2009, 1, 1, 15),
    (2012, 7, 1, 16),
    (2015, 7, 1, 17),
    (2017, 1, 1, 18),
];

/// GPS − UTC in seconds at a UTC instant (0 before 1981-07-01; 18 since 2017-01-01, the
/// last leap second announced by IERS up to the release of this table).
pub fn gps_minus_utc_s(utc_ns: i64) -> i16 {
    let day = utc_ns.div_euclid(NS_PER_S * 86_400);
    LEAP_TABLE
        .iter()
        .rev()
        .find(|(y, m, d, _)| day >= days_from_civil(*y, *m, *d))
        .map_or(0, |e| e.3)
}

/// GPS time ns (since 1980-01-06) of a UTC instant.
pub fn gps_ns_from_utc_ns(utc_ns: i64) -> i64 {
    utc_ns - GPS_EPOCH_UNIX_S * NS_PER_S + gps_minus_utc_s(utc_ns) as i64 * NS_PER_S
}

/// UTC ns of a GPS time (leap seconds looked up at the approximate UTC instant).
pub fn utc_ns_from_gps_ns(gps_ns: i64) -> i64 {
    let approx = gps_ns + GPS_EPOCH_UNIX_S * NS_PER_S;
    let leap = gps_minus_utc_s(approx - 18 * NS_PER_S) as i64;
    let utc = approx - leap * NS_PER_S;
    // Re-evaluate with the better estimate (differs only within seconds of a leap).
    approx - gps_minus_utc_s(utc) as i64 * NS_PER_S
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn civil_round_trip() {
        for days in [-800_000, -1, 0, 1, 10_957, 19_000, 20_415, 2_000_000] {
            let (y, m, d) = civil_from_days(days);
            assert_eq!(days_from_civil(y, m, d), days);
        }
        assert_eq!(days_from_civil(1980, 1, 6) * 86_400, GPS_EPOCH_UNIX_S);
    }

    #[test]
    fn rfc3339_and_leaps() {
        let c = Civil {
            year: 2004,
            month: 3,
            day: 4,
            hour: 16,
            minute: 48,
            second: 43,
            nanos: 5_000_000,
        };
        let t = utc_ns_from_civil(&c);
        assert_eq!(format_rfc3339_ms(t), "2004-03-04T16:48:43.005Z");
        assert_eq!(civil_from_utc_ns(t), c);
        assert_eq!(gps_minus_utc_s(t), 13);
        let t2 = utc_ns_from_civil(&Civil {
            year: 2026,
            month: 11,
            day: 23,
            hour: 0,
            minute: 0,
            second: 0,
            nanos: 0,
        });
        assert_eq!(gps_minus_utc_s(t2), 18);
        assert_eq!(utc_ns_from_gps_ns(gps_ns_from_utc_ns(t2)), t2);
        assert_eq!(utc_ns_from_gps_ns(gps_ns_from_utc_ns(t)), t);
    }
}
