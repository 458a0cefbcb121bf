//! Bit fields of navigation data as u-blox delivers it in UBX-RXM-SFRBX: the message's bits
//! from word 0's most significant bit on (GPS CNAV, Galileo F/NAV), as the interface
//! control documents number them (bit 0 = the first transmitted); and the other way, values
//! quantised into fields for the encoders (RINEX import).

/// The words of one message, read MSB first.
pub(crate) struct Bits<'a>(pub(crate) &'a [u32]);

impl Bits<'_> {
    /// Bit `i`; 0 beyond the words.
    pub(crate) fn bit(&self, i: u32) -> u64 {
        self.0
            .get((i / 32) as usize)
            .map_or(0, |w| u64::from((w >> (31 - i % 32)) & 1))
    }

    /// Bits `from..from+n`, unsigned; n ≤ 64.
    pub(crate) fn u(&self, from: u32, n: u32) -> u64 {
        (from..from + n).fold(0, |a, i| (a << 1) | self.bit(i))
    }

    /// The same, two's complement.
    pub(crate) fn s(&self, from: u32, n: u32) -> i64 {
        ((self.u(from, n) << (64 - n)) as i64) >> (64 - n)
    }

    /// The CRC-24Q of the first `n` bits, and whether it equals the 24 bits after them.
    pub(crate) fn crc24q_ok(&self, n: u32) -> bool {
        u64::from(super::galileo::crc24q(n, |i| self.bit(i) as u32)) == self.u(n, 24)
    }
}

/// A value that does not fit its field of a navigation message.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error("{field} = {value:e} does not fit its {bits}-bit field")]
pub struct OutOfRange {
    /// The field (the ICD's name).
    pub field: &'static str,
    /// The value, in the field's SI unit (semicircle fields in rad).
    pub value: f64,
    /// The field's width.
    pub bits: u32,
}

/// The integer `v` as a field of `bits` bits (two's complement when `signed`): `v` when it
/// fits.
pub fn check(field: &'static str, bits: u32, signed: bool, v: i64) -> Result<i64, OutOfRange> {
    let fits = if signed {
        (-(1i64 << (bits - 1))..(1i64 << (bits - 1))).contains(&v)
    } else {
        (0..(1i64 << bits)).contains(&v)
    };
    fits.then_some(v).ok_or(OutOfRange {
        field,
        value: v as f64,
        bits,
    })
}

/// round(`x` / `scale`) as a field of `bits` bits ([`check`]); `worst` receives the largest
/// |x / scale − round(x / scale)|, in LSBs.
pub fn quantise(
    field: &'static str,
    bits: u32,
    signed: bool,
    x: f64,
    scale: f64,
    worst: &mut f64,
) -> Result<i64, OutOfRange> {
    let q = x / scale;
    let r = q.round();
    let err = OutOfRange { field, value: x, bits };
    if !r.is_finite() || r.abs() > 2f64.powi(62) {
        return Err(err);
    }
    let v = check(field, bits, signed, r as i64).map_err(|_| err)?;
    *worst = worst.max((q - r).abs());
    Ok(v)
}

/// The words of one message being written, MSB first from word 0's most significant bit (the
/// layout [`Bits`] reads): fields checked against their width ([`check`], [`quantise`]), the
/// largest rounding in LSBs kept in `worst`.
pub(crate) struct BitsWriter<'a, const N: usize> {
    /// The words.
    pub(crate) w: [u32; N],
    worst: &'a mut f64,
}

impl<'a, const N: usize> BitsWriter<'a, N> {
    /// All bits 0.
    pub(crate) fn new(worst: &'a mut f64) -> Self {
        Self { w: [0; N], worst }
    }

    /// Bits `from..from+n` := `v` (two's complement when negative), which must fit.
    pub(crate) fn raw(
        &mut self,
        field: &'static str,
        (from, n, signed): (u32, u32, bool),
        v: i64,
    ) -> Result<(), OutOfRange> {
        let v = check(field, n, signed, v)?;
        for i in 0..n {
            let at = from + i;
            if let Some(word) = self.w.get_mut((at / 32) as usize) {
                *word |= (((v >> (n - 1 - i)) & 1) as u32) << (31 - at % 32);
            }
        }
        Ok(())
    }

    /// Bits `from..from+n` := round(`x` / `scale`), which must fit.
    pub(crate) fn put(
        &mut self,
        field: &'static str,
        at: (u32, u32, bool),
        x: f64,
        scale: f64,
    ) -> Result<(), OutOfRange> {
        let v = quantise(field, at.1, at.2, x, scale, self.worst)?;
        self.raw(field, at, v)
    }
}
