//! How far an orbit comes towards a wall: the largest value of a
//! coordinate over the orbit, between the RK4 step ends as well as at
//! them. A grazing test function is that extreme minus the wall's
//! position: negative while the orbit stays clear, zero where it touches
//! the wall tangentially.

use super::map::flow_of;
use super::newton::Orbit;
use crate::integrate::clock::ZERO_PHASE;
use crate::integrate::locate::Hermite;
use crate::integrate::Flow;
use crate::method::MethodSettings;
use crate::system::{IterationStats, Part, System};

/// The largest `sign`·x_c over the p iterations from x, x_c coordinate
/// `coordinate`: the reference stepped one RK4 step at a time (each a
/// one-step part of the iteration, the same arithmetic as the whole map),
/// the peak inside a step taken from the cubic Hermite interpolant of its
/// ends and their slopes F(t, y). The interpolant's error, h⁴·|x⁗|/384, is
/// of RK4's own order (1e-12 at the seed's 1800 steps per period), so the
/// peak is the RK4 solution's to the accuracy it has; re-stepping RK4 to
/// the interpolant's peak (as `integrate::locate` does for a crossing)
/// would change it by that much. A step with an impact or a crossing is
/// not one polynomial: there only its ends count.
pub fn largest<const D: usize, S: System<D> + Flow<D>>(
    system: &S,
    settings: &MethodSettings,
    x: &[f64; D],
    p: usize,
    coordinate: usize,
    sign: f64,
) -> f64 {
    let mut best = sign * x[coordinate];
    for_each_step(system, settings, x, p, coordinate, |ends, slopes, free| {
        best = best.max(sign * ends[1]);
        if free {
            best = best.max(hermite_peak(sign, ends, slopes));
        }
    });
    best
}

/// The free flight's closest approach to wall `wall` over the orbit, as
/// side·(x_c - position) at the largest local maximum of side·x_c inside a
/// step without impacts or crossings (where the normal velocity turns
/// from towards the wall to away from it): negative while every free
/// flight stays clear, zero where one touches the wall with zero normal
/// velocity. Impacts themselves do not count (their steps are skipped,
/// and the motion reaches them moving into the wall), so on an impacting
/// orbit this is the grazing test of a flight between impacts. -∞ when no
/// free flight turns back; NaN for a system without that wall.
pub fn free_approach<const D: usize, S: System<D> + Flow<D>>(
    system: &S,
    settings: &MethodSettings,
    orbit: &Orbit<D>,
    wall: usize,
) -> f64 {
    let Some(&w) = system.walls().get(wall) else {
        return f64::NAN;
    };
    let sign = w.side;
    let mut best = f64::NEG_INFINITY;
    let (state, period) = (orbit.state, orbit.period);
    for_each_step(
        system,
        settings,
        &state,
        period,
        w.coordinate,
        |ends, slopes, free| {
            if !free {
                return;
            }
            let (g0, g1) = (sign * ends[0], sign * ends[1]);
            let (s0, s1) = (sign * slopes[0], sign * slopes[1]);
            let hermite = Hermite::new(g0, s0, g1, s1, 1.0);
            if let Some(th) = hermite.peak() {
                best = best.max(hermite.value(th));
            } else if s0 > 0.0 && s1 == 0.0 {
                best = best.max(g1);
            }
        },
    );
    best - sign * w.position
}

/// Calls `visit` for every RK4 step of the p iterations from x with the
/// step's ends of coordinate `coordinate`, their slopes h·F_c per unit
/// step, and whether the step is free (no impact or crossing: then one
/// polynomial). The reference is stepped one step at a time, each a
/// one-step part of the iteration: the same arithmetic as the whole map.
fn for_each_step<const D: usize, S: System<D> + Flow<D>>(
    system: &S,
    settings: &MethodSettings,
    x: &[f64; D],
    p: usize,
    coordinate: usize,
    mut visit: impl FnMut([f64; 2], [f64; 2], bool),
) {
    let flow = flow_of(system, settings);
    let n = flow.steps_per_period;
    let h = system.period() / n as f64;
    let mut y = *x;
    for _ in 0..p {
        let mut phase = ZERO_PHASE;
        for index in 0..n {
            let f0 = system.rhs(&phase, &y);
            let mut ys = [y];
            let mut stats = [IterationStats::default()];
            system.part_many(
                &mut ys,
                &flow,
                Part { index, count: n },
                &mut phase,
                &mut stats,
            );
            let next = ys[0];
            let free = stats[0].crossings.iter().all(|&c| c == 0);
            let f1 = if free { system.rhs(&phase, &next) } else { f0 };
            visit(
                [y[coordinate], next[coordinate]],
                [h * f0[coordinate], h * f1[coordinate]],
                free,
            );
            y = next;
        }
        system.wrap(&mut y);
    }
}

/// The largest `sign`·p(s) over s ∈ [0, 1] of the cubic Hermite p with
/// p(0), p(1) = `ends` and p'(0), p'(1) = `slopes` (per unit s), at its
/// stationary points inside the step (the ends are the caller's; a
/// stationary point that is a minimum of sign·p lies below them, so the
/// caller's maximum is the same with it). -∞ without one.
fn hermite_peak(sign: f64, [p0, p1]: [f64; 2], [m0, m1]: [f64; 2]) -> f64 {
    let hermite = Hermite::new(p0, m0, p1, m1, 1.0);
    hermite
        .stationary_points()
        .iter()
        .filter(|s| !s.is_nan())
        .fold(f64::NEG_INFINITY, |m, &s| m.max(sign * hermite.value(s)))
}

/// How far past wall `wall` of the system the orbit would come, as
/// side·(x_c - position) at its largest over the orbit: negative while
/// the orbit stays clear, zero at grazing. On an orbit that meets the wall
/// it is zero, so a grazing point is located from the free side
/// ([`super::locate::locate_zero`]).
pub fn wall_excess<const D: usize, S: System<D> + Flow<D>>(
    system: &S,
    settings: &MethodSettings,
    orbit: &Orbit<D>,
    wall: usize,
) -> f64 {
    let w = system.walls()[wall];
    let peak = largest(
        system,
        settings,
        &orbit.state,
        orbit.period,
        w.coordinate,
        w.side,
    );
    peak - w.side * w.position
}

#[cfg(test)]
mod tests {
    use super::hermite_peak;

    #[test]
    fn the_hermite_peak_of_a_cubic_is_its_maximum_inside_the_step() {
        // p(s) = -(s - 0.3)²: p(0) = -0.09, p(1) = -0.49, p'(0) = 0.6,
        // p'(1) = -1.4; the Hermite cubic is p itself, its peak 0 at s = 0.3.
        let peak = hermite_peak(1.0, [-0.09, -0.49], [0.6, -1.4]);
        assert!(peak.abs() < 1e-16, "{peak}");
        // Mirrored (sign -1 of -p), the same peak.
        let mirrored = hermite_peak(-1.0, [0.09, 0.49], [-0.6, 1.4]);
        assert!(mirrored.abs() < 1e-16, "{mirrored}");
        // p(s) = s, monotone: no stationary point inside.
        assert_eq!(hermite_peak(1.0, [0.0, 1.0], [1.0, 1.0]), f64::NEG_INFINITY);
    }
}
