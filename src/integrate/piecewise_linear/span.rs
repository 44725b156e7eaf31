//! One iteration of a piecewise-linear system over a span of its period:
//! segment after segment, each scanned to its first crossing (`scan`),
//! the crossing applied (`crossing`), the tangent map and the records
//! carried along, until the span ends or the motion does something that
//! is not propagated.

use nalgebra::{DMatrix, DVector};
use std::sync::Arc;

use super::crossing::Record;
use super::dynamics::{augment, Mode, Watch};
use super::scan::{Next, Span};
use super::segment::{Point, Segment};
use super::system::{
    PiecewiseIteration, PiecewiseLinear, PiecewiseStatus, SlidingRule, SurfaceKind, GRAZING_RATE,
    MAX_CROSSINGS_PER_PERIOD,
};

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

/// Where the motion goes after a scan or a crossing.
enum Onward {
    /// On, along this segment from this point.
    Goes(Segment, Point),
    /// Nowhere: the iteration ends at this point, with this status.
    Ends(Point, PiecewiseStatus),
}

impl PiecewiseLinear {
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
        let mut record = Record::new(n, self.surfaces.len());
        let mut budget = MAX_SCAN_STEPS;
        let (mut segment, mut start) = match self.sliding_start(t0, y, region) {
            Ok(Some((segment, saltation))) => {
                record.jacobian = saltation;
                (record.log_det_saltation, record.rank_loss) = (f64::NAN, 1);
                let start = self.point(&segment, t0, segment.z0.rows(0, n).into_owned());
                (segment, start)
            }
            Ok(None) => {
                let segment = self.segment(t0, y, Mode::Region(region));
                let start = self.point(&segment, t0, y.clone());
                (segment, start)
            }
            Err(()) => {
                return record.finish(y.clone(), region, None, PiecewiseStatus::Sliding, t0);
            }
        };
        let (end, status) = loop {
            let next = self.next_crossing(&segment, start, &span, &mut budget);
            match self.after_scan(&segment, next, &mut record) {
                Onward::Goes(s, p) => (segment, start) = (s, p),
                Onward::Ends(p, status) => break (p, status),
            }
        };
        record.flow_to(self, &segment, end.t);
        let status = match status {
            PiecewiseStatus::Ok if record.grazing => PiecewiseStatus::Grazing,
            s => s,
        };
        let (region, sliding, state) = match segment.mode {
            Mode::Region(r) | Mode::Held { sides: r, .. } => (r, None, end.y),
            Mode::Sliding { switch, sides } => (sides, Some(switch), self.onto(switch, &end.y)),
        };
        record.finish(state, region, sliding, status, end.t)
    }

    /// What follows the scan of `segment` that ended with `next`: the
    /// segment the motion goes on with and its first point, or the point
    /// where the iteration ends and how.
    fn after_scan(&self, segment: &Segment, next: Next, record: &mut Record) -> Onward {
        // An accumulation of impacts on a stop, or a mass arriving at rest
        // on it, pressed: held there (as on the RK4 path), where the
        // surface is a stop.
        if let Next::Chattering(w, p) | Next::Sticking(w, p) = &next {
            if let Some((j, r)) = self.stop_met_at_rest(*w, segment) {
                let (held, s) = self.hold(j, &p.y);
                record.cross_at(self, segment, p.t, s);
                record.forget_stop(self.dimension());
                let segment = self.segment(p.t, &held, Mode::Held { event: j, sides: r });
                let start = self.point(&segment, p.t, held);
                return Onward::Goes(segment, start);
            }
        }
        match next {
            Next::End(p) => Onward::Ends(p, PiecewiseStatus::Ok),
            Next::Chattering(_, p) => Onward::Ends(p, PiecewiseStatus::Chattering),
            Next::Sticking(_, p) => Onward::Ends(p, PiecewiseStatus::Sticking),
            Next::Diverged(p) => Onward::Ends(p, PiecewiseStatus::Diverged),
            Next::Crossing(w, p) => self.crossing(segment, w, p, record),
        }
    }

    /// The stop and region of an accumulation or an arrival at rest on
    /// watched function w of `segment`, where that is a stop met in a
    /// region's field.
    fn stop_met_at_rest(&self, w: Option<usize>, segment: &Segment) -> Option<(usize, usize)> {
        match (segment.mode, w) {
            (Mode::Region(r), Some(w)) => match segment.dynamics.watch[w].what {
                Watch::Surface(j) => self.stop_of(j).map(|_| (j, r)),
                _ => None,
            },
            _ => None,
        }
    }

    /// The crossing of watched function w of `segment` at `p`: the segment
    /// after it and its first point, or where and how the iteration ends.
    fn crossing(&self, segment: &Segment, w: usize, p: Point, record: &mut Record) -> Onward {
        if record.total == MAX_CROSSINGS_PER_PERIOD {
            return Onward::Ends(p, PiecewiseStatus::TooManyCrossings);
        }
        let n = self.dimension();
        let watched = &segment.dynamics.watch[w];
        let gradient = watched.k.rows(0, n).into_owned();
        // k·B z, whose sign is the crossing's direction (n·F⁻ for a
        // surface); g' = σ k·B z is the approach rate, positive unless the
        // root is a tangency that rounding turned over.
        let approach = p.g1[w];
        let rate = watched.sign * approach;
        if let (Mode::Region(r), Watch::Surface(j), true) =
            (segment.mode, watched.what, approach <= 0.0)
        {
            if let Some(stop) = self.stop_of(j) {
                let (segment, start) = self.touched(segment, j, r, stop, &p, record);
                return Onward::Goes(segment, start);
            }
        }
        if approach.is_nan() || approach <= 0.0 {
            return Onward::Ends(p, PiecewiseStatus::Grazing);
        }
        if let Watch::Surface(_) = watched.what {
            record.min_crossing_rate = record.min_crossing_rate.min(approach);
        }
        if approach < GRAZING_RATE * gradient.norm() * p.field.norm() {
            record.grazing = true;
        }
        // A release from a stop is taken just past the root, where the
        // force pulls away by a margin: at the root itself the mass leaves
        // with zero speed and zero acceleration, which the scan that
        // follows would read back, to rounding, as a contact (the closed
        // form's `release_after` does the same).
        let p = match (segment.mode, watched.what) {
            (Mode::Held { event, sides }, Watch::Release) => {
                self.released(segment, event, sides, p)
            }
            _ => p,
        };
        let next = match self.transition(segment, w, &p, &gradient, rate, record) {
            Ok(next) => next,
            Err(status) => return Onward::Ends(p, status),
        };
        record.cross_at(self, segment, p.t, next.saltation);
        record.log_det_saltation += next.log_det;
        record.total += 1;
        let segment = self.segment(p.t, &next.y, next.mode);
        let mut start = self.point(&segment, p.t, next.y);
        if let Some(j) = next.leaving {
            // Leaving a sliding surface tangentially (Filippov's exit, where
            // the new side's rate n·F⁺ starts at 0): rounding must not read
            // that rate as a return to the surface.
            start.g1[j] = start.g1[j].min(0.0);
        }
        Onward::Goes(segment, start)
    }

    /// Stop j (coordinate i, velocity v) touched without approaching it,
    /// to rounding, from region r: a mass at rest there (right after a
    /// release, where the force pulling away is tiny). Held if pressed,
    /// else it moves on from rest; nothing to reverse.
    fn touched(
        &self,
        segment: &Segment,
        j: usize,
        r: usize,
        (i, v): (usize, usize),
        p: &Point,
        record: &mut Record,
    ) -> (Segment, Point) {
        let n = self.dimension();
        let mut y = p.y.clone();
        y[i] = self.surfaces[j].offset / self.surfaces[j].normal[i];
        y[v] = 0.0;
        let side = self.surfaces[j].normal[i].signum();
        let pressed = side * self.fields[r].eval(self.omega, p.t, &y)[v] > 0.0;
        record.flow_to(self, segment, p.t);
        let mode = if pressed {
            let (_, s) = self.hold(j, &p.y);
            record.jacobian = s * std::mem::take(&mut record.jacobian);
            record.forget_stop(n);
            Mode::Held { event: j, sides: r }
        } else {
            Mode::Region(r)
        };
        let segment = self.segment(p.t, &y, mode);
        let start = self.point(&segment, p.t, y);
        (segment, start)
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
}
