//! QR accumulation of Lyapunov exponents.
//!
//! From a generic frame Q_0 ([`generic_frame`]), each iteration factors
//! Q_n R_n = J_n Q_{n-1} (Householder, signs fixed so diag R > 0); then
//! λ_i = Σ_n ln R_ii^(n) / (n·T). The columns of Q_n span the most expanding
//! directions in order, so the exponents come out non-increasing once the
//! accumulation has converged.

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

/// The frame the accumulation starts from: the identity turned by a fixed
/// small rotation in general position (the Q of I + M/4, M of fixed
/// quasi-random entries in [-1/2, 1/2]; the same bits everywhere).
///
/// Not the identity itself: a map whose coordinates nearly decouple (a
/// state the rest of the flow barely feeds, like a decaying r' = -5r beside
/// the Lorenz flow) leaves a subspace of coordinate axes almost invariant,
/// and the frame's leading columns then reach a direction outside it only
/// as fast as the coupling (of the size of that state) turns them: from I,
/// the Lorenz section beside r = 1e-152 gave λ2 = -5.87 for -5 over 400
/// iterations, a bias of ln(1/r) in the sum. Here every column has a share
/// of at least a few hundredths of every direction, and the alignment
/// converges at the rate of the exponents' gaps. Nor a rotation far from
/// I: where the coordinates are close to the directions of growth (an
/// over-damped oscillator's position, most weakly coupled systems), the
/// unaligned start's bias, ln of each column's share of its direction over
/// N·T, stays near the identity's small one (a fully random frame put
/// ln 0.34 into λ1 of the stiff oscillator of tests/gpu.rs).
pub fn generic_frame<const D: usize>() -> SMatrix<f64, D, D>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    // Fractional parts of multiples of the golden ratio: equidistributed,
    // and far from any rational (decoupled, symmetric) structure.
    const GOLDEN: f64 = 0.618_033_988_749_894_9;
    let entries = SMatrix::<f64, D, D>::from_fn(|i, j| {
        let k = (i * D + j + 1) as f64;
        let turn = 0.25 * ((k * GOLDEN).fract() - 0.5);
        if i == j {
            1.0 + turn
        } else {
            turn
        }
    });
    qr_positive(entries).0
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
            q: generic_frame(),
            log_r: [0.0; D],
            steps: 0,
        }
    }

    /// Takes one Jacobian J_n; returns diag R_n (all of them finite and
    /// positive unless J_n is singular or not finite).
    pub fn push(&mut self, jacobian: &SMatrix<f64, D, D>) -> [f64; D] {
        let (q, r) = qr_positive(jacobian * self.q);
        self.q = q;
        let diag: [f64; D] = crate::array::from_fn(|i| r[(i, i)]);
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
            let collapsed: [bool; D] = crate::array::from_fn(|i| r[(i, i)] < floor);
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
        let diag: [f64; D] = crate::array::from_fn(|i| r[(i, i)]);
        for (sum, d) in self.log_r.iter_mut().zip(&diag) {
            *sum += d.ln();
        }
        self.steps += 1;
        diag
    }

    /// Forgets the sums, keeping the frame: the iterations pushed so far
    /// only turned Q towards the directions of growth (the transient's
    /// alignment), so that the averaging window starts from them rather
    /// than from the starting frame, whose projection onto those directions
    /// would otherwise stay in the sums as a bias of O(1/N).
    pub fn restart_sums(&mut self) {
        self.log_r = [0.0; D];
        self.steps = 0;
    }

    /// The sums Σ ln R_ii since the last restart, in the frame's order.
    pub fn sums(&self) -> &[f64; D] {
        &self.log_r
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
