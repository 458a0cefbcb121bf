//! What a UART receiving at one baud rate makes of bytes sent at another: the feeder's
//! emulation of a wrong line rate on a pseudo-terminal (which has none). Pure function.
//!
//! The sender puts each byte on the line as 10 bits (start 0, eight data bits LSB first,
//! stop 1), back to back, the line idling at 1 afterwards. The receiver waits for a falling
//! edge, checks the start bit at half a bit, samples eight data bits at the centres of its
//! own bit cells and the stop bit after them; a low stop bit is a framing error, and the byte
//! is still delivered, as Linux does in raw mode without `INPCK`. Then it looks for the next
//! falling edge from where it sampled the stop bit. Rates within 2 % of each other are
//! received correctly (a real UART tolerates a few percent).

/// Relative rate mismatch below which bytes are received intact.
pub const TOLERANCE: f64 = 0.02;

/// Line level at time `t` (in units of the sender's bit time) for `bytes` sent from 0.
fn level(bytes: &[u8], t: f64) -> bool {
    if t < 0.0 {
        return true;
    }
    let bit = t.floor() as usize;
    let (byte, pos) = (bit / 10, bit % 10);
    match bytes.get(byte) {
        None => true,
        Some(b) => match pos {
            0 => false,
            9 => true,
            k => b >> (k - 1) & 1 == 1,
        },
    }
}

/// Appends to `out` what a receiver at `rx_baud` reads from `bytes` sent at `tx_baud`.
pub fn receive(bytes: &[u8], tx_baud: u32, rx_baud: u32, out: &mut Vec<u8>) {
    if tx_baud == 0 || rx_baud == 0 || (f64::from(rx_baud) / f64::from(tx_baud) - 1.0).abs() < TOLERANCE {
        out.extend_from_slice(bytes);
        return;
    }
    sample(bytes, f64::from(tx_baud) / f64::from(rx_baud), out);
}

/// The receiver's sampling, with one receiver bit lasting `r` sender bits (time is counted in
/// sender bits).
fn sample(bytes: &[u8], r: f64, out: &mut Vec<u8>) {
    let end = bytes.len() as f64 * 10.0;
    // Falling edges can only happen on sender bit boundaries.
    let mut k = 0usize;
    while (k as f64) < end {
        let t = k as f64;
        if !level(bytes, t - 0.5) || level(bytes, t) {
            k += 1;
            continue;
        }
        // Start bit still low at its middle?
        if level(bytes, t + 0.5 * r) {
            k += 1;
            continue;
        }
        let mut v = 0u8;
        for bit in 0..8 {
            if level(bytes, t + (1.5 + f64::from(bit)) * r) {
                v |= 1 << bit;
            }
        }
        out.push(v);
        // Resume the search after the stop bit's sample point.
        let next = t + 9.5 * r;
        k = (next.ceil() as usize).max(k + 1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_rate_is_transparent() {
        let mut out = Vec::new();
        receive(b"$GPGGA,1*00\r\n", 9600, 9700, &mut out);
        assert_eq!(out, b"$GPGGA,1*00\r\n");
    }

    #[test]
    fn the_sampler_at_equal_rates_reproduces_every_byte() {
        let bytes: Vec<u8> = (0..=255).collect();
        let mut out = Vec::new();
        sample(&bytes, 1.0, &mut out);
        assert_eq!(out, bytes);
    }

    #[test]
    fn a_wrong_rate_garbles_nmea() {
        let line = b"$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47\r\n".repeat(5);
        for (tx, rx) in [(38_400, 9600), (9600, 38_400), (115_200, 4800), (4800, 57_600)] {
            let mut out = Vec::new();
            receive(&line, tx, rx, &mut out);
            assert_ne!(out, line, "{tx} → {rx}");
            // Slower receivers see fewer bytes, faster ones more.
            if rx < tx {
                assert!(out.len() < line.len(), "{tx} → {rx}: {}", out.len());
            }
            // Nothing the NMEA decoder accepts survives.
            let cap = crate::gnss::capture::decode_capture(&out, crate::gnss::Protocol::Nmea);
            let (fixes, counters) = (&cap.fixes, cap.nmea().unwrap());
            assert!(fixes.is_empty(), "{tx} → {rx}: {} fixes", fixes.len());
            assert!(counters.counters().framer.noise_bytes > 0, "{tx} → {rx}: {counters:?}");
        }
    }
}
