//! UBX-TIM decoders: the time pulse and time marks (u-blox 8 / M8 Receiver Description incl.
//! Protocol Specification, UBX-13003221, and u-blox F9 HPG Interface Description,
//! UBX-22008968: "UBX-TIM-TP", "UBX-TIM-TM2").

use super::messages::{UbxError, expect_len, i4, u1, u2, u4};

/// Nanoseconds per millisecond.
const NS_PER_MS: u64 = 1_000_000;

/// UBX-TIM-TP (0x0D 0x01), Time pulse time data: 16 bytes. Sent before each time pulse, it
/// gives the time of the **next** pulse and the quantisation error of that pulse.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TimTp {
    /// Time of week of the next pulse in the time base of `flags` bit 0, ms.
    pub tow_ms: u32,
    /// Sub-millisecond part of the time of week, 2^−32 ms.
    pub tow_sub_ms: u32,
    /// Quantisation error of the next pulse (pulse time − true time), ps.
    pub q_err_ps: i32,
    /// Week number of the next pulse in the same time base.
    pub week: u16,
    /// Flags: bit 0 `timeBase` (0 GNSS, 1 UTC), 1 `utc` (UTC available), 2–3 `raim`
    /// (0 n/a, 1 inactive, 2 active), 4 `qErrInvalid`, 5 `TpNotLocked` (protocol 32+).
    pub flags: u8,
    /// Time reference: bits 0–3 `timeRefGnss` (0 GPS, 1 GLONASS, 2 BeiDou, 3 Galileo) when the
    /// time base is GNSS, bits 4–7 `utcStandard` when it is UTC.
    pub ref_info: u8,
}

impl TimTp {
    /// The time base of `tow_ms`/`week` is UTC (else the GNSS of `ref_info`).
    pub fn utc_time_base(&self) -> bool {
        self.flags & 0x01 != 0
    }

    /// The quantisation error is valid (bit 4 clear; always on receivers before protocol 32).
    pub fn q_err_valid(&self) -> bool {
        self.flags & 0x10 == 0
    }

    /// Time of week of the next pulse in its time base, ns (the sub-millisecond part rounded
    /// to the ns).
    pub fn tow_ns(&self) -> i64 {
        let sub_ns = (u64::from(self.tow_sub_ms) * NS_PER_MS + (1 << 31)) >> 32;
        (u64::from(self.tow_ms) * NS_PER_MS + sub_ns) as i64
    }
}

/// UBX-TIM-TP (0x0D 0x01): see [`TimTp`].
pub fn decode_tim_tp(p: &[u8]) -> Result<TimTp, UbxError> {
    expect_len("TIM-TP", p, &[16], "16")?;
    Ok(TimTp {
        tow_ms: u4(p, 0),
        tow_sub_ms: u4(p, 4),
        q_err_ps: i4(p, 8),
        week: u2(p, 12),
        flags: u1(p, 14),
        ref_info: u1(p, 15),
    })
}

/// UBX-TIM-TM2 (0x0D 0x03), Time mark data: 28 bytes. The times of the last rising and
/// falling edges on an EXTINT input.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TimTm2 {
    /// Channel (EXTINT input) of the time mark.
    pub ch: u8,
    /// Flags: bit 0 `mode` (1 running), 1 `run`, 2 `newFallingEdge`, 3–4 `timeBase` (0
    /// receiver, 1 GNSS, 2 UTC), 5 `utc` available, 6 `time` valid, 7 `newRisingEdge`.
    pub flags: u8,
    /// Rising-edge counter.
    pub count: u16,
    /// Week number of the last rising edge.
    pub week_rising: u16,
    /// Week number of the last falling edge.
    pub week_falling: u16,
    /// Time of week of the last rising edge, ms.
    pub tow_rising_ms: u32,
    /// Sub-millisecond part of the rising edge time, ns.
    pub tow_sub_rising_ns: u32,
    /// Time of week of the last falling edge, ms.
    pub tow_falling_ms: u32,
    /// Sub-millisecond part of the falling edge time, ns.
    pub tow_sub_falling_ns: u32,
    /// Accuracy estimate, ns.
    pub acc_est_ns: u32,
}

impl TimTm2 {
    /// The time of the edges is valid (`time` flag).
    pub fn time_valid(&self) -> bool {
        self.flags & 0x40 != 0
    }

    /// The time base of the edges: 0 receiver time, 1 GNSS, 2 UTC.
    pub fn time_base(&self) -> u8 {
        (self.flags >> 3) & 0x03
    }

    /// Time of week of the last rising edge, ns.
    pub fn rising_tow_ns(&self) -> i64 {
        i64::from(self.tow_rising_ms) * 1_000_000 + i64::from(self.tow_sub_rising_ns)
    }

    /// Time of week of the last falling edge, ns.
    pub fn falling_tow_ns(&self) -> i64 {
        i64::from(self.tow_falling_ms) * 1_000_000 + i64::from(self.tow_sub_falling_ns)
    }
}

/// UBX-TIM-TM2 (0x0D 0x03): see [`TimTm2`].
pub fn decode_tim_tm2(p: &[u8]) -> Result<TimTm2, UbxError> {
    expect_len("TIM-TM2", p, &[28], "28")?;
    Ok(TimTm2 {
        ch: u1(p, 0),
        flags: u1(p, 1),
        count: u2(p, 2),
        week_rising: u2(p, 4),
        week_falling: u2(p, 6),
        tow_rising_ms: u4(p, 8),
        tow_sub_rising_ns: u4(p, 12),
        tow_falling_ms: u4(p, 16),
        tow_sub_falling_ns: u4(p, 20),
        acc_est_ns: u4(p, 24),
    })
}

#[cfg(test)]
mod tests {
    use super::super::nav::tests::P;
    use super::*;

    #[test]
    fn tim_tp_next_pulse() {
        let p = P::default()
            .u4(237_870_000)
            .u4(0x8000_0000)
            .i4(-4331)
            .u2(2146)
            .u1(0x0B)
            .u1(0x0F)
            .0;
        let t = decode_tim_tp(&p).unwrap();
        assert_eq!(
            (t.tow_ms, t.q_err_ps, t.week, t.ref_info),
            (237_870_000, -4331, 2146, 0x0F)
        );
        assert!(t.utc_time_base() && t.q_err_valid());
        assert_eq!(t.tow_ns(), 237_870_000_000_000 + 500_000, "half a millisecond");
        let max = TimTp {
            tow_sub_ms: u32::MAX,
            ..t
        };
        assert_eq!(max.tow_ns(), 237_870_001_000_000, "rounds up to the next ms");
        assert!(decode_tim_tp(&p[..15]).is_err());
    }

    #[test]
    fn tim_tm2_edges() {
        let p = P::default()
            .u1(0)
            .u1(0xEC)
            .u2(17)
            .u2(2146)
            .u2(2146)
            .u4(1000)
            .u4(250)
            .u4(1500)
            .u4(999_999)
            .u4(20)
            .0;
        let t = decode_tim_tm2(&p).unwrap();
        assert_eq!((t.count, t.week_rising, t.acc_est_ns, t.time_base()), (17, 2146, 20, 1));
        assert!(t.time_valid());
        assert_eq!((t.rising_tow_ns(), t.falling_tow_ns()), (1_000_000_250, 1_500_999_999));
        assert!(decode_tim_tm2(&p[..27]).is_err());
    }
}
