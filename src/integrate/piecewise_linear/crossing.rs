//! What a crossing found by the scan does: the mode that follows, the
//! state there and the saltation matrix that carries the tangent map
//! across (a switch's new region or the start of sliding, an event's
//! reset, the exit from sliding or from a hold), and the records of the
//! span they add to.

use nalgebra::{DMatrix, DVector};

use super::dynamics::{augment, Mode, Watch};
use super::segment::{Point, Segment};
use super::system::{
    PiecewiseIteration, PiecewiseLinear, PiecewiseStatus, SlidingRule, SurfaceKind,
};

/// The tangent map and the records of a span so far.
pub(super) struct Record {
    pub(super) jacobian: DMatrix<f64>,
    pub(super) crossings: Vec<u32>,
    /// Crossings over all surfaces.
    pub(super) total: u32,
    pub(super) log_det_saltation: f64,
    pub(super) rank_loss: u32,
    pub(super) trace_integral: f64,
    pub(super) min_crossing_rate: f64,
    /// A crossing approached its surface at a grazing rate.
    pub(super) grazing: bool,
}

impl Record {
    /// Nothing crossed yet, the tangent map the identity.
    pub(super) fn new(n: usize, surfaces: usize) -> Self {
        Record {
            jacobian: DMatrix::identity(n, n),
            crossings: vec![0_u32; surfaces],
            total: 0,
            log_det_saltation: 0.0,
            rank_loss: 0,
            trace_integral: 0.0,
            min_crossing_rate: f64::INFINITY,
            grazing: false,
        }
    }

    /// The tangent map carried along `segment` to time t.
    pub(super) fn flow_to(&mut self, system: &PiecewiseLinear, segment: &Segment, t: f64) {
        let dt = t - segment.t0;
        self.jacobian = system.flow(&segment.dynamics, dt) * std::mem::take(&mut self.jacobian);
        self.trace_integral += segment.dynamics.trace * dt;
    }

    /// The tangent map carried along `segment` to time t, then across a
    /// crossing there by `saltation`.
    pub(super) fn cross_at(
        &mut self,
        system: &PiecewiseLinear,
        segment: &Segment,
        t: f64,
        saltation: DMatrix<f64>,
    ) {
        let dt = t - segment.t0;
        self.jacobian =
            saltation * system.flow(&segment.dynamics, dt) * std::mem::take(&mut self.jacobian);
        self.trace_integral += segment.dynamics.trace * dt;
    }

    /// A mass held on a stop forgets the stop's coordinate and its
    /// velocity; the volume law does not apply to it.
    pub(super) fn forget_stop(&mut self, n: usize) {
        (self.log_det_saltation, self.rank_loss) = (f64::NAN, self.rank_loss.max(2.min(n as u32)));
    }

    /// The iteration that ends here.
    pub(super) fn finish(
        self,
        state: DVector<f64>,
        region: usize,
        sliding: Option<usize>,
        status: PiecewiseStatus,
        time: f64,
    ) -> PiecewiseIteration {
        PiecewiseIteration {
            state,
            region,
            sliding,
            jacobian: self.jacobian,
            crossings: self.crossings,
            status,
            log_det_saltation: self.log_det_saltation,
            rank_loss: self.rank_loss,
            trace_integral: self.trace_integral,
            min_crossing_rate: self.min_crossing_rate,
            time,
        }
    }
}

/// What follows a crossing.
pub(super) struct Transition {
    /// The next mode.
    pub(super) mode: Mode,
    /// The state there.
    pub(super) y: DVector<f64>,
    /// The saltation matrix.
    pub(super) saltation: DMatrix<f64>,
    /// Its ln|det|.
    pub(super) log_det: f64,
    /// The surface just left tangentially, if any.
    pub(super) leaving: Option<usize>,
}

impl PiecewiseLinear {
    /// The transition at the crossing `p` of watched function w of
    /// `segment`, approached along `gradient` at `rate` (σ k·B z before any
    /// move past the root); `Err` with the status the iteration stops with
    /// where the crossing is not propagated.
    pub(super) fn transition(
        &self,
        segment: &Segment,
        w: usize,
        p: &Point,
        gradient: &DVector<f64>,
        rate: f64,
        record: &mut Record,
    ) -> Result<Transition, PiecewiseStatus> {
        let n = self.dimension();
        let watched = &segment.dynamics.watch[w];
        match (segment.mode, watched.what) {
            (Mode::Region(r), Watch::Surface(j)) => match &self.surfaces[j].kind {
                SurfaceKind::Switch { sliding } => {
                    self.switch_crossing(r, j, *sliding, watched.sign, p, gradient, rate, record)
                }
                SurfaceKind::Event { reset, shift } => {
                    let y_plus = reset * &p.y + shift;
                    let next_region = self.region_after_reset(r, &p.y, &y_plus);
                    let f_plus = self.fields[next_region].eval(self.omega, p.t, &y_plus);
                    let s = reset + (&f_plus - reset * &p.field) * gradient.transpose() / rate;
                    let det = s.clone().determinant();
                    if det == 0.0 {
                        record.rank_loss = 1;
                    }
                    record.crossings[j] += 1;
                    Ok(Transition {
                        mode: Mode::Region(next_region),
                        y: y_plus,
                        saltation: s,
                        log_det: det.abs().ln(),
                        leaving: None,
                    })
                }
            },
            // Another surface met while sliding (a wall, a second switch):
            // motion on two surfaces at once is not propagated.
            (Mode::Sliding { .. }, Watch::Surface(_)) => Err(PiecewiseStatus::Sliding),
            // Another surface met while held on a stop: not propagated.
            (Mode::Held { .. }, Watch::Surface(_)) => Err(PiecewiseStatus::Sticking),
            (Mode::Held { event, sides }, Watch::Release) => {
                // The pressing force q = k·z reaches 0: the mass leaves the
                // stop, in its region's field, from rest. Its release time
                // moves by −k_y·δy/(dq/dt); the two fields agree there (the
                // held one differs by the pressing force along the
                // velocity, now 0), so the saltation is I to rounding.
                let f_plus = self.fields[sides].eval(self.omega, p.t, &p.y);
                let s =
                    DMatrix::identity(n, n) + (&f_plus - &p.field) * gradient.transpose() / rate;
                Ok(Transition {
                    mode: Mode::Region(sides),
                    y: p.y.clone(),
                    saltation: s,
                    log_det: f64::NAN,
                    leaving: Some(event),
                })
            }
            (Mode::Sliding { switch, sides }, Watch::Margin { plus }) => {
                let bit = 1 << self.bits[switch].expect("a switch has a region bit");
                let next_region = if plus { sides | bit } else { sides & !bit };
                let y_off = self.onto(switch, &p.y);
                let f_plus = self.fields[next_region].eval(self.omega, p.t, &y_off);
                // The exit on the margin q = k·z: its time moves by
                // −k_y·δy/(dq/dt).
                let s =
                    DMatrix::identity(n, n) + (&f_plus - &p.field) * gradient.transpose() / rate;
                Ok(Transition {
                    mode: Mode::Region(next_region),
                    y: y_off,
                    saltation: s,
                    log_det: f64::NAN,
                    leaving: Some(switch),
                })
            }
            (Mode::Region(_), Watch::Margin { .. } | Watch::Release)
            | (Mode::Sliding { .. }, Watch::Release)
            | (Mode::Held { .. }, Watch::Margin { .. }) => {
                unreachable!("margins are watched while sliding, the release while held")
            }
        }
    }

    /// A crossing of switch j from region r (`sign` its σ there): into
    /// sliding where its stick margins hold the motion and the rule
    /// propagates it, else across into the other region where the new
    /// field carries the state on.
    #[allow(clippy::too_many_arguments)]
    fn switch_crossing(
        &self,
        r: usize,
        j: usize,
        sliding: SlidingRule,
        sign: f64,
        p: &Point,
        gradient: &DVector<f64>,
        rate: f64,
        record: &mut Record,
    ) -> Result<Transition, PiecewiseStatus> {
        let n = self.dimension();
        let bit = self.bits[j].expect("a switch has a region bit");
        let next_region = r ^ (1 << bit);
        let (plus, minus) = self.stick_margins(j, r, p.t, &p.y);
        if plus > 0.0 && minus > 0.0 && sliding != SlidingRule::Stop {
            // Held on the surface: it slides, where that can be propagated.
            let Some(dynamics) = self.sliding_dynamics(j, r) else {
                return Err(PiecewiseStatus::Sliding);
            };
            let mode = Mode::Sliding {
                switch: j,
                sides: r,
            };
            let y_on = self.onto(j, &p.y);
            let f_s = self.field_of(&dynamics, p.t, &y_on);
            let s = DMatrix::identity(n, n) + (&f_s - &p.field) * gradient.transpose() / rate;
            record.crossings[j] += 1;
            record.rank_loss = 1;
            return Ok(Transition {
                mode,
                y: y_on,
                saltation: s,
                log_det: f64::NAN,
                leaving: None,
            });
        }
        let f_plus = self.fields[next_region].eval(self.omega, p.t, &p.y);
        let onward = gradient.dot(&f_plus);
        let carried = sign * onward;
        if carried.is_nan() || carried <= 0.0 {
            // The new field does not carry the state on across: both point
            // into the surface (Filippov sliding, not propagated here), or a
            // stick limit below Filippov's lets go.
            return Err(PiecewiseStatus::Sliding);
        }
        let s = DMatrix::identity(n, n) + (&f_plus - &p.field) * gradient.transpose() / rate;
        record.crossings[j] += 1;
        // det(I + u nᵀ/(n·F⁻)) = 1 + n·u/(n·F⁻), written exactly.
        let log_det = (onward / rate).abs().ln();
        Ok(Transition {
            mode: Mode::Region(next_region),
            y: p.y.clone(),
            saltation: s,
            log_det,
            leaving: None,
        })
    }

    /// The release from stop `event` (region `sides`) found at `p`, moved
    /// on along the held segment until the free field's force pulls away
    /// from the stop by 1e-12 of the size of its terms, with the stop's
    /// coordinate and velocity put back exactly at rest.
    pub(super) fn released(
        &self,
        segment: &Segment,
        event: usize,
        sides: usize,
        p: Point,
    ) -> Point {
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
}
