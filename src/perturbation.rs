//! The perturbed copies of the paper's method: where they start (a δ
//! relative to the state's size) and how their images are differenced
//! into the Jacobian's columns. Shared by the method, which estimates a
//! map's Jacobian from them, and by the systems that estimate their own
//! tangent maps the same way (a Poincaré map's, `system::section`).

/// The perturbation actually used at x: δ·max(1, ‖x‖∞). A relative δ keeps
/// the balance of truncation and rounding error the same for a state of
/// size 30 (Lorenz) as for one of size 1; f32 needs that.
pub fn perturbation_at(delta: f64, x: &[f64]) -> f64 {
    delta * x.iter().fold(1.0_f64, |m, v| m.max(v.abs()))
}

/// How the Jacobian's columns are differenced.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Difference {
    /// The paper's scheme: D copies at x + δe_i; error O(δ).
    #[default]
    Forward,
    /// 2D copies at x ± δe_i; error O(δ²), so δ can be larger against
    /// rounding, which is what f32 needs.
    Central,
}

impl Difference {
    pub fn name(self) -> &'static str {
        match self {
            Difference::Forward => "forward",
            Difference::Central => "central",
        }
    }

    /// The order of the scheme's error in δ: a copy that leaves the linear
    /// regime by a fraction r errs by r (forward) or r² (central).
    pub fn order(self) -> i32 {
        match self {
            Difference::Forward => 1,
            Difference::Central => 2,
        }
    }

    /// Perturbed copies per lane.
    pub fn copies(self, dimension: usize) -> usize {
        match self {
            Difference::Forward => dimension,
            Difference::Central => 2 * dimension,
        }
    }
}
