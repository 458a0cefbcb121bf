//! The MCAP container format, version 0 (<https://mcap.dev/spec>): magic, record opcodes and
//! the primitive field encodings that [`McapWriter`](super::McapWriter) and
//! [`McapReader`](super::McapReader) share.
//!
//! Spec, "File Structure" and "Serialization": a file is
//! `<Magic><Header><Data section>[<Summary section>][<Summary Offset section>]<Footer><Magic>`;
//! every record is `<opcode: u8><content length: u64><content>`; integers are little-endian;
//! a `String` is a `u32` byte length and UTF-8; `Bytes` fields carry their own `u32` or `u64`
//! length prefix as the record's table says; a `Map`/`Array` is a `u32` byte length followed
//! by its entries.

/// Leading and trailing magic: `0x89 M C A P 0 \r \n` (spec "Magic"; `0` is the major version).
pub const MAGIC: [u8; 8] = [0x89, b'M', b'C', b'A', b'P', b'0', b'\r', b'\n'];

/// Bytes of a record's opcode and length prefix.
pub const RECORD_PREFIX_LEN: u64 = 1 + 8;

/// Length of a Footer record's content: summary_start, summary_offset_start (u64) and summary_crc (u32).
pub const FOOTER_CONTENT_LEN: u64 = 8 + 8 + 4;

/// Bytes from the start of the Footer record to the end of the file (footer record plus magic).
pub const FOOTER_AND_MAGIC_LEN: u64 = RECORD_PREFIX_LEN + FOOTER_CONTENT_LEN + MAGIC.len() as u64;

/// Record opcodes (spec "Records").
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Opcode {
    /// "Header" (0x01)
    Header = 0x01,
    /// "Footer" (0x02)
    Footer = 0x02,
    /// "Schema" (0x03)
    Schema = 0x03,
    /// "Channel" (0x04)
    Channel = 0x04,
    /// "Message" (0x05)
    Message = 0x05,
    /// "Chunk" (0x06)
    Chunk = 0x06,
    /// "Message Index" (0x07)
    MessageIndex = 0x07,
    /// "Chunk Index" (0x08)
    ChunkIndex = 0x08,
    /// "Attachment" (0x09), not written by navsync.
    Attachment = 0x09,
    /// "Attachment Index" (0x0A), not written by navsync.
    AttachmentIndex = 0x0A,
    /// "Statistics" (0x0B)
    Statistics = 0x0B,
    /// "Metadata" (0x0C), not written by navsync.
    Metadata = 0x0C,
    /// "Metadata Index" (0x0D), not written by navsync.
    MetadataIndex = 0x0D,
    /// "Summary Offset" (0x0E)
    SummaryOffset = 0x0E,
    /// "Data End" (0x0F)
    DataEnd = 0x0F,
}

/// Name of a record type for messages ("Chunk", "opcode 0x42" for unknown ones).
pub fn opcode_name(op: u8) -> String {
    let name = match op {
        0x01 => "Header",
        0x02 => "Footer",
        0x03 => "Schema",
        0x04 => "Channel",
        0x05 => "Message",
        0x06 => "Chunk",
        0x07 => "MessageIndex",
        0x08 => "ChunkIndex",
        0x09 => "Attachment",
        0x0A => "AttachmentIndex",
        0x0B => "Statistics",
        0x0C => "Metadata",
        0x0D => "MetadataIndex",
        0x0E => "SummaryOffset",
        0x0F => "DataEnd",
        _ => return format!("opcode 0x{op:02x}"),
    };
    name.to_string()
}

/// Appends records and fields to a byte buffer.
pub(crate) struct Enc<'a>(pub &'a mut Vec<u8>);

impl Enc<'_> {
    pub fn u8(&mut self, v: u8) -> &mut Self {
        self.0.push(v);
        self
    }
    pub fn u16(&mut self, v: u16) -> &mut Self {
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }
    pub fn u32(&mut self, v: u32) -> &mut Self {
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }
    pub fn u64(&mut self, v: u64) -> &mut Self {
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }
    /// `String`: u32 length, UTF-8 bytes.
    pub fn str(&mut self, s: &str) -> &mut Self {
        self.bytes32(s.as_bytes())
    }
    /// `Bytes` with a u32 length prefix.
    pub fn bytes32(&mut self, b: &[u8]) -> &mut Self {
        self.u32(len32(b.len()));
        self.0.extend_from_slice(b);
        self
    }
    /// Starts a record: opcode and a length placeholder; returns the position to [`end`](Self::end).
    pub fn begin(&mut self, op: Opcode) -> usize {
        self.0.push(op as u8);
        let at = self.0.len();
        self.0.extend_from_slice(&[0; 8]);
        at
    }
    /// Patches the length of the record started at `at` to everything appended since.
    pub fn end(&mut self, at: usize) {
        let len = (self.0.len() - at - 8) as u64;
        self.0[at..at + 8].copy_from_slice(&len.to_le_bytes());
    }
    /// Starts a u32-length-prefixed map or array; returns the position to [`end_len32`](Self::end_len32).
    pub fn begin_len32(&mut self) -> usize {
        let at = self.0.len();
        self.0.extend_from_slice(&[0; 4]);
        at
    }
    /// Patches the u32 length prefix started at `at`.
    pub fn end_len32(&mut self, at: usize) {
        let len = len32(self.0.len() - at - 4);
        self.0[at..at + 4].copy_from_slice(&len.to_le_bytes());
    }
}

/// A u32 length; MCAP cannot express longer strings, maps or arrays (navsync's are tiny).
fn len32(n: usize) -> u32 {
    u32::try_from(n).unwrap_or(u32::MAX)
}

/// What was wrong with a record's content, at a byte position within it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct FieldError {
    /// Position within the record content.
    pub at: usize,
    /// What was wrong.
    pub problem: String,
}

/// Reads fields of one record's content.
pub(crate) struct Dec<'a> {
    data: &'a [u8],
    pos: usize,
}

impl<'a> Dec<'a> {
    pub fn new(data: &'a [u8]) -> Self {
        Self { data, pos: 0 }
    }
    pub fn pos(&self) -> usize {
        self.pos
    }
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], FieldError> {
        if self.data.len() - self.pos < n {
            return Err(FieldError {
                at: self.pos,
                problem: format!(
                    "{what}: needs {n} bytes, {} left in the record",
                    self.data.len() - self.pos
                ),
            });
        }
        let s = &self.data[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
    pub fn u16(&mut self, what: &str) -> Result<u16, FieldError> {
        let b = self.take(2, what)?;
        Ok(u16::from_le_bytes([b[0], b[1]]))
    }
    pub fn u32(&mut self, what: &str) -> Result<u32, FieldError> {
        let b = self.take(4, what)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }
    pub fn u64(&mut self, what: &str) -> Result<u64, FieldError> {
        let b = self.take(8, what)?;
        let mut a = [0u8; 8];
        a.copy_from_slice(b);
        Ok(u64::from_le_bytes(a))
    }
    pub fn bytes32(&mut self, what: &str) -> Result<&'a [u8], FieldError> {
        let n = self.u32(what)? as usize;
        self.take(n, what)
    }
    pub fn bytes64(&mut self, what: &str) -> Result<&'a [u8], FieldError> {
        let n = self.u64(what)?;
        let n = usize::try_from(n).map_err(|_| FieldError {
            at: self.pos,
            problem: format!("{what}: length {n} does not fit in memory"),
        })?;
        self.take(n, what)
    }
    pub fn str(&mut self, what: &str) -> Result<&'a str, FieldError> {
        let at = self.pos;
        let b = self.bytes32(what)?;
        core::str::from_utf8(b).map_err(|_| FieldError {
            at,
            problem: format!("{what}: not UTF-8"),
        })
    }
    /// `Map<string, string>`.
    pub fn str_map(&mut self, what: &str) -> Result<Vec<(String, String)>, FieldError> {
        let body = self.bytes32(what)?;
        let base = self.pos - body.len();
        let mut d = Dec::new(body);
        let mut out = Vec::new();
        while d.pos < body.len() {
            let k = d.str(what).map_err(|e| e.shifted(base))?;
            let v = d.str(what).map_err(|e| e.shifted(base))?;
            out.push((k.to_string(), v.to_string()));
        }
        Ok(out)
    }
    /// `Map<uint16, uint64>`.
    pub fn u16_u64_map(&mut self, what: &str) -> Result<Vec<(u16, u64)>, FieldError> {
        let body = self.bytes32(what)?;
        let base = self.pos - body.len();
        if body.len() % 10 != 0 {
            return Err(FieldError {
                at: base,
                problem: format!(
                    "{what}: {} bytes is not a whole number of (u16, u64) entries",
                    body.len()
                ),
            });
        }
        let mut d = Dec::new(body);
        let mut out = Vec::with_capacity(body.len() / 10);
        while d.pos < body.len() {
            out.push((d.u16(what)?, d.u64(what)?));
        }
        Ok(out)
    }
}

impl FieldError {
    fn shifted(mut self, by: usize) -> Self {
        self.at += by;
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fields_round_trip() {
        let mut buf = Vec::new();
        let mut e = Enc(&mut buf);
        let at = e.begin(Opcode::Channel);
        e.u16(7).u32(0xDEAD_BEEF).u64(u64::MAX).str("navsync/nav/state");
        let m = e.begin_len32();
        e.str("k").str("v");
        e.end_len32(m);
        e.end(at);
        assert_eq!(buf[0], Opcode::Channel as u8);
        let len = u64::from_le_bytes(buf[1..9].try_into().unwrap());
        assert_eq!(len as usize, buf.len() - 9);
        let mut d = Dec::new(&buf[9..]);
        assert_eq!(d.u16("a").unwrap(), 7);
        assert_eq!(d.u32("b").unwrap(), 0xDEAD_BEEF);
        assert_eq!(d.u64("c").unwrap(), u64::MAX);
        assert_eq!(d.str("d").unwrap(), "navsync/nav/state");
        assert_eq!(d.str_map("e").unwrap(), vec![("k".to_string(), "v".to_string())]);
        assert_eq!(d.pos(), buf.len() - 9);
        let err = d.u16("f").unwrap_err();
        assert!(err.problem.contains("f: needs 2 bytes, 0 left"), "{err:?}");
    }

    #[test]
    fn names() {
        assert_eq!(opcode_name(6), "Chunk");
        assert_eq!(opcode_name(0x42), "opcode 0x42");
    }
}
