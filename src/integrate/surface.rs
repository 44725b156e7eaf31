//! Event surfaces of any shape, g(y) = 0, beyond the walls: events, whose
//! reset maps the state where g crosses 0 from below, and switches, across
//! which the field itself changes (the piecewise-smooth systems of dry
//! friction and piecewise stiffness).
//!
//! A switch splits phase space into regions, one bit per switch (set on the
//! side where its g > 0), and each region has its own smooth field. The
//! integrator never evaluates a side from the raw state inside a step: a
//! trajectory carries its region, every step integrates one region's field
//! ([`InRegion`](super::InRegion)), and a step whose end lies across a surface (or whose
//! rate ∇g·F turns inside it, an excursion across and back) is cut at the
//! crossing, located on the integrator's own solution as impacts are
//! (Newton on re-stepped RK4, `locate::newton_in_bracket`).
//!
//! Each crossing multiplies phase-space volume by |det S|, S the saltation
//! matrix, which the sum rule needs (added to `IterationStats::log_flux`):
//!
//! ```text
//! event:  S = DR + (F⁺ - DR·F⁻ - ∂R/∂t) ∇gᵀ / (∇g·F⁻ + ∂g/∂t),
//! switch: S = I + (F⁺ - F⁻) ∇gᵀ / (∇g·F⁻),   det S = (∇g·F⁺) / (∇g·F⁻),
//! ```
//!
//! F⁻ the field before the crossing, F⁺ after it (after the reset R, in the
//! new region). A reset (an event's, or a stop's rebound) that jumps the
//! state across a switch puts the trajectory on that switch's other side
//! ([`jumped`]): F⁺ is that side's field. (For a stop, det S = e²
//! whatever F⁺ is.)
//!
//! **Sliding.** Where the fields on both sides point into a switch (the
//! rates a = ∇g·F on the negative side and b on the positive side with
//! a > 0 > b), the motion slides on it with Filippov's convex combination
//! F_s = F_a + α(F_b - F_a), α = a/(a - b), which keeps ∇g·F_s = 0: a mass
//! stuck to a belt under dry friction. With the mean rate m = (a + b)/2
//! (the rate without the discontinuity) and the half jump (a - b)/2, the
//! motion slides while |m| < L and leaves towards the side m points to when
//! |m| reaches L. Filippov's L is the half jump itself; a switch's stick
//! limit gives a larger L (static friction above kinetic), and then a
//! trajectory arriving with |m| < L sticks as well. A sliding phase
//! forgets the distance to the surface: the map loses a rank
//! (`IterationStats::rank_loss`), and the volume law does not apply to it
//! (its record becomes NaN).
//!
//! **Sliding on several switches at once** (two blocks on a belt, both
//! stuck): the region carries a set of sliding switches, and the field is
//! Utkin's equivalent control on the intersection of their surfaces
//! ([`Equivalent`]): each sliding switch's side replaced by the value
//! u_j ∈ [0, 1] that keeps its ∇g_j·F = 0, a small linear system where the
//! field is affine in each switch's side separately (checked on entry,
//! [`separable`]); one switch is Filippov's α to the bit. A motion
//! sliding on some switches that meets another slides on it too where
//! the sliding field on its two sides points into it, or within its stick
//! limit ([`joining_margins`]); it leaves one switch, the others still
//! sliding, when that switch's margins (its mean rate with the others
//! held at their controls, against its limit) run out. Sliding on k
//! switches at once collapses k directions for certain; phases on
//! different switches one after the other collapse between one and one
//! per phase (`IterationStats::sliding_phases`), which the lane decides
//! from the finite differences (`LaneAccumulator`).
//!
//! **Held on an event** (a ball locked onto a vibrating table): where an
//! event's crossings accumulate, the region carries bit `HELD + j` and the
//! motion stays on g = 0 with ġ = 0 (`impact::hold_step`) until the free
//! field pulls it away; two directions collapse, and the volume law does
//! not apply. Only in a model without switches (one field).

use nalgebra::DMatrix;

use super::clock::Phase;
use super::flow::Flow;
use super::region::MAX_SLIDING;
use super::wall::may_reach;

// What a surface is and the region bits moved below the `Flow` trait
// (`region`); here under their old paths, which the generated code and
// the systems name.
pub use super::region::{
    held_on, is_constrained, is_sliding, leaving, sides, sliding_on, sliding_set, SlidingSet,
    Surface, SurfaceBatch, SurfaceValues, HELD, MAX_SURFACES, SLIDING,
};

/// The equivalent control of a motion sliding on the switches of its
/// region's sliding set S at one state (Utkin's; Filippov's convex
/// combination for one switch), for a field that is affine in each
/// switch's side separately (dry friction: each block's force depends on
/// its own slip).
///
/// With F₀ the field with every switch of S on its negative side and F_k
/// with switch k alone on its positive side, the field is F(u) = F₀ +
/// Σ_k u_k (F_k - F₀), u_k ∈ [0, 1] (u = (1 + σ)/2 of the sign σ). On the
/// intersection of the surfaces the sliding field keeps every ∇g_j·F(u) =
/// 0: with a_j = ∇g_j·F₀ and c_jk = ∇g_j·F_k, the linear system
///
/// ```text
/// Σ_k (a_j - c_jk) u_k = a_j,   j ∈ S,
/// ```
///
/// which for one switch is u = a/(a - b), Filippov's α. Switch j's stick
/// margins are those of one switch with the others held at their u_k: its
/// two sides' rates a_j' = a_j + Σ_{k≠j} u_k (c_jk - a_j) and b_j' = c_jj +
/// (the same sum), their mean m_j = σ_j·(a_j' - b_j')/2 and the limit L_j
/// (the stick limit, or Filippov's half jump (a_j' - b_j')/2): (L_j - m_j,
/// L_j + m_j), both > 0 while j slides (|σ_j| < L_j in units of the half
/// jump).
#[derive(Clone, Copy, Debug)]
pub struct Equivalent<const D: usize> {
    /// The sliding field F(u).
    pub field: [f64; D],
    /// The stick margins (L - m, L + m) of every surface (those of S only
    /// are meaningful).
    pub margins: [(f64, f64); MAX_SURFACES],
}

/// The equivalent control of a trajectory in `region` (sliding on its
/// sliding set) at y: the sliding field, and the stick margins where
/// `margins` is asked for. `None` where the system for u is singular (two
/// surfaces whose controls cannot be told apart).
pub fn equivalent<const D: usize, F: Flow<D>>(
    flow: &F,
    region: u32,
    phase: &Phase,
    y: &[f64; D],
    margins: bool,
) -> Option<Equivalent<D>> {
    equivalent_on(
        flow,
        &SlidingSet::of(flow.surfaces(), region),
        phase,
        y,
        margins,
    )
}

/// [`equivalent`] on a sliding set gathered beforehand.
pub fn equivalent_on<const D: usize, F: Flow<D>>(
    flow: &F,
    set: &SlidingSet,
    phase: &Phase,
    y: &[f64; D],
    margins: bool,
) -> Option<Equivalent<D>> {
    let SlidingSet { members, n, base } = *set;
    let lo = flow.rhs_in(base, phase, y);
    if n == 1 {
        // One switch: the system below is one quotient, written out (the
        // general path's arrays cost the one-switch friction belt 15% of
        // its time, measured).
        let (j, bit) = members[0];
        let hi = flow.rhs_in(base | 1 << bit, phase, y);
        let g = flow.surface_gradient(j, phase, y);
        let a: f64 = (0..D).map(|i| g[i] * lo[i]).sum();
        let b: f64 = (0..D).map(|i| g[i] * hi[i]).sum();
        let alpha = a / (a - b);
        if !alpha.is_finite() {
            return None;
        }
        let mut out = Equivalent {
            field: crate::array::from_fn(|i| lo[i] + alpha * (hi[i] - lo[i])),
            margins: [(f64::NAN, f64::NAN); MAX_SURFACES],
        };
        if margins {
            let mean = 0.5 * (a + b);
            let limit = flow.stick_limit(j, y).unwrap_or(0.5 * (a - b));
            out.margins[j] = (limit - mean, limit + mean);
        }
        return Some(out);
    }
    let mut fields = [[0.0; D]; MAX_SLIDING];
    let mut gradients = [[0.0; D]; MAX_SLIDING];
    for (m, &(j, bit)) in members[..n].iter().enumerate() {
        fields[m] = flow.rhs_in(base | 1 << bit, phase, y);
        gradients[m] = flow.surface_gradient(j, phase, y);
    }
    let dot = |n: &[f64; D], f: &[f64; D]| -> f64 { (0..D).map(|i| n[i] * f[i]).sum() };
    // a[j] = ∇g_j·F₀, c[j][k] = ∇g_j·F_k.
    let a: [f64; MAX_SLIDING] =
        crate::array::from_fn(|m| if m < n { dot(&gradients[m], &lo) } else { 0.0 });
    let c: [[f64; MAX_SLIDING]; MAX_SLIDING] = crate::array::from_fn(|m| {
        crate::array::from_fn(|k| {
            if m < n && k < n {
                dot(&gradients[m], &fields[k])
            } else {
                0.0
            }
        })
    });
    let u = solve(n, |j, k| a[j] - c[j][k], &a)?;
    let mut field = lo;
    for (k, hi) in fields[..n].iter().enumerate() {
        for i in 0..D {
            field[i] += u[k] * (hi[i] - lo[i]);
        }
    }
    let mut out = Equivalent {
        field,
        margins: [(f64::NAN, f64::NAN); MAX_SURFACES],
    };
    if margins {
        for (m, &(j, _)) in members[..n].iter().enumerate() {
            let (mut below, mut above) = (a[m], c[m][m]);
            for k in (0..n).filter(|&k| k != m) {
                let held = u[k] * (c[m][k] - a[m]);
                below += held;
                above += held;
            }
            let mean = 0.5 * (below + above);
            let limit = flow.stick_limit(j, y).unwrap_or(0.5 * (below - above));
            out.margins[j] = (limit - mean, limit + mean);
        }
    }
    Some(out)
}

/// Solves the n × n system M u = r (n ≤ [`MAX_SLIDING`]) by Gaussian
/// elimination with partial pivoting; one switch is the plain quotient
/// r/M (Filippov's α to the bit). `None` where M is singular.
fn solve(
    n: usize,
    m: impl Fn(usize, usize) -> f64,
    r: &[f64; MAX_SLIDING],
) -> Option<[f64; MAX_SLIDING]> {
    let mut u = [0.0; MAX_SLIDING];
    if n == 1 {
        u[0] = r[0] / m(0, 0);
        return u[0].is_finite().then_some(u);
    }
    // The augmented matrix [M | r], r in the last column.
    let mut a = [[0.0; MAX_SLIDING + 1]; MAX_SLIDING];
    for (i, row) in a.iter_mut().enumerate().take(n) {
        for (k, x) in row.iter_mut().enumerate().take(n) {
            *x = m(i, k);
        }
        row[MAX_SLIDING] = r[i];
    }
    for col in 0..n {
        let pivot = (col..n).max_by(|&p, &q| a[p][col].abs().total_cmp(&a[q][col].abs()))?;
        a.swap(col, pivot);
        if a[col][col] == 0.0 {
            return None;
        }
        let pivot_row = a[col];
        for row in a.iter_mut().take(n).skip(col + 1) {
            let factor = row[col] / pivot_row[col];
            for (x, p) in row.iter_mut().zip(&pivot_row).skip(col) {
                *x -= factor * p;
            }
        }
    }
    for row in (0..n).rev() {
        let mut s = a[row][MAX_SLIDING];
        for k in row + 1..n {
            s -= a[row][k] * u[k];
        }
        u[row] = s / a[row][row];
    }
    u.iter().all(|v| v.is_finite()).then_some(u)
}

/// Whether the field is affine in the sides of the switches of
/// `region`'s sliding set separately (no term with two of their signs
/// together), at y: the corner with all of them positive is F₀ + Σ_k (F_k
/// - F₀), to rounding. The equivalent control assumes it.
pub fn separable<const D: usize, F: Flow<D>>(
    flow: &F,
    region: u32,
    phase: &Phase,
    y: &[f64; D],
) -> bool {
    let SlidingSet { members, n, base } = SlidingSet::of(flow.surfaces(), region);
    if n < 2 {
        return true;
    }
    let lo = flow.rhs_in(base, phase, y);
    let mut sum = lo;
    let mut all = base;
    let mut scale = lo.iter().fold(1.0, |s: f64, v| s.max(v.abs()));
    for &(_, bit) in &members[..n] {
        let hi = flow.rhs_in(base | 1 << bit, phase, y);
        scale = hi.iter().fold(scale, |s, v| s.max(v.abs()));
        for i in 0..D {
            sum[i] += hi[i] - lo[i];
        }
        all |= 1 << bit;
    }
    let corner = flow.rhs_in(all, phase, y);
    (0..D).all(|i| (corner[i] - sum[i]).abs() <= 1e-12 * scale * (n as f64))
}

/// A flow sliding on the switches of its region's sliding set: the
/// equivalent control's field ([`Equivalent`]), whose rate along every
/// sliding surface's ∇g is 0. (NaN where the control is singular, which
/// entering the sliding checks first.)
pub struct Sliding<'a, F> {
    pub flow: &'a F,
    pub set: SlidingSet,
}

impl<'a, F> Sliding<'a, F> {
    /// The sliding flow of a trajectory in `region`.
    pub fn new<const D: usize>(flow: &'a F, region: u32) -> Self
    where
        F: Flow<D>,
    {
        Sliding {
            flow,
            set: SlidingSet::of(flow.surfaces(), region),
        }
    }
}

impl<const D: usize, F: Flow<D>> Flow<D> for Sliding<'_, F> {
    fn rhs(&self, phase: &Phase, y: &[f64; D]) -> [f64; D] {
        equivalent_on(self.flow, &self.set, phase, y, false).map_or([f64::NAN; D], |e| e.field)
    }

    #[inline(always)]
    fn step_one(&self, stages: &[Phase; 3], y: &[f64; D], h: f64) -> [f64; D] {
        self.flow
            .slide_step(&self.set, stages, y, h)
            .unwrap_or_else(|| super::rk4::step_at(self, stages, y, h))
    }

    fn forcing_frequency(&self) -> f64 {
        self.flow.forcing_frequency()
    }
}

/// The stick margins (L - m, L + m) of switch j (bit `bit`) for a
/// trajectory in `region` that meets it, where it slides on the switches
/// of its region's sliding set (none, or some): the fields on j's two
/// sides are those sliding set's equivalent-control fields with j's side
/// cleared and set, a and b their rates along ∇g_j, m = (a + b)/2 and L
/// the stick limit or Filippov's half jump (a - b)/2 (the module's docs).
/// Both > 0: j holds the motion too. `None` where the sliding set's
/// control is singular.
pub fn joining_margins<const D: usize, F: Flow<D>>(
    flow: &F,
    region: u32,
    j: usize,
    bit: u32,
    phase: &Phase,
    y: &[f64; D],
) -> Option<(f64, f64)> {
    let side = |r: u32| {
        if is_sliding(r) {
            equivalent(flow, r, phase, y, false).map(|e| e.field)
        } else {
            Some(flow.rhs_in(r, phase, y))
        }
    };
    let (lo, hi) = (side(region & !(1 << bit))?, side(region | 1 << bit)?);
    let n = flow.surface_gradient(j, phase, y);
    let a: f64 = (0..D).map(|i| n[i] * lo[i]).sum();
    let b: f64 = (0..D).map(|i| n[i] * hi[i]).sum();
    let m = 0.5 * (a + b);
    let limit = flow.stick_limit(j, y).unwrap_or(0.5 * (a - b));
    Some((limit - m, limit + m))
}

/// The rate ∇g_j·F of surface j along the field a trajectory in `region`
/// follows: its region's, or the sliding field.
pub fn rate_along<const D: usize, F: Flow<D>>(
    flow: &F,
    region: u32,
    j: usize,
    phase: &Phase,
    y: &[f64; D],
) -> f64 {
    if !is_sliding(region) {
        return flow.surface_values(region, phase, y).rate[j];
    }
    let field = Sliding::new(flow, region).rhs(phase, y);
    let n = flow.surface_gradient(j, phase, y);
    (0..D).map(|i| n[i] * field[i]).sum()
}

/// The region of y: bit b set where switch b's g > 0.
pub fn region_of<const D: usize, F: Flow<D>>(flow: &F, phase: &Phase, y: &[f64; D]) -> u32 {
    if flow.surfaces().is_empty() {
        return 0;
    }
    let values = flow.surface_values(0, phase, y);
    let mut region = 0;
    for (j, s) in flow.surfaces().iter().enumerate() {
        if let Surface::Switch { bit } = s {
            if values.g[j] > 0.0 {
                region |= 1 << bit;
            }
        }
    }
    // A motion held on an event's surface (sticking) is on it with no rate
    // through it, pressed in: the held steps keep g and ġ at rounding (see
    // `impact::onto_hold`), far below a tolerance that no free motion
    // meets without its crossings accumulating at once.
    let tolerance = HELD_TOLERANCE * y.iter().fold(1.0, |m: f64, v| m.max(v.abs()));
    for (j, s) in flow.surfaces().iter().enumerate() {
        if *s != Surface::Event || region >> HELD != 0 {
            continue;
        }
        if let Some(v) = flow.event_hold(j, phase, y) {
            if v.g.abs() <= tolerance && v.rate.abs() <= tolerance && v.pressing > 0.0 {
                region |= 1 << (HELD + j as u32);
            }
        }
    }
    region
}

/// How close to an event's surface, and how slowly through it, a state
/// counts as held there, relative to its largest component.
const HELD_TOLERANCE: f64 = 1e-10;

/// The region after a reset jumps the state (an event's reset, a stop's
/// rebound) from where the surfaces had `before` to where they have
/// `after`: a switch that the jump moves strictly off its side of it (g
/// from ≤ 0 to > 0, or from ≥ 0 to < 0: a rebound that reverses a velocity
/// across a friction's slip) takes the side of `after`; the others keep
/// their bit (a trajectory just across a switch may lie on its other side
/// to the location's rounding, and a jump that does not cross must not
/// undo that crossing). A sliding region is kept as it is: a reset met
/// while sliding is flagged before it is applied. The exact backend's
/// `PiecewiseLinear::region_after_reset` is the same rule.
pub fn jumped(
    surfaces: &[Surface],
    region: u32,
    before: &SurfaceValues,
    after: &SurfaceValues,
) -> u32 {
    if is_sliding(region) {
        return region;
    }
    let mut region = region;
    for (j, s) in surfaces.iter().enumerate() {
        if let Surface::Switch { bit } = *s {
            let (g0, g1) = (before.g[j], after.g[j]);
            if g1 > 0.0 && g0 <= 0.0 {
                region |= 1 << bit;
            } else if g1 < 0.0 && g0 >= 0.0 {
                region &= !(1 << bit);
            }
        }
    }
    region
}

/// Whether a step of size h from values `before` to `after` (oriented by
/// the trajectory's region) may cross surface j: the stop test
/// (`wall::may_reach`: its end lies across, or its rate turns from
/// approaching to leaving inside the step within reach of the surface;
/// the rate is g's derivative along the motion, as a stop's speed is its
/// gap's, so the same bound on the step's cubic holds).
#[inline(always)]
pub fn may_cross(
    kind: Surface,
    region: u32,
    before: (f64, f64),
    after: (f64, f64),
    h: f64,
) -> bool {
    let o = kind.orientation(region);
    let (g0, r0, g1, r1) = (o * before.0, o * before.1, o * after.0, o * after.1);
    may_reach(g0, r0, g1, r1, h, true)
}

/// ln |det S| of an event's crossing: the reset's Jacobian `dr` and rate
/// `reset_rate` (∂R/∂t), the fields `before_field` (F⁻) and `after_field`
/// (F⁺), the surface's gradient ∇g and its rate along F⁻, `rate` = ∇g·F⁻ +
/// ∂g/∂t. -∞ when the reset collapses a direction (det DR = 0).
pub fn event_log_det<const D: usize>(
    dr: &[[f64; D]; D],
    reset_rate: &[f64; D],
    gradient: &[f64; D],
    rate: f64,
    before_field: &[f64; D],
    after_field: &[f64; D],
) -> f64 {
    let s = DMatrix::from_fn(D, D, |i, k| {
        let dr_f: f64 = (0..D).map(|m| dr[i][m] * before_field[m]).sum();
        dr[i][k] + (after_field[i] - dr_f - reset_rate[i]) * gradient[k] / rate
    });
    s.determinant().abs().ln()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::integrate::clock::ZERO_PHASE;

    /// Two blocks on a belt at speed `vb` (x1, v1, x2, v2), each with
    /// friction ±mu on its own slip (switch j on v_j - vb, bit j), coupled
    /// by a spring; `product` adds a term with both signs multiplied.
    struct Blocks {
        mu: f64,
        vb: f64,
        limit: Option<f64>,
        product: bool,
    }

    const SWITCHES: [Surface; 2] = [Surface::Switch { bit: 0 }, Surface::Switch { bit: 1 }];

    impl Flow<4> for Blocks {
        fn rhs(&self, phase: &Phase, y: &[f64; 4]) -> [f64; 4] {
            self.rhs_in(0, phase, y)
        }

        fn surfaces(&self) -> &[Surface] {
            &SWITCHES
        }

        fn surface_gradient(&self, j: usize, _phase: &Phase, _y: &[f64; 4]) -> [f64; 4] {
            crate::array::from_fn(|i| if i == 2 * j + 1 { 1.0 } else { 0.0 })
        }

        fn stick_limit(&self, _j: usize, _y: &[f64; 4]) -> Option<f64> {
            self.limit
        }

        fn rhs_in(&self, region: u32, _phase: &Phase, y: &[f64; 4]) -> [f64; 4] {
            let sign = |bit: u32| if region >> bit & 1 == 1 { 1.0 } else { -1.0 };
            let both = if self.product {
                0.1 * sign(0) * sign(1)
            } else {
                0.0
            };
            [
                y[1],
                -2.0 * y[0] + y[2] - self.mu * sign(0) + 0.3 + both,
                y[3],
                -2.0 * y[2] + y[0] - self.mu * sign(1),
            ]
        }
    }

    #[test]
    fn a_reset_across_a_switch_takes_its_other_side_and_rounding_does_not() {
        // An event (no bit) and switches on bits 0 and 1.
        let surfaces = [
            Surface::Event,
            Surface::Switch { bit: 0 },
            Surface::Switch { bit: 1 },
        ];
        let values = |g: [f64; 3]| SurfaceValues {
            g: [g[0], g[1], g[2], 0.0],
            rate: [0.0; MAX_SURFACES],
        };
        // A rebound reverses a velocity across switch 0 (0.3 → -0.1), not
        // across switch 1: bit 0 is cleared, bit 1 kept.
        let before = values([0.0, 0.3, 2.0]);
        let after = values([0.0, -0.1, 1.5]);
        assert_eq!(jumped(&surfaces, 0b11, &before, &after), 0b10);
        // The other way: a bit set.
        assert_eq!(jumped(&surfaces, 0b10, &after, &before), 0b11);
        // Just across switch 0 by the location's rounding (on its positive
        // side, g a hair below 0), a reset that does not cross it keeps
        // the side; one that lands on it exactly (g = 0) too.
        let hair = values([0.0, -1e-17, 1.5]);
        assert_eq!(
            jumped(&surfaces, 0b11, &hair, &values([0.0, -0.2, 1.5])),
            0b11
        );
        assert_eq!(
            jumped(&surfaces, 0b11, &before, &values([0.0, 0.0, 1.5])),
            0b11
        );
        // From exactly on it, a jump to either side takes that side.
        let on = values([0.0, 0.0, 1.5]);
        assert_eq!(jumped(&surfaces, 0b10, &on, &values([0.0, 0.1, 1.5])), 0b11);
        assert_eq!(
            jumped(&surfaces, 0b11, &on, &values([0.0, -0.1, 1.5])),
            0b10
        );
        // An event's own g never moves a bit; a sliding region is kept.
        let sliding = sliding_on(0b01, 1);
        assert_eq!(jumped(&surfaces, sliding, &before, &after), sliding);
    }

    #[test]
    fn the_equivalent_control_keeps_every_sliding_surface_s_rate_at_zero() {
        let flow = Blocks {
            mu: 0.5,
            vb: 0.2,
            limit: Some(0.6),
            product: false,
        };
        let y = [0.1, flow.vb, -0.15, flow.vb];
        let both = sliding_on(sliding_on(0, 0), 1);
        let e = equivalent(&flow, both, &ZERO_PHASE, &y, true).expect("solvable");
        assert!(
            e.field[1].abs() <= 1e-15 && e.field[3].abs() <= 1e-15,
            "{:?}",
            e.field
        );
        assert_eq!((e.field[0], e.field[2]), (flow.vb, flow.vb));
        // Each block's margins: the force on it without its friction
        // (the other's held at its control) against the stick limit.
        let rest = [-2.0 * y[0] + y[2] + 0.3, -2.0 * y[2] + y[0]];
        for (j, rest) in rest.iter().enumerate() {
            let (plus, minus) = e.margins[j];
            assert!((plus - (0.6 - rest)).abs() <= 1e-15, "{j}: {plus}");
            assert!((minus - (0.6 + rest)).abs() <= 1e-15, "{j}: {minus}");
        }
        assert!(separable(&flow, both, &ZERO_PHASE, &y));
        let product = Blocks {
            product: true,
            ..flow
        };
        assert!(!separable(&product, both, &ZERO_PHASE, &y));
    }

    #[test]
    fn one_sliding_switch_is_filippov_s_combination_to_the_bit() {
        let flow = Blocks {
            mu: 0.5,
            vb: 0.2,
            limit: None,
            product: false,
        };
        let y = [0.1, flow.vb, -0.15, 0.7];
        // Slipping block 2 on its positive side, block 1 sliding.
        let region = sliding_on(1 << 1, 0);
        let (lo, hi) = (
            flow.rhs_in(1 << 1, &ZERO_PHASE, &y),
            flow.rhs_in(1 << 1 | 1, &ZERO_PHASE, &y),
        );
        let (a, b) = (lo[1], hi[1]);
        let alpha = a / (a - b);
        let filippov: [f64; 4] = crate::array::from_fn(|i| lo[i] + alpha * (hi[i] - lo[i]));
        let e = equivalent(&flow, region, &ZERO_PHASE, &y, true).expect("solvable");
        assert_eq!(e.field, filippov);
        let half_jump = 0.5 * (a - b);
        let mean = 0.5 * (a + b);
        assert_eq!(e.margins[0], (half_jump - mean, half_jump + mean));
        assert_eq!(
            joining_margins(&flow, 1 << 1, 0, 0, &ZERO_PHASE, &y),
            Some(e.margins[0])
        );
    }
}
