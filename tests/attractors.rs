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
    ];
    for (table, key, reason) in cases {
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
    // starts × values is a size like any other.
    let wide = COEXISTING.replace("values = [0.6]", "from = 0.5\nto = 1.5\ncount = 100000");
    let error = parse(
        &format!("{wide}[attractors]\nstarts = 100000\nbox = {{ x = [0, 1] }}\n"),
        &[],
    )
    .unwrap_err();
    assert!(error.to_string().contains("attractors.starts"), "{error}");
}
