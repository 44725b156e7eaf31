//! The GPU backend against the CPU reference path and the exact backend, on
//! whatever adapter exists (lavapipe in CI, where skipping is an error).

mod common;

use common::{assert_same_bits, gpu_or_skip, PERIODIC_ETAS, SEED};
use lyapsweep::method::lane::RESOLUTION_BOUND;
use lyapsweep::method::LaneStatus;
use lyapsweep::scene::{Backend, Precision};
use lyapsweep::{Report, RunOptions};

fn values(v: &[f64]) -> String {
    let list: Vec<String> = v.iter().map(|x| format!("{x}")).collect();
    format!("sweep.values=[{}]", list.join(", "))
}

fn run(text: &str, overrides: &[String], options: RunOptions) -> Report {
    let overrides: Vec<&str> = overrides.iter().map(String::as_str).collect();
    lyapsweep::run_with(&common::scene(text, &overrides), &options).expect("runs")
}

#[test]
fn f64_matches_the_cpu_per_iteration_and_in_exponents() {
    if !gpu_or_skip(
        "f64_matches_the_cpu_per_iteration_and_in_exponents",
        Precision::F64,
    ) {
        return;
    }
    let keep = RunOptions {
        keep_jacobians: true,
        ..Default::default()
    };
    for location in ["newton", "linear"] {
        let base = vec![
            values(&PERIODIC_ETAS),
            format!("integration.impact_location=\"{location}\""),
        ];
        let with = |backend: &str| {
            let mut o = base.clone();
            o.push(format!("run.backend=\"{backend}\""));
            o
        };
        let cpu = run(SEED, &with("cpu"), keep.clone());
        let gpu = run(SEED, &with("gpu"), keep.clone());
        assert_eq!(gpu.backend, Backend::Gpu);
        assert_eq!(gpu.precision, Precision::F64);
        for (k, eta) in PERIODIC_ETAS.iter().enumerate() {
            let (c, g) = (&cpu.lanes[k], &gpu.lanes[k]);
            // The paper's linear location misses the sum rule by 1.3e-3 at
            // η = 0.8 (the impact time off by the interpolation's error), and
            // both paths say so.
            assert_eq!(g.status, c.status, "{location} η = {eta}");
            if location == "newton" {
                assert_eq!(g.status, LaneStatus::Ok, "{location} η = {eta}");
            }
            assert_eq!(c.jacobians.len(), 1000 * 4);
            assert_eq!(g.jacobians.len(), c.jacobians.len());
            // Rounding differences (a fused multiply-add here, an operation
            // order there) are amplified by 1/δ = 1e8 in each column.
            let mut worst: f64 = 0.0;
            for (jc, jg) in c.jacobians.chunks(4).zip(g.jacobians.chunks(4)) {
                let scale = jc.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
                let diff = jc
                    .iter()
                    .zip(jg)
                    .fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()));
                worst = worst.max(diff / scale);
            }
            assert!(
                worst < 1e-6,
                "{location} η = {eta}: Jacobians differ by {worst:e} of their scale"
            );
            for (a, b) in c.exponents.iter().zip(&g.exponents) {
                assert!(
                    (a - b).abs() < 1e-7,
                    "{location} η = {eta}: CPU {:?} vs GPU {:?}",
                    c.exponents,
                    g.exponents
                );
            }
            assert_eq!(c.impacts_per_period, g.impacts_per_period);
        }
        let v = gpu.gpu.as_ref().unwrap().validation.as_ref().unwrap();
        assert!(v.max_difference < 1e-7, "validation {v:?}");
    }
}

#[test]
fn f32_matches_the_exact_backend_and_keeps_the_sum_rule() {
    if !gpu_or_skip(
        "f32_matches_the_exact_backend_and_keeps_the_sum_rule",
        Precision::F32,
    ) {
        return;
    }
    let exact = run(
        SEED,
        &[values(&PERIODIC_ETAS), "run.backend=\"exact\"".into()],
        RunOptions::default(),
    );
    let gpu = run(
        SEED,
        &[
            values(&PERIODIC_ETAS),
            "run.backend=\"gpu\"".into(),
            "run.precision=\"f32\"".into(),
        ],
        RunOptions::default(),
    );
    assert_eq!(gpu.precision, Precision::F32);
    for (k, eta) in PERIODIC_ETAS.iter().enumerate() {
        let (e, g) = (&exact.lanes[k], &gpu.lanes[k]);
        assert_eq!(g.status, LaneStatus::Ok);
        for (a, b) in e.exponents.iter().zip(&g.exponents) {
            assert!(
                (a - b).abs() < 5e-4,
                "η = {eta}: exact {:?} vs f32 {:?}",
                e.exponents,
                g.exponents
            );
        }
    }
    let sweep = run(
        SEED,
        &[
            "sweep.from=0.5".into(),
            "sweep.to=1.5".into(),
            "sweep.count=101".into(),
            "run.backend=\"gpu\"".into(),
            "run.precision=\"f32\"".into(),
        ],
        RunOptions::default(),
    );
    for (lane, expected) in sweep.lanes.iter().zip(&sweep.expected_sums) {
        assert_eq!(lane.status, LaneStatus::Ok);
        assert!(
            (lane.exponent_sum() - expected).abs() < 5e-4,
            "sum {} vs {expected}",
            lane.exponent_sum()
        );
    }
}

#[test]
fn henon_and_lorenz_match_their_published_values_on_the_gpu() {
    for precision in [Precision::F64, Precision::F32] {
        if !gpu_or_skip(
            "henon_and_lorenz_match_their_published_values_on_the_gpu",
            precision,
        ) {
            continue;
        }
        let p = precision.name();
        let henon = lyapsweep::run(&common::committed_scene(
            "henon.toml",
            &["run.backend=\"gpu\"", &format!("run.precision=\"{p}\"")],
        ))
        .unwrap();
        let l = &henon.lanes[0].exponents;
        // f64 as on the CPU. In f32 a chaotic map's orbit is itself rounded at
        // 6e-8 per step and settles on a slightly different (eventually
        // periodic) orbit: measured λ1 = 0.41716 at 10⁵ and 0.41586 at 4·10⁵
        // iterations, against 0.41801 and 0.41882 in f64. That is the
        // arithmetic's orbit, not the method's error, so f32 gets 5e-3.
        let (tolerance, sum_tolerance) = if precision == Precision::F64 {
            // The sum is ln b up to the rounding of each difference column,
            // about 1e-8 per iteration at δ = 1e-8. On the CPU it averages to
            // 1e-11 over 10⁵ iterations; on lavapipe's f64 (contracted to
            // fused multiply-adds) 1.5e-9, measured.
            (2e-3, 1e-8)
        } else {
            // Measured 1.7e-5.
            (5e-3, 5e-5)
        };
        assert!(
            (l[0] - 0.41922).abs() < tolerance && (l[1] - -1.62319).abs() < tolerance,
            "{p} Hénon {l:?}"
        );
        assert!(
            (l[0] + l[1] - 0.3_f64.ln()).abs() < sum_tolerance,
            "{p} Hénon sum {}",
            l[0] + l[1]
        );

        let lorenz = lyapsweep::run(&common::committed_scene(
            "lorenz.toml",
            &["run.backend=\"gpu\"", &format!("run.precision=\"{p}\"")],
        ))
        .unwrap();
        let l = &lorenz.lanes[0].exponents;
        for (got, published) in l.iter().zip([0.9056, 0.0, -14.5723]) {
            assert!((got - published).abs() < 0.02, "{p} Lorenz {l:?}");
        }
        let sum: f64 = l.iter().sum();
        assert!(
            (sum - -(10.0 + 1.0 + 8.0 / 3.0)).abs() < 1e-3,
            "{p} Lorenz sum {sum}"
        );
    }
}

#[test]
fn large_sweeps_split_into_batches_and_match_the_cpu() {
    let precision = if gpu_or_skip("large_sweeps (f64)", Precision::F64) {
        Precision::F64
    } else if gpu_or_skip("large_sweeps (f32)", Precision::F32) {
        Precision::F32
    } else {
        return;
    };
    let p = precision.name();
    for (count, steps, max_batch_lanes, batches) in
        [(4096, 60, None, 1), (100_000, 20, Some(40_000), 3)]
    {
        let overrides = vec![
            "sweep.from=0.5".to_owned(),
            "sweep.to=1.5".to_owned(),
            format!("sweep.count={count}"),
            format!("integration.steps_per_period={steps}"),
            "integration.transient=5".to_owned(),
            "integration.iterations=10".to_owned(),
            "output.bifurcation_points=2".to_owned(),
            "run.backend=\"gpu\"".to_owned(),
            format!("run.precision=\"{p}\""),
            "run.validate=8".to_owned(),
        ];
        let report = run(
            SEED,
            &overrides,
            RunOptions {
                max_batch_lanes,
                ..Default::default()
            },
        );
        assert_eq!(report.lanes.len(), count);
        let gpu = report.gpu.as_ref().unwrap();
        // At least the forced split; more where the device's dispatch limit
        // binds first.
        assert!(
            gpu.batches >= batches,
            "{count} values: {} batches",
            gpu.batches
        );
        let v = gpu.validation.as_ref().unwrap();
        assert_eq!(v.lanes.len(), 8);
        assert!(v.lanes.contains(&0) && v.lanes.contains(&(count - 1)));
        let tolerance = if precision == Precision::F64 {
            1e-7
        } else {
            1e-3
        };
        assert!(
            v.max_difference < tolerance,
            "{count} values: GPU vs CPU {:e}",
            v.max_difference
        );
        // A lane of the chaotic window may miss the sum rule by a little more
        // than 1e-6 (the seed sweep's worst, 1.2e-6), or carry a standard
        // error above a tenth of its λ1, and say so.
        assert!(report.lanes.iter().all(|l| l.status == LaneStatus::Ok
            || matches!(
                l.status,
                LaneStatus::Unresolved { .. }
                    | LaneStatus::SumRule { .. }
                    | LaneStatus::Uncertain { .. }
            )));
        assert!(report
            .lanes
            .iter()
            .all(|l| l.bifurcation.len() == 4 && l.exponents.len() == 2));
    }
}

#[test]
fn variants_without_wall_or_copies_match_the_cpu() {
    if !gpu_or_skip(
        "variants_without_wall_or_copies_match_the_cpu",
        Precision::F64,
    ) {
        return;
    }
    let base = [
        values(&[0.8, 1.2]),
        "integration.steps_per_period=200".to_owned(),
        "integration.transient=20".to_owned(),
        "integration.iterations=50".to_owned(),
        "output.bifurcation_points=5".to_owned(),
    ];
    for extra in ["system.wall=30.0", "output.lyapunov=\"none\""] {
        let with = |backend: &str| {
            let mut o = base.to_vec();
            o.push(extra.to_owned());
            o.push(format!("run.backend=\"{backend}\""));
            o
        };
        let cpu = run(SEED, &with("cpu"), RunOptions::default());
        let gpu = run(SEED, &with("gpu"), RunOptions::default());
        let name = &gpu.gpu.as_ref().unwrap().variant;
        if extra.contains("wall") {
            assert!(name.contains("no-wall"), "{name}");
        } else {
            assert!(name.contains("reference-only"), "{name}");
            assert!(gpu.lanes.iter().all(|l| l.exponents.is_empty()));
        }
        for (c, g) in cpu.lanes.iter().zip(&gpu.lanes) {
            for (a, b) in c.exponents.iter().zip(&g.exponents) {
                assert!(
                    (a - b).abs() < 1e-9,
                    "{extra}: {:?} vs {:?}",
                    c.exponents,
                    g.exponents
                );
            }
            assert_eq!(c.bifurcation.len(), g.bifurcation.len());
            for (a, b) in c.bifurcation.iter().zip(&g.bifurcation) {
                assert!((a - b).abs() < 1e-10, "{extra}: points {a} vs {b}");
            }
        }
    }
}

#[test]
fn workgroup_size_changes_no_digit_and_device_time_is_measured() {
    for precision in [Precision::F64, Precision::F32] {
        let p = precision.name();
        if !gpu_or_skip(
            "workgroup_size_changes_no_digit_and_device_time_is_measured",
            precision,
        ) {
            continue;
        }
        // A hard mix: the seed's chaotic and grazing window, sticking (f = 3),
        // e = 0 and an overflowing forcing, 100 values each, so no size
        // divides the lane or trajectory count. Size 1 puts every invocation
        // alone in its SIMD group: on lavapipe, an earlier impact kernel let
        // a chattering lane change its neighbours there (docs/STABILITY.md,
        // "lavapipe's loop cap").
        let scenes: [&[&str]; 3] = [
            &["sweep.from=0.69", "sweep.to=0.74", "sweep.count=100"],
            &[
                "system.f=3",
                "system.restitution=0.5",
                "sweep.from=0.2",
                "sweep.to=1.5",
                "sweep.count=100",
            ],
            &[
                "system.restitution=0",
                "sweep.parameter=\"f\"",
                "sweep.from=0.5",
                "sweep.to=1e10",
                "sweep.count=100",
            ],
        ];
        for scene in scenes {
            let mut overrides: Vec<String> = scene.iter().map(|s| s.to_string()).collect();
            overrides.extend([
                "run.backend=\"gpu\"".to_owned(),
                format!("run.precision=\"{p}\""),
                "run.validate=0".to_owned(),
                "integration.steps_per_period=200".to_owned(),
                "integration.transient=20".to_owned(),
                "integration.iterations=40".to_owned(),
                "output.bifurcation_points=1".to_owned(),
            ]);
            let reports: Vec<Report> = [1, 32, 64, 256]
                .iter()
                .map(|&size| {
                    let options = RunOptions {
                        workgroup_size: Some(size),
                        ..Default::default()
                    };
                    run(SEED, &overrides, options)
                })
                .collect();
            for other in &reports[1..] {
                for (k, (a, b)) in reports[0].lanes.iter().zip(&other.lanes).enumerate() {
                    let same = |x: &f64, y: &f64| x == y || (x.is_nan() && y.is_nan());
                    assert!(
                        a.exponents
                            .iter()
                            .zip(&b.exponents)
                            .all(|(x, y)| same(x, y)),
                        "{p} {scene:?} lane {k}: bit for bit"
                    );
                    assert_eq!(a.bifurcation, b.bifurcation, "{p} {scene:?} lane {k}");
                    assert_eq!(a.status, b.status);
                }
            }
            // Where the adapter has timestamp queries (lavapipe does), the
            // device time of the passes is reported, positive, and inside the
            // wall time of the transient and averaging phases.
            let summary = lyapsweep::backend::gpu::context::list();
            if summary.iter().any(|s| s.timestamps) {
                for r in &reports {
                    let t = r.gpu.as_ref().expect("gpu report").timings;
                    let busy = t.gpu_busy.expect("timestamp queries ran").as_secs_f64();
                    let wall = (t.transient + t.averaging).as_secs_f64();
                    assert!(
                        busy > 0.0 && busy <= wall * 1.05 + 1e-3,
                        "{busy} s of {wall} s"
                    );
                }
            }
        }
    }
}

#[test]
fn a_sweep_dispatched_in_rows_or_short_dispatches_is_the_sweep_in_one_row() {
    for precision in [Precision::F64, Precision::F32] {
        let p = precision.name();
        let test = "a_sweep_dispatched_in_rows_or_short_dispatches_is_the_sweep_in_one_row";
        if !gpu_or_skip(test, precision) {
            continue;
        }
        // The seed's chaotic and grazing window, 1 000 values: 5 000
        // trajectories, 79 workgroups of 64. Ten to a row is one batch in
        // rows; three to a row holds 576 invocations a dispatch, so the
        // sweep is also split into batches of 115 lanes.
        let overrides: Vec<String> = [
            "sweep.from=0.69",
            "sweep.to=0.74",
            "sweep.count=1000",
            "run.backend=\"gpu\"",
            "run.validate=0",
            "integration.steps_per_period=200",
            "integration.transient=10",
            "integration.iterations=20",
            "output.bifurcation_points=1",
        ]
        .iter()
        .map(|s| s.to_string())
        .chain([format!("run.precision=\"{p}\"")])
        .collect();
        let one_row = run(SEED, &overrides, RunOptions::default());
        assert_eq!(one_row.gpu.as_ref().unwrap().batches, 1);
        for (width, batches) in [(10, 1), (3, 9)] {
            let options = RunOptions {
                workgroups_per_row: Some(width),
                ..Default::default()
            };
            let rows = run(SEED, &overrides, options);
            assert_eq!(rows.gpu.as_ref().unwrap().batches, batches, "{p} {width}");
            let impacts = assert_same_bits(&rows, &one_row, &format!("{p}, {width} a row"));
            assert!(impacts > 0.0, "the window meets the wall");
        }
        // Three RK4 steps a dispatch (a budget of 15 000 lane-steps) instead
        // of the whole period: the state goes through memory between
        // dispatches in full, so the numbers are the same.
        let options = RunOptions {
            dispatch_lane_steps: Some(15_000),
            ..Default::default()
        };
        let short = run(SEED, &overrides, options);
        assert_eq!(short.gpu.as_ref().unwrap().chunk_steps, 3);
        assert_same_bits(&short, &one_row, &format!("{p}, 3 steps a dispatch"));
    }
}

#[test]
fn a_faulty_or_chattering_lane_touches_no_other_lane() {
    for precision in [Precision::F64, Precision::F32] {
        let p = precision.name();
        if !gpu_or_skip(
            "a_faulty_or_chattering_lane_touches_no_other_lane",
            precision,
        ) {
            continue;
        }
        // 70 lanes of f = 1, but lane 10 overflows (f = 1e308) and lane 60
        // bounces violently (f = 1e10). On lavapipe, with SIMD groups of 8,
        // an earlier impact kernel let lane 60 change lanes 56 to 63.
        let mut f = vec![1.0; 70];
        f[10] = 1e308;
        f[60] = 1e10;
        let base = |v: &[f64]| {
            let list: Vec<String> = v.iter().map(|x| format!("{x:e}")).collect();
            vec![
                "sweep.parameter=\"f\"".to_owned(),
                format!("sweep.values=[{}]", list.join(", ")),
                "run.backend=\"gpu\"".to_owned(),
                format!("run.precision=\"{p}\""),
                "run.validate=0".to_owned(),
                "integration.transient=50".to_owned(),
                "integration.iterations=100".to_owned(),
                "output.bifurcation_points=1".to_owned(),
            ]
        };
        let mixed = run(SEED, &base(&f), RunOptions::default());
        let clean = run(SEED, &base(&[1.0]), RunOptions::default());
        assert!(
            matches!(mixed.lanes[10].status, LaneStatus::NonFinite { .. }),
            "{p}: {}",
            mixed.lanes[10].status
        );
        for (k, lane) in mixed.lanes.iter().enumerate() {
            if k == 10 || k == 60 {
                continue;
            }
            assert_eq!(lane.status, LaneStatus::Ok, "{p} lane {k}");
            assert_eq!(lane.exponents, clean.lanes[0].exponents, "{p} lane {k}");
            assert_eq!(lane.bifurcation, clean.lanes[0].bifurcation, "{p} lane {k}");
        }
        // Lane 60 (f = 1e10) is whatever its own dynamics make it.
        assert!(mixed.flagged() >= 1);
    }
}

#[test]
fn f32_perturbations_from_1e_2_to_1e_6_are_answered_or_flagged() {
    if !gpu_or_skip(
        "f32_perturbations_from_1e_2_to_1e_6_are_answered_or_flagged",
        Precision::F32,
    ) {
        return;
    }
    // Measured on lavapipe: 1e-4 keeps the sum rule to 1e-4 at all three
    // values; 1e-2 flags the chaotic value `chattering` (copies that far
    // from the reference meet the wall elsewhere); 1e-6 is `unresolved`
    // (bounds 5.5e-3 to 1.8). Below 4.8e-7 the scene is refused.
    for delta in [1e-2, 1e-4, 1e-6] {
        let overrides = vec![
            "sweep.values=[0.8, 0.715, 1.25]".to_owned(),
            "run.backend=\"gpu\"".to_owned(),
            "run.precision=\"f32\"".to_owned(),
            "run.validate=0".to_owned(),
            format!("integration.perturbation={delta:e}"),
        ];
        let report = run(SEED, &overrides, RunOptions::default());
        common::assert_answered_or_flagged(&report, delta);
        if delta == 1e-4 {
            assert!(report.lanes.iter().all(|l| l.status == LaneStatus::Ok));
            let error = report.max_sum_error().unwrap();
            assert!(error < 1e-4, "δ = 1e-4: sum-rule error {error:e}");
        }
    }
}

#[test]
fn sticking_and_perfectly_inelastic_impacts_match_the_cpu() {
    // Sticking (f = 3 > X_w = 2, e = 0.5; η = 0.3 sticks every period) and
    // e = 0 (λ2 = -∞): the kernels' sticking model and rank-loss flags
    // against the CPU path's.
    let scenes: [&[&str]; 2] = [
        &[
            "system.f=3",
            "system.restitution=0.5",
            "sweep.values=[0.3, 0.5, 0.8, 1.2]",
        ],
        &["system.restitution=0", "sweep.values=[0.8, 0.9, 1.2]"],
    ];
    for precision in [Precision::F64, Precision::F32] {
        let p = precision.name();
        if !gpu_or_skip(
            "sticking_and_perfectly_inelastic_impacts_match_the_cpu",
            precision,
        ) {
            continue;
        }
        let (exponent_tolerance, point_tolerance) = if precision == Precision::F64 {
            (1e-6, 1e-9)
        } else {
            // Measured: 5e-4 in λ (η = 0.5 sticking scene), 2e-7 in the points.
            (5e-3, 1e-4)
        };
        for scene in scenes {
            let mut overrides: Vec<String> = scene.iter().map(|s| s.to_string()).collect();
            overrides.extend([
                "integration.transient=100".to_owned(),
                "integration.iterations=200".to_owned(),
                "output.bifurcation_points=1".to_owned(),
            ]);
            let with = |backend: &str, precision: &str| {
                let mut o = overrides.clone();
                o.push(format!("run.backend=\"{backend}\""));
                o.push(format!("run.precision=\"{precision}\""));
                o
            };
            let cpu = run(SEED, &with("cpu", "f64"), RunOptions::default());
            let gpu = run(SEED, &with("gpu", p), RunOptions::default());
            assert!(cpu.lanes.iter().any(|l| l.status != LaneStatus::Ok));
            for (k, (c, g)) in cpu.lanes.iter().zip(&gpu.lanes).enumerate() {
                assert_eq!(g.status, c.status, "{p} {scene:?} lane {k}");
                for (x, y) in c.exponents.iter().zip(&g.exponents) {
                    if x.is_infinite() {
                        assert_eq!(x, y, "{p} {scene:?} lane {k}");
                    } else {
                        assert!(
                            (x - y).abs() < exponent_tolerance,
                            "{p} {scene:?} lane {k}: {x} vs gpu {y}"
                        );
                    }
                }
                for (x, y) in c.bifurcation.iter().zip(&g.bifurcation) {
                    assert!((x - y).abs() < point_tolerance, "{p} lane {k}: {x} vs {y}");
                }
            }
        }
    }
}

#[test]
fn a_long_f32_run_keeps_the_forcing_phase() {
    if !gpu_or_skip("a_long_f32_run_keeps_the_forcing_phase", Precision::F32) {
        return;
    }
    // 10⁵ iterations: the forcing phase restarts at every period and no time
    // variable exists, so an f32 run stays on the f64 orbit (a drifting phase
    // would rotate the stroboscopic point). Measured at 10⁶ iterations
    // (docs/STABILITY.md, 324 s on lavapipe): within 6e-7 of the f64 CPU.
    let overrides = |backend: &str, precision: &str| {
        vec![
            "sweep.values=[0.8, 1.1]".to_owned(),
            "integration.steps_per_period=80".to_owned(),
            "integration.transient=99900".to_owned(),
            "integration.iterations=100".to_owned(),
            "output.lyapunov=\"none\"".to_owned(),
            "output.bifurcation_points=1".to_owned(),
            format!("run.backend=\"{backend}\""),
            format!("run.precision=\"{precision}\""),
        ]
    };
    let cpu = run(SEED, &overrides("cpu", "f64"), RunOptions::default());
    let gpu = run(SEED, &overrides("gpu", "f32"), RunOptions::default());
    for (c, g) in cpu.lanes.iter().zip(&gpu.lanes) {
        assert_eq!(g.status, LaneStatus::Ok);
        assert!(c.impacts_per_period > 0.0);
        assert_eq!(c.impacts_per_period, g.impacts_per_period);
        for (x, y) in c.bifurcation.iter().zip(&g.bifurcation) {
            assert!((x - y).abs() < 1e-5, "f64 {x} vs f32 {y}");
        }
    }
}

#[test]
fn grazing_iterations_are_re_estimated_on_the_host() {
    // η = 0.71172 at 1800 steps: one iteration meets the wall at speed 1e-3
    // (tests/stability.rs). Without re-estimation the GPU missed the sum
    // rule by 3.7e-2 at δ = 1e-6; the host redoes flagged iterations on the
    // CPU with the δ ladder. Measured: f64 flags the CPU's 3 iterations and
    // matches it to 7e-14 (1.6e-6 off the sum rule).
    //
    // f32 (δ = 2e-4) re-estimates only the iterations whose truncation error
    // is above its own rounding (`is_grazing`): 12 here, 1.04e-5 off the sum
    // rule. Flagging all 85 above 1e-4 gave 7.9e-7, more accurate than f32
    // is elsewhere: over a 512-value seed sweep in f32 (transient 100,
    // iterations 200) ordinary lanes are off by 7.8e-6 in the median and up
    // to 1.5e-4, and grazing lanes left unflagged by up to 1.9e-3. So f32's
    // bound is the one its ordinary lanes meet, f64's the method's.
    for precision in [Precision::F64, Precision::F32] {
        let p = precision.name();
        if !gpu_or_skip("grazing_iterations_are_re_estimated_on_the_host", precision) {
            continue;
        }
        let overrides = vec![
            "sweep.values=[0.7117216117216117]".to_owned(),
            "integration.steps_per_period=1800".to_owned(),
            "run.backend=\"gpu\"".to_owned(),
            format!("run.precision=\"{p}\""),
        ];
        let report = run(SEED, &overrides, RunOptions::default());
        let lane = &report.lanes[0];
        assert_eq!(lane.status, LaneStatus::Ok, "{p}");
        assert!(lane.grazing >= 1, "{p}: no grazing iteration flagged");
        let error = (lane.exponent_sum() - -0.1).abs();
        let bound = match precision {
            Precision::F64 => 1e-5,
            Precision::F32 => 1.5e-4,
        };
        assert!(error < bound, "{p}: sum rule off by {error:e}");
    }
}

#[test]
fn grazing_sub_maps_are_re_estimated_from_their_own_start() {
    if !gpu_or_skip(
        "grazing_sub_maps_are_re_estimated_from_their_own_start",
        Precision::F64,
    ) {
        return;
    }
    // The grazing lane above, each iteration cut into 20 sub-maps: the host
    // re-estimates a flagged part from the reference's state at the part's
    // start and the forcing phase there, as the CPU path does. Measured:
    // parts 0 and 2 graze, and the GPU matches the CPU to 3e-12; with the
    // phase left at 0 for part 2, λ1 was 1e-4 off.
    let with = |backend: &str| {
        vec![
            "sweep.values=[0.7117216117216117]".to_owned(),
            "integration.steps_per_period=1800".to_owned(),
            "integration.submaps=20".to_owned(),
            format!("run.backend=\"{backend}\""),
        ]
    };
    let gpu = run(SEED, &with("gpu"), RunOptions::default());
    let cpu = run(SEED, &with("cpu"), RunOptions::default());
    let (g, c) = (&gpu.lanes[0], &cpu.lanes[0]);
    assert_eq!(g.plan.parts, 20);
    assert_eq!(g.status, LaneStatus::Ok);
    assert!(g.grazing >= 1, "no grazing part flagged");
    assert_eq!(g.grazing, c.grazing);
    for (x, y) in g.exponents.iter().zip(&c.exponents) {
        assert!((x - y).abs() < 1e-9, "gpu {x} vs cpu {y}");
    }
    let error = (g.exponent_sum() - -0.1).abs();
    assert!(error < 1e-5, "sum rule off by {error:e}");
}

/// Over-damped lanes (ζ = 20 and 2, no wall in reach): steps raised and each
/// iteration cut into sub-maps on the GPU as on the CPU (tests/stability.rs).
/// Both exponents come out in both precisions: against the CPU run with the
/// GPU's plan, and against the closed form -ζ ± √(ζ² - 1).
#[test]
fn stiff_lanes_are_cut_into_sub_maps_on_the_gpu() {
    for precision in [Precision::F64, Precision::F32] {
        let p = precision.name();
        if !gpu_or_skip("stiff_lanes_are_cut_into_sub_maps_on_the_gpu", precision) {
            continue;
        }
        for zeta in [20.0, 2.0] {
            let base = [
                format!("system.zeta={zeta}"),
                "system.wall=100".to_owned(),
                "sweep.values=[0.1, 0.2]".to_owned(),
                "integration.transient=5".to_owned(),
                "integration.iterations=50".to_owned(),
            ];
            let with = |extra: &[String]| {
                let mut o = base.to_vec();
                o.extend_from_slice(extra);
                o
            };
            // f32 at its default δ; the CPU (f64 only) takes the same δ.
            let delta = if precision == Precision::F64 {
                "1e-6"
            } else {
                "2e-4"
            };
            let gpu = run(
                SEED,
                &with(&[
                    "run.backend=\"gpu\"".into(),
                    format!("run.precision=\"{p}\""),
                    format!("integration.perturbation={delta}"),
                ]),
                RunOptions::default(),
            );
            let plan = gpu.lanes[0].plan;
            assert!(plan.parts > 1, "{p} ζ = {zeta}: {plan:?}");
            assert_eq!(plan.steps_per_period % plan.parts, 0);
            // The CPU path with the GPU's plan, in the same δ.
            let cpu = run(
                SEED,
                &with(&[
                    "run.backend=\"cpu\"".into(),
                    format!("integration.perturbation={delta}"),
                    format!("integration.steps_per_period={}", plan.steps_per_period),
                    format!("integration.submaps={}", plan.parts),
                ]),
                RunOptions::default(),
            );
            let kappa = f64::sqrt(zeta * zeta - 1.0);
            let closed = [-zeta + kappa, -zeta - kappa];
            for (k, eta) in [0.1, 0.2].into_iter().enumerate() {
                let (g, c) = (&gpu.lanes[k], &cpu.lanes[k]);
                // RK4 planned at h·ρ = 0.1 has a relative error near 1e-6 in
                // the fast exponent: the sum rule may say so (ζ = 2: 4.7e-6
                // against 4.0e-6).
                assert!(
                    matches!(c.status, LaneStatus::Ok | LaneStatus::SumRule { .. }),
                    "cpu ζ = {zeta}, η = {eta}: {:?}",
                    c.status
                );
                assert_eq!(g.plan, plan);
                assert_eq!(c.plan, plan);
                let period = std::f64::consts::TAU / eta;
                // f64: the same arithmetic up to operation order (measured:
                // λ1 within a relative 1.2e-10, λ2 within 4e-14). f32 runs
                // at the edge of what it resolves (ζ = 20: ln R_11 of a part
                // is 2e-3 against rounding noise of 3e-4; λ1 measured 1e-4
                // off): the lane's own resolution bound must cover its
                // error, and a lane past 1e-3 says `unresolved`.
                let bound = match g.status {
                    LaneStatus::Ok | LaneStatus::SumRule { .. } => RESOLUTION_BOUND,
                    LaneStatus::Unresolved { bound } if precision == Precision::F32 => bound,
                    ref other => panic!("{p} ζ = {zeta}, η = {eta}: {other:?}"),
                };
                for i in 0..2 {
                    let (x, y) = (g.exponents[i], c.exponents[i]);
                    let difference = (x - y).abs();
                    let within = if precision == Precision::F64 {
                        [1e-9, 1e-12][i] * y.abs()
                    } else {
                        bound
                    };
                    assert!(
                        difference < within,
                        "{p} ζ = {zeta}, η = {eta}: λ{} gpu {x} vs cpu {y}",
                        i + 1
                    );
                    // The closed form, up to the QR's start (tests/stability.rs).
                    assert!(
                        (x - closed[i]).abs() < 1.0 / (50.0 * period),
                        "{p} ζ = {zeta}, η = {eta}: λ{} {x} vs closed form {}",
                        i + 1,
                        closed[i]
                    );
                }
            }
        }
    }
}

/// Over-damped with a reachable wall (tests/stability.rs): the mass sticks
/// every period, on the GPU as on the CPU, in sub-mapped iterations. Each
/// period's bounces onto the wall (e = 1) run lavapipe past its loop cap
/// within 256 steps per dispatch: the batch is redone with shorter
/// dispatches, and before that check existed the GPU's mass ended the
/// period far from the wall it should rest on.
#[test]
fn stiff_lanes_stick_on_the_wall_on_the_gpu() {
    for precision in [Precision::F64, Precision::F32] {
        let p = precision.name();
        if !gpu_or_skip("stiff_lanes_stick_on_the_wall_on_the_gpu", precision) {
            continue;
        }
        let zeta = 20.0;
        let base = [
            format!("system.zeta={zeta}"),
            format!("system.wall={}", 0.3 / (2.0 * zeta * 0.2)),
            "sweep.values=[0.1, 0.2]".to_owned(),
            "integration.transient=5".to_owned(),
            "integration.iterations=50".to_owned(),
            "output.bifurcation_points=1".to_owned(),
        ];
        let with = |extra: &[String]| {
            let mut o = base.to_vec();
            o.extend_from_slice(extra);
            o
        };
        let gpu = run(
            SEED,
            &with(&[
                "run.backend=\"gpu\"".into(),
                format!("run.precision=\"{p}\""),
            ]),
            RunOptions::default(),
        );
        let plan = gpu.lanes[0].plan;
        assert!(plan.parts > 1, "{p}: {plan:?}");
        let cpu = run(
            SEED,
            &with(&[
                "run.backend=\"cpu\"".into(),
                format!("integration.steps_per_period={}", plan.steps_per_period),
                format!("integration.submaps={}", plan.parts),
            ]),
            RunOptions::default(),
        );
        for (k, (g, c)) in gpu.lanes.iter().zip(&cpu.lanes).enumerate() {
            assert_eq!(
                g.status,
                LaneStatus::Collapsed { exponents: 2 },
                "{p} lane {k}"
            );
            assert_eq!(c.status, g.status, "{p} lane {k}");
            assert!(g.exponents.iter().all(|&l| l == f64::NEG_INFINITY));
            // Measured: f64 to the last digit, f32 within 1.4e-6.
            let tolerance = if precision == Precision::F64 {
                1e-9
            } else {
                1e-5
            };
            for (x, y) in g.bifurcation.iter().zip(&c.bifurcation) {
                assert!(
                    (x - y).abs() < tolerance,
                    "{p} lane {k}: gpu {x} vs cpu {y}"
                );
            }
        }
    }
}

/// Extreme sweeps (tests/stability.rs, case 5) on the GPU: η over three
/// decades in one batch (every lane at the steps η = 0.01 needs), forcing up
/// to 100 times the seed's, and a wall out of reach.
#[test]
fn extreme_sweeps_keep_the_sum_rule_on_the_gpu() {
    for precision in [Precision::F64, Precision::F32] {
        let p = precision.name();
        if !gpu_or_skip("extreme_sweeps_keep_the_sum_rule_on_the_gpu", precision) {
            continue;
        }
        let sweep = |extra: &[&str]| {
            let mut o: Vec<String> = extra.iter().map(|s| s.to_string()).collect();
            o.extend([
                "integration.transient=100".to_owned(),
                "integration.iterations=200".to_owned(),
                "run.backend=\"gpu\"".to_owned(),
                format!("run.precision=\"{p}\""),
            ]);
            run(SEED, &o, RunOptions::default())
        };
        // Measured: f64 within 2.8e-7 of the sum rule (η = 0.01), f32 within
        // 7e-5 (the f32 tolerance of the other GPU tests is 5e-4); λ = -ζ
        // within 3e-5 without impacts.
        let tolerance = if precision == Precision::F64 {
            1e-6
        } else {
            5e-4
        };
        common::assert_extreme_sweeps(sweep, tolerance, p);
    }
}

/// A shard runs its lanes as the whole sweep would: the GPU takes the plan
/// (steps, sub-maps) of the whole sweep, not of the shard's lanes, so the
/// merged shards are the unsharded run to the last bit.
#[test]
fn a_gpu_shard_runs_its_lanes_as_the_whole_sweep_does() {
    if !gpu_or_skip(
        "a_gpu_shard_runs_its_lanes_as_the_whole_sweep_does",
        Precision::F64,
    ) {
        return;
    }
    // Only lane 1 (ζ = 2) needs raised steps and sub-maps; shard 0 of 2
    // holds lanes 0 and 2 (ζ = 0.05, 0.1), which alone would need neither.
    let overrides = [
        "sweep.parameter=\"zeta\"",
        "sweep.values=[0.05, 2.0, 0.1]",
        "system.eta=0.2",
        "system.wall=100",
        "integration.transient=5",
        "integration.iterations=30",
        "run.backend=\"gpu\"",
    ];
    let scene = common::scene(SEED, &overrides);
    let whole = lyapsweep::run(&scene).expect("runs");
    for index in 0..2 {
        let shard = lyapsweep::scene::Shard { index, count: 2 };
        let part = lyapsweep::run(&scene.clone().sharded(shard).unwrap()).expect("runs");
        for (j, lane) in part.lanes.iter().enumerate() {
            let k = index + 2 * j;
            assert_eq!(lane.plan, whole.lanes[k].plan, "lane {k}");
            assert!(lane.plan.parts > 1, "lane {k} runs the whole sweep's plan");
            assert_eq!(lane.exponents, whole.lanes[k].exponents, "lane {k}");
        }
    }
}

/// The lane of tests/stability.rs whose copy would start behind the wall:
/// the finish kernel flags such a copy when it seeds it, and the GPU gives
/// the CPU's exponents (central: the other side; forward: re-estimated).
#[test]
fn a_copy_seeded_behind_the_wall_is_handled_as_on_the_cpu() {
    if !gpu_or_skip(
        "a_copy_seeded_behind_the_wall_is_handled_as_on_the_cpu",
        Precision::F64,
    ) {
        return;
    }
    for difference in ["central", "forward"] {
        let with = |backend: &str| {
            vec![
                "system.f=1.083170254403131".to_owned(),
                "sweep.values=[0.8228962818003913]".to_owned(),
                "integration.steps_per_period=150".to_owned(),
                "integration.transient=200".to_owned(),
                "integration.iterations=400".to_owned(),
                format!("integration.difference=\"{difference}\""),
                format!("run.backend=\"{backend}\""),
            ]
        };
        let cpu = run(SEED, &with("cpu"), RunOptions::default());
        let gpu = run(SEED, &with("gpu"), RunOptions::default());
        let (c, g) = (&cpu.lanes[0], &gpu.lanes[0]);
        assert_eq!(g.status, LaneStatus::Ok);
        assert_eq!(g.grazing, c.grazing, "{difference}");
        // Measured: within 5e-14.
        for (x, y) in g.exponents.iter().zip(&c.exponents) {
            assert!((x - y).abs() < 1e-9, "{difference}: gpu {x} vs cpu {y}");
        }
    }
}
