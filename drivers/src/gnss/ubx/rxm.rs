//! UBX-RXM decoders: raw measurements and broadcast navigation data (u-blox 8 / M8 Receiver
//! Description incl. Protocol Specification, UBX-13003221, and u-blox F9 HPG Interface
//! Description, UBX-22008968: "UBX-RXM-RAWX", "UBX-RXM-SFRBX").

use super::messages::{MAX_MEAS, MAX_WORDS, UbxError, expect_blocks, i1, r4, r8, u1, u2, u4};

/// One measurement of RXM-RAWX.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RawxMeas {
    /// Pseudorange, m.
    pub pr_mes_m: f64,
    /// Carrier phase, cycles.
    pub cp_mes_cycles: f64,
    /// Doppler (positive towards the satellite), Hz.
    pub do_mes_hz: f32,
    /// GNSS (`gnssId`, as in NAV-SAT).
    pub gnss_id: u8,
    /// Satellite number within its GNSS.
    pub sv_id: u8,
    /// Signal (`sigId`, F9; reserved 0 on M8).
    pub sig_id: u8,
    /// GLONASS frequency slot + 7 (0..=13).
    pub freq_id: u8,
    /// Carrier phase locktime, ms (capped at 64500).
    pub locktime_ms: u16,
    /// Carrier-to-noise density ratio, dBHz.
    pub cno_dbhz: u8,
    /// Pseudorange standard deviation, m (0.01 × 2^n).
    pub pr_stdev_m: f64,
    /// Carrier phase standard deviation, cycles (0.004 × n).
    pub cp_stdev_cycles: f64,
    /// Doppler standard deviation, Hz (0.002 × 2^n).
    pub do_stdev_hz: f64,
    /// Tracking status: bit 0 `prValid`, 1 `cpValid`, 2 `halfCyc`, 3 `subHalfCyc`.
    pub trk_stat: u8,
}

impl RawxMeas {
    const EMPTY: RawxMeas = RawxMeas {
        pr_mes_m: 0.0,
        cp_mes_cycles: 0.0,
        do_mes_hz: 0.0,
        gnss_id: 0,
        sv_id: 0,
        sig_id: 0,
        freq_id: 0,
        locktime_ms: 0,
        cno_dbhz: 0,
        pr_stdev_m: 0.0,
        cp_stdev_cycles: 0.0,
        do_stdev_hz: 0.0,
        trk_stat: 0,
    };
}

/// UBX-RXM-RAWX (0x02 0x15), Multi-GNSS raw measurements: 16 + 32·`numMeas` bytes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RxmRawx {
    /// Receiver local time of week of the measurements (GPS time scale), s.
    pub rcv_tow_s: f64,
    /// GPS week of the measurements.
    pub week: u16,
    /// GPS − UTC leap seconds, s (0 when unknown).
    pub leap_s: i8,
    /// Measurements announced (`numMeas`).
    pub num_meas: u8,
    /// Receiver status: bit 0 `leapSec` (leap seconds known), 1 `clkReset`.
    pub rec_stat: u8,
    /// Message version (F9: 1; M8: reserved 0).
    pub version: u8,
    /// The first [`MAX_MEAS`] measurements; `meas[..len]` are valid.
    pub meas: [RawxMeas; MAX_MEAS],
    /// Valid entries of `meas`.
    pub len: usize,
    /// Measurements that did not fit.
    pub dropped: usize,
}

impl RxmRawx {
    /// The measurements decoded.
    pub fn measurements(&self) -> &[RawxMeas] {
        self.meas.get(..self.len).unwrap_or(&[])
    }
}

/// UBX-RXM-RAWX (0x02 0x15): see [`RxmRawx`].
pub fn decode_rxm_rawx(p: &[u8]) -> Result<RxmRawx, UbxError> {
    if p.len() < 16 {
        return Err(UbxError::Length {
            name: "RXM-RAWX",
            len: p.len(),
            expected: "16 + 32·numMeas",
        });
    }
    let n = usize::from(u1(p, 11));
    expect_blocks("RXM-RAWX", p, 16, 32, n, "16 + 32·numMeas")?;
    let mut out = RxmRawx {
        rcv_tow_s: r8(p, 0),
        week: u2(p, 8),
        leap_s: i1(p, 10),
        num_meas: u1(p, 11),
        rec_stat: u1(p, 12),
        version: u1(p, 13),
        meas: [RawxMeas::EMPTY; MAX_MEAS],
        len: n.min(MAX_MEAS),
        dropped: n.saturating_sub(MAX_MEAS),
    };
    for (i, m) in out.meas.iter_mut().take(n).enumerate() {
        let o = 16 + 32 * i;
        *m = RawxMeas {
            pr_mes_m: r8(p, o),
            cp_mes_cycles: r8(p, o + 8),
            do_mes_hz: r4(p, o + 16),
            gnss_id: u1(p, o + 20),
            sv_id: u1(p, o + 21),
            sig_id: u1(p, o + 22),
            freq_id: u1(p, o + 23),
            locktime_ms: u2(p, o + 24),
            cno_dbhz: u1(p, o + 26),
            pr_stdev_m: 0.01 * f64::from(1u32 << (u1(p, o + 27) & 0x0F)),
            cp_stdev_cycles: 0.004 * f64::from(u1(p, o + 28) & 0x0F),
            do_stdev_hz: 0.002 * f64::from(1u32 << (u1(p, o + 29) & 0x0F)),
            trk_stat: u1(p, o + 30),
        };
    }
    Ok(out)
}

/// UBX-RXM-SFRBX (0x02 0x13), Broadcast navigation data subframe: 8 + 4·`numWords` bytes.
/// The data words are delivered as the receiver sent them (their layout depends on the GNSS
/// and signal; see the protocol's "Broadcast navigation data" section).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RxmSfrbx {
    /// GNSS (`gnssId`).
    pub gnss_id: u8,
    /// Satellite number within its GNSS.
    pub sv_id: u8,
    /// Signal (`sigId`, F9; reserved on M8).
    pub sig_id: u8,
    /// GLONASS frequency slot + 7.
    pub freq_id: u8,
    /// Words announced (`numWords`).
    pub num_words: u8,
    /// Tracking channel (`chn`; reserved on early M8 firmware).
    pub chn: u8,
    /// Message version (0x01 or 0x02).
    pub version: u8,
    /// The first [`MAX_WORDS`] data words, unchanged; `words[..len]` are valid.
    pub words: [u32; MAX_WORDS],
    /// Valid entries of `words`.
    pub len: usize,
    /// Words that did not fit.
    pub dropped: usize,
}

impl RxmSfrbx {
    /// The data words.
    pub fn data_words(&self) -> &[u32] {
        self.words.get(..self.len).unwrap_or(&[])
    }
}

/// UBX-RXM-SFRBX (0x02 0x13): see [`RxmSfrbx`].
pub fn decode_rxm_sfrbx(p: &[u8]) -> Result<RxmSfrbx, UbxError> {
    if p.len() < 8 {
        return Err(UbxError::Length {
            name: "RXM-SFRBX",
            len: p.len(),
            expected: "8 + 4·numWords",
        });
    }
    let n = usize::from(u1(p, 4));
    expect_blocks("RXM-SFRBX", p, 8, 4, n, "8 + 4·numWords")?;
    let mut out = RxmSfrbx {
        gnss_id: u1(p, 0),
        sv_id: u1(p, 1),
        sig_id: u1(p, 2),
        freq_id: u1(p, 3),
        num_words: u1(p, 4),
        chn: u1(p, 5),
        version: u1(p, 6),
        words: [0; MAX_WORDS],
        len: n.min(MAX_WORDS),
        dropped: n.saturating_sub(MAX_WORDS),
    };
    for (i, w) in out.words.iter_mut().take(n).enumerate() {
        *w = u4(p, 8 + 4 * i);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::super::nav::tests::P;
    use super::*;
    use navsync_shared::samples::MAX_RAW_MEASUREMENTS;

    #[test]
    fn rxm_rawx_measurements() {
        let head = |n: u8| {
            P::default()
                .r8(453_600.25)
                .u2(2146)
                .i1(18)
                .u1(n)
                .u1(0x01)
                .u1(1)
                .zeros(2)
        };
        let meas_sig = |sv: u8, sig: u8| {
            P::default()
                .r8(21_000_000.5)
                .r8(110_000_000.25)
                .r4(-1234.5)
                .u1(0)
                .u1(sv)
                .u1(sig)
                .u1(0)
                .u2(64_500)
                .u1(45)
                .u1(3)
                .u1(5)
                .u1(2)
                .u1(0x07)
                .u1(0)
        };
        let meas = |sv| meas_sig(sv, 0);
        let mut p = head(2).0;
        p.extend(meas(5).0);
        p.extend(meas(9).0);
        let m = decode_rxm_rawx(&p).unwrap();
        assert_eq!(
            (m.rcv_tow_s, m.week, m.leap_s, m.num_meas, m.rec_stat, m.version),
            (453_600.25, 2146, 18, 2, 1, 1)
        );
        let r = m.measurements();
        assert_eq!(
            (r.len(), r[1].sv_id, r[0].pr_mes_m, r[0].cp_mes_cycles, r[0].do_mes_hz),
            (2, 9, 21_000_000.5, 110_000_000.25, -1234.5)
        );
        assert_eq!((r[0].locktime_ms, r[0].cno_dbhz, r[0].trk_stat), (64_500, 45, 7));
        assert_eq!(
            (r[0].pr_stdev_m, r[0].cp_stdev_cycles, r[0].do_stdev_hz),
            (0.08, 0.02, 0.008)
        );
        assert!(decode_rxm_rawx(&p[..p.len() - 32]).is_err(), "numMeas says 2");
        // An all-band receiver's 70 signals, L5 first in its order: all decoded; the sample's
        // 64 are the 15 L1 C/A, the 25 L2C and the first 24 L5, the other 6 counted.
        let mut big = head(70).0;
        for i in 0..70u8 {
            let sig = match i {
                0..30 => 7,
                30..55 => 3,
                _ => 0,
            };
            big.extend(meas_sig(i, sig).0);
        }
        let m = decode_rxm_rawx(&big).unwrap();
        assert_eq!((m.len, m.dropped), (70, 0));
        let raw = super::super::samples::raw_sample(&m, 0, 0);
        assert_eq!((usize::from(raw.num_meas), raw.dropped), (MAX_RAW_MEASUREMENTS, 6));
        let kept: Vec<(u8, u8)> = raw.meas.iter().map(|r| (r.sig_id, r.sv_id)).collect();
        let want: Vec<(u8, u8)> = (55..70)
            .map(|sv| (0, sv))
            .chain((30..55).map(|sv| (3, sv)))
            .chain((0..24).map(|sv| (7, sv)))
            .collect();
        assert_eq!(kept, want);
    }

    #[test]
    fn rxm_sfrbx_words_unchanged() {
        let mut p = P::default().u1(0).u1(3).u1(0).u1(0).u1(10).u1(4).u1(2).u1(0).0;
        for w in 0..10u32 {
            p.extend((0x22C0_0000 + w).to_le_bytes());
        }
        let m = decode_rxm_sfrbx(&p).unwrap();
        assert_eq!((m.gnss_id, m.sv_id, m.num_words, m.chn, m.version), (0, 3, 10, 4, 2));
        assert_eq!(
            m.data_words(),
            (0..10).map(|w| 0x22C0_0000 + w).collect::<Vec<u32>>().as_slice()
        );
        assert!(decode_rxm_sfrbx(&p[..44]).is_err());
        let mut long = P::default().u1(0).u1(3).u1(0).u1(0).u1(20).u1(4).u1(2).u1(0).0;
        long.extend([0u8; 80]);
        assert_eq!(decode_rxm_sfrbx(&long).map(|m| (m.len, m.dropped)), Ok((MAX_WORDS, 4)));
    }
}
