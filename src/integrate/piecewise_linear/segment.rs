//! A segment: the exact flow of one mode from a point, evaluated anywhere
//! along it from its start (so that rounding does not accumulate), with
//! the watched functions and their first two derivatives at each point.

use nalgebra::{DMatrix, DVector};
use std::sync::Arc;

use super::dynamics::{augment, Dynamics, Mode};
use super::system::PiecewiseLinear;

/// A segment: the flow of one mode from (t0, y0).
#[derive(Clone, Debug)]
pub(super) struct Segment {
    pub(super) t0: f64,
    pub(super) mode: Mode,
    pub(super) dynamics: Arc<Dynamics>,
    /// z(t0) = [y0; 1; cos ωt0; sin ωt0].
    pub(super) z0: DVector<f64>,
}

/// A point of a segment, with what the scan needs of every watched function.
#[derive(Clone, Debug)]
pub(super) struct Point {
    pub(super) t: f64,
    pub(super) y: DVector<f64>,
    /// F(t, y) of the segment's mode.
    pub(super) field: DVector<f64>,
    /// g_i, g_i', g_i''.
    pub(super) g: Vec<f64>,
    pub(super) g1: Vec<f64>,
    pub(super) g2: Vec<f64>,
}

impl PiecewiseLinear {
    /// The top-left block of exp(B s): exp(A s), or exp(P A s) sliding.
    pub(super) fn flow(&self, dynamics: &Dynamics, s: f64) -> DMatrix<f64> {
        let n = self.dimension();
        let e = (&dynamics.b * s).exp();
        e.view((0, 0), (n, n)).into_owned()
    }

    pub(super) fn segment(&self, t0: f64, y0: &DVector<f64>, mode: Mode) -> Segment {
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
    pub(super) fn point(&self, segment: &Segment, t: f64, y: DVector<f64>) -> Point {
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
    pub(super) fn eval(&self, segment: &Segment, t: f64) -> Point {
        let n = self.dimension();
        let e = (&segment.dynamics.b * (t - segment.t0)).exp();
        let y = e.rows(0, n) * &segment.z0;
        self.point(segment, t, y)
    }
}
