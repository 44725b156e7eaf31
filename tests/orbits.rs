//! Periodic orbits of the seed's oscillator solved by Newton, followed in
//! η and their grazing points located.

mod common;

use lyapsweep::method::MethodSettings;
use lyapsweep::orbit::*;
use lyapsweep::plan::method_settings;
use lyapsweep::scene::{Backend, Precision};
use lyapsweep::system::model::ModelFlow;
use lyapsweep::system::{Params, System};

type Seed = ModelFlow<2>;

const ZETA: f64 = 0.05;

/// The seed's scene (ζ = 0.05, f = 1, X_w = 2, e = 1, 1800 steps per
/// period) at η = `eta`, with the index of η.
fn seed(eta: f64) -> (Params, MethodSettings, usize) {
    let scene = common::committed_scene("seed-fig3.toml", &["sweep.count=2"]);
    let settings = method_settings(&scene, Backend::Cpu, Precision::F64);
    let index = scene.system.parameter_index("eta").expect("eta");
    let params = params_at(&scene.lane_params(0), index, eta);
    (params, settings, index)
}

/// The non-impacting orbit's point at t = 0: the linear response
/// x = Re[f e^{iηt} / (1 - η² + 2iζη)].
fn linear_response(eta: f64) -> [f64; 2] {
    let (a, b) = (1.0 - eta * eta, 2.0 * ZETA * eta);
    let d2 = a * a + b * b;
    [a / d2, eta * b / d2]
}

fn newton() -> NewtonSettings {
    NewtonSettings::default()
}

/// The largest |λ_i + ζ| over a branch's points.
fn worst_exponent_error(branch: &Branch<2>) -> f64 {
    branch
        .points
        .iter()
        .flat_map(|p| p.floquet.exponents.iter().map(|e| (e + ZETA).abs()))
        .fold(0.0, f64::max)
}

#[test]
fn newton_finds_the_seed_s_non_impacting_orbit_with_exponents_minus_zeta() {
    for (eta, steps) in [(0.5, 2), (1.5, 2)] {
        let (params, settings, _) = seed(eta);
        let system = Seed::new(&params);
        let mut orbit = solve(&system, &settings, &newton(), &[0.0, 0.0], 1).expect("orbit");
        assert_eq!(orbit.steps, steps, "η = {eta}");
        assert!(orbit.residual <= 1e-10, "η = {eta}: {}", orbit.residual);
        assert_eq!(orbit.stats.impacts, 0);
        // RK4's orbit against the exact one: its global error at
        // h = T/1800, h⁴/120 per unit time, is a few 1e-11 here.
        let exact = linear_response(eta);
        for (i, (x, e)) in orbit.state.iter().zip(exact).enumerate() {
            let error = (x - e).abs();
            assert!(error < 1e-10, "η = {eta}, state {i}: {error:e}");
        }
        let f = refined_floquet(&system, &settings, &params, &mut orbit);
        // A complex pair of modulus e^{-ζT}: both exponents -ζ, up to
        // RK4's -Re(λ⁵)h⁴/120 (1e-12) and the ladder's rounding.
        for e in &f.exponents {
            assert!((e + ZETA).abs() < 1e-10, "η = {eta}: {e}");
        }
        // A complex pair (at η = 0.5 close to the real axis: ω_d·T is 4π
        // less 0.016).
        assert!(f.multipliers[0].im > 0.0, "{:?}", f.multipliers);
        assert_eq!(f.multipliers[0], f.multipliers[1].conj());
        assert_eq!(f.expected_sum, -2.0 * ZETA);
        assert!(
            f.sum_error().abs() < 1e-10,
            "η = {eta}: {:e}",
            f.sum_error()
        );
        assert!(f.stable());
    }
}

/// The non-impacting orbit followed from η = 0.5 up and from 1.5 down:
/// its branch ends where it grazes the wall, which is located by the
/// wall's excess (the largest x minus X_w) from the free side, against
/// the linear response's amplitude f/√((1-η²)² + (2ζη)²) = X_w.
#[test]
fn the_seed_s_non_impacting_branch_grazes_where_the_linear_amplitude_is_the_wall() {
    for (eta, direction, exact) in [
        (0.5, 1.0, 0.7106873690939233),
        (1.5, -1.0, 1.2185743569476413),
    ] {
        let (params, settings, index) = seed(eta);
        let orbit = solve(
            &Seed::new(&params),
            &settings,
            &newton(),
            &linear_response(eta),
            1,
        )
        .expect("orbit");
        let continuation = ContinuationSettings {
            direction,
            ..ContinuationSettings::over(index, (0.5, 1.5))
        };
        let branch = continue_branch::<2, Seed>(
            &params,
            &settings,
            &newton(),
            &continuation,
            &orbit.state,
            1,
        );
        // Newton from the free orbit finds no orbit across the grazing
        // point (the impacting one leaves it with a square root): the
        // branch ends there.
        let BranchEnd::StepTooSmall { parameter, .. } = branch.end else {
            panic!("η from {eta}: {:?}", branch.end);
        };
        assert!((parameter - exact).abs() < 1e-7, "{parameter}");
        assert!(branch.points.iter().all(|p| p.orbit.stats.impacts == 0));
        assert!(branch.points.iter().all(|p| p.orbit.residual <= 1e-10));
        let worst = worst_exponent_error(&branch);
        assert!(worst < 1e-10, "η from {eta}: {worst:e}");

        let last = branch.points.last().expect("points");
        let beyond = last.parameter + direction * continuation.max_step;
        let test = |s: &Seed, o: &Orbit<2>| Some(wall_excess(s, &settings, o, 0));
        let found = locate_zero::<2, Seed, _>(
            &params,
            &settings,
            &newton(),
            index,
            (last.parameter, &last.orbit),
            (beyond, None),
            test,
            1e-10,
        )
        .expect("bracketed");
        let error = (found.parameter - exact).abs();
        assert!(
            error < 1e-8,
            "η from {eta}: {} off by {error:e}",
            found.parameter
        );
        // At the grazing point the orbit touches the wall: excess 0.
        let system = Seed::new(&params_at(&params, index, found.parameter));
        assert!(wall_excess(&system, &settings, &found.orbit, 0).abs() < 1e-9);
    }
}

#[test]
fn a_solve_that_fails_says_why() {
    let (params, settings, _) = seed(0.8);
    let system = Seed::new(&params);
    // Behind the wall (x > X_w = 2).
    assert_eq!(
        solve(&system, &settings, &newton(), &[2.5, 0.0], 1).unwrap_err(),
        Failure::Inadmissible { steps: 0 }
    );
    assert_eq!(
        solve(&system, &settings, &newton(), &[f64::NAN, 0.0], 1).unwrap_err(),
        Failure::NonFinite { steps: 0 }
    );
    let none = NewtonSettings {
        max_steps: 0,
        ..newton()
    };
    let Failure::NotConverged { steps, residual } =
        solve(&system, &settings, &none, &[0.0, 0.0], 1).unwrap_err()
    else {
        panic!("not converged");
    };
    assert_eq!(steps, 0);
    assert!(residual > 0.1, "{residual}");
}

/// The Hénon map's fixed points x = 1 - a·x² + b·x, y = b·x have a closed
/// form, x = (-(1-b) + √((1-b)² + 4a)) / (2a), and so do their
/// bifurcations: a period doubling where a multiplier (a root of
/// μ² + 2ax·μ - b) is -1, at a = 3(1-b)²/4, and the fold where the two
/// fixed points are born, at a = -(1-b)²/4. Followed from a = 1.4 (the
/// saddle in the attractor) down, the branch doubles, passes the fold and
/// comes back on the other fixed point; both are located to 1e-8.
#[test]
fn the_henon_fixed_point_branch_passes_its_fold_and_both_bifurcations_are_located() {
    use lyapsweep::system::henon::Henon;
    let text = "[system]\nkind = \"henon\"\n[sweep]\nvalues = [1.4]\n";
    let scene = common::scene(text, &[]);
    let settings = method_settings(&scene, Backend::Cpu, Precision::F64);
    let params = scene.lane_params(0);
    let (a, b) = (1.4, 0.3);
    let index = scene.system.parameter_index("a").expect("a");
    let fixed = |a: f64, root: f64| {
        let x = (-(1.0 - b) + root * ((1.0 - b) * (1.0 - b) + 4.0 * a).sqrt()) / (2.0 * a);
        [x, b * x]
    };
    let start = fixed(a, 1.0);
    let orbit = solve(&Henon::new(&params), &settings, &newton(), &[0.6, 0.2], 1).expect("orbit");
    // Within the residual bound 1e-10 over |μ_i - 1| ≥ 0.8.
    assert!(
        (orbit.state[0] - start[0]).abs() < 1e-10,
        "{:?} {start:?}",
        orbit.state
    );
    // An unstable orbit (a saddle): μ = -ax ± √(a²x² + b).
    let f = floquet(&orbit, &params);
    let ax = a * start[0];
    let exact = [-ax - (ax * ax + b).sqrt(), -ax + (ax * ax + b).sqrt()];
    assert!(
        (f.multipliers[0].re - exact[0]).abs() < 1e-9,
        "{:?}",
        f.multipliers
    );
    assert!(
        (f.multipliers[1].re - exact[1]).abs() < 1e-9,
        "{:?}",
        f.multipliers
    );
    assert!((f.sum_error()).abs() < 1e-9, "{:e}", f.sum_error());
    assert!(!f.stable());

    let continuation = ContinuationSettings {
        direction: -1.0,
        max_points: 300,
        ..ContinuationSettings::over(index, (-0.5, 1.5))
    };
    let branch = continue_branch::<2, Henon>(
        &params,
        &settings,
        &newton(),
        &continuation,
        &orbit.state,
        1,
    );
    let lowest = branch
        .points
        .iter()
        .map(|p| p.parameter)
        .fold(f64::INFINITY, f64::min);
    let fold = -(1.0 - b) * (1.0 - b) / 4.0;
    assert!(lowest > fold && lowest < fold + 1e-3, "turned at {lowest}");
    // Every point on one of the two fixed points.
    for p in &branch.points {
        let on = [1.0, -1.0]
            .iter()
            .map(|&root| {
                (p.orbit.state[0] - fixed(p.parameter, root)[0]).abs()
                    / p.orbit.state[0].abs().max(1.0)
            })
            .fold(f64::INFINITY, f64::min);
        assert!(on < 1e-9, "a = {}: {:?}", p.parameter, p.orbit.state);
    }
    let found = bifurcations::<2, Henon>(
        &params,
        &settings,
        &newton(),
        &continuation,
        &branch.points,
        1e-10,
    );
    let kinds: Vec<(Kind, f64)> = found.iter().map(|b| (b.kind, b.point.parameter)).collect();
    assert_eq!(found.len(), 2, "{kinds:?}");
    let doubling = 3.0 * (1.0 - b) * (1.0 - b) / 4.0;
    assert_eq!(found[0].kind, Kind::PeriodDoubling);
    assert!(
        (found[0].point.parameter - doubling).abs() < 1e-8,
        "{kinds:?}"
    );
    assert_eq!(found[1].kind, Kind::Fold);
    assert!((found[1].point.parameter - fold).abs() < 1e-8, "{kinds:?}");
    // Past the fold the other fixed point runs off to infinity as a → 0⁻.
    assert_eq!(branch.end, BranchEnd::MaxPoints);
}

/// The seed's impacting period-1 orbit, found by its attractor at η = 0.6
/// (800 iterations from rest), followed in η: a closed branch (an isola)
/// with two folds, the stable orbit born at one with the unstable one and
/// both lost at the other. Each fold is checked against an independent
/// computation on the exact backend's closed form
/// (`integrate::closed_form`, through `System::iterate_exact`): its exact
/// map and exact Jacobian, the fold solved as U(x) = x, det(DU - I) = 0
/// by Newton in (x, η).
#[test]
fn the_seed_s_impacting_orbit_is_an_isola_whose_folds_match_the_closed_form() {
    let (params, settings, index) = seed(0.6);
    let system = Seed::new(&params);
    let flow = lyapsweep::orbit::map::flow_of(&system, &settings);
    let mut x = [0.0, 0.0];
    for _ in 0..800 {
        x = system.iterate(&x, &flow, &mut Default::default());
    }
    let orbit = solve(&system, &settings, &newton(), &x, 1).expect("orbit");
    assert_eq!(orbit.stats.impacts, 1);
    let continuation = ContinuationSettings::over(index, (0.5, 1.5));
    let branch = continue_branch::<2, Seed>(
        &params,
        &settings,
        &newton(),
        &continuation,
        &orbit.state,
        1,
    );
    assert_eq!(branch.end, BranchEnd::Closed);
    assert!(branch.points.iter().all(|p| p.orbit.stats.impacts == 1));
    // The sum rule (-2ζ: elastic impacts) on stable and unstable points.
    for p in &branch.points {
        assert!(
            p.floquet.sum_error().abs() < 1e-9,
            "η = {}: {:e}",
            p.parameter,
            p.floquet.sum_error()
        );
    }
    let found = bifurcations::<2, Seed>(
        &params,
        &settings,
        &newton(),
        &continuation,
        &branch.points,
        1e-10,
    );
    let kinds: Vec<(Kind, f64)> = found.iter().map(|b| (b.kind, b.point.parameter)).collect();
    assert_eq!(found.len(), 2, "{kinds:?}");
    for b in &found {
        assert_eq!(b.kind, Kind::Fold);
        let exact = closed_form_fold(&params, index, b.point.orbit.state, b.point.parameter);
        let error = (b.point.parameter - exact).abs();
        assert!(
            error < 1e-8,
            "fold at {} against {exact}: {error:e}",
            b.point.parameter
        );
    }
    let mut etas: Vec<f64> = kinds.iter().map(|k| k.1).collect();
    etas.sort_by(f64::total_cmp);
    assert!(
        (etas[0] - 0.5712).abs() < 1e-4 && (etas[1] - 0.6170).abs() < 1e-4,
        "{etas:?}"
    );
}

/// The fold of the closed form's period-1 orbit near (x, η): Newton on
/// G(x, η) = (U(x) - x, det(DU(x) - I)) with U and DU the closed form's,
/// G's own Jacobian by central differences (Newton converges to G's zero
/// whatever that Jacobian's small error).
fn closed_form_fold(base: &Params, index: usize, x: [f64; 2], eta: f64) -> f64 {
    use lyapsweep::system::Part;
    let g = |y: [f64; 3]| {
        let system = Seed::new(&params_at(base, index, y[2]));
        let mut stats = Default::default();
        let (image, j) = system
            .iterate_exact(&[y[0], y[1]], Part::WHOLE, &mut stats)
            .expect("the seed has a closed form");
        let det = (j[(0, 0)] - 1.0) * (j[(1, 1)] - 1.0) - j[(0, 1)] * j[(1, 0)];
        [image[0] - y[0], image[1] - y[1], det]
    };
    let mut y = [x[0], x[1], eta];
    for _ in 0..20 {
        let r = g(y);
        if r.iter().all(|v| v.abs() < 1e-14) {
            break;
        }
        let h = 1e-7;
        let jac = nalgebra::Matrix3::from_fn(|row, col| {
            let (mut up, mut down) = (y, y);
            up[col] += h;
            down[col] -= h;
            (g(up)[row] - g(down)[row]) / (up[col] - down[col])
        });
        let dy = jac
            .lu()
            .solve(&nalgebra::Vector3::new(-r[0], -r[1], -r[2]))
            .expect("regular at a fold");
        for i in 0..3 {
            y[i] += dy[i];
        }
    }
    y[2]
}
