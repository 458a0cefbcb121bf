//! UBX message decoding: payload bytes → typed structs, one pure function per message.
//!
//! Layouts follow u-blox 8 / M8 Receiver Description incl. Protocol Specification
//! (UBX-13003221) and u-blox F9 HPG Interface Description (UBX-22008968); each decoder names
//! its section ("UBX-NAV-PVT" …). The decoders live by class: [`super::nav`], [`super::tim`],
//! [`super::rxm`], [`super::esf`] (with HNR), [`super::mon`] (with ACK). All multi-byte fields
//! are little-endian.
//!
//! A payload of a length the message cannot have is a [`UbxError`], never a panic or an
//! out-of-bounds read. Repeated blocks (satellites, measurements, words) go into fixed-capacity
//! arrays ([`MAX_SATS`], [`MAX_MEAS`], …); blocks that did not fit are counted in the struct.

use super::esf::{EsfMeas, EsfRaw, HnrPvt};
use super::mon::{Ack, MonVer};
use super::nav::{
    NavDop, NavEoe, NavPosllh, NavPvt, NavSat, NavSol, NavStatus, NavSvinfo, NavTimegps, NavTimeutc, NavVelned,
};
use super::rxm::{RxmRawx, RxmSfrbx};
use super::tim::{TimTm2, TimTp};

/// Satellites kept from one NAV-SAT / NAV-SVINFO.
pub const MAX_SATS: usize = 64;
/// Measurements kept from one RXM-RAWX: all its one-byte `numMeas` can announce (an all-band
/// receiver reports 70 and more; the sample keeps what [`RawMeasurement::keep_rank`] ranks
/// first).
///
/// [`RawMeasurement::keep_rank`]: navsync_shared::samples::RawMeasurement::keep_rank
pub const MAX_MEAS: usize = 255;
/// Data words kept from one RXM-SFRBX (GPS L1 C/A: 10, Galileo I/NAV: 8, BeiDou: 10).
pub const MAX_WORDS: usize = 16;
/// Sensor readings kept from one ESF-MEAS / ESF-RAW.
pub const MAX_ESF: usize = 32;
/// Extension strings kept from one MON-VER.
pub const MAX_EXTENSIONS: usize = 8;

/// Why a payload could not be decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum UbxError {
    /// The payload length is not one the message can have.
    #[error("{name}: payload of {len} bytes, expected {expected}")]
    Length {
        /// The message, e.g. `NAV-PVT`.
        name: &'static str,
        /// The payload length received, bytes.
        len: usize,
        /// The lengths it can have, for the log (e.g. `92`, `8 + 12·numSvs`).
        expected: &'static str,
    },
    /// The message carries a version field whose value this decoder does not know.
    #[error("{name}: unknown message version {version}")]
    Version {
        /// The message.
        name: &'static str,
        /// The version received.
        version: u8,
    },
}

/// Checks that `p` is exactly one of `lens` bytes long.
pub(crate) fn expect_len(name: &'static str, p: &[u8], lens: &[usize], expected: &'static str) -> Result<(), UbxError> {
    if lens.contains(&p.len()) {
        Ok(())
    } else {
        Err(UbxError::Length {
            name,
            len: p.len(),
            expected,
        })
    }
}

/// Checks that `p` is `head + block·n` bytes with `n` the count announced in the payload.
pub(crate) fn expect_blocks(
    name: &'static str,
    p: &[u8],
    head: usize,
    block: usize,
    n: usize,
    expected: &'static str,
) -> Result<(), UbxError> {
    if p.len() == head + block * n {
        Ok(())
    } else {
        Err(UbxError::Length {
            name,
            len: p.len(),
            expected,
        })
    }
}

/// Little-endian field readers over a payload; out of range reads give 0 (decoders check the
/// length first, so that never happens on their own offsets).
pub(crate) fn bytes<const N: usize>(p: &[u8], off: usize) -> [u8; N] {
    off.checked_add(N)
        .and_then(|end| p.get(off..end))
        .and_then(|s| <[u8; N]>::try_from(s).ok())
        .unwrap_or([0; N])
}

/// `U1` at `off`.
pub(crate) fn u1(p: &[u8], off: usize) -> u8 {
    p.get(off).copied().unwrap_or(0)
}

/// `I1` at `off`.
pub(crate) fn i1(p: &[u8], off: usize) -> i8 {
    i8::from_le_bytes(bytes(p, off))
}

/// `U2` at `off`.
pub(crate) fn u2(p: &[u8], off: usize) -> u16 {
    u16::from_le_bytes(bytes(p, off))
}

/// `I2` at `off`.
pub(crate) fn i2(p: &[u8], off: usize) -> i16 {
    i16::from_le_bytes(bytes(p, off))
}

/// `U4` at `off`.
pub(crate) fn u4(p: &[u8], off: usize) -> u32 {
    u32::from_le_bytes(bytes(p, off))
}

/// `I4` at `off`.
pub(crate) fn i4(p: &[u8], off: usize) -> i32 {
    i32::from_le_bytes(bytes(p, off))
}

/// `R4` at `off`.
pub(crate) fn r4(p: &[u8], off: usize) -> f32 {
    f32::from_le_bytes(bytes(p, off))
}

/// `R8` at `off`.
pub(crate) fn r8(p: &[u8], off: usize) -> f64 {
    f64::from_le_bytes(bytes(p, off))
}

/// A decoded UBX message. Held by value (on the stack while a frame is handled): the
/// variable-length messages' fixed arrays make some variants a few kB, which is the price of
/// decoding without allocation.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Message {
    /// UBX-NAV-PVT.
    NavPvt(NavPvt),
    /// UBX-NAV-SOL.
    NavSol(NavSol),
    /// UBX-NAV-TIMEGPS.
    NavTimegps(NavTimegps),
    /// UBX-NAV-POSLLH.
    NavPosllh(NavPosllh),
    /// UBX-NAV-VELNED.
    NavVelned(NavVelned),
    /// UBX-NAV-DOP.
    NavDop(NavDop),
    /// UBX-NAV-STATUS.
    NavStatus(NavStatus),
    /// UBX-NAV-TIMEUTC.
    NavTimeutc(NavTimeutc),
    /// UBX-NAV-SAT.
    NavSat(NavSat),
    /// UBX-NAV-SVINFO.
    NavSvinfo(NavSvinfo),
    /// UBX-NAV-EOE.
    NavEoe(NavEoe),
    /// UBX-TIM-TP.
    TimTp(TimTp),
    /// UBX-TIM-TM2.
    TimTm2(TimTm2),
    /// UBX-RXM-RAWX.
    RxmRawx(RxmRawx),
    /// UBX-RXM-SFRBX.
    RxmSfrbx(RxmSfrbx),
    /// UBX-ESF-MEAS.
    EsfMeas(EsfMeas),
    /// UBX-ESF-RAW.
    EsfRaw(EsfRaw),
    /// UBX-HNR-PVT.
    HnrPvt(HnrPvt),
    /// UBX-MON-VER.
    MonVer(MonVer),
    /// UBX-ACK-ACK.
    AckAck(Ack),
    /// UBX-ACK-NAK.
    AckNak(Ack),
    /// A message this front end does not decode.
    Other {
        /// Message class.
        class: u8,
        /// Message id.
        id: u8,
    },
}

impl Message {
    /// The message's name, e.g. `NAV-PVT` (`?` for [`Message::Other`]).
    pub fn name(&self) -> &'static str {
        match self {
            Self::NavPvt(_) => "NAV-PVT",
            Self::NavSol(_) => "NAV-SOL",
            Self::NavTimegps(_) => "NAV-TIMEGPS",
            Self::NavPosllh(_) => "NAV-POSLLH",
            Self::NavVelned(_) => "NAV-VELNED",
            Self::NavDop(_) => "NAV-DOP",
            Self::NavStatus(_) => "NAV-STATUS",
            Self::NavTimeutc(_) => "NAV-TIMEUTC",
            Self::NavSat(_) => "NAV-SAT",
            Self::NavSvinfo(_) => "NAV-SVINFO",
            Self::NavEoe(_) => "NAV-EOE",
            Self::TimTp(_) => "TIM-TP",
            Self::TimTm2(_) => "TIM-TM2",
            Self::RxmRawx(_) => "RXM-RAWX",
            Self::RxmSfrbx(_) => "RXM-SFRBX",
            Self::EsfMeas(_) => "ESF-MEAS",
            Self::EsfRaw(_) => "ESF-RAW",
            Self::HnrPvt(_) => "HNR-PVT",
            Self::MonVer(_) => "MON-VER",
            Self::AckAck(_) => "ACK-ACK",
            Self::AckNak(_) => "ACK-NAK",
            Self::Other { .. } => "?",
        }
    }
}

/// Decodes the payload of a UBX frame of `class`/`id`. Messages this front end does not
/// decode are [`Message::Other`].
pub fn decode(class: u8, id: u8, payload: &[u8]) -> Result<Message, UbxError> {
    use super::{esf, mon, nav, rxm, tim};
    Ok(match (class, id) {
        (0x01, 0x07) => Message::NavPvt(nav::decode_nav_pvt(payload)?),
        (0x01, 0x06) => Message::NavSol(nav::decode_nav_sol(payload)?),
        (0x01, 0x20) => Message::NavTimegps(nav::decode_nav_timegps(payload)?),
        (0x01, 0x02) => Message::NavPosllh(nav::decode_nav_posllh(payload)?),
        (0x01, 0x12) => Message::NavVelned(nav::decode_nav_velned(payload)?),
        (0x01, 0x04) => Message::NavDop(nav::decode_nav_dop(payload)?),
        (0x01, 0x03) => Message::NavStatus(nav::decode_nav_status(payload)?),
        (0x01, 0x21) => Message::NavTimeutc(nav::decode_nav_timeutc(payload)?),
        (0x01, 0x35) => Message::NavSat(nav::decode_nav_sat(payload)?),
        (0x01, 0x30) => Message::NavSvinfo(nav::decode_nav_svinfo(payload)?),
        (0x01, 0x61) => Message::NavEoe(nav::decode_nav_eoe(payload)?),
        (0x0D, 0x01) => Message::TimTp(tim::decode_tim_tp(payload)?),
        (0x0D, 0x03) => Message::TimTm2(tim::decode_tim_tm2(payload)?),
        (0x02, 0x15) => Message::RxmRawx(rxm::decode_rxm_rawx(payload)?),
        (0x02, 0x13) => Message::RxmSfrbx(rxm::decode_rxm_sfrbx(payload)?),
        (0x10, 0x02) => Message::EsfMeas(esf::decode_esf_meas(payload)?),
        (0x10, 0x03) => Message::EsfRaw(esf::decode_esf_raw(payload)?),
        (0x28, 0x00) => Message::HnrPvt(esf::decode_hnr_pvt(payload)?),
        (0x0A, 0x04) => Message::MonVer(mon::decode_mon_ver(payload)?),
        (0x05, 0x01) => Message::AckAck(mon::decode_ack(payload)?),
        (0x05, 0x00) => Message::AckNak(mon::decode_ack(payload)?),
        _ => Message::Other { class, id },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn readers_are_little_endian_and_never_panic() {
        let p = [0x01, 0x02, 0x03, 0x04, 0xFF];
        assert_eq!(u2(&p, 0), 0x0201);
        assert_eq!(u4(&p, 0), 0x0403_0201);
        assert_eq!(i1(&p, 4), -1);
        assert_eq!(u4(&p, 3), 0, "out of range reads 0");
        assert_eq!(r8(&p, usize::MAX - 2), 0.0);
    }

    #[test]
    fn every_message_rejects_every_wrong_length_without_panicking() {
        let ids = [
            (1, 7),
            (1, 6),
            (1, 0x20),
            (1, 2),
            (1, 0x12),
            (1, 4),
            (1, 3),
            (1, 0x21),
            (1, 0x35),
            (1, 0x30),
            (1, 0x61),
            (0x0D, 1),
            (0x0D, 3),
            (2, 0x15),
            (2, 0x13),
            (0x10, 2),
            (0x10, 3),
            (0x28, 0),
            (0x0A, 4),
            (5, 1),
            (5, 0),
        ];
        let buf = [0xFFu8; 700];
        for (class, id) in ids {
            let mut ok = 0;
            for len in 0..buf.len() {
                if let Ok(m) = decode(class, id, &buf[..len]) {
                    ok += 1;
                    assert!(!matches!(m, Message::Other { .. }));
                }
            }
            assert!(ok < 100, "{class:#x}/{id:#x} accepted {ok} lengths");
        }
        assert_eq!(decode(0x27, 3, &[]), Ok(Message::Other { class: 0x27, id: 3 }));
    }
}
