//! Sweeps across machines and over two parameters, through the binary:
//! `--shard i/n` and `lyapsweep merge` give the files of one run, byte for
//! byte; `[sweep.second]` writes the grid; bad shards and merges are refused
//! with exit code 2 and nothing written.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// A small sweep over f, with a lane that overflows (f = 1e308: it stops
/// early and keeps fewer bifurcation points than the others).
const SCENE: &str = r#"
name = "shards"
[system]
kind = "impact-oscillator"
eta = 0.8
[sweep]
parameter = "f"
values = [0.5, 1.0, 1e308, 1.5, 2.0, 2.5, 3.0]
[integration]
steps_per_period = 120
transient = 20
iterations = 40
[run]
backend = "cpu"
[output]
bifurcation_points = 6
plot = false
"#;

fn lyapsweep(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_lyapsweep"))
        .args(args)
        .env("LYAPSWEEP_PROGRESS_SECONDS", "0")
        .output()
        .expect("the binary runs")
}

fn ok(output: Output) -> Output {
    assert!(
        output.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    output
}

/// Runs `scene` (written into `dir`) with `extra` arguments into `dir/out`.
fn run(dir: &Path, scene: &str, out: &str, extra: &[&str]) -> PathBuf {
    let path = dir.join("scene.toml");
    std::fs::write(&path, scene).unwrap();
    let out = dir.join(out);
    let mut args = vec![
        "run",
        path.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "-q",
    ];
    args.extend_from_slice(extra);
    ok(lyapsweep(&args));
    out
}

fn bytes(path: PathBuf) -> Vec<u8> {
    std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Shards of `scene` run one by one, merged (given in scrambled order), and
/// compared with one run, file by file.
fn merged_equals_whole(scene: &str, shards: usize, files: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let whole = run(dir.path(), scene, "whole", &[]);
    let mut parts: Vec<PathBuf> = (0..shards)
        .map(|i| {
            run(
                dir.path(),
                scene,
                &format!("shard{i}"),
                &["--shard", &format!("{i}/{shards}")],
            )
        })
        .collect();
    parts.reverse();
    parts.rotate_left(1);
    let merged = dir.path().join("merged");
    let mut args = vec!["merge", "--out", merged.to_str().unwrap()];
    args.extend(parts.iter().map(|p| p.to_str().unwrap()));
    ok(lyapsweep(&args));
    for file in files.iter().chain(&["scene.toml"]) {
        assert!(
            bytes(whole.join(file)) == bytes(merged.join(file)),
            "{file} differs after merging {shards} shards"
        );
    }
}

#[test]
fn a_merged_sharded_run_equals_one_run_byte_for_byte() {
    merged_equals_whole(SCENE, 3, &["spectrum.csv", "bifurcation.csv"]);
    // More shards than some get lanes for: 7 lanes in 4 shards.
    merged_equals_whole(SCENE, 4, &["spectrum.csv", "bifurcation.csv"]);
}

#[test]
fn a_merged_sharded_grid_equals_one_run_byte_for_byte() {
    let grid = SCENE.replace(
        "[integration]",
        "[sweep.second]\nparameter = \"eta\"\nvalues = [0.7, 0.9, 1.1]\n[integration]",
    );
    merged_equals_whole(&grid, 5, &["grid.csv", "bifurcation.csv"]);
}

/// The models issue's impact pair (models/impact-pair.toml, inlined so
/// that the scene stands alone in a temporary folder) over a grid of (η, e).
fn model_grid() -> String {
    let model = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("models/impact-pair.toml"),
    )
    .unwrap();
    format!(
        "name = \"model-grid\"\n{model}\n\
         [sweep]\nparameter = \"eta\"\nvalues = [0.6, 0.9, 1.2, 1.8]\n\
         [sweep.second]\nparameter = \"e\"\nvalues = [0.5, 0.9]\n\
         [integration]\nsteps_per_period = 120\ntransient = 20\niterations = 40\n\
         [run]\nbackend = \"cpu\"\n[output]\nbifurcation_points = 6\nplot = false\n"
    )
}

#[test]
fn a_model_s_grid_shards_and_merges_like_a_built_in_s() {
    let scene = model_grid();
    merged_equals_whole(&scene, 3, &["grid.csv", "bifurcation.csv"]);
    // The grid's figure is drawn from a model's files too, and its columns
    // name the events.
    let dir = tempfile::tempdir().unwrap();
    let out = run(
        dir.path(),
        &scene.replace("plot = false", "plot = true"),
        "out",
        &[],
    );
    assert!(out.join("heat-map.png").exists());
    let grid = std::fs::read_to_string(out.join("grid.csv")).unwrap();
    let header = grid.lines().next().unwrap();
    assert!(
        header.starts_with("eta,e,lambda_1,lambda_2,lambda_sum,expected_sum,lambda_error,impacts_per_period,right_stop_per_period,left_stop_per_period,"),
        "{header}"
    );
    assert_eq!(grid.lines().count(), 1 + 8);
}

#[test]
fn a_two_parameter_sweep_writes_the_grid_first_axis_fastest() {
    let dir = tempfile::tempdir().unwrap();
    let grid = SCENE.replace(
        "[integration]",
        "[sweep.second]\nparameter = \"eta\"\nvalues = [0.7, 0.9, 1.1]\n[integration]",
    );
    let out = run(dir.path(), &grid, "grid", &[]);
    assert!(!out.join("spectrum.csv").exists());
    let text = String::from_utf8(bytes(out.join("grid.csv"))).unwrap();
    let rows: Vec<Vec<&str>> = text.lines().map(|l| l.split(',').collect()).collect();
    assert_eq!(rows[0][..4], ["f", "eta", "lambda_1", "lambda_2"]);
    let f = [0.5, 1.0, 1e308, 1.5, 2.0, 2.5, 3.0];
    let eta = [0.7, 0.9, 1.1];
    assert_eq!(rows.len(), 1 + f.len() * eta.len(), "a 7 × 3 grid");
    for (k, row) in rows[1..].iter().enumerate() {
        assert_eq!(row.len(), rows[0].len());
        let value = |t: &str| t.parse::<f64>().unwrap();
        assert_eq!(
            (value(row[0]), value(row[1])),
            (f[k % 7], eta[k / 7]),
            "row {k}"
        );
    }
    // Each grid row is the lane a one-parameter sweep at that η computes.
    let line = run(
        dir.path(),
        &SCENE.replace("eta = 0.8", "eta = 0.9"),
        "line",
        &[],
    );
    let line = String::from_utf8(bytes(line.join("spectrum.csv"))).unwrap();
    for (k, row) in line.lines().skip(1).enumerate() {
        let (f_value, rest) = row.split_once(',').unwrap();
        assert_eq!(rows[1 + 7 + k].join(","), format!("{f_value},0.9,{rest}"));
    }
}

/// Runs the binary, expects exit code 2 with `needle` in a one-line message
/// and nothing at `out`.
fn refused(args: &[&str], needle: &str, out: &Path) {
    let output = lyapsweep(args);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(2), "stderr: {stderr}");
    assert!(stderr.contains(needle), "{needle:?} not in: {stderr}");
    assert_eq!(stderr.trim().lines().count(), 1, "{stderr}");
    assert!(!out.exists(), "{} written", out.display());
}

#[test]
fn bad_shards_and_merges_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("scene.toml");
    std::fs::write(&scene, SCENE).unwrap();
    let out = dir.path().join("out");
    let (s, o) = (scene.to_str().unwrap(), out.to_str().unwrap());
    for shard in ["3/3", "1/0", "a/b", "2", "8/8"] {
        refused(&["run", s, "--out", o, "--shard", shard], "--shard", &out);
    }
    // 7 lanes cannot make 8 shards.
    refused(
        &["run", s, "--out", o, "--shard", "0/8"],
        "would be empty",
        &out,
    );

    let a = run(dir.path(), SCENE, "a", &["--shard", "0/2"]);
    let b = run(dir.path(), SCENE, "b", &["--shard", "1/2"]);
    let other = run(
        dir.path(),
        &SCENE.replace("iterations = 40", "iterations = 41"),
        "other",
        &["--shard", "1/2"],
    );
    let whole = run(dir.path(), SCENE, "whole", &[]);
    let merged = dir.path().join("merged");
    let m = merged.to_str().unwrap();
    let path = |p: &PathBuf| p.to_str().unwrap().to_owned();
    refused(
        &["merge", "--out", m, &path(&a)],
        "shard(s) 1 of 2 missing",
        &merged,
    );
    refused(
        &["merge", "--out", m, &path(&a), &path(&a)],
        "given twice",
        &merged,
    );
    refused(
        &["merge", "--out", m, &path(&a), &path(&other)],
        "different scenes",
        &merged,
    );
    refused(
        &["merge", "--out", m, &path(&a), &path(&whole)],
        "shard.toml",
        &merged,
    );
    ok(lyapsweep(&["merge", "--out", m, &path(&b), &path(&a)]));
}

#[test]
fn progress_is_reported_in_plain_lines_off_a_terminal_and_quiet_says_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("scene.toml");
    std::fs::write(&scene, SCENE).unwrap();
    let s = scene.to_str().unwrap();
    let out = dir.path().join("out");
    let o = out.to_str().unwrap();
    // LYAPSWEEP_PROGRESS_SECONDS = 0: a line at every poll (100 ms), and a
    // last one when the run ends; stderr is a pipe here, not a terminal.
    let loud = ok(lyapsweep(&["run", s, "--out", o]));
    let stderr = String::from_utf8_lossy(&loud.stderr);
    let last = stderr.lines().last().unwrap_or_default();
    assert!(
        last.starts_with("progress: 100% (420 of 420 lane-iterations)"),
        "{stderr}"
    );
    let quiet = ok(lyapsweep(&["run", s, "--out", o, "--quiet"]));
    assert!(
        quiet.stderr.is_empty(),
        "{}",
        String::from_utf8_lossy(&quiet.stderr)
    );
}

#[test]
fn every_committed_scene_is_valid() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
    let mut names = Vec::new();
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        let scene = lyapsweep::scene::load(&path, &[])
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        names.push(scene.name.clone());
        if scene.name == "eta-f-map" {
            // The two-parameter showcase: 512 × 512 lanes, λ1 on the grid.
            assert_eq!(scene.sweep.lanes(), 512 * 512);
            assert!(scene.lyapunov && scene.plot);
        }
        if scene.name == "million-map" {
            // A million lanes, whose results fit one batch of the budget.
            assert_eq!(scene.sweep.lanes(), 1024 * 1024);
            let i = &scene.integration;
            assert_eq!(
                (i.steps_per_period, i.transient, i.iterations),
                (200, 50, 50)
            );
            assert!(
                scene.sweep.lanes() * lyapsweep::plan::lane_bytes(&scene)
                    < lyapsweep::plan::BATCH_BYTES
            );
            assert!(scene.lyapunov && scene.plot);
        }
    }
    names.sort();
    assert_eq!(
        names,
        [
            "belt-into-stop",
            "chaotic-window",
            "duffing",
            "eta-f-map",
            "forced-pendulum",
            "friction-belt",
            "henon",
            "impact-pair",
            "lorenz",
            "lorenz-section",
            "million-map",
            "rossler-section",
            "seed-fig3",
            "soft-stop",
            "two-block-belt",
            "two-mass-chain",
            "van-der-pol",
            "vibrating-table"
        ]
    );
}

/// PNG width and height, from the IHDR chunk.
fn png_size(path: &Path) -> (u32, u32) {
    let b = bytes(path.to_owned());
    assert_eq!(&b[1..4], b"PNG", "{} is a PNG", path.display());
    let at = |k: usize| u32::from_be_bytes([b[k], b[k + 1], b[k + 2], b[k + 3]]);
    (at(16), at(20))
}

#[test]
fn runs_draw_their_figures_and_plot_redraws_them_from_the_csvs() {
    use lyapsweep::output::plot::{HEAT_MAP_SIZE, SWEEP_SIZE};
    let dir = tempfile::tempdir().unwrap();
    let line = run(
        dir.path(),
        &SCENE.replace("plot = false", "plot = true"),
        "line",
        &[],
    );
    assert_eq!(png_size(&line.join("figure.png")), SWEEP_SIZE);
    let svg = String::from_utf8(bytes(line.join("figure.svg"))).unwrap();
    assert!(svg.contains("<svg") && svg.contains("shards"));
    // Redrawn from the CSV files alone, the figure is the run's.
    let drawn = bytes(line.join("figure.png"));
    std::fs::remove_file(line.join("figure.png")).unwrap();
    ok(lyapsweep(&["plot", line.to_str().unwrap()]));
    assert!(
        bytes(line.join("figure.png")) == drawn,
        "plot redraws the same figure"
    );
    // Elsewhere, with --out.
    let elsewhere = dir.path().join("figures");
    ok(lyapsweep(&[
        "plot",
        line.to_str().unwrap(),
        "--out",
        elsewhere.to_str().unwrap(),
    ]));
    assert!(bytes(elsewhere.join("figure.png")) == drawn);

    // A grid draws the heat map of λ1; `plot = true` is the default for
    // more than one value.
    let grid = run(
        dir.path(),
        &SCENE.replace("plot = false", "").replace(
            "[integration]",
            "[sweep.second]\nparameter = \"eta\"\nvalues = [0.7, 0.9, 1.1]\n[integration]",
        ),
        "grid",
        &[],
    );
    assert_eq!(png_size(&grid.join("heat-map.png")), HEAT_MAP_SIZE);
    assert!(!grid.join("figure.png").exists());
    // The run draws its map from the λ1 it wrote; read back, they are the
    // same numbers and the same map.
    let drawn = bytes(grid.join("heat-map.png"));
    std::fs::remove_file(grid.join("heat-map.png")).unwrap();
    ok(lyapsweep(&["plot", grid.to_str().unwrap()]));
    assert!(
        bytes(grid.join("heat-map.png")) == drawn,
        "plot redraws the same map"
    );
    // A shard draws nothing; its merge does.
    let shard = run(
        dir.path(),
        &SCENE.replace("plot = false", ""),
        "s",
        &["--shard", "0/1"],
    );
    assert!(!shard.join("figure.png").exists());
    let merged = dir.path().join("merged");
    ok(lyapsweep(&[
        "merge",
        "--out",
        merged.to_str().unwrap(),
        shard.to_str().unwrap(),
    ]));
    assert_eq!(png_size(&merged.join("figure.png")), SWEEP_SIZE);
}

#[test]
fn plot_refuses_a_folder_that_is_not_a_run() {
    let dir = tempfile::tempdir().unwrap();
    let output = lyapsweep(&["plot", dir.path().to_str().unwrap()]);
    assert_eq!(output.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("manifest.toml"), "{stderr}");
    assert!(
        stderr.contains("not a complete lyapsweep output folder"),
        "{stderr}"
    );
}
