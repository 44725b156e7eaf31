//! How sure a lane's exponents are: an error estimate of its own for
//! every row, from the two ways a finite average of ln R_ii misses the
//! limit.
//!
//! - **The frame.** The exponents are Σ ln R_ii over the averaging time
//!   t, and ln R_ii depends on where the frame started until the frame
//!   has turned onto the directions of growth; its projection onto them
//!   stays in the sums as an error of O(1/t). A second direction, started
//!   from the frame's last column (the one furthest from the first), is
//!   pushed through the same Jacobians (J v / |J v|); its Σ ln |J v| over
//!   t estimates λ1 again, and the difference between the two is what the
//!   start of the frame still puts into λ1. An average over a time short
//!   against the system's own time scales (a map period far below them)
//!   shows here: the two starts disagree at the size of the exponents.
//! - **The path.** Each running sum S_i(t) = Σ ln R_ii is λ_i·t plus a
//!   fluctuation, and the estimate λ̂_i = S_i(t_N)/t_N is off by that
//!   fluctuation's change over the run, divided by t_N. With the residual
//!   r_i(t) = S_i(t) - λ̂_i·t (0 at both ends) and R_i its root mean square
//!   over the iterations, √6·R_i/t_N is the standard error of λ̂_i where
//!   the fluctuation is a random walk (a chaotic orbit: r_i is then a
//!   Brownian bridge, whose mean square is σ²t_N/6), and within a factor
//!   1.2 of the largest error where it is a bounded oscillation of the
//!   frame (a complex pair of multipliers, which the frame follows round
//!   for ever: r_i's root mean square is then near its amplitude over √2).
//!   It needs no block length, so it does not alias with the oscillation
//!   as batch means do (blocks of one turn each see no spread at all).
//!
//! The lane's estimate is their sum: the frame's difference plus the
//! largest of the √6·R_i/t_N, per unit time.

use nalgebra::SMatrix;

/// The sums behind a lane's error estimate (see the module's header).
#[derive(Clone, Debug)]
pub struct Uncertainty<const D: usize> {
    /// The second leading direction, unit length.
    probe: [f64; D],
    /// Σ ln |J v| over the averaging Jacobians.
    probe_log: f64,
    /// Over the averaging iterations n: their count, Σ t_n², Σ s_i(t_n)·t_n
    /// and Σ s_i(t_n)², from which Σ r_i² follows once λ̂_i is known, with
    /// s_i = S_i - ρ_i·t the sums less the slopes ρ_i of the first
    /// iteration. Taken from S_i itself, Σ r_i² would be the difference of
    /// numbers of the size of (λ_i·t)²: a stiff lane's λ2 = -2e4 over 1e5
    /// time units put 1e7 of rounding into it, an estimate 1e5 times its
    /// error.
    reference: Option<[f64; D]>,
    points: usize,
    time_squares: f64,
    cross: [f64; D],
    sum_squares: [f64; D],
}

impl<const D: usize> Uncertainty<D> {
    /// The estimate's sums, the second direction started from `start` (the
    /// QR frame's last column).
    pub fn new(start: [f64; D]) -> Self {
        Uncertainty {
            probe: start,
            probe_log: 0.0,
            reference: None,
            points: 0,
            time_squares: 0.0,
            cross: [0.0; D],
            sum_squares: [0.0; D],
        }
    }

    /// Pushes the second direction through one Jacobian; `averaging` says
    /// whether its growth counts (the aligning iterations only turn it).
    pub fn push(&mut self, jacobian: &SMatrix<f64, D, D>, averaging: bool) {
        let image: [f64; D] =
            crate::array::from_fn(|i| (0..D).map(|k| jacobian[(i, k)] * self.probe[k]).sum());
        let norm = image.iter().map(|v| v * v).sum::<f64>().sqrt();
        if norm > 0.0 && norm.is_finite() {
            self.probe = image.map(|v| v / norm);
        }
        if averaging {
            self.probe_log += norm.ln();
        }
    }

    /// Ends an averaging iteration with the QR sums S_i = Σ ln R_ii and the
    /// averaging time t so far.
    pub fn end_iteration(&mut self, log_r: &[f64; D], time: f64) {
        let reference = *self
            .reference
            .get_or_insert_with(|| log_r.map(|s| s / time));
        self.points += 1;
        self.time_squares += time * time;
        for i in 0..D {
            let s = log_r[i] - reference[i] * time;
            self.cross[i] += s * time;
            self.sum_squares[i] += s * s;
        }
    }

    /// The estimate per unit time for a run that ended with the QR sums
    /// `log_r` (in the frame's order) after `time`, its exponents `lambda`
    /// (sorted, non-increasing) of which the last `collapsed` are -∞ and
    /// left out. NaN where it cannot be made: fewer than two iterations,
    /// or a leading exponent that is not finite.
    pub fn error(&self, log_r: &[f64; D], lambda: &[f64], collapsed: usize, time: f64) -> f64 {
        if self.points < 2 || lambda.is_empty() || !lambda[0].is_finite() {
            return f64::NAN;
        }
        let frame = (self.probe_log / time - lambda[0]).abs();
        let n = self.points as f64;
        // The frame's columns, not the sorted exponents: a column keeps its
        // exponent once the frame has turned.
        let kept = D - collapsed.min(D);
        let reference = self.reference.unwrap_or([0.0; D]);
        let path = (0..kept)
            .map(|i| {
                let slope = log_r[i] / time - reference[i];
                let squares = self.sum_squares[i] - 2.0 * slope * self.cross[i]
                    + slope * slope * self.time_squares;
                (6.0 * squares.max(0.0) / n).sqrt() / time
            })
            .fold(0.0, f64::max);
        frame + path
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_map_with_one_fixed_jacobian_is_certain() {
        // J = diag(2, 1/2) from a start off both axes: the second direction
        // turns onto the first axis during the alignment, and the sums grow
        // on straight lines.
        let j = SMatrix::<f64, 2, 2>::new(2.0, 0.0, 0.0, 0.5);
        let mut u = Uncertainty::<2>::new([0.6, 0.8]);
        for _ in 0..60 {
            u.push(&j, false);
        }
        let mut log_r = [0.0; 2];
        for n in 1..=100 {
            u.push(&j, true);
            log_r = [log_r[0] + 2f64.ln(), log_r[1] + 0.5f64.ln()];
            u.end_iteration(&log_r, n as f64);
        }
        let lambda = [2f64.ln(), 0.5f64.ln()];
        assert!(u.error(&log_r, &lambda, 0, 100.0) < 1e-12);
    }

    #[test]
    fn a_path_that_zigzags_gives_its_residual() {
        // ln R alternating 1 and 3: S_n = 2n - 1 for odd n, 2n for even n,
        // so against the line 2t through the end the residual is -1, 0,
        // -1, 0, ... (mean square 1/2), and the estimate √(6/2)/N.
        let n = 1000;
        let mut u = Uncertainty::<1>::new([1.0]);
        let mut log_r = [0.0];
        for k in 1..=n {
            let growth: f64 = if k % 2 == 1 { 1.0 } else { 3.0 };
            log_r[0] += growth;
            u.push(&SMatrix::<f64, 1, 1>::new(growth.exp()), true);
            u.end_iteration(&log_r, k as f64);
        }
        // One dimension: the second direction is the frame, no frame term.
        let expected = 3.0f64.sqrt() / n as f64;
        let error = u.error(&log_r, &[2.0], 0, n as f64);
        assert!(
            (error - expected).abs() < 1e-9 * expected,
            "{error} {expected}"
        );
    }
}
