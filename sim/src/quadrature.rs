//! Gauss–Legendre quadrature for the IMU interval averages.
//!
//! An n-point rule integrates polynomials of degree 2n − 1 exactly; for a smooth integrand
//! its error on an interval of length T is T^{2n+1} (n!)⁴ / ((2n+1) ((2n)!)³) · f^{(2n)}(ξ)
//! (Abramowitz & Stegun 25.4.30). The simulator's integrands are analytic within a segment,
//! and the callers split intervals at segment boundaries.

/// A rule on [−1, 1]: (node, weight) pairs.
pub type Rule = &'static [(f64, f64)];

/// 3-point rule (exact to degree 5).
pub const GL3: Rule = &[
    (-0.774_596_669_241_483_4, 5.0 / 9.0),
    (0.0, 8.0 / 9.0),
    (0.774_596_669_241_483_4, 5.0 / 9.0),
];

/// 5-point rule (exact to degree 9).
pub const GL5: Rule = &[
    (-0.906_179_845_938_664, 0.236_926_885_056_189_1),
    (-0.538_469_310_105_683_1, 0.478_628_670_499_366_5),
    (0.0, 128.0 / 225.0),
    (0.538_469_310_105_683_1, 0.478_628_670_499_366_5),
    (0.906_179_845_938_664, 0.236_926_885_056_189_1),
];

/// 8-point rule (exact to degree 15), the reference in tests.
pub const GL8: Rule = &[
    (-0.960_289_856_497_536_3, 0.101_228_536_290_376_3),
    (-0.796_666_477_413_626_7, 0.222_381_034_453_374_5),
    (-0.525_532_409_916_329, 0.313_706_645_877_887_3),
    (-0.183_434_642_495_649_8, 0.362_683_783_378_362),
    (0.183_434_642_495_649_8, 0.362_683_783_378_362),
    (0.525_532_409_916_329, 0.313_706_645_877_887_3),
    (0.796_666_477_413_626_7, 0.222_381_034_453_374_5),
    (0.960_289_856_497_536_3, 0.101_228_536_290_376_3),
];

/// ∫_a^b f(t) dt of a vector-valued integrand with rule `rule`.
pub fn integrate<const N: usize>(rule: Rule, a: f64, b: f64, mut f: impl FnMut(f64) -> [f64; N]) -> [f64; N] {
    let half = 0.5 * (b - a);
    let mid = 0.5 * (a + b);
    let mut acc = [0.0; N];
    for &(x, w) in rule {
        let y = f(mid + half * x);
        for (s, v) in acc.iter_mut().zip(y) {
            *s += w * half * v;
        }
    }
    acc
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weights_sum_to_two_and_polynomials_exact() {
        for (rule, degree) in [(GL3, 5), (GL5, 9), (GL8, 15)] {
            let s: f64 = rule.iter().map(|p| p.1).sum();
            assert!((s - 2.0).abs() < 1e-14);
            // ∫_0^1 t^d dt = 1/(d+1).
            let [v] = integrate(rule, 0.0, 1.0, |t| [t.powi(degree)]);
            assert!((v - 1.0 / (degree as f64 + 1.0)).abs() < 1e-14, "degree {degree}: {v}");
        }
    }

    #[test]
    fn smooth_integrand() {
        let [v] = integrate(GL5, 0.0, 0.005, |t| [(40.0 * t).sin()]);
        let exact = (1.0 - (0.2f64).cos()) / 40.0;
        assert!((v - exact).abs() < 1e-18);
    }
}
