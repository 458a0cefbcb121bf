//! Sensor fusion (u-blox ADR/UDR receivers such as the NEO-M8L/M8U): the receiver's own
//! sensor readings (UBX-ESF-MEAS, UBX-ESF-RAW) and its high-rate fused solution
//! (UBX-HNR-PVT). Sections of u-blox 8 / M8 Receiver Description incl. Protocol
//! Specification (UBX-13003221).

use super::messages::{MAX_ESF, UbxError, expect_len, i4, u1, u2, u4};

/// One sensor reading: a 24-bit signed value and its type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EsfData {
    /// Data type (M8 protocol, "UBX-ESF-MEAS", data type table): e.g. 5 gyroscope z angular
    /// rate, 11 speed ticks, 12 gyroscope temperature, 16/17/18 accelerometer x/y/z.
    pub data_type: u8,
    /// The 24-bit value, sign-extended; its scale depends on `data_type`.
    pub value: i32,
}

impl EsfData {
    const EMPTY: EsfData = EsfData { data_type: 0, value: 0 };

    fn from_word(w: u32) -> Self {
        Self {
            data_type: ((w >> 24) & 0x3F) as u8,
            // Sign-extend the low 24 bits.
            value: ((w << 8) as i32) >> 8,
        }
    }
}

/// UBX-ESF-MEAS (0x10 0x02), External sensor fusion measurements: 8 + 4·`numMeas` bytes, plus
/// 4 when `calibTtagValid`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EsfMeas {
    /// Time tag of the measurements (sensor or receiver time, as configured), ms.
    pub time_tag_ms: u32,
    /// Flags: bits 0–1 `timeMarkSent`, 2 `timeMarkEdge`, 3 `calibTtagValid`, 11–15 `numMeas`.
    pub flags: u16,
    /// Data provider identification.
    pub id: u16,
    /// The readings; `data[..len]` are valid.
    pub data: [EsfData; MAX_ESF],
    /// Valid entries of `data`.
    pub len: usize,
    /// Readings that did not fit.
    pub dropped: usize,
    /// Receiver local time calibrated, ms (`calibTtag`, when `calibTtagValid`).
    pub calib_ttag_ms: Option<u32>,
}

impl EsfMeas {
    /// The readings decoded.
    pub fn readings(&self) -> &[EsfData] {
        self.data.get(..self.len).unwrap_or(&[])
    }
}

/// UBX-ESF-MEAS (0x10 0x02): see [`EsfMeas`].
pub fn decode_esf_meas(p: &[u8]) -> Result<EsfMeas, UbxError> {
    const EXPECTED: &str = "8 + 4·numMeas (+ 4 with calibTtag)";
    if p.len() < 8 {
        return Err(UbxError::Length {
            name: "ESF-MEAS",
            len: p.len(),
            expected: EXPECTED,
        });
    }
    let flags = u2(p, 4);
    let n = usize::from(flags >> 11);
    let calib = flags & 0x08 != 0;
    let len = 8 + 4 * n + if calib { 4 } else { 0 };
    expect_len("ESF-MEAS", p, &[len], EXPECTED)?;
    let mut out = EsfMeas {
        time_tag_ms: u4(p, 0),
        flags,
        id: u2(p, 6),
        data: [EsfData::EMPTY; MAX_ESF],
        len: n.min(MAX_ESF),
        dropped: n.saturating_sub(MAX_ESF),
        calib_ttag_ms: calib.then(|| u4(p, 8 + 4 * n)),
    };
    for (i, d) in out.data.iter_mut().take(n).enumerate() {
        *d = EsfData::from_word(u4(p, 8 + 4 * i));
    }
    Ok(out)
}

/// One reading of ESF-RAW with its sensor time tag.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EsfRawData {
    /// The reading.
    pub data: EsfData,
    /// Sensor time tag, sensor ticks (the sensor's own clock).
    pub s_ttag: u32,
}

/// UBX-ESF-RAW (0x10 0x03), Raw sensor measurements: 4 + 8·N bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EsfRaw {
    /// The readings; `data[..len]` are valid.
    pub data: [EsfRawData; MAX_ESF],
    /// Valid entries of `data`.
    pub len: usize,
    /// Readings that did not fit.
    pub dropped: usize,
}

impl EsfRaw {
    /// The readings decoded.
    pub fn readings(&self) -> &[EsfRawData] {
        self.data.get(..self.len).unwrap_or(&[])
    }
}

/// UBX-ESF-RAW (0x10 0x03): see [`EsfRaw`].
pub fn decode_esf_raw(p: &[u8]) -> Result<EsfRaw, UbxError> {
    if p.len() < 4 || !(p.len() - 4).is_multiple_of(8) {
        return Err(UbxError::Length {
            name: "ESF-RAW",
            len: p.len(),
            expected: "4 + 8·N",
        });
    }
    let n = (p.len() - 4) / 8;
    let empty = EsfRawData {
        data: EsfData::EMPTY,
        s_ttag: 0,
    };
    let mut out = EsfRaw {
        data: [empty; MAX_ESF],
        len: n.min(MAX_ESF),
        dropped: n.saturating_sub(MAX_ESF),
    };
    for (i, d) in out.data.iter_mut().take(n).enumerate() {
        let o = 4 + 8 * i;
        *d = EsfRawData {
            data: EsfData::from_word(u4(p, o)),
            s_ttag: u4(p, o + 4),
        };
    }
    Ok(out)
}

/// UBX-HNR-PVT (0x28 0x00), High rate output of PVT solution: 72 bytes. The fused
/// (GNSS + sensors) solution at the high navigation rate, between and independent of the
/// NAV epochs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HnrPvt {
    /// GPS time of week of the solution, ms.
    pub itow_ms: u32,
    /// UTC year.
    pub year: u16,
    /// UTC month, 1..=12.
    pub month: u8,
    /// UTC day.
    pub day: u8,
    /// UTC hour.
    pub hour: u8,
    /// UTC minute.
    pub min: u8,
    /// UTC second, 0..=60.
    pub sec: u8,
    /// Validity flags as NAV-PVT's: bit 0 `validDate`, 1 `validTime`, 2 `fullyResolved`.
    pub valid: u8,
    /// Fraction of the second, ns (may be negative).
    pub nano_ns: i32,
    /// GPS fix type, as [`super::nav::NavPvt::fix_type`].
    pub gps_fix: u8,
    /// Flags: bit 0 `GPSfixOK`, 1 `DiffSoln`, 2 `WKNSET`, 3 `TOWSET`, 4 `headVehValid`.
    pub flags: u8,
    /// Longitude, degrees east (WGS-84).
    pub lon_deg: f64,
    /// Latitude, degrees north (WGS-84).
    pub lat_deg: f64,
    /// Height above the WGS-84 ellipsoid, m.
    pub height_m: f64,
    /// Height above mean sea level, m.
    pub h_msl_m: f64,
    /// Ground speed (2D), m/s.
    pub g_speed_mps: f64,
    /// Speed (3D), m/s.
    pub speed_mps: f64,
    /// Heading of motion (2D), degrees.
    pub head_mot_deg: f64,
    /// Heading of vehicle (2D), degrees.
    pub head_veh_deg: f64,
    /// Horizontal accuracy estimate, m.
    pub h_acc_m: f64,
    /// Vertical accuracy estimate, m.
    pub v_acc_m: f64,
    /// Speed accuracy estimate, m/s.
    pub s_acc_mps: f64,
    /// Heading accuracy estimate, degrees.
    pub head_acc_deg: f64,
}

impl HnrPvt {
    /// `validDate` and `validTime`.
    pub fn valid_date_time(&self) -> bool {
        self.valid & 0x03 == 0x03
    }

    /// `GPSfixOK`.
    pub fn fix_ok(&self) -> bool {
        self.flags & 0x01 != 0
    }

    /// `DiffSoln`.
    pub fn diff_soln(&self) -> bool {
        self.flags & 0x02 != 0
    }
}

/// UBX-HNR-PVT (0x28 0x00): see [`HnrPvt`].
pub fn decode_hnr_pvt(p: &[u8]) -> Result<HnrPvt, UbxError> {
    expect_len("HNR-PVT", p, &[72], "72")?;
    let milli = |o| f64::from(i4(p, o)) / 1e3;
    let deg5 = |o| f64::from(i4(p, o)) / 1e5;
    Ok(HnrPvt {
        itow_ms: u4(p, 0),
        year: u2(p, 4),
        month: u1(p, 6),
        day: u1(p, 7),
        hour: u1(p, 8),
        min: u1(p, 9),
        sec: u1(p, 10),
        valid: u1(p, 11),
        nano_ns: i4(p, 12),
        gps_fix: u1(p, 16),
        flags: u1(p, 17),
        lon_deg: f64::from(i4(p, 20)) / 1e7,
        lat_deg: f64::from(i4(p, 24)) / 1e7,
        height_m: milli(28),
        h_msl_m: milli(32),
        g_speed_mps: milli(36),
        speed_mps: milli(40),
        head_mot_deg: deg5(44),
        head_veh_deg: deg5(48),
        h_acc_m: f64::from(u4(p, 52)) / 1e3,
        v_acc_m: f64::from(u4(p, 56)) / 1e3,
        s_acc_mps: f64::from(u4(p, 60)) / 1e3,
        head_acc_deg: f64::from(u4(p, 64)) / 1e5,
    })
}

#[cfg(test)]
mod tests {
    use super::super::nav::tests::P;
    use super::*;

    #[test]
    fn esf_meas_readings() {
        // 3 readings and the calibrated time tag.
        let p = P::default()
            .u4(1000)
            .u2((3 << 11) | 0x08)
            .u2(0)
            .u4((16 << 24) | 0x00FF_FFFF)
            .u4((17 << 24) | 0x0000_0010)
            .u4((5 << 24) | 0x0080_0000)
            .u4(777)
            .0;
        let m = decode_esf_meas(&p).unwrap();
        assert_eq!((m.time_tag_ms, m.len, m.calib_ttag_ms), (1000, 3, Some(777)));
        let r = m.readings();
        assert_eq!(
            r[0],
            EsfData {
                data_type: 16,
                value: -1
            }
        );
        assert_eq!(
            r[1],
            EsfData {
                data_type: 17,
                value: 16
            }
        );
        assert_eq!(r[2].value, -(1 << 23));
        assert!(decode_esf_meas(&p[..20]).is_err(), "calibTtag announced but missing");
        assert!(decode_esf_meas(&[0; 7]).is_err());
    }

    #[test]
    fn esf_raw_readings() {
        let p = P::default()
            .zeros(4)
            .u4((14 << 24) | 5)
            .u4(123)
            .u4((13 << 24) | 0x00FF_FFFE)
            .u4(124)
            .0;
        let m = decode_esf_raw(&p).unwrap();
        assert_eq!(m.len, 2);
        assert_eq!(
            m.readings()[1].data,
            EsfData {
                data_type: 13,
                value: -2
            }
        );
        assert_eq!(m.readings()[1].s_ttag, 124);
        assert!(decode_esf_raw(&p[..19]).is_err() && decode_esf_raw(&[]).is_err());
    }

    #[test]
    fn hnr_pvt_fields() {
        let p = P::default()
            .u4(228_730_100)
            .u2(2024)
            .u1(1)
            .u1(30)
            .u1(15)
            .u1(31)
            .u1(52)
            .u1(0x37)
            .i4(100_000_000)
            .u1(4)
            .u1(0x1D)
            .zeros(2)
            .i4(93_117_355)
            .i4(487_409_630)
            .i4(311_793)
            .i4(264_182)
            .i4(407)
            .i4(500)
            .i4(24_919_370)
            .i4(1_000_000)
            .u4(5_124)
            .u4(11_540)
            .u4(310)
            .u4(484_090)
            .zeros(4)
            .0;
        let h = decode_hnr_pvt(&p).unwrap();
        assert_eq!(
            (h.itow_ms, h.year, h.sec, h.nano_ns, h.gps_fix),
            (228_730_100, 2024, 52, 100_000_000, 4)
        );
        assert!(h.valid_date_time() && h.fix_ok() && !h.diff_soln());
        assert_eq!((h.lat_deg, h.lon_deg), (48.740_963, 9.311_735_5));
        assert_eq!(
            (h.height_m, h.h_msl_m, h.g_speed_mps, h.speed_mps),
            (311.793, 264.182, 0.407, 0.5)
        );
        assert_eq!((h.h_acc_m, h.v_acc_m, h.s_acc_mps), (5.124, 11.54, 0.31));
        assert!((h.head_mot_deg - 249.1937).abs() < 1e-9 && (h.head_acc_deg - 4.8409).abs() < 1e-9);
        assert!(decode_hnr_pvt(&p[..71]).is_err());
    }
}
