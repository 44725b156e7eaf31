//! The statuses decided over a finished lane, whichever backend ran it:
//! the sum rule, `short-average` against the flow's slowest time scale,
//! `uncertain` against the row's own error.

use rayon::prelude::*;

use super::validation::validation_tolerance;
use crate::method::{LaneResult, LaneStatus};
use crate::scene::{Precision, Scene};

/// The sum rule's tolerance for a lane: the precision's own accuracy, as
/// the GPU's validation holds it, relative to the exponents' scale
/// max(1, Σ|λ_i|), plus the error the row already states (`grazing_bound`,
/// its near-grazing iterations' estimate).
pub fn sum_rule_tolerance(precision: Precision, lane: &LaneResult) -> f64 {
    let scale = lane.exponents.iter().map(|e| e.abs()).sum::<f64>().max(1.0);
    let stated = if lane.grazing_bound.is_finite() {
        lane.grazing_bound
    } else {
        0.0
    };
    validation_tolerance(precision) * scale + stated
}

/// Marks `ok` lanes whose exponents miss the sum rule (the tool's built-in
/// accuracy check) by more than [`sum_rule_tolerance`]: an error the lane's
/// other checks did not catch (copies carried out of the linear regime by a
/// burst of expansion, the paper's linear impact location), which its
/// numbers carry.
pub(super) fn flag_sum_rule(lanes: &mut [LaneResult], expected_sums: &[f64], precision: Precision) {
    lanes
        .par_iter_mut()
        .zip(expected_sums)
        .for_each(|(lane, &expected)| {
            let finite = lane.exponents.iter().all(|e| e.is_finite());
            if lane.status != LaneStatus::Ok || lane.exponents.is_empty() || !finite {
                return;
            }
            let miss = (lane.exponent_sum() - expected).abs();
            if miss > sum_rule_tolerance(precision, lane) {
                lane.status = LaneStatus::SumRule { miss };
            }
        });
}

/// Time scales of the flow's slowest mode (1/|μ|, see
/// `SystemInfo::slowest_rate`) that a lane's averaging must span, or it is
/// `short-average`. On the seed's oscillator (|μ| = 1) the period-1
/// orbit's exponents over 1000 iterations are off by 0.8 of their size at
/// 0.63 time scales (η = 1e4), by 1e-3 at 6.3 (η = 1e3) and 63 (η = 100)
/// alike; below about ten the error depends on where in its turn the
/// frame stopped, so no estimate from the run itself can be trusted
/// (docs/STABILITY.md, "How sure a row is").
pub const SHORT_AVERAGE: f64 = 10.0;

/// The largest `lambda_error` a row may state and stay `ok`: a tenth of
/// |λ1|, the exponent whose sign tells chaos from order, plus a
/// thousandth of the spectrum's scale max |λ_i|, so that a λ1 at zero (a
/// bifurcation, a flow's neutral direction in a time-T map) is judged
/// against the rest of the spectrum.
pub fn error_tolerance(lane: &LaneResult) -> f64 {
    let scale = lane.exponents.iter().fold(0.0_f64, |m, e| m.max(e.abs()));
    0.1 * lane.exponents[0].abs() + 1e-3 * scale
}

/// Marks `ok` lanes whose exponents are not yet the limit they estimate:
/// an averaging time short against the flow's slowest time scale
/// ([`SHORT_AVERAGE`]), or an error estimate above
/// [`error_tolerance`] (NaN: too few iterations to make one).
pub(super) fn flag_uncertain(scene: &Scene, lanes: &mut [LaneResult]) {
    let iterations = scene.integration.iterations as f64;
    lanes.par_iter_mut().enumerate().for_each(|(k, lane)| {
        let finite = lane.exponents.iter().all(|e| e.is_finite());
        if lane.status != LaneStatus::Ok || lane.exponents.is_empty() || !finite {
            return;
        }
        let rate = (scene.system.slowest_rate)(&scene.lane_params(k));
        let scales = lane.period * iterations * rate;
        if rate > 0.0 && scales < SHORT_AVERAGE {
            lane.status = LaneStatus::ShortAverage { scales };
        } else if lane.error.is_nan() || lane.error > error_tolerance(lane) {
            lane.status = LaneStatus::Uncertain { error: lane.error };
        }
    });
}
