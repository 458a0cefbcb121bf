//! Receiver identification and command acknowledgements: UBX-MON-VER, UBX-ACK-ACK and
//! UBX-ACK-NAK (u-blox 8 / M8 Receiver Description incl. Protocol Specification,
//! UBX-13003221, and u-blox F9 HPG Interface Description, UBX-22008968).

use super::messages::{MAX_EXTENSIONS, UbxError, bytes, u1};

/// UBX-MON-VER (0x0A 0x04), Receiver and software version: 40 + 30·N bytes of
/// NUL-padded ASCII.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MonVer {
    /// Software version (`swVersion`, 30 characters, NUL-padded).
    pub sw_version: [u8; 30],
    /// Hardware version (`hwVersion`, 10 characters, NUL-padded).
    pub hw_version: [u8; 10],
    /// Extension strings (`FWVER=…`, `PROTVER=…`, supported GNSS …); `extensions[..len]`
    /// are valid.
    pub extensions: [[u8; 30]; MAX_EXTENSIONS],
    /// Valid entries of `extensions`.
    pub len: usize,
    /// Extensions that did not fit.
    pub dropped: usize,
}

impl MonVer {
    /// A NUL-padded field as text (up to the first NUL; `?` if it is not ASCII).
    pub fn text(field: &[u8]) -> &str {
        let end = field.iter().position(|&b| b == 0).unwrap_or(field.len());
        core::str::from_utf8(field.get(..end).unwrap_or(&[])).unwrap_or("?")
    }

    /// The protocol version from a `PROTVER=xx.yy` (or `PROTVER xx.yy`) extension, ×100
    /// (e.g. 1800 for 18.00).
    pub fn protocol_version_x100(&self) -> Option<u32> {
        self.extensions.iter().take(self.len).find_map(|e| {
            let t = Self::text(e);
            let v = t.strip_prefix("PROTVER")?.trim_start_matches(['=', ' ']);
            let (major, minor) = v.split_once('.').unwrap_or((v, ""));
            let mut digits = minor
                .bytes()
                .take_while(u8::is_ascii_digit)
                .map(|d| u32::from(d - b'0'));
            let (tens, ones) = (digits.next().unwrap_or(0), digits.next().unwrap_or(0));
            Some(major.trim().parse::<u32>().ok()? * 100 + tens * 10 + ones)
        })
    }
}

/// UBX-MON-VER (0x0A 0x04): see [`MonVer`].
pub fn decode_mon_ver(p: &[u8]) -> Result<MonVer, UbxError> {
    if p.len() < 40 || !(p.len() - 40).is_multiple_of(30) {
        return Err(UbxError::Length {
            name: "MON-VER",
            len: p.len(),
            expected: "40 + 30·N",
        });
    }
    let n = (p.len() - 40) / 30;
    let mut out = MonVer {
        sw_version: bytes(p, 0),
        hw_version: bytes(p, 30),
        extensions: [[0; 30]; MAX_EXTENSIONS],
        len: n.min(MAX_EXTENSIONS),
        dropped: n.saturating_sub(MAX_EXTENSIONS),
    };
    for (i, e) in out.extensions.iter_mut().take(n).enumerate() {
        *e = bytes(p, 40 + 30 * i);
    }
    Ok(out)
}

/// UBX-ACK-ACK (0x05 0x01) / UBX-ACK-NAK (0x05 0x00), Message acknowledged / not
/// acknowledged: 2 bytes, the class and id of the configuration message concerned.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Ack {
    /// Class of the acknowledged message.
    pub cls_id: u8,
    /// Id of the acknowledged message.
    pub msg_id: u8,
}

/// UBX-ACK-ACK / UBX-ACK-NAK: see [`Ack`].
pub fn decode_ack(p: &[u8]) -> Result<Ack, UbxError> {
    if p.len() != 2 {
        return Err(UbxError::Length {
            name: "ACK",
            len: p.len(),
            expected: "2",
        });
    }
    Ok(Ack {
        cls_id: u1(p, 0),
        msg_id: u1(p, 1),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn field<const N: usize>(s: &str) -> [u8; N] {
        let mut f = [0u8; N];
        f[..s.len()].copy_from_slice(s.as_bytes());
        f
    }

    #[test]
    fn mon_ver_strings() {
        let mut p = field::<30>("ROM CORE 3.01 (107888)").to_vec();
        p.extend(field::<10>("00080000"));
        for e in ["FWVER=SPG 3.01", "PROTVER=18.00", "GPS;GLO;GAL;BDS"] {
            p.extend(field::<30>(e));
        }
        let m = decode_mon_ver(&p).unwrap();
        assert_eq!(MonVer::text(&m.sw_version), "ROM CORE 3.01 (107888)");
        assert_eq!(MonVer::text(&m.hw_version), "00080000");
        assert_eq!((m.len, MonVer::text(&m.extensions[2])), (3, "GPS;GLO;GAL;BDS"));
        assert_eq!(m.protocol_version_x100(), Some(1800));
        assert!(decode_mon_ver(&p[..69]).is_err() && decode_mon_ver(&p[..39]).is_err());
        let old = decode_mon_ver(&p[..40]).unwrap();
        assert_eq!((old.len, old.protocol_version_x100()), (0, None));
    }

    #[test]
    fn ack() {
        assert_eq!(decode_ack(&[6, 1]), Ok(Ack { cls_id: 6, msg_id: 1 }));
        assert!(decode_ack(&[6]).is_err() && decode_ack(&[6, 1, 0]).is_err());
    }
}
