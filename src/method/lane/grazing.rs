//! Near-grazing iterations: when an estimate's truncation error is worth
//! re-estimating, and the ladder of smaller δ that re-estimates it.

use nalgebra::{Const, DimMin, SMatrix};

use super::settings::MethodSettings;
use crate::integrate::clock::{Phase, ZERO_PHASE};
use crate::method::jacobian;
use crate::perturbation::perturbation_at;
use crate::system::{FlowSettings, IterationStats, Params, Part, System};

/// A grazing iteration: its estimated error in ln R_ii is above this. The
/// estimate is the copies' nonlinearity (forward differences) or its square
/// (central), times the Jacobian's Hadamard ratio Π‖column‖ / |det|: near
/// grazing the Jacobian is nearly of rank one with large entries, and the
/// contracting part, which sets the smallest exponents and the sum, is a
/// small difference of large numbers.
///
/// Measured: at 1e-6 forward differences at δ = 1e-8 flagged nearly every
/// impacting iteration of a periodic orbit (nonlinearity ~1e-7 times a ratio
/// of ~10), and the ladder made the paper-recipe comparison 5 times slower
/// for an error of 1e-8 instead of 5e-8. Real grazing iterations score far
/// above 1 (2e5 at the seed sweep's worst value), so 1e-4 separates them.
pub const GRAZING_ERROR: f64 = 1e-4;
/// The δ ladder of a grazing iteration: rungs δ·10^(-k/2), k = 1..=RUNGS,
/// down to the rounding floor. Twenty rungs reach ten decades below δ: from
/// f32's 2e-4 (the GPU host re-estimates in f64 at the scene's δ) they reach
/// the f64 floor, where eight rungs stopped at 2e-8 and missed the seed's
/// worst value by 1.2e-3.
const GRAZING_RUNGS: i32 = 20;

/// ln R_ii of J's QR factorisation, and ln of J's Hadamard ratio.
fn log_diagonal<const D: usize>(j: &SMatrix<f64, D, D>) -> ([f64; D], f64)
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let (_, r) = crate::method::qr::qr_positive(*j);
    let log_r: [f64; D] = crate::array::from_fn(|i| r[(i, i)].ln());
    let log_columns: f64 = (0..D).map(|i| j.column(i).norm().ln()).sum();
    (log_r, log_columns - log_r.iter().sum::<f64>())
}

/// The Jacobian estimate of one iteration; near grazing, the best of a
/// ladder of smaller δ.
///
/// A slow impact at speed v bends the map on the scale δ·a/v² (a the
/// acceleration at the wall), and a copy may meet the wall once more or
/// less than the reference; the copies then leave the linear regime
/// (`IterationStats::nonlinearity`). Such an iteration is re-estimated at
/// δ·10^(-k/2) down to the rounding floor; the estimate kept is the one
/// that changes least towards the next smaller δ (where truncation has
/// stopped mattering and rounding has not started to), and that change is
/// its error estimate. The reference image is the same whatever δ.
pub fn estimate_resolving_grazing<const D: usize, S: System<D>>(
    system: &S,
    flow: &FlowSettings,
    settings: &MethodSettings,
    part: Part,
    phase: &mut Phase,
    x: &[f64; D],
    stats: &mut IterationStats,
) -> ([f64; D], SMatrix<f64, D, D>)
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let delta = perturbation_at(settings.perturbation, x);
    let start = *phase;
    let mut first = *stats;
    let estimate = jacobian::estimate(
        system,
        flow,
        part,
        phase,
        x,
        delta,
        settings.difference,
        &mut first,
    );
    resolve_grazing(
        system, flow, settings, part, start, x, stats, first, estimate,
    )
}

/// The rest of [`estimate_resolving_grazing`] once the first estimate
/// (U(x), DU(x) at the scene's δ, with its statistics `first`) is taken:
/// kept unless the iteration grazes, else the δ ladder from `start`, the
/// forcing phase at the part's start. `stats` are those before the
/// estimate, and after it on return.
#[allow(clippy::too_many_arguments)]
pub(super) fn resolve_grazing<const D: usize, S: System<D>>(
    system: &S,
    flow: &FlowSettings,
    settings: &MethodSettings,
    part: Part,
    start: Phase,
    x: &[f64; D],
    stats: &mut IterationStats,
    first: IterationStats,
    (image, j0): ([f64; D], SMatrix<f64, D, D>),
) -> ([f64; D], SMatrix<f64, D, D>)
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let delta = perturbation_at(settings.perturbation, x);
    // A collapsed iteration's Jacobian is singular by nature, not by error.
    let steps_per_part = flow.steps_per_period / part.count;
    if first.rank_loss > 0 || !is_grazing(settings, steps_per_part, first.nonlinearity, &j0) {
        *stats = first;
        return (image, j0);
    }
    let (log0, _) = log_diagonal(&j0);
    // Rungs sit half a decade apart, so a plateau two rungs wide is a
    // decade of δ. The rounding floor: relative noise u·√steps/δ of 1e-2 in an image-sized
    // column; the ladder itself finds where rounding starts to matter.
    let floor = perturbation_at(
        settings.rounding_unit * (flow.steps_per_period as f64 / part.count as f64).sqrt() * 1e2,
        x,
    );
    let mut rungs = vec![(j0, log0, first)];
    for k in 1..=GRAZING_RUNGS {
        let d = delta * 10f64.powf(-f64::from(k) / 2.0);
        if d < floor {
            break;
        }
        let mut st = *stats;
        let mut again = start;
        let (_, j) = jacobian::estimate(
            system,
            flow,
            part,
            &mut again,
            x,
            d,
            settings.difference,
            &mut st,
        );
        let (log_r, _) = log_diagonal(&j);
        rungs.push((j, log_r, st));
    }
    let change = |a: &[f64; D], b: &[f64; D]| {
        let sum = (a.iter().sum::<f64>() - b.iter().sum::<f64>()).abs();
        a.iter().zip(b).fold(sum, |m, (x, y)| m.max((x - y).abs()))
    };
    // A rung's error: its larger change towards either neighbour, so that
    // two rungs agreeing by chance in the rounding noise do not pass for a
    // plateau.
    let (best, error) = (1..rungs.len().saturating_sub(1))
        .map(|k| {
            let left = change(&rungs[k - 1].1, &rungs[k].1);
            let right = change(&rungs[k].1, &rungs[k + 1].1);
            (k, left.max(right))
        })
        .filter(|(_, e)| !e.is_nan())
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap_or((0, f64::INFINITY));
    let (j, _, st) = rungs.swap_remove(best);
    *stats = IterationStats {
        grazing: true,
        grazing_error: error,
        ..st
    };
    (image, j)
}

/// Whether an estimate with this nonlinearity and Jacobian is a grazing
/// iteration worth re-estimating: its truncation error in ln R_ii (the
/// nonlinearity, or its square for central differences, times the
/// Jacobian's Hadamard ratio) is above [`GRAZING_ERROR`] and above the
/// rounding error the same estimate carries anyway (the relative noise of a
/// column, u·√(steps accumulated)/δ, times the same ratio). Below the
/// rounding, a smaller δ can only trade truncation for more rounding: in
/// f64 that never decides (the noise is ~1e-8), but f32's δ = 2e-4 has
/// noise 6e-4: a threshold below that rounding had the host of an f32 GPU
/// run re-estimate thousands of the seed's iterations for nothing
/// (docs/BENCHMARKS.md, "f32's perturbation δ").
pub fn is_grazing<const D: usize>(
    settings: &MethodSettings,
    steps_per_part: usize,
    nonlinearity: f64,
    j: &SMatrix<f64, D, D>,
) -> bool
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let (_, log_hadamard) = log_diagonal(j);
    let ratio = log_hadamard.exp();
    let suspect = nonlinearity.powi(settings.difference.order()) * ratio;
    let rounding = settings.column_noise(steps_per_part) * ratio;
    !suspect.is_nan() && suspect > GRAZING_ERROR.max(rounding)
}

/// The Jacobian of one part of an iteration (the whole iteration, or a
/// sub-map) from the reference's state x at the part's start, by
/// [`estimate_resolving_grazing`], row-major, with what happened
/// (`dispatch::Runner::reestimate`).
pub fn reestimate_of<const D: usize, S: System<D>>(
    params: &Params,
    settings: &MethodSettings,
    part: Part,
    x: &[f64],
) -> (Vec<f64>, IterationStats)
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let system = S::new(params);
    let x: [f64; D] = crate::array::from_fn(|i| x[i]);
    let mut stats = IterationStats::default();
    // The forcing phase at the part's start, advanced through the earlier
    // parts exactly as the reference's was (no trajectory rides along).
    let mut phase = ZERO_PHASE;
    for earlier in Part::all(part.count).take(part.index) {
        system.part_many(&mut [], &settings.flow, earlier, &mut phase, &mut []);
    }
    let (_, j) = estimate_resolving_grazing(
        &system,
        &settings.flow,
        settings,
        part,
        &mut phase,
        &x,
        &mut stats,
    );
    (j.transpose().iter().copied().collect(), stats)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{self, Backend, Precision};

    fn settings(precision: &str) -> MethodSettings {
        let text = format!(
            "[system]\nkind = \"impact-oscillator\"\n[sweep]\nvalues = [0.7]\n[run]\nprecision = \"{precision}\"\n"
        );
        let scene = scene::parse(&text, "test", "test", &[]).expect("scene");
        let precision = if precision == "f32" {
            Precision::F32
        } else {
            Precision::F64
        };
        crate::plan::method_settings(&scene, Backend::Gpu, precision)
    }

    #[test]
    fn grazing_is_truncation_above_the_estimate_s_own_rounding() {
        let (f64s, f32s) = (settings("f64"), settings("f32"));
        assert_eq!(f32s.perturbation, 2e-4);
        // Columns (1, 0) and (1, 0.1): Hadamard ratio |c2|/R22 = 10.05.
        let j = SMatrix::<f64, 2, 2>::new(1.0, 1.0, 0.0, 0.1);
        // Central differences: truncation nonlinearity²·ratio. At 1e-2 it
        // is 1e-3: above GRAZING_ERROR and f64's rounding (u·√1800/1e-6
        // ·ratio ≈ 9e-8), below f32's (u/2e-4·ratio ≈ 6e-3).
        assert!(is_grazing(&f64s, 1800, 1e-2, &j));
        assert!(!is_grazing(&f32s, 1800, 1e-2, &j));
        // At 0.1 (1e-1 of truncation) both re-estimate; at 1e-3 neither.
        assert!(is_grazing(&f64s, 1800, 0.1, &j));
        assert!(is_grazing(&f32s, 1800, 0.1, &j));
        assert!(!is_grazing(&f64s, 1800, 1e-3, &j));
        assert!(!is_grazing(&f32s, 1800, 1e-3, &j));
    }
}
