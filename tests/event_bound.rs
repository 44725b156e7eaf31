//! A lane whose trajectory meets events without end in one iteration: the
//! impact pair under strong negative damping, where energy pumped in
//! between impacts shortens the flights until a period holds hundreds of
//! thousands of located impacts (never 64 in one step). Such a lane ends
//! with `too-many-events(iteration=k)` on every path it can run (the native
//! step loops, the tape's interpreter, the GPU's kernels in f64 and f32,
//! the exact propagator), and no other lane notices.

mod common;

use std::path::Path;
use std::process::{Command, Output};

use lyapsweep::scene::Precision;

/// The tiny run of the impact pair that a property test drew (at
/// ζ = -300460 it ran past 100 s before the bound), with `more` keys.
fn run_tiny(out: &Path, backend: &str, more: &[&str], env: &[(&str, &str)]) -> Output {
    let scene = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/impact-pair.toml");
    let mut args = vec!["run", scene, "-q", "--out", out.to_str().unwrap()];
    let backend = format!("run.backend={backend}");
    for key in [
        "sweep.count=2",
        "integration.transient=5",
        "integration.iterations=5",
        "output.bifurcation_points=2",
        &backend,
    ]
    .iter()
    .chain(more)
    {
        args.extend(["--set", key]);
    }
    Command::new(env!("CARGO_BIN_EXE_lyapsweep"))
        .args(&args)
        .envs(env.iter().copied())
        .output()
        .expect("the binary runs")
}

/// spectrum.csv's status column, a row per lane.
fn statuses(out: &Path) -> Vec<String> {
    let rows = std::fs::read_to_string(out.join("spectrum.csv")).unwrap();
    rows.lines()
        .skip(1)
        .map(|row| row.rsplit(',').next().unwrap().to_owned())
        .collect()
}

/// Every lane of the drawn run at damping `zeta` (`lanes` of them) fails
/// with the bound's status in its first transient iteration: the run exits
/// 1 (every lane failed), naming the status, and writes their rows without
/// numbers.
fn every_lane_ends_at_the_bound(
    zeta: &str,
    backend: &str,
    more: &[&str],
    env: &[(&str, &str)],
    lanes: usize,
) {
    let zeta = format!("model.parameters.zeta={zeta}");
    let more: Vec<&str> = [zeta.as_str()]
        .into_iter()
        .chain(more.iter().copied())
        .collect();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let output = run_tiny(&out, backend, &more, env);
    let stderr = String::from_utf8_lossy(&output.stderr);
    let what = format!("{backend} {more:?} {env:?}");
    assert_eq!(output.status.code(), Some(1), "{what}: {stderr}");
    assert!(
        stderr.contains(&format!("every lane failed ({lanes} too-many-events)")),
        "{what}: {stderr}"
    );
    assert_eq!(
        statuses(&out),
        vec!["too-many-events(iteration=0)"; lanes],
        "{what}"
    );
    let rows = std::fs::read_to_string(out.join("spectrum.csv")).unwrap();
    for row in rows.lines().skip(1) {
        // No exponents: the lane gave no numbers.
        let fields: Vec<&str> = row.split(',').collect();
        assert!(fields[1..4].iter().all(|f| *f == "NaN"), "{what}: {row}");
    }
}

#[test]
fn a_lane_past_the_bound_on_events_ends_with_its_status_on_the_cpu_path() {
    // The lanes stepped together across the sweep, and one lane alone.
    every_lane_ends_at_the_bound("-300460", "cpu", &[], &[], 2);
    every_lane_ends_at_the_bound("-300460", "cpu", &["sweep.count=1"], &[], 1);
    every_lane_ends_at_the_bound(
        "-300460",
        "cpu",
        &[],
        &[("LYAPSWEEP_STEP_LOOPS", "interpreter")],
        2,
    );
    // The exact propagator, at its own bound on crossings (the same).
    every_lane_ends_at_the_bound("-300460", "exact", &[], &[], 2);
}

#[test]
fn a_lane_past_the_bound_on_events_ends_with_its_status_on_the_gpu() {
    for precision in [Precision::F64, Precision::F32] {
        if !common::gpu_or_skip("events past the bound on the GPU", precision) {
            continue;
        }
        let key = format!("run.precision={}", precision.name());
        // ζ = -300460 ends so too (measured: f64, 205 s), but its plan of
        // 9.4e7 steps a period is 3.7e6 dispatches of lavapipe's 256 steps
        // over the run, each a launch even where every trajectory has
        // stopped; ζ = -3000, 9.4e5 steps a period, meets the bound alike.
        every_lane_ends_at_the_bound("-3000", "gpu", &[&key], &[], 2);
    }
}

/// A lane past the bound beside one that is not, on the CPU path: the run
/// succeeds, and the other lane's row is byte for byte what a run of its
/// value alone writes. (The GPU runs every lane of a sweep with one plan,
/// the stiffest lane's: its sound lane would take ten million steps a
/// period on lavapipe, and no longer be its run alone.)
#[test]
fn a_lane_past_the_bound_on_events_touches_no_other_lane() {
    let dir = tempfile::tempdir().unwrap();
    let rows_of = |values: &str, name: &str| {
        let out = dir.path().join(name);
        let sweep = format!("sweep={{parameter=\"zeta\", values={values}}}");
        let output = run_tiny(&out, "cpu", &[&sweep], &[]);
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(0), "{values}: {stderr}");
        let rows = std::fs::read_to_string(out.join("spectrum.csv")).unwrap();
        rows.lines().skip(1).map(str::to_owned).collect::<Vec<_>>()
    };
    let both = rows_of("[-300460, 0.05]", "both");
    let alone = rows_of("[0.05]", "alone");
    assert!(
        both[0].ends_with(",too-many-events(iteration=0)"),
        "{both:?}"
    );
    assert_eq!(both[1], alone[0]);
    assert!(alone[0].ends_with(",ok"), "{alone:?}");
}
