//! Exact propagator of a piecewise-linear, harmonically forced system
//!
//! ```text
//! y' = A_r y + c_r + p_r cos ωt + q_r sin ωt      in region r,
//! h_j(y) = n_j·y − d_j                            surface j,
//! ```
//!
//! with its exact tangent map: the general form of the ground truth that
//! [`closed_form`](super::closed_form) is for the seed oscillator alone. A
//! surface either *switches* the field (region r has bit j set where
//! h_j > 0; the fields are indexed by those bits) or is an *event*: the
//! motion is confined to h_j ≤ 0 and, reaching h_j = 0 from below, is
//! reset, y ↦ R_j y + s_j (a stop: v ↦ −e v). One iteration is one period
//! of the stroboscopic map in local time t ∈ [0, T], the forcing phase ωt
//! restarting at 0.
//!
//! **Flow.** Between crossings the field is linear; appending the forcing
//! coordinates w = (1, cos ωt, sin ωt), whose norm is √2 for ever, makes it
//! homogeneous (Van Loan, "Computing integrals involving the matrix
//! exponential", IEEE TAC 23, 1978):
//!
//! ```text
//! z = [y; w],   z' = B z,   B = [[A, c, p, q],
//!                                [0, 0, 0, 0 ],
//!                                [0, 0, 0, −ω],
//!                                [0, 0, ω, 0 ]],   z(t0 + s) = exp(B s) z(t0),
//! ```
//!
//! exact for any A (singular, resonant with ω, unstable), and the top-left
//! block of exp(B s) is exp(A s), the flow matrix of the tangent map. Every
//! point of a segment is computed from the segment's start, so rounding does
//! not accumulate along the search.
//!
//! **Crossings.** The scan watches linear functions of z, g = σ k·z, with
//! σ = ±1 chosen so that a crossing is g reaching 0 from below: each
//! surface (k = [n; −d; 0; 0]) and, while sliding, the two stick margins
//! (below). A scan certified by a bound L ≥ |g'''| over each step (see
//! [`PiecewiseLinear::iterate`]) cannot step over a near-grazing approach,
//! and each root is refined by safeguarded Newton, g' = σ k·B z, to machine
//! precision. The earliest crossing over all of them is taken.
//!
//! **Tangent map.** The product of flow matrices and saltation matrices
//! (Müller, "Calculation of Lyapunov exponents for dynamic systems with
//! discontinuities", Chaos Solitons Fractals 5, 1995; Leine & Nijmeijer,
//! *Dynamics and Bifurcations of Non-Smooth Mechanical Systems*, 2004, §3.3):
//!
//! ```text
//! event:  S = R + (F⁺ − R F⁻) nᵀ / (n·F⁻),   F⁺ the field at R y⁻ + s,
//! switch: S = I + (F⁺ − F⁻) nᵀ / (n·F⁻),     F⁺ the new region's field at y⁻,  det S = n·F⁺ / n·F⁻.
//! ```
//!
//! **Sliding.** On a switch built with [`LinearSurface::sliding_switch`],
//! with the rates a = n·F_lo and b = n·F_hi of the fields on its two sides
//! (bit cleared, bit set), the mean rate m = (a + b)/2 and the limit L (the
//! switch's stick limit, else Filippov's half jump (a − b)/2), the motion
//! slides on the surface while both margins L − m and L + m are positive,
//! and leaves towards + when L − m reaches 0, towards − when L + m does:
//! the CPU integrator's rule (`surface::stick_margins`). It is propagated
//! exactly where the jump F_hi − F_lo = Δ is a constant vector (A, p, q
//! equal on both sides, only c differs: dry friction μ sign(slip)). Then
//! Filippov's field F_lo + α Δ, α = a/(a − b) = −a/(n·Δ), is
//!
//! ```text
//! F_s = P F_lo = P F_hi,   P = I − Δ nᵀ/(n·Δ)   (the projection along Δ onto n·y = const),
//! ```
//!
//! linear in z again, B_s = [[P A, P c, P p, P q], ...], and the margins
//! L ∓ m are linear functions of z (m = n·M_lo z + (n·Δ)/2 with M_lo the
//! top rows of B_lo; L a constant times the coordinate 1), which the same
//! scan watches. The tangent map through a sliding phase is
//!
//! ```text
//! S_out · exp(P A s) · S_in,   S_in  = I + (F_s − F⁻) nᵀ/(n·F⁻)          (det 0: n·F_s = 0),
//!                              S_out = I + (F⁺ − F_s) k_yᵀ/(dq/dt),
//! ```
//!
//! S_in the saltation onto the sliding field, S_out that of the exit on the
//! margin q = k·z that reaches 0 (k_y its gradient in y, dq/dt = k·B_s z
//! its full rate, forcing included: the exit time's sensitivity, di Bernardo
//! et al., *Piecewise-smooth Dynamical Systems*, 2008, §7.2). A sliding
//! phase forgets the distance to the surface: the map loses a rank
//! ([`PiecewiseIteration::rank_loss`]). Sliding is reported and not
//! propagated ([`PiecewiseStatus::Sliding`]) on a plain
//! [`LinearSurface::switch`], where the jump is not constant, where the jump
//! is not attracting (n·Δ ≥ 0), and where the sliding motion meets another
//! surface (motion on two surfaces at once).
//!
//! **Sticking on a stop.** On a stop (an event x_i = d whose reset reverses
//! the velocity x_v, x_i' = x_v: `PiecewiseLinear::stop_of`), a mass that
//! arrives at rest pressed into it, or ends an accumulating (Zeno)
//! sequence of bounces there, is held (`Mode::Held`): the region's field
//! with x_v's row removed, linear again, while the pressing force
//! σ·F_v (a linear function of z) stays positive; the scan watches it and
//! the mass leaves from rest where it falls to 0 (taken just past the
//! root, where the force pulls away by a margin, as the closed form does).
//! The hold forgets x_i and x_v (S_in zeroes their rows and columns; the
//! other states' rows of the held field are the free field's, so the
//! arrival time moves them only at second order): two exponents -∞, as on
//! the RK4 path (`impact::stuck_step`). A contact without approach right
//! after a release (the force pulling away is tiny there) is read as the
//! mass at rest: held again if pressed, else moving on. Sticking on an
//! event that is not a stop is not propagated: the iteration stops and
//! says so.

use nalgebra::{DMatrix, DVector};
use std::f64::consts::SQRT_2;
use std::sync::Arc;

/// Crossings allowed in one period, over all surfaces, before the iteration
/// is abandoned with [`PiecewiseStatus::Chattering`].
pub const MAX_CROSSINGS_PER_PERIOD: u32 = 10_000;

/// A crossing whose approach rate n·F⁻ (towards the surface) is below this
/// fraction of |n|·|F⁻| is grazing ([`PiecewiseStatus::Grazing`]): the
/// saltation matrix grows like 1/(n·F⁻), so the Jacobian is dominated by
/// rounding. For the seed oscillator |n|·|F⁻| ≈ |X''| ≈ 1, which makes this
/// the closed form's `GRAZING_VELOCITY`.
pub const GRAZING_RATE: f64 = 1e-12;

/// Scan steps allowed in one period (a guard against pathological
/// near-tangencies; a normal period needs a few dozen per surface).
const MAX_SCAN_STEPS: u32 = 1_000_000;

/// Largest scan step, as a fraction of the span. The scan is certified for
/// any step; this only keeps the first trial of each step sensible.
const H_MAX_FRACTION: f64 = 0.25;

/// Smallest scan step, as a fraction of the span: below it the scan stops
/// halving and decides from the values at both ends (a contact missed there
/// would be L h³/6 deep, ~1e-36 of the span's scale).
const H_MIN_FRACTION: f64 = 1e-12;

/// A bounce off an event surface whose predicted flight 2|g'|/g'' is shorter
/// than this fraction of the span is the tail of an accumulating (Zeno)
/// sequence of events.
const CHATTER_TIME_FRACTION: f64 = 1e-11;

/// So is a bounce whose height g'²/(2g'') is below this many ulps of the
/// surface's scale |d| + |n||y|.
const CHATTER_HEIGHT_ULPS: f64 = 64.0;

/// The two sides of a sliding switch count as one field plus a constant
/// jump when A, p and q agree to this many ulps of their size (the model
/// side builds them by evaluating expressions, which may round the two
/// sides differently).
const JUMP_ULPS: f64 = 64.0;

/// Iterations of the root refinement (it converges in a handful).
const MAX_REFINE: usize = 200;

/// Forcing coordinates appended to the state: 1, cos ωt, sin ωt.
const FORCING: usize = 3;

/// One region's field: y' = A y + c + p cos ωt + q sin ωt.
#[derive(Clone, Debug, PartialEq)]
pub struct LinearField {
    /// A, N×N.
    pub a: DMatrix<f64>,
    /// c.
    pub constant: DVector<f64>,
    /// p, the amplitude of cos ωt.
    pub cos: DVector<f64>,
    /// q, the amplitude of sin ωt.
    pub sin: DVector<f64>,
}

impl LinearField {
    /// y' = A y + c + p cos ωt + q sin ωt.
    pub fn new(
        a: DMatrix<f64>,
        constant: DVector<f64>,
        cos: DVector<f64>,
        sin: DVector<f64>,
    ) -> Self {
        LinearField {
            a,
            constant,
            cos,
            sin,
        }
    }

    /// An unforced field y' = A y + c.
    pub fn autonomous(a: DMatrix<f64>, constant: DVector<f64>) -> Self {
        let n = a.nrows();
        LinearField::new(a, constant, DVector::zeros(n), DVector::zeros(n))
    }

    /// The state dimension N.
    pub fn dimension(&self) -> usize {
        self.a.nrows()
    }

    /// F(t, y) = A y + c + p cos ωt + q sin ωt.
    pub fn eval(&self, omega: f64, t: f64, y: &DVector<f64>) -> DVector<f64> {
        let (sin, cos) = (omega * t).sin_cos();
        self.at_phase(cos, sin, y)
    }

    /// F at the forcing phase (cos ωt, sin ωt).
    fn at_phase(&self, cos: f64, sin: f64, y: &DVector<f64>) -> DVector<f64> {
        &self.a * y + &self.constant + &self.cos * cos + &self.sin * sin
    }

    /// The augmented generator B of z = [y; 1; cos ωt; sin ωt] (module docs).
    pub fn augmented(&self, omega: f64) -> DMatrix<f64> {
        let n = self.dimension();
        let mut b = DMatrix::zeros(n + FORCING, n + FORCING);
        b.view_mut((0, 0), (n, n)).copy_from(&self.a);
        b.view_mut((0, n), (n, 1)).copy_from(&self.constant);
        b.view_mut((0, n + 1), (n, 1)).copy_from(&self.cos);
        b.view_mut((0, n + 2), (n, 1)).copy_from(&self.sin);
        // cos' = −ω sin, sin' = ω cos.
        b[(n + 1, n + 2)] = -omega;
        b[(n + 2, n + 1)] = omega;
        b
    }
}

/// What a switch does where both fields point into it (or its stick limit
/// holds the motion on it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SlidingRule {
    /// Not propagated: the iteration stops with
    /// [`PiecewiseStatus::Sliding`] at the arrival. The default of
    /// [`LinearSurface::switch`], so that a caller who has not said which
    /// limit holds (a model with static friction above kinetic) is not
    /// given Filippov's silently.
    Stop,
    /// Slides while both margins L ∓ m are positive, L = Filippov's
    /// (a − b)/2, or `stick_limit` where given (module docs).
    Slide {
        /// L, a constant (static friction); None for Filippov's.
        stick_limit: Option<f64>,
    },
}

/// What happens where a surface's h crosses zero.
#[derive(Clone, Debug, PartialEq)]
pub enum SurfaceKind {
    /// The field switches across the surface; no reset. Region bit j is 1
    /// where h_j > 0 (j counting the switches only, in order).
    Switch {
        /// Sliding on it: propagated, or reported.
        sliding: SlidingRule,
    },
    /// An event: fires when h crosses 0 from below (the motion is confined
    /// to h ≤ 0) and maps y ↦ reset·y + shift (a stop: v ↦ −e v).
    Event {
        /// R, N×N: the Jacobian of the reset.
        reset: DMatrix<f64>,
        /// s.
        shift: DVector<f64>,
    },
}

impl SurfaceKind {
    fn is_switch(&self) -> bool {
        matches!(self, SurfaceKind::Switch { .. })
    }
}

/// A surface h(y) = normal·y − offset (linear in the state, not in time).
#[derive(Clone, Debug, PartialEq)]
pub struct LinearSurface {
    /// n = ∇h.
    pub normal: DVector<f64>,
    /// d.
    pub offset: f64,
    /// Switch or event.
    pub kind: SurfaceKind,
}

impl LinearSurface {
    /// A switching surface n·y = d on which sliding is reported, not
    /// propagated ([`SlidingRule::Stop`]).
    pub fn switch(normal: DVector<f64>, offset: f64) -> Self {
        LinearSurface {
            normal,
            offset,
            kind: SurfaceKind::Switch {
                sliding: SlidingRule::Stop,
            },
        }
    }

    /// A switching surface n·y = d on which the motion slides (Filippov's
    /// rule with `stick_limit` None, else held while |m| < stick_limit).
    pub fn sliding_switch(normal: DVector<f64>, offset: f64, stick_limit: Option<f64>) -> Self {
        LinearSurface {
            normal,
            offset,
            kind: SurfaceKind::Switch {
                sliding: SlidingRule::Slide { stick_limit },
            },
        }
    }

    /// An event surface n·y = d, confining the motion to n·y ≤ d, with reset
    /// y ↦ R y + s.
    pub fn event(
        normal: DVector<f64>,
        offset: f64,
        reset: DMatrix<f64>,
        shift: DVector<f64>,
    ) -> Self {
        LinearSurface {
            normal,
            offset,
            kind: SurfaceKind::Event { reset, shift },
        }
    }

    /// h(y) = n·y − d.
    pub fn value(&self, y: &DVector<f64>) -> f64 {
        self.normal.dot(y) - self.offset
    }

    /// h as a function of z: [n; −d; 0; 0].
    fn augmented(&self) -> DVector<f64> {
        let n = self.normal.len();
        let mut k = DVector::zeros(n + FORCING);
        k.rows_mut(0, n).copy_from(&self.normal);
        k[n] = -self.offset;
        k
    }
}

/// A system that cannot be propagated, with the numbers that say why.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PiecewiseError {
    /// The fields are not one per region.
    #[error("{switches} switching surfaces make {expected} regions, but {got} fields were given")]
    FieldCount {
        switches: usize,
        expected: usize,
        got: usize,
    },
    /// More switching surfaces than region indices can hold.
    #[error("{switches} switching surfaces: at most {max} are supported")]
    TooManySwitches { switches: usize, max: usize },
    /// A matrix or vector does not match the state dimension.
    #[error("{what} is {got}, but the state has dimension {dimension}")]
    Shape {
        what: String,
        dimension: usize,
        got: String,
    },
    /// A coefficient, ω, an offset or a stick limit is NaN or infinite.
    #[error("{what} is not finite")]
    NotFinite { what: String },
}

/// How an iteration ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PiecewiseStatus {
    /// The span was completed; state and Jacobian are those at its end
    /// (sliding phases included).
    Ok,
    /// Crossings accumulated (more than [`MAX_CROSSINGS_PER_PERIOD`], or a
    /// bounce off an event surface below the time or position resolution,
    /// the tail of a Zeno sequence), or the scan exhausted its step budget:
    /// stopped at [`PiecewiseIteration::time`].
    Chattering,
    /// A crossing approached the surface at a rate |n·F⁻| below
    /// [`GRAZING_RATE`]·|n||F⁻|: the state is right but the tangent map is
    /// not to be trusted (it may be huge). The span was completed, unless the
    /// rate was not positive at all (a tangency lost in rounding, where no
    /// saltation matrix exists): then it stopped at the crossing.
    Grazing,
    /// Sliding that is not propagated: at a switch whose rule is
    /// [`SlidingRule::Stop`], whose jump is not a constant attracting vector
    /// (stopped at the arrival, before the switch), or a sliding motion
    /// meeting another surface (stopped there, still sliding).
    Sliding,
    /// After an event the state is on the surface with zero rate n·F⁺ = 0
    /// (a reset to rest, e = 0), pressed into it by the field: it would stick.
    /// Not propagated; stopped after the reset.
    Sticking,
    /// The state left the floating-point range.
    Diverged,
}

/// The result of one iteration.
#[derive(Clone, Debug)]
pub struct PiecewiseIteration {
    /// y at the end of the span (at [`Self::time`] when stopped early).
    pub state: DVector<f64>,
    /// The region of the final state (while sliding, the side it arrived
    /// from).
    pub region: usize,
    /// The switch the final state slides on, if any.
    pub sliding: Option<usize>,
    /// The exact tangent map ∂state/∂y(t0) = Φ_k S_k ··· S_1 Φ_0, Φ the flow
    /// matrices exp(A_r Δt) (exp(P A Δt) while sliding) of the segments, S
    /// the saltation matrices.
    pub jacobian: DMatrix<f64>,
    /// Crossings of each surface (switches in either direction, arrivals
    /// on a switch that start a sliding phase, events); a departure from
    /// sliding is not counted, as on the CPU path.
    pub crossings: Vec<u32>,
    /// How the iteration ended.
    pub status: PiecewiseStatus,
    /// Σ ln|det S| over the crossings: −∞ after a singular reset (e = 0);
    /// NaN once the motion has slid, where the volume law does not apply
    /// (the CPU path's `log_flux` likewise).
    pub log_det_saltation: f64,
    /// Directions the tangent map collapsed: 1 after a sliding phase or a
    /// singular reset, else 0 (as the CPU path's `rank_loss`).
    pub rank_loss: u32,
    /// Σ tr(A) Δt over the segments (tr(P A) while sliding): with
    /// [`Self::log_det_saltation`], ln|det J| by Liouville's formula, the
    /// sum of the exponents.
    pub trace_integral: f64,
    /// Smallest approach rate |n·F⁻| of the crossings (∞ without any).
    pub min_crossing_rate: f64,
    /// Local time reached: the span's end unless stopped early.
    pub time: f64,
}

/// What a watched function of z is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Watch {
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
struct Watched {
    what: Watch,
    /// k, of length N + 3.
    k: DVector<f64>,
    /// σ: g rises through 0 at a crossing.
    sign: f64,
    /// An event surface (confining: bounces and sticking apply).
    event: bool,
    /// (|r_y|, √2 |r_w|) with [r_y; r_w] = (Bᵀ)³ k, so that
    /// |g'''| = |r_y·y + r_w·w| ≤ |r_y||y| + √2 |r_w|.
    jerk: (f64, f64),
}

/// The linear flow of one mode (a region, or sliding on a switch) with the
/// functions its scan watches and their bounds.
#[derive(Clone, Debug)]
struct Dynamics {
    /// B, the augmented generator.
    b: DMatrix<f64>,
    /// tr of B's state block.
    trace: f64,
    /// max(μ₂(A), 0), μ₂ the logarithmic 2-norm λ_max((A + Aᵀ)/2), A the
    /// state block of B.
    growth: f64,
    /// √2 |[c p q]|_F ≥ |c + p cos + q sin|.
    drive: f64,
    watch: Vec<Watched>,
}

/// What a segment integrates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Mode {
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

/// A piecewise-linear, harmonically forced system with its surfaces.
#[derive(Clone, Debug)]
pub struct PiecewiseLinear {
    omega: f64,
    fields: Vec<LinearField>,
    surfaces: Vec<LinearSurface>,
    /// The region bit of each surface (None for events).
    bits: Vec<Option<u32>>,
    regions: Vec<Arc<Dynamics>>,
}

/// The scan's settings for one span.
#[derive(Clone, Copy, Debug)]
struct Span {
    end: f64,
    h_max: f64,
    h_min: f64,
    chatter_time: f64,
}

/// A segment: the flow of one mode from (t0, y0).
#[derive(Clone, Debug)]
struct Segment {
    t0: f64,
    mode: Mode,
    dynamics: Arc<Dynamics>,
    /// z(t0) = [y0; 1; cos ωt0; sin ωt0].
    z0: DVector<f64>,
}

/// A point of a segment, with what the scan needs of every watched function.
#[derive(Clone, Debug)]
struct Point {
    t: f64,
    y: DVector<f64>,
    /// F(t, y) of the segment's mode.
    field: DVector<f64>,
    /// g_i, g_i', g_i''.
    g: Vec<f64>,
    g1: Vec<f64>,
    g2: Vec<f64>,
}

/// What ended a scan of a segment.
enum Next {
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
    /// Validates the shapes (2^switches fields, one per region, indexed by
    /// the bits of the switches in the order they appear in `surfaces`;
    /// every vector and matrix N-dimensional) and precomputes the bounds of
    /// the certified scan.
    pub fn new(
        omega: f64,
        fields: Vec<LinearField>,
        surfaces: Vec<LinearSurface>,
    ) -> Result<Self, PiecewiseError> {
        if !omega.is_finite() {
            return Err(PiecewiseError::NotFinite { what: "ω".into() });
        }
        let switches = surfaces.iter().filter(|s| s.kind.is_switch()).count();
        const MAX_SWITCHES: usize = 16;
        if switches > MAX_SWITCHES {
            return Err(PiecewiseError::TooManySwitches {
                switches,
                max: MAX_SWITCHES,
            });
        }
        let expected = 1 << switches;
        if fields.len() != expected {
            return Err(PiecewiseError::FieldCount {
                switches,
                expected,
                got: fields.len(),
            });
        }
        let n = fields[0].dimension();
        let square = |what: String, m: &DMatrix<f64>| {
            if m.shape() != (n, n) {
                return Err(PiecewiseError::Shape {
                    what,
                    dimension: n,
                    got: format!("{}×{}", m.nrows(), m.ncols()),
                });
            }
            finite(what, m.iter())
        };
        let vector = |what: String, v: &DVector<f64>| {
            if v.len() != n {
                return Err(PiecewiseError::Shape {
                    what,
                    dimension: n,
                    got: format!("of length {}", v.len()),
                });
            }
            finite(what, v.iter())
        };
        for (r, field) in fields.iter().enumerate() {
            square(format!("field {r}: A"), &field.a)?;
            vector(format!("field {r}: constant"), &field.constant)?;
            vector(format!("field {r}: cos"), &field.cos)?;
            vector(format!("field {r}: sin"), &field.sin)?;
        }
        for (j, surface) in surfaces.iter().enumerate() {
            vector(format!("surface {j}: normal"), &surface.normal)?;
            finite(format!("surface {j}: offset"), [surface.offset].iter())?;
            match &surface.kind {
                SurfaceKind::Event { reset, shift } => {
                    square(format!("surface {j}: reset"), reset)?;
                    vector(format!("surface {j}: shift"), shift)?;
                }
                SurfaceKind::Switch {
                    sliding:
                        SlidingRule::Slide {
                            stick_limit: Some(limit),
                        },
                } => finite(format!("surface {j}: stick limit"), [*limit].iter())?,
                SurfaceKind::Switch { .. } => {}
            }
        }
        let mut next_bit = 0;
        let bits: Vec<Option<u32>> = surfaces
            .iter()
            .map(|s| match s.kind {
                SurfaceKind::Switch { .. } => {
                    next_bit += 1;
                    Some(next_bit - 1)
                }
                SurfaceKind::Event { .. } => None,
            })
            .collect();
        let regions = fields
            .iter()
            .enumerate()
            .map(|(r, field)| {
                let watch = surfaces
                    .iter()
                    .enumerate()
                    .map(|(j, s)| (Watch::Surface(j), s.augmented(), side_sign(bits[j], r)))
                    .collect();
                let event = |w: Watch| match w {
                    Watch::Surface(j) => bits[j].is_none(),
                    Watch::Margin { .. } | Watch::Release => false,
                };
                Arc::new(dynamics(field.augmented(omega), watch, event))
            })
            .collect();
        Ok(PiecewiseLinear {
            omega,
            fields,
            surfaces,
            bits,
            regions,
        })
    }

    /// ω of the forcing.
    pub fn omega(&self) -> f64 {
        self.omega
    }

    /// The fields, indexed by region.
    pub fn fields(&self) -> &[LinearField] {
        &self.fields
    }

    /// The surfaces.
    pub fn surfaces(&self) -> &[LinearSurface] {
        &self.surfaces
    }

    /// The state dimension N.
    pub fn dimension(&self) -> usize {
        self.fields[0].dimension()
    }

    /// Whether the motion from y0 at t = 0 can reach an event's surface:
    /// `false` only where a bound proves it never does, so that the GPU
    /// kernels may leave the impact code out (`true` when unsure: with
    /// switches, or a field that is not asymptotically stable).
    ///
    /// Before the first event the motion is the free one, y = y_p + u: the
    /// periodic response y_p(t) = y_c + a cos ωt + b sin ωt (A y_c = −c,
    /// A a − ω b = −p, ω a + A b = −q) and u' = A u. Where A is stable, the
    /// solution P > 0 of Aᵀ P + P A = −I makes uᵀ P u non-increasing, so by
    /// Cauchy–Schwarz in P's metric |n·u(t)| ≤ √(u(0)ᵀ P u(0) · nᵀ P⁻¹ n).
    /// So n·y never exceeds n·y_c + √((n·a)² + (n·b)²) + that, and a
    /// surface n·y = d beyond it is never reached. (For the seed's wall this
    /// is the energy bound |X_p| + √(u² + u'²) up to P's condition number,
    /// 1.1 at ζ = 0.05.)
    pub fn may_reach_an_event(&self, y0: &DVector<f64>) -> bool {
        if self.fields.len() != 1 || self.bits.iter().any(Option::is_some) {
            return true;
        }
        let field = &self.fields[0];
        let (a, omega) = (&field.a, self.omega);
        let n = self.dimension();
        let Some(center) = a.clone().lu().solve(&-&field.constant) else {
            return true;
        };
        let mut harmonic = DMatrix::zeros(2 * n, 2 * n);
        harmonic.view_mut((0, 0), (n, n)).copy_from(a);
        harmonic.view_mut((n, n), (n, n)).copy_from(a);
        for i in 0..n {
            harmonic[(i, n + i)] = -omega;
            harmonic[(n + i, i)] = omega;
        }
        let mut forcing = DVector::zeros(2 * n);
        forcing.rows_mut(0, n).copy_from(&-&field.cos);
        forcing.rows_mut(n, n).copy_from(&-&field.sin);
        let Some(ab) = harmonic.lu().solve(&forcing) else {
            return true;
        };
        let (cos, sin) = (ab.rows(0, n), ab.rows(n, n));
        // Aᵀ P + P A = −I as (I ⊗ Aᵀ + Aᵀ ⊗ I) vec P = −vec I (columns).
        let identity = DMatrix::<f64>::identity(n, n);
        let kron = identity.kronecker(&a.transpose()) + a.transpose().kronecker(&identity);
        let minus_identity = DVector::from_iterator(n * n, identity.iter().map(|v| -v));
        let Some(vec_p) = kron.lu().solve(&minus_identity) else {
            return true;
        };
        let p = DMatrix::from_column_slice(n, n, vec_p.as_slice());
        let p = (&p + p.transpose()) * 0.5;
        let Some(cholesky) = p.clone().cholesky() else {
            return true;
        };
        let u0 = y0 - &center - cos;
        let energy = u0.dot(&(&p * &u0));
        self.surfaces.iter().any(|surface| {
            let normal = &surface.normal;
            let reach = normal.dot(&center)
                + normal.dot(&cos).hypot(normal.dot(&sin))
                + (energy * normal.dot(&cholesky.solve(normal))).sqrt();
            // NaN counts as reachable; so does a surface within rounding.
            let beyond = reach < surface.offset - 1e-9 * (reach.abs() + surface.offset.abs());
            !beyond
        })
    }

    /// The region of y: bit k set where the k-th switch has h > 0.
    pub fn region(&self, y: &DVector<f64>) -> usize {
        self.surfaces
            .iter()
            .zip(&self.bits)
            .filter_map(|(s, bit)| bit.map(|b| ((s.value(y) > 0.0) as usize) << b))
            .sum()
    }

    /// One map iteration: from y in `region` at local time 0 over
    /// [0, period] (the forcing restarts at ωt = 0 every period).
    ///
    /// Preconditions: y is on the allowed side of every event surface
    /// (h ≤ 0; a start on one moving into it, n·F > 0, fires at t = 0), and
    /// `region` agrees with the switches' signs except on a surface itself,
    /// where it says which field the motion starts in. A start on a
    /// sliding switch (|h| within rounding) where its margins hold slides
    /// from t = 0, entered from `region`'s side (S_in applied, no crossing
    /// counted). An event exactly at the end is applied: the state returned
    /// is the post-reset one.
    ///
    /// The scan over a step [a, a+h] certifies each watched function with
    /// the cubic majorant g(a+s) ≤ g(a) + g'(a)s + g''(a)s²/2 + Ls³/6,
    /// L ≥ |g'''| on the step (as the closed form does with |X'''|).
    /// Writing g''' = r_y·y + r_w·w ([r_y; r_w] = (Bᵀ)³ σk) and bounding
    /// |y| along the step through the logarithmic norm μ = μ₂(A),
    /// d|y|/dt ≤ μ|y| + |C w|, |w| = √2:
    ///
    /// ```text
    /// |y(a+s)| ≤ e^{μ⁺s} (|y(a)| + √2 |C|_F s),   L = |r_y| max|y| + √2 |r_w|.
    /// ```
    ///
    /// A step is taken only when every function's majorant stays below 0;
    /// otherwise it is halved until each function in doubt is certified to
    /// rise through 0 once (a bracket, refined by safeguarded Newton), or
    /// until h reaches 1e-12 of the span, where the ends decide.
    pub fn iterate(&self, y: &DVector<f64>, region: usize, period: f64) -> PiecewiseIteration {
        self.iterate_span(y, region, 0.0, period)
    }

    /// [`iterate`](Self::iterate) over the part [t0, t1] of a period (a
    /// sub-map), from y at local time t0.
    ///
    /// Panics if y is not N-dimensional or `region` is not a region index
    /// (below 2^switches).
    pub fn iterate_span(
        &self,
        y: &DVector<f64>,
        region: usize,
        t0: f64,
        t1: f64,
    ) -> PiecewiseIteration {
        let n = self.dimension();
        assert_eq!(
            y.len(),
            n,
            "state of length {} for a {n}-dimensional system",
            y.len()
        );
        assert!(
            region < self.fields.len(),
            "region {region} of a system with {} regions",
            self.fields.len()
        );
        let length = t1 - t0;
        let span = Span {
            end: t1,
            h_max: H_MAX_FRACTION * length,
            h_min: H_MIN_FRACTION * length,
            chatter_time: CHATTER_TIME_FRACTION * length,
        };
        let mut jacobian = DMatrix::identity(n, n);
        let mut crossings = vec![0_u32; self.surfaces.len()];
        let mut total = 0_u32;
        let mut log_det_saltation = 0.0;
        let mut rank_loss = 0;
        let mut trace_integral = 0.0;
        let mut min_crossing_rate = f64::INFINITY;
        let mut grazing = false;
        let mut budget = MAX_SCAN_STEPS;

        let (mut segment, mut start) = match self.sliding_start(t0, y, region) {
            Ok(Some((segment, saltation))) => {
                jacobian = saltation;
                (log_det_saltation, rank_loss) = (f64::NAN, 1);
                let start = self.point(&segment, t0, segment.z0.rows(0, n).into_owned());
                (segment, start)
            }
            Ok(None) => {
                let segment = self.segment(t0, y, Mode::Region(region));
                let start = self.point(&segment, t0, y.clone());
                (segment, start)
            }
            Err(()) => {
                let segment = self.segment(t0, y, Mode::Region(region));
                let start = self.point(&segment, t0, y.clone());
                return PiecewiseIteration {
                    state: y.clone(),
                    region,
                    sliding: None,
                    jacobian,
                    crossings,
                    status: PiecewiseStatus::Sliding,
                    log_det_saltation,
                    rank_loss,
                    trace_integral,
                    min_crossing_rate,
                    time: start.t,
                };
            }
        };

        let (end, status) = loop {
            // An accumulation of impacts on a stop, or a mass arriving at
            // rest on it, pressed: held there (as on the RK4 path), where
            // the surface is a stop.
            let at_rest = |w: Option<usize>, segment: &Segment| match (segment.mode, w) {
                (Mode::Region(r), Some(w)) => match segment.dynamics.watch[w].what {
                    Watch::Surface(j) => self.stop_of(j).map(|_| (j, r)),
                    _ => None,
                },
                _ => None,
            };
            let next = self.next_crossing(&segment, start, &span, &mut budget);
            if let Next::Chattering(w, p) | Next::Sticking(w, p) = &next {
                if let Some((j, r)) = at_rest(*w, &segment) {
                    let (held, s) = self.hold(j, p);
                    let dt = p.t - segment.t0;
                    jacobian = s * self.flow(&segment.dynamics, dt) * jacobian;
                    trace_integral += segment.dynamics.trace * dt;
                    // The held motion forgets the stop's coordinate and
                    // its velocity; the volume law does not apply to it.
                    (log_det_saltation, rank_loss) = (f64::NAN, rank_loss.max(2.min(n as u32)));
                    segment = self.segment(p.t, &held, Mode::Held { event: j, sides: r });
                    start = self.point(&segment, p.t, held);
                    continue;
                }
            }
            let (w, p) = match next {
                Next::End(p) => break (p, PiecewiseStatus::Ok),
                Next::Chattering(_, p) => break (p, PiecewiseStatus::Chattering),
                Next::Sticking(_, p) => break (p, PiecewiseStatus::Sticking),
                Next::Diverged(p) => break (p, PiecewiseStatus::Diverged),
                Next::Crossing(w, p) => (w, p),
            };
            if total == MAX_CROSSINGS_PER_PERIOD {
                break (p, PiecewiseStatus::Chattering);
            }
            let watched = &segment.dynamics.watch[w];
            let gradient = watched.k.rows(0, n).into_owned();
            // k·B z, whose sign is the crossing's direction (n·F⁻ for a
            // surface); g' = σ k·B z is the approach rate, positive unless
            // the root is a tangency that rounding turned over.
            let approach = p.g1[w];
            let rate = watched.sign * approach;
            if let (Mode::Region(r), Watch::Surface(j), true) =
                (segment.mode, watched.what, approach <= 0.0)
            {
                if let Some((i, v)) = self.stop_of(j) {
                    // A stop touched without approaching it, to rounding:
                    // a mass at rest there (right after a release, where
                    // the force pulling away is tiny). Held if pressed,
                    // else it moves on from rest; nothing to reverse.
                    let mut y = p.y.clone();
                    y[i] = self.surfaces[j].offset / self.surfaces[j].normal[i];
                    y[v] = 0.0;
                    let side = self.surfaces[j].normal[i].signum();
                    let pressed = side * self.fields[r].eval(self.omega, p.t, &y)[v] > 0.0;
                    let dt = p.t - segment.t0;
                    jacobian = self.flow(&segment.dynamics, dt) * jacobian;
                    trace_integral += segment.dynamics.trace * dt;
                    let mode = if pressed {
                        let (_, s) = self.hold(j, &p);
                        jacobian = s * jacobian;
                        (log_det_saltation, rank_loss) = (f64::NAN, rank_loss.max(2.min(n as u32)));
                        Mode::Held { event: j, sides: r }
                    } else {
                        Mode::Region(r)
                    };
                    segment = self.segment(p.t, &y, mode);
                    start = self.point(&segment, p.t, y);
                    continue;
                }
            }
            if approach.is_nan() || approach <= 0.0 {
                break (p, PiecewiseStatus::Grazing);
            }
            if let Watch::Surface(_) = watched.what {
                min_crossing_rate = min_crossing_rate.min(approach);
            }
            if approach < GRAZING_RATE * gradient.norm() * p.field.norm() {
                grazing = true;
            }
            // A release from a stop is taken just past the root, where the
            // force pulls away by a margin: at the root itself the mass
            // leaves with zero speed and zero acceleration, which the scan
            // that follows would read back, to rounding, as a contact (the
            // closed form's `release_after` does the same).
            let p = match (segment.mode, watched.what) {
                (Mode::Held { event, sides }, Watch::Release) => {
                    self.released(&segment, event, sides, p)
                }
                _ => p,
            };
            // The next mode, the state there, the saltation matrix, its
            // ln|det|, and the surface just left tangentially (if any).
            let (next_mode, y_plus, saltation, log_det, leaving) =
                match (segment.mode, watched.what) {
                    (Mode::Region(r), Watch::Surface(j)) => match &self.surfaces[j].kind {
                        SurfaceKind::Switch { sliding } => {
                            let bit = self.bits[j].expect("a switch has a region bit");
                            let next_region = r ^ (1 << bit);
                            let (plus, minus) = self.stick_margins(j, r, p.t, &p.y);
                            if plus > 0.0 && minus > 0.0 && *sliding != SlidingRule::Stop {
                                // Held on the surface: it slides, where that can
                                // be propagated.
                                let Some(dynamics) = self.sliding_dynamics(j, r) else {
                                    break (p, PiecewiseStatus::Sliding);
                                };
                                let mode = Mode::Sliding {
                                    switch: j,
                                    sides: r,
                                };
                                let y_on = self.onto(j, &p.y);
                                let f_s = self.field_of(&dynamics, p.t, &y_on);
                                let s = DMatrix::identity(n, n)
                                    + (&f_s - &p.field) * gradient.transpose() / rate;
                                crossings[j] += 1;
                                rank_loss = 1;
                                (mode, y_on, s, f64::NAN, None)
                            } else {
                                let f_plus = self.fields[next_region].eval(self.omega, p.t, &p.y);
                                let onward = gradient.dot(&f_plus);
                                let carried = watched.sign * onward;
                                if carried.is_nan() || carried <= 0.0 {
                                    // The new field does not carry the state on
                                    // across: both point into the surface
                                    // (Filippov sliding, not propagated here), or
                                    // a stick limit below Filippov's lets go.
                                    break (p, PiecewiseStatus::Sliding);
                                }
                                let s = DMatrix::identity(n, n)
                                    + (&f_plus - &p.field) * gradient.transpose() / rate;
                                crossings[j] += 1;
                                // det(I + u nᵀ/(n·F⁻)) = 1 + n·u/(n·F⁻), written
                                // exactly.
                                let log_det = (onward / rate).abs().ln();
                                (Mode::Region(next_region), p.y.clone(), s, log_det, None)
                            }
                        }
                        SurfaceKind::Event { reset, shift } => {
                            let y_plus = reset * &p.y + shift;
                            let next_region = self.region_after_reset(r, &p.y, &y_plus);
                            let f_plus = self.fields[next_region].eval(self.omega, p.t, &y_plus);
                            let s =
                                reset + (&f_plus - reset * &p.field) * gradient.transpose() / rate;
                            let det = s.clone().determinant();
                            if det == 0.0 {
                                rank_loss = 1;
                            }
                            crossings[j] += 1;
                            (Mode::Region(next_region), y_plus, s, det.abs().ln(), None)
                        }
                    },
                    (Mode::Sliding { .. }, Watch::Surface(_)) => {
                        // Another surface met while sliding (a wall, a second
                        // switch): motion on two surfaces at once is not
                        // propagated.
                        break (p, PiecewiseStatus::Sliding);
                    }
                    (Mode::Held { .. }, Watch::Surface(_)) => {
                        // Another surface met while held on a stop: not
                        // propagated.
                        break (p, PiecewiseStatus::Sticking);
                    }
                    (Mode::Held { event, sides }, Watch::Release) => {
                        // The pressing force q = k·z reaches 0: the mass
                        // leaves the stop, in its region's field, from rest.
                        // Its release time moves by −k_y·δy/(dq/dt); the two
                        // fields agree there (the held one differs by the
                        // pressing force along the velocity, now 0), so the
                        // saltation is I to rounding.
                        let f_plus = self.fields[sides].eval(self.omega, p.t, &p.y);
                        let s = DMatrix::identity(n, n)
                            + (&f_plus - &p.field) * gradient.transpose() / rate;
                        (Mode::Region(sides), p.y.clone(), s, f64::NAN, Some(event))
                    }
                    (Mode::Sliding { switch, sides }, Watch::Margin { plus }) => {
                        let bit = 1 << self.bits[switch].expect("a switch has a region bit");
                        let next_region = if plus { sides | bit } else { sides & !bit };
                        let y_off = self.onto(switch, &p.y);
                        let f_plus = self.fields[next_region].eval(self.omega, p.t, &y_off);
                        // The exit on the margin q = k·z: its time moves by
                        // −k_y·δy/(dq/dt).
                        let s = DMatrix::identity(n, n)
                            + (&f_plus - &p.field) * gradient.transpose() / rate;
                        (Mode::Region(next_region), y_off, s, f64::NAN, Some(switch))
                    }
                    (Mode::Region(_), Watch::Margin { .. } | Watch::Release)
                    | (Mode::Sliding { .. }, Watch::Release)
                    | (Mode::Held { .. }, Watch::Margin { .. }) => {
                        unreachable!("margins are watched while sliding, the release while held")
                    }
                };
            let dt = p.t - segment.t0;
            jacobian = saltation * self.flow(&segment.dynamics, dt) * jacobian;
            trace_integral += segment.dynamics.trace * dt;
            log_det_saltation += log_det;
            total += 1;
            segment = self.segment(p.t, &y_plus, next_mode);
            start = self.point(&segment, p.t, y_plus);
            if let Some(j) = leaving {
                // Leaving a sliding surface tangentially (Filippov's exit,
                // where the new side's rate n·F⁺ starts at 0): rounding
                // must not read that rate as a return to the surface.
                start.g1[j] = start.g1[j].min(0.0);
            }
        };
        let dt = end.t - segment.t0;
        jacobian = self.flow(&segment.dynamics, dt) * jacobian;
        trace_integral += segment.dynamics.trace * dt;
        let status = match status {
            PiecewiseStatus::Ok if grazing => PiecewiseStatus::Grazing,
            s => s,
        };
        let (region, sliding, state) = match segment.mode {
            Mode::Region(r) | Mode::Held { sides: r, .. } => (r, None, end.y),
            Mode::Sliding { switch, sides } => (sides, Some(switch), self.onto(switch, &end.y)),
        };
        PiecewiseIteration {
            state,
            region,
            sliding,
            jacobian,
            crossings,
            status,
            log_det_saltation,
            rank_loss,
            trace_integral,
            min_crossing_rate,
            time: end.t,
        }
    }

    /// A start on a sliding switch: the sliding segment and the saltation
    /// S_in onto it from `region`'s field; None where the start does not
    /// slide; Err where it would slide on a switch (or several) where that
    /// is not propagated.
    #[allow(clippy::type_complexity)]
    fn sliding_start(
        &self,
        t0: f64,
        y: &DVector<f64>,
        region: usize,
    ) -> Result<Option<(Segment, DMatrix<f64>)>, ()> {
        let mut held = self.surfaces.iter().enumerate().filter(|(j, s)| {
            matches!(
                s.kind,
                SurfaceKind::Switch {
                    sliding: SlidingRule::Slide { .. }
                }
            ) && s.value(y).abs() <= self.resolution(&s.augmented(), y)
                && {
                    let (plus, minus) = self.stick_margins(*j, region, t0, y);
                    plus > 0.0 && minus > 0.0
                }
        });
        let Some((j, surface)) = held.next() else {
            return Ok(None);
        };
        if held.next().is_some() {
            return Err(());
        }
        let dynamics = self.sliding_dynamics(j, region).ok_or(())?;
        let n = self.dimension();
        let y_on = self.onto(j, y);
        let f_s = self.field_of(&dynamics, t0, &y_on);
        // From the given side's field, or the other's where that one runs
        // along the surface (a stick limit holding a motion whose field
        // has no rate).
        let bit = 1 << self.bits[j].expect("a switch has a region bit");
        let mut f_in = self.fields[region].eval(self.omega, t0, &y_on);
        if surface.normal.dot(&f_in) == 0.0 {
            f_in = self.fields[region ^ bit].eval(self.omega, t0, &y_on);
        }
        let rate = surface.normal.dot(&f_in);
        let s = DMatrix::identity(n, n) + (f_s - f_in) * surface.normal.transpose() / rate;
        let mode = Mode::Sliding {
            switch: j,
            sides: region,
        };
        let segment = Segment {
            t0,
            mode,
            dynamics: Arc::new(dynamics),
            z0: augment(&y_on, self.omega, t0),
        };
        Ok(Some((segment, s)))
    }

    /// The stick margins (L − m, L + m) of switch j at (t, y), the other
    /// switches' sides those of `sides` (module docs). A switch that does
    /// not slide ([`SlidingRule::Stop`]) has Filippov's, −b and a.
    fn stick_margins(&self, j: usize, sides: usize, t: f64, y: &DVector<f64>) -> (f64, f64) {
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
    fn sliding_dynamics(&self, j: usize, sides: usize) -> Option<Dynamics> {
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
    fn stop_of(&self, j: usize) -> Option<(usize, usize)> {
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
    fn held_dynamics(&self, event: usize, sides: usize) -> Dynamics {
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
    fn other_surfaces(&self, on: usize, sides: usize) -> Vec<(Watch, DVector<f64>, f64)> {
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
    fn is_event(&self, w: Watch) -> bool {
        match w {
            Watch::Surface(k) => self.bits[k].is_none(),
            Watch::Margin { .. } | Watch::Release => false,
        }
    }

    /// A mass coming to rest on stop `event` at `p`: the
    /// state put on the stop at rest (x_i = d, x_v = 0) and the saltation
    /// into the held motion, which forgets x_i and x_v (the other states'
    /// rows of the held field are the free field's, so the arrival time
    /// moves them only at second order).
    fn hold(&self, event: usize, p: &Point) -> (DVector<f64>, DMatrix<f64>) {
        let n = self.dimension();
        let (i, v) = self.stop_of(event).expect("a stop");
        let surface = &self.surfaces[event];
        let mut y = p.y.clone();
        y[i] = surface.offset / surface.normal[i];
        y[v] = 0.0;
        let mut s = DMatrix::identity(n, n);
        s[(i, i)] = 0.0;
        s[(v, v)] = 0.0;
        (y, s)
    }

    /// The release from stop `event` (region `sides`) found at `p`, moved
    /// on along the held segment until the free field's force pulls away
    /// from the stop by 1e-12 of the size of its terms, with the stop's
    /// coordinate and velocity put back exactly at rest.
    fn released(&self, segment: &Segment, event: usize, sides: usize, p: Point) -> Point {
        let (i, v) = self
            .stop_of(event)
            .expect("a held mode is entered on a stop");
        let side = self.surfaces[event].normal[i].signum();
        let row = self.regions[sides].b.row(v).transpose();
        let at_rest = |q: Point| -> (DVector<f64>, f64, f64) {
            let mut y = q.y;
            y[i] = self.surfaces[event].offset / self.surfaces[event].normal[i];
            y[v] = 0.0;
            let z = augment(&y, self.omega, q.t);
            let terms: f64 = row.iter().zip(z.iter()).map(|(a, b)| (a * b).abs()).sum();
            (y, side * row.dot(&z), 1e-12 * terms)
        };
        let (mut t, mut nudge) = (p.t, 4.0 * f64::EPSILON * p.t.abs().max(1.0));
        let (mut y, mut pressing, margin) = at_rest(p);
        for _ in 0..60 {
            if pressing <= -margin {
                break;
            }
            t += nudge;
            nudge *= 2.0;
            (y, pressing, _) = at_rest(self.eval(segment, t));
        }
        self.point(segment, t, y)
    }

    /// y moved along n onto switch j's surface (a sliding state kept on it
    /// against rounding).
    fn onto(&self, j: usize, y: &DVector<f64>) -> DVector<f64> {
        let s = &self.surfaces[j];
        let h = s.value(y);
        if h == 0.0 {
            return y.clone();
        }
        y - &s.normal * (h / s.normal.norm_squared())
    }

    /// The field of `dynamics` at (t, y): the state rows of B z.
    fn field_of(&self, dynamics: &Dynamics, t: f64, y: &DVector<f64>) -> DVector<f64> {
        let n = self.dimension();
        dynamics.b.rows(0, n) * augment(y, self.omega, t)
    }

    /// The region after a reset from y⁻ to y⁺: a switch the reset moves
    /// strictly off its side (h from ≤ 0 to > 0, or from ≥ 0 to < 0: a stop
    /// reversing the velocity across a friction surface v = 0) takes the
    /// side of y⁺. A switch the reset leaves on its side keeps its bit, so
    /// that a state on a switching surface, or a rounding across it, keeps
    /// the region it was given. The RK4 path's rule (`surface::jumped`).
    fn region_after_reset(
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

    /// The top-left block of exp(B s): exp(A s), or exp(P A s) sliding.
    fn flow(&self, dynamics: &Dynamics, s: f64) -> DMatrix<f64> {
        let n = self.dimension();
        let e = (&dynamics.b * s).exp();
        e.view((0, 0), (n, n)).into_owned()
    }

    fn segment(&self, t0: f64, y0: &DVector<f64>, mode: Mode) -> Segment {
        let dynamics = match mode {
            Mode::Region(r) => self.regions[r].clone(),
            Mode::Sliding { switch, sides } => Arc::new(
                self.sliding_dynamics(switch, sides)
                    .expect("a sliding mode is entered only where it is propagated"),
            ),
            Mode::Held { event, sides } => Arc::new(self.held_dynamics(event, sides)),
        };
        Segment {
            t0,
            mode,
            dynamics,
            z0: augment(y0, self.omega, t0),
        }
    }

    /// The point of `segment` at t with state y (kept exactly as given).
    fn point(&self, segment: &Segment, t: f64, y: DVector<f64>) -> Point {
        let n = self.dimension();
        let d = &segment.dynamics;
        let z = augment(&y, self.omega, t);
        // z' = B z and z'' = B² z: the field, and the forcing's rotation.
        let bz = &d.b * &z;
        let b2z = &d.b * &bz;
        let count = d.watch.len();
        let (mut g, mut g1, mut g2) = (
            Vec::with_capacity(count),
            Vec::with_capacity(count),
            Vec::with_capacity(count),
        );
        for w in &d.watch {
            g.push(w.sign * w.k.dot(&z));
            g1.push(w.sign * w.k.dot(&bz));
            g2.push(w.sign * w.k.dot(&b2z));
        }
        Point {
            t,
            y,
            field: bz.rows(0, n).into_owned(),
            g,
            g1,
            g2,
        }
    }

    /// The point of `segment` at t, always from the segment's start.
    fn eval(&self, segment: &Segment, t: f64) -> Point {
        let n = self.dimension();
        let e = (&segment.dynamics.b * (t - segment.t0)).exp();
        let y = e.rows(0, n) * &segment.z0;
        self.point(segment, t, y)
    }

    /// L ≥ |g_i'''| on [t, t + step] along a segment of `dynamics` through
    /// y (see [`iterate`](Self::iterate)).
    fn jerk_bound(&self, dynamics: &Dynamics, i: usize, y_norm: f64, step: f64) -> f64 {
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
    fn resolution(&self, k: &DVector<f64>, y: &DVector<f64>) -> f64 {
        let n = self.dimension();
        let constant: f64 = k.rows(n, FORCING).iter().map(|x| x.abs()).sum();
        CHATTER_HEIGHT_ULPS * f64::EPSILON * (constant + k.rows(0, n).norm() * y.norm())
    }

    /// Scans `segment` from `start` for the first crossing in (start.t, end]
    /// over all watched functions (see [`iterate`](Self::iterate)).
    fn next_crossing(
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
    fn refine(&self, segment: &Segment, j: usize, mut lo: Point, mut hi: Point) -> Point {
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
    fn maximum(&self, segment: &Segment, j: usize, mut lo: Point, mut hi: Point) -> Point {
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

/// Errs on the first NaN or infinity.
fn finite<'a>(what: String, values: impl Iterator<Item = &'a f64>) -> Result<(), PiecewiseError> {
    let mut values = values;
    if values.all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(PiecewiseError::NotFinite { what })
    }
}

/// σ of switch `bit` for a motion in `region`: g = σh rises through 0 at a
/// crossing (events, bit None, are approached from below).
fn side_sign(bit: Option<u32>, region: usize) -> f64 {
    match bit {
        Some(b) if region & (1 << b) != 0 => -1.0,
        _ => 1.0,
    }
}

/// z = [y; 1; cos ωt; sin ωt].
fn augment(y: &DVector<f64>, omega: f64, t: f64) -> DVector<f64> {
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
fn dynamics(
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

/// Whether q(s) = g₀ + g₁s + g₂s²/2 + Ls³/6 < 0 for all s ∈ (0, h]: the
/// scan's test here and in `closed_form`, a non-finite q counting as not
/// certified.
///
/// A point on (or, by rounding, just beyond) the surface counts as g₀ = 0;
/// it is then certified to leave when g₁ ≤ 0 and q(s)/s = g₁ + g₂s/2 +
/// Ls²/6, a convex quadratic that starts at g₁ ≤ 0, is negative at h.
pub(super) fn certified_below(g0: f64, g1: f64, g2: f64, jerk: f64, h: f64) -> bool {
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
pub(super) fn certified_increasing(g1: f64, g2: f64, jerk: f64, h: f64) -> bool {
    g1 > 0.0 && g1 + h * (g2 - 0.5 * h * jerk) > 0.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::integrate::closed_form::{ExactStatus, ForcedImpactOscillator};
    use std::f64::consts::{PI, TAU};

    fn vector(v: &[f64]) -> DVector<f64> {
        DVector::from_column_slice(v)
    }

    fn matrix(rows: [[f64; 2]; 2]) -> DMatrix<f64> {
        DMatrix::from_row_slice(2, 2, rows.as_flattened())
    }

    /// The damped oscillator's field X'' = -2ζX' - kX + s + f cos ηt.
    fn oscillator_field(zeta: f64, stiffness: f64, constant: f64, f: f64) -> LinearField {
        LinearField::new(
            matrix([[0.0, 1.0], [-stiffness, -2.0 * zeta]]),
            vector(&[0.0, constant]),
            vector(&[0.0, f]),
            DVector::zeros(2),
        )
    }

    /// The seed oscillator X'' = -2ζX' - X + f cos ηt, X ≤ X_w, V ↦ -eV:
    /// one field, one event surface X - X_w with reset diag(1, -e).
    fn seed(zeta: f64, f: f64, eta: f64, wall: f64, e: f64) -> PiecewiseLinear {
        let stop = LinearSurface::event(
            vector(&[1.0, 0.0]),
            wall,
            matrix([[1.0, 0.0], [0.0, -e]]),
            DVector::zeros(2),
        );
        PiecewiseLinear::new(eta, vec![oscillator_field(zeta, 1.0, 0.0, f)], vec![stop]).unwrap()
    }

    /// The soft stop x'' = -2ζx' - x - k_s(x - gap)·[x > gap] + f cos ηt:
    /// two fields, one switch x - gap.
    fn soft_stop(zeta: f64, f: f64, eta: f64, ks: f64, gap: f64) -> PiecewiseLinear {
        let free = oscillator_field(zeta, 1.0, 0.0, f);
        let stiff = oscillator_field(zeta, 1.0 + ks, ks * gap, f);
        let contact = LinearSurface::switch(vector(&[1.0, 0.0]), gap);
        PiecewiseLinear::new(eta, vec![free, stiff], vec![contact]).unwrap()
    }

    /// |a - b| / max(1, scale): the error, relative where the scale is large.
    fn error(a: f64, b: f64, scale: f64) -> f64 {
        (a - b).abs() / scale.max(1.0)
    }

    #[test]
    fn a_stop_is_unreachable_only_beyond_the_free_motion_s_reach() {
        // The seed's free motion sampled over 40 periods (the closed form's
        // free flight, far wall): its largest x against the bound's verdict
        // for a stop just short of it, and the nearest stop the bound
        // calls unreachable.
        let mut decided = 0;
        for (zeta, eta) in [(0.05, 1.0), (0.05, 0.6), (0.3, 1.4), (2.0, 0.5)] {
            let free = ForcedImpactOscillator::new(zeta, 1.0, eta, 1e9, 1.0).unwrap();
            for start in [[0.0, 0.0], [3.0, -2.0], [-5.0, 4.0]] {
                let samples = 40 * 400;
                let dt = 40.0 * free.period() / samples as f64;
                let highest = (0..=samples)
                    .map(|k| free.free_flight(0.0, start, k as f64 * dt)[0])
                    .fold(f64::NEG_INFINITY, f64::max);
                let reaches =
                    |wall: f64| seed(zeta, 1.0, eta, wall, 1.0).may_reach_an_event(&vector(&start));
                // Never "unreachable" for a wall the motion reaches.
                assert!(
                    reaches(highest * (1.0 - 1e-6) - 1e-6),
                    "ζ = {zeta}, η = {eta}, {start:?}"
                );
                // And not far beyond it: the first wall found unreachable
                // (measured: 1.0 to 2.2 times the reach, and 6.5 against
                // 0.47 overdamped from (-5, 4), P's conditioning).
                let mut wall = highest.abs() * (1.0 + 1e-6) + 1e-6;
                while reaches(wall) {
                    wall *= 1.01;
                }
                let size = start[0].hypot(start[1]);
                assert!(
                    wall <= 2.5 * highest.abs() + size + 0.1,
                    "ζ = {zeta}, η = {eta}, {start:?}: reach {highest}, bound {wall}"
                );
                decided += 1;
            }
        }
        assert_eq!(decided, 12);
        // Undamped, the bound does not hold (no P): reachable, to be safe.
        assert!(seed(0.0, 1.0, 0.5, 1e6, 1.0).may_reach_an_event(&vector(&[0.0, 0.0])));
    }

    #[test]
    fn seed_oscillator_matches_closed_form() {
        let (mut worst_state, mut worst_jacobian) = (0.0_f64, 0.0_f64);
        for e in [1.0, 0.8] {
            for eta in [0.8, 1.3, 2.5, 4.0] {
                let osc = ForcedImpactOscillator::new(0.05, 1.0, eta, 2.0, e).unwrap();
                let system = seed(0.05, 1.0, eta, 2.0, e);
                let period = osc.period();
                for start in [[0.0, 3.0], [1.5, -1.0], [0.0, 0.0]] {
                    let mut y = start;
                    let mut impacts = 0;
                    // Consecutive periods of the closed form's orbit, each
                    // from the same state for both.
                    for _ in 0..20 {
                        let exact = osc.iterate(y);
                        assert_eq!(exact.status, ExactStatus::Ok);
                        let it = system.iterate(&vector(&y), 0, period);
                        assert_eq!(it.status, PiecewiseStatus::Ok, "η={eta} e={e} from {y:?}");
                        assert_eq!(
                            it.crossings,
                            vec![exact.impacts],
                            "η={eta} e={e} from {y:?}"
                        );
                        assert_eq!(it.time, period);
                        let scale = exact.state[0].abs().max(exact.state[1].abs());
                        for i in 0..2 {
                            worst_state =
                                worst_state.max(error(it.state[i], exact.state[i], scale));
                        }
                        let scale = exact.jacobian.abs().max();
                        for i in 0..2 {
                            for j in 0..2 {
                                worst_jacobian = worst_jacobian.max(error(
                                    it.jacobian[(i, j)],
                                    exact.jacobian[(i, j)],
                                    scale,
                                ));
                            }
                        }
                        // Liouville: det J = e^{-2ζT} e^{2·impacts}.
                        let expected = -2.0 * 0.05 * period + 2.0 * e.ln() * exact.impacts as f64;
                        assert!(
                            (it.trace_integral + it.log_det_saltation - expected).abs() < 1e-12
                        );
                        impacts += exact.impacts;
                        y = exact.state;
                    }
                    if start[1] == 3.0 {
                        assert!(impacts >= 1, "η={eta} e={e}: no impacts");
                    }
                }
            }
        }
        eprintln!("seed vs closed form: state {worst_state:.2e}, Jacobian {worst_jacobian:.2e}");
        assert!(worst_state <= 1e-10 && worst_jacobian <= 1e-10);
    }

    /// One period of the soft stop by n RK4 steps, each in the field of the
    /// region at its start; a step that ends across x = gap is redone to the
    /// crossing, located by bisection on the RK4 sub-step, and finished from
    /// there in the other field. Returns the end and the crossings.
    fn rk4_soft_stop(
        (zeta, f, eta, ks, gap): (f64, f64, f64, f64, f64),
        y0: [f64; 2],
        n: usize,
    ) -> ([f64; 2], u32) {
        let rhs = |t: f64, y: [f64; 2], stiff: bool| {
            let spring = if stiff { ks * (y[0] - gap) } else { 0.0 };
            [
                y[1],
                -2.0 * zeta * y[1] - y[0] - spring + f * (eta * t).cos(),
            ]
        };
        let step = |t: f64, y: [f64; 2], h: f64, stiff: bool| {
            let add = |y: [f64; 2], k: [f64; 2], s: f64| [y[0] + s * k[0], y[1] + s * k[1]];
            let k1 = rhs(t, y, stiff);
            let k2 = rhs(t + 0.5 * h, add(y, k1, 0.5 * h), stiff);
            let k3 = rhs(t + 0.5 * h, add(y, k2, 0.5 * h), stiff);
            let k4 = rhs(t + h, add(y, k3, h), stiff);
            std::array::from_fn(|i| y[i] + h / 6.0 * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i]))
        };
        let h = TAU / eta / n as f64;
        let (mut y, mut stiff, mut crossings) = (y0, y0[0] > gap, 0);
        for k in 0..n {
            let t = k as f64 * h;
            let next = step(t, y, h, stiff);
            if (next[0] > gap) == stiff {
                y = next;
                continue;
            }
            let (mut lo, mut hi) = (0.0, h);
            for _ in 0..100 {
                let mid = 0.5 * (lo + hi);
                if (step(t, y, mid, stiff)[0] > gap) == stiff {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            let contact = step(t, y, hi, stiff);
            stiff = !stiff;
            crossings += 1;
            y = step(t + hi, contact, h - hi, stiff);
        }
        (y, crossings)
    }

    /// Central differences (δ = 1e-6) of `iterate(..).state` against its
    /// Jacobian; returns the worst error relative to max(1, |J|).
    fn finite_difference_error(
        system: &PiecewiseLinear,
        y: &DVector<f64>,
        region: usize,
        period: f64,
    ) -> f64 {
        let it = system.iterate(y, region, period);
        let delta = 1e-6;
        let scale = it.jacobian.abs().max();
        let mut worst = 0.0_f64;
        for j in 0..y.len() {
            let (mut plus, mut minus) = (y.clone(), y.clone());
            plus[j] += delta;
            minus[j] -= delta;
            let (ip, im) = (
                system.iterate(&plus, region, period),
                system.iterate(&minus, region, period),
            );
            assert_eq!(
                ip.crossings, it.crossings,
                "perturbation changed the crossings"
            );
            assert_eq!(
                im.crossings, it.crossings,
                "perturbation changed the crossings"
            );
            for i in 0..y.len() {
                let fd = (ip.state[i] - im.state[i]) / (2.0 * delta);
                worst = worst.max(error(fd, it.jacobian[(i, j)], scale));
            }
        }
        worst
    }

    #[test]
    fn soft_stop_matches_rk4_and_finite_differences() {
        let (zeta, f, ks, gap) = (0.05, 1.0, 20.0, 1.0);
        let (mut worst_state, mut worst_fd, mut worst_det) = (0.0_f64, 0.0_f64, 0.0_f64);
        for eta in [0.8, 1.3, 2.5] {
            let system = soft_stop(zeta, f, eta, ks, gap);
            let period = TAU / eta;
            let mut y = vector(&[0.0, 2.0]);
            let mut region = system.region(&y);
            let mut crossings = 0;
            for _ in 0..6 {
                let it = system.iterate(&y, region, period);
                assert_eq!(it.status, PiecewiseStatus::Ok);
                let (reference, rk4_crossings) =
                    rk4_soft_stop((zeta, f, eta, ks, gap), [y[0], y[1]], 200_000);
                assert_eq!(it.crossings, vec![rk4_crossings], "η={eta}");
                for (x, r) in it.state.iter().zip(reference) {
                    worst_state = worst_state.max((x - r).abs());
                }
                worst_fd = worst_fd.max(finite_difference_error(&system, &y, region, period));
                // Continuous field: det S = n·F⁺/n·F⁻ = v/v = 1, and
                // ln|det J| = ∫ tr A = -2ζT.
                assert_eq!(it.log_det_saltation, 0.0);
                let log_det = it.jacobian.determinant().abs().ln();
                worst_det = worst_det
                    .max((log_det - (it.trace_integral + it.log_det_saltation)).abs())
                    .max((it.trace_integral + 2.0 * zeta * period).abs());
                crossings += it.crossings[0];
                (y, region) = (it.state, it.region);
            }
            assert!(crossings >= 4, "η={eta}: {crossings} crossings");
        }
        eprintln!(
            "soft stop: state vs RK4 {worst_state:.2e}, Jacobian vs FD {worst_fd:.2e}, \
             ln det {worst_det:.2e}"
        );
        assert!(worst_state <= 1e-9);
        assert!(worst_fd <= 1e-6);
        assert!(worst_det <= 1e-10);
    }

    /// Dry friction x'' = -x - μ sign(v): region 0 (v ≤ 0) has +μ, region 1
    /// (v > 0) has -μ; one switch v = 0.
    fn dry_friction(mu: f64) -> PiecewiseLinear {
        let a = matrix([[0.0, 1.0], [-1.0, 0.0]]);
        let backward = LinearField::autonomous(a.clone(), vector(&[0.0, mu]));
        let forward = LinearField::autonomous(a, vector(&[0.0, -mu]));
        let v = LinearSurface::switch(vector(&[0.0, 1.0]), 0.0);
        PiecewiseLinear::new(1.0, vec![backward, forward], vec![v]).unwrap()
    }

    #[test]
    fn sliding_is_reported_not_propagated() {
        let system = dry_friction(0.5);
        // |x| < μ at v = 0: the backward field pushes v up (-x + μ > 0), the
        // forward one down (-x - μ < 0): both into v = 0.
        let y = vector(&[0.2, -0.1]);
        let it = system.iterate(&y, system.region(&y), TAU);
        assert_eq!(it.status, PiecewiseStatus::Sliding);
        assert_eq!(it.crossings, vec![0]);
        assert_eq!(it.region, 0);
        assert!(it.time > 0.0 && it.time < 0.5, "{}", it.time);
        assert!(it.state[1].abs() < 1e-15, "{}", it.state);

        // |x| > μ: a genuine crossing (v' = -x ∓ μ > 0 on both sides), with
        // a discontinuous field: det S = n·F⁺/n·F⁻ = (-x - μ)/(-x + μ) at
        // the crossing, where (x - μ)² + v² has kept its initial value.
        let y = vector(&[-2.0, -0.1]);
        let it = system.iterate(&y, 0, 0.5);
        assert_eq!(it.status, PiecewiseStatus::Ok);
        assert_eq!((it.crossings[0], it.region), (1, 1));
        let x = 0.5 - (2.5_f64 * 2.5 + 0.1 * 0.1).sqrt();
        let expected = ((-x - 0.5) / (-x + 0.5)).ln();
        assert!((it.log_det_saltation - expected).abs() < 1e-14);
        let log_det = it.jacobian.determinant().abs().ln();
        assert!((log_det - it.log_det_saltation).abs() < 1e-12, "tr A = 0");
        let fd = finite_difference_error(&system, &y, 0, 0.5);
        assert!(fd <= 1e-6, "{fd:e}");
    }

    /// The belt oscillator x'' = -2ζx' - x - μ sign(x' - vb) + f cos ηt:
    /// region 0 (slip v - vb < 0) has +μ, region 1 has -μ; the switch
    /// v = vb slides (Filippov's rule, or held while |m| < `limit`).
    fn belt(
        (zeta, mu, vb, f, eta): (f64, f64, f64, f64, f64),
        limit: Option<f64>,
    ) -> PiecewiseLinear {
        let field = |c: f64| oscillator_field(zeta, 1.0, c, f);
        let slip = LinearSurface::sliding_switch(vector(&[0.0, 1.0]), vb, limit);
        PiecewiseLinear::new(eta, vec![field(mu), field(-mu)], vec![slip]).unwrap()
    }

    /// One period of the belt oscillator written out as Filippov's system:
    /// off the belt, RK4 steps of T/n in the field of the side, a step that
    /// ends across v = vb redone to the crossing (bisected on the RK4
    /// sub-step); there, with the rates a = -2ζvb - x + μ + f cos ηt and
    /// b = a - 2μ, m = a - μ, L = `limit` or μ: it sticks while L ∓ m > 0,
    /// moving exactly as x' = vb, v = vb, and leaves where a margin reaches
    /// 0 (bisected on that closed form) to the side L - m ≤ 0 says.
    /// Returns the end and the arrivals at v = vb.
    fn filippov_belt(
        (zeta, mu, vb, f, eta): (f64, f64, f64, f64, f64),
        limit: Option<f64>,
        y0: [f64; 2],
        n: usize,
    ) -> ([f64; 2], u32) {
        let limit = limit.unwrap_or(mu);
        let margins = |t: f64, x: f64| {
            let m = -2.0 * zeta * vb - x + f * (eta * t).cos();
            (limit - m, limit + m)
        };
        let held = |(plus, minus): (f64, f64)| plus > 0.0 && minus > 0.0;
        let rhs = |t: f64, y: [f64; 2], hi: bool| {
            let friction = if hi { -mu } else { mu };
            [
                y[1],
                -2.0 * zeta * y[1] - y[0] + friction + f * (eta * t).cos(),
            ]
        };
        let rk4 = |t: f64, y: [f64; 2], h: f64, hi: bool| {
            let add = |y: [f64; 2], k: [f64; 2], s: f64| [y[0] + s * k[0], y[1] + s * k[1]];
            let k1 = rhs(t, y, hi);
            let k2 = rhs(t + 0.5 * h, add(y, k1, 0.5 * h), hi);
            let k3 = rhs(t + 0.5 * h, add(y, k2, 0.5 * h), hi);
            let k4 = rhs(t + h, add(y, k3, h), hi);
            std::array::from_fn(|i| y[i] + h / 6.0 * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i]))
        };
        let period = TAU / eta;
        let h = period / n as f64;
        let (mut t, mut y, mut arrivals) = (0.0, y0, 0);
        let mut sliding = (y[1] - vb).abs() <= 1e-12 && held(margins(0.0, y[0]));
        let mut hi = y[1] > vb;
        while t < period {
            let step = h.min(period - t);
            if sliding {
                let x = |s: f64| y[0] + vb * s;
                if held(margins(t + step, x(step))) {
                    (t, y) = (t + step, [x(step), vb]);
                    continue;
                }
                let (mut lo, mut up) = (0.0, step);
                for _ in 0..200 {
                    let mid = 0.5 * (lo + up);
                    if mid <= lo || mid >= up {
                        break;
                    }
                    if held(margins(t + mid, x(mid))) {
                        lo = mid;
                    } else {
                        up = mid;
                    }
                }
                let (plus, minus) = margins(t + up, x(up));
                (t, y, hi, sliding) = (t + up, [x(up), vb], plus <= minus, false);
                continue;
            }
            let next = rk4(t, y, step, hi);
            if (next[1] > vb) == hi {
                (t, y) = (t + step, next);
                continue;
            }
            let (mut lo, mut up) = (0.0, step);
            for _ in 0..200 {
                let mid = 0.5 * (lo + up);
                if mid <= lo || mid >= up {
                    break;
                }
                if (rk4(t, y, mid, hi)[1] > vb) == hi {
                    lo = mid;
                } else {
                    up = mid;
                }
            }
            let contact = rk4(t, y, up, hi);
            (t, y) = (t + up, [contact[0], vb]);
            arrivals += 1;
            if held(margins(t, y[0])) {
                sliding = true;
            } else {
                hi = !hi;
            }
        }
        (y, arrivals)
    }

    #[test]
    fn stick_slip_matches_a_filippov_reference() {
        let (zeta, mu, vb, f) = (0.05, 0.5, 0.2, 1.0);
        let mut worst = 0.0_f64;
        for limit in [None, Some(0.6)] {
            for eta in [0.3, 0.4, 0.6] {
                let system = belt((zeta, mu, vb, f, eta), limit);
                let period = TAU / eta;
                let mut y = vector(&[0.0, 0.0]);
                let mut region = system.region(&y);
                let (mut arrivals, mut slid) = (0, 0);
                for _ in 0..20 {
                    let it = system.iterate(&y, region, period);
                    assert_eq!(it.status, PiecewiseStatus::Ok, "η={eta} {limit:?}");
                    let (reference, rk4_arrivals) =
                        filippov_belt((zeta, mu, vb, f, eta), limit, [y[0], y[1]], 20_000);
                    assert_eq!(
                        it.crossings,
                        vec![rk4_arrivals],
                        "η={eta} {limit:?} from {y}"
                    );
                    let error = (it.state[0] - reference[0])
                        .abs()
                        .max((it.state[1] - reference[1]).abs());
                    worst = worst.max(error);
                    // A sliding phase in the period (or carried into it)
                    // collapses the velocity.
                    if it.rank_loss == 1 {
                        assert!(it.log_det_saltation.is_nan());
                        let scale = it.jacobian.abs().max().powi(2);
                        assert!(it.jacobian.determinant().abs() <= 1e-15 * scale);
                        slid += 1;
                    }
                    if it.sliding.is_some() {
                        assert_eq!(it.state[1], vb);
                    }
                    arrivals += it.crossings[0];
                    (y, region) = (it.state, it.region);
                }
                assert!(
                    arrivals >= 20 && slid >= 10,
                    "η={eta}: {arrivals} arrivals, {slid} slid"
                );
            }
        }
        eprintln!("stick-slip vs Filippov RK4: state {worst:.2e}");
        assert!(worst <= 1e-9, "{worst:e}");
    }

    #[test]
    fn stick_slip_jacobian_matches_finite_differences() {
        // Periods that enter and leave sliding from a start off the belt:
        // S_in, exp(P A s) and S_out against central differences.
        let (zeta, mu, vb, f) = (0.05, 0.5, 0.2, 1.0);
        let (mut checked, mut worst) = (0, 0.0_f64);
        for limit in [None, Some(0.6)] {
            for eta in [0.3, 0.4, 0.6] {
                let system = belt((zeta, mu, vb, f, eta), limit);
                let period = TAU / eta;
                let mut y = vector(&[0.0, 0.0]);
                let mut region = system.region(&y);
                for _ in 0..30 {
                    let it = system.iterate(&y, region, period);
                    let off = (y[1] - vb).abs() > 1e-3;
                    if off && it.rank_loss == 1 && it.sliding.is_none() {
                        let fd = finite_difference_error(&system, &y, region, period);
                        assert!(fd <= 1e-6, "η={eta} {limit:?} from {y}: {fd:e}");
                        (checked, worst) = (checked + 1, worst.max(fd));
                    }
                    (y, region) = (it.state, it.region);
                }
            }
        }
        eprintln!("stick-slip Jacobian vs FD: {worst:.2e} over {checked} periods");
        assert!(checked >= 5, "{checked} periods checked");
    }

    /// λ1 of the belt oscillator from the exact Jacobians, per unit time:
    /// QR once a period over `iterations` periods after `transient`, Q
    /// restarting from I (the CPU path's protocol). Also the state reached.
    fn belt_exponent(
        eta: f64,
        transient: usize,
        iterations: usize,
    ) -> (f64, f64, DVector<f64>, usize) {
        let system = belt((0.05, 0.5, 0.2, 1.0, eta), None);
        let period = TAU / eta;
        let mut y = vector(&[0.0, 0.0]);
        let mut region = system.region(&y);
        let mut q = DMatrix::identity(2, 2);
        let mut logs = [0.0; 2];
        for k in 0..transient + iterations {
            let it = system.iterate(&y, region, period);
            assert_eq!(it.status, PiecewiseStatus::Ok, "η={eta}, period {k}");
            if k >= transient {
                let qr = (&it.jacobian * &q).qr();
                let r = qr.r();
                q = qr.q();
                for (i, l) in logs.iter_mut().enumerate() {
                    *l += r[(i, i)].abs().ln();
                }
            }
            (y, region) = (it.state, it.region);
        }
        let total = iterations as f64 * period;
        (logs[0] / total, logs[1] / total, y, region)
    }

    #[test]
    fn stick_slip_exponents() {
        // The CPU path's λ1 (lyapsweep's FD method, Filippov's rule, 200 +
        // 300 periods), converged in its step and δ to 1e-8.
        for (eta, cpu) in [(0.3, -0.0983497), (0.4, -0.0562861), (0.6, -0.2395735)] {
            let (l1, l2, y, region) = belt_exponent(eta, 200, 300);
            // Sticking collapses the velocity once a period: λ2 = -∞.
            assert_eq!(l2, f64::NEG_INFINITY);
            assert!(
                (l1 - cpu).abs() <= 1e-6,
                "η={eta}: exact {l1} against the CPU's {cpu}"
            );
            // The orbit has settled on a periodic one (p periods), whose
            // Jacobian over p periods has rank 1: its one nonzero
            // eigenvalue, the trace, gives λ1 for an infinite window. A
            // window of W periods from Q = I differs from it by
            // ln(|Π J e1| / |tr Π J|) / (W T) at most, the start vector's
            // share, which does not vanish for W = 300.
            let system = belt((0.05, 0.5, 0.2, 1.0, eta), None);
            let period = TAU / eta;
            let (mut z, mut r, mut product, mut p) =
                (y.clone(), region, DMatrix::identity(2, 2), 0);
            loop {
                let it = system.iterate(&z, r, period);
                product = &it.jacobian * product;
                (z, r, p) = (it.state, it.region, p + 1);
                if (&z - &y).norm() <= 1e-12 || p == 8 {
                    break;
                }
            }
            assert!((&z - &y).norm() <= 1e-12, "η={eta}: no period up to 8");
            assert!(product.rank(1e-12 * product.abs().max()) == 1);
            let limit = product.trace().abs().ln() / (p as f64 * period);
            let start = (product.column(0).norm() / product.trace().abs()).ln();
            eprintln!(
                "η={eta}: exact λ1 = {l1:.9} (200 + 300 periods, Q from I; CPU {cpu}), \
                 {limit:.9} on the period-{p} orbit (start vector's share {:.2e})",
                start / (300.0 * period)
            );
            assert!((l1 - limit - start / (300.0 * period)).abs() <= 1e-9);
        }
    }

    #[test]
    fn sticking_for_good_keeps_the_position_and_forgets_the_velocity() {
        // vb = 0 and |x| < μ - f: the spring and the forcing never overcome
        // friction (|-x + f cos ηt| < μ), so the mass never moves.
        let (zeta, mu, f, eta) = (0.05, 0.5, 0.2, 0.8);
        let system = belt((zeta, mu, 0.0, f, eta), None);
        let period = TAU / eta;
        for region in [0, 1] {
            let y = vector(&[0.1, 0.0]);
            let it = system.iterate(&y, region, period);
            assert_eq!(it.status, PiecewiseStatus::Ok);
            assert_eq!((it.crossings[0], it.sliding, it.rank_loss), (0, Some(0), 1));
            assert!(
                (it.state[0] - 0.1).abs() <= 1e-14 && it.state[1] == 0.0,
                "{}",
                it.state
            );
            // (x, v) ↦ (x, 0): rank 1.
            let expected = matrix([[1.0, 0.0], [0.0, 0.0]]);
            assert!(
                (&it.jacobian - expected).abs().max() <= 1e-14,
                "{}",
                it.jacobian
            );
            assert_eq!(it.jacobian.rank(1e-12), 1);
        }
        // Arriving from a slip: one crossing, then stuck where it arrived.
        let it = system.iterate(&vector(&[0.1, -0.05]), 0, period);
        assert_eq!(it.status, PiecewiseStatus::Ok);
        assert_eq!((it.crossings[0], it.sliding, it.rank_loss), (1, Some(0), 1));
        assert_eq!(it.state[1], 0.0);
        let again = system.iterate(&it.state, it.region, period);
        assert!((&again.state - &it.state).norm() <= 1e-14);
        assert_eq!(again.jacobian.rank(1e-12), 1);
    }

    #[test]
    fn sliding_that_cannot_be_propagated_is_reported() {
        // A jump with a y-dependent part (friction proportional to x):
        // F_hi - F_lo is not constant, so the sliding field is not linear.
        let a = matrix([[0.0, 1.0], [-1.0, 0.0]]);
        let lo = LinearField::autonomous(a.clone(), vector(&[0.0, 0.5]));
        let hi = LinearField::autonomous(matrix([[0.0, 1.0], [-1.5, 0.0]]), vector(&[0.0, -0.5]));
        let v = LinearSurface::sliding_switch(vector(&[0.0, 1.0]), 0.0, None);
        let system = PiecewiseLinear::new(1.0, vec![lo, hi], vec![v]).unwrap();
        let it = system.iterate(&vector(&[0.2, -0.1]), 0, TAU);
        assert_eq!((it.status, it.crossings[0]), (PiecewiseStatus::Sliding, 0));
        // Sliding into a wall: two surfaces at once.
        let field = |c: f64| oscillator_field(0.05, 1.0, c, 0.2);
        let slip = LinearSurface::sliding_switch(vector(&[0.0, 1.0]), 0.3, None);
        let wall = LinearSurface::event(
            vector(&[1.0, 0.0]),
            0.2,
            matrix([[1.0, 0.0], [0.0, -0.5]]),
            DVector::zeros(2),
        );
        let system =
            PiecewiseLinear::new(0.8, vec![field(0.5), field(-0.5)], vec![slip, wall]).unwrap();
        let it = system.iterate(&vector(&[0.0, 0.3]), 0, TAU / 0.8);
        assert_eq!(it.status, PiecewiseStatus::Sliding);
        assert_eq!(it.sliding, Some(0));
        assert!(
            (it.state[0] - 0.2).abs() < 1e-12 && it.time < 1.0,
            "{} at {}",
            it.state,
            it.time
        );
    }

    /// The time and height of the highest point of the seed's free flight
    /// from y0 over one period (an interior maximum), from the closed form.
    fn free_maximum(eta: f64, y0: [f64; 2]) -> (f64, f64) {
        let free = ForcedImpactOscillator::new(0.05, 1.0, eta, 1e9, 1.0).unwrap();
        let n = 4000;
        let h = free.period() / n as f64;
        let mut best = (0.0, f64::NEG_INFINITY);
        for k in 0..=n {
            let t = k as f64 * h;
            let x = free.free_flight(0.0, y0, t)[0];
            if x > best.1 {
                best = (t, x);
            }
        }
        let (mut lo, mut hi) = (best.0 - h, best.0 + h);
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if free.free_flight(0.0, y0, mid)[1] > 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let x = free.free_flight(0.0, y0, lo)[0].max(free.free_flight(0.0, y0, hi)[0]);
        (lo, x)
    }

    #[test]
    fn near_grazing_is_not_stepped_over() {
        // Starts whose free flight has one clear maximum in the period.
        for (eta, y0) in [(1.1, [-3.0, 0.0]), (0.8, [-2.0, -2.0]), (1.1, [-1.0, 1.0])] {
            let period = TAU / eta;
            let (_, x_max) = free_maximum(eta, y0);
            let y = vector(&y0);
            let free = seed(0.05, 1.0, eta, 1e9, 1.0).iterate(&y, 0, period);
            for gap in [1e-5, 1e-9, 1e-12, 1e-13] {
                // h = x - X_w peaks at -gap: no event.
                let miss = seed(0.05, 1.0, eta, x_max + gap, 1.0).iterate(&y, 0, period);
                assert_eq!(miss.crossings, vec![0], "gap +{gap}, η={eta}");
                assert_eq!(miss.status, PiecewiseStatus::Ok);
                assert_eq!(miss.state, free.state);
                // Peaks at +gap: one event, approached at v⁻ ≈ √(2|X''|gap).
                let hit = seed(0.05, 1.0, eta, x_max - gap, 1.0).iterate(&y, 0, period);
                assert_eq!(hit.crossings, vec![1], "gap -{gap}, η={eta}");
                assert_eq!(hit.status, PiecewiseStatus::Ok);
                let t_max = free_maximum(eta, y0).0;
                let osc = ForcedImpactOscillator::new(0.05, 1.0, eta, 1e9, 1.0).unwrap();
                let acc = osc.acceleration(t_max, osc.free_flight(0.0, y0, t_max));
                let v = (2.0 * acc.abs() * gap).sqrt();
                assert!(
                    (hit.min_crossing_rate / v - 1.0).abs() < 0.02,
                    "gap -{gap}: v⁻ = {} vs {v}",
                    hit.min_crossing_rate
                );
                // The same surface as a switch between two equal fields:
                // in and out again, or not at all.
                for (wall, expected) in [(x_max + gap, 0), (x_max - gap, 2)] {
                    let field = oscillator_field(0.05, 1.0, 0.0, 1.0);
                    let switch = LinearSurface::switch(vector(&[1.0, 0.0]), wall);
                    let system =
                        PiecewiseLinear::new(eta, vec![field.clone(), field], vec![switch])
                            .unwrap();
                    let it = system.iterate(&y, 0, period);
                    assert_eq!(it.crossings, vec![expected], "switch, gap {gap}, η={eta}");
                    assert_eq!((it.status, it.region), (PiecewiseStatus::Ok, 0));
                    assert!((&it.state - &free.state).norm() < 1e-13);
                }
            }
        }
    }

    #[test]
    fn resets_to_rest_and_accumulating_events_hold_the_mass() {
        // e = 0 with the force pulling off the wall (-X_w + f cos ηt < 0):
        // propagated, the Jacobian of rank 1 (ln det S = -∞), as the
        // closed form has it.
        let eta = 0.8;
        let osc = ForcedImpactOscillator::new(0.05, 1.0, eta, 2.0, 0.0).unwrap();
        let system = seed(0.05, 1.0, eta, 2.0, 0.0);
        let y = [0.0, 3.0];
        let (exact, it) = (osc.iterate(y), system.iterate(&vector(&y), 0, osc.period()));
        assert_eq!((exact.status, exact.rank_loss), (ExactStatus::Ok, 1));
        assert_eq!(it.status, PiecewiseStatus::Ok);
        assert_eq!(it.crossings, vec![exact.impacts]);
        assert_eq!(it.log_det_saltation, f64::NEG_INFINITY);
        for i in 0..2 {
            assert!((it.state[i] - exact.state[i]).abs() < 1e-13);
            for j in 0..2 {
                assert!((it.jacobian[(i, j)] - exact.jacobian[(i, j)]).abs() < 1e-12);
            }
        }
        // X_w = -2: the force -X_w + f cos ηt ≥ 1 presses into the wall for
        // ever. e = 0 comes to rest on it at the first contact, e = 0.5 at
        // the end of a Zeno sequence of bounces: held there to the period's
        // end (Mode::Held), the stop's coordinate and velocity forgotten,
        // as in the closed form.
        for (e, bounces) in [(0.0, 1..2), (0.5, 11..100)] {
            let held = seed(0.05, 1.0, eta, -2.0, e).iterate(&vector(&[-3.0, 0.0]), 0, TAU / eta);
            let closed = ForcedImpactOscillator::new(0.05, 1.0, eta, -2.0, e)
                .unwrap()
                .iterate([-3.0, 0.0]);
            assert_eq!(
                (held.status, held.rank_loss),
                (PiecewiseStatus::Ok, 2),
                "e = {e}"
            );
            assert_eq!(
                (closed.status, closed.rank_loss),
                (ExactStatus::Ok, 2),
                "e = {e}"
            );
            assert!(
                bounces.contains(&held.crossings[0]),
                "e = {e}: {:?}",
                held.crossings
            );
            assert_eq!((held.state[0], held.state[1]), (-2.0, 0.0), "e = {e}");
            assert_eq!(held.state.as_slice(), closed.state.as_slice(), "e = {e}");
            assert_eq!(held.time, TAU / eta);
            assert!(held.jacobian.iter().all(|&j| j == 0.0), "e = {e}");
        }
        // e = 1 bounces all period long and completes it.
        let bounce = seed(0.05, 1.0, eta, -2.0, 1.0).iterate(&vector(&[-3.0, 0.0]), 0, TAU / eta);
        assert_eq!(bounce.status, PiecewiseStatus::Ok);
        assert!(bounce.crossings[0] >= 2);
    }

    #[test]
    fn grazing_crossing_is_flagged() {
        // On the wall, moving into it at 1e-14: an event at t = 0 whose
        // saltation matrix is ~1e14. The period completes, flagged.
        let system = seed(0.05, 1.0, 0.8, 2.0, 0.8);
        let it = system.iterate(&vector(&[2.0, 1e-14]), 0, TAU / 0.8);
        assert_eq!(it.status, PiecewiseStatus::Grazing);
        assert_eq!(it.time, TAU / 0.8);
        assert_eq!(it.min_crossing_rate, 1e-14);
        // Moving away from it: no event.
        let away = system.iterate(&vector(&[2.0, -0.5]), 0, TAU / 0.8);
        assert_eq!((away.status, away.crossings[0]), (PiecewiseStatus::Ok, 0));
    }

    #[test]
    fn resets_across_a_switch_change_the_region() {
        // The seed with a switch on v = 0 between two equal fields: every
        // reset v ↦ -ev flips its region bit without a crossing, and every
        // turning point in flight crosses it. The map and its Jacobian are
        // the seed's (S = I at the switch).
        let eta = 1.3;
        let plain = seed(0.05, 1.0, eta, 2.0, 0.8);
        let mut surfaces = plain.surfaces().to_vec();
        surfaces.push(LinearSurface::switch(vector(&[0.0, 1.0]), 0.0));
        let field = plain.fields()[0].clone();
        let split = PiecewiseLinear::new(eta, vec![field.clone(), field], surfaces).unwrap();
        let period = TAU / eta;
        let mut y = vector(&[0.0, 3.0]);
        let mut region = split.region(&y);
        let (mut impacts, mut turns) = (0, 0);
        for _ in 0..10 {
            let reference = plain.iterate(&y, 0, period);
            let it = split.iterate(&y, region, period);
            assert_eq!(it.status, PiecewiseStatus::Ok);
            assert_eq!(it.crossings[0], reference.crossings[0]);
            assert!((&it.state - &reference.state).norm() < 1e-12);
            assert!((&it.jacobian - &reference.jacobian).norm() < 1e-10);
            assert_eq!(it.region, split.region(&it.state));
            impacts += it.crossings[0];
            turns += it.crossings[1];
            (y, region) = (it.state, it.region);
        }
        assert!(
            impacts >= 3 && turns >= 10,
            "{impacts} impacts, {turns} turns"
        );
    }

    #[test]
    fn resonant_and_singular_fields_are_exact() {
        // Undamped resonance x'' = -x + cos t, which the closed form cannot
        // take: x = x₀ cos t + v₀ sin t + (t/2) sin t, so one period adds
        // π to v and the flow matrix is exp(2πA) = I.
        let resonant =
            PiecewiseLinear::new(1.0, vec![oscillator_field(0.0, 1.0, 0.0, 1.0)], vec![]).unwrap();
        let it = resonant.iterate(&vector(&[0.3, -0.2]), 0, TAU);
        assert_eq!(it.status, PiecewiseStatus::Ok);
        assert!((it.state[0] - 0.3).abs() < 1e-14 && (it.state[1] - (-0.2 + PI)).abs() < 1e-14);
        assert!((it.jacobian.clone() - DMatrix::identity(2, 2)).abs().max() < 1e-14);

        // A bouncing ball x'' = -g over a floor, h = -x ≤ 0, A nilpotent
        // (A³ = 0: the bound on h''' needs no bound on |y|). Dropped from
        // rest at height H, elastic: it lands at t₁ = √(2H/g) with speed
        // v₁ = g t₁ and leaves upwards.
        let (g, height) = (9.81, 1.0);
        let ball = PiecewiseLinear::new(
            1.0,
            vec![LinearField::autonomous(
                matrix([[0.0, 1.0], [0.0, 0.0]]),
                vector(&[0.0, -g]),
            )],
            vec![LinearSurface::event(
                vector(&[-1.0, 0.0]),
                0.0,
                matrix([[1.0, 0.0], [0.0, -1.0]]),
                DVector::zeros(2),
            )],
        )
        .unwrap();
        let y = vector(&[height, 0.0]);
        let it = ball.iterate(&y, 0, 1.0);
        assert_eq!((it.status, it.crossings[0]), (PiecewiseStatus::Ok, 1));
        let t1 = (2.0 * height / g).sqrt();
        let (v1, s) = (g * t1, 1.0 - t1);
        assert!((it.state[0] - (v1 * s - 0.5 * g * s * s)).abs() < 1e-13);
        assert!((it.state[1] - (v1 - g * s)).abs() < 1e-13);
        assert!((it.min_crossing_rate - v1).abs() < 1e-13);
        // det S = 1 (e = 1, tr A = 0).
        assert!(it.log_det_saltation.abs() < 1e-14);
        assert!((it.jacobian.determinant() - 1.0).abs() < 1e-13);
        let fd = finite_difference_error(&ball, &y, 0, 1.0);
        assert!(fd <= 1e-6, "{fd:e}");
    }

    #[test]
    fn shapes_are_validated() {
        let field = oscillator_field(0.05, 1.0, 0.0, 1.0);
        let switch = LinearSurface::switch(vector(&[1.0, 0.0]), 1.0);
        assert_eq!(
            PiecewiseLinear::new(1.0, vec![field.clone()], vec![switch.clone()]).unwrap_err(),
            PiecewiseError::FieldCount {
                switches: 1,
                expected: 2,
                got: 1
            }
        );
        let wide = LinearSurface::switch(vector(&[1.0, 0.0, 0.0]), 1.0);
        assert!(matches!(
            PiecewiseLinear::new(1.0, vec![field.clone(), field.clone()], vec![wide]),
            Err(PiecewiseError::Shape { .. })
        ));
        assert!(matches!(
            PiecewiseLinear::new(f64::NAN, vec![field.clone()], vec![]),
            Err(PiecewiseError::NotFinite { .. })
        ));
        // Region bits follow the switches' order, events between them
        // taking none.
        let stop = LinearSurface::event(
            vector(&[0.0, 1.0]),
            5.0,
            DMatrix::identity(2, 2),
            DVector::zeros(2),
        );
        let other = LinearSurface::switch(vector(&[0.0, 1.0]), 0.0);
        let system = PiecewiseLinear::new(1.0, vec![field; 4], vec![switch, stop, other]).unwrap();
        assert_eq!(system.region(&vector(&[2.0, -1.0])), 0b01);
        assert_eq!(system.region(&vector(&[0.0, 1.0])), 0b10);
        assert_eq!(system.region(&vector(&[1.0, 0.0])), 0b00);
    }
}
