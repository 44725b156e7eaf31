//! QR accumulation of Lyapunov exponents.
//!
//! With Q_0 = I, each iteration factors Q_n R_n = J_n Q_{n-1} (Householder,
//! signs fixed so diag R > 0); then λ_i = Σ_n ln R_ii^(n) / (n·T). The columns
//! of Q_n span the most expanding directions in order, so the exponents come
//! out non-increasing once the accumulation has converged.

use nalgebra::{Const, DimMin, SMatrix};

/// QR factorisation with diag R > 0 (unique for invertible matrices).
pub fn qr_positive<const D: usize>(
    m: SMatrix<f64, D, D>,
) -> (SMatrix<f64, D, D>, SMatrix<f64, D, D>)
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let qr = m.qr();
    let (mut q, mut r) = (qr.q(), qr.r());
    for i in 0..D {
        if r[(i, i)] < 0.0 {
            // Q R = (Q S)(S R) with S = diag(±1): flip row i of R and column i of Q.
            r.row_mut(i).neg_mut();
            q.column_mut(i).neg_mut();
        }
    }
    (q, r)
}

/// The running sums Σ ln R_ii and the current orthonormal frame Q_n.
#[derive(Clone, Debug)]
pub struct QrAccumulator<const D: usize> {
    q: SMatrix<f64, D, D>,
    log_r: [f64; D],
    steps: usize,
}

impl<const D: usize> Default for QrAccumulator<D>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    fn default() -> Self {
        Self::new()
    }
}

impl<const D: usize> QrAccumulator<D>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    pub fn new() -> Self {
        QrAccumulator {
            q: SMatrix::identity(),
            log_r: [0.0; D],
            steps: 0,
        }
    }

    /// Takes one Jacobian J_n; returns diag R_n (all of them finite and
    /// positive unless J_n is singular or not finite).
    pub fn push(&mut self, jacobian: &SMatrix<f64, D, D>) -> [f64; D] {
        let (q, r) = qr_positive(jacobian * self.q);
        self.q = q;
        let diag: [f64; D] = std::array::from_fn(|i| r[(i, i)]);
        for (sum, d) in self.log_r.iter_mut().zip(&diag) {
            *sum += d.ln();
        }
        self.steps += 1;
        diag
    }

    /// [`push`](Self::push) of a Jacobian that may have collapsed up to
    /// `at_most` directions (sliding phases): a column of the frame that
    /// J maps to below `floor` (R_ii < floor, rounding) ahead of one that
    /// it does not is moved to the frame's end, and J·Q factored again, so
    /// the collapsed directions take the last positions, as the exponents'
    /// -∞ assume. In exact arithmetic such a column's R_ii is 0 and its
    /// frame direction arbitrary; kept in place, its rounding (ln R_ii ≈
    /// -23 at δ = 1e-6) would land in a finite exponent's sum: two
    /// uncoupled blocks from the identity frame, whose first two columns
    /// both lie in the first block's plane, put it in λ2 (4.7e-3 per unit
    /// time over 300 periods of 15.7, measured). A frame whose collapsed
    /// columns are already last is factored exactly as by `push`.
    pub fn push_collapsing(
        &mut self,
        jacobian: &SMatrix<f64, D, D>,
        floor: f64,
        at_most: usize,
    ) -> [f64; D] {
        let mut frame = self.q;
        let (mut q, mut r) = qr_positive(jacobian * frame);
        for _ in 0..at_most {
            let collapsed: [bool; D] = std::array::from_fn(|i| r[(i, i)] < floor);
            let ahead = (0..D).find(|&i| collapsed[i] && collapsed[i + 1..].iter().any(|c| !c));
            let Some(i) = ahead else {
                break;
            };
            frame = SMatrix::from_fn(|row, col| {
                let from = match col {
                    c if c < i => c,
                    c if c == D - 1 => i,
                    c => c + 1,
                };
                frame[(row, from)]
            });
            (q, r) = qr_positive(jacobian * frame);
        }
        self.q = q;
        let diag: [f64; D] = std::array::from_fn(|i| r[(i, i)]);
        for (sum, d) in self.log_r.iter_mut().zip(&diag) {
            *sum += d.ln();
        }
        self.steps += 1;
        diag
    }

    /// Forgets the sums, keeping the frame: the iterations pushed so far
    /// only turned Q towards the directions of growth (the transient's
    /// alignment), so that the averaging window starts from them rather
    /// than from I, whose projection onto those directions would otherwise
    /// stay in the sums as a bias of O(1/N).
    pub fn restart_sums(&mut self) {
        self.log_r = [0.0; D];
        self.steps = 0;
    }

    /// The current frame Q_n.
    pub fn frame(&self) -> &SMatrix<f64, D, D> {
        &self.q
    }

    /// λ_i = Σ ln R_ii / time, over a total `time` however many matrices
    /// it took (a Poincaré map's factors of return times of their own).
    pub fn exponents_over(&self, time: f64) -> [f64; D] {
        self.log_r.map(|s| s / time)
    }

    /// λ_i = Σ ln R_ii / (steps · period), in the order of the frame's columns.
    pub fn exponents(&self, period: f64) -> [f64; D] {
        let time = self.steps as f64 * period;
        self.log_r.map(|s| s / time)
    }
}
