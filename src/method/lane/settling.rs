//! How long a lane takes to settle: the iterations until its reference
//! comes within the attractor tolerance of the orbit it ends on and stays
//! there (its convergence time).
//!
//! The lane keeps its reference points from the start (x_0, the start
//! itself, then one per iteration, transient and averaging alike) and,
//! once its orbit is known, scans them from the last back to the last one
//! that lies outside the tolerance: the convergence time is the iteration
//! after it (0 when the start already lies on the orbit).
//!
//! - A periodic orbit's points are its last `period` points; x_n is
//!   within the tolerance of the orbit when |x_n - y|∞ ≤ tol·max(1,
//!   |x_n|∞, |y|∞) for one of its points y (the measure that tells two
//!   lanes' orbits apart, `attractor::group`).
//! - An aperiodic orbit is the box around the lane's averaged points (the
//!   kind of region two aperiodic lanes are matched by, over all the
//!   points the lane averaged, not the few it keeps: those cover a chaotic
//!   attractor too thinly, and a start would seem to settle only near the
//!   run's end): x_n is within when its gap to the box is at most
//!   tol·max(1, |x_n|∞, the box's largest |x|). Its time is then at most
//!   the transient's length.
//!
//! The points are kept only while the lane runs (runs with basin images):
//! (transient + iterations)·D numbers a lane in flight.

use super::orbit::return_tolerance;

/// The relative distance within which two lanes' orbit points are one
/// point: ten times the return test's tolerance in the run's arithmetic
/// (each lane's own points settle within that of their orbit, so two
/// lanes' points within twice it).
pub fn attractor_tolerance(rounding_unit: f64) -> f64 {
    10.0 * return_tolerance(rounding_unit)
}

/// A lane's reference points from its start, for its convergence time.
#[derive(Clone, Debug, Default)]
pub struct Settling<const D: usize> {
    points: Vec<[f64; D]>,
}

impl<const D: usize> Settling<D> {
    /// Keeps the next point (the start first).
    pub fn push(&mut self, x: &[f64; D]) {
        self.points.push(*x);
    }

    /// The last `n` points kept (all of them when fewer), oldest first,
    /// D numbers each.
    pub fn last(&self, n: usize) -> Vec<f64> {
        let from = self.points.len().saturating_sub(n);
        self.points[from..].iter().flatten().copied().collect()
    }

    /// The convergence time onto the lane's periodic orbit `orbit` (its
    /// `period` points, D numbers each), or with `None` onto the box of its
    /// last `averaged` points, at relative tolerance `tolerance`; `None`
    /// when no point was kept, or the orbit or the box has no point.
    pub fn time(&self, orbit: Option<&[f64]>, averaged: usize, tolerance: f64) -> Option<usize> {
        let kept = self.points.len();
        let target = match orbit {
            Some(orbit) if orbit.len() >= D && kept > 0 => Target::Points(orbit),
            None if averaged > 0 && averaged <= kept => {
                Target::Region(Region::of(&self.points[kept - averaged..]))
            }
            _ => return None,
        };
        let outside = self
            .points
            .iter()
            .rposition(|x| !target.holds(x, tolerance));
        Some(outside.map_or(0, |n| n + 1))
    }
}

/// What a lane settles onto: its periodic orbit's points (D numbers each),
/// or the box of its averaged points.
enum Target<'a> {
    Points(&'a [f64]),
    Region(Region),
}

impl Target<'_> {
    /// Whether x lies within `tolerance` of the target.
    fn holds(&self, x: &[f64], tolerance: f64) -> bool {
        match self {
            Target::Points(orbit) => orbit
                .chunks_exact(x.len())
                .any(|y| relative_distance(x, y) <= tolerance),
            Target::Region(region) => region.holds(x, tolerance),
        }
    }
}

/// |x - y|∞ / max(1, |x|∞, |y|∞).
pub(super) fn relative_distance(x: &[f64], y: &[f64]) -> f64 {
    let scale = x.iter().chain(y).fold(1.0_f64, |m, v| m.max(v.abs()));
    x.iter()
        .zip(y)
        .fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()))
        / scale
}

/// The box around an aperiodic orbit's points and their largest |x|.
struct Region {
    bounds: Vec<(f64, f64)>,
    scale: f64,
}

impl Region {
    fn of<const D: usize>(points: &[[f64; D]]) -> Region {
        let bounds = (0..D)
            .map(|i| {
                points
                    .iter()
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
                        (lo.min(x[i]), hi.max(x[i]))
                    })
            })
            .collect();
        let scale = points.iter().flatten().fold(1.0_f64, |m, v| m.max(v.abs()));
        Region { bounds, scale }
    }

    /// Whether x's gap to the box is within the tolerance.
    fn holds(&self, x: &[f64], tolerance: f64) -> bool {
        let gap = x
            .iter()
            .zip(&self.bounds)
            .fold(0.0_f64, |gap, (&v, &(lo, hi))| gap.max(lo - v).max(v - hi));
        let scale = x.iter().fold(self.scale, |m, v| m.max(v.abs()));
        gap <= tolerance * scale
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// x_n = 2 + 0.5^n onto the fixed point 2: within 1e-5 from the first
    /// n with 0.5^n ≤ 1e-5·(2 + 0.5^n), n = 16.
    #[test]
    fn a_contraction_settles_when_it_comes_within_the_tolerance() {
        let mut settling = Settling::<1>::default();
        for n in 0..40 {
            settling.push(&[2.0 + 0.5f64.powi(n)]);
        }
        let t = settling.time(Some(&[2.0]), 10, 1e-5).unwrap();
        let first = (0..40)
            .find(|&n| 0.5f64.powi(n) <= 1e-5 * (2.0 + 0.5f64.powi(n)))
            .unwrap() as usize;
        assert_eq!((t, first), (16, 16));
        assert_eq!(settling.time(Some(&[]), 10, 1e-5), None);
        assert_eq!(Settling::<1>::default().time(Some(&[2.0]), 1, 1e-5), None);
        assert_eq!(settling.time(None, 41, 1e-5), None);
    }

    /// A point that leaves the orbit again resets the time; a start on the
    /// orbit has time 0; without a period, the box of the last averaged
    /// points takes the points within it.
    #[test]
    fn the_last_point_outside_decides() {
        let mut settling = Settling::<2>::default();
        for x in [
            [0.0, 1.0],
            [5.0, 5.0],
            [0.0, 1.0],
            [3.0, 3.0],
            [0.0, 1.0],
            [1.0, 0.0],
        ] {
            settling.push(&x);
        }
        let orbit = [0.0, 1.0, 1.0, 0.0];
        assert_eq!(settling.time(Some(&orbit), 2, 1e-9), Some(4));
        // The last two points span [0, 1]²: [3, 3] is the last outside.
        assert_eq!(settling.time(None, 2, 1e-9), Some(4));
        // The last four span [0, 3]²: [5, 5] is the last outside; the last
        // five hold it.
        assert_eq!(settling.time(None, 4, 1e-9), Some(2));
        assert_eq!(settling.time(None, 5, 1e-9), Some(0));
    }
}
