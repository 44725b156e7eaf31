//! Crossings inside an RK4 step: wall impacts, and the general surfaces of
//! `integrate::surface` (events, switches, sliding), in one loop.
//!
//! A rigid wall (a stop) at X = X_w acts on one coordinate of a flow (a
//! position X) whose rate is another coordinate (its velocity V = X'),
//! from one side. A step that reaches a wall or crosses a surface is split:
//! integrate to the crossing, apply it (the reset V → -e·V with X = X_w
//! exactly, an event's reset, a switch's new region, or the start of a
//! sliding phase), then integrate the rest of the step, and look again, so
//! several crossings in one step, on one surface or several, work and no
//! step ends behind a wall or integrates across a switch.
//!
//! Located by `integrate::locate`; resolved, the walls' impacts and
//! sticking with them, in `resolve`; a general surface crossed in
//! `cross`; a motion held on an event in `hold`, one sliding on switches
//! in `slide`.

mod cross;
mod hold;
mod resolve;
mod slide;

pub use resolve::{reaches_wall, resolve, resting_on, step, stuck_step, MAX_IMPACTS_PER_STEP};

// A wall as data and the stop test moved below the `Flow` trait
// (`wall`); here under their old paths, which the generated code and the
// GPU host name.
pub use super::wall::{may_turn_past, Wall, MAX_WALLS, TURN_REACH};

#[cfg(test)]
mod tests {
    use super::*;
    use crate::integrate::clock::Phase;
    use crate::integrate::clock::ZERO_PHASE;
    use crate::integrate::flow::Flow;
    use crate::integrate::iteration::{ImpactLocation, IterationStats};
    use crate::integrate::locate::Hermite;
    use crate::integrate::rk4;

    /// An autonomous step: ω = 0, the phase never moves.
    fn step_at<const D: usize, F: Flow<D>>(
        flow: &F,
        wall: &Wall,
        location: ImpactLocation,
        y: &[f64; D],
        h: f64,
        stats: &mut IterationStats,
    ) -> [f64; D] {
        step(
            &Walled { flow, wall: *wall },
            location,
            0.0,
            &ZERO_PHASE,
            &ZERO_PHASE,
            y,
            h,
            stats,
        )
        .0
    }

    /// A flow with one wall added.
    struct Walled<'a, F> {
        flow: &'a F,
        wall: Wall,
    }

    impl<const D: usize, F: Flow<D>> Flow<D> for Walled<'_, F> {
        fn rhs(&self, phase: &Phase, y: &[f64; D]) -> [f64; D] {
            self.flow.rhs(phase, y)
        }

        fn walls(&self) -> &[Wall] {
            std::slice::from_ref(&self.wall)
        }
    }

    /// X'' = a > 0: a ball thrown at a ceiling by constant gravity. RK4 is
    /// exact on quadratics, so the only error left is the impact location.
    struct Gravity {
        a: f64,
    }

    impl Flow<2> for Gravity {
        fn rhs(&self, _phase: &Phase, y: &[f64; 2]) -> [f64; 2] {
            [y[1], self.a]
        }
    }

    /// The bouncing ball in closed form from rest at distance d below the wall.
    fn bouncing(a: f64, d: f64, e: f64, t: f64) -> ([f64; 2], u32) {
        let mut t_hit = (2.0 * d / a).sqrt();
        if t < t_hit {
            return ([-d + 0.5 * a * t * t, a * t], 0);
        }
        let mut v = a * t_hit;
        let mut impacts = 0;
        loop {
            impacts += 1;
            v *= e;
            let flight = 2.0 * v / a;
            if t < t_hit + flight {
                let s = t - t_hit;
                return ([-v * s + 0.5 * a * s * s, -v + a * s], impacts);
            }
            t_hit += flight;
        }
    }

    #[test]
    fn several_impacts_in_one_step_are_all_applied() {
        let (a, d, e) = (9.81, 0.5, 0.6);
        let flow = Gravity { a };
        let wall = Wall::above(0.0, e);
        // One step long enough for four impacts.
        let h = 1.2;
        let (expected, impacts) = bouncing(a, d, e, h);
        assert!(
            impacts >= 4,
            "the test needs several impacts, got {impacts}"
        );
        let mut stats = IterationStats::default();
        let y = step_at(
            &flow,
            &wall,
            ImpactLocation::Newton,
            &[-d, 0.0],
            h,
            &mut stats,
        );
        assert_eq!(stats.impacts, impacts);
        assert!(!stats.chattering);
        assert!((y[0] - expected[0]).abs() < 1e-12, "{y:?} vs {expected:?}");
        assert!((y[1] - expected[1]).abs() < 1e-12, "{y:?} vs {expected:?}");
    }

    #[test]
    fn no_step_ends_behind_the_wall() {
        let flow = Gravity { a: 9.81 };
        for location in [ImpactLocation::Newton, ImpactLocation::Linear] {
            for e in [1.0, 0.9, 0.5] {
                let wall = Wall::above(0.0, e);
                let (mut t, mut y) = (0.0, [-1.0, 0.0]);
                let mut stats = IterationStats::default();
                let h = 0.0137;
                while t < 2.0 {
                    y = step_at(&flow, &wall, location, &y, h, &mut stats);
                    t += h;
                    assert!(
                        y[0] <= 0.0,
                        "{location:?}, e = {e}: x = {} behind the wall at t = {t}",
                        y[0]
                    );
                }
                assert!(stats.impacts > 0);
            }
        }
    }

    /// X'' = -X: a free oscillation whose top is at amplitude A.
    struct Harmonic;

    impl Flow<2> for Harmonic {
        fn rhs(&self, _phase: &Phase, y: &[f64; 2]) -> [f64; 2] {
            [y[1], -y[0]]
        }
    }

    #[test]
    fn an_excursion_past_the_wall_between_step_ends_is_an_impact() {
        // x(t) = cos(t - 0.1): the peak at t = 0.1 lies inside the step
        // [0, 0.2], whose ends are both at cos(0.1) = 0.995 < 1 - 1e-6 = the
        // wall (RK4's error over the half step is about 1e-8).
        let wall = Wall::above(1.0 - 1e-6, 1.0);
        let y0 = [0.1_f64.cos(), 0.1_f64.sin()];
        let mut stats = IterationStats::default();
        let y = step_at(
            &Harmonic,
            &wall,
            ImpactLocation::Newton,
            &y0,
            0.2,
            &mut stats,
        );
        assert_eq!(stats.impacts, 1, "the near-grazing impact was stepped over");
        assert!(y[0] <= wall.position);
        // The paper's linear location only looks at the step ends and misses it.
        let mut linear = IterationStats::default();
        step_at(
            &Harmonic,
            &wall,
            ImpactLocation::Linear,
            &y0,
            0.2,
            &mut linear,
        );
        assert_eq!(linear.impacts, 0);
    }

    /// X'' = -X - k·X³: a stiffening spring, whose turns are not those of
    /// a harmonic.
    struct Stiffening {
        k: f64,
    }

    impl Flow<2> for Stiffening {
        fn rhs(&self, _phase: &Phase, y: &[f64; 2]) -> [f64; 2] {
            [y[1], -y[0] - self.k * y[0] * y[0] * y[0]]
        }
    }

    #[test]
    fn a_step_s_cubic_rises_at_most_half_the_turn_reach_above_its_ends() {
        // The bound behind `may_turn_past`: any cubic Hermite interpolant
        // whose slope turns from + to - stays below max(g0, g1) +
        // (4/27)·h·(s0 - s1), half of TURN_REACH's; tight for ends level
        // with each other (the peak of g0 = g1 = 0, s0 = -s1 is exactly
        // h·s0/4 < (8/27)·h·s0).
        let mut tightest: f64 = 0.0;
        for i in 0..20_000 {
            let u = |k: usize| ((i * 7919 + k * 104_729) % 10_007) as f64 / 10_007.0;
            let (g0, g1) = (
                -u(1) * [1e-3, 0.1, 3.0][i % 3],
                -u(2) * [1e-3, 0.1, 3.0][i % 3],
            );
            let (s0, s1) = (1e-3 + 10.0 * u(3), -1e-3 - 10.0 * u(4));
            let h = [1e-3, 0.03, 0.3][(i / 3) % 3] * (0.5 + u(5));
            let hermite = Hermite::new(g0, s0, g1, s1, h);
            let Some(th) = hermite.peak() else { continue };
            let rise = hermite.value(th) - g0.max(g1);
            let bound = 0.5 * TURN_REACH * h * (s0 - s1);
            assert!(rise <= bound * (1.0 + 1e-12), "{rise:e} > {bound:e}");
            tightest = tightest.max(rise / bound);
        }
        assert!(
            tightest > 0.5,
            "the bound is not tested near its edge: {tightest}"
        );
    }

    #[test]
    fn a_turn_out_of_reach_never_passes_the_wall() {
        // What `may_turn_past` leaves out, the re-step to the Hermite peak
        // (which decides) never finds beyond the wall: turns of a harmonic
        // and a stiffening oscillation, 12 to 6000 steps per cycle, with
        // the wall placed just out of reach, where the step's cubic falls
        // short by half the reach and RK4 would need to overshoot it by
        // that much.
        let mut tested = 0;
        for i in 0..40_000 {
            let u = |k: usize| ((i * 7919 + k * 104_729) % 10_007) as f64 / 10_007.0;
            let amplitude = 0.05 + 5.0 * u(1);
            let k = [0.0, 0.5, 3.0][i % 3];
            let per_cycle = [20.0, 50.0, 200.0, 1800.0, 3600.0][i % 5];
            // Per cycle of the motion: the spring's frequency at this
            // amplitude, to first order (1 + (3/4)·k·A²)^½.
            let omega = (1.0 + 0.75 * k * amplitude * amplitude).sqrt();
            let h = std::f64::consts::TAU / omega / per_cycle * (0.6 + u(2));
            // A step starting before the peak X = amplitude (V = 0), by up
            // to one step.
            let flow = Stiffening { k };
            let back = h * u(3);
            let mut y0 = [amplitude, 0.0];
            // Reached backwards: the state `back` before the peak.
            let reversed = rk4::step(&Reversed(&flow), &ZERO_PHASE, &ZERO_PHASE, &y0, back).0;
            y0 = reversed;
            let y1 = rk4::step(&flow, &ZERO_PHASE, &ZERO_PHASE, &y0, h).0;
            let (s0, s1) = (y0[1], y1[1]);
            if !(s0 > 0.0 && s1 < 0.0) {
                continue;
            }
            let reach = TURN_REACH * h * (s0 - s1);
            let highest = y0[0].max(y1[0]);
            // Just out of reach, by a thousandth to a tenth of it.
            let wall = Wall::above(highest + reach * (1.001 + 0.1 * u(4)), 1.0);
            let (g0, g1) = (wall.gap(&y0), wall.gap(&y1));
            assert!(!may_turn_past(g0, s0, g1, s1, h), "{i}");
            let hermite = Hermite::new(g0, s0, g1, s1, h);
            let peak = hermite.peak().expect("the slope turns");
            let at_peak = rk4::step(&flow, &ZERO_PHASE, &ZERO_PHASE, &y0, peak * h).0;
            assert!(
                wall.gap(&at_peak) <= -0.25 * reach,
                "{i}: RK4's peak {:e} short of the wall, the reach {reach:e}",
                -wall.gap(&at_peak)
            );
            tested += 1;
        }
        assert!(tested > 30_000, "{tested} turns");
    }

    #[test]
    fn a_turn_out_of_reach_never_crosses_a_curved_moving_surface() {
        // `surface::may_cross`'s reach, on a surface curved in the state
        // and moving with the time, g = x + 0.3·x² + b·cos(w·t) - c, whose
        // rate along the motion is (1 + 0.6·x)·v - b·w·sin(w·t): along
        // harmonic and stiffening oscillations, 20 to 1000 steps per
        // cycle, the first step in which the rate turns, with the surface
        // placed just out of reach; the re-step to the Hermite peak (which
        // decides) never comes within a quarter of the reach.
        use crate::integrate::surface::{self, Surface};
        let mut tested = 0;
        for i in 0..4000 {
            let u = |k: usize| ((i * 7919 + k * 104_729) % 10_007) as f64 / 10_007.0;
            let k = [0.0, 0.5, 3.0][i % 3];
            let amplitude = 0.05 + 3.0 * u(1);
            let omega = (1.0 + 0.75 * k * amplitude * amplitude).sqrt();
            let per_cycle = [20.0, 50.0, 200.0, 1000.0][i % 4];
            let h = std::f64::consts::TAU / omega / per_cycle * (0.6 + u(2));
            let (b, w) = (0.3 * u(5), 0.2 + 2.0 * u(6));
            let value = |t: f64, y: &[f64; 2]| y[0] + 0.3 * y[0] * y[0] + b * (w * t).cos();
            let rate = |t: f64, y: &[f64; 2]| (1.0 + 0.6 * y[0]) * y[1] - b * w * (w * t).sin();
            let flow = Stiffening { k };
            let angle = std::f64::consts::TAU * u(3);
            let (mut t0, mut y0) = (
                10.0 * u(4),
                [amplitude * angle.cos(), amplitude * angle.sin()],
            );
            for _ in 0..(3.0 * per_cycle) as usize {
                let y1 = rk4::step(&flow, &ZERO_PHASE, &ZERO_PHASE, &y0, h).0;
                let (r0, r1) = (rate(t0, &y0), rate(t0 + h, &y1));
                if !(r0 > 0.0 && r1 < 0.0) {
                    (t0, y0) = (t0 + h, y1);
                    continue;
                }
                let reach = TURN_REACH * h * (r0 - r1);
                let highest = value(t0, &y0).max(value(t0 + h, &y1));
                let c = highest + reach * (1.001 + 0.1 * u(7));
                let (g0, g1) = (value(t0, &y0) - c, value(t0 + h, &y1) - c);
                assert!(
                    !surface::may_cross(Surface::Event, 0, (g0, r0), (g1, r1), h),
                    "{i}"
                );
                let peak = Hermite::new(g0, r0, g1, r1, h)
                    .peak()
                    .expect("the slope turns");
                let at_peak = rk4::step(&flow, &ZERO_PHASE, &ZERO_PHASE, &y0, peak * h).0;
                let g = value(t0 + peak * h, &at_peak) - c;
                assert!(
                    g <= -0.25 * reach,
                    "{i}: RK4's peak {:e} short of the surface, the reach {reach:e}",
                    -g
                );
                tested += 1;
                break;
            }
        }
        assert!(tested > 3000, "{tested} turns");
    }

    /// A flow run backwards in time.
    struct Reversed<'a, F>(&'a F);

    impl<F: Flow<2>> Flow<2> for Reversed<'_, F> {
        fn rhs(&self, phase: &Phase, y: &[f64; 2]) -> [f64; 2] {
            let [a, b] = self.0.rhs(phase, y);
            [-a, -b]
        }
    }

    #[test]
    fn a_mass_pressed_onto_the_wall_sticks() {
        // e = 0: the velocity dies at the first impact and gravity keeps
        // the ball on the wall: it rests there, and the step says the
        // state has forgotten where it came from.
        let wall = Wall::above(0.0, 0.0);
        let mut stats = IterationStats::default();
        let y = step_at(
            &Gravity { a: 1.0 },
            &wall,
            ImpactLocation::Newton,
            &[-0.1, 0.0],
            2.0,
            &mut stats,
        );
        assert!(!stats.chattering);
        assert_eq!(stats.impacts, 1);
        assert_eq!(stats.rank_loss, 2);
        assert_eq!(y, [0.0, 0.0]);
    }

    #[test]
    fn the_hermite_peak_is_the_slope_s_root_to_rounding() {
        // Steps across a turning point of a motion with harmonics, from
        // 50 to 3600 steps per cycle: the closed form against bisection on
        // the slope carried to the last bit. The slope's own rounding,
        // about ε·|slope(0)| against a curvature of its size, moves a root
        // by a few ε: that is the bound (measured: 1.5ε).
        let mut worst: f64 = 0.0;
        for i in 0..4000 {
            let u = |k: usize| ((i * 7919 + k * 104_729) % 10_007) as f64 / 10_007.0;
            let amplitude = 0.1 + 3.0 * u(1);
            let h = std::f64::consts::TAU / [50.0, 200.0, 1800.0, 3600.0][i % 4] * (0.6 + u(2));
            let t0 = h * u(3);
            let x = |t: f64| amplitude * ((t - t0).cos() + 0.1 * (3.0 * (t - t0)).cos());
            let v = |t: f64| -amplitude * ((t - t0).sin() + 0.3 * (3.0 * (t - t0)).sin());
            let hermite = Hermite::new(x(0.0) - 2.0, v(0.0), x(h) - 2.0, v(h), h);
            let Some(th) = hermite.peak() else { continue };
            let (mut a, mut b) = (0.0_f64, 1.0_f64);
            while b - a > f64::EPSILON {
                let mid = 0.5 * (a + b);
                if hermite.slope(mid) > 0.0 {
                    a = mid;
                } else {
                    b = mid;
                }
            }
            worst = worst.max((th - 0.5 * (a + b)).abs());
        }
        assert!(worst <= 4.0 * f64::EPSILON, "{worst:e}");
    }
}
