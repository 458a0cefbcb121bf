//! Bit fields of navigation data as u-blox delivers it in UBX-RXM-SFRBX: the message's bits
//! from word 0's most significant bit on (GPS CNAV, Galileo F/NAV), as the interface
//! control documents number them (bit 0 = the first transmitted).

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
