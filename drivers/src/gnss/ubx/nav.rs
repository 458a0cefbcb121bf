//! UBX-NAV decoders: the navigation solution and the satellites it used.
//!
//! Sections of u-blox 8 / M8 Receiver Description incl. Protocol Specification
//! (UBX-13003221) and u-blox F9 HPG Interface Description (UBX-22008968), "UBX-NAV-…". Every
//! NAV message starts with `iTOW`, the GPS time of week of the navigation epoch (ms), which
//! is the same in all messages of one epoch and is the key that groups them.

use super::messages::{MAX_SATS, UbxError, expect_blocks, expect_len, i1, i2, i4, u1, u2, u4};

/// UBX-NAV-PVT (0x01 0x07), Navigation position velocity time solution: 92 bytes (u-blox 8/M8
/// protocol 15+ and F9; 84 bytes on u-blox 7, without `headVeh`/`magDec`/`magAcc`). Bytes
/// 78.. differ: M8 has `flags3` (X1, bit 0 `invalidLlh`) and reserved bytes, F9 `flags3` as
/// X2 (bit 0 `invalidLlh`, bits 1–4 `lastCorrectionAge`); the high byte is 0 on M8.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NavPvt {
    /// GPS time of week of the navigation epoch, ms.
    pub itow_ms: u32,
    /// UTC year.
    pub year: u16,
    /// UTC month, 1..=12.
    pub month: u8,
    /// UTC day of month, 1..=31.
    pub day: u8,
    /// UTC hour, 0..=23.
    pub hour: u8,
    /// UTC minute, 0..=59.
    pub min: u8,
    /// UTC second, 0..=60.
    pub sec: u8,
    /// Validity flags: bit 0 `validDate`, 1 `validTime`, 2 `fullyResolved`, 3 `validMag`.
    pub valid: u8,
    /// Time accuracy estimate (UTC), ns.
    pub t_acc_ns: u32,
    /// Fraction of the second to add to the UTC time above, ns (−1e9..1e9, may be negative).
    pub nano_ns: i32,
    /// GNSS fix type: 0 no fix, 1 dead reckoning only, 2 2D, 3 3D, 4 GNSS + dead reckoning,
    /// 5 time only.
    pub fix_type: u8,
    /// Fix status flags: bit 0 `gnssFixOK`, 1 `diffSoln`, 2–4 `psmState`, 5 `headVehValid`,
    /// 6–7 `carrSoln` (0 none, 1 float, 2 fixed).
    pub flags: u8,
    /// Additional flags: bit 5 `confirmedAvai`, 6 `confirmedDate`, 7 `confirmedTime`.
    pub flags2: u8,
    /// Satellites used in the solution.
    pub num_sv: u8,
    /// Longitude, degrees east (WGS-84).
    pub lon_deg: f64,
    /// Latitude, degrees north (WGS-84).
    pub lat_deg: f64,
    /// Height above the WGS-84 ellipsoid, m.
    pub height_m: f64,
    /// Height above mean sea level, m.
    pub h_msl_m: f64,
    /// Horizontal accuracy estimate, m.
    pub h_acc_m: f64,
    /// Vertical accuracy estimate, m.
    pub v_acc_m: f64,
    /// Velocity north (NED), m/s.
    pub vel_n_mps: f64,
    /// Velocity east (NED), m/s.
    pub vel_e_mps: f64,
    /// Velocity down (NED), m/s.
    pub vel_d_mps: f64,
    /// Ground speed (2D), m/s.
    pub g_speed_mps: f64,
    /// Heading of motion (2D), degrees clockwise from true north.
    pub head_mot_deg: f64,
    /// Speed accuracy estimate, m/s.
    pub s_acc_mps: f64,
    /// Heading accuracy estimate (motion and vehicle), degrees.
    pub head_acc_deg: f64,
    /// Position DOP.
    pub p_dop: f64,
    /// `flags3` (see the type's doc): bit 0 `invalidLlh`.
    pub flags3: u16,
    /// Heading of vehicle (2D), degrees; `None` on the 84-byte u-blox 7 layout.
    pub head_veh_deg: Option<f64>,
    /// Magnetic declination, degrees; `None` unless `validMag` (and 92 bytes).
    pub mag_dec_deg: Option<f64>,
    /// Magnetic declination accuracy, degrees; `None` unless `validMag` (and 92 bytes).
    pub mag_acc_deg: Option<f64>,
}

impl NavPvt {
    /// The UTC second of the date and time fields, ns since 1970 (`nano` not added).
    pub fn utc_second_ns(&self) -> i64 {
        navsync_shared::time::utc_ns_from_civil(&navsync_shared::time::Civil {
            year: i64::from(self.year),
            month: u32::from(self.month),
            day: u32::from(self.day),
            hour: u32::from(self.hour),
            minute: u32::from(self.min),
            second: u32::from(self.sec),
            nanos: 0,
        })
    }

    /// `validDate` and `validTime`: the UTC date and time fields are valid.
    pub fn valid_date_time(&self) -> bool {
        self.valid & 0x03 == 0x03
    }

    /// `fullyResolved`: the UTC time of day has no seconds uncertainty.
    pub fn fully_resolved(&self) -> bool {
        self.valid & 0x04 != 0
    }

    /// `gnssFixOK`: the fix is within the receiver's DOP and accuracy masks.
    pub fn gnss_fix_ok(&self) -> bool {
        self.flags & 0x01 != 0
    }

    /// `diffSoln`: differential corrections were applied.
    pub fn diff_soln(&self) -> bool {
        self.flags & 0x02 != 0
    }

    /// `carrSoln`: carrier phase range solution, 0 none, 1 float, 2 fixed ambiguities.
    pub fn carr_soln(&self) -> u8 {
        self.flags >> 6
    }

    /// `invalidLlh`: longitude, latitude, height and hMSL are invalid.
    pub fn invalid_llh(&self) -> bool {
        self.flags3 & 0x01 != 0
    }
}

/// UBX-NAV-PVT (0x01 0x07): see [`NavPvt`].
pub fn decode_nav_pvt(p: &[u8]) -> Result<NavPvt, UbxError> {
    expect_len("NAV-PVT", p, &[84, 92], "92 (84 on u-blox 7)")?;
    let long = p.len() == 92;
    let valid = u1(p, 11);
    let mag = long && valid & 0x08 != 0;
    Ok(NavPvt {
        itow_ms: u4(p, 0),
        year: u2(p, 4),
        month: u1(p, 6),
        day: u1(p, 7),
        hour: u1(p, 8),
        min: u1(p, 9),
        sec: u1(p, 10),
        valid,
        t_acc_ns: u4(p, 12),
        nano_ns: i4(p, 16),
        fix_type: u1(p, 20),
        flags: u1(p, 21),
        flags2: u1(p, 22),
        num_sv: u1(p, 23),
        lon_deg: deg7(i4(p, 24)),
        lat_deg: deg7(i4(p, 28)),
        height_m: milli(i4(p, 32)),
        h_msl_m: milli(i4(p, 36)),
        h_acc_m: milli_u(u4(p, 40)),
        v_acc_m: milli_u(u4(p, 44)),
        vel_n_mps: milli(i4(p, 48)),
        vel_e_mps: milli(i4(p, 52)),
        vel_d_mps: milli(i4(p, 56)),
        g_speed_mps: milli(i4(p, 60)),
        head_mot_deg: deg5(i4(p, 64)),
        s_acc_mps: milli_u(u4(p, 68)),
        head_acc_deg: deg5_u(u4(p, 72)),
        p_dop: centi(u2(p, 76)),
        flags3: if long { u2(p, 78) } else { 0 },
        head_veh_deg: long.then(|| deg5(i4(p, 84))),
        mag_dec_deg: mag.then(|| f64::from(i2(p, 88)) / 1e2),
        mag_acc_deg: mag.then(|| f64::from(u2(p, 90)) / 1e2),
    })
}

/// UBX-NAV-SOL (0x01 0x06), Navigation solution information: 52 bytes. ECEF position and
/// velocity with GPS week and time of week (u-blox 4 to 8; superseded by NAV-PVT).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NavSol {
    /// GPS time of week of the navigation epoch, ms.
    pub itow_ms: u32,
    /// Fractional part of the time of week (`iTOW` + this is the precise time), ns.
    pub ftow_ns: i32,
    /// GPS week number (not rolled over at 1024).
    pub week: i16,
    /// GPS fix type: 0 no fix, 1 dead reckoning only, 2 2D, 3 3D, 4 GPS + dead reckoning,
    /// 5 time only.
    pub gps_fix: u8,
    /// Flags: bit 0 `GPSfixOK`, 1 `DiffSoln`, 2 `WKNSET` (week valid), 3 `TOWSET` (time of
    /// week valid).
    pub flags: u8,
    /// ECEF X, m.
    pub ecef_x_m: f64,
    /// ECEF Y, m.
    pub ecef_y_m: f64,
    /// ECEF Z, m.
    pub ecef_z_m: f64,
    /// 3D position accuracy estimate, m.
    pub p_acc_m: f64,
    /// ECEF X velocity, m/s.
    pub ecef_vx_mps: f64,
    /// ECEF Y velocity, m/s.
    pub ecef_vy_mps: f64,
    /// ECEF Z velocity, m/s.
    pub ecef_vz_mps: f64,
    /// Speed accuracy estimate, m/s.
    pub s_acc_mps: f64,
    /// Position DOP.
    pub p_dop: f64,
    /// Satellites used in the solution.
    pub num_sv: u8,
}

impl NavSol {
    /// `GPSfixOK`: the fix is within the receiver's DOP and accuracy masks.
    pub fn fix_ok(&self) -> bool {
        self.flags & 0x01 != 0
    }

    /// `DiffSoln`: differential corrections were applied.
    pub fn diff_soln(&self) -> bool {
        self.flags & 0x02 != 0
    }

    /// `WKNSET` and `TOWSET`: week and time of week are valid.
    pub fn time_valid(&self) -> bool {
        self.flags & 0x0C == 0x0C
    }
}

/// UBX-NAV-SOL (0x01 0x06): see [`NavSol`].
pub fn decode_nav_sol(p: &[u8]) -> Result<NavSol, UbxError> {
    expect_len("NAV-SOL", p, &[52], "52")?;
    Ok(NavSol {
        itow_ms: u4(p, 0),
        ftow_ns: i4(p, 4),
        week: i2(p, 8),
        gps_fix: u1(p, 10),
        flags: u1(p, 11),
        ecef_x_m: centi_i(i4(p, 12)),
        ecef_y_m: centi_i(i4(p, 16)),
        ecef_z_m: centi_i(i4(p, 20)),
        p_acc_m: f64::from(u4(p, 24)) / 1e2,
        ecef_vx_mps: centi_i(i4(p, 28)),
        ecef_vy_mps: centi_i(i4(p, 32)),
        ecef_vz_mps: centi_i(i4(p, 36)),
        s_acc_mps: f64::from(u4(p, 40)) / 1e2,
        p_dop: centi(u2(p, 44)),
        num_sv: u1(p, 47),
    })
}

/// UBX-NAV-TIMEGPS (0x01 0x20), GPS time solution: 16 bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NavTimegps {
    /// GPS time of week of the navigation epoch, ms.
    pub itow_ms: u32,
    /// Fractional part of the time of week, ns.
    pub ftow_ns: i32,
    /// GPS week number.
    pub week: i16,
    /// GPS − UTC leap seconds, s.
    pub leap_s: i8,
    /// Validity: bit 0 `towValid`, 1 `weekValid`, 2 `leapSValid`.
    pub valid: u8,
    /// Time accuracy estimate, ns.
    pub t_acc_ns: u32,
}

impl NavTimegps {
    /// `towValid` and `weekValid`.
    pub fn time_valid(&self) -> bool {
        self.valid & 0x03 == 0x03
    }

    /// `leapSValid`: `leap_s` is the current leap-second count (not the firmware default).
    pub fn leap_valid(&self) -> bool {
        self.valid & 0x04 != 0
    }
}

/// UBX-NAV-TIMEGPS (0x01 0x20): see [`NavTimegps`].
pub fn decode_nav_timegps(p: &[u8]) -> Result<NavTimegps, UbxError> {
    expect_len("NAV-TIMEGPS", p, &[16], "16")?;
    Ok(NavTimegps {
        itow_ms: u4(p, 0),
        ftow_ns: i4(p, 4),
        week: i2(p, 8),
        leap_s: i1(p, 10),
        valid: u1(p, 11),
        t_acc_ns: u4(p, 12),
    })
}

/// UBX-NAV-POSLLH (0x01 0x02), Geodetic position solution: 28 bytes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NavPosllh {
    /// GPS time of week of the navigation epoch, ms.
    pub itow_ms: u32,
    /// Longitude, degrees east (WGS-84).
    pub lon_deg: f64,
    /// Latitude, degrees north (WGS-84).
    pub lat_deg: f64,
    /// Height above the WGS-84 ellipsoid, m.
    pub height_m: f64,
    /// Height above mean sea level, m.
    pub h_msl_m: f64,
    /// Horizontal accuracy estimate, m.
    pub h_acc_m: f64,
    /// Vertical accuracy estimate, m.
    pub v_acc_m: f64,
}

/// UBX-NAV-POSLLH (0x01 0x02): see [`NavPosllh`].
pub fn decode_nav_posllh(p: &[u8]) -> Result<NavPosllh, UbxError> {
    expect_len("NAV-POSLLH", p, &[28], "28")?;
    Ok(NavPosllh {
        itow_ms: u4(p, 0),
        lon_deg: deg7(i4(p, 4)),
        lat_deg: deg7(i4(p, 8)),
        height_m: milli(i4(p, 12)),
        h_msl_m: milli(i4(p, 16)),
        h_acc_m: milli_u(u4(p, 20)),
        v_acc_m: milli_u(u4(p, 24)),
    })
}

/// UBX-NAV-VELNED (0x01 0x12), Velocity solution in NED frame: 36 bytes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NavVelned {
    /// GPS time of week of the navigation epoch, ms.
    pub itow_ms: u32,
    /// Velocity north, m/s.
    pub vel_n_mps: f64,
    /// Velocity east, m/s.
    pub vel_e_mps: f64,
    /// Velocity down, m/s.
    pub vel_d_mps: f64,
    /// Speed (3D), m/s.
    pub speed_mps: f64,
    /// Ground speed (2D), m/s.
    pub g_speed_mps: f64,
    /// Heading of motion (2D), degrees clockwise from true north.
    pub heading_deg: f64,
    /// Speed accuracy estimate, m/s.
    pub s_acc_mps: f64,
    /// Course / heading accuracy estimate, degrees.
    pub c_acc_deg: f64,
}

/// UBX-NAV-VELNED (0x01 0x12): see [`NavVelned`].
pub fn decode_nav_velned(p: &[u8]) -> Result<NavVelned, UbxError> {
    expect_len("NAV-VELNED", p, &[36], "36")?;
    Ok(NavVelned {
        itow_ms: u4(p, 0),
        vel_n_mps: centi_i(i4(p, 4)),
        vel_e_mps: centi_i(i4(p, 8)),
        vel_d_mps: centi_i(i4(p, 12)),
        speed_mps: f64::from(u4(p, 16)) / 1e2,
        g_speed_mps: f64::from(u4(p, 20)) / 1e2,
        heading_deg: deg5(i4(p, 24)),
        s_acc_mps: f64::from(u4(p, 28)) / 1e2,
        c_acc_deg: deg5_u(u4(p, 32)),
    })
}

/// UBX-NAV-DOP (0x01 0x04), Dilution of precision: 18 bytes. DOPs are dimensionless.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NavDop {
    /// GPS time of week of the navigation epoch, ms.
    pub itow_ms: u32,
    /// Geometric DOP.
    pub g_dop: f64,
    /// Position DOP.
    pub p_dop: f64,
    /// Time DOP.
    pub t_dop: f64,
    /// Vertical DOP.
    pub v_dop: f64,
    /// Horizontal DOP.
    pub h_dop: f64,
    /// Northing DOP.
    pub n_dop: f64,
    /// Easting DOP.
    pub e_dop: f64,
}

/// UBX-NAV-DOP (0x01 0x04): see [`NavDop`].
pub fn decode_nav_dop(p: &[u8]) -> Result<NavDop, UbxError> {
    expect_len("NAV-DOP", p, &[18], "18")?;
    Ok(NavDop {
        itow_ms: u4(p, 0),
        g_dop: centi(u2(p, 4)),
        p_dop: centi(u2(p, 6)),
        t_dop: centi(u2(p, 8)),
        v_dop: centi(u2(p, 10)),
        h_dop: centi(u2(p, 12)),
        n_dop: centi(u2(p, 14)),
        e_dop: centi(u2(p, 16)),
    })
}

/// UBX-NAV-STATUS (0x01 0x03), Receiver navigation status: 16 bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NavStatus {
    /// GPS time of week of the navigation epoch, ms.
    pub itow_ms: u32,
    /// GPS fix type, as [`NavSol::gps_fix`].
    pub gps_fix: u8,
    /// Flags: bit 0 `gpsFixOk`, 1 `diffSoln`, 2 `wknSet`, 3 `towSet`.
    pub flags: u8,
    /// Fix status: bit 0 `diffCorr` (corrections available), 1 `carrSolnValid`, 6–7
    /// `mapMatching`.
    pub fix_stat: u8,
    /// Further flags: bits 0–1 `psmState`, 3–4 `spoofDetState`, 6–7 `carrSoln` (0 none,
    /// 1 float, 2 fixed).
    pub flags2: u8,
    /// Time to first fix, ms.
    pub ttff_ms: u32,
    /// Milliseconds since startup or reset, ms.
    pub msss_ms: u32,
}

impl NavStatus {
    /// `gpsFixOk`: the fix is within the receiver's DOP and accuracy masks.
    pub fn fix_ok(&self) -> bool {
        self.flags & 0x01 != 0
    }

    /// `diffSoln`: differential corrections were applied.
    pub fn diff_soln(&self) -> bool {
        self.flags & 0x02 != 0
    }

    /// `carrSoln`: 0 none, 1 float, 2 fixed ambiguities.
    pub fn carr_soln(&self) -> u8 {
        self.flags2 >> 6
    }
}

/// UBX-NAV-STATUS (0x01 0x03): see [`NavStatus`].
pub fn decode_nav_status(p: &[u8]) -> Result<NavStatus, UbxError> {
    expect_len("NAV-STATUS", p, &[16], "16")?;
    Ok(NavStatus {
        itow_ms: u4(p, 0),
        gps_fix: u1(p, 4),
        flags: u1(p, 5),
        fix_stat: u1(p, 6),
        flags2: u1(p, 7),
        ttff_ms: u4(p, 8),
        msss_ms: u4(p, 12),
    })
}

/// UBX-NAV-TIMEUTC (0x01 0x21), UTC time solution: 20 bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NavTimeutc {
    /// GPS time of week of the navigation epoch, ms.
    pub itow_ms: u32,
    /// Time accuracy estimate (UTC), ns.
    pub t_acc_ns: u32,
    /// Fraction of the second to add to the time below, ns (may be negative).
    pub nano_ns: i32,
    /// UTC year.
    pub year: u16,
    /// UTC month, 1..=12.
    pub month: u8,
    /// UTC day of month.
    pub day: u8,
    /// UTC hour.
    pub hour: u8,
    /// UTC minute.
    pub min: u8,
    /// UTC second, 0..=60.
    pub sec: u8,
    /// Validity: bit 0 `validTOW`, 1 `validWKN`, 2 `validUTC`, 4–7 `utcStandard`.
    pub valid: u8,
}

impl NavTimeutc {
    /// `validUTC`: the UTC time (leap seconds known) is valid.
    pub fn utc_valid(&self) -> bool {
        self.valid & 0x04 != 0
    }
}

/// UBX-NAV-TIMEUTC (0x01 0x21): see [`NavTimeutc`].
pub fn decode_nav_timeutc(p: &[u8]) -> Result<NavTimeutc, UbxError> {
    expect_len("NAV-TIMEUTC", p, &[20], "20")?;
    Ok(NavTimeutc {
        itow_ms: u4(p, 0),
        t_acc_ns: u4(p, 4),
        nano_ns: i4(p, 8),
        year: u2(p, 12),
        month: u1(p, 14),
        day: u1(p, 15),
        hour: u1(p, 16),
        min: u1(p, 17),
        sec: u1(p, 18),
        valid: u1(p, 19),
    })
}

/// One satellite of NAV-SAT (or of NAV-SVINFO, converted).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SatInfo {
    /// GNSS: 0 GPS, 1 SBAS, 2 Galileo, 3 BeiDou, 4 IMES, 5 QZSS, 6 GLONASS (u-blox `gnssId`).
    pub gnss_id: u8,
    /// Satellite number within its GNSS (u-blox `svId`; SBAS 120..=158, GLONASS slot 1..=24
    /// or 255 unknown).
    pub sv_id: u8,
    /// Carrier-to-noise density ratio, dBHz.
    pub cno_dbhz: u8,
    /// Elevation, degrees (−90..=90); outside that range it is unknown.
    pub elev_deg: i8,
    /// Azimuth, degrees (0..=360); outside that range it is unknown.
    pub azim_deg: i16,
    /// Pseudorange residual, m.
    pub pr_res_m: f64,
    /// The satellite is used in the navigation solution.
    pub used: bool,
    /// Signal quality indicator, 0 no signal .. 7 code and carrier locked (u-blox `qualityInd`).
    pub quality: u8,
    /// Health: 0 unknown, 1 healthy, 2 unhealthy.
    pub health: u8,
    /// The message's flags for this satellite, unchanged (NAV-SAT X4, NAV-SVINFO X1).
    pub flags: u32,
}

impl SatInfo {
    /// An unused slot.
    pub const EMPTY: SatInfo = SatInfo {
        gnss_id: 0,
        sv_id: 0,
        cno_dbhz: 0,
        elev_deg: 0,
        azim_deg: 0,
        pr_res_m: 0.0,
        used: false,
        quality: 0,
        health: 0,
        flags: 0,
    };

    /// Elevation in degrees when known (|elev| ≤ 90).
    pub fn elevation_deg(&self) -> Option<i8> {
        (self.elev_deg.unsigned_abs() <= 90).then_some(self.elev_deg)
    }

    /// Azimuth in degrees when known (0..=360; 360 is reported as 0).
    pub fn azimuth_deg(&self) -> Option<i16> {
        match self.azim_deg {
            360 => Some(0),
            a if (0..360).contains(&a) => Some(a),
            _ => None,
        }
    }
}

/// UBX-NAV-SAT (0x01 0x35), Satellite information: 8 + 12·`numSvs` bytes, version 1.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NavSat {
    /// GPS time of week of the navigation epoch, ms.
    pub itow_ms: u32,
    /// Satellites announced (`numSvs`).
    pub num_svs: u8,
    /// The first [`MAX_SATS`] satellites; `sats[..len]` are valid.
    pub sats: [SatInfo; MAX_SATS],
    /// Valid entries of `sats`.
    pub len: usize,
    /// Satellites that did not fit into `sats`.
    pub dropped: usize,
}

impl NavSat {
    /// The satellites decoded.
    pub fn satellites(&self) -> &[SatInfo] {
        self.sats.get(..self.len).unwrap_or(&[])
    }
}

/// UBX-NAV-SAT (0x01 0x35): see [`NavSat`].
pub fn decode_nav_sat(p: &[u8]) -> Result<NavSat, UbxError> {
    if p.len() < 8 {
        return Err(UbxError::Length {
            name: "NAV-SAT",
            len: p.len(),
            expected: "8 + 12·numSvs",
        });
    }
    let version = u1(p, 4);
    if version != 1 {
        return Err(UbxError::Version {
            name: "NAV-SAT",
            version,
        });
    }
    let n = usize::from(u1(p, 5));
    expect_blocks("NAV-SAT", p, 8, 12, n, "8 + 12·numSvs")?;
    let mut out = NavSat {
        itow_ms: u4(p, 0),
        num_svs: u1(p, 5),
        sats: [SatInfo::EMPTY; MAX_SATS],
        len: n.min(MAX_SATS),
        dropped: n.saturating_sub(MAX_SATS),
    };
    for (i, s) in out.sats.iter_mut().take(n).enumerate() {
        let o = 8 + 12 * i;
        let flags = u4(p, o + 8);
        *s = SatInfo {
            gnss_id: u1(p, o),
            sv_id: u1(p, o + 1),
            cno_dbhz: u1(p, o + 2),
            elev_deg: i1(p, o + 3),
            azim_deg: i2(p, o + 4),
            pr_res_m: f64::from(i2(p, o + 6)) / 10.0,
            used: flags & 0x08 != 0,
            quality: (flags & 0x07) as u8,
            health: ((flags >> 4) & 0x03) as u8,
            flags,
        };
    }
    Ok(out)
}

/// UBX-NAV-SVINFO (0x01 0x30), Space vehicle information: 8 + 12·`numCh` bytes (u-blox 4
/// to 8; superseded by NAV-SAT). Satellites are numbered in u-blox's legacy single range
/// (M8 protocol, "Satellite Numbering"), converted to `gnssId`/`svId` by [`legacy_sv`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NavSvinfo {
    /// GPS time of week of the navigation epoch, ms.
    pub itow_ms: u32,
    /// Channels announced (`numCh`).
    pub num_ch: u8,
    /// `globalFlags`: bits 0–2 `chipGen` (0 Antaris, 1 u-blox 5, 2 u-blox 6, 3 u-blox 7,
    /// 4 u-blox 8).
    pub global_flags: u8,
    /// The first [`MAX_SATS`] channels with a satellite number that maps to a GNSS (see
    /// [`legacy_sv`]); `sats[..len]` are valid. `flags` holds the channel's X1 flags
    /// (bit 0 `svUsed`, 1 `diffCorr`, 2 `orbitAvail`, 3 `orbitEph`, 4 `unhealthy`).
    pub sats: [SatInfo; MAX_SATS],
    /// The receiver channel of each entry of `sats`.
    pub chn: [u8; MAX_SATS],
    /// Valid entries of `sats`.
    pub len: usize,
    /// Channels that did not fit into `sats`.
    pub dropped: usize,
    /// Channels with a satellite number outside every GNSS range (0, reserved ranges).
    pub unknown: usize,
}

impl NavSvinfo {
    /// The satellites decoded.
    pub fn satellites(&self) -> &[SatInfo] {
        self.sats.get(..self.len).unwrap_or(&[])
    }
}

/// The `gnssId`/`svId` of a satellite in u-blox's legacy numbering (M8 protocol, appendix
/// "Satellite Numbering"): GPS 1–32, BeiDou 33–64 (svId 6–37) and 159–163 (1–5), GLONASS
/// 65–96 (1–32) and 255 (unknown slot), SBAS 120–158, IMES 173–182 (1–10), QZSS 193–202
/// (1–10), Galileo 211–246 (1–36). `None` for numbers outside these ranges.
pub fn legacy_sv(svid: u8) -> Option<(u8, u8)> {
    Some(match svid {
        1..=32 => (0, svid),
        33..=64 => (3, svid - 27),
        65..=96 => (6, svid - 64),
        120..=158 => (1, svid),
        159..=163 => (3, svid - 158),
        173..=182 => (4, svid - 172),
        193..=202 => (5, svid - 192),
        211..=246 => (2, svid - 210),
        255 => (6, 255),
        _ => return None,
    })
}

/// UBX-NAV-SVINFO (0x01 0x30): see [`NavSvinfo`].
pub fn decode_nav_svinfo(p: &[u8]) -> Result<NavSvinfo, UbxError> {
    if p.len() < 8 {
        return Err(UbxError::Length {
            name: "NAV-SVINFO",
            len: p.len(),
            expected: "8 + 12·numCh",
        });
    }
    let n = usize::from(u1(p, 4));
    expect_blocks("NAV-SVINFO", p, 8, 12, n, "8 + 12·numCh")?;
    let mut out = NavSvinfo {
        itow_ms: u4(p, 0),
        num_ch: u1(p, 4),
        global_flags: u1(p, 5),
        sats: [SatInfo::EMPTY; MAX_SATS],
        chn: [0; MAX_SATS],
        len: 0,
        dropped: 0,
        unknown: 0,
    };
    for i in 0..n {
        let o = 8 + 12 * i;
        let Some((gnss_id, sv_id)) = legacy_sv(u1(p, o + 1)) else {
            out.unknown += 1;
            continue;
        };
        let (Some(slot), Some(chn)) = (out.sats.get_mut(out.len), out.chn.get_mut(out.len)) else {
            out.dropped += 1;
            continue;
        };
        let flags = u1(p, o + 2);
        *chn = u1(p, o);
        *slot = SatInfo {
            gnss_id,
            sv_id,
            cno_dbhz: u1(p, o + 4),
            elev_deg: i1(p, o + 5),
            azim_deg: i2(p, o + 6),
            pr_res_m: f64::from(i4(p, o + 8)) / 1e2,
            used: flags & 0x01 != 0,
            quality: u1(p, o + 3) & 0x0F,
            health: if flags & 0x10 != 0 { 2 } else { 1 },
            flags: u32::from(flags),
        };
        out.len += 1;
    }
    Ok(out)
}

/// UBX-NAV-EOE (0x01 0x61), End of epoch: 4 bytes. The receiver sends it after the last NAV
/// message of an epoch (protocol 18+).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NavEoe {
    /// GPS time of week of the navigation epoch that ended, ms.
    pub itow_ms: u32,
}

/// UBX-NAV-EOE (0x01 0x61): see [`NavEoe`].
pub fn decode_nav_eoe(p: &[u8]) -> Result<NavEoe, UbxError> {
    expect_len("NAV-EOE", p, &[4], "4")?;
    Ok(NavEoe { itow_ms: u4(p, 0) })
}

/// 1e-7 degrees → degrees.
fn deg7(v: i32) -> f64 {
    f64::from(v) / 1e7
}

/// 1e-5 degrees → degrees.
fn deg5(v: i32) -> f64 {
    f64::from(v) / 1e5
}

/// Unsigned 1e-5 degrees → degrees.
fn deg5_u(v: u32) -> f64 {
    f64::from(v) / 1e5
}

/// Milli-units (mm, mm/s) → units.
fn milli(v: i32) -> f64 {
    f64::from(v) / 1e3
}

/// Unsigned milli-units → units.
fn milli_u(v: u32) -> f64 {
    f64::from(v) / 1e3
}

/// Centi-units (cm, cm/s) → units.
fn centi_i(v: i32) -> f64 {
    f64::from(v) / 1e2
}

/// Unsigned hundredths (DOPs) → units.
fn centi(v: u16) -> f64 {
    f64::from(v) / 1e2
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A little-endian payload builder.
    #[derive(Default)]
    pub(crate) struct P(pub Vec<u8>);

    impl P {
        pub(crate) fn u1(mut self, v: u8) -> Self {
            self.0.push(v);
            self
        }
        pub(crate) fn i1(self, v: i8) -> Self {
            self.u1(v as u8)
        }
        pub(crate) fn u2(mut self, v: u16) -> Self {
            self.0.extend_from_slice(&v.to_le_bytes());
            self
        }
        pub(crate) fn i2(self, v: i16) -> Self {
            self.u2(v as u16)
        }
        pub(crate) fn u4(mut self, v: u32) -> Self {
            self.0.extend_from_slice(&v.to_le_bytes());
            self
        }
        pub(crate) fn i4(self, v: i32) -> Self {
            self.u4(v as u32)
        }
        pub(crate) fn r4(mut self, v: f32) -> Self {
            self.0.extend_from_slice(&v.to_le_bytes());
            self
        }
        pub(crate) fn r8(mut self, v: f64) -> Self {
            self.0.extend_from_slice(&v.to_le_bytes());
            self
        }
        pub(crate) fn zeros(mut self, n: usize) -> Self {
            self.0.extend(std::iter::repeat_n(0, n));
            self
        }
    }

    /// A NAV-PVT payload: 2021-06-10 18:18:57 UTC, 3D fix with `flags`, at 50.1°N 14.4°E.
    pub(crate) fn pvt(itow_ms: u32, fix_type: u8, flags: u8) -> Vec<u8> {
        P::default()
            .u4(itow_ms)
            .u2(2021)
            .u1(6)
            .u1(10)
            .u1(18)
            .u1(18)
            .u1(57)
            .u1(0x37)
            .u4(25)
            .i4(-123_456)
            .u1(fix_type)
            .u1(flags)
            .u1(0xEA)
            .u1(12)
            .i4(144_299_469)
            .i4(501_350_845)
            .i4(348_941)
            .i4(304_671)
            .u4(2_513)
            .u4(4_894)
            .i4(-10)
            .i4(20)
            .i4(-30)
            .i4(24)
            .i4(12_345_678)
            .u4(350)
            .u4(9_000_000)
            .u2(156)
            .u2(0x0001)
            .zeros(4)
            .i4(9_000_000)
            .i2(420)
            .u2(50)
            .0
    }

    /// [`pvt`] with its UTC time of day moved by `iTOW` seconds for the small `iTOW`s (below
    /// 100 s) of synthetic epoch sequences (18:18:57 + iTOW/1000 s, the nano field kept), so
    /// that successive epochs of a test have successive times; as [`pvt`] otherwise.
    pub(crate) fn pvt_at(itow_ms: u32, fix_type: u8, flags: u8) -> Vec<u8> {
        let mut p = pvt(itow_ms, fix_type, flags);
        if itow_ms >= 100_000 {
            return p;
        }
        let tod = (18 * 3600 + 18 * 60 + 57 + itow_ms / 1000) % 86_400;
        p[8] = (tod / 3600) as u8;
        p[9] = (tod / 60 % 60) as u8;
        p[10] = (tod % 60) as u8;
        p
    }

    #[test]
    fn nav_pvt_fields_and_units() {
        let m = decode_nav_pvt(&pvt(237_537_000, 3, 0x83)).unwrap();
        assert_eq!(m.itow_ms, 237_537_000);
        assert_eq!(
            (m.year, m.month, m.day, m.hour, m.min, m.sec),
            (2021, 6, 10, 18, 18, 57)
        );
        assert!(m.valid_date_time() && m.fully_resolved());
        assert_eq!((m.t_acc_ns, m.nano_ns, m.fix_type, m.num_sv), (25, -123_456, 3, 12));
        assert!(m.gnss_fix_ok() && m.diff_soln());
        assert_eq!(m.carr_soln(), 2);
        assert_eq!(m.lon_deg, 14.429_946_9);
        assert_eq!(m.lat_deg, 50.135_084_5);
        assert_eq!((m.height_m, m.h_msl_m), (348.941, 304.671));
        assert_eq!((m.h_acc_m, m.v_acc_m), (2.513, 4.894));
        assert_eq!(
            (m.vel_n_mps, m.vel_e_mps, m.vel_d_mps, m.g_speed_mps),
            (-0.01, 0.02, -0.03, 0.024)
        );
        assert!((m.head_mot_deg - 123.45678).abs() < 1e-12);
        assert_eq!((m.s_acc_mps, m.head_acc_deg, m.p_dop), (0.35, 90.0, 1.56));
        assert!(m.invalid_llh());
        assert_eq!(m.head_veh_deg, Some(90.0));
        assert_eq!((m.mag_dec_deg, m.mag_acc_deg), (None, None), "validMag not set");
        let mut u7 = pvt(1, 3, 1);
        u7.truncate(84);
        let m7 = decode_nav_pvt(&u7).unwrap();
        assert_eq!((m7.head_veh_deg, m7.flags3), (None, 0));
        assert!(matches!(
            decode_nav_pvt(&u7[..83]),
            Err(UbxError::Length { len: 83, .. })
        ));
    }

    #[test]
    fn nav_sol_fields_and_units() {
        let p = P::default()
            .u4(400_463_000)
            .i4(78_688)
            .i2(2307)
            .u1(3)
            .u1(0xDD)
            .i4(-200_169_183)
            .i4(-392_507_428)
            .i4(459_654_616)
            .u4(2446)
            .i4(21)
            .i4(-20)
            .i4(-7)
            .u4(103)
            .u2(326)
            .u1(0)
            .u1(5)
            .u4(0)
            .0;
        let m = decode_nav_sol(&p).unwrap();
        assert_eq!(
            (m.itow_ms, m.ftow_ns, m.week, m.gps_fix, m.num_sv),
            (400_463_000, 78_688, 2307, 3, 5)
        );
        assert!(m.fix_ok() && !m.diff_soln() && m.time_valid());
        assert_eq!(
            (m.ecef_x_m, m.ecef_y_m, m.ecef_z_m),
            (-2_001_691.83, -3_925_074.28, 4_596_546.16)
        );
        assert_eq!((m.p_acc_m, m.s_acc_mps, m.p_dop), (24.46, 1.03, 3.26));
        assert_eq!((m.ecef_vx_mps, m.ecef_vy_mps, m.ecef_vz_mps), (0.21, -0.2, -0.07));
        assert!(decode_nav_sol(&p[..51]).is_err());
    }

    #[test]
    fn nav_time_messages() {
        let p = P::default().u4(237_887_000).i4(321_732).i2(2146).i1(18).u1(7).u4(12).0;
        let t = decode_nav_timegps(&p).unwrap();
        assert_eq!(
            (t.itow_ms, t.ftow_ns, t.week, t.leap_s, t.t_acc_ns),
            (237_887_000, 321_732, 2146, 18, 12)
        );
        assert!(t.time_valid() && t.leap_valid());
        let p = P::default()
            .u4(237_887_000)
            .u4(9)
            .i4(-5)
            .u2(2021)
            .u1(2)
            .u1(23)
            .u1(18)
            .u1(4)
            .u1(29)
            .u1(0x37)
            .0;
        let u = decode_nav_timeutc(&p).unwrap();
        assert_eq!(
            (u.year, u.month, u.day, u.hour, u.min, u.sec, u.nano_ns),
            (2021, 2, 23, 18, 4, 29, -5)
        );
        assert!(u.utc_valid());
        assert!(decode_nav_timeutc(&p[..19]).is_err() && decode_nav_timegps(&[0; 17]).is_err());
        assert_eq!(decode_nav_eoe(&7u32.to_le_bytes()), Ok(NavEoe { itow_ms: 7 }));
        assert!(decode_nav_eoe(&[0; 5]).is_err());
    }

    #[test]
    fn nav_posllh_velned_dop_status() {
        let p = P::default()
            .u4(1)
            .i4(-688_066_651)
            .i4(447_654_405)
            .i4(13_684)
            .i4(43_156)
            .u4(20_619)
            .u4(14_580)
            .0;
        let m = decode_nav_posllh(&p).unwrap();
        assert_eq!((m.lon_deg, m.lat_deg), (-68.806_665_1, 44.765_440_5));
        assert_eq!(
            (m.height_m, m.h_msl_m, m.h_acc_m, m.v_acc_m),
            (13.684, 43.156, 20.619, 14.58)
        );
        let p = P::default()
            .u4(1)
            .i4(-11)
            .i4(28)
            .i4(1)
            .u4(30)
            .u4(30)
            .i4(11_127_230)
            .u4(103)
            .u4(500_000)
            .0;
        let v = decode_nav_velned(&p).unwrap();
        assert_eq!(
            (v.vel_n_mps, v.vel_e_mps, v.vel_d_mps, v.speed_mps),
            (-0.11, 0.28, 0.01, 0.3)
        );
        assert_eq!((v.g_speed_mps, v.s_acc_mps, v.c_acc_deg), (0.3, 1.03, 5.0));
        assert!((v.heading_deg - 111.2723).abs() < 1e-9);
        let p = P::default()
            .u4(1)
            .u2(366)
            .u2(326)
            .u2(174)
            .u2(295)
            .u2(128)
            .u2(90)
            .u2(91)
            .0;
        let d = decode_nav_dop(&p).unwrap();
        assert_eq!(
            (d.g_dop, d.p_dop, d.t_dop, d.v_dop, d.h_dop, d.n_dop, d.e_dop),
            (3.66, 3.26, 1.74, 2.95, 1.28, 0.9, 0.91)
        );
        let p = P::default()
            .u4(1)
            .u1(5)
            .u1(0xDD)
            .u1(0x03)
            .u1(0x88)
            .u4(30_000)
            .u4(99_000)
            .0;
        let s = decode_nav_status(&p).unwrap();
        assert_eq!(
            (s.gps_fix, s.fix_stat, s.ttff_ms, s.msss_ms, s.carr_soln()),
            (5, 3, 30_000, 99_000, 2)
        );
        assert!(s.fix_ok() && !s.diff_soln());
        assert!(decode_nav_posllh(&[0; 27]).is_err() && decode_nav_velned(&[0; 37]).is_err());
        assert!(decode_nav_dop(&[0; 16]).is_err() && decode_nav_status(&[0; 15]).is_err());
    }

    fn sat_block(gnss: u8, sv: u8, cno: u8, el: i8, az: i16, used: bool) -> P {
        P::default()
            .u1(gnss)
            .u1(sv)
            .u1(cno)
            .i1(el)
            .i2(az)
            .i2(-7)
            .u4(if used { 0x1F } else { 0x14 })
    }

    #[test]
    fn nav_sat_satellites() {
        let mut p = P::default().u4(9).u1(1).u1(3).zeros(2).0;
        p.extend(sat_block(6, 2, 33, 27, 63, true).0);
        p.extend(sat_block(0, 5, 19, -91, 360, false).0);
        p.extend(sat_block(1, 133, 0, 10, -1, false).0);
        let m = decode_nav_sat(&p).unwrap();
        assert_eq!((m.itow_ms, m.num_svs, m.len, m.dropped), (9, 3, 3, 0));
        let s = m.satellites();
        assert_eq!(
            (
                s[0].gnss_id,
                s[0].sv_id,
                s[0].cno_dbhz,
                s[0].used,
                s[0].quality,
                s[0].health
            ),
            (6, 2, 33, true, 7, 1)
        );
        assert_eq!(
            (s[0].elevation_deg(), s[0].azimuth_deg(), s[0].pr_res_m),
            (Some(27), Some(63), -0.7)
        );
        assert_eq!(
            (s[1].elevation_deg(), s[1].azimuth_deg(), s[1].used),
            (None, Some(0), false)
        );
        assert_eq!(s[2].azimuth_deg(), None);
        assert!(decode_nav_sat(&p[..p.len() - 1]).is_err());
        let mut v2 = p.clone();
        v2[4] = 2;
        assert_eq!(
            decode_nav_sat(&v2),
            Err(UbxError::Version {
                name: "NAV-SAT",
                version: 2
            })
        );
        // More satellites than fit: counted, not stored.
        let mut big = P::default().u4(9).u1(1).u1(70).zeros(2).0;
        for i in 0..70u8 {
            big.extend(sat_block(0, i + 1, 30, 10, 10, i % 2 == 0).0);
        }
        let m = decode_nav_sat(&big).unwrap();
        assert_eq!((m.len, m.dropped, m.satellites().len()), (MAX_SATS, 6, MAX_SATS));
    }

    #[test]
    fn nav_svinfo_satellites_in_legacy_numbering() {
        let ch = |chn: u8, svid: u8, flags: u8| {
            P::default()
                .u1(chn)
                .u1(svid)
                .u1(flags)
                .u1(7)
                .u1(40)
                .i1(45)
                .i2(200)
                .i4(-123)
                .0
        };
        let mut p = P::default().u4(5).u1(4).u1(4).zeros(2).0;
        p.extend(ch(0, 12, 0x0D));
        p.extend(ch(1, 70, 0x10));
        p.extend(ch(2, 0, 0));
        p.extend(ch(3, 214, 0x01));
        let m = decode_nav_svinfo(&p).unwrap();
        assert_eq!((m.num_ch, m.global_flags, m.len, m.unknown), (4, 4, 3, 1));
        let s = m.satellites();
        assert_eq!(
            (s[0].gnss_id, s[0].sv_id, s[0].used, s[0].health, s[0].pr_res_m),
            (0, 12, true, 1, -1.23)
        );
        assert_eq!((s[1].gnss_id, s[1].sv_id, s[1].used, s[1].health), (6, 6, false, 2));
        assert_eq!((s[2].gnss_id, s[2].sv_id, m.chn[2]), (2, 4, 3));
        assert!(decode_nav_svinfo(&p[..20]).is_err());
        assert_eq!(legacy_sv(40), Some((3, 13)));
        assert_eq!(legacy_sv(160), Some((3, 2)));
        assert_eq!((legacy_sv(100), legacy_sv(0)), (None, None));
    }
}
