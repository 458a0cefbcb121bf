//! Input formats shared by the fuzz targets.
//!
//! The IIO targets take a device description in text, as the driver reads it from sysfs, then
//! (after the first empty line) binary records:
//!
//! ```text
//! # comment
//! anglvel_x 1 be:s32/32>>0 0.0001          <name> <index> <type> [<scale> [<offset>]]
//! timestamp 8 le:s64/64>>0
//!
//! <records: any bytes>
//! ```
//!
//! `<type>` is the `in_<name>_type` attribute, `<scale>`/`<offset>` the `in_<name>_scale` /
//! `_offset` attributes (default 1 and 0).

/// One description line.
#[derive(Debug, Clone, PartialEq)]
pub struct IioLine<'a> {
    /// The whole line, trimmed.
    pub text: &'a str,
    /// Channel name.
    pub name: &'a str,
    /// `_index` text.
    pub index: &'a str,
    /// `_type` text.
    pub ty: &'a str,
    /// `_scale` text, if given.
    pub scale: Option<&'a str>,
    /// `_offset` text, if given.
    pub offset: Option<&'a str>,
}

/// Splits an IIO input into its description lines (comments and blank-free lines only; lines
/// that are not UTF-8 are skipped) and the record bytes after the first empty line.
pub fn split_iio(data: &[u8]) -> (Vec<IioLine<'_>>, &[u8]) {
    let (head, records) = match data.windows(2).position(|w| w == b"\n\n") {
        Some(p) => (&data[..p], &data[p + 2..]),
        None => (data, &data[data.len()..]),
    };
    let lines = head
        .split(|&b| b == b'\n')
        .filter_map(|l| core::str::from_utf8(l).ok())
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .map(|text| {
            let mut w = text.split_ascii_whitespace();
            IioLine {
                text,
                name: w.next().unwrap_or(""),
                index: w.next().unwrap_or(""),
                ty: w.next().unwrap_or(""),
                scale: w.next(),
                offset: w.next(),
            }
        })
        .collect();
    (lines, records)
}
