//! Locating a crossing inside an RK4 step on the integrator's own
//! solution: a guess from the cubic Hermite interpolant of the step's ends
//! (its root, or its peak where the motion turns back inside the step),
//! then safeguarded Newton on RK4 re-stepped from the step's start. One
//! algorithm for the walls, the general surfaces and the Poincaré section
//! (`section`); the exact propagators (`closed_form`, `piecewise_linear`)
//! find roots of the exact solution instead, by a certified scan.

use super::clock::{cos_sin, Phase};
use super::flow::Flow;
use super::rk4;
use super::wall::{may_reach, Wall};

use super::iteration::ImpactLocation;

/// RK4 steps of any size s from a given phase: the re-steps of impact location.
pub(super) struct SubStep<'a, F> {
    pub(super) flow: &'a F,
    pub(super) omega: f64,
}

impl<F> SubStep<'_, F> {
    pub(super) fn step<const D: usize>(
        &self,
        phase: &Phase,
        y: &[f64; D],
        s: f64,
    ) -> ([f64; D], Phase)
    where
        F: Flow<D>,
    {
        rk4::step(self.flow, phase, &cos_sin(0.5 * self.omega * s), y, s)
    }
}

/// Locates the crossing of a general surface inside the step [0, h] from
/// (phase0, y0) to y1, given its oriented distance and rate (> 0 beyond
/// and approaching) at both ends, as [`locate_newton`] locates an impact
/// ([`hermite_newton`]); an event's surface just left by its reset is met
/// again after the trough (`rebounding`).
#[allow(clippy::too_many_arguments)]
pub(super) fn locate<const D: usize, F: Flow<D>>(
    sub: &SubStep<F>,
    location: ImpactLocation,
    phase0: &Phase,
    y0: &[f64; D],
    h: f64,
    y1: &[f64; D],
    start: (f64, f64),
    end: (f64, f64),
    rebounding: bool,
    distance: impl Fn(f64, &[f64; D]) -> f64,
    rate: impl Fn(f64, &[f64; D]) -> f64,
) -> Option<(f64, [f64; D])> {
    if location == ImpactLocation::Linear {
        if end.0 <= 0.0 {
            return None;
        }
        let theta = (-start.0 / (end.0 - start.0)).clamp(0.0, 1.0);
        return Some((
            theta * h,
            crate::array::from_fn(|i| y0[i] + theta * (y1[i] - y0[i])),
        ));
    }
    let hermite = Hermite::new(start.0, start.1, end.0, end.1, h);
    let scale = y0.iter().fold(1.0, |m: f64, v| m.max(v.abs()));
    let at = |s: f64| sub.step(phase0, y0, s).0;
    if rebounding && end.0 > 0.0 && start.0 >= 0.0 && start.1 < 0.0 {
        // Just reset onto an event's surface (g at its rounding, ≥ 0) and
        // leaving it, the motion comes back within the step (a bounce
        // shorter than a step, as bounces accumulating are): the crossing
        // from below is the one after the trough, not the rounding at 0.
        let trough = Hermite::new(-start.0, -start.1, -end.0, -end.1, h).peak()?;
        if hermite.value(trough) >= 0.0 {
            // No flight at all: it meets the surface at once, at rest
            // relative to it (its crossings accumulate there).
            let s = trough * h;
            return Some((s, at(s)));
        }
        return Some(newton_from(
            at,
            distance,
            rate,
            scale,
            trough * h,
            h,
            hermite.first_root(trough, 1.0) * h,
        ));
    }
    // An excursion no deeper than the location's own tolerance is a touch
    // in rounding (a motion leaving a sliding surface tangentially), not a
    // crossing.
    hermite_newton(
        at,
        distance,
        rate,
        scale,
        (&hermite, h),
        end.0 > 0.0,
        start.1 > 0.0 && end.1 < 0.0,
        4.0 * f64::EPSILON * scale,
    )
}

/// Re-steps RK4 from (phase0, y0) to the impact on `wall` inside the step
/// [0, h] to y1: returns the offset s into the step and the state RK4
/// reaches there, X(s) = X_w to rounding.
pub(super) fn locate_newton<const D: usize, F: Flow<D>>(
    sub: &SubStep<F>,
    wall: &Wall,
    phase0: &Phase,
    y0: &[f64; D],
    h: f64,
    y1: &[f64; D],
) -> Option<(f64, [f64; D])> {
    let (g0, s0, g1, s1) = (wall.gap(y0), wall.speed(y0), wall.gap(y1), wall.speed(y1));
    let hermite = Hermite::new(g0, s0, g1, s1, h);
    // Both ends short of the wall, the velocity turning inside the step
    // within reach of it (the stop test, its end short of the wall): an
    // excursion past the wall in between is a (near-grazing) impact.
    hermite_newton(
        |s| sub.step(phase0, y0, s).0,
        |_, y| wall.gap(y),
        |_, y| wall.speed(y),
        wall.position,
        (&hermite, h),
        g1 > 0.0,
        may_reach(g0, s0, g1, s1, h, true),
        0.0,
    )
}

/// The crossing inside the step [0, h] of g(s) = distance(at(s)), the
/// Hermite interpolant of its ends `hermite`: where the step ends beyond
/// (`beyond`), in the bracket [0, h] from the cubic's root; else where it
/// turns back inside the step (`turns`), in the bracket up to the cubic's
/// peak, from the root before it, provided RK4 re-stepped to the peak lies
/// more than `touch` beyond (the interpolant locates the peak well, X is
/// flat there, but its value is off by O(h⁴): RK4 decides). Then
/// safeguarded Newton ([`newton_in_bracket`]).
#[allow(clippy::too_many_arguments)]
fn hermite_newton<const D: usize>(
    at: impl Fn(f64) -> [f64; D],
    distance: impl Fn(f64, &[f64; D]) -> f64,
    rate: impl Fn(f64, &[f64; D]) -> f64,
    scale: f64,
    (hermite, h): (&Hermite, f64),
    beyond: bool,
    turns: bool,
    touch: f64,
) -> Option<(f64, [f64; D])> {
    // The bracket [lo, hi] of s: g(lo) <= 0 < g(hi).
    let (hi, guess) = if beyond {
        (h, hermite.first_root(0.0, 1.0))
    } else if turns {
        let peak = hermite.peak()?;
        if distance(peak * h, &at(peak * h)) <= touch {
            return None;
        }
        (peak * h, hermite.first_root(0.0, peak))
    } else {
        return None;
    };
    Some(newton_in_bracket(at, distance, rate, scale, hi, guess * h))
}

/// The paper's location: the crossing fraction of a straight line between the
/// step's ends, and the state interpolated linearly there.
pub(super) fn locate_linear<const D: usize>(
    wall: &Wall,
    y0: &[f64; D],
    h: f64,
    y1: &[f64; D],
) -> Option<(f64, [f64; D])> {
    if wall.gap(y1) <= 0.0 {
        return None;
    }
    let c = wall.coordinate;
    let theta = ((wall.position - y0[c]) / (y1[c] - y0[c])).clamp(0.0, 1.0);
    Some((
        theta * h,
        crate::array::from_fn(|i| y0[i] + theta * (y1[i] - y0[i])),
    ))
}

/// Safeguarded Newton on a crossing: g(s) = distance(at(s)), with g'(s) ≈
/// rate(at(s)), in the bracket [0, hi] from s, bisecting whenever Newton
/// would leave the bracket; g is resolved to 4 ulp of `scale` (where the
/// surface lies). `at(s)` is RK4 re-stepped from the step's start, so the
/// crossing lies on the integrator's own solution. The impact's and the
/// Poincaré section's location.
pub(crate) fn newton_in_bracket<const D: usize>(
    at: impl Fn(f64) -> [f64; D],
    distance: impl Fn(f64, &[f64; D]) -> f64,
    rate: impl Fn(f64, &[f64; D]) -> f64,
    scale: f64,
    hi: f64,
    s: f64,
) -> (f64, [f64; D]) {
    newton_from(at, distance, rate, scale, 0.0, hi, s)
}

/// [`newton_in_bracket`] in the bracket [lo, hi].
fn newton_from<const D: usize>(
    at: impl Fn(f64) -> [f64; D],
    distance: impl Fn(f64, &[f64; D]) -> f64,
    rate: impl Fn(f64, &[f64; D]) -> f64,
    scale: f64,
    mut lo: f64,
    mut hi: f64,
    mut s: f64,
) -> (f64, [f64; D]) {
    let tolerance = 4.0 * f64::EPSILON * scale.abs().max(1.0);
    let mut y = at(s);
    for _ in 0..32 {
        let g = distance(s, &y);
        if g.abs() <= tolerance {
            break;
        }
        if g > 0.0 {
            hi = s;
        } else {
            lo = s;
        }
        let newton = s - g / rate(s, &y);
        s = if newton > lo && newton < hi && newton.is_finite() {
            newton
        } else {
            0.5 * (lo + hi)
        };
        if hi - lo <= f64::EPSILON * hi.abs() {
            break;
        }
        y = at(s);
    }
    (s, y)
}

/// The cubic Hermite interpolant of g = X - X_w over one step, in θ ∈ [0, 1],
/// from the values and derivatives (velocities) at both ends.
pub struct Hermite {
    c: [f64; 4],
}

impl Hermite {
    pub fn new(g0: f64, v0: f64, g1: f64, v1: f64, h: f64) -> Self {
        let (d0, d1) = (v0 * h, v1 * h);
        // g(θ) = c0 + c1 θ + c2 θ² + c3 θ³
        let c2 = 3.0 * (g1 - g0) - 2.0 * d0 - d1;
        let c3 = 2.0 * (g0 - g1) + d0 + d1;
        Hermite {
            c: [g0, d0, c2, c3],
        }
    }

    pub fn value(&self, th: f64) -> f64 {
        let c = &self.c;
        c[0] + th * (c[1] + th * (c[2] + th * c[3]))
    }

    pub fn slope(&self, th: f64) -> f64 {
        let c = &self.c;
        c[1] + th * (2.0 * c[2] + th * 3.0 * c[3])
    }

    /// Where the slope turns from positive to negative inside (0, 1), given
    /// slope(0) > 0 > slope(1): the quadratic slope a·θ² + b·θ + c then has
    /// exactly one root there, found in closed form with the root formula
    /// that does not cancel (q = -(b + sign(b)·√disc)/2, roots q/a and
    /// c/q). Safeguarded Newton from the midpoint, stopped only when an
    /// iterate repeated, took 25 iterations on average (up to 64: near the
    /// root the slope's rounding moves each step by a few ulps, and the
    /// bracket closed by bisection): at one call per oscillation and
    /// trajectory, 7 percent of the CPU path's time on a 200-step sweep
    /// of the seed's oscillator. Twin of `hermite_peak`.
    pub fn peak(&self) -> Option<f64> {
        if !(self.slope(0.0) > 0.0 && self.slope(1.0) < 0.0) {
            return None;
        }
        let (a, b, c) = (3.0 * self.c[3], 2.0 * self.c[2], self.c[1]);
        let root = (b * b - 4.0 * a * c).max(0.0).sqrt();
        // b >= 0: a < -b - c < 0 (the slope at 1), so q < 0 and the root
        // in (0, 1) is q/a (c/q < 0). b < 0: q > 0 and c/q is the smaller
        // positive root (or the only one).
        let th = if b >= 0.0 {
            -0.5 * (b + root) / a
        } else {
            c / (-0.5 * (b - root))
        };
        Some(th.clamp(0.0, 1.0))
    }

    /// The cubic's stationary points inside [0, 1] (NaN where there are
    /// fewer than two): the roots of its slope a·θ² + b·θ + c, the one
    /// without cancellation first (q = -(b + sign(b)·√disc)/2, q/a), the
    /// other from the product (c/q). Maxima and minima alike: a caller
    /// after the largest value compares them with the ends. The orbit's
    /// grazing tests take the peaks of a step this way, whatever the signs
    /// of its end slopes (a +→-→+ step holds a peak and a trough).
    pub(crate) fn stationary_points(&self) -> [f64; 2] {
        let (a, b, c) = (3.0 * self.c[3], 2.0 * self.c[2], self.c[1]);
        let mut roots = [f64::NAN; 2];
        if a.abs() <= 1e-300 {
            if b != 0.0 {
                roots[0] = -c / b;
            }
        } else {
            let disc = b * b - 4.0 * a * c;
            if disc >= 0.0 {
                let q = -0.5 * (b + b.signum() * disc.sqrt());
                roots = [q / a, if q != 0.0 { c / q } else { f64::NAN }];
            }
        }
        roots.map(|th| {
            if (0.0..=1.0).contains(&th) {
                th
            } else {
                f64::NAN
            }
        })
    }

    /// The first upward root of the cubic in [a, b] (g(a) <= 0 < g(b)), by
    /// bisection refined with Newton; used only as Newton's starting guess.
    pub fn first_root(&self, mut a: f64, mut b: f64) -> f64 {
        let mut th =
            a + (b - a) * (-self.value(a) / (self.value(b) - self.value(a))).clamp(0.0, 1.0);
        for _ in 0..8 {
            let g = self.value(th);
            if g > 0.0 {
                b = th;
            } else {
                a = th;
            }
            let next = th - g / self.slope(th);
            th = if next > a && next < b {
                next
            } else {
                0.5 * (a + b)
            };
        }
        th
    }
}
