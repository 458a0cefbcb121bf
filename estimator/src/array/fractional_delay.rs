//! Lagrange fractional-delay FIR (Laakso, Välimäki, Karjalainen & Laine, "Splitting the unit
//! delay", IEEE Signal Processing Magazine 13(1), 1996, eq. 42):
//!
//! h(n) = Π_{k=0..N, k≠n} (D − k) / (n − k),  n = 0 … N,
//!
//! the order-N polynomial interpolator that delays a uniformly sampled signal by D samples.
//! The integer part of a delay is taken by choosing which N + 1 samples the filter spans; the
//! fractional part then sits in the middle of the span (N/2 − ½ ≤ D ≤ N/2 + ½), where the
//! Lagrange filter's error is smallest.

/// Largest supported order.
pub const MAX_ORDER: usize = 7;

/// Coefficients h(0..=N) for delay `d` samples (measured from the first tap).
pub fn lagrange_coefficients(order: usize, d: f64, out: &mut [f64; MAX_ORDER + 1]) {
    let n_taps = order + 1;
    for (n, h) in out.iter_mut().enumerate().take(n_taps) {
        let mut v = 1.0;
        for k in 0..n_taps {
            if k != n {
                v *= (d - k as f64) / (n as f64 - k as f64);
            }
        }
        *h = v;
    }
}

/// Where to interpolate a uniformly sampled signal at fractional sample position `x`
/// (0 = first sample): the first tap index and the delay within the span, chosen so the
/// delay is centred. Returns `None` when `x` needs samples before 0 or at/after `len`.
pub fn span(order: usize, x: f64, len: usize) -> Option<(usize, f64)> {
    let half = (order as f64 - 1.0) / 2.0;
    let first = (x - half).floor();
    if first < 0.0 || first as usize + order >= len || !x.is_finite() {
        return None;
    }
    Some((first as usize, x - first))
}

/// Interpolates `get(i)` (samples 0..len) at fractional position `x` with an order-`order`
/// Lagrange filter; `None` outside the available span.
pub fn interpolate(order: usize, x: f64, len: usize, get: impl Fn(usize) -> f64) -> Option<f64> {
    let (first, d) = span(order, x, len)?;
    let mut h = [0.0; MAX_ORDER + 1];
    lagrange_coefficients(order, d, &mut h);
    Some((0..=order).map(|n| h[n] * get(first + n)).sum())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn integer_delays_pick_samples_and_coefficients_sum_to_one() {
        let mut h = [0.0; MAX_ORDER + 1];
        lagrange_coefficients(3, 2.0, &mut h);
        assert_eq!(&h[..4], &[0.0, 0.0, 1.0, 0.0]);
        lagrange_coefficients(3, 1.37, &mut h);
        assert!((h[..4].iter().sum::<f64>() - 1.0).abs() < 1e-14);
    }

    #[test]
    fn cubic_reproduces_cubics_exactly_and_sines_closely() {
        let f = |t: f64| 0.3 * t * t * t - t * t + 2.0 * t - 5.0;
        let y = interpolate(3, 4.3, 10, |i| f(i as f64)).unwrap();
        assert!((y - f(4.3)).abs() < 1e-12);
        // A 15 Hz sine sampled at 200 Hz, shifted by 0.37 sample: cubic error ≈ 1e−3 relative.
        let w = 2.0 * std::f64::consts::PI * 15.0 / 200.0;
        let y = interpolate(3, 20.37, 64, |i| (w * i as f64).sin()).unwrap();
        assert!(
            (y - (w * 20.37).sin()).abs() < 2e-3,
            "{}",
            (y - (w * 20.37).sin()).abs()
        );
        assert!(
            interpolate(3, 0.5, 10, |_| 0.0).is_none(),
            "needs a sample before the start"
        );
        assert!(
            interpolate(3, 8.2, 10, |_| 0.0).is_none(),
            "needs a sample past the end"
        );
    }
}
