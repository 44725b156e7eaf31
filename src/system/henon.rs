//! The Hénon map (the paper's eq. 7), the method's smallest check:
//!
//! x' = 1 - a·x² + y,  y' = b·x,  with DU = [[-2ax, 1], [b, 0]] (eq. 8).
//!
//! One iteration is one map step (T = 1); det DU = -b, so λ1 + λ2 = ln|b|.

use nalgebra::SMatrix;

use super::{
    check_finite, FlowSettings, IterationStats, Parameter, Params, Part, System, SystemInfo,
};

pub const INFO: SystemInfo = SystemInfo {
    kind: "henon",
    parameters: &[
        Parameter {
            name: "a",
            default: 1.4,
            doc: "quadratic coefficient a",
        },
        Parameter {
            name: "b",
            default: 0.3,
            doc: "contraction b (det DU = -b)",
        },
    ],
    state_names: &["x", "y"],
    default_sweep: "a",
    default_initial_state: &[0.0, 0.0],
    is_flow: false,
    has_exact: true,
    exact: super::ExactPropagator::PiecewiseLinear,
    check,
    check_state: |_, _| Ok(()),
    expected_sum: |p, _| p.get("b").abs().ln(),
    // A map: its iterations are its time.
    slowest_rate: |_| 0.0,
    period: super::period_of::<2, Henon>,
    forcing_frequency: |_| 0.0,
    gpu_refuses: |_| None,
    wgsl: Some(crate::model::codegen::wgsl::SystemFile::plain(
        include_str!("../../shaders/system/henon.wgsl"),
    )),
    wall_reachable: None,
    model: None,
    table: "system",
    events: &[],
};

#[derive(Clone, Copy, Debug)]
pub struct Henon {
    pub a: f64,
    pub b: f64,
}

fn check(p: &Params) -> Result<(), (&'static str, String)> {
    check_finite(p)?;
    if p.get("b") == 0.0 {
        return Err((
            "b",
            "must be non-zero: with b = 0 the map is not invertible and λ2 = -∞".into(),
        ));
    }
    Ok(())
}

impl Henon {
    /// x' = 1 - a·x² + y, y' = b·x.
    fn step(&self, x: &[f64; 2]) -> [f64; 2] {
        [1.0 - self.a * x[0] * x[0] + x[1], self.b * x[0]]
    }
}

impl System<2> for Henon {
    fn new(p: &Params) -> Self {
        Henon {
            a: p.get("a"),
            b: p.get("b"),
        }
    }

    fn period(&self) -> f64 {
        1.0
    }

    fn iterate(&self, x: &[f64; 2], _: &FlowSettings, _: &mut IterationStats) -> [f64; 2] {
        self.step(x)
    }

    fn iterate_exact(
        &self,
        x: &[f64; 2],
        _: Part,
        _: &mut IterationStats,
    ) -> Option<([f64; 2], SMatrix<f64, 2, 2>)> {
        // DU = [[-2ax, 1], [b, 0]] (the paper's eq. 8).
        let jacobian = SMatrix::<f64, 2, 2>::new(-2.0 * self.a * x[0], 1.0, self.b, 0.0);
        Some((self.step(x), jacobian))
    }
}
