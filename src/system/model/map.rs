//! A compiled model as the method's [`System`]: a lane built from its
//! parameters, its maps (a period map of the flow), the exact backend's
//! propagator where it has one, and its time scales.

use nalgebra::{DVector, SMatrix};

use crate::integrate::clock::Phase;
use crate::integrate::closed_form::ExactStatus;
use crate::integrate::piecewise_linear::PiecewiseStatus;
use crate::integrate::{part_map_many, time_map, time_map_many, Surface};
use crate::model::compiled::{reads_state_or_time, walls_at};
use crate::system::{FlowSettings, IterationStats, Params, Part, System};

use super::description::{code_of, eigen_scales, wrap_angle, PILOT_PERIODS, PILOT_SAMPLES};
use super::flow::{Exact, ModelFlow};

impl<const D: usize> System<D> for ModelFlow<D> {
    fn new(p: &Params) -> Self {
        let code = code_of(p);
        ModelFlow {
            code,
            params: p.values.clone(),
            constants: code
                .regions
                .iter()
                .map(|f| f.equations.lane_values(&p.values).constants)
                .collect(),
            surface_constants: code
                .regions
                .iter()
                .map(|f| f.surfaces.lane_values(&p.values).constants)
                .collect(),
            frequency: code.frequency(&p.values),
            period: code.period(&p.values),
            walls: walls_at(code, &p.values),
            constant_gradients: code
                .surfaces
                .iter()
                .map(|s| {
                    s.gradient.iter().all(|e| !reads_state_or_time(e)).then(|| {
                        s.gradient
                            .iter()
                            .map(|e| e.eval(&[], &p.values, 0.0))
                            .collect()
                    })
                })
                .collect(),
            constant_stick_limits: code
                .surfaces
                .iter()
                .map(|s| match &s.stick_limit {
                    Some(l) if !reads_state_or_time(l) => Some(l.eval(&[], &p.values, 0.0)),
                    _ => None,
                })
                .collect(),
            exact: std::sync::OnceLock::new(),
            info: p.info,
        }
    }

    fn period(&self) -> f64 {
        self.period
    }

    fn iterate(&self, x: &[f64; D], flow: &FlowSettings, stats: &mut IterationStats) -> [f64; D] {
        time_map(self, x, self.period, flow, stats)
    }

    /// The piecewise-linear propagator's span: exact flow matrices between
    /// crossings located by a certified search, saltation matrices at them
    /// (or the seed's closed form, for its kind).
    fn iterate_exact(
        &self,
        x: &[f64; D],
        part: Part,
        stats: &mut IterationStats,
    ) -> Option<([f64; D], SMatrix<f64, D, D>)> {
        let exact = self
            .exact
            .get_or_init(|| self.exact_propagator())
            .as_ref()?;
        let (t0, t1) = part.span(self.period);
        let exact = match exact {
            Exact::PiecewiseLinear(exact) => exact,
            Exact::SeedClosedForm(closed) => {
                let it = closed.iterate_span([x[0], x[1]], t0, t1);
                stats.impacts += it.impacts;
                stats.crossings[0] += it.impacts;
                stats.rank_loss = stats.rank_loss.max(it.rank_loss);
                stats.chattering |= it.status != ExactStatus::Ok;
                let state: [f64; D] = crate::array::from_fn(|i| it.state[i]);
                return Some((state, SMatrix::from_column_slice(it.jacobian.as_slice())));
            }
        };
        let y = DVector::from_column_slice(x);
        let it = exact.iterate_span(&y, exact.region(&y), t0, t1);
        let walls = self.walls.len();
        let mut wall_log_det = 0.0;
        for (j, &c) in it.crossings.iter().enumerate() {
            stats.crossings[j] += c;
            if j < walls {
                stats.impacts += c;
                if c > 0 {
                    wall_log_det += 2.0 * f64::from(c) * self.walls[j].restitution.ln();
                }
            }
        }
        // The walls' e² per impact is in the expected sum already; the
        // general surfaces' det S goes with the orbit.
        let general = it.log_det_saltation - wall_log_det;
        if general.is_finite() {
            stats.log_flux += general;
        } else {
            stats.rank_loss = stats.rank_loss.max(1);
        }
        // Sliding forgets one direction, a mass held on a stop two.
        stats.rank_loss = stats.rank_loss.max(it.rank_loss);
        stats.slowest_impact = stats.slowest_impact.min(it.min_crossing_rate);
        match it.status {
            PiecewiseStatus::Ok => {}
            PiecewiseStatus::Sliding => stats.sliding = true,
            PiecewiseStatus::Grazing => {
                stats.grazing = true;
                stats.grazing_error = f64::INFINITY;
            }
            PiecewiseStatus::Chattering | PiecewiseStatus::Sticking => stats.chattering = true,
            PiecewiseStatus::Diverged => {}
            // Ended as the RK4 path ends a trajectory past its bound on
            // events: non-finite, flagged (the lane is `too-many-events`).
            PiecewiseStatus::TooManyCrossings => {
                stats.too_many_events = true;
                return Some(([f64::NAN; D], SMatrix::from_element(f64::NAN)));
            }
        }
        let state: [f64; D] = crate::array::from_fn(|i| it.state[i]);
        Some((state, SMatrix::from_column_slice(it.jacobian.as_slice())))
    }

    fn iterate_lanes(
        systems: &[&Self],
        xs: &mut [[f64; D]],
        flow: &FlowSettings,
        stats: &mut [IterationStats],
    ) {
        crate::system::time_map_lanes(systems, xs, flow, stats)
    }

    /// Not where [`part_many`](System::part_many) integrates a
    /// state-dependent divergence along the reference.
    fn averages_across_lanes(&self) -> bool {
        self.code.equations_divergence().is_none()
    }

    fn iterate_many(&self, ys: &mut [[f64; D]], flow: &FlowSettings, stats: &mut [IterationStats]) {
        time_map_many(self, ys, self.period, flow, stats)
    }

    fn part_many(
        &self,
        ys: &mut [[f64; D]],
        flow: &FlowSettings,
        part: Part,
        phase: &mut Phase,
        stats: &mut [IterationStats],
    ) {
        let (start, start_phase) = (ys.first().copied(), *phase);
        part_map_many(self, ys, self.period, flow, part, phase, stats);
        // A divergence that depends on the state: integrated along the
        // reference (the same steps again, alone), for the sum rule.
        if let (Some(tape), Some(start)) = (&self.code.equations_divergence(), start) {
            let h = self.period / flow.steps_per_period as f64;
            let half = crate::integrate::clock::half_turn(self.frequency, h, flow.steps_per_period);
            let steps = part.steps(flow.steps_per_period).len();
            let constants = tape.lane_values(&self.params).constants;
            let density = |phase: &Phase, y: &[f64; D]| -> f64 {
                let y: [[f64; 1]; D] = crate::array::from_fn(|i| [y[i]]);
                let out: [[f64; 1]; 1] = tape.eval(|j| [constants[j]], &[*phase], &y);
                out[0][0]
            };
            let (end, integral) = crate::integrate::advance_integrating(
                self,
                &start,
                start_phase,
                (h, half),
                steps,
                density,
                &flow.stop,
            );
            debug_assert!(flow.stop.requested() || end == ys[0]);
            stats[0].log_flux += integral;
        }
    }

    /// The largest |eigenvalue| of the Jacobian at the origin: exact for a
    /// flow linear between impacts (the seed's oscillator gives 1, as its
    /// hand-written twin does), an estimate for a nonlinear one (see
    /// `time_scales`).
    fn stiffness(&self) -> f64 {
        self.scales_at_origin().0
    }

    /// The fastest decay rate at the origin, -min Re λ (0 if none decays).
    fn contraction(&self) -> f64 {
        self.scales_at_origin().1
    }

    /// A flow whose Jacobian depends on the state (or time) has its time
    /// scales where its orbit goes, not at the origin (van der Pol's
    /// origin is unstable; it contracts on its relaxation cycle): the
    /// largest over the origin and a pilot of `PILOT_PERIODS` periods
    /// from the initial state, sampled `PILOT_SAMPLES` times a period. A
    /// constant Jacobian (a flow linear between impacts) is read at the
    /// origin alone, as [`stiffness`](System::stiffness) does.
    fn time_scales(&self, initial: &[f64], flow: &FlowSettings) -> (f64, f64) {
        let at_origin = (self.stiffness(), self.contraction());
        let constant = self
            .code
            .regions
            .iter()
            .all(|f| f.jacobian.iter().all(|e| !reads_state_or_time(e)));
        if constant || initial.len() != D {
            return at_origin;
        }
        let mut y: [f64; D] = crate::array::from_fn(|i| initial[i]);
        let mut scales = at_origin;
        let mut stats = [IterationStats::default()];
        for _ in 0..PILOT_PERIODS {
            let mut phase = crate::integrate::clock::ZERO_PHASE;
            for part in Part::all(PILOT_SAMPLES) {
                let t = self.period * part.index as f64 / PILOT_SAMPLES as f64;
                let region = crate::integrate::surface::sides(
                    crate::integrate::surface::region_of(self, &phase, &y),
                );
                let (stiffness, contraction) = eigen_scales(&self.jacobian_at(&y, t, region));
                scales = (scales.0.max(stiffness), scales.1.max(contraction));
                let mut ys = [y];
                part_map_many(
                    self,
                    &mut ys,
                    self.period,
                    flow,
                    part,
                    &mut phase,
                    &mut stats,
                );
                y = ys[0];
                if !y.iter().all(|v| v.is_finite()) {
                    return scales;
                }
            }
        }
        scales
    }

    fn admits(&self, y: &[f64; D]) -> bool {
        self.walls.iter().all(|w| w.gap(y) <= 0.0)
            && self
                .code
                .surfaces
                .iter()
                .all(|s| s.kind != Surface::Event || s.g.eval(y, &self.params, 0.0) <= 0.0)
    }

    fn wrap(&self, x: &mut [f64; D]) {
        for &i in &self.code.model.angles {
            x[i] = wrap_angle(x[i]);
        }
    }
}
