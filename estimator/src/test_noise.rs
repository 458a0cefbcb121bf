//! Deterministic noise for the crate's tests.

/// A standard normal deviate (splitmix64 → uniform → the sum of 12, centred): reproducible
/// without a random-number crate.
pub fn gauss(state: &mut u64) -> f64 {
    let mut s = 0.0;
    for _ in 0..12 {
        *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = *state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        s += (z ^ (z >> 31)) as f64 / u64::MAX as f64;
    }
    s - 6.0
}
