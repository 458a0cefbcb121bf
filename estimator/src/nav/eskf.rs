//! The error-state Kalman filter engine: covariance propagation and the measurement update
//! with chi-square innovation gating. Closed loop: the error state is fed back into the
//! nominal state after every update, so only the covariance is carried between steps.

use nalgebra::{SMatrix, SVector};

use super::error_state::{N, StateMat, StateVec};

/// Chi-square 99.9 % quantiles for 1…6 degrees of freedom (innovation gate).
pub const CHI2_999: [f64; 6] = [10.83, 13.82, 16.27, 18.47, 20.52, 22.46];

/// The innovation gate for `M` measured components: the 99.9 % chi-square quantile times
/// `gate_scale`.
pub fn gate_of<const M: usize>(gate_scale: f64) -> f64 {
    CHI2_999[(M - 1).min(CHI2_999.len() - 1)] * gate_scale
}

/// Outcome of a measurement update (the error state inline: boxing it would allocate per
/// update).
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Update {
    /// Fused.
    Accepted {
        /// The error-state estimate to feed back.
        dx: StateVec,
        /// The normalised innovation squared.
        nis: f64,
    },
    /// Gated out.
    Rejected {
        /// The normalised innovation squared that failed the gate.
        nis: f64,
    },
}

/// Covariance of the error state.
#[derive(Debug, Clone)]
pub struct Eskf {
    /// Error-state covariance P.
    pub p: StateMat,
    /// A state held as a consider parameter (Schmidt 1966): the updates leave its estimate and
    /// its variance as they are (its row of the gain is zero) and keep its correlations with
    /// the others consistent (the Joseph form holds for any gain). For a state the
    /// measurements cannot tell apart from the others at the moment, whose information would
    /// otherwise come only through the linearisation's noise.
    pub held: Option<usize>,
}

impl Eskf {
    /// A filter with initial covariance `p0`.
    pub fn new(p0: StateMat) -> Self {
        Self { p: p0, held: None }
    }

    /// The gain P Hᵀ S⁻¹ with the [`held`](Self::held) state's row zeroed.
    fn gain<const M: usize>(&self, pht: &SMatrix<f64, N, M>, s_inv: &SMatrix<f64, M, M>) -> SMatrix<f64, N, M> {
        let mut k = pht * s_inv;
        if let Some(i) = self.held {
            k.row_mut(i).fill(0.0);
        }
        k
    }

    /// P ← Φ P Φᵀ + Q_d (Brown & Hwang eq. 5.2.10), symmetrised.
    ///
    /// Φ = I + F·Δt is sparse (82 non-zeros of 676, 100 with the scale factors): both products
    /// run over its non-zero entries only ([`sparse_sandwich`]), the same sums in the same
    /// order as the dense product, so the same numbers.
    pub fn predict(&mut self, phi: &StateMat, qd: &StateMat) {
        let p = sparse_sandwich(phi, &self.p) + qd;
        self.p = (p + p.transpose()) * 0.5;
    }

    /// Kalman update with innovation `dz = h(x̂) − z` (computed minus measured, KF-GINS sign),
    /// Jacobian `h` and noise `r`; gated at the 99.9 % chi-square quantile (times `gate_scale`).
    /// Joseph form P = (I−KH)P(I−KH)ᵀ + KRKᵀ.
    pub fn update<const M: usize>(
        &mut self,
        dz: &SVector<f64, M>,
        h: &SMatrix<f64, M, N>,
        r: &SMatrix<f64, M, M>,
        gate_scale: f64,
    ) -> Update {
        let pht = self.p * h.transpose();
        let s = h * pht + r;
        let Some(s_inv) = s.try_inverse() else {
            return Update::Rejected { nis: f64::INFINITY };
        };
        let nis = (dz.transpose() * s_inv * dz)[(0, 0)];
        let gate = gate_of::<M>(gate_scale);
        if !nis.is_finite() || nis > gate {
            return Update::Rejected { nis };
        }
        let k = self.gain(&pht, &s_inv);
        let dx = k * dz;
        let i_kh = StateMat::identity() - k * h;
        let p = i_kh * self.p * i_kh.transpose() + k * r * k.transpose();
        self.p = (p + p.transpose()) * 0.5;
        Update::Accepted { dx, nis }
    }

    /// The normalised innovation squared of a measurement (terms as for
    /// [`update`](Self::update)) and whether it passes the same gate, without fusing it.
    pub fn gate<const M: usize>(
        &self,
        dz: &SVector<f64, M>,
        h: &SMatrix<f64, M, N>,
        r: &SMatrix<f64, M, M>,
        gate_scale: f64,
    ) -> (bool, f64) {
        let s = h * self.p * h.transpose() + r;
        let Some(s_inv) = s.try_inverse() else {
            return (false, f64::INFINITY);
        };
        let nis = (dz.transpose() * s_inv * dz)[(0, 0)];
        let gate = gate_of::<M>(gate_scale);
        (nis.is_finite() && nis <= gate, nis)
    }

    /// Kalman update without a gate, returning the error-state estimate to feed back and the
    /// log-likelihood of the innovation, −½(νᵀS⁻¹ν + ln det S + M ln 2π) with S = HPHᵀ + R
    /// (the weight of a hypothesis in a bank of filters: Alspach & Sorenson 1972). `None` when S
    /// is not positive definite.
    pub fn update_with_likelihood<const M: usize>(
        &mut self,
        dz: &SVector<f64, M>,
        h: &SMatrix<f64, M, N>,
        r: &SMatrix<f64, M, M>,
    ) -> Option<(StateVec, f64)> {
        let pht = self.p * h.transpose();
        let s = h * pht + r;
        let chol = s.cholesky()?;
        let ln_det: f64 = (0..M).map(|i| 2.0 * chol.l_dirty()[(i, i)].ln()).sum();
        let s_inv = chol.inverse();
        let nis = (dz.transpose() * s_inv * dz)[(0, 0)];
        if !(nis.is_finite() && ln_det.is_finite()) {
            return None;
        }
        let k = self.gain(&pht, &s_inv);
        let dx = k * dz;
        let i_kh = StateMat::identity() - k * h;
        let p = i_kh * self.p * i_kh.transpose() + k * r * k.transpose();
        self.p = (p + p.transpose()) * 0.5;
        let ll = -0.5 * (nis + ln_det + M as f64 * (2.0 * std::f64::consts::PI).ln());
        Some((dx, ll))
    }

    /// Forgets what the filter knew of state `i`: its covariance row and column zeroed (no
    /// correlation with the others), its variance set to `var`.
    pub fn reopen(&mut self, i: usize, var: f64) {
        self.p.row_mut(i).fill(0.0);
        self.p.column_mut(i).fill(0.0);
        self.p[(i, i)] = var;
    }

    /// 1-sigma of state `i`.
    pub fn std(&self, i: usize) -> f64 {
        self.p[(i, i)].max(0.0).sqrt()
    }
}

/// Φ P Φᵀ over Φ's non-zero entries, for a symmetric P (as [`Eskf::predict`] keeps it): P·Φᵀ
/// is (Φ·P)ᵀ, so the product is ((P·Φᵀ)ᵀ)·Φᵀ, two [`times_phi_t`]. Each element is the sum of
/// the dense product's terms in the dense product's order (nalgebra's static-size `gemm` adds
/// column k's term for k = 0, 1, …), less the terms whose Φ factor is zero, which add nothing:
/// the same value (a zero term could only change the sign of a zero, or turn an infinite P
/// into NaN, which the integrity monitor catches either way).
fn sparse_sandwich(phi: &StateMat, p: &StateMat) -> StateMat {
    times_phi_t(&times_phi_t(p, phi).transpose(), phi)
}

/// X·Φᵀ over Φ's non-zero entries: column j is Σ_k Φ[j, k]·X[:, k], k increasing (column
/// operations, vectorised).
fn times_phi_t(x: &StateMat, phi: &StateMat) -> StateMat {
    let mut out = StateMat::zeros();
    for j in 0..N {
        let mut col = out.column_mut(j);
        for k in 0..N {
            let a = phi[(j, k)];
            if a != 0.0 {
                col.axpy(a, &x.column(k), 1.0);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix1, SMatrix, Vector1};

    /// The sparse Φ·P·Φᵀ gives the dense product's numbers, bit for bit, for a symmetric P
    /// and a Φ of the navigation model's shape (identity plus off-diagonal blocks).
    #[test]
    fn the_sparse_propagation_is_the_dense_one_bit_for_bit() {
        // Deterministic "random" entries: a symmetric positive definite P, and Φ the identity
        // plus about 120 small off-diagonal entries.
        let a = StateMat::from_fn(|i, j| ((i * 7919 + j * 104_729) % 1000) as f64 / 1000.0 - 0.5);
        let p = a * a.transpose() + StateMat::identity();
        let phi = StateMat::from_fn(|i, j| match (i * 31 + j * 17) % 6 {
            _ if i == j => 1.0,
            0 => ((i * 13 + j * 7) % 100) as f64 * 1e-4 - 5e-3,
            _ => 0.0,
        });
        let dense = phi * p * phi.transpose();
        let sparse = sparse_sandwich(&phi, &p);
        assert!(
            dense
                .iter()
                .zip(sparse.iter())
                .all(|(d, s)| d.to_bits() == s.to_bits() || d == s)
        );
    }

    #[test]
    fn scalar_update_matches_the_textbook_and_gates_outliers() {
        let mut f = Eskf::new(StateMat::identity() * 4.0);
        let mut h = SMatrix::<f64, 1, N>::zeros();
        h[(0, 0)] = 1.0;
        // P = 4, R = 1: K = 0.8, posterior variance 0.8.
        match f.update(&Vector1::new(1.0), &h, &Matrix1::new(1.0), 1.0) {
            Update::Accepted { dx, nis } => {
                assert!((dx[0] - 0.8).abs() < 1e-12 && (nis - 0.2).abs() < 1e-12);
            }
            other => panic!("{other:?}"),
        }
        assert!((f.p[(0, 0)] - 0.8).abs() < 1e-12);
        assert!(matches!(
            f.update(&Vector1::new(10.0), &h, &Matrix1::new(1.0), 1.0),
            Update::Rejected { .. }
        ));
    }

    #[test]
    fn a_held_state_keeps_its_estimate_and_variance_and_stays_consistent() {
        // States 0 and 1 correlated at 0.9; state 0 measured. Free, state 1 moves by
        // P10/(P00+R)·dz and its variance shrinks; held, it does neither, and its covariance
        // with state 0 is what the Joseph form gives for that gain: (1 − K0)·P01.
        let mut p = StateMat::identity();
        p[(0, 1)] = 0.9;
        p[(1, 0)] = 0.9;
        let mut h = SMatrix::<f64, 1, N>::zeros();
        h[(0, 0)] = 1.0;
        let (dz, r) = (Vector1::new(1.0), Matrix1::new(1.0));
        let mut free = Eskf::new(p);
        let Update::Accepted { dx, .. } = free.update(&dz, &h, &r, 1.0) else {
            panic!("gated")
        };
        assert!((dx[1] - 0.45).abs() < 1e-12 && free.p[(1, 1)] < 0.6);
        let mut held = Eskf::new(p);
        held.held = Some(1);
        let Update::Accepted { dx, .. } = held.update(&dz, &h, &r, 1.0) else {
            panic!("gated")
        };
        assert!((dx[0] - 0.5).abs() < 1e-12 && dx[1] == 0.0);
        assert!((held.p[(1, 1)] - 1.0).abs() < 1e-12 && (held.p[(0, 0)] - 0.5).abs() < 1e-12);
        assert!((held.p[(0, 1)] - 0.45).abs() < 1e-12);
        assert!(held.p.cholesky().is_some());
    }
}
