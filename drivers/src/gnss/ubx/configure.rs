//! `navsync gnss --configure`: sets a u-blox receiver up for navsync, in RAM only (a power
//! cycle restores the receiver's own configuration). Pure: a state machine that says which
//! frame to write next and takes the receiver's answers.
//!
//! 1. Poll UBX-MON-VER. No answer: the port carries no UBX (an NMEA-only receiver), an error.
//! 2. The protocol version decides the generation: below 27 (u-blox 8 / M8) the legacy
//!    messages, UBX-CFG-MSG (enable each output message on the current port at every
//!    navigation epoch) and UBX-CFG-TP5 (time pulse 1: 1 Hz, 100 ms, aligned to GPS time,
//!    rising edge on the second, only when locked); from 27 (F9, M10) UBX-CFG-VALSET in the
//!    RAM layer with the same settings as configuration keys, for UART1, UART2 and USB.
//! 3. Each command waits for its UBX-ACK-ACK or -NAK (or a timeout) before the next; optional
//!    messages the receiver does not have (RXM-RAWX on a plain M8N, ESF-MEAS without sensors)
//!    are NAKed and reported, the rest still applies.
//!
//! Messages enabled: NAV-PVT, NAV-EOE, NAV-SAT, TIM-TP, TIM-TM2, RXM-RAWX, RXM-SFRBX, ESF-MEAS.
//! References: u-blox 8 / M8 Receiver Description (UBX-13003221): UBX-MON-VER, UBX-CFG-MSG,
//! UBX-CFG-TP5, UBX-ACK; u-blox F9 HPG Interface Description (UBX-22008968): UBX-CFG-VALSET
//! and the configuration keys CFG-MSGOUT-*, CFG-TP-*.

use super::framer::ubx_frame;
use super::mon::MonVer;

/// Protocol version (×100) from which a receiver is configured with CFG-VALSET.
pub const VALSET_FROM_PROTVER_X100: u32 = 2700;

/// One configuration command and what it is for.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Command {
    /// What it sets, for the report.
    pub what: &'static str,
    /// The UBX frame.
    pub frame: Vec<u8>,
    /// Class and id the receiver acknowledges.
    pub acked_as: (u8, u8),
    /// A NAK is expected on receivers that lack the feature (reported, not an error).
    pub optional: bool,
}

/// The UBX-MON-VER poll (empty payload).
pub fn poll_version() -> Vec<u8> {
    ubx_frame(0x0A, 0x04, &[])
}

/// Output messages: (name, class, id, optional, CFG-MSGOUT keys for UART1, UART2, USB).
const MESSAGES: [(&str, u8, u8, bool, [u32; 3]); 8] = [
    ("NAV-PVT", 0x01, 0x07, false, [0x2091_0007, 0x2091_0008, 0x2091_0009]),
    ("NAV-EOE", 0x01, 0x61, false, [0x2091_0160, 0x2091_0161, 0x2091_0162]),
    ("NAV-SAT", 0x01, 0x35, false, [0x2091_0016, 0x2091_0017, 0x2091_0018]),
    ("TIM-TP", 0x0D, 0x01, false, [0x2091_017E, 0x2091_017F, 0x2091_0180]),
    ("TIM-TM2", 0x0D, 0x03, true, [0x2091_0179, 0x2091_017A, 0x2091_017B]),
    ("RXM-RAWX", 0x02, 0x15, true, [0x2091_02A5, 0x2091_02A6, 0x2091_02A7]),
    ("RXM-SFRBX", 0x02, 0x13, true, [0x2091_0232, 0x2091_0233, 0x2091_0234]),
    ("ESF-MEAS", 0x10, 0x02, true, [0x2091_0278, 0x2091_0279, 0x2091_027A]),
];

/// Time pulse 1 as configuration keys: (key, value, size in bytes). Enabled, period and
/// length given (not frequency and ratio), 1 s period and 100 ms pulses when locked, no pulse
/// when not locked, GPS time grid, aligned to the top of second, rising edge.
const TIME_PULSE_KEYS: [(u32, u32, usize); 11] = [
    (0x1005_0007, 1, 1),         // CFG-TP-TP1_ENA
    (0x2005_0023, 0, 1),         // CFG-TP-PULSE_DEF: period
    (0x2005_0030, 1, 1),         // CFG-TP-PULSE_LENGTH_DEF: length
    (0x4005_0002, 1_000_000, 4), // CFG-TP-PERIOD_TP1, µs
    (0x4005_0003, 1_000_000, 4), // CFG-TP-PERIOD_LOCK_TP1, µs
    (0x4005_0004, 0, 4),         // CFG-TP-LEN_TP1, µs (not locked: no pulse)
    (0x4005_0005, 100_000, 4),   // CFG-TP-LEN_LOCK_TP1, µs
    (0x1005_0009, 1, 1),         // CFG-TP-USE_LOCKED_TP1
    (0x2005_000C, 1, 1),         // CFG-TP-TIMEGRID_TP1: GPS
    (0x1005_000A, 1, 1),         // CFG-TP-ALIGN_TO_TOW_TP1
    (0x1005_000B, 1, 1),         // CFG-TP-POL_TP1: rising
];

/// A UBX-CFG-VALSET (0x06 0x8A) frame, RAM layer, with `(key, value, size)` items.
fn valset(items: &[(u32, u32, usize)]) -> Vec<u8> {
    let mut p = vec![0u8, 0x01, 0, 0]; // version 0, layers: RAM, reserved
    for &(key, value, size) in items {
        p.extend_from_slice(&key.to_le_bytes());
        p.extend_from_slice(&value.to_le_bytes()[..size]);
    }
    ubx_frame(0x06, 0x8A, &p)
}

/// UBX-CFG-TP5 (0x06 0x31, version 1): time pulse 1 as in [`TIME_PULSE_KEYS`].
fn cfg_tp5() -> Vec<u8> {
    let mut p = [0u8; 32];
    p[1] = 1; // version
    p[8..12].copy_from_slice(&1_000_000u32.to_le_bytes()); // freqPeriod, µs
    p[12..16].copy_from_slice(&1_000_000u32.to_le_bytes()); // freqPeriodLock, µs
    p[16..20].copy_from_slice(&0u32.to_le_bytes()); // pulseLenRatio, µs: none unlocked
    p[20..24].copy_from_slice(&100_000u32.to_le_bytes()); // pulseLenRatioLock, µs
    // flags: active, lockGnssFreq, lockedOtherSet, isLength, alignToTow, polarity (rising),
    // gridUtcGnss = 1 (GPS).
    let flags: u32 = 0b1 | 0b10 | 0b100 | 0b1_0000 | 0b10_0000 | 0b100_0000 | 0b1000_0000;
    p[28..32].copy_from_slice(&flags.to_le_bytes());
    ubx_frame(0x06, 0x31, &p)
}

/// The commands for a receiver whose MON-VER reports `protver_x100` (`None`: not reported,
/// an old receiver: the legacy messages).
pub fn commands(protver_x100: Option<u32>) -> Vec<Command> {
    if protver_x100.is_some_and(|v| v >= VALSET_FROM_PROTVER_X100) {
        let mut out = Vec::new();
        for (name, _, _, optional, keys) in MESSAGES {
            let items: Vec<(u32, u32, usize)> = keys.iter().map(|&k| (k, 1, 1)).collect();
            out.push(Command {
                what: name,
                frame: valset(&items),
                acked_as: (0x06, 0x8A),
                optional,
            });
        }
        out.push(Command {
            what: "time pulse 1 (1 Hz, 100 ms, GPS grid)",
            frame: valset(&TIME_PULSE_KEYS),
            acked_as: (0x06, 0x8A),
            optional: false,
        });
        return out;
    }
    let mut out: Vec<Command> = MESSAGES
        .iter()
        .map(|&(name, class, id, optional, _)| Command {
            what: name,
            frame: ubx_frame(0x06, 0x01, &[class, id, 1]),
            acked_as: (0x06, 0x01),
            optional,
        })
        .collect();
    out.push(Command {
        what: "time pulse 1 (1 Hz, 100 ms, GPS grid)",
        frame: cfg_tp5(),
        acked_as: (0x06, 0x31),
        optional: false,
    });
    out
}

/// What the receiver said to one command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Answer {
    /// UBX-ACK-ACK.
    Acked,
    /// UBX-ACK-NAK.
    Nakked,
    /// Nothing within the timeout.
    TimedOut,
}

/// The outcome of a configuration, for the log and the error.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Report {
    /// The receiver's software and protocol versions, as MON-VER gave them.
    pub version: String,
    /// Each command and its answer.
    pub answers: Vec<(&'static str, bool, Answer)>,
}

impl Report {
    /// Required commands that were not acknowledged.
    pub fn failed(&self) -> Vec<&'static str> {
        self.answers
            .iter()
            .filter(|(_, optional, a)| !optional && *a != Answer::Acked)
            .map(|(what, ..)| *what)
            .collect()
    }
}

/// The receiver's version line for the report.
pub fn describe_version(v: &MonVer) -> String {
    let mut s = format!("{} / {}", MonVer::text(&v.sw_version), MonVer::text(&v.hw_version));
    for e in v.extensions.iter().take(v.len) {
        s.push_str(", ");
        s.push_str(MonVer::text(e));
    }
    s
}

/// The answer to command `c` in an ACK (`acked`) for `(class, id)`, if it is about `c`.
pub fn answer_to(c: &Command, class: u8, id: u8, acked: bool) -> Option<Answer> {
    ((class, id) == c.acked_as).then_some(if acked { Answer::Acked } else { Answer::Nakked })
}

#[cfg(test)]
mod tests {
    use super::super::framer::{Frame, UbxFramer};
    use super::*;

    fn frames(bytes: &[u8]) -> Vec<(u8, u8, Vec<u8>)> {
        let mut f = UbxFramer::new();
        let mut out = Vec::new();
        f.push(bytes, 0, 0, &mut |fr| {
            if let Frame::Ubx { class, id, payload, .. } = fr {
                out.push((class, id, payload.to_vec()));
            }
        });
        out
    }

    #[test]
    fn m8_gets_cfg_msg_and_tp5_f9_gets_valset_in_ram() {
        let m8 = commands(Some(1800));
        assert_eq!(m8.len(), 9);
        let f = frames(&m8[0].frame);
        assert_eq!(f, vec![(0x06, 0x01, vec![0x01, 0x07, 1])], "NAV-PVT every epoch");
        let tp5 = frames(&m8[8].frame);
        assert_eq!((tp5[0].0, tp5[0].1, tp5[0].2.len()), (0x06, 0x31, 32));
        assert!(!m8[0].optional && m8[5].optional, "RXM-RAWX is optional");

        let f9 = commands(Some(2750));
        let pvt = frames(&f9[0].frame);
        let p = &pvt[0].2;
        assert_eq!((pvt[0].0, pvt[0].1, p[0], p[1]), (0x06, 0x8A, 0, 1), "VALSET v0, RAM");
        // Three keys of one byte each: UART1, UART2, USB.
        assert_eq!(p.len(), 4 + 3 * 5);
        assert_eq!(u32::from_le_bytes([p[4], p[5], p[6], p[7]]), 0x2091_0007);
        assert_eq!(p[8], 1);
        let tp = frames(&f9[8].frame);
        assert_eq!(tp[0].2.len(), 4 + 7 * 5 + 4 * 8);
        assert_eq!(answer_to(&f9[0], 0x06, 0x8A, false), Some(Answer::Nakked));
        assert_eq!(answer_to(&f9[0], 0x06, 0x01, true), None);
        // The poll decodes as an empty MON-VER request.
        let poll = frames(&poll_version());
        assert_eq!((poll[0].0, poll[0].1, poll[0].2.len()), (0x0A, 0x04, 0));
    }

    #[test]
    fn the_report_names_required_commands_not_acknowledged() {
        let r = Report {
            version: String::new(),
            answers: vec![
                ("NAV-PVT", false, Answer::Acked),
                ("RXM-RAWX", true, Answer::Nakked),
                ("TIM-TP", false, Answer::TimedOut),
            ],
        };
        assert_eq!(r.failed(), vec!["TIM-TP"]);
    }
}
