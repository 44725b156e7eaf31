//! Poincaré sections: the flow of an autonomous system from a point to its
//! next crossing of a coordinate plane y_k = c in a given direction, located
//! on the integrator's own solution as accurately as an impact (Newton on
//! re-stepped RK4 from the step's cubic Hermite interpolant).
//!
//! The trajectories of a lane (the reference and its perturbed copies)
//! reach the section at different times: they are stepped together in one
//! structure-of-arrays batch, and each leaves the batch when it crosses.

use super::avx2::vectorised;
use super::clock::{Phase, ZERO_PHASE};
use super::flow::Flow;
use super::locate::{newton_in_bracket, Hermite};
use super::rk4;

/// The plane y_state = at, crossed in `direction` (+1: increasing).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Section {
    pub state: usize,
    pub at: f64,
    pub direction: f64,
}

impl Section {
    /// Signed distance past the section in the crossing direction.
    #[inline(always)]
    pub fn distance<const N: usize>(&self, y: &[f64; N]) -> f64 {
        self.direction * (y[self.state] - self.at)
    }

    /// Whether a step from `before` to `after` crosses it: from behind it
    /// to on or past it (the section kernel's `crossed`, generated from
    /// model::ir::section, is its twin).
    #[inline(always)]
    pub fn crossed<const N: usize>(&self, before: &[f64; N], after: &[f64; N]) -> bool {
        self.distance(before) < 0.0 && self.distance(after) >= 0.0
    }

    /// Its rate of change along the flow.
    pub fn rate<const N: usize, F: Flow<N>>(&self, flow: &F, y: &[f64; N]) -> f64 {
        self.direction * flow.rhs(&ZERO_PHASE, y)[self.state]
    }
}

/// Where one trajectory met the section: the state (y_state = at exactly)
/// and the time it took; `None` when it did not within the steps allowed.
pub type Crossing<const N: usize> = Option<([f64; N], f64)>;

/// Trajectories stepped together per batch.
const BATCH: usize = 8;

/// Steps each of `ys` with RK4 steps of h (at most `max_steps`) until it
/// crosses `section` (from behind it to on or past it), and returns each
/// crossing. A start on the section counts only once it has left it.
pub fn next_crossings<const N: usize, F: Flow<N>>(
    flow: &F,
    section: &Section,
    ys: &[[f64; N]],
    h: f64,
    max_steps: usize,
) -> Vec<Crossing<N>> {
    let mut out = Vec::with_capacity(ys.len());
    for chunk in ys.chunks(BATCH) {
        vectorised(
            #[inline(always)]
            || match chunk.len() {
                1 => out.extend(batch::<N, 1, F>(flow, section, chunk, h, max_steps)),
                2..=4 => out.extend(batch::<N, 4, F>(flow, section, chunk, h, max_steps)),
                _ => out.extend(batch::<N, BATCH, F>(flow, section, chunk, h, max_steps)),
            },
        );
    }
    out
}

#[inline(always)]
fn batch<const N: usize, const W: usize, F: Flow<N>>(
    flow: &F,
    section: &Section,
    ys: &[[f64; N]],
    h: f64,
    max_steps: usize,
) -> Vec<Crossing<N>> {
    let n = ys.len();
    let mut y: [[f64; W]; N] =
        crate::array::from_fn(|i| crate::array::from_fn(|w| ys[w.min(n - 1)][i]));
    let mut crossed: Vec<Crossing<N>> = vec![None; n];
    let mut open = n;
    let stages: [Phase; 3] = [ZERO_PHASE; 3];
    for step in 0..max_steps {
        let y1 = flow.step_shared(&stages, &y, h);
        for k in 0..n {
            if crossed[k].is_some() {
                continue;
            }
            let before: [f64; N] = crate::array::from_fn(|i| y[i][k]);
            let after: [f64; N] = crate::array::from_fn(|i| y1[i][k]);
            if section.crossed(&before, &after) {
                crossed[k] = Some(crossing_in_step(flow, section, &before, &after, h, step));
                open -= 1;
            }
        }
        if open == 0 {
            break;
        }
        y = y1;
    }
    crossed
}

/// Steps each of `ys` by `steps` RK4 steps of h (an autonomous flow),
/// as structure-of-arrays batches.
pub fn advance<const N: usize, F: Flow<N>>(flow: &F, ys: &mut [[f64; N]], h: f64, steps: usize) {
    for chunk in ys.chunks_mut(BATCH) {
        vectorised(
            #[inline(always)]
            || match chunk.len() {
                1 => advance_batch::<N, 1, F>(flow, chunk, h, steps),
                2..=4 => advance_batch::<N, 4, F>(flow, chunk, h, steps),
                _ => advance_batch::<N, BATCH, F>(flow, chunk, h, steps),
            },
        );
    }
}

#[inline(always)]
fn advance_batch<const N: usize, const W: usize, F: Flow<N>>(
    flow: &F,
    ys: &mut [[f64; N]],
    h: f64,
    steps: usize,
) {
    let n = ys.len();
    let mut y: [[f64; W]; N] =
        crate::array::from_fn(|i| crate::array::from_fn(|w| ys[w.min(n - 1)][i]));
    let stages: [Phase; 3] = [ZERO_PHASE; 3];
    for _ in 0..steps {
        y = flow.step_shared(&stages, &y, h);
    }
    for (k, out) in ys.iter_mut().enumerate() {
        *out = crate::array::from_fn(|i| y[i][k]);
    }
}

/// The crossing inside RK4 step number `step` (of h, counted from the
/// start) from `before` to `after`, which [`Section::crossed`]: the state
/// on the section and the time from the start. The GPU steps the
/// trajectories and hands the host the crossing step, which locates it
/// here as the CPU does.
pub fn crossing_in_step<const N: usize, F: Flow<N>>(
    flow: &F,
    section: &Section,
    before: &[f64; N],
    after: &[f64; N],
    h: f64,
    step: usize,
) -> ([f64; N], f64) {
    let (s, at) = locate(flow, section, before, after, h);
    (at, step as f64 * h + s)
}

/// The crossing inside the step from y0 to y1 (distance < 0 before, ≥ 0
/// after): its offset s into the step and the state RK4 reaches there,
/// with the section coordinate set to the plane exactly.
fn locate<const N: usize, F: Flow<N>>(
    flow: &F,
    section: &Section,
    y0: &[f64; N],
    y1: &[f64; N],
    h: f64,
) -> (f64, [f64; N]) {
    let at = |s: f64| rk4::step(flow, &ZERO_PHASE, &ZERO_PHASE, y0, s).0;
    let hermite = Hermite::new(
        section.distance(y0),
        section.rate(flow, y0),
        section.distance(y1),
        section.rate(flow, y1),
        h,
    );
    let (s, mut y) = newton_in_bracket(
        at,
        |_, y| section.distance(y),
        |_, y| section.rate(flow, y),
        section.at,
        h,
        hermite.first_root(0.0, 1.0) * h,
    );
    y[section.state] = section.at;
    (s, y)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// x' = -y, y' = x: circles; the section y = 0 crossed upwards is
    /// met at x > 0 after the time of the angle still to go.
    struct Rotation;

    impl Flow<2> for Rotation {
        fn rhs(&self, _phase: &Phase, y: &[f64; 2]) -> [f64; 2] {
            [-y[1], y[0]]
        }
    }

    #[test]
    fn a_circle_returns_to_its_section_after_one_turn() {
        let section = Section {
            state: 1,
            at: 0.0,
            direction: 1.0,
        };
        // From on the section, and from a quarter turn before it.
        let starts = [[1.0, 0.0], [0.0, -2.0], [0.5, 0.0]];
        let h = std::f64::consts::TAU / 997.0;
        let crossings = next_crossings(&Rotation, &section, &starts, h, 10_000);
        let expected_times = [
            std::f64::consts::TAU,
            std::f64::consts::FRAC_PI_2,
            std::f64::consts::TAU,
        ];
        for ((c, start), t) in crossings.iter().zip(&starts).zip(expected_times) {
            let (y, time) = c.expect("crosses");
            let radius = (start[0] * start[0] + start[1] * start[1]).sqrt();
            assert_eq!(y[1], 0.0);
            // RK4's error in the radius after ~1000 steps of h ≈ 0.0063.
            assert!((y[0] - radius).abs() < 1e-10, "{y:?}");
            assert!((time - t).abs() < 1e-10, "{time} vs {t}");
        }
    }
}
