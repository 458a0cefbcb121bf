//! A capture cut into timed chunks: what `navsync feed` writes, and when (in capture time).
//! Pure functions on bytes.
//!
//! - NMEA captures (gpsd-style logs): `#` comment lines are skipped; a `# Delay-Cookie: <c>`
//!   header makes `<c>` a write boundary that is not sent (as gpsfake does). A new chunk
//!   starts at every fix sentence (GGA, RMC, GNS, GLL) whose time tag differs from the
//!   current chunk's; it is due that much later than the previous chunk (wrapping at
//!   midnight; a step back or a jump of more than [`MAX_STEP_S`] counts as no delay or one
//!   second). Every other sentence (GSA, GSV, ZDA, proprietary, …) goes out with the chunk
//!   before it, so what a receiver sends in one burst stays one burst.
//! - Raw captures (anything else, e.g. binary protocols) are paced by the line rate: chunks
//!   of up to [`RAW_CHUNK`] bytes, each due when its first byte would start on the line
//!   (10 bits per character).

/// Largest time-tag step taken as real; larger ones (capture gaps) count as one second.
pub const MAX_STEP_S: f64 = 10.0;
/// Bytes per chunk of a raw capture.
pub const RAW_CHUNK: usize = 64;

/// One write.
#[derive(Debug, Clone, PartialEq)]
pub struct Chunk {
    /// When it is due, s of capture time after the first chunk.
    pub due_s: f64,
    /// The bytes.
    pub bytes: Vec<u8>,
}

/// What kind of capture a file is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CaptureKind {
    /// Text lines, mostly NMEA sentences and `#` comments.
    Nmea,
    /// Anything else.
    Raw,
}

/// Decides whether `bytes` is an NMEA log: at least 80 % of its first 64 lines start with
/// `$`, `!` or `#`, and it is mostly printable text.
pub fn detect(bytes: &[u8]) -> CaptureKind {
    let head = &bytes[..bytes.len().min(16 * 1024)];
    let printable = head
        .iter()
        .filter(|&&b| b == b'\r' || b == b'\n' || b == b'\t' || (0x20..0x7f).contains(&b))
        .count();
    if head.is_empty() || printable * 10 < head.len() * 9 {
        return CaptureKind::Raw;
    }
    let lines: Vec<&[u8]> = head
        .split(|&b| b == b'\n')
        .map(|l| l.strip_suffix(b"\r").unwrap_or(l))
        .filter(|l| !l.is_empty())
        .take(64)
        .collect();
    let nmea = lines
        .iter()
        .filter(|l| matches!(l.first(), Some(b'$' | b'!' | b'#')))
        .count();
    if !lines.is_empty() && nmea * 5 >= lines.len() * 4 {
        CaptureKind::Nmea
    } else {
        CaptureKind::Raw
    }
}

/// Seconds of the day of a fix sentence's time tag (`hhmmss[.sss]`), `None` for other
/// sentences or an empty/malformed tag.
pub fn fix_time_tag_s(sentence: &[u8]) -> Option<f64> {
    let text = core::str::from_utf8(sentence).ok()?;
    let body = text.strip_prefix('$')?;
    let body = body.split('*').next()?;
    let mut fields = body.split(',');
    let address = fields.next()?;
    if address.len() < 5 {
        return None;
    }
    let kind = &address.as_bytes()[address.len() - 3..];
    let field = match kind {
        b"GGA" | b"RMC" | b"GNS" => fields.next()?,
        b"GLL" => fields.nth(4)?,
        _ => return None,
    };
    parse_hhmmss(field)
}

fn parse_hhmmss(f: &str) -> Option<f64> {
    if f.len() < 6 || !f.as_bytes()[..6].iter().all(u8::is_ascii_digit) {
        return None;
    }
    let h: f64 = f[0..2].parse().ok()?;
    let m: f64 = f[2..4].parse().ok()?;
    let s: f64 = f[4..].parse().ok()?;
    (h < 24.0 && m < 60.0 && s < 61.0).then_some(h * 3600.0 + m * 60.0 + s)
}

/// The write-boundary character of a `# Delay-Cookie: <c> …` header line.
fn delay_cookie(comment: &[u8]) -> Option<u8> {
    let text = core::str::from_utf8(comment).ok()?;
    let rest = text
        .trim_start_matches('#')
        .trim_start()
        .strip_prefix("Delay-Cookie:")?;
    match rest.trim_start().as_bytes() {
        [c, ..] if !c.is_ascii_whitespace() => Some(*c),
        _ => None,
    }
}

/// The chunks of an NMEA capture.
pub fn nmea_chunks(bytes: &[u8]) -> Vec<Chunk> {
    let mut chunks: Vec<Chunk> = Vec::new();
    let mut cookie = None;
    let mut current_tag: Option<f64> = None;
    let mut due = 0.0;
    for line in bytes.split_inclusive(|&b| b == b'\n') {
        if line.first() == Some(&b'#') {
            cookie = cookie.or_else(|| delay_cookie(line));
            continue;
        }
        let trimmed = line.strip_suffix(b"\n").unwrap_or(line);
        let trimmed = trimmed.strip_suffix(b"\r").unwrap_or(trimmed);
        let data: Vec<u8> = match cookie {
            Some(c) => line.iter().copied().filter(|&b| b != c).collect(),
            None => line.to_vec(),
        };
        let clean: Vec<u8> = match cookie {
            Some(c) => trimmed.iter().copied().filter(|&b| b != c).collect(),
            None => trimmed.to_vec(),
        };
        let tag = fix_time_tag_s(&clean);
        let starts = chunks.is_empty()
            || match (tag, current_tag) {
                (Some(t), Some(c)) => t != c,
                (Some(_), None) => true,
                (None, _) => false,
            };
        if starts {
            if let (Some(t), Some(c)) = (tag, current_tag) {
                // The shorter way round the clock: across midnight forwards or backwards.
                let mut step = t - c;
                if step < -43_200.0 {
                    step += 86_400.0;
                } else if step > 43_200.0 {
                    step -= 86_400.0;
                }
                due += if step <= 0.0 {
                    0.0
                } else if step > MAX_STEP_S {
                    1.0
                } else {
                    step
                };
            }
            chunks.push(Chunk {
                due_s: due,
                bytes: Vec::new(),
            });
        }
        if tag.is_some() {
            current_tag = tag;
        }
        if let Some(last) = chunks.last_mut() {
            last.bytes.extend_from_slice(&data);
        }
    }
    chunks.retain(|c| !c.bytes.is_empty());
    chunks
}

/// The chunks of a raw capture at `baud` (10 bits per character).
pub fn raw_chunks(bytes: &[u8], baud: u32) -> Vec<Chunk> {
    let s_per_byte = 10.0 / f64::from(baud.max(1));
    bytes
        .chunks(RAW_CHUNK)
        .enumerate()
        .map(|(i, c)| Chunk {
            due_s: (i * RAW_CHUNK) as f64 * s_per_byte,
            bytes: c.to_vec(),
        })
        .collect()
}

/// Capture time from the first chunk's start to the end of the last chunk's bytes, s.
pub fn duration_s(chunks: &[Chunk], baud: u32) -> f64 {
    chunks
        .last()
        .map_or(0.0, |c| c.due_s + c.bytes.len() as f64 * 10.0 / f64::from(baud.max(1)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn time_tags() {
        assert_eq!(
            fix_time_tag_s(b"$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47"),
            Some(45_319.0)
        );
        assert_eq!(fix_time_tag_s(b"$GNRMC,000001.50,A,,,,,,,,,*00"), Some(1.5));
        assert_eq!(
            fix_time_tag_s(b"$GPGLL,4916.45,N,12311.12,W,225444,A*31"),
            Some(82_484.0)
        );
        assert_eq!(
            fix_time_tag_s(b"$GPZDA,201530.00,04,07,2002,00,00*60"),
            None,
            "ZDA does not pace"
        );
        assert_eq!(fix_time_tag_s(b"$GPGGA,,,,*00"), None);
        assert_eq!(fix_time_tag_s(b"$GPGSV,3,1,11*00"), None);
        assert_eq!(fix_time_tag_s(b"\xff\xfe"), None);
        assert_eq!(
            fix_time_tag_s("$GPGé,1".as_bytes()),
            None,
            "no panic inside a UTF-8 character"
        );
    }

    #[test]
    fn epochs_become_chunks() {
        let cap = b"# Name: x\n$GPGSV,1*00\r\n$GPGGA,000000,a*00\r\n$GPGSA,b*00\r\n$GPRMC,000000,c*00\r\n\
$GPGGA,000001,d*00\r\n$GPGSV,e*00\r\n$GPGGA,000003.5,f*00\r\n$GPGGA,235959,g*00\r\n$GPGGA,000000,h*00\r\n";
        let c = nmea_chunks(cap);
        let summary: Vec<(f64, usize)> = c
            .iter()
            .map(|c| (c.due_s, c.bytes.iter().filter(|&&b| b == b'\n').count()))
            .collect();
        // Leading GSV + epoch 0 (GGA GSA RMC), epoch 1 (GGA GSV), 3.5, then 23:59:59 (back:
        // no delay) and midnight (+1 s).
        assert_eq!(
            summary,
            vec![(0.0, 1), (0.0, 3), (1.0, 2), (3.5, 1), (3.5, 1), (4.5, 1)]
        );
        let all: Vec<u8> = c.iter().flat_map(|c| c.bytes.clone()).collect();
        assert_eq!(all, cap[10..].to_vec(), "every non-comment byte, in order");
    }

    #[test]
    fn delay_cookie_is_not_sent() {
        let cap = b"# Delay-Cookie: | 0.01\n$GPGGA,|12351|9,x*00\n";
        let c = nmea_chunks(cap);
        assert_eq!(c.len(), 1);
        assert_eq!(c[0].bytes, b"$GPGGA,123519,x*00\n");
    }

    #[test]
    fn raw_is_paced_by_the_line() {
        let c = raw_chunks(&[0u8; 150], 9600);
        assert_eq!(c.len(), 3);
        assert!((c[1].due_s - 64.0 * 10.0 / 9600.0).abs() < 1e-12);
        assert!((duration_s(&c, 9600) - 150.0 * 10.0 / 9600.0).abs() < 1e-12);
        assert_eq!(detect(&[0xFA, 0xFF, 0x36, 0x00, 0xCB]), CaptureKind::Raw);
        assert_eq!(detect(b"# gpsd log\n$GPGGA,1*00\r\n$GPRMC,2*00\r\n"), CaptureKind::Nmea);
        assert_eq!(detect(b"hello\nworld\n"), CaptureKind::Raw);
    }
}
