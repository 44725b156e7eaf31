//! The modes of motion beside a region's free field, as linear flows:
//! sliding on a switch (Filippov's field, its stick margins watched) and
//! held at rest on a stop (the pressing force watched), with the moves
//! onto their surfaces and the region after a reset.

use nalgebra::{DMatrix, DVector};

use super::dynamics::{augment, dynamics, side_sign, Dynamics, Watch, FORCING};
use super::system::{PiecewiseLinear, SlidingRule, SurfaceKind};

/// The two sides of a sliding switch count as one field plus a constant
/// jump when A, p and q agree to this many ulps of their size (the model
/// side builds them by evaluating expressions, which may round the two
/// sides differently).
const JUMP_ULPS: f64 = 64.0;

impl PiecewiseLinear {
    /// The stick margins (L − m, L + m) of switch j at (t, y), the other
    /// switches' sides those of `sides` (module docs). A switch that does
    /// not slide ([`SlidingRule::Stop`]) has Filippov's, −b and a.
    pub(super) fn stick_margins(
        &self,
        j: usize,
        sides: usize,
        t: f64,
        y: &DVector<f64>,
    ) -> (f64, f64) {
        let bit = 1 << self.bits[j].expect("a switch has a region bit");
        let normal = &self.surfaces[j].normal;
        let a = normal.dot(&self.fields[sides & !bit].eval(self.omega, t, y));
        let b = normal.dot(&self.fields[sides | bit].eval(self.omega, t, y));
        let m = 0.5 * (a + b);
        let limit = match self.surfaces[j].kind {
            SurfaceKind::Switch {
                sliding:
                    SlidingRule::Slide {
                        stick_limit: Some(limit),
                    },
            } => limit,
            _ => 0.5 * (a - b),
        };
        (limit - m, limit + m)
    }

    /// The flow while sliding on switch j, the other sides those of
    /// `sides` (module docs): None where it is not propagated (the rule is
    /// [`SlidingRule::Stop`], the jump is not a constant vector, or does
    /// not attract, n·Δ ≥ 0).
    pub(super) fn sliding_dynamics(&self, j: usize, sides: usize) -> Option<Dynamics> {
        let SurfaceKind::Switch {
            sliding: SlidingRule::Slide { stick_limit },
        } = self.surfaces[j].kind
        else {
            return None;
        };
        let n = self.dimension();
        let bit = 1 << self.bits[j].expect("a switch has a region bit");
        let (lo, hi) = (&self.fields[sides & !bit], &self.fields[sides | bit]);
        let same = |x: &DMatrix<f64>, y: &DMatrix<f64>| {
            let scale = x.amax().max(y.amax());
            (x - y).amax() <= JUMP_ULPS * f64::EPSILON * scale
        };
        let column = |v: &DVector<f64>| DMatrix::from_column_slice(n, 1, v.as_slice());
        if !(same(&lo.a, &hi.a)
            && same(&column(&lo.cos), &column(&hi.cos))
            && same(&column(&lo.sin), &column(&hi.sin)))
        {
            return None;
        }
        let normal = &self.surfaces[j].normal;
        let jump = &hi.constant - &lo.constant;
        let normal_jump = normal.dot(&jump);
        if normal_jump.is_nan() || normal_jump >= 0.0 {
            return None;
        }
        // B_s = [P M_lo; forcing rows], P = I − Δ nᵀ/(n·Δ).
        let projection = DMatrix::identity(n, n) - &jump * normal.transpose() / normal_jump;
        let mut b = self.regions[sides & !bit].b.clone();
        let top = &projection * b.rows(0, n);
        b.rows_mut(0, n).copy_from(&top);
        // a(z) = k_a·z, k_a = M_loᵀ n; m = k_a·z + (n·Δ)/2.
        let k_a = self.regions[sides & !bit].b.rows(0, n).transpose() * normal;
        let limit = stick_limit.unwrap_or(-0.5 * normal_jump);
        let mut plus = -&k_a; // L − m
        plus[n] += limit - 0.5 * normal_jump;
        let mut minus = k_a; // L + m
        minus[n] += limit + 0.5 * normal_jump;
        let mut watch = self.other_surfaces(j, sides);
        // A margin reaching 0 from above: g = −q rises through 0.
        watch.push((Watch::Margin { plus: true }, plus, -1.0));
        watch.push((Watch::Margin { plus: false }, minus, -1.0));
        Some(dynamics(b, watch, |w| self.is_event(w)))
    }

    /// Surface j as a stop: (i, j_v), where it is an event x_i = d (its
    /// normal along state i alone) whose reset changes the velocity x_v
    /// alone, x_i' = x_v in every region. The RK4 path's stops
    /// (`integrate::Wall`) are these.
    pub(super) fn stop_of(&self, j: usize) -> Option<(usize, usize)> {
        let surface = &self.surfaces[j];
        let SurfaceKind::Event { reset, .. } = &surface.kind else {
            return None;
        };
        let n = self.dimension();
        let mut along = (0..n).filter(|&i| surface.normal[i] != 0.0);
        let (i, None) = (along.next()?, along.next()) else {
            return None;
        };
        let moved: Vec<usize> = (0..n)
            .filter(|&c| (0..n).any(|r| reset[(r, c)] != if r == c { 1.0 } else { 0.0 }))
            .collect();
        let [v] = moved[..] else {
            return None;
        };
        let velocity_of_i = self.fields.iter().all(|f| {
            f.constant[i] == 0.0
                && f.cos[i] == 0.0
                && f.sin[i] == 0.0
                && (0..n).all(|c| f.a[(i, c)] == if c == v { 1.0 } else { 0.0 })
        });
        (v != i && velocity_of_i).then_some((i, v))
    }

    /// The held motion on stop `event` in region `sides`: the region's
    /// field with the velocity's row removed (the pressing force taken up
    /// by the stop; x_i' = x_v = 0 follows), and the scan's watch: the
    /// other surfaces, and the release, where the pressing force
    /// σ·F_v (σ the stop's side) falls to 0.
    pub(super) fn held_dynamics(&self, event: usize, sides: usize) -> Dynamics {
        let n = self.dimension();
        let (i, v) = self
            .stop_of(event)
            .expect("a held mode is entered on a stop");
        let mut b = self.regions[sides].b.clone();
        b.row_mut(v).fill(0.0);
        // The pressing force σ·F_v = σ·(row v of B)·z, σ = sign of n_i.
        let side = self.surfaces[event].normal[i].signum();
        let pressing = self.regions[sides].b.row(v).transpose() * side;
        let mut watch = self.other_surfaces(event, sides);
        // The pressing force reaching 0 from above: g = −q rises through 0.
        watch.push((Watch::Release, pressing, -1.0));
        debug_assert_eq!(b.nrows(), n + FORCING);
        dynamics(b, watch, |w| self.is_event(w))
    }

    /// What a mode on surface `on` (sliding on it, or held on it) watches
    /// of the other surfaces, with the orientations of region `sides`.
    pub(super) fn other_surfaces(
        &self,
        on: usize,
        sides: usize,
    ) -> Vec<(Watch, DVector<f64>, f64)> {
        self.surfaces
            .iter()
            .enumerate()
            .filter(|&(k, _)| k != on)
            .map(|(k, s)| {
                (
                    Watch::Surface(k),
                    s.augmented(),
                    side_sign(self.bits[k], sides),
                )
            })
            .collect()
    }

    /// Whether a watched function is an event surface's h (bounces and
    /// sticking apply to it).
    pub(super) fn is_event(&self, w: Watch) -> bool {
        match w {
            Watch::Surface(k) => self.bits[k].is_none(),
            Watch::Margin { .. } | Watch::Release => false,
        }
    }

    /// A mass coming to rest on stop `event` at y: the
    /// state put on the stop at rest (x_i = d, x_v = 0) and the saltation
    /// into the held motion, which forgets x_i and x_v (the other states'
    /// rows of the held field are the free field's, so the arrival time
    /// moves them only at second order).
    pub(super) fn hold(&self, event: usize, y: &DVector<f64>) -> (DVector<f64>, DMatrix<f64>) {
        let n = self.dimension();
        let (i, v) = self.stop_of(event).expect("a stop");
        let surface = &self.surfaces[event];
        let mut y = y.clone();
        y[i] = surface.offset / surface.normal[i];
        y[v] = 0.0;
        let mut s = DMatrix::identity(n, n);
        s[(i, i)] = 0.0;
        s[(v, v)] = 0.0;
        (y, s)
    }

    /// y moved along n onto switch j's surface (a sliding state kept on it
    /// against rounding).
    pub(super) fn onto(&self, j: usize, y: &DVector<f64>) -> DVector<f64> {
        let s = &self.surfaces[j];
        let h = s.value(y);
        if h == 0.0 {
            return y.clone();
        }
        y - &s.normal * (h / s.normal.norm_squared())
    }

    /// The field of `dynamics` at (t, y): the state rows of B z.
    pub(super) fn field_of(&self, dynamics: &Dynamics, t: f64, y: &DVector<f64>) -> DVector<f64> {
        let n = self.dimension();
        dynamics.b.rows(0, n) * augment(y, self.omega, t)
    }

    /// The region after a reset from y⁻ to y⁺: a switch the reset moves
    /// strictly off its side (h from ≤ 0 to > 0, or from ≥ 0 to < 0: a stop
    /// reversing the velocity across a friction surface v = 0) takes the
    /// side of y⁺. A switch the reset leaves on its side keeps its bit, so
    /// that a state on a switching surface, or a rounding across it, keeps
    /// the region it was given. The RK4 path's rule (`surface::jumped`).
    pub(super) fn region_after_reset(
        &self,
        region: usize,
        before: &DVector<f64>,
        after: &DVector<f64>,
    ) -> usize {
        let mut region = region;
        for (s, bit) in self.surfaces.iter().zip(&self.bits) {
            if let Some(b) = bit {
                let (h0, h1) = (s.value(before), s.value(after));
                if h1 > 0.0 && h0 <= 0.0 {
                    region |= 1 << b;
                } else if h1 < 0.0 && h0 >= 0.0 {
                    region &= !(1 << b);
                }
            }
        }
        region
    }
}
