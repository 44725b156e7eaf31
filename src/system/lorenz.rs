//! The Lorenz flow, the engine's check at three dimensions:
//!
//! x' = σ(y - x),  y' = x(ρ - z) - y,  z' = xy - βz.
//!
//! The map is the time-`period` map of the flow (state (x, y, z), three
//! exponents, one of them zero: the flow direction). The divergence is the
//! constant -(σ + 1 + β), so the exponents sum to it exactly.

use super::{
    check_finite, FlowSettings, IterationStats, Parameter, Params, Part, System, SystemInfo,
};
use crate::integrate::clock::Phase;
use crate::integrate::{part_map_many, time_map, time_map_many, Flow};

pub const INFO: SystemInfo = SystemInfo {
    kind: "lorenz",
    parameters: &[
        Parameter {
            name: "sigma",
            default: 10.0,
            doc: "Prandtl number σ",
        },
        Parameter {
            name: "rho",
            default: 28.0,
            doc: "Rayleigh number ρ",
        },
        Parameter {
            name: "beta",
            default: 8.0 / 3.0,
            doc: "geometric factor β",
        },
        Parameter {
            name: "period",
            default: 1.0,
            doc: "time of one map iteration",
        },
    ],
    state_names: &["x", "y", "z"],
    default_sweep: "rho",
    default_initial_state: &[1.0, 1.0, 1.0],
    is_flow: true,
    has_exact: false,
    check,
    check_state: |_, _| Ok(()),
    expected_sum: |p, _| -(p.get("sigma") + 1.0 + p.get("beta")),
    period: super::period_of::<3, Lorenz>,
    forcing_frequency: super::forcing_of::<3, Lorenz>,
    gpu_refuses: |_| None,
    wgsl: Some(include_str!("../../shaders/system/lorenz.wgsl")),
    wall_reachable: None,
    model: None,
    table: "system",
    events: &[],
};

#[derive(Clone, Copy, Debug)]
pub struct Lorenz {
    pub sigma: f64,
    pub rho: f64,
    pub beta: f64,
    pub period: f64,
}

fn check(p: &Params) -> Result<(), (&'static str, String)> {
    check_finite(p)?;
    if p.get("period") <= 0.0 {
        return Err(("period", format!("must be > 0, got {}", p.get("period"))));
    }
    Ok(())
}

impl Flow<3> for Lorenz {
    #[inline]
    fn rhs(&self, _phase: &Phase, s: &[f64; 3]) -> [f64; 3] {
        let [x, y, z] = *s;
        [
            self.sigma * (y - x),
            x * (self.rho - z) - y,
            x * y - self.beta * z,
        ]
    }
}

impl System<3> for Lorenz {
    fn new(p: &Params) -> Self {
        Lorenz {
            sigma: p.get("sigma"),
            rho: p.get("rho"),
            beta: p.get("beta"),
            period: p.get("period"),
        }
    }

    fn period(&self) -> f64 {
        self.period
    }

    fn iterate(&self, x: &[f64; 3], flow: &FlowSettings, stats: &mut IterationStats) -> [f64; 3] {
        time_map(self, x, self.period, flow, stats)
    }

    fn iterate_lanes(systems: &[Self], xs: &mut [[f64; 3]], flow: &FlowSettings) {
        super::time_map_lanes(systems, xs, flow)
    }

    fn iterate_many(&self, ys: &mut [[f64; 3]], flow: &FlowSettings, stats: &mut [IterationStats]) {
        time_map_many(self, ys, self.period, flow, stats)
    }

    fn part_many(
        &self,
        ys: &mut [[f64; 3]],
        flow: &FlowSettings,
        part: Part,
        phase: &mut Phase,
        stats: &mut [IterationStats],
    ) {
        part_map_many(self, ys, self.period, flow, part, phase, stats)
    }

    /// The linearisation at the origin: eigenvalues -β and
    /// (-(σ+1) ± √((σ-1)² + 4σρ))/2; the most negative sets the scale.
    fn stiffness(&self) -> f64 {
        let (s, r, b) = (self.sigma, self.rho, self.beta);
        let disc = ((s - 1.0).powi(2) + 4.0 * s * r).max(0.0).sqrt();
        (0.5 * (s + 1.0 + disc)).max(b)
    }

    /// Phase-space volume contracts at σ + 1 + β = -(λ1 + λ2 + λ3), which
    /// is -λ3 up to the small positive λ1 (13.67 against 14.57 at the
    /// classical parameters).
    fn contraction(&self) -> f64 {
        self.sigma + 1.0 + self.beta
    }
}
