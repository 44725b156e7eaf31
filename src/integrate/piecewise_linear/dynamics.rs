//! The linear flow of one mode of a piecewise-linear system in the
//! augmented state z = [y; 1; cos ωt; sin ωt], with the linear functions
//! of z its scan watches and the bounds that certify the scan: what every
//! other part of the propagator is built on.

use nalgebra::{DMatrix, DVector};
use std::f64::consts::SQRT_2;

/// Forcing coordinates appended to the state: 1, cos ωt, sin ωt.
pub(super) const FORCING: usize = 3;

/// What a watched function of z is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Watch {
    /// Surface j's h.
    Surface(usize),
    /// A stick margin of the sliding switch: L − m (reaching 0, the motion
    /// leaves to the positive side, `plus`) or L + m (to the negative).
    Margin { plus: bool },
    /// The force pressing a mass at rest into its stop (reaching 0, it
    /// leaves).
    Release,
}

/// A linear function of z that the scan watches: g = σ k·z.
#[derive(Clone, Debug)]
pub(super) struct Watched {
    pub(super) what: Watch,
    /// k, of length N + 3.
    pub(super) k: DVector<f64>,
    /// σ: g rises through 0 at a crossing.
    pub(super) sign: f64,
    /// An event surface (confining: bounces and sticking apply).
    pub(super) event: bool,
    /// (|r_y|, √2 |r_w|) with [r_y; r_w] = (Bᵀ)³ k, so that
    /// |g'''| = |r_y·y + r_w·w| ≤ |r_y||y| + √2 |r_w|.
    pub(super) jerk: (f64, f64),
}

/// The linear flow of one mode (a region, or sliding on a switch) with the
/// functions its scan watches and their bounds.
#[derive(Clone, Debug)]
pub(super) struct Dynamics {
    /// B, the augmented generator.
    pub(super) b: DMatrix<f64>,
    /// tr of B's state block.
    pub(super) trace: f64,
    /// max(μ₂(A), 0), μ₂ the logarithmic 2-norm λ_max((A + Aᵀ)/2), A the
    /// state block of B.
    pub(super) growth: f64,
    /// √2 |[c p q]|_F ≥ |c + p cos + q sin|.
    pub(super) drive: f64,
    pub(super) watch: Vec<Watched>,
}

/// What a segment integrates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Mode {
    /// A region's field.
    Region(usize),
    /// Sliding on switch `switch`, the other switches' sides those of
    /// `sides` (whose own bit is the side the motion arrived from).
    Sliding { switch: usize, sides: usize },
    /// At rest on stop `event` (an event surface x_i = d whose reset
    /// reverses x_i's velocity x_j, [`PiecewiseLinear::stop_of`]), pressed
    /// into it, in region `sides`: x_i and x_j held, the other states
    /// moving on (the RK4 path's `impact::stuck_step`).
    Held { event: usize, sides: usize },
}

/// σ of switch `bit` for a motion in `region`: g = σh rises through 0 at a
/// crossing (events, bit None, are approached from below).
pub(super) fn side_sign(bit: Option<u32>, region: usize) -> f64 {
    match bit {
        Some(b) if region & (1 << b) != 0 => -1.0,
        _ => 1.0,
    }
}

/// z = [y; 1; cos ωt; sin ωt].
pub(super) fn augment(y: &DVector<f64>, omega: f64, t: f64) -> DVector<f64> {
    let n = y.len();
    let (sin, cos) = (omega * t).sin_cos();
    let mut z = DVector::zeros(n + FORCING);
    z.rows_mut(0, n).copy_from(y);
    z[n] = 1.0;
    z[n + 1] = cos;
    z[n + 2] = sin;
    z
}

/// The flow of generator `b` with the scan's bounds for the functions
/// `watch` (what, k, σ) (see [`Dynamics`]).
pub(super) fn dynamics(
    b: DMatrix<f64>,
    watch: Vec<(Watch, DVector<f64>, f64)>,
    event: impl Fn(Watch) -> bool,
) -> Dynamics {
    let n = b.nrows() - FORCING;
    let a = b.view((0, 0), (n, n)).into_owned();
    let symmetric = (&a + a.transpose()) * 0.5;
    // The eigenvalues are exact to about ε|A|; the margin keeps the bound an
    // upper one.
    let margin = 64.0 * f64::EPSILON * a.norm();
    let growth = (symmetric.symmetric_eigenvalues().max() + margin).max(0.0);
    let drive = SQRT_2 * b.view((0, n), (n, FORCING)).norm();
    let bt = b.transpose();
    let watch = watch
        .into_iter()
        .map(|(what, k, sign)| {
            let r = &bt * (&bt * (&bt * &k));
            Watched {
                what,
                event: event(what),
                jerk: (r.rows(0, n).norm(), SQRT_2 * r.rows(n, FORCING).norm()),
                k,
                sign,
            }
        })
        .collect();
    Dynamics {
        trace: a.trace(),
        b,
        growth,
        drive,
        watch,
    }
}
