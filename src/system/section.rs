//! A model's Poincaré map: an autonomous flow in N states reduced to its
//! returns to a section y_k = c (seed eq. 1-2). The map's coordinates are
//! the other N - 1 states in order; perturbations are taken in them on the
//! section, and each trajectory runs to its own next crossing
//! (`integrate::section`). One iteration lasts its return time; exponents
//! are per unit of the total time, and the sum rule gains the section's
//! flux term ln |F_k(x_0)/F_k(x_n)| (see `IterationStats::log_flux`).
//!
//! A section has no period: `steps_per_period` counts RK4 steps per unit
//! time. Iterations are not cut into parts (the method's sub-maps), so a
//! strongly contracting direction is resolved only as far as one return's
//! finite difference does (the lane's resolution bound says how far).

use nalgebra::{DMatrix, SMatrix};

use super::model::ModelFlow;
use super::{FlowSettings, IterationStats, Params, System};
use crate::integrate::clock::{Phase, ZERO_PHASE};
use crate::integrate::section::{advance, next_crossings, Crossing, Section};
use crate::integrate::{Flow, Stop};
use crate::model::compiled::Code;
use crate::model::ir::tape::Tape;
use crate::perturbation::{perturbation_at, Difference};

/// The contraction one part of a return may have, e^PART_CONTRACTION: far
/// above the finite difference's rounding noise (see `tangent_factors`).
const PART_CONTRACTION: f64 = 4.0;

/// A return that takes longer than this many time units is no return:
/// the trajectory does not come back to the section (the lane fails with
/// `no-return`, see [`crate::system::NO_RETURN`]).
const MAX_RETURN_TIME: f64 = 1e4;

/// The Poincaré map of a model's flow in N = D + 1 states.
#[derive(Clone, Debug)]
pub struct SectionFlow<const D: usize, const N: usize> {
    flow: ModelFlow<N>,
    section: Section,
    /// div F where it depends on the state, with its lane constants: its
    /// integral along the reference's return joins the flux term.
    divergence: Option<(&'static Tape, Vec<f64>)>,
}

/// One return of the reference to the section: the map's image (NaN
/// where there is no return), the time it took, the flux term
/// ln |F_k(start)/F_k(end)| and the speed through the section.
#[derive(Clone, Copy, Debug)]
pub struct Return<const D: usize> {
    pub image: [f64; D],
    pub time: f64,
    pub log_flux: f64,
    pub speed: f64,
}

impl<const D: usize> Return<D> {
    pub fn add_to(&self, stats: &mut IterationStats) {
        stats.time += self.time;
        stats.log_flux += self.log_flux;
        // A slow crossing is a near-tangency of the section, where a copy
        // may cross elsewhere (or a loop later): the grazing test of
        // impacts applies to it as it is.
        stats.slowest_impact = stats.slowest_impact.min(self.speed);
    }
}

/// The tangent map of one return, built part by part (see
/// `tangent_factors`): each part runs the reference and its copies for
/// `steps` RK4 steps of `h` from `y`.
#[derive(Clone, Debug)]
pub struct TangentParts<const N: usize> {
    pub parts: usize,
    pub steps: usize,
    pub h: f64,
    /// The reference at the start of the next part.
    pub y: [f64; N],
    /// The directions the copies start along (N×D, orthonormal).
    frame: DMatrix<f64>,
}

impl<const D: usize, const N: usize> SectionFlow<D, N> {
    /// The point of the flow on the section with map coordinates x.
    pub fn lift(&self, x: &[f64; D]) -> [f64; N] {
        let k = self.section.state;
        crate::array::from_fn(|i| match i.cmp(&k) {
            std::cmp::Ordering::Less => x[i],
            std::cmp::Ordering::Equal => self.section.at,
            std::cmp::Ordering::Greater => x[i - 1],
        })
    }

    /// The map coordinates of a point of the flow (on the section).
    fn project(&self, y: &[f64; N]) -> [f64; D] {
        let k = self.section.state;
        crate::array::from_fn(|i| if i < k { y[i] } else { y[i + 1] })
    }

    pub fn flow(&self) -> &ModelFlow<N> {
        &self.flow
    }

    pub fn section(&self) -> &Section {
        &self.section
    }

    /// The RK4 step of a return and the most steps one may take.
    pub fn return_steps(flow: &FlowSettings) -> (f64, usize) {
        (
            1.0 / flow.steps_per_period as f64,
            (MAX_RETURN_TIME * flow.steps_per_period as f64) as usize,
        )
    }

    /// The return from `start` that ended in `crossing` (none: an image of
    /// [`crate::system::NO_RETURN`], the time and flux NaN).
    pub fn return_from(&self, start: &[f64; N], crossing: Crossing<N>) -> Return<D> {
        let velocity = |y: &[f64; N]| self.flow.rhs(&ZERO_PHASE, y)[self.section.state];
        match crossing {
            Some((y, time)) => Return {
                image: self.project(&y),
                time,
                log_flux: (velocity(start) / velocity(&y)).abs().ln(),
                speed: velocity(&y).abs(),
            },
            None => Return {
                image: [crate::system::NO_RETURN; D],
                time: f64::NAN,
                log_flux: f64::NAN,
                speed: f64::NAN,
            },
        }
    }

    /// The next crossing of each of `ys`.
    fn returns(&self, ys: &[[f64; N]], flow: &FlowSettings) -> Vec<Return<D>> {
        let (h, max_steps) = Self::return_steps(flow);
        next_crossings(&self.flow, &self.section, ys, h, max_steps)
            .into_iter()
            .zip(ys)
            .map(|(crossing, start)| self.return_from(start, crossing))
            .collect()
    }

    /// The parts of the tangent map of a return of time τ from x: as many
    /// as keep each part's contraction within e^PART_CONTRACTION, each of
    /// whole steps no longer than the return's.
    pub fn tangent_parts(&self, x: &[f64; D], tau: f64, flow: &FlowSettings) -> TangentParts<N> {
        let h = 1.0 / flow.steps_per_period as f64;
        let parts = ((self.flow.contraction() * tau / PART_CONTRACTION).ceil() as usize).max(1);
        let span = tau / parts as f64;
        let steps = (span / h).ceil().max(1.0) as usize;
        let k = self.section.state;
        // The frame: the section's coordinates, as directions of the flow.
        let mut frame = DMatrix::<f64>::zeros(N, D);
        for i in 0..D {
            frame[(if i < k { i } else { i + 1 }, i)] = 1.0;
        }
        TangentParts {
            parts,
            steps,
            h: span / steps as f64,
            y: self.lift(x),
            frame,
        }
    }

    /// The next part's perturbation δ and its trajectories: the reference,
    /// then the copies at y ± δ·q_i along the frame's columns.
    pub fn part_starts(
        &self,
        part: &TangentParts<N>,
        relative_delta: f64,
        difference: Difference,
    ) -> (f64, Vec<[f64; N]>) {
        let delta = perturbation_at(relative_delta, &part.y);
        let copies = difference.copies(D);
        let mut ys = vec![part.y; 1 + copies];
        for (c, copy) in ys[1..].iter_mut().enumerate() {
            let (i, sign) = if c < D { (c, 1.0) } else { (c - D, -1.0) };
            for (r, v) in copy.iter_mut().enumerate() {
                *v += sign * delta * part.frame[(r, i)];
            }
        }
        (delta, ys)
    }

    /// ∫ div F along the reference over the next part, where div F depends
    /// on the state (its end is the reference's to the bit).
    pub fn part_divergence(&self, part: &TangentParts<N>, stop: &Stop) -> Option<f64> {
        let (tape, constants) = self.divergence.as_ref()?;
        let density = |_: &Phase, y: &[f64; N]| -> f64 {
            let y: [[f64; 1]; N] = crate::array::from_fn(|i| [y[i]]);
            let out: [[f64; 1]; 1] = tape.eval(|j| [constants[j]], &[ZERO_PHASE], &y);
            out[0][0]
        };
        let (_, integral) = crate::integrate::advance_integrating(
            &self.flow,
            &part.y,
            ZERO_PHASE,
            // A section's flow is autonomous: its steps' phases are all zero.
            (part.h, ZERO_PHASE),
            part.steps,
            density,
            stop,
        );
        Some(integral)
    }

    /// The factor R_j of a part from its trajectories' ends `ys`, with the
    /// next part's frame and start.
    pub fn part_end(
        &self,
        part: &mut TangentParts<N>,
        ys: &[[f64; N]],
        delta: f64,
        difference: Difference,
    ) -> SMatrix<f64, D, D> {
        let mut columns = DMatrix::<f64>::zeros(N, D);
        for i in 0..D {
            for r in 0..N {
                columns[(r, i)] = match difference {
                    Difference::Forward => (ys[1 + i][r] - ys[0][r]) / delta,
                    Difference::Central => (ys[1 + i][r] - ys[1 + D + i][r]) / (2.0 * delta),
                };
            }
        }
        // Remove the flow direction: the projection onto the section at
        // the return kills it (P·Φ(τ, t)·F(y(t)) = P·F(y(τ)) = 0), and
        // left in, the neutral direction would crowd the contracting
        // one out of the frame, to be cancelled at the end.
        let f = self.flow.rhs(&ZERO_PHASE, &ys[0]);
        let norm = f.iter().map(|v| v * v).sum::<f64>().sqrt();
        if norm > 0.0 {
            for i in 0..D {
                let along: f64 = (0..N).map(|r| f[r] * columns[(r, i)]).sum::<f64>() / norm;
                for r in 0..N {
                    columns[(r, i)] -= along * f[r] / norm;
                }
            }
        }
        let qr = columns.qr();
        let (mut q, mut r) = (qr.q(), qr.r());
        for i in 0..D {
            if r[(i, i)] < 0.0 {
                q.column_mut(i).neg_mut();
                r.row_mut(i).neg_mut();
            }
        }
        part.frame = q;
        part.y = ys[0];
        SMatrix::from_fn(|a, b| r[(a, b)])
    }

    /// The last factor, P·Q at the return point (the located crossing, on
    /// the section): the frame projected onto the section along the flow.
    pub fn last_factor(&self, part: &TangentParts<N>, image: &[f64; D]) -> SMatrix<f64, D, D> {
        let k = self.section.state;
        let end = self.lift(image);
        let f = self.flow.rhs(&ZERO_PHASE, &end);
        SMatrix::<f64, D, D>::from_fn(|a, b| {
            let row = if a < k { a } else { a + 1 };
            part.frame[(row, b)] - f[row] / f[k] * part.frame[(k, b)]
        })
    }
}

impl<const D: usize, const N: usize> System<D> for SectionFlow<D, N> {
    fn new(p: &Params) -> Self {
        let code: &Code = p.info.model.expect("a model's parameters");
        let section = code.section.as_ref().expect("a section model");
        SectionFlow {
            divergence: code
                .divergence_along
                .as_ref()
                .map(|tape| (tape, tape.lane_values(&p.values).constants)),
            flow: ModelFlow::new(p),
            section: Section {
                state: section.state,
                at: section.at.eval(&[], &p.values, 0.0),
                direction: if section.increasing { 1.0 } else { -1.0 },
            },
        }
    }

    /// The unit of time over which `steps_per_period` counts steps.
    fn period(&self) -> f64 {
        1.0
    }

    fn iterate(&self, x: &[f64; D], flow: &FlowSettings, stats: &mut IterationStats) -> [f64; D] {
        let mut ys = [*x];
        self.iterate_many(&mut ys, flow, std::slice::from_mut(stats));
        ys[0]
    }

    fn iterate_many(&self, xs: &mut [[f64; D]], flow: &FlowSettings, stats: &mut [IterationStats]) {
        let starts: Vec<[f64; N]> = xs.iter().map(|x| self.lift(x)).collect();
        for ((x, st), back) in xs
            .iter_mut()
            .zip(stats.iter_mut())
            .zip(self.returns(&starts, flow))
        {
            *x = back.image;
            back.add_to(st);
        }
    }

    /// The tangent map of one return, U'(x) = P·Φ(τ)·E, as factors: E
    /// embeds the section's coordinates in the flow's, Φ(τ) is the flow's
    /// tangent map over the reference's return time τ and P projects onto
    /// the section along the flow at the return point y (P = S·(I - F
    /// e_kᵀ/F_k), S dropping coordinate k). Φ is estimated by the paper's
    /// perturbed copies, but of the flow over fixed times, in parts short
    /// enough that no column contracts below the rounding noise: the
    /// copies start along the columns of an orthonormal frame Q (N×D), and
    /// each part's Φ_j·Q = Q'·R_j gives the factor R_j and the next frame.
    /// The last factor is P·Q. No copy has to find the section, so a
    /// near-tangent return (F_k small) is as well resolved as any other.
    fn tangent_factors(
        &self,
        x: &[f64; D],
        flow: &FlowSettings,
        relative_delta: f64,
        difference: Difference,
        stats: &mut IterationStats,
        factors: &mut Vec<SMatrix<f64, D, D>>,
    ) -> Option<[f64; D]> {
        let back = self.returns(&[self.lift(x)], flow)[0];
        back.add_to(stats);
        if !back.time.is_finite() {
            return Some(back.image);
        }
        let mut part = self.tangent_parts(x, back.time, flow);
        for _ in 0..part.parts {
            let (delta, mut ys) = self.part_starts(&part, relative_delta, difference);
            advance(&self.flow, &mut ys, part.h, part.steps);
            if let Some(integral) = self.part_divergence(&part, &flow.stop) {
                stats.log_flux += integral;
            }
            factors.push(self.part_end(&mut part, &ys, delta, difference));
        }
        factors.push(self.last_factor(&part, &back.image));
        Some(back.image)
    }

    /// From a point of the flow (all N states) to its first crossing.
    fn start(&self, initial: &[f64], flow: &FlowSettings) -> [f64; D] {
        let y: [f64; N] = crate::array::from_fn(|i| initial[i]);
        self.returns(&[y], flow)[0].image
    }

    fn stiffness(&self) -> f64 {
        self.flow.stiffness()
    }

    /// Parts are not taken (see the module's note).
    fn contraction(&self) -> f64 {
        0.0
    }
}
