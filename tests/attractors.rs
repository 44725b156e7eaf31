//! Many starts per swept value (`[attractors]`): each (value, start) is a
//! lane of its own, computed as a single-start run from that state would
//! compute it, on the CPU and the GPU paths; every lane's orbit period is
//! reported; coexisting attractors show up as lanes of one value that end
//! on different orbits.

mod common;

use common::gpu_or_skip;
use lyapsweep::method::LaneStatus;
use lyapsweep::scene::{Layout, Precision};
use lyapsweep::{scene, Error};

/// The seed's oscillator at η = 0.6, where a non-impacting and an
/// impacting period-1 orbit coexist.
const COEXISTING: &str = r#"
[system]
kind = "impact-oscillator"
zeta = 0.05
f = 1.0
wall = 2.0
restitution = 1.0
[sweep]
parameter = "eta"
values = [0.6]
[integration]
steps_per_period = 1800
transient = 300
iterations = 300
initial_state = [0.0, 0.0]
[run]
backend = "cpu"
[output]
bifurcation_points = 1
"#;

fn parse(text: &str, overrides: &[&str]) -> lyapsweep::Result<lyapsweep::Scene> {
    let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
    scene::parse(text, "test scene", "test", &overrides)
}

/// The lanes of the box's 4 × 4 grid end on two period-1 orbits: the
/// non-impacting one, whose exponents are the linear oscillator's
/// (-ζ, -ζ, exactly: its eigenvalues -ζ ± i√(1 - ζ²)), and the impacting
/// one, one impact per period, with a larger λ1. The non-impacting one
/// draws most of the box.
#[test]
fn a_grid_of_starts_finds_both_period_one_orbits() {
    let text = format!(
        "{COEXISTING}[attractors]\ngrid = [4, 4]\nbox = {{ x = [-3, 1.9], v = [-3, 3] }}\n"
    );
    let scene = common::scene(&text, &[]);
    assert_eq!(scene.lane_count(), 16);
    let report = common::run(&scene);
    let (mut free, mut impacting) = (Vec::new(), Vec::new());
    for (k, lane) in report.lanes.iter().enumerate() {
        assert_eq!(lane.status, LaneStatus::Ok, "lane {k}");
        assert_eq!(lane.orbit_period, Some(1), "lane {k}");
        let sum = lane.exponent_sum();
        assert!((sum + 0.1).abs() < 1e-8, "lane {k}: sum {sum}");
        match lane.impacts_per_period {
            0.0 => free.push(lane),
            1.0 => impacting.push(lane),
            n => panic!("lane {k}: {n} impacts per period"),
        }
    }
    for lane in &free {
        for e in &lane.exponents {
            assert!((e + 0.05).abs() < 1e-5, "{:?}", lane.exponents);
        }
    }
    // Every impacting lane is the same orbit: the same exponents.
    let l1 = impacting[0].exponents[0];
    assert!(l1 > -0.03 && l1 < -0.01, "{l1}");
    for lane in &impacting {
        assert!((lane.exponents[0] - l1).abs() < 1e-8);
    }
    assert!(!impacting.is_empty() && free.len() > impacting.len());

    // Each orbit's exponents within 1e-8 of the exact backend's, started
    // on a point of the orbit.
    let on = |lane: &lyapsweep::method::LaneResult| {
        format!("[{}, {}]", lane.bifurcation[0], lane.bifurcation[1])
    };
    let exact = common::scene(
        &format!(
            "{}[attractors]\nlist = [{}, {}]\n",
            COEXISTING.replace("backend = \"cpu\"", "backend = \"exact\""),
            on(free[0]),
            on(impacting[0])
        ),
        &[],
    );
    let exact = common::run(&exact);
    for (lane, exact) in [free[0], impacting[0]].iter().zip(&exact.lanes) {
        assert_eq!(exact.orbit_period, Some(1));
        assert_eq!(exact.impacts_per_period, lane.impacts_per_period);
        for (a, b) in lane.exponents.iter().zip(&exact.exponents) {
            assert!(
                (a - b).abs() < 1e-8,
                "{:?} against the exact {:?}",
                lane.exponents,
                exact.exponents
            );
        }
    }
}

/// Lane (value, start) of a many-start sweep is, to the bit, the lane of
/// the single-start sweep from that state.
fn assert_starts_are_single_runs(backend: &str, precision: &str) {
    let base = format!("{COEXISTING}\n",)
        .replace("values = [0.6]", "values = [0.6, 0.8, 1.1]")
        .replace(
            "backend = \"cpu\"",
            &format!("backend = \"{backend}\"\nprecision = \"{precision}\""),
        );
    let starts = [[0.0, 0.0], [1.5, 0.1], [-2.5, 2.0]];
    let list: Vec<String> = starts
        .iter()
        .map(|s| format!("[{}, {}]", s[0], s[1]))
        .collect();
    let many = common::scene(
        &format!("{base}[attractors]\nlist = [{}]\n", list.join(", ")),
        &[
            "integration.transient=40",
            "integration.iterations=60",
            "integration.steps_per_period=400",
        ],
    );
    assert_eq!(many.lane_count(), 9);
    let report = common::run(&many);
    for (s, start) in starts.iter().enumerate() {
        let single = common::scene(
            &base,
            &[
                "integration.transient=40",
                "integration.iterations=60",
                "integration.steps_per_period=400",
                &format!("integration.initial_state=[{}, {}]", start[0], start[1]),
            ],
        );
        let alone = common::run(&single);
        for v in 0..3 {
            let lane = &report.lanes[v * starts.len() + s];
            let mut expected = alone.lanes[v].clone();
            // Validation picks other lanes in a sweep of another size.
            if matches!(expected.status, LaneStatus::Mismatch { .. }) {
                expected.status = lane.status;
            }
            // Only a run with [attractors] keeps the orbit's points: its
            // last is the lane's final state, the single run's last point.
            assert!(expected.orbit.is_empty());
            let dim = 2;
            assert_eq!(
                lane.orbit[lane.orbit.len() - dim..],
                expected.bifurcation[expected.bifurcation.len() - dim..],
                "{backend} {precision}: value {v}, start {s}"
            );
            expected.orbit = lane.orbit.clone();
            assert_eq!(
                format!("{lane:?}"),
                format!("{expected:?}"),
                "{backend} {precision}: value {v}, start {s}"
            );
        }
    }
}

#[test]
fn a_start_s_lane_is_the_single_start_lane_on_the_cpu() {
    assert_starts_are_single_runs("cpu", "f64");
}

#[test]
fn a_start_s_lane_is_the_single_start_lane_on_the_gpu() {
    for (precision, name) in [(Precision::F64, "f64"), (Precision::F32, "f32")] {
        if gpu_or_skip(
            "a_start_s_lane_is_the_single_start_lane_on_the_gpu",
            precision,
        ) {
            assert_starts_are_single_runs("gpu", name);
        }
    }
}

/// A grid runs over the box's states in the model's order, the first
/// fastest, corners included (numpy's linspace); random starts are the
/// same for the same seed, inside the box, and the states the box does
/// not name keep `initial_state`.
#[test]
fn grids_and_random_starts_are_where_the_table_says() {
    let grid = parse(
        &format!("{COEXISTING}[attractors]\ngrid = [3, 2]\nbox = {{ v = [-1, 1], x = [-3, 1] }}\n"),
        &[],
    )
    .unwrap();
    let starts = grid.sweep.starts.as_ref().unwrap();
    assert_eq!(starts.layout, Layout::Grid { counts: vec![3, 2] });
    // x (the first state) varies fastest over 3 points, v over 2.
    let expected = [
        [-3.0, -1.0],
        [-1.0, -1.0],
        [1.0, -1.0],
        [-3.0, 1.0],
        [-1.0, 1.0],
        [1.0, 1.0],
    ];
    let got: Vec<[f64; 2]> = starts.states.iter().map(|s| [s[0], s[1]]).collect();
    assert_eq!(got, expected);
    assert_eq!(starts.max_period, 12);

    let random = |seed: u64| {
        parse(
            &format!(
                "{COEXISTING}[attractors]\nstarts = 50\nseed = {seed}\nbox = {{ x = [-3, 1.5] }}\nmax_period = 4\n"
            ),
            &["integration.initial_state=[0.0, 0.25]"],
        )
        .unwrap()
        .sweep
        .starts
        .clone()
        .unwrap()
    };
    let (a, b, c) = (random(7), random(7), random(8));
    assert_eq!(a, b);
    assert_ne!(a.states, c.states);
    assert_eq!(a.max_period, 4);
    assert_eq!(a.states.len(), 50);
    for state in &a.states {
        assert!((-3.0..1.5).contains(&state[0]), "{state:?}");
        assert_eq!(state[1], 0.25);
    }
}

/// Each `(table, key, reason)`: the `[attractors]` table is refused with
/// an input error naming the key and the reason.
fn refused(cases: &[(&str, &str, &str)]) {
    for &(table, key, reason) in cases {
        let text = format!("{COEXISTING}[attractors]\n{table}\n");
        let error = parse(&text, &[])
            .err()
            .unwrap_or_else(|| panic!("{table}: accepted"));
        let message = error.to_string();
        assert!(
            message.contains(key) && message.contains(reason),
            "{table}: {message}"
        );
        assert!(
            matches!(error, Error::Invalid { .. } | Error::Syntax { .. }),
            "{table}: {error:?}"
        );
    }
}

/// Bad basin keys are refused by name, before any work.
#[test]
fn bad_basin_keys_name_their_key() {
    refused(&[
        (
            "starts = 4\nbox = { x = [0, 1] }\nbasins = 1",
            "attractors.basins",
            "needs grid = [nx, ny]",
        ),
        (
            "grid = [4]\nbox = { x = [0, 1] }\nbasins = 1",
            "attractors.basins",
            "two states",
        ),
        (
            "list = [[0, 0]]\nbasins = 2",
            "attractors.basins",
            "needs grid",
        ),
        (
            "grid = [4, 3]\nbox = { x = [0, 1], v = [0, 1] }\nbasins = 1\nbasin_box = 4",
            "attractors.basin_box",
            "shorter side (3)",
        ),
        (
            "grid = [4, 3]\nbox = { x = [0, 1], v = [0, 1] }\nbasins = 1\nbasin_box = 0",
            "attractors.basin_box",
            "between 1",
        ),
        (
            "grid = [4, 3]\nbox = { x = [0, 1], v = [0, 1] }\nbasin_box = 2",
            "attractors.basin_box",
            "attractors.basins",
        ),
        (
            "grid = [4, 3]\nbox = { x = [0, 1], v = [0, 1] }\nbasins = -1",
            "attractors.basins",
            "",
        ),
        (
            "grid = [4, 3]\nbox = { x = [0, 1], v = [0, 1] }\nearly_stop = 10",
            "attractors.early_stop",
            "attractors.basins",
        ),
        (
            "grid = [4, 3]\nbox = { x = [0, 1], v = [0, 1] }\nbasins = 1\nearly_stop = -1",
            "attractors.early_stop",
            "",
        ),
        (
            "grid = [4, 3]\nbox = { x = [0, 1], v = [0, 1] }\nbasins = 1\nearly_stop = 2.5",
            "attractors.early_stop",
            "",
        ),
    ]);
}

/// Bad distributions of random starts are refused by their key, before
/// any work.
#[test]
fn bad_distributions_name_their_key() {
    let normal = |mean: &str, sd: &str| {
        format!(
            "starts = 8\nbox = {{ x = [-3, 1.9], v = [-3, 3] }}\ndistribution = {{ kind = \"normal\", mean = {{ {mean} }}, sd = {{ {sd} }} }}"
        )
    };
    let cases = [
        (
            "grid = [4, 3]\nbox = { x = [0, 1], v = [0, 1] }\ndistribution = { kind = \"uniform\" }".to_string(),
            "attractors.distribution",
            "applies to random starts",
        ),
        (
            "starts = 8\nbox = { x = [0, 1] }\ndistribution = { kind = \"gaussian\" }".to_string(),
            "attractors.distribution.kind",
            "\"uniform\" or \"normal\"",
        ),
        (
            "starts = 8\nbox = { x = [0, 1] }\ndistribution = { kind = \"uniform\", sd = { x = 1 } }".to_string(),
            "attractors.distribution.sd",
            "applies to kind = \"normal\"",
        ),
        (
            "starts = 8\nbox = { x = [0, 1] }\ndistribution = { kind = \"normal\", spread = 1 }".to_string(),
            "spread",
            "",
        ),
        (normal("x = 0", "x = 1, v = 1"), "attractors.distribution.mean", "needs a value for v"),
        (normal("x = 2, v = 0", "x = 1, v = 1"), "attractors.distribution.mean.x", "within the box"),
        (normal("x = 0, v = 0", "x = 0, v = 1"), "attractors.distribution.sd.x", "positive"),
        (normal("x = 0, v = 0", "x = 1, v = 1e9"), "attractors.distribution.sd.v", "at most 100 times"),
        (normal("x = 0, v = 0, y = 1", "x = 1, v = 1"), "attractors.distribution.mean.y", "not a state of the box"),
        (normal("x = 0, v = 0", "x = nan, v = 1"), "attractors.distribution.sd.x", "positive"),
    ];
    let borrowed: Vec<(&str, &str, &str)> =
        cases.iter().map(|(t, k, r)| (t.as_str(), *k, *r)).collect();
    refused(&borrowed);
}

/// Bad tables are refused with the key and the reason, before any work.
#[test]
fn bad_attractors_tables_name_their_key() {
    let cases = [
        (
            "starts = 4\nlist = [[0, 0]]",
            "attractors",
            "exactly one of",
        ),
        ("starts = 4", "attractors.box", "is required"),
        (
            "starts = 4\nbox = { y = [0, 1] }",
            "attractors.box.y",
            "is not a state",
        ),
        (
            "starts = 4\nbox = { x = [1, 0] }",
            "attractors.box.x",
            "low < high",
        ),
        (
            "grid = [3]\nbox = { x = [0, 1], v = [0, 1] }",
            "attractors.grid",
            "one count per state",
        ),
        (
            "grid = [3, 2]\nbox = { x = [0, 1], v = [0, 1] }\nseed = 3",
            "attractors.seed",
            "random",
        ),
        (
            "list = [[0, 0, 1]]",
            "attractors.list",
            "start 0 has 3 numbers",
        ),
        ("list = [[2.5, 0]]", "attractors.list", "start 0 ([2.5, 0])"),
        (
            "starts = 0\nbox = { x = [0, 1] }",
            "attractors.starts",
            "between 1 and",
        ),
        (
            "list = [[0, 0]]\nmax_period = 0",
            "attractors.max_period",
            "at least 1",
        ),
        (
            "starts = 4\nbox = { x = [0, 1] }\ncolour = 1",
            "attractors",
            "colour",
        ),
        (
            "list = [[0, 0]]\ncontinuation = \"sideways\"",
            "attractors.continuation",
            "unknown variant `sideways`",
        ),
    ];
    refused(&cases);
    // starts × values is a size like any other.
    let wide = COEXISTING.replace("values = [0.6]", "from = 0.5\nto = 1.5\ncount = 100000");
    let error = parse(
        &format!("{wide}[attractors]\nstarts = 100000\nbox = {{ x = [0, 1] }}\n"),
        &[],
    )
    .unwrap_err();
    assert!(error.to_string().contains("attractors.starts"), "{error}");
    // A shard would split a value's starts from each other.
    let whole = parse(&format!("{COEXISTING}[attractors]\nlist = [[0, 0]]\n"), &[]).unwrap();
    let error = whole
        .sharded(scene::Shard { index: 0, count: 1 })
        .unwrap_err();
    assert!(error.to_string().contains("--shard"), "{error}");
    // A section's points are not whole states to continue a flow from.
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/lorenz-section.toml");
    let error = scene::load(
        &path,
        &[
            "attractors.list=[[1, 1, 1]]".into(),
            "attractors.continuation=\"up\"".into(),
        ],
    )
    .unwrap_err();
    assert!(
        error
            .to_string()
            .contains("attractors.continuation: needs a period map"),
        "{error}"
    );
}

/// A sweep's attractors, through the command's entry (continuation
/// included).
fn attractors_of(scene: &lyapsweep::Scene) -> lyapsweep::Attractors {
    attractors_with(scene, &Default::default())
}

/// [`attractors_of`] with `options`.
fn attractors_with(
    scene: &lyapsweep::Scene,
    options: &lyapsweep::RunOptions,
) -> lyapsweep::Attractors {
    let batch = lyapsweep::plan::batch_lanes(scene);
    let (_, found) =
        lyapsweep::run_streaming(scene, options, batch, |_, _| Ok(())).expect("the sweep runs");
    found.expect("a scene with [attractors]")
}

/// The attractors of one value as (period, impacts per period, final
/// point) for comparisons between runs.
fn final_point(a: &lyapsweep::attractor::group::Attractor) -> [f64; 2] {
    let orbit = &a.first.lane.orbit;
    [orbit[orbit.len() - 2], orbit[orbit.len() - 1]]
}

/// Whether two runs' attractors are one orbit: the same period and
/// impacts, and the one's final point on the other's orbit.
fn same_orbit(
    a: &lyapsweep::attractor::group::Attractor,
    b: &lyapsweep::attractor::group::Attractor,
    tolerance: f64,
) -> bool {
    let (x, y) = (&a.first.lane, &b.first.lane);
    let p = final_point(a);
    x.orbit_period == y.orbit_period
        && x.impacts_per_period == y.impacts_per_period
        && y.orbit
            .chunks_exact(2)
            .any(|q| (q[0] - p[0]).abs().max((q[1] - p[1]).abs()) < tolerance)
}

/// Where the seed's oscillator holds two period-1 orbits (η = 0.58 to
/// 0.615), a 6 × 6 grid of starts finds both at each value: each one's
/// exponents within 1e-8 of the exact backend started on its final point,
/// and each start's attractor (so the basin fractions) the same as the
/// exact backend's from the same start.
#[test]
fn the_window_s_attractors_and_basins_match_the_exact_backend() {
    let text = format!(
        "{COEXISTING}[attractors]\ngrid = [6, 6]\nbox = {{ x = [-3, 1.9], v = [-3, 3] }}\n"
    )
    .replace("values = [0.6]", "values = [0.58, 0.6, 0.61]");
    let cpu = attractors_of(&common::scene(&text, &[]));
    let exact = attractors_of(&common::scene(
        &text.replace("backend = \"cpu\"", "backend = \"exact\""),
        &[],
    ));
    for (v, eta) in [0.58, 0.6, 0.61].into_iter().enumerate() {
        let (found, truth) = (&cpu.values[v], &exact.values[v]);
        assert_eq!(found.count(), 2, "η = {eta}: {found:?}");
        assert_eq!(truth.count(), 2, "η = {eta}");
        let impacts: Vec<f64> = found
            .attractors
            .iter()
            .map(|a| a.first.lane.impacts_per_period)
            .collect();
        assert!(
            impacts.contains(&0.0) && impacts.contains(&1.0),
            "{impacts:?}"
        );
        for a in &found.attractors {
            assert_eq!(a.first.lane.orbit_period, Some(1));
            let p = final_point(a);
            let alone = common::run(&common::scene(
                &format!("{COEXISTING}[attractors]\nlist = [[{}, {}]]\n", p[0], p[1])
                    .replace("values = [0.6]", &format!("values = [{eta}]"))
                    .replace("backend = \"cpu\"", "backend = \"exact\""),
                &[],
            ));
            for (x, y) in a.first.lane.exponents.iter().zip(&alone.lanes[0].exponents) {
                assert!((x - y).abs() < 1e-8, "η = {eta}: {x} against the exact {y}");
            }
        }
        // Start by start, the same attractor: the same basins.
        for s in 0..36 {
            let mine = &found.attractors[found.of_start[s].unwrap()];
            let theirs = &truth.attractors[truth.of_start[s].unwrap()];
            assert!(same_orbit(mine, theirs, 1e-6), "η = {eta}, start {s}");
        }
        for a in &found.attractors {
            let b = truth
                .attractors
                .iter()
                .find(|b| same_orbit(a, b, 1e-6))
                .unwrap();
            assert_eq!(a.starts, b.starts, "η = {eta}");
        }
    }
    assert_eq!(cpu.several(), 3);
    // Three values far apart, without continuation: branches by distance
    // alone; each value's two attractors on two different ones.
    for value in &cpu.values {
        let ids: Vec<_> = value.attractors.iter().map(|a| a.branch.unwrap()).collect();
        assert_ne!(ids[0], ids[1]);
    }
}

/// The same on the GPU path, with its CPU validation lanes: the
/// attractors of each value and each start's attractor as the CPU path
/// finds them, the exponents within the precision's validation tolerance.
#[test]
fn the_window_s_attractors_on_the_gpu_are_the_cpu_s() {
    let text = format!(
        "{COEXISTING}[attractors]\ngrid = [6, 6]\nbox = {{ x = [-3, 1.9], v = [-3, 3] }}\n"
    )
    .replace("values = [0.6]", "values = [0.58, 0.6, 0.61]");
    let cpu = attractors_of(&common::scene(&text, &[]));
    for (precision, name) in [(Precision::F64, "f64"), (Precision::F32, "f32")] {
        if !gpu_or_skip(
            "the_window_s_attractors_on_the_gpu_are_the_cpu_s",
            precision,
        ) {
            continue;
        }
        let gpu_text = text.replace(
            "backend = \"cpu\"",
            &format!("backend = \"gpu\"\nprecision = \"{name}\"\nvalidate = 4"),
        );
        let gpu = attractors_of(&common::scene(&gpu_text, &[]));
        let tolerance = lyapsweep::driver::validation_tolerance(precision);
        let points = if precision == Precision::F64 {
            1e-6
        } else {
            1e-3
        };
        for v in 0..3 {
            let (found, truth) = (&gpu.values[v], &cpu.values[v]);
            assert_eq!(found.count(), truth.count(), "{name}, value {v}");
            for s in 0..36 {
                let mine = &found.attractors[found.of_start[s].unwrap()];
                let theirs = &truth.attractors[truth.of_start[s].unwrap()];
                assert!(
                    same_orbit(mine, theirs, points),
                    "{name}, value {v}, start {s}"
                );
                for (x, y) in mine
                    .first
                    .lane
                    .exponents
                    .iter()
                    .zip(&theirs.first.lane.exponents)
                {
                    assert!((x - y).abs() < tolerance, "{name}: {x} against {y}");
                }
            }
            assert!(found
                .attractors
                .iter()
                .all(|a| !matches!(a.first.lane.status, LaneStatus::Mismatch { .. })));
        }
        // With continuation passes, and the device's batches cut to 5 lanes
        // (the scene's starts and each pass in overlapped batches): the
        // same attractors, links and exponents, to the bit.
        if precision == Precision::F64 {
            let continued = common::scene(
                &gpu_text.replace("[attractors]\n", "[attractors]\ncontinuation = \"both\"\n"),
                &[],
            );
            let whole = attractors_of(&continued);
            assert!(whole.passes > 0 && whole.continued_lanes > 0);
            let split = attractors_with(
                &continued,
                &lyapsweep::RunOptions {
                    max_batch_lanes: Some(5),
                    ..Default::default()
                },
            );
            assert_eq!(format!("{:?}", split.values), format!("{:?}", whole.values));
            assert_eq!(
                (split.passes, split.continued_lanes, split.branches),
                (whole.passes, whole.continued_lanes, whole.branches)
            );
        }
    }
}

/// From one start at rest, continuation finds what the grid does: going
/// up from the values where the start falls on the non-impacting orbit it
/// follows that orbit through the window where the start falls on the
/// impacting one; going down it follows the impacting orbit to its fold.
/// The branch ids stay the same along each.
#[test]
fn continuation_follows_both_orbits_through_the_window() {
    let text = format!("{COEXISTING}[attractors]\nlist = [[0.0, 0.0]]\ncontinuation = \"both\"\n")
        .replace("values = [0.6]", "from = 0.55\nto = 0.65\ncount = 21")
        .replace("steps_per_period = 1800", "steps_per_period = 600")
        .replace("transient = 300", "transient = 200")
        .replace("iterations = 300", "iterations = 100");
    let value = |found: &lyapsweep::Attractors, eta: f64| {
        found.values[((eta - 0.55) / 0.005_f64).round() as usize].clone()
    };
    let both = attractors_of(&common::scene(&text, &[]));
    let grid = attractors_of(&common::scene(
        &text.replace(
            "list = [[0.0, 0.0]]\ncontinuation = \"both\"",
            "grid = [4, 4]\nbox = { x = [-3, 1.9], v = [-3, 3] }",
        ),
        &[],
    ));
    assert!(both.passes > 1, "{} passes", both.passes);
    for v in 0..21 {
        let (found, truth) = (&both.values[v], &grid.values[v]);
        assert_eq!(found.count(), truth.count(), "value {v}");
        for a in &found.attractors {
            assert!(
                truth.attractors.iter().any(|b| same_orbit(a, b, 1e-5)),
                "value {v}"
            );
        }
    }
    // Two attractors from η = 0.575 to 0.615, one outside.
    assert_eq!(both.several(), 9);
    let branch = |found: &lyapsweep::Attractors, eta: f64, impacts: f64| {
        value(found, eta)
            .attractors
            .iter()
            .find(|a| a.first.lane.impacts_per_period == impacts)
            .and_then(|a| a.branch)
    };
    let free = branch(&both, 0.55, 0.0).unwrap();
    let impacting = branch(&both, 0.6, 1.0).unwrap();
    assert_ne!(free, impacting);
    for k in 0..21 {
        let eta = 0.55 + 0.005 * k as f64;
        assert_eq!(branch(&both, eta, 0.0), Some(free), "η = {eta}");
        if (0.5725..0.6175).contains(&eta) {
            assert_eq!(branch(&both, eta, 1.0), Some(impacting), "η = {eta}");
        }
    }
    // One way only: up never finds the impacting orbit below the values
    // the start falls on it; down finds it there.
    let up = attractors_of(&common::scene(&text.replace("\"both\"", "\"up\""), &[]));
    let down = attractors_of(&common::scene(&text.replace("\"both\"", "\"down\""), &[]));
    assert_eq!(branch(&up, 0.575, 1.0), None);
    assert!(branch(&down, 0.575, 1.0).is_some());
    assert!(branch(&up, 0.6, 0.0).is_some());
}

/// attractors.csv has one row per (value, attractor) with the basins
/// summing to 1 at each value, and every lane's row in spectrum.csv and
/// bifurcation.csv names the branch of the attractor it ended on.
#[test]
fn attractors_csv_and_the_branch_columns_agree() {
    let text = format!(
        "{COEXISTING}[attractors]\ngrid = [4, 4]\nbox = {{ x = [-3, 1.9], v = [-3, 3] }}\n"
    )
    .replace("values = [0.6]", "values = [0.56, 0.6]");
    let scene = common::scene(&text, &[]);
    let report = common::run(&scene);
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("set");
    lyapsweep::output::write(&scene, &report, &out).unwrap();
    let read = |name: &str| {
        let mut reader = csv::Reader::from_path(out.join(name)).unwrap();
        let header: Vec<String> = reader.headers().unwrap().iter().map(String::from).collect();
        let rows: Vec<Vec<String>> = reader
            .records()
            .map(|r| r.unwrap().iter().map(String::from).collect())
            .collect();
        (header, rows)
    };
    let (header, rows) = read("attractors.csv");
    assert_eq!(
        header,
        [
            "eta",
            "branch",
            "period",
            "impacts_per_period",
            "lambda_1",
            "lambda_2",
            "lambda_sum",
            "expected_sum",
            "lambda_error",
            "basin_fraction",
            "starts",
            "x",
            "v",
            "status"
        ]
    );
    // η = 0.56: the non-impacting orbit alone; η = 0.6: both.
    let at = |eta: &str| rows.iter().filter(|r| r[0] == eta).collect::<Vec<_>>();
    assert_eq!(at("0.56").len(), 1);
    assert_eq!(at("0.6").len(), 2);
    for eta in ["0.56", "0.6"] {
        let basins: f64 = at(eta).iter().map(|r| r[9].parse::<f64>().unwrap()).sum();
        let starts: usize = at(eta)
            .iter()
            .map(|r| r[10].parse::<usize>().unwrap())
            .sum();
        assert!((basins - 1.0).abs() < 1e-12);
        assert_eq!(starts, 16);
    }
    let (header, lanes) = read("spectrum.csv");
    let branch = header.iter().position(|h| h == "branch").unwrap();
    let impacts = header
        .iter()
        .position(|h| h == "impacts_per_period")
        .unwrap();
    assert_eq!(header[branch - 1], "start");
    assert_eq!(lanes.len(), 32);
    for lane in &lanes {
        let row = rows
            .iter()
            .find(|r| r[0] == lane[0] && r[1] == lane[branch])
            .unwrap_or_else(|| panic!("{lane:?}: no attractor of its branch"));
        assert_eq!(row[3], lane[impacts], "{lane:?}");
    }
    let (header, points) = read("bifurcation.csv");
    assert_eq!(header, ["eta", "x", "v", "start", "branch"]);
    for (point, lane) in points.iter().zip(&lanes) {
        assert_eq!(point[4], lane[branch]);
    }
}

/// A `.npy` file of a 2-D array of little-endian i32, read here without
/// the writer's code: (rows, columns, numbers).
fn read_npy_i32(path: &std::path::Path) -> (usize, usize, Vec<i32>) {
    let bytes = std::fs::read(path).unwrap();
    assert_eq!(&bytes[..8], b"\x93NUMPY\x01\x00");
    let header_len = usize::from(bytes[8]) + 256 * usize::from(bytes[9]);
    let header = std::str::from_utf8(&bytes[10..10 + header_len]).unwrap();
    assert!(header.contains("'descr': '<i4'"), "{header}");
    assert!(header.contains("'fortran_order': False"), "{header}");
    let shape = header.split("'shape': (").nth(1).unwrap();
    let shape = &shape[..shape.find(')').unwrap()];
    let dims: Vec<usize> = shape
        .split(',')
        .filter(|s| !s.trim().is_empty())
        .map(|s| s.trim().parse().unwrap())
        .collect();
    let data = &bytes[10 + header_len..];
    let numbers: Vec<i32> = data
        .chunks_exact(4)
        .map(|c| i32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    assert_eq!(numbers.len(), dims[0] * dims[1]);
    (dims[0], dims[1], numbers)
}

/// Daza et al.'s basin entropy of a label image, written apart from the
/// library's: boxes of `n` × `n` (the leftover edge cells dropped), each
/// box's Gibbs entropy over its labels' shares; the mean over all boxes
/// and over those with more than one label.
fn entropy_by_hand(rows: usize, columns: usize, labels: &[i32], n: usize) -> (f64, f64) {
    let mut entropies = Vec::new();
    let mut boundary = Vec::new();
    for top in (0..rows - rows % n).step_by(n) {
        for left in (0..columns - columns % n).step_by(n) {
            // Over the box's admissible starts (label -2 is not a basin's).
            let mut counts = std::collections::BTreeMap::new();
            for r in top..top + n {
                for c in left..left + n {
                    let label = labels[r * columns + c];
                    if label != -2 {
                        *counts.entry(label).or_insert(0.0) += 1.0;
                    }
                }
            }
            let cells: f64 = counts.values().sum();
            if cells == 0.0 {
                continue;
            }
            let shares: Vec<f64> = counts.values().map(|k| k / cells).collect();
            let s: f64 = shares.iter().map(|p| -p * p.ln()).sum();
            entropies.push(s);
            if counts.len() > 1 {
                boundary.push(s);
            }
        }
    }
    let mean = |v: &[f64]| {
        if v.is_empty() {
            0.0
        } else {
            v.iter().sum::<f64>() / v.len() as f64
        }
    };
    (mean(&entropies), mean(&boundary))
}

/// The seed's oscillator at η = 0.6 over a 32 × 32 grid of the box with
/// `basins = 1`: `basins-0.npy` labels every start with its lane's branch
/// (spectrum.csv's column, start by start), its two period-1 orbits'
/// fractions are the labels' shares, the basin entropy and the boundary's
/// are those computed here from the file, and the boundary between the
/// two basins is smooth by the ln 2 criterion; the image is drawn and the
/// labels are in the manifest.
#[test]
fn a_basin_image_labels_every_start_and_its_measures_are_the_file_s() {
    let (nx, ny) = (32, 32);
    let text = format!(
        "{COEXISTING}[attractors]\ngrid = [{nx}, {ny}]\nbox = {{ x = [-3, 1.9], v = [-3, 3] }}\nbasins = 1\nbasin_box = 4\n"
    )
    .replace("[output]", "[output]\nplot = true");
    let scene = common::scene(&text, &[]);
    let report = common::run(&scene);
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("set");
    lyapsweep::output::write(&scene, &report, &out).unwrap();
    let (rows, columns, labels) = read_npy_i32(&out.join("basins-0.npy"));
    assert_eq!((rows, columns), (ny, nx));
    for name in ["basins-0.png", "basins-0.svg"] {
        assert!(out.join(name).exists(), "{name}");
    }
    let manifest = std::fs::read_to_string(out.join("manifest.toml")).unwrap();
    assert!(manifest.contains("name = \"basins-0.npy\""), "{manifest}");

    let mut spectrum = csv::Reader::from_path(out.join("spectrum.csv")).unwrap();
    let branch = spectrum
        .headers()
        .unwrap()
        .iter()
        .position(|h| h == "branch")
        .unwrap();
    let by_start: Vec<i32> = spectrum
        .records()
        .map(|r| r.unwrap()[branch].parse().unwrap_or(-1))
        .collect();
    assert_eq!(labels, by_start);

    let mut table = csv::Reader::from_path(out.join("attractors.csv")).unwrap();
    let header: Vec<String> = table.headers().unwrap().iter().map(String::from).collect();
    let col = |name: &str| header.iter().position(|h| h == name).unwrap();
    let rows: Vec<csv::StringRecord> = table.records().map(|r| r.unwrap()).collect();
    assert_eq!(rows.len(), 2, "the free and the impacting period-1 orbits");
    let (s_b, s_bb) = entropy_by_hand(ny, nx, &labels, 4);
    let number = |row: &csv::StringRecord, name: &str| row[col(name)].parse::<f64>().unwrap();
    for row in &rows {
        let label: i32 = row[col("branch")].parse().unwrap();
        let share = labels.iter().filter(|&&l| l == label).count() as f64 / labels.len() as f64;
        let fraction = number(row, "basin_fraction");
        assert_eq!(fraction, share);
        assert!((0.3..0.7).contains(&fraction), "{fraction}");
        let error = (fraction * (1.0 - fraction) / labels.len() as f64).sqrt();
        assert!((number(row, "basin_fraction_error") - error).abs() <= 1e-15);
        let half: Vec<i32> = (0..ny)
            .step_by(2)
            .flat_map(|j| (0..nx).step_by(2).map(move |i| (i, j)))
            .map(|(i, j)| labels[j * nx + i])
            .collect();
        let half_share = half.iter().filter(|&&l| l == label).count() as f64 / half.len() as f64;
        assert_eq!(number(row, "basin_fraction_half"), half_share);
        assert!((number(row, "basin_entropy") - s_b).abs() < 1e-12, "{s_b}");
        assert!(
            (number(row, "boundary_basin_entropy") - s_bb).abs() < 1e-12,
            "{s_bb}"
        );
        assert_eq!(&row[col("fractal_boundary")], "false");
        // The nearest start of the other basin from the orbit's point, in
        // the box's scaled max norm, computed from the file.
        let (x0, v0) = (number(row, "x"), number(row, "v"));
        let along = |lo: f64, hi: f64, n: usize, k: usize| {
            if k + 1 == n {
                hi
            } else {
                lo + k as f64 * (hi - lo) / (n - 1) as f64
            }
        };
        let shock = (0..nx * ny)
            .filter(|&k| labels[k] != label && labels[k] >= 0)
            .map(|k| {
                let (x, v) = (along(-3.0, 1.9, nx, k % nx), along(-3.0, 3.0, ny, k / nx));
                ((x - x0).abs() / 4.9).max((v - v0).abs() / 6.0)
            })
            .fold(f64::INFINITY, f64::min);
        let written = number(row, "critical_shock");
        assert!((written - shock).abs() < 1e-12, "{written} against {shock}");
        assert!(shock > 0.0 && shock < 0.5, "{shock}");
    }
    assert!(s_b > 0.0 && s_bb > 0.0 && s_bb <= std::f64::consts::LN_2);
}

/// A basin image's box may reach past the wall (here x up to 3, the wall
/// at 2): those starts are not run, labelled -2 (`inadmissible-start` in
/// spectrum.csv), drawn apart and left out of the measures; the others'
/// labels are those of a box that stops at the wall, start by start, and
/// the fractions are of the admissible starts. On the GPU too, when one is
/// present, with the same labels.
#[test]
fn starts_behind_the_wall_are_labelled_apart_and_left_out_of_the_measures() {
    let (nx, ny) = (13, 8);
    let scene_text = |x_to: u32, nx: usize| {
        format!(
            "{COEXISTING}[attractors]\ngrid = [{nx}, {ny}]\nbox = {{ x = [-3, {x_to}], v = [-3, 3] }}\nbasins = 1\nbasin_box = 2\n"
        )
    };
    let dir = tempfile::tempdir().unwrap();
    let labels_of = |text: &str, name: &str| {
        let scene = common::scene(text, &[]);
        let report = common::run(&scene);
        let out = dir.path().join(name);
        lyapsweep::output::write(&scene, &report, &out).unwrap();
        let (rows, columns, labels) = read_npy_i32(&out.join("basins-0.npy"));
        assert_eq!(rows, ny);
        (columns, labels, out)
    };
    // x = -3 + 0.5 k on both grids, exactly: columns 11 and 12 (x = 2.5, 3)
    // lie behind the wall; x = 2 is on it, admissible.
    let (columns, past, out) = labels_of(&scene_text(3, nx), "past");
    let (inside_columns, inside, _) = labels_of(&scene_text(2, 11), "inside");
    assert_eq!((columns, inside_columns), (13, 11));
    for r in 0..ny {
        for c in 0..nx {
            let label = past[r * nx + c];
            if c >= 11 {
                assert_eq!(label, -2, "row {r}, column {c}");
            } else {
                assert_eq!(label, inside[r * 11 + c], "row {r}, column {c}");
            }
        }
    }
    assert!(past.contains(&0) && past.contains(&1), "{past:?}");

    let rows = |file: &str| -> (Vec<String>, Vec<csv::StringRecord>) {
        let mut table = csv::Reader::from_path(out.join(file)).unwrap();
        let header = table.headers().unwrap().iter().map(String::from).collect();
        (header, table.records().map(|r| r.unwrap()).collect())
    };
    let (header, lanes) = rows("spectrum.csv");
    let status = header.iter().position(|h| h == "status").unwrap();
    for (k, lane) in lanes.iter().enumerate() {
        assert_eq!(
            &lane[status] == "inadmissible-start",
            k % nx >= 11,
            "start {k}: {lane:?}"
        );
    }
    let (header, attractors) = rows("attractors.csv");
    let col = |name: &str| header.iter().position(|h| h == name).unwrap();
    assert_eq!(
        attractors.len(),
        2,
        "the two orbits, no row for the starts not run"
    );
    let admissible = (ny * 11) as f64;
    let (s_b, s_bb) = entropy_by_hand(ny, nx, &past, 2);
    for row in &attractors {
        let label: i32 = row[col("branch")].parse().unwrap();
        let share = past.iter().filter(|&&l| l == label).count() as f64 / admissible;
        assert_eq!(row[col("basin_fraction")].parse::<f64>().unwrap(), share);
        let entropy: f64 = row[col("basin_entropy")].parse().unwrap();
        assert!((entropy - s_b).abs() < 1e-12, "{entropy} against {s_b}");
        let boundary: f64 = row[col("boundary_basin_entropy")].parse().unwrap();
        assert!((boundary - s_bb).abs() < 1e-12, "{boundary} against {s_bb}");
    }

    if gpu_or_skip(
        "starts_behind_the_wall_are_labelled_apart_and_left_out_of_the_measures",
        Precision::F64,
    ) {
        let gpu = scene_text(3, nx).replace(
            "backend = \"cpu\"",
            "backend = \"gpu\"\nprecision = \"f64\"",
        );
        let (_, on_gpu, _) = labels_of(&gpu, "gpu");
        assert_eq!(on_gpu, past);
    }
}

/// The basin labels of a grid of starts on the GPU (f64) are the CPU
/// path's, start by start, and so are each attractor's convergence times
/// (the GPU's from the references the host recomputes).
#[test]
fn basin_labels_on_the_gpu_are_the_cpu_s() {
    if !gpu_or_skip("basin_labels_on_the_gpu_are_the_cpu_s", Precision::F64) {
        return;
    }
    let text = format!(
        "{COEXISTING}[attractors]\ngrid = [16, 16]\nbox = {{ x = [-3, 1.9], v = [-3, 3] }}\nbasins = 1\n"
    );
    let labels = |text: &str| {
        let found = attractors_of(&common::scene(text, &[]));
        let times: Vec<_> = found.values[0]
            .attractors
            .iter()
            .map(|a| (a.branch, a.convergence()))
            .collect();
        let image = lyapsweep::attractor::basins::image(&found, 0, (16, 16));
        (image.labels, times)
    };
    let (cpu, cpu_times) = labels(&text);
    let (gpu, gpu_times) = labels(&text.replace(
        "backend = \"cpu\"",
        "backend = \"gpu\"\nprecision = \"f64\"",
    ));
    assert_eq!(cpu, gpu);
    assert!(cpu.contains(&0) && cpu.contains(&1), "{cpu:?}");
    assert_eq!(cpu_times, gpu_times);
    assert!(cpu_times.iter().all(|t| t.1.is_some()), "{cpu_times:?}");
}

/// The uncertainty exponent of a label file, computed here: pairs of
/// starts s cells apart along either state (s = 1, 2, 4, ... while 8s fits
/// the shorter side), from the starts that have a partner at the largest
/// s; α the least-squares slope of ln f(s) against ln s.
fn uncertainty_by_hand(rows: usize, columns: usize, labels: &[i32]) -> f64 {
    let mut shifts = vec![1];
    while 8 * 2 * shifts[shifts.len() - 1] <= rows.min(columns) {
        shifts.push(2 * shifts[shifts.len() - 1]);
    }
    let largest = shifts[shifts.len() - 1];
    let mut logs = Vec::new();
    for &s in &shifts {
        let (mut pairs, mut differ) = (0, 0);
        for r in 0..rows {
            for c in 0..columns {
                if c + largest < columns {
                    pairs += 1;
                    differ += usize::from(labels[r * columns + c] != labels[r * columns + c + s]);
                }
                if r + largest < rows {
                    pairs += 1;
                    differ += usize::from(labels[r * columns + c] != labels[(r + s) * columns + c]);
                }
            }
        }
        if differ > 0 {
            logs.push(((s as f64).ln(), (differ as f64 / pairs as f64).ln()));
        }
    }
    let n = logs.len() as f64;
    let mx = logs.iter().map(|p| p.0).sum::<f64>() / n;
    let my = logs.iter().map(|p| p.1).sum::<f64>() / n;
    let sxy: f64 = logs.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let sxx: f64 = logs.iter().map(|p| (p.0 - mx).powi(2)).sum();
    sxy / sxx
}

/// Each start's convergence time computed here: its reference iterated
/// from the start (`System::iterate`, as a lane steps it) for the run's
/// transient and iterations, and the iteration after the last point
/// farther than the attractor tolerance (1e-5 of max(1, |x|∞, |y|∞) in
/// f64) from `orbit_point`.
fn convergence_by_hand(scene: &lyapsweep::Scene, start: usize, orbit_point: [f64; 2]) -> usize {
    use lyapsweep::system::System;
    let settings =
        lyapsweep::plan::method_settings(scene, lyapsweep::scene::Backend::Cpu, Precision::F64);
    let system = lyapsweep::system::model::ModelFlow::<2>::new(&scene.lane_params(start));
    let flow = lyapsweep::orbit::map::flow_of(&system, &settings);
    let mut x = system.start(scene.lane_initial_state(start), &flow);
    let mut last_outside = None;
    for n in 0..=settings.transient + settings.iterations {
        if n > 0 {
            x = system.iterate(&x, &flow, &mut Default::default());
            system.wrap(&mut x);
        }
        let scale = x
            .iter()
            .chain(&orbit_point)
            .fold(1.0_f64, |m, v| m.max(v.abs()));
        let distance = (x[0] - orbit_point[0])
            .abs()
            .max((x[1] - orbit_point[1]).abs());
        if distance > 1e-5 * scale {
            last_outside = Some(n);
        }
    }
    last_outside.map_or(0, |n| n + 1)
}

/// The seed at η = 0.6 over a 32 × 32 grid with `basins = 1`: each
/// attractor's convergence times (mean, median, largest over its starts)
/// are those computed here start by start from the label file and the
/// orbit's point, and the value's uncertainty exponent and boundary
/// dimension are the file's; the two basins' boundary is smooth (α near 1).
#[test]
fn convergence_times_and_the_uncertainty_exponent_are_the_file_s() {
    let (nx, ny) = (32, 32);
    let text = format!(
        "{COEXISTING}[attractors]\ngrid = [{nx}, {ny}]\nbox = {{ x = [-3, 1.9], v = [-3, 3] }}\nbasins = 1\nbasin_box = 4\n"
    );
    let scene = common::scene(&text, &[]);
    let report = common::run(&scene);
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("set");
    lyapsweep::output::write(&scene, &report, &out).unwrap();
    let (_, _, labels) = read_npy_i32(&out.join("basins-0.npy"));
    let mut table = csv::Reader::from_path(out.join("attractors.csv")).unwrap();
    let header: Vec<String> = table.headers().unwrap().iter().map(String::from).collect();
    let col = |name: &str| header.iter().position(|h| h == name).unwrap();
    let rows: Vec<csv::StringRecord> = table.records().map(|r| r.unwrap()).collect();
    let number = |row: &csv::StringRecord, name: &str| row[col(name)].parse::<f64>().unwrap();
    assert_eq!(rows.len(), 2);
    let alpha = uncertainty_by_hand(ny, nx, &labels);
    assert!((0.7..1.3).contains(&alpha), "{alpha}");
    for row in &rows {
        assert!((number(row, "uncertainty_exponent") - alpha).abs() < 1e-12);
        assert!((number(row, "boundary_dimension") - (2.0 - alpha)).abs() < 1e-12);
        let label: i32 = row[col("branch")].parse().unwrap();
        assert_eq!(row[col("period")].parse::<usize>().unwrap(), 1);
        let point = [number(row, "x"), number(row, "v")];
        let mut times: Vec<usize> = (0..nx * ny)
            .filter(|&k| labels[k] == label)
            .map(|k| convergence_by_hand(&scene, k, point))
            .collect();
        times.sort_unstable();
        let n = times.len();
        let mean = times.iter().sum::<usize>() as f64 / n as f64;
        let median = if n % 2 == 1 {
            times[n / 2] as f64
        } else {
            0.5 * (times[n / 2 - 1] + times[n / 2]) as f64
        };
        let largest = times[n - 1];
        assert!(
            (number(row, "convergence_mean") - mean).abs() < 1e-9,
            "{} against {mean}",
            number(row, "convergence_mean")
        );
        assert_eq!(number(row, "convergence_median"), median);
        assert_eq!(number(row, "convergence_max") as usize, largest);
        assert!(largest > 0 && largest < 600, "{largest}");
    }
}

/// Early stops (`attractors.early_stop`, on by default with basin
/// images): the seed's oscillator at η = 0.6 and 1.3 over a 24 × 24 grid
/// of the box, its orbits learned from every fourth start along x and v, then its starts
/// stopped once their reference has stayed within the attractor
/// tolerance of a learned orbit for 10 iterations, labels every start as
/// the full transients do (`early_stop = 0`), start by start, with each
/// attractor's row, fraction and convergence times the same; most starts
/// stop, each stopped lane saying so in its status.
#[test]
fn early_stops_give_the_labels_of_the_full_transients() {
    let (nx, ny) = (24, 24);
    let text = format!(
        "{COEXISTING}[attractors]\ngrid = [{nx}, {ny}]\nbox = {{ x = [-3, 1.9], v = [-3, 3] }}\nbasins = 2\n"
    )
    .replace("values = [0.6]", "values = [0.6, 1.3]");
    let run = |text: &str| {
        let scene = common::scene(text, &[]);
        let batch = lyapsweep::plan::batch_lanes(&scene);
        let mut stopped = 0;
        let (summary, found) =
            lyapsweep::run_streaming(&scene, &Default::default(), batch, |_, report| {
                stopped += report
                    .lanes
                    .iter()
                    .filter(|l| matches!(l.status, LaneStatus::EarlyStop { .. }))
                    .count();
                Ok(())
            })
            .expect("the sweep runs");
        assert_eq!(summary.lanes, 2 * nx * ny, "one row per start");
        (found.expect("attractors"), stopped)
    };
    let (full, none) = run(&text.replace("basins = 2", "basins = 2\nearly_stop = 0"));
    let (early, stopped) = run(&text);
    assert_eq!(none, 0);
    assert!(
        stopped > nx * ny,
        "{stopped} of {} starts stopped",
        2 * nx * ny
    );
    for (point, eta) in [0.6, 1.3].into_iter().enumerate() {
        let labels = |found: &lyapsweep::Attractors| {
            lyapsweep::attractor::basins::image(found, point, (nx, ny)).labels
        };
        assert_eq!(labels(&early), labels(&full), "η = {eta}");
        let rows = |found: &lyapsweep::Attractors| -> Vec<String> {
            found.values[point]
                .attractors
                .iter()
                .map(|a| {
                    let lane = &a.first.lane;
                    assert!(!matches!(lane.status, LaneStatus::EarlyStop { .. }));
                    format!(
                        "{:?} {:?} {} {:?} {} {:?}",
                        a.branch,
                        lane.orbit_period,
                        lane.impacts_per_period,
                        lane.status,
                        a.starts,
                        a.convergence()
                    )
                })
                .collect()
        };
        assert_eq!(rows(&early), rows(&full), "η = {eta}");
    }
    let at = |found: &lyapsweep::Attractors| found.values[0].count();
    assert_eq!((at(&full), at(&early)), (2, 2));
}

/// Basin stability under a normal distribution of starts
/// (`attractors.distribution`): the seed at η = 0.6 from 400 starts drawn
/// around (x, v) = (-1, 0.5), truncated to the box; the starts have
/// the distribution's means and deviations within their sampling error
/// and lie in the box, and attractors.csv gives each attractor's fraction
/// with its binomial standard error √(f(1-f)/N). Uniform starts (the
/// default) are those drawn before the key existed.
#[test]
fn basin_stability_under_a_normal_distribution_of_starts() {
    let table = "starts = 400\nbox = { x = [-3, 1.9], v = [-3, 3] }\n";
    let normal = format!(
        "{table}distribution = {{ kind = \"normal\", mean = {{ x = -1.0, v = 0.5 }}, sd = {{ x = 0.5, v = 0.8 }} }}\n"
    );
    let text = format!("{COEXISTING}[attractors]\n{normal}");
    let scene = common::scene(&text, &[]);
    let states = &scene.sweep.starts.as_ref().unwrap().states;
    for (i, (mean, sd)) in [(-1.0, 0.5), (0.5, 0.8)].into_iter().enumerate() {
        let n = states.len() as f64;
        let m = states.iter().map(|s| s[i]).sum::<f64>() / n;
        let d = (states.iter().map(|s| (s[i] - m).powi(2)).sum::<f64>() / n).sqrt();
        assert!(
            (m - mean).abs() < 4.0 * sd / n.sqrt(),
            "state {i}: mean {m}"
        );
        assert!((d - sd).abs() < 0.15 * sd, "state {i}: sd {d}");
    }
    assert!(states
        .iter()
        .all(|s| (-3.0..=1.9).contains(&s[0]) && (-3.0..=3.0).contains(&s[1])));
    // The default distribution draws the starts uniform in the box as before:
    // lo + (hi - lo)·u per state of the box, in order, from the seed.
    let uniform = common::scene(&format!("{COEXISTING}[attractors]\n{table}"), &[]);
    let mut rng = fastrand::Rng::with_seed(1);
    let before: Vec<Vec<f64>> = (0..400)
        .map(|_| vec![-3.0 + 4.9 * rng.f64(), -3.0 + 6.0 * rng.f64()])
        .collect();
    assert_eq!(uniform.sweep.starts.as_ref().unwrap().states, before);

    let report = common::run(&scene);
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("set");
    lyapsweep::output::write(&scene, &report, &out).unwrap();
    let mut table = csv::Reader::from_path(out.join("attractors.csv")).unwrap();
    let header: Vec<String> = table.headers().unwrap().iter().map(String::from).collect();
    let col = |name: &str| header.iter().position(|h| h == name).unwrap();
    let rows: Vec<csv::StringRecord> = table.records().map(|r| r.unwrap()).collect();
    let mut total = 0.0;
    for row in &rows {
        let f: f64 = row[col("basin_fraction")].parse().unwrap();
        let error: f64 = row[col("basin_fraction_error")].parse().unwrap();
        assert!(
            (error - (f * (1.0 - f) / 400.0).sqrt()).abs() < 1e-15,
            "{f}: {error}"
        );
        total += f;
    }
    assert!((total - 1.0).abs() < 1e-12);
    assert!(!rows.is_empty());
}
