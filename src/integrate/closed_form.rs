//! Closed-form ("exact") propagator of the forced, damped impact oscillator
//!
//! ```text
//! X'' = -2ζ X' - X + f cos(η t),        X ≤ X_w,
//! X = X_w with V = X' > 0   ⇒   V ↦ -e V,   e ∈ [0, 1],
//! ```
//!
//! used as the ground truth against which the time-stepping integrators are
//! checked. One iteration is one period T = 2π/η of the stroboscopic map, in
//! local time t ∈ [0, T] (the forcing is T-periodic, so every iteration starts
//! at t = 0 and the forcing phase never drifts).
//!
//! Between impacts the motion is linear and is propagated in closed form:
//!
//! ```text
//! X_p(t) = A cos ηt + B sin ηt,   A = f(1-η²)/D,  B = 2ζηf/D,  D = (1-η²)² + (2ζη)²,
//! u = (X - X_p, V - V_p),         u' = M u,       M = [[0, 1], [-1, -2ζ]],
//! exp(M t) = e^{-ζt} [ c(t) I + s(t) (M + ζI) ],  (M + ζI)² = κ² I,  κ² = ζ² - 1,
//! ```
//!
//! with c = cos ωt, s = sin(ωt)/ω, ω = √(1-ζ²) for ζ < 1; c = 1, s = t for
//! ζ = 1; c = cosh κt, s = sinh(κt)/κ for ζ > 1.
//!
//! Impacts are located by a left-to-right scan that is certified by a bound on
//! |X'''|, so that it cannot step over a near-grazing approach, and refined to
//! machine precision by safeguarded Newton iteration. (Roots of the exact
//! solution: the RK4 path's location, `integrate::locate`, finds roots of
//! RK4 re-stepped instead, and the two are kept apart.) The tangent map of
//! one period is the exact product of free-flight flow matrices and impact
//! saltation matrices.

use nalgebra::{Matrix2, Vector2};
use std::f64::consts::TAU;

// The certified scan's two tests, shared with the general propagator.
use super::piecewise_linear::{certified_below, certified_increasing};

/// Impacts allowed in one forcing period before the iteration is abandoned
/// with [`ExactStatus::Chattering`].
pub const MAX_IMPACTS_PER_PERIOD: u32 = 10_000;

/// Pre-impact velocities below this count as grazing impacts
/// ([`ExactIteration::grazing`]): the saltation matrix grows like 1/v⁻, so the
/// Jacobian of such a period is dominated by its rounding errors.
pub const GRAZING_VELOCITY: f64 = 1e-12;

/// Scan steps allowed in one period (a guard against pathological
/// near-tangencies; a normal period needs a few dozen).
const MAX_SCAN_STEPS: u32 = 1_000_000;

/// Largest scan step, as a fraction of min(2π, T). The scan is certified for
/// any step length; this only keeps the first trial of each step sensible.
const H_MAX_FRACTION: f64 = 0.25;

/// Smallest scan step, as a fraction of T. Below it the scan stops halving and
/// decides from the values at both ends (a contact missed there would have
/// a depth of order |X'''| h³ ≈ 1e-36).
const H_MIN_FRACTION: f64 = 1e-12;

/// A bounce off the wall whose predicted flight 2|V⁺|/X'' is shorter than this
/// fraction of T is the tail of an accumulating (Zeno) impact sequence.
const CHATTER_TIME_FRACTION: f64 = 1e-11;

/// So is a bounce whose height V⁺²/(2X'') is below this many ulps of the
/// position scale: the contact times, and with them the velocities, would
/// be rounding noise.
const CHATTER_HEIGHT_ULPS: f64 = 64.0;

/// Iterations of the root refinement (it converges in a handful).
const MAX_REFINE: usize = 200;

/// The forced, damped impact oscillator `X'' = -2ζX' - X + f cos(ηt)` with a
/// rigid wall at `X = wall` approached from below, and Newtonian restitution
/// `V ↦ -e V` at contact.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ForcedImpactOscillator {
    /// Damping ratio ζ ≥ 0.
    pub zeta: f64,
    /// Forcing amplitude f.
    pub f: f64,
    /// Forcing frequency η > 0 (the natural frequency is 1).
    pub eta: f64,
    /// Wall position X_w.
    pub wall: f64,
    /// Coefficient of restitution e ∈ [0, 1].
    pub restitution: f64,
}

/// How an exact iteration ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ExactStatus {
    /// The period was completed; state and Jacobian are those at t = T.
    Ok,
    /// Impacts accumulated (more than [`MAX_IMPACTS_PER_PERIOD`], or a
    /// bounce off the wall below the time or position resolution, the tail of
    /// a Zeno sequence that would end in sticking), or the search exhausted
    /// its step budget: the iteration stopped early, at
    /// [`ExactIteration::time`].
    Chattering,
}

/// The result of one exact forcing period.
#[derive(Clone, Copy, Debug)]
pub struct ExactIteration {
    /// (X, V) at t = T (at [`Self::time`] when the status is not `Ok`).
    pub state: [f64; 2],
    /// The exact tangent map ∂state/∂state(0):
    /// `exp(M(t_end - t_k)) S_k exp(M(t_k - t_{k-1})) ··· S_1 exp(M t_1)`.
    pub jacobian: Matrix2<f64>,
    /// Impacts during this period.
    pub impacts: u32,
    /// Smallest pre-impact velocity v⁻ of the period (∞ if there was none).
    pub min_impact_velocity: f64,
    /// Impacts with v⁻ < [`GRAZING_VELOCITY`]; their saltation matrices make
    /// the Jacobian meaningless (it may even be infinite or NaN).
    pub grazing: u32,
    /// Dimensions the iteration collapsed: 1 after an impact with e = 0, 2
    /// after sticking (the mass rests on the wall while the force presses it
    /// there, and leaves when the force reverses, at a time set by the
    /// forcing alone). The Jacobian has rank 2 - rank_loss.
    pub rank_loss: u32,
    /// Local time reached: T, unless the status is not `Ok`.
    pub time: f64,
    /// How the period ended.
    pub status: ExactStatus,
}

impl ForcedImpactOscillator {
    /// Validates the parameters.
    ///
    /// Errors if ζ < 0, η ≤ 0, f or X_w is not finite, e ∉ [0, 1], or ζ = 0
    /// with η = 1 (undamped resonance: no periodic particular solution).
    pub fn new(zeta: f64, f: f64, eta: f64, wall: f64, restitution: f64) -> Result<Self, String> {
        if !(zeta.is_finite() && zeta >= 0.0) {
            return Err(format!("damping ratio must be finite and >= 0, got {zeta}"));
        }
        if !(eta.is_finite() && eta > 0.0) {
            return Err(format!(
                "forcing frequency must be finite and > 0, got {eta}"
            ));
        }
        if !f.is_finite() {
            return Err(format!("forcing amplitude must be finite, got {f}"));
        }
        if !wall.is_finite() {
            return Err(format!("wall position must be finite, got {wall}"));
        }
        if !(0.0..=1.0).contains(&restitution) {
            return Err(format!("restitution must lie in [0, 1], got {restitution}"));
        }
        if zeta == 0.0 && eta == 1.0 {
            return Err("undamped resonance (zeta = 0, eta = 1) has no periodic response".into());
        }
        Ok(Self {
            zeta,
            f,
            eta,
            wall,
            restitution,
        })
    }

    /// The forcing period T = 2π/η.
    pub fn period(&self) -> f64 {
        TAU / self.eta
    }

    /// exp(M t), M = [[0, 1], [-1, -2ζ]]: the free-flight flow matrix of the
    /// deviation u = (X - X_p, V - V_p) from the particular solution, which is
    /// also the tangent map of a free flight of duration t.
    ///
    /// ```text
    /// exp(M t) = [[E_c + ζ E_s,  E_s        ],
    ///             [-E_s,         E_c - ζ E_s]],   E_c = e^{-ζt} c(t),  E_s = e^{-ζt} s(t).
    /// ```
    ///
    /// For ζ > 1 it is evaluated through the slow and fast exponentials
    /// e^{-t/p} and e^{-2κt} (p = ζ + κ), which neither overflows nor cancels
    /// for large ζt or for ζ just above 1. Meant for t ≥ 0.
    pub fn flow_matrix(&self, t: f64) -> Matrix2<f64> {
        flow(self.zeta, Damping::new(self.zeta), t)
    }

    /// The free-flight state at local time `t1` from state `y0` at local time
    /// `t0`, ignoring the wall: y(t1) = y_p(t1) + exp(M(t1 - t0)) (y0 - y_p(t0)).
    pub fn free_flight(&self, t0: f64, y0: [f64; 2], t1: f64) -> [f64; 2] {
        let model = Model::new(self);
        let p = model.eval(&model.segment(t0, y0), t1);
        [p.x, p.v]
    }

    /// The acceleration X'' = -2ζV - X + f cos(ηt) at local time `t`.
    pub fn acceleration(&self, t: f64, y: [f64; 2]) -> f64 {
        -2.0 * self.zeta * y[1] - y[0] + self.f * (self.eta * t).cos()
    }

    /// The saltation matrix of an impact at local time `t` with pre-impact
    /// velocity `v_minus` = v⁻ > 0:
    ///
    /// ```text
    /// S = [[-e, 0], [(a⁺ + e a⁻)/v⁻, -e]],   det S = e²,
    /// a⁻ = -2ζ v⁻ - X_w + f cos ηt,   a⁺ = 2ζ e v⁻ - X_w + f cos ηt.
    /// ```
    ///
    /// The damping terms cancel in a⁺ + e a⁻ = (1 + e)(f cos ηt - X_w), which
    /// is how it is evaluated. The entry diverges like 1/v⁻ at grazing.
    pub fn saltation(&self, t: f64, v_minus: f64) -> Matrix2<f64> {
        let e = self.restitution;
        let jump = (1.0 + e) * (self.f * (self.eta * t).cos() - self.wall);
        Matrix2::new(-e, 0.0, jump / v_minus, -e)
    }

    /// A mass at rest on the wall since `t`: still held there at `t1` (the
    /// end point), or released, with the free flight from the release.
    fn rest_on_wall(&self, model: &Model, t: f64, t1: f64) -> Rest {
        let y = [self.wall, 0.0];
        let release = self.release_after(t);
        if release >= t1 {
            return Rest::Held(model.exact_point(&model.segment(t1, y), y));
        }
        let segment = model.segment(release, y);
        let start = model.exact_point(&segment, y);
        Rest::Released(segment, start)
    }

    /// When a mass at rest on the wall since `t` leaves it: the first time
    /// after `t` at which the net force there, -X_w + f·cos(ηt), falls to
    /// zero (∞ if it never does).
    fn release_after(&self, t: f64) -> f64 {
        let c = self.wall / self.f;
        if !(-1.0..1.0).contains(&c) {
            // f·cos never falls below X_w: pressed for ever (or never, but
            // then the mass would not have stuck).
            return f64::INFINITY;
        }
        let first = c.acos();
        // Within rounding of a release angle counts as that release (not
        // the next period's), so a mass stopped right at it leaves.
        let turns = ((self.eta * t - first) / TAU - 1e-9).ceil().max(0.0);
        let mut release = ((first + turns * TAU) / self.eta).max(t);
        // Just past the root, so that the event search starting there sees
        // the force pulling away and does not stick again on rounding.
        let margin = 1e-12 * (self.wall.abs() + self.f.abs());
        let mut nudge = 4.0 * f64::EPSILON * release.abs().max(1.0);
        for _ in 0..40 {
            if -self.wall + self.f * (self.eta * release).cos() <= -margin {
                break;
            }
            release += nudge;
            nudge *= 2.0;
        }
        release
    }

    /// One forcing period from phase 0, with the exact tangent map.
    ///
    /// Precondition: `y0[0] <= wall`. A start on the wall moving into it
    /// (V > 0) impacts at t = 0 (a start beyond the wall is handled like one
    /// on it). An impact exactly at t = T is applied, so the returned state
    /// is always the post-impact one.
    ///
    /// No allocation: everything lives on the stack.
    pub fn iterate(&self, y0: [f64; 2]) -> ExactIteration {
        self.iterate_span(y0, 0.0, self.period())
    }

    /// [`iterate`](Self::iterate) over the part [t0, t1] of a period (a
    /// sub-map: see `system::Part`), from y0 at t0.
    pub fn iterate_span(&self, y0: [f64; 2], t0: f64, t1: f64) -> ExactIteration {
        let mut model = Model::new(self);
        model.t_end = t1;
        let mut segment = model.segment(t0, y0);
        let mut start = model.exact_point(&segment, y0);
        let mut jacobian = Matrix2::identity();
        let mut impacts = 0_u32;
        let mut grazing = 0_u32;
        let mut min_impact_velocity = f64::INFINITY;
        let mut rank_loss = 0;
        let mut budget = MAX_SCAN_STEPS;

        let (end, status) = loop {
            match model.next_event(&segment, start, &mut budget) {
                Event::End(p) => break (p, ExactStatus::Ok),
                // At rest on the wall, or the tail of an accumulating
                // sequence of bounces, under a force pressing into the wall:
                // the mass sticks until the force reverses.
                Event::Sticking(p) | Event::Chattering(p) if p.x >= self.wall && p.acc > 0.0 => {
                    rank_loss = 2;
                    jacobian = Matrix2::zeros();
                    match self.rest_on_wall(&model, p.t, t1) {
                        Rest::Held(end) => break (end, ExactStatus::Ok),
                        Rest::Released(s, a) => (segment, start) = (s, a),
                    }
                }
                Event::Sticking(p) | Event::Chattering(p) => break (p, ExactStatus::Chattering),
                Event::Impact(p) => {
                    if impacts == MAX_IMPACTS_PER_PERIOD {
                        if p.acc > 0.0 {
                            // Dense bounces under a pressing force: at rest.
                            rank_loss = 2;
                            jacobian = Matrix2::zeros();
                            match self.rest_on_wall(&model, p.t, t1) {
                                Rest::Held(end) => break (end, ExactStatus::Ok),
                                Rest::Released(s, a) => (segment, start) = (s, a),
                            }
                            continue;
                        }
                        break (p, ExactStatus::Chattering);
                    }
                    // A root found with V ≤ 0 is a tangency lost in rounding.
                    let v_minus = p.v.max(0.0);
                    if v_minus == 0.0 && (rank_loss == 2 || start.v == 0.0) {
                        // Touching the wall at rest, right after a release
                        // (the force there is zero to rounding): nothing to
                        // reverse, and the Jacobian is already zero (or the
                        // part began at rest after sticking), which a
                        // singular saltation would only turn into NaN.
                        if p.acc > 0.0 {
                            match self.rest_on_wall(&model, p.t, t1) {
                                Rest::Held(end) => break (end, ExactStatus::Ok),
                                Rest::Released(s, a) => (segment, start) = (s, a),
                            }
                        } else {
                            let y = [self.wall, 0.0];
                            segment = model.segment(p.t, y);
                            start = model.exact_point(&segment, y);
                        }
                        continue;
                    }
                    impacts += 1;
                    min_impact_velocity = min_impact_velocity.min(v_minus);
                    if v_minus < GRAZING_VELOCITY {
                        grazing += 1;
                    }
                    jacobian =
                        self.saltation(p.t, v_minus) * model.flow(p.t - segment.t0) * jacobian;
                    if self.restitution == 0.0 {
                        rank_loss = rank_loss.max(1);
                    }
                    let y = [self.wall, -self.restitution * v_minus];
                    segment = model.segment(p.t, y);
                    start = model.exact_point(&segment, y);
                }
            }
        };
        jacobian = model.flow(end.t - segment.t0) * jacobian;

        ExactIteration {
            state: [end.x, end.v],
            jacobian,
            impacts,
            min_impact_velocity,
            grazing,
            rank_loss,
            time: end.t,
            status,
        }
    }
}

/// The three forms of exp(M t).
#[derive(Clone, Copy, Debug)]
enum Damping {
    /// ζ < 1, ω = √(1-ζ²).
    Under { omega: f64 },
    /// ζ = 1.
    Critical,
    /// ζ > 1, κ = √(ζ²-1), p = ζ + κ; the eigenvalues are -1/p and -p.
    Over { kappa: f64, p: f64 },
}

impl Damping {
    fn new(zeta: f64) -> Self {
        // (1-ζ)(1+ζ) rather than 1-ζ², so that ω and κ keep full relative
        // precision for ζ within 1e-8 of 1.
        if zeta < 1.0 {
            Damping::Under {
                omega: ((1.0 - zeta) * (1.0 + zeta)).sqrt(),
            }
        } else if zeta > 1.0 {
            let kappa = ((zeta - 1.0) * (zeta + 1.0)).sqrt();
            Damping::Over {
                kappa,
                p: zeta + kappa,
            }
        } else {
            Damping::Critical
        }
    }
}

/// exp(M t) for M = [[0, 1], [-1, -2ζ]] (see [`ForcedImpactOscillator::flow_matrix`]).
fn flow(zeta: f64, damping: Damping, t: f64) -> Matrix2<f64> {
    match damping {
        Damping::Under { omega } => {
            let decay = (-zeta * t).exp();
            let (sin, cos) = (omega * t).sin_cos();
            let es = decay * sin / omega;
            let ec = decay * cos;
            Matrix2::new(ec + zeta * es, es, -es, ec - zeta * es)
        }
        Damping::Critical => {
            let decay = (-t).exp();
            Matrix2::new(decay * (1.0 + t), decay * t, -decay * t, decay * (1.0 - t))
        }
        Damping::Over { kappa, p } => {
            // With e₁ = e^{-t/p} (slow mode, -1/p = κ - ζ), r = e^{-2κt} and
            // w = (1 - r)/(2κ):  e^{-ζt} cosh κt = e₁(1 + r)/2,
            // e^{-ζt} sinh(κt)/κ = e₁ w, and (using p - 1/p = 2κ)
            //   E_c + ζE_s = e₁(1 + w/p),   E_c - ζE_s = e₁(r - w/p).
            // Every factor is bounded, nothing cancels except where the entry
            // itself passes through zero, and expm1 keeps w exact as κ → 0.
            let slow = (-t / p).exp();
            let fast = (-2.0 * kappa * t).exp();
            let w = -(-2.0 * kappa * t).exp_m1() / (2.0 * kappa);
            Matrix2::new(
                slow * (1.0 + w / p),
                slow * w,
                -slow * w,
                slow * (fast - w / p),
            )
        }
    }
}

/// A point of a free-flight segment with what the contact search needs.
#[derive(Clone, Copy, Debug)]
struct Point {
    t: f64,
    x: f64,
    v: f64,
    /// X'' at t.
    acc: f64,
    /// Deviation from the particular solution, u = (X - X_p, V - V_p).
    u: Vector2<f64>,
}

/// Where a sticking mass is at the end of an iteration's span.
enum Rest {
    Held(Point),
    Released(Segment, Point),
}

/// A free flight starting at local time `t0` with deviation `u0`.
#[derive(Clone, Copy, Debug)]
struct Segment {
    t0: f64,
    u0: Vector2<f64>,
}

/// What ended a scan of a free-flight segment.
enum Event {
    /// Reached t = T without contact.
    End(Point),
    /// Contact (the pre-impact point).
    Impact(Point),
    /// At rest on the wall, pushed into it.
    Sticking(Point),
    /// Accumulating impacts or exhausted budget.
    Chattering(Point),
}

/// Constants of one parameter set, computed once per iteration.
#[derive(Clone, Copy, Debug)]
struct Model {
    zeta: f64,
    eta: f64,
    f: f64,
    wall: f64,
    damping: Damping,
    /// Particular solution X_p = a cos ηt + b sin ηt.
    a: f64,
    b: f64,
    /// Where the iteration (or the part of it) ends: the period T unless set.
    t_end: f64,
    /// √(A² + B²).
    particular_amplitude: f64,
    /// |X_p'''| ≤ η³ √(A² + B²).
    particular_jerk: f64,
    /// |(2ζ, 4ζ² - 1)|, the first row of M³ (see `jerk_bound`).
    energy_jerk: f64,
    h_max: f64,
    h_min: f64,
    chatter_time: f64,
}

impl Model {
    fn new(osc: &ForcedImpactOscillator) -> Self {
        let ForcedImpactOscillator {
            zeta, f, eta, wall, ..
        } = *osc;
        let detuning = (1.0 - eta) * (1.0 + eta);
        let two_zeta_eta = 2.0 * zeta * eta;
        let d = detuning * detuning + two_zeta_eta * two_zeta_eta;
        let a = f * detuning / d;
        let b = two_zeta_eta * f / d;
        let period = TAU / eta;
        Model {
            zeta,
            eta,
            f,
            wall,
            damping: Damping::new(zeta),
            a,
            b,
            t_end: period,
            particular_amplitude: a.hypot(b),
            particular_jerk: eta * eta * eta * a.hypot(b),
            energy_jerk: (2.0 * zeta).hypot(4.0 * zeta * zeta - 1.0),
            h_max: H_MAX_FRACTION * period.min(TAU),
            h_min: H_MIN_FRACTION * period,
            chatter_time: CHATTER_TIME_FRACTION * period,
        }
    }

    fn flow(&self, t: f64) -> Matrix2<f64> {
        flow(self.zeta, self.damping, t)
    }

    /// (X_p, V_p) at t.
    fn particular(&self, t: f64) -> (f64, f64) {
        let (sin, cos) = (self.eta * t).sin_cos();
        (
            self.a * cos + self.b * sin,
            self.eta * (self.b * cos - self.a * sin),
        )
    }

    fn segment(&self, t0: f64, y0: [f64; 2]) -> Segment {
        let (xp, vp) = self.particular(t0);
        Segment {
            t0,
            u0: Vector2::new(y0[0] - xp, y0[1] - vp),
        }
    }

    /// The segment's starting point, with the given state kept exactly (so
    /// that a start on the wall is recognised as such).
    fn exact_point(&self, segment: &Segment, y: [f64; 2]) -> Point {
        let t = segment.t0;
        Point {
            t,
            x: y[0],
            v: y[1],
            acc: -2.0 * self.zeta * y[1] - y[0] + self.f * (self.eta * t).cos(),
            u: segment.u0,
        }
    }

    /// The free-flight point at local time t. Always from the segment start,
    /// so rounding does not accumulate along the scan.
    fn eval(&self, segment: &Segment, t: f64) -> Point {
        let u = self.flow(t - segment.t0) * segment.u0;
        let (xp, vp) = self.particular(t);
        Point {
            t,
            x: xp + u.x,
            v: vp + u.y,
            // X_p'' = -η² X_p and u'' = (M u)₂.
            acc: -self.eta * self.eta * xp - u.x - 2.0 * self.zeta * u.y,
            u,
        }
    }

    /// An upper bound of |X'''| on [t, ∞) along the free flight through a
    /// point with deviation u.
    ///
    /// The particular part contributes η³√(A²+B²). For the homogeneous part,
    /// X_h''' = (M³u)₁ and |u| never grows (d|u|²/dt = -4ζu₂²), giving
    /// |(2ζ, 4ζ²-1)|·|u|. The modal forms are sharper away from ζ = 1:
    /// for ζ < 1, X_h = Re(K e^{λs}) with |λ| = 1 and
    /// |K| = √(u₁² + ((u₂+ζu₁)/ω)²); for ζ > 1, X_h = α e^{-s/p} + β e^{-ps}
    /// with β = -(u₂ + u₁/p)/(2κ), α = u₁ - β, and each term's third
    /// derivative decays from |α|/p³ and |β|p³. The smallest bound is used.
    fn jerk_bound(&self, u: Vector2<f64>) -> f64 {
        let energy = self.energy_jerk * u.x.hypot(u.y);
        let modal = match self.damping {
            Damping::Under { omega } => u.x.hypot((u.y + self.zeta * u.x) / omega),
            Damping::Critical => f64::INFINITY,
            Damping::Over { kappa, p } => {
                let beta = -(u.y + u.x / p) / (2.0 * kappa);
                let alpha = u.x - beta;
                alpha.abs() / (p * p * p) + beta.abs() * (p * p * p)
            }
        };
        self.particular_jerk + energy.min(modal)
    }

    /// Scans the free flight from `start` for the first contact in
    /// (start.t, T].
    ///
    /// Over [a, a+h], with g = X - X_w and L ≥ |g'''|,
    /// g(a+s) ≤ q(s) = g(a) + g'(a)s + g''(a)s²/2 + Ls³/6; a step is taken
    /// only when q < 0 on (0, h], so no contact, however brief, is stepped
    /// over. Otherwise the step is halved until either g(a+h) ≥ 0 with g
    /// certified increasing on [a, a+h] (a bracket of the first root), or h
    /// reaches h_min, where the ends decide (including a velocity maximum
    /// inside the step that reaches the wall).
    fn next_event(&self, segment: &Segment, start: Point, budget: &mut u32) -> Event {
        let t_end = self.t_end;
        let mut a = start;
        let mut h = self.h_max;
        if start.x >= self.wall && start.v < 0.0 && start.acc > 0.0 {
            // Leaving the wall against a force pushing back: the bounce lasts
            // about 2|V|/X'', so start with half of that rather than halving
            // down from h_max.
            h = h.min(-start.v / start.acc);
        }
        loop {
            if a.x >= self.wall {
                // On the wall: the segment's start after an impact, or a
                // point that rounding put there.
                if a.v > 0.0 {
                    return Event::Impact(a);
                }
                if a.acc > 0.0 {
                    if a.v == 0.0 {
                        return Event::Sticking(a);
                    }
                    // A bounce below the time or position resolution: the
                    // tail of an accumulating impact sequence.
                    let scale = self.wall.abs() + self.particular_amplitude + a.u.norm();
                    let resolution = CHATTER_HEIGHT_ULPS * f64::EPSILON * scale;
                    if -2.0 * a.v < self.chatter_time * a.acc
                        || a.v * a.v < 2.0 * a.acc * resolution
                    {
                        return Event::Chattering(a);
                    }
                }
            }
            if a.t >= t_end {
                return Event::End(a);
            }
            if *budget == 0 {
                return Event::Chattering(a);
            }
            *budget -= 1;
            let remaining = t_end - a.t;
            let (step, t_b) = if h >= remaining {
                (remaining, t_end)
            } else {
                (h, a.t + h)
            };
            let g = a.x - self.wall;
            let jerk = self.jerk_bound(a.u);
            let b = self.eval(segment, t_b);
            if certified_below(g, a.v, a.acc, jerk, step) {
                a = b;
                h = (2.0 * h).min(self.h_max);
                continue;
            }
            let fine = step <= self.h_min;
            if b.x >= self.wall {
                if fine || (g < 0.0 && certified_increasing(a.v, a.acc, jerk, step)) {
                    return Event::Impact(self.refine(segment, a, b));
                }
            } else if fine {
                if a.v > 0.0 && b.v < 0.0 {
                    let top = self.velocity_zero(segment, a, b);
                    if top.x >= self.wall {
                        return Event::Impact(self.refine(segment, a, top));
                    }
                }
                a = b;
                h = (2.0 * step).min(self.h_max);
                continue;
            }
            h = 0.5 * step;
        }
    }

    /// The contact time in [lo, hi], where g(lo) < 0 (or lo is a start on
    /// the wall moving away from it), g(hi) ≥ 0 and g has no other root:
    /// Newton's method, falling back to bisection whenever a Newton step
    /// would leave the bracket.
    fn refine(&self, segment: &Segment, mut lo: Point, mut hi: Point) -> Point {
        let tol = 2.0 * f64::EPSILON * hi.t.abs().max(1.0);
        let mut current = hi;
        let mut lo_evaluated = false;
        for _ in 0..MAX_REFINE {
            if hi.t - lo.t <= tol {
                break;
            }
            let newton = if current.v > 0.0 {
                current.t - (current.x - self.wall) / current.v
            } else {
                f64::NAN
            };
            let t = if newton > lo.t && newton < hi.t {
                newton
            } else {
                0.5 * (lo.t + hi.t)
            };
            let moved = (t - current.t).abs();
            let p = self.eval(segment, t);
            if p.x >= self.wall {
                hi = p;
            } else {
                lo = p;
                lo_evaluated = true;
            }
            current = p;
            if p.x == self.wall || moved <= tol {
                break;
            }
        }
        if lo_evaluated && self.wall - lo.x < hi.x - self.wall {
            lo
        } else {
            hi
        }
    }

    /// The velocity maximum between a (V > 0) and b (V < 0), by bisection;
    /// of the two final points, the higher one.
    fn velocity_zero(&self, segment: &Segment, mut lo: Point, mut hi: Point) -> Point {
        let tol = 2.0 * f64::EPSILON * hi.t.abs().max(1.0);
        for _ in 0..MAX_REFINE {
            if hi.t - lo.t <= tol {
                break;
            }
            let p = self.eval(segment, 0.5 * (lo.t + hi.t));
            if p.v > 0.0 {
                lo = p;
            } else {
                hi = p;
            }
        }
        if lo.x >= hi.x {
            lo
        } else {
            hi
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn oscillator(zeta: f64, f: f64, eta: f64, wall: f64, e: f64) -> ForcedImpactOscillator {
        ForcedImpactOscillator::new(zeta, f, eta, wall, e).unwrap()
    }

    /// exp(M t) by scaling and squaring of a 30-term Taylor series.
    fn expm_taylor(zeta: f64, t: f64) -> Matrix2<f64> {
        let m = Matrix2::new(0.0, 1.0, -1.0, -2.0 * zeta) * t;
        let norm = m.abs().max();
        let squarings = if norm > 0.25 {
            (norm / 0.25).log2().ceil() as i32
        } else {
            0
        };
        let a = m / 2f64.powi(squarings);
        let mut term = Matrix2::identity();
        let mut sum = Matrix2::identity();
        for n in 1..30 {
            term = term * a / n as f64;
            sum += term;
        }
        for _ in 0..squarings {
            sum = sum * sum;
        }
        sum
    }

    /// exp(M t) = V diag(e^{λ₁t}, e^{λ₂t}) V⁻¹ for ζ > 1, written out.
    fn expm_eigen(zeta: f64, t: f64) -> Matrix2<f64> {
        let kappa = (zeta * zeta - 1.0).sqrt();
        let l1 = -1.0 / (zeta + kappa);
        let l2 = -(zeta + kappa);
        let (e1, e2) = ((l1 * t).exp(), (l2 * t).exp());
        let d = l1 - l2;
        Matrix2::new(
            (-l2 * e1 + l1 * e2) / d,
            (e1 - e2) / d,
            l1 * l2 * (e2 - e1) / d,
            (l1 * e1 - l2 * e2) / d,
        )
    }

    fn assert_matrix_close(a: &Matrix2<f64>, b: &Matrix2<f64>, rel: f64, what: &str) {
        let scale = b.abs().max();
        for i in 0..2 {
            for j in 0..2 {
                // Entry-wise relative, except for entries far below the
                // matrix norm (near a zero of that entry).
                let tol = rel * b[(i, j)].abs().max(1e-3 * scale);
                assert!(
                    (a[(i, j)] - b[(i, j)]).abs() <= tol,
                    "{what}: entry ({i},{j}) {} vs {} (tol {tol:e})",
                    a[(i, j)],
                    b[(i, j)]
                );
            }
        }
    }

    fn rk4(osc: &ForcedImpactOscillator, t0: f64, y0: [f64; 2], t1: f64, n: usize) -> [f64; 2] {
        let rhs = |t: f64, y: [f64; 2]| [y[1], osc.acceleration(t, y)];
        let h = (t1 - t0) / n as f64;
        let mut y = y0;
        for k in 0..n {
            let t = t0 + k as f64 * h;
            let k1 = rhs(t, y);
            let k2 = rhs(
                t + 0.5 * h,
                [y[0] + 0.5 * h * k1[0], y[1] + 0.5 * h * k1[1]],
            );
            let k3 = rhs(
                t + 0.5 * h,
                [y[0] + 0.5 * h * k2[0], y[1] + 0.5 * h * k2[1]],
            );
            let k4 = rhs(t + h, [y[0] + h * k3[0], y[1] + h * k3[1]]);
            for i in 0..2 {
                y[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
            }
        }
        y
    }

    fn transient(osc: &ForcedImpactOscillator, n: usize) -> [f64; 2] {
        let mut y = [0.0, 0.0];
        for _ in 0..n {
            let it = osc.iterate(y);
            assert_eq!(it.status, ExactStatus::Ok);
            y = it.state;
        }
        y
    }

    #[test]
    fn constructor_rejects_bad_parameters() {
        assert!(ForcedImpactOscillator::new(-0.1, 1.0, 0.8, 2.0, 1.0).is_err());
        assert!(ForcedImpactOscillator::new(f64::NAN, 1.0, 0.8, 2.0, 1.0).is_err());
        assert!(ForcedImpactOscillator::new(0.05, 1.0, 0.0, 2.0, 1.0).is_err());
        assert!(ForcedImpactOscillator::new(0.05, f64::INFINITY, 0.8, 2.0, 1.0).is_err());
        assert!(ForcedImpactOscillator::new(0.05, 1.0, 0.8, f64::NAN, 1.0).is_err());
        assert!(ForcedImpactOscillator::new(0.05, 1.0, 0.8, 2.0, 1.5).is_err());
        assert!(ForcedImpactOscillator::new(0.05, 1.0, 0.8, 2.0, -0.1).is_err());
        assert!(ForcedImpactOscillator::new(0.05, 1.0, 0.8, 2.0, f64::NAN).is_err());
        assert!(ForcedImpactOscillator::new(0.0, 1.0, 1.0, 2.0, 1.0).is_err());
        assert!(ForcedImpactOscillator::new(0.0, 1.0, 1.1, 2.0, 1.0).is_ok());
        let osc = oscillator(0.05, 1.0, 0.8, 2.0, 1.0);
        assert!((osc.period() - TAU / 0.8).abs() < 1e-15);
    }

    #[test]
    fn flow_matrix_matches_taylor_series() {
        for zeta in [0.0, 0.05, 0.7, 1.0 - 1e-9, 1.0, 1.0 + 1e-9, 1.3, 2.0] {
            let osc = oscillator(zeta, 1.0, 0.8, 2.0, 1.0);
            for t in [0.0, 1e-3, 0.1, 0.5, 1.0, 3.7, 10.0, 25.0] {
                let phi = osc.flow_matrix(t);
                assert_matrix_close(
                    &phi,
                    &expm_taylor(zeta, t),
                    1e-12,
                    &format!("ζ={zeta} t={t}"),
                );
                let det = (-2.0 * zeta * t).exp();
                // Rounding of Φ₁₁Φ₂₂ - Φ₁₂Φ₂₁ itself scales with the products.
                let products =
                    (phi[(0, 0)] * phi[(1, 1)]).abs() + (phi[(0, 1)] * phi[(1, 0)]).abs();
                assert!(
                    (phi.determinant() - det).abs() <= 1e-13 * det + 1e-15 * products,
                    "det at ζ={zeta} t={t}: {} vs {det}",
                    phi.determinant()
                );
            }
        }
    }

    #[test]
    fn flow_matrix_is_continuous_through_critical_damping() {
        let t = 2.5;
        let critical = oscillator(1.0, 1.0, 0.8, 2.0, 1.0).flow_matrix(t);
        for zeta in [1.0 - 1e-8, 1.0 - 1e-12, 1.0 + 1e-12, 1.0 + 1e-8] {
            let phi = oscillator(zeta, 1.0, 0.8, 2.0, 1.0).flow_matrix(t);
            // dΦ/dζ is O(t²) here, so the difference must be O((ζ-1)·t²).
            let bound = 10.0 * (zeta - 1.0).abs() * t * t + 1e-15;
            assert!((phi - critical).abs().max() <= bound, "ζ = {zeta}");
        }
    }

    #[test]
    fn flow_matrix_heavy_damping() {
        let zeta = 200.0;
        let osc = oscillator(zeta, 1.0, 0.8, 2.0, 1.0);
        for t in [1e-4, 1e-3, 4e-3] {
            assert_matrix_close(
                &osc.flow_matrix(t),
                &expm_taylor(zeta, t),
                1e-12,
                "ζ=200 taylor",
            );
        }
        for t in [1e-3, 0.01, 0.1, 1.0, 10.0, 100.0] {
            let phi = osc.flow_matrix(t);
            assert_matrix_close(&phi, &expm_eigen(zeta, t), 1e-12, &format!("ζ=200 t={t}"));
            // Semigroup property, which checks the large-t regime
            // independently of any reference formula.
            let half = osc.flow_matrix(0.5 * t);
            assert_matrix_close(
                &(half * half),
                &phi,
                1e-12,
                &format!("ζ=200 semigroup t={t}"),
            );
        }
        for t in [1e-3, 0.01] {
            let det = (-2.0 * zeta * t).exp();
            let phi = osc.flow_matrix(t);
            assert!((phi.determinant() - det).abs() <= 1e-12 * det);
        }
        for t in [100.0, 1000.0] {
            let phi = osc.flow_matrix(t);
            assert!(phi.iter().all(|x| x.is_finite()), "{phi}");
            // Only the slow mode e^{-t/p} survives: Φ₁₁ ≈ e^{-t/p}(1 + 1/(2κp)).
            let kappa = (zeta * zeta - 1.0_f64).sqrt();
            let p = zeta + kappa;
            let expected = (-t / p).exp() * (1.0 + 1.0 / (2.0 * kappa * p));
            assert!((phi[(0, 0)] - expected).abs() <= 1e-13 * expected);
        }
        // Also well behaved for ζ ≫ 1 at long times in the other regimes.
        for zeta in [0.99, 5.0, 50.0] {
            let phi = oscillator(zeta, 1.0, 0.8, 2.0, 1.0).flow_matrix(1000.0);
            assert!(phi.iter().all(|x| x.is_finite()));
        }
    }

    #[test]
    fn free_flight_matches_rk4() {
        let osc = oscillator(0.05, 1.0, 0.8, 1e9, 1.0);
        let period = osc.period();
        let cases = [
            (0.0, [0.0, 0.0], period),
            (0.0, [1.5, -0.3], period),
            (0.7, [0.3, -0.4], 0.7 + 2.0 * period),
        ];
        for (t0, y0, t1) in cases {
            let exact = osc.free_flight(t0, y0, t1);
            let reference = rk4(&osc, t0, y0, t1, 200_000);
            for i in 0..2 {
                assert!(
                    (exact[i] - reference[i]).abs() < 1e-12,
                    "{exact:?} vs {reference:?}"
                );
            }
        }
        // Without a reachable wall, iterate is free flight with Jacobian exp(MT).
        let it = osc.iterate([0.0, 0.0]);
        assert_eq!(it.impacts, 0);
        assert_eq!(it.status, ExactStatus::Ok);
        assert_eq!(it.state, osc.free_flight(0.0, [0.0, 0.0], period));
        assert_eq!(it.jacobian, osc.flow_matrix(period));
    }

    #[test]
    fn free_flight_other_damping_regimes_match_rk4() {
        for zeta in [1.0, 1.0 + 1e-9, 3.0] {
            let osc = oscillator(zeta, 1.0, 0.8, 1e9, 1.0);
            let exact = osc.free_flight(0.3, [0.5, 1.0], 6.0);
            let reference = rk4(&osc, 0.3, [0.5, 1.0], 6.0, 200_000);
            for i in 0..2 {
                assert!((exact[i] - reference[i]).abs() < 1e-12, "ζ={zeta}");
            }
        }
    }

    #[test]
    fn saltation_determinant_is_e_squared() {
        for e in [1.0, 0.8, 0.3] {
            let osc = oscillator(0.05, 1.0, 0.8, 2.0, e);
            for (t, v) in [(0.3, 1.0), (2.0, 0.01), (5.0, 3.0)] {
                let s = osc.saltation(t, v);
                assert!((s.determinant() - e * e).abs() < 1e-15);
                // The off-diagonal entry against its definition.
                let a_minus = osc.acceleration(t, [2.0, v]);
                let a_plus = osc.acceleration(t, [2.0, -e * v]);
                let entry = (a_plus + e * a_minus) / v;
                assert!((s[(1, 0)] - entry).abs() <= 1e-13 * entry.abs().max(1.0));
            }
        }
    }

    /// Central differences of `iterate(..).state` against its Jacobian.
    fn check_jacobian(osc: &ForcedImpactOscillator, y: [f64; 2]) -> ExactIteration {
        let it = osc.iterate(y);
        assert_eq!(it.status, ExactStatus::Ok);
        let delta = 1e-6;
        let scale = it.jacobian.abs().max();
        for j in 0..2 {
            let (mut plus, mut minus) = (y, y);
            plus[j] += delta;
            minus[j] -= delta;
            let (ip, im) = (osc.iterate(plus), osc.iterate(minus));
            assert_eq!(ip.impacts, it.impacts, "perturbation changed the impacts");
            assert_eq!(im.impacts, it.impacts, "perturbation changed the impacts");
            for i in 0..2 {
                let fd = (ip.state[i] - im.state[i]) / (2.0 * delta);
                let err = (fd - it.jacobian[(i, j)]).abs();
                assert!(
                    err <= 1e-6 * scale.max(1.0),
                    "J[{i},{j}] = {} vs finite difference {fd} (η = {}, e = {})",
                    it.jacobian[(i, j)],
                    osc.eta,
                    osc.restitution
                );
            }
        }
        it
    }

    #[test]
    fn jacobian_matches_finite_differences() {
        for (eta, e) in [(0.8, 1.0), (0.95, 1.0), (1.1, 1.0), (0.8, 0.8), (1.1, 0.8)] {
            let osc = oscillator(0.05, 1.0, eta, 2.0, e);
            let y = transient(&osc, 200);
            let it = check_jacobian(&osc, y);
            assert!(it.impacts >= 1, "η = {eta}, e = {e}: no impacts");
            assert!(it.min_impact_velocity > 1e-3);
            assert_eq!(it.grazing, 0);
        }
    }

    #[test]
    fn jacobian_matches_finite_differences_overdamped() {
        // Overdamped (ζ = 3, κ ≈ 2.8), three impacts per period.
        let osc = oscillator(3.0, 10.0, 0.8, 1.5, 0.8);
        let y = transient(&osc, 30);
        let it = check_jacobian(&osc, y);
        assert_eq!(it.impacts, 3);
        // Critically damped.
        let osc = oscillator(1.0, 5.0, 0.8, 1.5, 0.9);
        let y = transient(&osc, 30);
        let it = check_jacobian(&osc, y);
        assert!(it.impacts >= 1);
    }

    #[test]
    fn determinant_of_jacobian() {
        for (eta, e) in [(0.8, 0.8), (1.1, 0.8), (0.95, 0.5), (0.8, 1.0)] {
            let osc = oscillator(0.05, 1.0, eta, 2.0, e);
            let mut y = [0.0, 0.0];
            let mut seen_impacts = 0;
            for _ in 0..100 {
                let it = osc.iterate(y);
                assert_eq!(it.status, ExactStatus::Ok);
                let expected =
                    (-2.0 * osc.zeta * osc.period()).exp() * e.powi(2 * it.impacts as i32);
                let det = it.jacobian.determinant();
                assert!(
                    (det - expected).abs() <= 1e-10 * expected,
                    "η={eta} e={e}: det {det} vs {expected} ({} impacts)",
                    it.impacts
                );
                seen_impacts += it.impacts;
                y = it.state;
            }
            assert!(seen_impacts >= 50);
        }
    }

    /// The time and height of the highest point of the free flight from y0
    /// over one period (which must be an interior maximum).
    fn free_maximum(osc: &ForcedImpactOscillator, y0: [f64; 2]) -> (f64, f64) {
        let period = osc.period();
        let n = 4000;
        let h = period / n as f64;
        let mut best = (0.0, f64::NEG_INFINITY);
        for k in 0..=n {
            let t = k as f64 * h;
            let x = osc.free_flight(0.0, y0, t)[0];
            if x > best.1 {
                best = (t, x);
            }
        }
        // Bisection on V around the best sample.
        let (mut lo, mut hi) = (best.0 - h, best.0 + h);
        assert!(osc.free_flight(0.0, y0, lo)[1] > 0.0 && osc.free_flight(0.0, y0, hi)[1] < 0.0);
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if osc.free_flight(0.0, y0, mid)[1] > 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let x = osc.free_flight(0.0, y0, lo)[0].max(osc.free_flight(0.0, y0, hi)[0]);
        (lo, x)
    }

    /// Starts whose free flight has a single clear maximum in the period
    /// (every other point at least 1.3 lower).
    const ONE_MAXIMUM: [(f64, [f64; 2]); 3] =
        [(1.1, [-3.0, 0.0]), (0.8, [-2.0, -2.0]), (1.1, [-1.0, 1.0])];

    #[test]
    fn near_grazing_is_resolved() {
        for (eta, y0) in ONE_MAXIMUM {
            let free = oscillator(0.05, 1.0, eta, 1e9, 1.0);
            let (t_max, x_max) = free_maximum(&free, y0);
            let acc = free.acceleration(t_max, free.free_flight(0.0, y0, t_max));
            assert!(acc < -0.1);
            for gap in [1e-5, 1e-8, 1e-10, 1e-13] {
                for e in [1.0, 0.5] {
                    let miss = oscillator(0.05, 1.0, eta, x_max + gap, e).iterate(y0);
                    assert_eq!(miss.impacts, 0, "gap +{gap}, η={eta}");
                    assert_eq!(miss.status, ExactStatus::Ok);
                    assert_eq!(miss.state, free.iterate(y0).state);

                    let hit = oscillator(0.05, 1.0, eta, x_max - gap, e).iterate(y0);
                    assert_eq!(hit.impacts, 1, "gap -{gap}, η={eta}");
                    assert_eq!(hit.status, ExactStatus::Ok);
                    assert_eq!(hit.grazing, 0);
                    // Energy: v⁻ ≈ √(2|X''|·gap) at the crossing.
                    let v = (2.0 * acc.abs() * gap).sqrt();
                    assert!(
                        (hit.min_impact_velocity / v - 1.0).abs() < 0.02,
                        "gap -{gap}: v⁻ = {} vs {v}",
                        hit.min_impact_velocity
                    );
                }
            }
        }
    }

    #[test]
    fn impact_is_located_to_machine_precision() {
        let (eta, y0) = ONE_MAXIMUM[0];
        let wall = 2.0;
        let osc = oscillator(0.05, 1.0, eta, wall, 1.0);
        let it = osc.iterate(y0);
        assert_eq!(it.impacts, 1);
        // Find the crossing independently, by bisection on the free flight
        // below its maximum, and continue the reflected motion from it.
        let free = oscillator(0.05, 1.0, eta, 1e9, 1.0);
        let (mut lo, mut hi) = (0.0, free_maximum(&free, y0).0);
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if free.free_flight(0.0, y0, mid)[0] < wall {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let y = free.free_flight(0.0, y0, hi);
        assert!((y[0] - wall).abs() < 1e-15);
        let end = free.free_flight(hi, [wall, -y[1]], osc.period());
        for i in 0..2 {
            assert!(
                (it.state[i] - end[i]).abs() < 1e-13,
                "{:?} vs {end:?}",
                it.state
            );
        }
        assert!((it.min_impact_velocity - y[1]).abs() < 1e-13);
    }

    /// One period by 100k RK4 steps, with a contact inside a step located by
    /// bisection on the RK4 sub-step: an independent (slow) reference.
    fn rk4_with_impacts(osc: &ForcedImpactOscillator, y0: [f64; 2]) -> ([f64; 2], u32) {
        let n = 100_000;
        let h = osc.period() / n as f64;
        let mut y = y0;
        let mut impacts = 0;
        for k in 0..n {
            let t = k as f64 * h;
            let next = rk4(osc, t, y, t + h, 1);
            if next[0] <= osc.wall {
                y = next;
                continue;
            }
            let (mut lo, mut hi) = (0.0, h);
            for _ in 0..100 {
                let mid = 0.5 * (lo + hi);
                if rk4(osc, t, y, t + mid, 1)[0] > osc.wall {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            let contact = rk4(osc, t, y, t + hi, 1);
            impacts += 1;
            let reflected = [osc.wall, -osc.restitution * contact[1]];
            y = rk4(osc, t + hi, reflected, t + h, 1);
        }
        (y, impacts)
    }

    #[test]
    fn impacting_periods_match_rk4_with_event_location() {
        let cases = [
            // η = 1.25 from rest settles on an impacting period-1 orbit that
            // coexists with the non-impacting one (amplitude 1.74 < X_w).
            (
                0.05,
                1.0,
                1.25,
                2.0,
                1.0,
                [1.2922725999892106, 2.9074656537817396],
            ),
            (0.05, 1.0, 0.8, 2.0, 0.8, [-3.0, 1.0]),
            (0.05, 1.0, 1.1, 1.5, 0.6, [-1.0, 1.0]),
            (
                3.0,
                10.0,
                0.8,
                1.5,
                0.8,
                [-0.058659165449897716, 1.6940667365178181],
            ),
        ];
        for (zeta, f, eta, wall, e, y0) in cases {
            let osc = oscillator(zeta, f, eta, wall, e);
            let it = osc.iterate(y0);
            let (reference, impacts) = rk4_with_impacts(&osc, y0);
            assert_eq!(it.status, ExactStatus::Ok);
            assert_eq!(it.impacts, impacts);
            assert!(impacts >= 1);
            for i in 0..2 {
                assert!(
                    (it.state[i] - reference[i]).abs() < 1e-10,
                    "ζ={zeta} η={eta}: {:?} vs {reference:?}",
                    it.state
                );
            }
        }
    }

    #[test]
    fn contraction_without_impacts() {
        // η = 1.5 settles without impacts from rest; η = 1.25 from rest finds
        // an impacting orbit, so it starts on the non-impacting one (the
        // particular solution, |X_p| ≤ 1.74 < X_w = 2).
        for (eta, settle) in [(1.5, true), (1.25, false)] {
            let osc = oscillator(0.05, 1.0, eta, 2.0, 1.0);
            let period = osc.period();
            let mut y = if settle {
                transient(&osc, 200)
            } else {
                let model = Model::new(&osc);
                let (x, v) = model.particular(0.0);
                [x, v]
            };
            let rate = (-osc.zeta * period).exp();
            // Accumulated QR of the Jacobians gives both Lyapunov exponents.
            let mut q = Matrix2::<f64>::identity();
            let mut sums = [0.0; 2];
            let iterations = 1000;
            for _ in 0..iterations {
                let it = osc.iterate(y);
                assert_eq!(it.impacts, 0);
                for lambda in it.jacobian.complex_eigenvalues().iter() {
                    assert!((lambda.norm() / rate - 1.0).abs() < 1e-12);
                }
                let qr = (it.jacobian * q).qr();
                let r = qr.r();
                sums[0] += r[(0, 0)].abs().ln();
                sums[1] += r[(1, 1)].abs().ln();
                q = qr.q();
                y = it.state;
            }
            for s in sums {
                let exponent = s / (iterations as f64 * period);
                assert!((exponent + osc.zeta).abs() < 1e-3, "{exponent}");
            }
            let total = (sums[0] + sums[1]) / (iterations as f64 * period);
            assert!((total + 2.0 * osc.zeta).abs() < 1e-12, "{total}");
        }
    }

    #[test]
    fn heavy_damping_iterates() {
        let zeta = 200.0;
        // Wall out of reach: the period map is the free flight.
        let free = oscillator(zeta, 1.0, 0.8, 1.0, 1.0);
        let y0 = [-0.5, 3.0];
        let it = free.iterate(y0);
        assert_eq!((it.status, it.impacts), (ExactStatus::Ok, 0));
        assert_eq!(it.state, free.free_flight(0.0, y0, free.period()));
        assert_eq!(it.jacobian, free.flow_matrix(free.period()));
        // X_p ≈ (f/2ζη) sin ηt reaches 3.1e-3, pressing the mass against a wall
        // at 1e-3: it impacts and then chatters (finite result, early stop).
        // at 1e-3: it impacts, the bounces accumulate and it sticks (the
        // state then forgets its start: rank 0).
        let pressed = oscillator(zeta, 1.0, 0.8, 1e-3, 0.7).iterate([0.0, 0.0]);
        assert!(pressed.impacts >= 1);
        assert_eq!(pressed.status, ExactStatus::Ok);
        assert_eq!(pressed.rank_loss, 2);
        assert_eq!(pressed.time, free.period());
        assert!(pressed.state.iter().all(|x| x.is_finite()));
        assert_eq!(pressed.jacobian, Matrix2::zeros());
    }

    #[test]
    fn sticking_and_accumulating_impacts_end_at_rest() {
        // X_w = -2: the force -X_w + f cos ηt ≥ 1 always pushes into the
        // wall: the mass sticks for the rest of the period and never leaves.
        let stick = oscillator(0.05, 1.0, 0.8, -2.0, 0.0).iterate([-3.0, 0.0]);
        assert_eq!(stick.status, ExactStatus::Ok);
        assert_eq!((stick.impacts, stick.rank_loss), (1, 2));
        assert_eq!(stick.state, [-2.0, 0.0]);
        assert_eq!(stick.time, TAU / 0.8);

        // e = 0.5: a Zeno sequence of bounces, then the same rest.
        let chatter = oscillator(0.05, 1.0, 0.8, -2.0, 0.5).iterate([-3.0, 0.0]);
        assert_eq!(chatter.status, ExactStatus::Ok);
        assert_eq!(chatter.rank_loss, 2);
        assert!(chatter.impacts > 10 && chatter.impacts < 100);
        assert_eq!(chatter.state, [-2.0, 0.0]);

        // f = 3 > X_w = 2 presses only while cos ηt > 2/3: stuck on the
        // wall at ηt = 0, the mass leaves at ηt = arccos(2/3).
        let osc = oscillator(0.05, 3.0, 0.8, 2.0, 0.5);
        assert!((osc.release_after(0.0) - (2.0_f64 / 3.0).acos() / 0.8).abs() < 1e-9);
        // Released already this period: the next release is a period on.
        let next = ((2.0_f64 / 3.0).acos() + TAU) / 0.8;
        assert!((osc.release_after(2.0) - next).abs() < 1e-9);

        // Elastic: bounces all period long but completes it.
        let bounce = oscillator(0.05, 1.0, 0.8, -2.0, 1.0).iterate([-3.0, 0.0]);
        assert_eq!(bounce.status, ExactStatus::Ok);
        assert!(bounce.impacts >= 2);
        assert!(bounce.state[0] <= -2.0);
    }

    #[test]
    fn start_on_the_wall() {
        let osc = oscillator(0.05, 1.0, 0.8, 2.0, 0.8);
        // Moving into the wall: immediate impact at t = 0.
        let it = osc.iterate([2.0, 0.5]);
        assert!(it.impacts >= 1);
        assert_eq!(it.min_impact_velocity, 0.5);
        // Moving away: the start itself is no impact.
        let away = osc.iterate([2.0, -0.5]);
        let free = oscillator(0.05, 1.0, 0.8, 1e9, 0.8);
        assert_eq!(away.impacts, 0);
        assert_eq!(away.state, free.iterate([2.0, -0.5]).state);
    }
}
