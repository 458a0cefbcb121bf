//! What travels between hosts: key expressions, payload and attachment.
//!
//! * Key: `navsync/<instance>/<service without "navsync/">`, e.g. the service
//!   `navsync/nav/state` of the instance `car1` is `navsync/car1/nav/state`. The instance names
//!   the host (or the navsync installation) the samples come from.
//! * Payload: the sample as CDR with the `navsync_msgs` definitions, exactly as in the
//!   recordings ([`navsync_shared::cdr`]).
//! * Attachment: the sample type's layout version (`navsync.NavState.v2`), a NUL, and the
//!   exporter's per-key sequence number as a little-endian `u64` (a gap is a loss). A
//!   subscriber whose layout differs refuses the sample and says so.

use navsync_recording::Encoding;
use navsync_recording::channels::ChannelType;
use navsync_shared::samples::AnySample;
use navsync_shared::services::ServiceKind;

/// The key of `service` of `instance`.
pub fn key_of(instance: &str, service: &str) -> String {
    format!(
        "navsync/{instance}/{}",
        service.strip_prefix("navsync/").unwrap_or(service)
    )
}

/// The instance and service of a key written by [`key_of`], if it is a navsync service.
pub fn parse_key(key: &str) -> Option<(&str, String)> {
    let rest = key.strip_prefix("navsync/")?;
    let (instance, tail) = rest.split_once('/')?;
    let service = format!("navsync/{tail}");
    ServiceKind::of(&service).map(|_| (instance, service))
}

/// Whether an instance name is usable in a key (one non-empty chunk without wildcards).
pub fn valid_instance(s: &str) -> bool {
    !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_' || c == '.')
}

/// The attachment of a sample of `kind` with sequence number `seq`.
pub fn attachment(kind: ServiceKind, seq: u64, out: &mut Vec<u8>) {
    out.clear();
    out.extend_from_slice(kind.type_name().as_bytes());
    out.push(0);
    out.extend_from_slice(&seq.to_le_bytes());
}

/// Why a received sample was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Refused {
    /// The key is not a navsync service.
    #[error("`{0}` is not a navsync key (navsync/<instance>/<service>)")]
    Key(String),
    /// No attachment, or not navsync's.
    #[error("{0}: no navsync attachment (layout version and sequence number)")]
    Attachment(String),
    /// Another layout version.
    #[error("{key}: the sender's layout is {theirs}, this navsync reads {ours}: update navsync on one of the hosts")]
    Layout {
        /// The key.
        key: String,
        /// The sender's layout version.
        theirs: String,
        /// This side's.
        ours: &'static str,
    },
    /// The payload does not decode.
    #[error("{key}: {problem}")]
    Payload {
        /// The key.
        key: String,
        /// What was wrong.
        problem: String,
    },
}

/// A received sample: where it came from, its sequence number and the sample.
#[derive(Debug, Clone, Copy)]
pub struct Received<'a> {
    /// The sender's instance.
    pub instance: &'a str,
    /// The exporter's sequence number on this key.
    pub seq: u64,
    /// The sample.
    pub sample: AnySample,
}

/// Decodes what arrived on `key` (pure: bytes in, sample or reason out).
pub fn decode<'a>(key: &'a str, payload: &[u8], attachment: Option<&[u8]>) -> Result<(Received<'a>, String), Refused> {
    let (instance, service) = parse_key(key).ok_or_else(|| Refused::Key(key.to_string()))?;
    let kind = ServiceKind::of(&service).ok_or_else(|| Refused::Key(key.to_string()))?;
    let a = attachment.ok_or_else(|| Refused::Attachment(key.to_string()))?;
    let nul = a
        .iter()
        .position(|&b| b == 0)
        .ok_or_else(|| Refused::Attachment(key.to_string()))?;
    let (layout, rest) = (&a[..nul], &a[nul + 1..]);
    let seq: [u8; 8] = rest.try_into().map_err(|_| Refused::Attachment(key.to_string()))?;
    if layout != kind.type_name().as_bytes() {
        return Err(Refused::Layout {
            key: key.to_string(),
            theirs: String::from_utf8_lossy(layout).into_owned(),
            ours: kind.type_name(),
        });
    }
    let ty = ChannelType {
        kind,
        codec: navsync_recording::channels::Codec::Cdr,
    };
    let sample = navsync_recording::channels::decode(ty, payload).map_err(|problem| Refused::Payload {
        key: key.to_string(),
        problem,
    })?;
    Ok((
        Received {
            instance,
            seq: u64::from_le_bytes(seq),
            sample,
        },
        service,
    ))
}

/// Encodes a sample's payload (CDR) into `out`.
pub fn encode(sample: &AnySample, out: &mut Vec<u8>) {
    Encoding::Cdr.encode(sample, out);
}

/// Counts losses from per-key sequence numbers.
#[derive(Debug, Default)]
pub struct GapCounter {
    last: std::collections::HashMap<String, u64>,
}

impl GapCounter {
    /// Notes `seq` on `key`; returns how many were lost before it (0 for the first, and for a
    /// sender that restarted and counts from 0 again).
    pub fn note(&mut self, key: &str, seq: u64) -> u64 {
        let lost = match self.last.get(key) {
            Some(&prev) if seq > prev => seq - prev - 1,
            _ => 0,
        };
        match self.last.get_mut(key) {
            Some(v) => *v = seq,
            None => {
                self.last.insert(key.to_string(), seq);
            }
        }
        lost
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use navsync_shared::reflect::Reflect;
    use navsync_shared::samples::NavState;

    #[test]
    fn a_nav_state_crosses_and_a_wrong_layout_is_refused_by_name() {
        let mut n = NavState::zeroed();
        n.seq = 17;
        n.lat_deg = 48.1;
        n.gnss_delay_s = f64::NAN;
        let (mut payload, mut att) = (Vec::new(), Vec::new());
        encode(&AnySample::Nav(n), &mut payload);
        attachment(ServiceKind::NavState, 5, &mut att);
        let key = key_of("car1", "navsync/nav/state");
        assert_eq!(key, "navsync/car1/nav/state");
        let (r, service) = decode(&key, &payload, Some(&att)).unwrap();
        assert_eq!((r.instance, r.seq, service.as_str()), ("car1", 5, "navsync/nav/state"));
        let AnySample::Nav(back) = r.sample else { panic!("kind") };
        assert_eq!(back.lat_deg.to_bits(), n.lat_deg.to_bits());
        assert!(back.gnss_delay_s.is_nan());
        let mut old = b"navsync.NavState.v0\0".to_vec();
        old.extend_from_slice(&5u64.to_le_bytes());
        let e = decode(&key, &payload, Some(&old)).unwrap_err();
        assert!(
            e.to_string().contains("navsync.NavState.v0") && e.to_string().contains("v2"),
            "{e}"
        );
        assert!(matches!(decode(&key, &payload, None), Err(Refused::Attachment(_))));
        assert!(matches!(
            decode("navsync/car1/x", &payload, Some(&att)),
            Err(Refused::Key(_))
        ));
        assert!(matches!(
            decode(&key, &payload[..10], Some(&att)),
            Err(Refused::Payload { .. })
        ));
    }

    #[test]
    fn gaps_are_counted_per_key() {
        let mut g = GapCounter::default();
        assert_eq!(g.note("a", 0), 0);
        assert_eq!(g.note("a", 1), 0);
        assert_eq!(g.note("a", 5), 3);
        assert_eq!(g.note("b", 9), 0);
        assert_eq!(g.note("a", 0), 0, "a restarted sender");
    }
}
