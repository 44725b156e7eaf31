//! The perturbation estimate of the map's Jacobian (the paper's eq. 6):
//! column i of DU(x_n) ≈ (U(x_n + δ·e_i) - U(x_n)) / δ.
//!
//! The perturbed copies restart from x_n every iteration, so they never
//! separate far enough to leave the linear regime, and a copy crossing a
//! discontinuity (an impact) needs no special linearisation.

use nalgebra::SMatrix;

use crate::integrate::clock::Phase;
use crate::model::compiled::MAX_STATES;
pub use crate::perturbation::Difference;
use crate::system::{FlowSettings, IterationStats, Part, System};

/// Trajectories an estimate integrates at most: the reference and 2D copies
/// for central differences, D up to a model's most states (a period map's
/// dimension is its states').
const MAX_TRAJECTORIES: usize = 1 + 2 * MAX_STATES;

/// Integrates the reference from x and its perturbed copies together (in
/// lockstep, see [`crate::integrate::time_map_many`]) and returns U(x) and
/// the estimated DU(x) ([`Copies`]).
///
/// `part` of the iteration (the whole one, or a sub-map) starts at the
/// forcing phase `phase`, which is advanced to the part's end.
#[allow(clippy::too_many_arguments)]
pub fn estimate<const D: usize, S: System<D>>(
    system: &S,
    flow: &FlowSettings,
    part: Part,
    phase: &mut Phase,
    x: &[f64; D],
    delta: f64,
    difference: Difference,
    stats: &mut IterationStats,
) -> ([f64; D], SMatrix<f64, D, D>) {
    let copies = Copies::new(system, x, delta, difference);
    let n = copies.count();
    let mut ys = [[0.0; D]; MAX_TRAJECTORIES];
    ys[..n].copy_from_slice(copies.starts());
    let mut st = [IterationStats::default(); MAX_TRAJECTORIES];
    system.part_many(&mut ys[..n], flow, part, phase, &mut st[..n]);
    copies.difference(&ys[..n], &st[..n], stats)
}

/// The trajectories of one Jacobian estimate: the reference from x and its
/// perturbed copies. [`new`](Self::new) starts them, whoever integrates
/// them ([`estimate`], or a batch across lanes, `method::lane::run_lanes`),
/// and [`difference`](Self::difference) takes U(x) and DU(x) from their
/// ends.
///
/// Forward (the paper's eq. 6): column i = (U(x + δe_i) - U(x)) / δ⁺_i.
/// Central: column i = (U(x + δe_i) - U(x - δe_i)) / (δ⁺_i + δ⁻_i). The steps
/// actually taken, δ⁺ = (x_i + δ) - x_i and δ⁻ = x_i - (x_i - δ), not δ: the
/// two differ by the rounding of x_i ± δ, which would otherwise bias every
/// column by up to ulp(x_i)/δ.
///
/// With central differences, a copy that met the wall a different number of
/// times than the reference crossed a grazing boundary, where the map is not
/// smooth and its difference is O(1) wrong: that column is then differenced
/// on the other side, one-sided against the reference image.
#[derive(Clone, Copy, Debug)]
pub struct Copies<const D: usize> {
    starts: [[f64; D]; MAX_TRAJECTORIES],
    steps: [f64; MAX_TRAJECTORIES],
    admitted: [bool; MAX_TRAJECTORIES],
    difference: Difference,
}

impl<const D: usize> Copies<D> {
    /// The reference at x and its copies at δ from it.
    pub fn new<S: System<D>>(system: &S, x: &[f64; D], delta: f64, difference: Difference) -> Self {
        let copies = difference.copies(D);
        assert!(
            copies < MAX_TRAJECTORIES,
            "dimension {D} is above the supported {MAX_STATES}"
        );
        let mut ys = [*x; MAX_TRAJECTORIES];
        let mut steps = [0.0; MAX_TRAJECTORIES];
        for c in 0..copies {
            let (i, sign) = if c < D { (c, 1.0) } else { (c - D, -1.0) };
            let y = &mut ys[1 + c];
            y[i] += sign * delta;
            steps[1 + c] = sign * (y[i] - x[i]);
        }
        // A copy that would start behind the wall (the reference is within δ
        // of it) is no perturbation of the reference's motion: the wall throws
        // it back at once, and its column would be O(1) wrong. Like a copy that
        // crossed a grazing boundary, it is differenced on the other side.
        let admitted = crate::array::from_fn(|t| system.admits(&ys[t]));
        Copies {
            starts: ys,
            steps,
            admitted,
            difference,
        }
    }

    /// How many trajectories: the reference and its copies.
    pub fn count(&self) -> usize {
        1 + self.difference.copies(D)
    }

    /// The trajectories' starts, the reference first, to be integrated
    /// over the iteration (or part).
    pub fn starts(&self) -> &[[f64; D]] {
        &self.starts[..self.count()]
    }

    /// U(x) and the estimated DU(x) from the trajectories' ends `ys` and
    /// their statistics `st` (the reference's first); the reference's
    /// counts are added to `stats`.
    pub fn difference(
        &self,
        ys: &[[f64; D]],
        st: &[IterationStats],
        stats: &mut IterationStats,
    ) -> ([f64; D], SMatrix<f64, D, D>) {
        let (steps, admitted) = (&self.steps, &self.admitted);
        stats.impacts += st[0].impacts;
        stats.time += st[0].time;
        stats.log_flux += st[0].log_flux;
        for (c, r) in stats.crossings.iter_mut().zip(st[0].crossings) {
            *c += r;
        }
        stats.rank_loss = stats.rank_loss.max(st[0].rank_loss);
        stats.sliding_phases += st[0].sliding_phases;
        stats.chattering |= st.iter().any(|s| s.chattering);
        stats.too_many_events |= st.iter().any(|s| s.too_many_events);
        stats.sliding |= st.iter().any(|s| s.sliding);

        let image = ys[0];
        let same = |t: usize| admitted[t] && st[t].crossings == st[0].crossings;
        // How far a copy's impacts moved, relative to the reference's: near
        // grazing, an impact at speed v moves by δ·a/v² of itself (a the
        // acceleration at the wall), and so does the difference quotient.
        let departure = |t: usize| {
            if t == 0 {
                0.0
            } else if !admitted[t] {
                f64::INFINITY
            } else if st[0].slowest_impact == f64::INFINITY {
                // No impact (nor section crossing) to move.
                0.0
            } else if !same(t) {
                f64::INFINITY
            } else {
                (st[t].slowest_impact - st[0].slowest_impact).abs() / st[0].slowest_impact
            }
        };
        // How far a central column's two copies left the linear regime
        // between the stops: |U₊ + U₋ - 2U₀| / |U₊ - U₋| (max norms) is
        // δ·|U''|/|U'|, the size of the second-order term the central
        // difference cancels only at its own order. A flow that expands in
        // bursts within one iteration (the Dadras flow's period map) carries
        // its copies out of the linear regime without any impact; such an
        // iteration is re-estimated with the δ ladder like a grazing one.
        // Twin of the finish kernel's `asymmetry` (model::ir::finish).
        let asymmetry = |a: usize, b: usize| {
            if a == 0 || b == 0 {
                return 0.0;
            }
            let (mut even, mut odd) = (0.0_f64, 0.0_f64);
            for ((up, down), at) in ys[a].iter().zip(&ys[b]).zip(&ys[0]) {
                let (plus, minus) = (up - at, down - at);
                even = even.max((plus + minus).abs());
                odd = odd.max((plus - minus).abs());
            }
            if even == 0.0 {
                0.0
            } else {
                even / odd
            }
        };
        let mut jacobian = SMatrix::<f64, D, D>::zeros();
        stats.nonlinearity = 0.0;
        for i in 0..D {
            let (plus, minus) = (1 + i, 1 + D + i);
            let (a, b, step) = match self.difference {
                Difference::Forward => (plus, 0, steps[plus]),
                Difference::Central => match (same(plus), same(minus)) {
                    (false, true) => (0, minus, steps[minus]),
                    (true, false) => (plus, 0, steps[plus]),
                    _ => (plus, minus, steps[plus] + steps[minus]),
                },
            };
            stats.nonlinearity = stats
                .nonlinearity
                .max(departure(a))
                .max(departure(b))
                .max(asymmetry(a, b));
            for k in 0..D {
                jacobian[(k, i)] = (ys[a][k] - ys[b][k]) / step;
            }
        }
        stats.slowest_impact = stats.slowest_impact.min(st[0].slowest_impact);
        (image, jacobian)
    }
}
