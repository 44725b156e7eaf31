//! The seed paper's impact oscillator (eq. 13–14):
//!
//! X'' = -2ζX' - X + f·cos(ητ), with a rigid wall at X = X_w where X' → -e·X'.
//!
//! The map is stroboscopic: the state (X, X') sampled at ητ ≡ 0 (mod 2π),
//! period T = 2π/η. Each impact multiplies phase-space area by e² and the flow
//! contracts it at rate 2ζ, so the exponents per unit time sum to
//! -2ζ + 2·ln(e)·(impacts per unit time): -0.1 for the paper's parameters.

use std::f64::consts::TAU;

use nalgebra::SMatrix;

use super::{
    check_finite, FlowSettings, IterationStats, Parameter, Params, Part, System, SystemInfo,
};
use crate::integrate::clock::Phase;
use crate::integrate::closed_form::{ExactStatus, ForcedImpactOscillator};
use crate::integrate::{part_map_many, time_map, time_map_many, Flow, Wall};

pub const INFO: SystemInfo = SystemInfo {
    kind: "impact-oscillator",
    parameters: &[
        Parameter {
            name: "zeta",
            default: 0.05,
            doc: "damping ratio ζ",
        },
        Parameter {
            name: "f",
            default: 1.0,
            doc: "forcing amplitude f = F/(mω²)",
        },
        Parameter {
            name: "wall",
            default: 2.0,
            doc: "wall position X_w",
        },
        Parameter {
            name: "restitution",
            default: 1.0,
            doc: "coefficient of restitution e",
        },
        Parameter {
            name: "eta",
            default: 1.0,
            doc: "forcing frequency η = Ω/ω",
        },
    ],
    state_names: &["x", "v"],
    default_sweep: "eta",
    default_initial_state: &[0.0, 0.0],
    is_flow: true,
    has_exact: true,
    check,
    check_state,
    expected_sum,
    period: super::period_of::<2, ImpactOscillator>,
    forcing_frequency: super::forcing_of::<2, ImpactOscillator>,
    gpu_refuses: |_| None,
    wgsl: Some(include_str!("../../shaders/system/impact_oscillator.wgsl")),
    wall_reachable: Some(wall_reachable),
    model: None,
    table: "system",
    events: &[],
};

/// The oscillator with its parameters.
#[derive(Clone, Copy, Debug)]
pub struct ImpactOscillator {
    pub zeta: f64,
    pub f: f64,
    pub wall: f64,
    pub restitution: f64,
    pub eta: f64,
    walls: [Wall; 1],
    /// The same oscillator in closed form (the exact backend), built once.
    closed_form: Option<ForcedImpactOscillator>,
}

fn check(p: &Params) -> Result<(), (&'static str, String)> {
    check_finite(p)?;
    if p.get("eta") <= 0.0 {
        return Err(("eta", format!("must be > 0, got {}", p.get("eta"))));
    }
    if p.get("zeta") < 0.0 {
        return Err(("zeta", format!("must be >= 0, got {}", p.get("zeta"))));
    }
    let e = p.get("restitution");
    if !(0.0..=1.0).contains(&e) {
        return Err(("restitution", format!("must lie in [0, 1], got {e}")));
    }
    if p.get("zeta") == 0.0 && p.get("eta") == 1.0 {
        return Err((
            "eta",
            "η = 1 with ζ = 0 is undamped resonance: the response grows without bound".into(),
        ));
    }
    Ok(())
}

fn check_state(p: &Params, x: &[f64]) -> Result<(), String> {
    let wall = p.get("wall");
    if !admitted(wall, x[0]) {
        return Err(format!("x = {} lies behind the wall at {wall}", x[0]));
    }
    Ok(())
}

/// A state may start at position x: not behind the wall (on it, the mass
/// may rest). Twin of `behind_wall` in shaders/finish.wgsl.
fn admitted(wall: f64, x: f64) -> bool {
    x <= wall
}

/// Between impacts X = X_p + u with X_p = A cos ητ + B sin ητ the harmonic
/// response and u'' + 2ζu' + u = 0, whose energy u² + u'² never grows
/// (d/dt = -4ζu'²). So X never exceeds |X_p| + √(u(0)² + u'(0)²) before the
/// first impact: a wall beyond that bound is never reached.
fn wall_reachable(p: &Params, x: &[f64]) -> bool {
    let (zeta, f, eta) = (p.get("zeta"), p.get("f"), p.get("eta"));
    let d = (1.0 - eta * eta).powi(2) + (2.0 * zeta * eta).powi(2);
    let (a, b) = (f * (1.0 - eta * eta) / d, f * 2.0 * zeta * eta / d);
    let (u, du) = (x[0] - a, x[1] - eta * b);
    let bound = (a * a + b * b).sqrt() + (u * u + du * du).sqrt();
    // NaN anywhere counts as reachable: compile the impact code when unsure.
    p.get("wall") <= bound * (1.0 + 1e-9) || bound.is_nan()
}

fn expected_sum(p: &Params, impacts_per_time: &[f64]) -> f64 {
    let impacts_per_time = impacts_per_time[0];
    let restitution_term = if impacts_per_time == 0.0 {
        0.0
    } else {
        2.0 * p.get("restitution").ln() * impacts_per_time
    };
    -2.0 * p.get("zeta") + restitution_term
}

impl Flow<2> for ImpactOscillator {
    /// X' = V, V' = -2ζV - X + f·cos(ητ), with phase = (cos ητ, sin ητ).
    #[inline]
    fn rhs(&self, phase: &Phase, y: &[f64; 2]) -> [f64; 2] {
        [y[1], -2.0 * self.zeta * y[1] - y[0] + self.f * phase[0]]
    }

    fn forcing_frequency(&self) -> f64 {
        self.eta
    }

    fn walls(&self) -> &[Wall] {
        &self.walls
    }
}

impl System<2> for ImpactOscillator {
    fn new(p: &Params) -> Self {
        ImpactOscillator {
            zeta: p.get("zeta"),
            f: p.get("f"),
            wall: p.get("wall"),
            restitution: p.get("restitution"),
            eta: p.get("eta"),
            walls: [Wall::above(p.get("wall"), p.get("restitution"))],
            closed_form: ForcedImpactOscillator::new(
                p.get("zeta"),
                p.get("f"),
                p.get("eta"),
                p.get("wall"),
                p.get("restitution"),
            )
            .ok(),
        }
    }

    fn period(&self) -> f64 {
        TAU / self.eta
    }

    fn iterate(&self, x: &[f64; 2], flow: &FlowSettings, stats: &mut IterationStats) -> [f64; 2] {
        time_map(self, x, self.period(), flow, stats)
    }

    fn iterate_lanes(systems: &[Self], xs: &mut [[f64; 2]], flow: &FlowSettings) {
        super::time_map_lanes(systems, xs, flow)
    }

    fn iterate_many(&self, ys: &mut [[f64; 2]], flow: &FlowSettings, stats: &mut [IterationStats]) {
        time_map_many(self, ys, self.period(), flow, stats)
    }

    fn part_many(
        &self,
        ys: &mut [[f64; 2]],
        flow: &FlowSettings,
        part: Part,
        phase: &mut Phase,
        stats: &mut [IterationStats],
    ) {
        part_map_many(self, ys, self.period(), flow, part, phase, stats)
    }

    fn iterate_exact(
        &self,
        x: &[f64; 2],
        part: Part,
        stats: &mut IterationStats,
    ) -> Option<([f64; 2], SMatrix<f64, 2, 2>)> {
        let (t0, t1) = part.span(self.period());
        let it = self.closed_form.as_ref()?.iterate_span(*x, t0, t1);
        stats.impacts += it.impacts;
        stats.rank_loss = stats.rank_loss.max(it.rank_loss);
        stats.chattering |= it.status != ExactStatus::Ok;
        Some((it.state, it.jacobian))
    }

    /// The free oscillator's largest eigenvalue modulus: 1 when
    /// under-damped (the pair -ζ ± i√(1-ζ²)), ζ + √(ζ² - 1) when over-damped.
    fn stiffness(&self) -> f64 {
        if self.zeta < 1.0 {
            1.0
        } else {
            self.zeta + (self.zeta * self.zeta - 1.0).sqrt()
        }
    }

    /// The free motion's most negative exponent, -ζ - √(ζ² - 1) (-ζ when
    /// under-damped). Impacts with e < 1 contract further, by ln e each, but
    /// at an instant: the parts are about the flow between them.
    fn contraction(&self) -> f64 {
        self.zeta + (self.zeta * self.zeta - 1.0).max(0.0).sqrt()
    }

    fn admits(&self, y: &[f64; 2]) -> bool {
        admitted(self.wall, y[0])
    }
}
