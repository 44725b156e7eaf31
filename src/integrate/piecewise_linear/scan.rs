//! The certified scan of a segment for its first crossing: steps bounded
//! by a cubic majorant of every watched function, halved until each one in
//! doubt is bracketed, and each root refined by safeguarded Newton on the
//! exact solution. (Roots of the exact solution: the RK4 path's location,
//! `integrate::locate`, solves a different problem, roots of its own
//! re-stepped integrator.)

use nalgebra::DVector;

use super::dynamics::{Dynamics, FORCING};
use super::segment::{Point, Segment};
use super::system::PiecewiseLinear;

/// So is a bounce whose height g'²/(2g'') is below this many ulps of the
/// surface's scale |d| + |n||y|.
const CHATTER_HEIGHT_ULPS: f64 = 64.0;

/// Iterations of the root refinement (it converges in a handful).
const MAX_REFINE: usize = 200;

/// The scan's settings for one span.
#[derive(Clone, Copy, Debug)]
pub(super) struct Span {
    pub(super) end: f64,
    pub(super) h_max: f64,
    pub(super) h_min: f64,
    pub(super) chatter_time: f64,
}

/// What ended a scan of a segment.
pub(super) enum Next {
    End(Point),
    /// The watched function of this index reached 0.
    Crossing(usize, Point),
    /// An accumulation of events on watched event surface j.
    Chattering(Option<usize>, Point),
    /// At rest on watched event surface j, pressed into it.
    Sticking(Option<usize>, Point),
    Diverged(Point),
}

impl PiecewiseLinear {
    /// L ≥ |g_i'''| on [t, t + step] along a segment of `dynamics` through
    /// y (see [`iterate`](Self::iterate)).
    pub(super) fn jerk_bound(&self, dynamics: &Dynamics, i: usize, y_norm: f64, step: f64) -> f64 {
        let (ry, rw) = dynamics.watch[i].jerk;
        if ry == 0.0 {
            // g''' does not see y ((Aᵀ)³ k_y = 0): no bound on |y| needed,
            // and none to overflow into ∞·0.
            return rw;
        }
        let reach = (dynamics.growth * step).exp() * (y_norm + dynamics.drive * step);
        ry * reach + rw
    }

    /// The scale below which k·z at y is rounding: |d| + |n||y| for a
    /// surface.
    pub(super) fn resolution(&self, k: &DVector<f64>, y: &DVector<f64>) -> f64 {
        let n = self.dimension();
        let constant: f64 = k.rows(n, FORCING).iter().map(|x| x.abs()).sum();
        CHATTER_HEIGHT_ULPS * f64::EPSILON * (constant + k.rows(0, n).norm() * y.norm())
    }

    /// Scans `segment` from `start` for the first crossing in (start.t, end]
    /// over all watched functions (see [`iterate`](Self::iterate)).
    pub(super) fn next_crossing(
        &self,
        segment: &Segment,
        start: Point,
        span: &Span,
        budget: &mut u32,
    ) -> Next {
        let dynamics = &segment.dynamics;
        let watch = &dynamics.watch;
        let count = watch.len();
        let mut a = start;
        let mut h = span.h_max;
        for (j, w) in watch.iter().enumerate() {
            if a.g1[j] < 0.0 && a.g2[j] > 0.0 && a.g[j] >= -self.resolution(&w.k, &a.y) {
                // Leaving a surface against a field pushing back: the bounce
                // lasts about 2|g'|/g'', so start with half of that rather
                // than halving down from h_max.
                h = h.min(-a.g1[j] / a.g2[j]);
            }
        }
        loop {
            if !a.y.iter().all(|x| x.is_finite()) {
                return Next::Diverged(a);
            }
            for (j, w) in watch.iter().enumerate() {
                if w.event
                    && a.g[j] >= -self.resolution(&w.k, &a.y)
                    && a.g1[j] <= 0.0
                    && a.g2[j] > 0.0
                {
                    // On an event surface (to rounding), pressed into it.
                    if a.g1[j] == 0.0 {
                        return Next::Sticking(Some(j), a);
                    }
                    // A bounce below the time or position resolution: the
                    // tail of an accumulating sequence of events.
                    let resolution = self.resolution(&watch[j].k, &a.y);
                    if -2.0 * a.g1[j] < span.chatter_time * a.g2[j]
                        || a.g1[j] * a.g1[j] < 2.0 * a.g2[j] * resolution
                    {
                        return Next::Chattering(Some(j), a);
                    }
                }
                if a.g[j] >= 0.0 && (a.g1[j] > 0.0 || (a.g1[j] == 0.0 && a.g2[j] > 0.0)) {
                    // On (or past) the surface, moving into it: crossing now.
                    return Next::Crossing(j, a);
                }
            }
            if a.t >= span.end {
                return Next::End(a);
            }
            if *budget == 0 {
                return Next::Chattering(None, a);
            }
            *budget -= 1;
            let remaining = span.end - a.t;
            let (step, t_b) = if h >= remaining {
                (remaining, span.end)
            } else {
                (h, a.t + h)
            };
            let b = self.eval(segment, t_b);
            let y_norm = a.y.norm();
            let mut in_doubt = Vec::new();
            let mut bracketed = true;
            for j in 0..count {
                let jerk = self.jerk_bound(dynamics, j, y_norm, step);
                if certified_below(a.g[j], a.g1[j], a.g2[j], jerk, step) {
                    continue;
                }
                in_doubt.push(j);
                bracketed &= b.g[j] >= 0.0
                    && a.g[j] < 0.0
                    && certified_increasing(a.g1[j], a.g2[j], jerk, step);
            }
            if in_doubt.is_empty() {
                a = b;
                h = (2.0 * h).min(span.h_max);
                continue;
            }
            let fine = step <= span.h_min;
            if bracketed || fine {
                // Each function in doubt either rises through 0 once in
                // the step (bracketed), or, at the finest step, is decided
                // from the ends, including a maximum inside the step that
                // reaches 0.
                let mut first: Option<(usize, Point)> = None;
                for &j in &in_doubt {
                    let root = if b.g[j] >= 0.0 {
                        Some(self.refine(segment, j, a.clone(), b.clone()))
                    } else if a.g1[j] > 0.0 && b.g1[j] < 0.0 {
                        let top = self.maximum(segment, j, a.clone(), b.clone());
                        (top.g[j] >= 0.0).then(|| self.refine(segment, j, a.clone(), top))
                    } else {
                        None
                    };
                    if let Some(p) = root {
                        if first.as_ref().is_none_or(|(_, q)| p.t < q.t) {
                            first = Some((j, p));
                        }
                    }
                }
                if let Some((j, p)) = first {
                    return Next::Crossing(j, p);
                }
                a = b;
                h = (2.0 * step).min(span.h_max);
                continue;
            }
            h = 0.5 * step;
        }
    }

    /// The crossing of surface j in [lo, hi], where g_j(lo) < 0 (or lo is a
    /// start on the surface moving away from it), g_j(hi) ≥ 0 and g_j has
    /// no other root: Newton's method, falling back to bisection whenever a
    /// Newton step would leave the bracket. Of the final bracket, the end
    /// nearer the surface.
    pub(super) fn refine(
        &self,
        segment: &Segment,
        j: usize,
        mut lo: Point,
        mut hi: Point,
    ) -> Point {
        let tol = 2.0 * f64::EPSILON * hi.t.abs().max(1.0);
        let (mut t, mut g, mut g1) = (hi.t, hi.g[j], hi.g1[j]);
        let mut lo_evaluated = false;
        for _ in 0..MAX_REFINE {
            if hi.t - lo.t <= tol {
                break;
            }
            let newton = if g1 > 0.0 { t - g / g1 } else { f64::NAN };
            let next = if newton > lo.t && newton < hi.t {
                newton
            } else {
                0.5 * (lo.t + hi.t)
            };
            let moved = (next - t).abs();
            let p = self.eval(segment, next);
            (t, g, g1) = (p.t, p.g[j], p.g1[j]);
            if g >= 0.0 {
                hi = p;
            } else {
                lo = p;
                lo_evaluated = true;
            }
            if g == 0.0 || moved <= tol {
                break;
            }
        }
        if lo_evaluated && -lo.g[j] < hi.g[j] {
            lo
        } else {
            hi
        }
    }

    /// The maximum of g_j between lo (g_j' > 0) and hi (g_j' < 0), by
    /// bisection on g_j'; of the two final points, the higher.
    pub(super) fn maximum(
        &self,
        segment: &Segment,
        j: usize,
        mut lo: Point,
        mut hi: Point,
    ) -> Point {
        let tol = 2.0 * f64::EPSILON * hi.t.abs().max(1.0);
        for _ in 0..MAX_REFINE {
            if hi.t - lo.t <= tol {
                break;
            }
            let p = self.eval(segment, 0.5 * (lo.t + hi.t));
            if p.g1[j] > 0.0 {
                lo = p;
            } else {
                hi = p;
            }
        }
        if lo.g[j] >= hi.g[j] {
            lo
        } else {
            hi
        }
    }
}

/// Whether q(s) = g₀ + g₁s + g₂s²/2 + Ls³/6 < 0 for all s ∈ (0, h]: the
/// scan's test here and in `closed_form`, a non-finite q counting as not
/// certified.
///
/// A point on (or, by rounding, just beyond) the surface counts as g₀ = 0;
/// it is then certified to leave when g₁ ≤ 0 and q(s)/s = g₁ + g₂s/2 +
/// Ls²/6, a convex quadratic that starts at g₁ ≤ 0, is negative at h.
pub(in crate::integrate) fn certified_below(g0: f64, g1: f64, g2: f64, jerk: f64, h: f64) -> bool {
    if g0 >= 0.0 {
        return g1 <= 0.0 && g1 + h * (0.5 * g2 + h * jerk / 6.0) < 0.0;
    }
    let q = |s: f64| g0 + s * (g1 + s * (0.5 * g2 + s * jerk / 6.0));
    let end = q(h);
    if end.is_nan() || end >= 0.0 {
        return false;
    }
    // An interior maximum is the smaller root of q'(s) = g₁ + g₂s + Ls²/2,
    // which is positive only if g₁ > 0 and g₂ ≤ 0; written as
    // 2g₁/(√disc − g₂) to avoid cancellation.
    if g1 > 0.0 && g2 <= 0.0 {
        let disc = g2 * g2 - 2.0 * jerk * g1;
        if disc >= 0.0 {
            let denominator = disc.sqrt() - g2;
            if denominator > 0.0 {
                let s = 2.0 * g1 / denominator;
                let top = q(s);
                if s < h && (top.is_nan() || top >= 0.0) {
                    return false;
                }
            }
        }
    }
    true
}

/// Whether g' > 0 on [0, h], from g'(s) ≥ g₁ + g₂s − Ls²/2 (concave, so
/// checking both ends suffices).
pub(in crate::integrate) fn certified_increasing(g1: f64, g2: f64, jerk: f64, h: f64) -> bool {
    g1 > 0.0 && g1 + h * (g2 - 0.5 * h * jerk) > 0.0
}
