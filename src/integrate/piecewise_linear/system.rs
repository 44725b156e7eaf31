//! A piecewise-linear, harmonically forced system as data: its fields,
//! its surfaces, their validation, and what one iteration of it returns.
//! The propagation itself is `span`'s.

use nalgebra::{DMatrix, DVector};
use std::sync::Arc;

use super::dynamics::{dynamics, side_sign, Dynamics, Watch, FORCING};

/// Crossings allowed in one period, over all surfaces, before the iteration
/// is abandoned with [`PiecewiseStatus::TooManyCrossings`]: the RK4 path's
/// bound on located events, so that both end such a lane alike.
pub const MAX_CROSSINGS_PER_PERIOD: u32 = crate::integrate::MAX_EVENTS_PER_ITERATION;

/// A crossing whose approach rate n·F⁻ (towards the surface) is below this
/// fraction of |n|·|F⁻| is grazing ([`PiecewiseStatus::Grazing`]): the
/// saltation matrix grows like 1/(n·F⁻), so the Jacobian is dominated by
/// rounding. For the seed oscillator |n|·|F⁻| ≈ |X''| ≈ 1, which makes this
/// the closed form's `GRAZING_VELOCITY`.
pub const GRAZING_RATE: f64 = 1e-12;

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
    pub(super) fn at_phase(&self, cos: f64, sin: f64, y: &DVector<f64>) -> DVector<f64> {
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
    pub(super) fn is_switch(&self) -> bool {
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
    pub(super) fn augmented(&self) -> DVector<f64> {
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
    /// Crossings accumulated (a bounce off an event surface below the time
    /// or position resolution, the tail of a Zeno sequence), or the scan
    /// exhausted its step budget: stopped at [`PiecewiseIteration::time`].
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
    /// More than [`MAX_CROSSINGS_PER_PERIOD`] crossings in the span (energy
    /// pumped in between impacts faster than they take it out): stopped
    /// at the last; the lane ends there (`too-many-events`).
    TooManyCrossings,
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

/// A piecewise-linear, harmonically forced system with its surfaces.
#[derive(Clone, Debug)]
pub struct PiecewiseLinear {
    pub(super) omega: f64,
    pub(super) fields: Vec<LinearField>,
    pub(super) surfaces: Vec<LinearSurface>,
    /// The region bit of each surface (None for events).
    pub(super) bits: Vec<Option<u32>>,
    pub(super) regions: Vec<Arc<Dynamics>>,
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
