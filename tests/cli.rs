//! The `lyapsweep` binary: bad input is refused with exit code 2, a message
//! naming the key, and nothing written; good input writes whole CSV files.

mod common;

use std::path::Path;
use std::process::{Command, Output};

use lyapsweep::scene::Precision;

const BASE: &str = r#"
[system]
kind = "impact-oscillator"
eta = 0.8
[integration]
steps_per_period = 200
transient = 5
iterations = 10
"#;

fn lyapsweep(dir: &Path, scene: &str, extra: &[&str]) -> Output {
    let path = dir.join("scene.toml");
    std::fs::write(&path, scene).unwrap();
    Command::new(env!("CARGO_BIN_EXE_lyapsweep"))
        .arg("run")
        .arg(&path)
        .arg("--out")
        .arg(dir.join("out"))
        .args(extra)
        .output()
        .expect("the binary runs")
}

/// Runs a bad scene and checks exit code 2, `key` in the message, no output.
fn refused(scene: &str, extra: &[&str], key: &str) {
    let dir = tempfile::tempdir().unwrap();
    let out = lyapsweep(dir.path(), scene, extra);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(
        out.status.code(),
        Some(2),
        "exit code for {key}; stderr: {stderr}"
    );
    assert!(
        stderr.contains(key),
        "message does not name {key}: {stderr}"
    );
    assert_eq!(
        stderr.trim().lines().count(),
        1,
        "one message expected: {stderr}"
    );
    assert!(!dir.path().join("out").exists(), "output written for {key}");
}

fn with(section_line: &str) -> String {
    format!("{BASE}{section_line}\n")
}

#[test]
fn impossible_values_name_their_key() {
    refused(&BASE.replace("eta = 0.8", "eta = -1.0"), &[], "system.eta");
    refused(&BASE.replace("eta = 0.8", "eta = 0.0"), &[], "system.eta");
    refused(
        &BASE.replace("eta = 0.8", "eta = 0.8\nrestitution = 1.5"),
        &[],
        "system.restitution",
    );
    refused(
        &BASE.replace("eta = 0.8", "eta = 0.8\nrestitution = -0.1"),
        &[],
        "system.restitution",
    );
    refused(&BASE.replace("eta = 0.8", "eta = nan"), &[], "system.eta");
    // The kind's model file bounds its parameters (negative damping is
    // refused, as the retired hand-written system did).
    refused(
        &BASE.replace("eta = 0.8", "eta = 0.8\nzeta = -0.05"),
        &[],
        "system.zeta: must be >= 0, got -0.05",
    );
    refused(
        &BASE.replace("iterations = 10", "iterations = 10\nperturbation = 0.0"),
        &[],
        "integration.perturbation",
    );
    refused(
        &BASE.replace("iterations = 10", "iterations = 10\nperturbation = -1e-7"),
        &[],
        "integration.perturbation",
    );
    refused(
        &BASE.replace("iterations = 10", "iterations = 10\nperturbation = nan"),
        &[],
        "integration.perturbation",
    );
    refused(
        &BASE.replace("steps_per_period = 200", "steps_per_period = 0"),
        &[],
        "integration.steps_per_period",
    );
    refused(
        &BASE.replace("iterations = 10", "iterations = 0"),
        &[],
        "integration.iterations",
    );
    // The `lorenz` kind runs a model whose map period is its parameter
    // `period`: the message names the scene's key.
    refused(
        &BASE
            .replace("impact-oscillator", "lorenz")
            .replace("eta = 0.8", "period = 0.0"),
        &[],
        "system.period",
    );
    // The aligning iterations are the transient's last ones.
    refused(
        &BASE.replace("iterations = 10", "iterations = 10\nalign = 100000"),
        &[],
        "integration.align",
    );
    refused(
        &with("[sweep]\nfrom = 0.5\nto = 1.5\ncount = 0"),
        &[],
        "sweep.count",
    );
    refused(
        &with("[sweep]\nfrom = -0.5\nto = 1.5\ncount = 3"),
        &[],
        "sweep.from",
    );
    refused(&with("[sweep]\nvalues = [0.5, 0.0]"), &[], "sweep.values");
    refused(&with("[sweep]\nvalues = []"), &[], "sweep.values");
    refused(&with("[sweep]\nfrom = 0.5\nto = nan"), &[], "sweep.to");
    refused(
        &BASE.replace(
            "iterations = 10",
            "iterations = 10\ninitial_state = [2.5, 0.0]",
        ),
        &[],
        "integration.initial_state",
    );
    refused(
        &BASE.replace("iterations = 10", "iterations = 10\ninitial_state = [0.0]"),
        &[],
        "integration.initial_state",
    );
    refused(
        &BASE.replace(
            "iterations = 10",
            "iterations = 10\ninitial_state = [nan, 0.0]",
        ),
        &[],
        "integration.initial_state",
    );
    refused(
        &with("[output]\nbifurcation_points = 11"),
        &[],
        "output.bifurcation_points",
    );
}

#[test]
fn unknown_keys_and_parameters_are_refused() {
    refused(
        &BASE.replace("eta = 0.8", "eta = 0.8\nmass = 2.0"),
        &[],
        "system.mass",
    );
    refused(
        &with("[sweep]\nparameter = \"sigma\"\nfrom = 1.0\nto = 2.0"),
        &[],
        "sweep.parameter",
    );
    refused(
        &BASE.replace("iterations = 10", "iterations = 10\nstepz = 3"),
        &[],
        "stepz",
    );
    refused(&with("[colours]\nred = 1"), &[], "colours");
    refused(
        &BASE.replace("impact-oscillator", "pendulum"),
        &[],
        "system.kind",
    );
    refused("[integration]\niterations = 3\n", &[], "system");
}

#[test]
fn wrong_types_are_refused() {
    refused(
        &BASE.replace("steps_per_period = 200", "steps_per_period = \"many\""),
        &[],
        "integration.steps_per_period",
    );
    refused(
        &BASE.replace("steps_per_period = 200", "steps_per_period = -3"),
        &[],
        "integration.steps_per_period",
    );
    refused(
        &BASE.replace("eta = 0.8", "eta = \"fast\""),
        &[],
        "system.eta",
    );
    refused(&with("[run]\nbackend = \"quantum\""), &[], "run.backend");
    refused(&with("[run]\nprecision = \"f16\""), &[], "run.precision");
    refused(&with("[integration.extra]\nx = 1"), &[], "integration");
    refused(&format!("{BASE}\nthis is not toml"), &[], "scene");
}

#[test]
fn flags_and_overrides_are_checked_like_the_scene() {
    refused(BASE, &["--set", "system.eta=-2"], "system.eta");
    refused(
        BASE,
        &["--set", "integration.transient=\"x\""],
        "integration.transient",
    );
    refused(BASE, &["--set", "nonsense"], "--set nonsense");
    refused(
        BASE,
        &["--set", "system.kind.deep=1"],
        "--set system.kind.deep=1",
    );
    refused(
        BASE,
        &["--backend", "cpu", "--precision", "f32"],
        "run.precision",
    );
    refused(
        &BASE
            .replace("impact-oscillator", "lorenz")
            .replace("eta = 0.8", ""),
        &["--backend", "exact"],
        "run.backend",
    );
}

#[test]
fn a_good_run_writes_whole_files_with_the_documented_columns() {
    let dir = tempfile::tempdir().unwrap();
    let scene = with("[sweep]\nfrom = 0.8\nto = 1.2\ncount = 3\n[output]\nbifurcation_points = 4");
    // 200 iterations: over 20 the impacting orbits' rows say `uncertain`
    // (λ1 = -0.0445 ± 0.016 at η = 0.8, where the limit is -0.05).
    let out = lyapsweep(dir.path(), &scene, &["--set", "integration.iterations=200"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let summary = String::from_utf8_lossy(&out.stdout);
    for needle in [
        "backend",
        "lanes",
        "time",
        "max |lambda_sum - expected_sum|",
        "max lambda_error",
    ] {
        assert!(
            summary.contains(needle),
            "summary lacks {needle}: {summary}"
        );
    }
    let spectrum = std::fs::read_to_string(dir.path().join("out/spectrum.csv")).unwrap();
    let mut lines = spectrum.lines();
    assert_eq!(
        lines.next().unwrap(),
        "eta,lambda_1,lambda_2,lambda_sum,expected_sum,lambda_error,impacts_per_period,grazing,grazing_bound,period,status"
    );
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 3);
    for (row, eta) in rows.iter().zip(["0.8", "1", "1.2"]) {
        assert_eq!(row[0], eta);
        let l1: f64 = row[1].parse().unwrap();
        let l2: f64 = row[2].parse().unwrap();
        let sum: f64 = row[3].parse().unwrap();
        assert_eq!(l1 + l2, sum);
        assert!(l1 >= l2);
        assert_eq!(row[4], "-0.1");
        // The row's stated error, within the tolerance of an `ok` row.
        let error: f64 = row[5].parse().unwrap();
        assert!(error >= 0.0 && error < 0.1 * l1.abs(), "{error}");
        assert_eq!(row[7], "0", "no grazing iteration at a periodic point");
        assert_eq!(row[8], "0");
        // The period: a whole number, or empty when none closes.
        assert!(row[9].is_empty() || row[9].parse::<usize>().is_ok_and(|p| (1..=12).contains(&p)));
        assert_eq!(row[10], "ok");
    }
    let bifurcation = std::fs::read_to_string(dir.path().join("out/bifurcation.csv")).unwrap();
    assert!(bifurcation.starts_with("eta,x,v\n"));
    assert_eq!(bifurcation.lines().count(), 1 + 3 * 4);
    // The scene as run, the CSV files, their manifest and the figure; no
    // temporary files, and nothing left beside the folder.
    let mut names: Vec<String> = std::fs::read_dir(dir.path().join("out"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(
        names,
        [
            "bifurcation.csv",
            "figure.png",
            "figure.svg",
            "manifest.toml",
            "scene.toml",
            "spectrum.csv"
        ]
    );
    let mut beside: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    beside.sort();
    assert_eq!(beside, ["out", "scene.toml"]);
}

#[test]
fn an_adapter_name_that_matches_nothing_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scene.toml");
    std::fs::write(&path, BASE).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_lyapsweep"))
        .args(["run", path.to_str().unwrap(), "--backend", "gpu", "--out"])
        .arg(dir.path().join("out"))
        .env("WGPU_ADAPTER_NAME", "no-such-adapter-anywhere")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("WGPU_ADAPTER_NAME") && stderr.contains("no-such-adapter-anywhere"),
        "{stderr}"
    );
    assert!(!stderr.contains("panicked"));
    assert!(!dir.path().join("out").exists());
}

#[test]
fn devices_lists_each_adapter_with_its_f64_support_and_limits() {
    let out = Command::new(env!("CARGO_BIN_EXE_lyapsweep"))
        .arg("devices")
        .output()
        .unwrap();
    assert!(out.status.success());
    let stdout = String::from_utf8_lossy(&out.stdout);
    let adapters = lyapsweep::backend::gpu::context::list();
    if adapters.is_empty() {
        assert!(stdout.contains("no GPU adapters found"), "{stdout}");
    }
    // Numbered, for `run --device N`.
    for (n, a) in adapters.iter().enumerate() {
        let line = stdout
            .lines()
            .find(|l| l.starts_with(&format!("{n}: {} [{}]", a.name, a.backend)))
            .unwrap_or_else(|| panic!("{} missing from: {stdout}", a.name));
        assert!(
            line.contains(if a.f64 { "f64 yes" } else { "f64 no" }),
            "{line}"
        );
        assert!(line.contains("max storage binding"), "{line}");
    }
}

/// Copies the folder `from` into `to`, recursively.
fn copy_folder(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_folder(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), target).unwrap();
        }
    }
}

/// `LYAPSWEEP_SHADER_DIR` composes the kernels from a copy of `shaders/`
/// (for kernel experiments without a rebuild): an unchanged copy gives the
/// binary's bits, an edited one other numbers, and the summary says where
/// the kernels came from.
#[test]
fn kernels_from_a_shader_folder_are_used_and_said() {
    if !common::gpu_or_skip(
        "kernels_from_a_shader_folder_are_used_and_said",
        Precision::F32,
    ) {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let shaders = dir.path().join("shaders");
    copy_folder(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("shaders"),
        &shaders,
    );
    let scene = dir.path().join("scene.toml");
    std::fs::write(&scene, BASE).unwrap();
    let run = |name: &str, folder: Option<&Path>| {
        let mut command = Command::new(env!("CARGO_BIN_EXE_lyapsweep"));
        command
            .arg("run")
            .arg(&scene)
            .args([
                "--backend",
                "gpu",
                "--precision",
                "f32",
                "--set",
                "run.validate=0",
            ])
            .arg("--out")
            .arg(dir.path().join(name))
            .env_remove("LYAPSWEEP_SHADER_DIR");
        if let Some(folder) = folder {
            command.env("LYAPSWEEP_SHADER_DIR", folder);
        }
        let out = command.output().unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
        assert!(
            out.status.success(),
            "{stdout}{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let spectrum = std::fs::read(dir.path().join(name).join("spectrum.csv")).unwrap();
        (stdout, spectrum)
    };
    let said = format!("composed from {} (LYAPSWEEP_SHADER_DIR)", shaders.display());
    let (stdout, binary) = run("binary", None);
    assert!(!stdout.contains("LYAPSWEEP_SHADER_DIR"), "{stdout}");
    let (stdout, copied) = run("copy", Some(&shaders));
    assert!(stdout.contains(&said), "{stdout}");
    assert_eq!(copied, binary, "the same sources, other bits");
    // The RK4 increment of the kernel's step loop taken over a step a
    // part in 10 000 too long: other numbers.
    let kernel = shaders.join("integrate.wgsl");
    let text = std::fs::read_to_string(&kernel).unwrap();
    let call = "rk4_increment(p, tr.phase, step.half, y, step.h)";
    assert!(text.contains(call));
    let longer = "rk4_increment(p, tr.phase, step.half, y, step.h * real(1.0001))";
    std::fs::write(&kernel, text.replace(call, longer)).unwrap();
    let (stdout, edited) = run("edited", Some(&shaders));
    assert!(stdout.contains(&said), "{stdout}");
    assert_ne!(edited, binary, "the edited kernels were not used");
}

#[test]
fn a_shader_folder_without_the_kernels_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let empty = dir.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    let path = dir.path().join("scene.toml");
    std::fs::write(&path, BASE).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_lyapsweep"))
        .args(["run", path.to_str().unwrap(), "--backend", "gpu", "--out"])
        .arg(dir.path().join("out"))
        .env("LYAPSWEEP_SHADER_DIR", &empty)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("LYAPSWEEP_SHADER_DIR") && stderr.contains("integrate.wgsl"),
        "{stderr}"
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(!dir.path().join("out").exists());
}

/// With `[attractors]` and continuation, the summary says how many values
/// hold more than one attractor, the set holds attractors.csv, and a shard
/// is refused (a value's starts are compared with each other).
#[test]
fn a_run_with_many_starts_counts_its_values_with_several_attractors() {
    let scene = format!(
        "{BASE}[sweep]\nfrom = 0.55\nto = 0.65\ncount = 21\n[output]\nbifurcation_points = 2\n[attractors]\nlist = [[0.0, 0.0]]\ncontinuation = \"both\"\n"
    )
    .replace("steps_per_period = 200", "steps_per_period = 600")
    .replace("transient = 5", "transient = 200")
    .replace("iterations = 10", "iterations = 100");
    let dir = tempfile::tempdir().unwrap();
    let out = lyapsweep(dir.path(), &scene, &[]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains("21 values of eta in [0.55, 0.65] × 1 starts"),
        "{stdout}"
    );
    assert!(
        stdout
            .contains("attractors   30 over 21 values in 2 branches; 9 values hold more than one"),
        "{stdout}"
    );
    assert!(stdout.contains("continued "), "{stdout}");
    let attractors = std::fs::read_to_string(dir.path().join("out/attractors.csv")).unwrap();
    assert_eq!(attractors.lines().count(), 1 + 30);
    refused(&scene, &["--shard", "0/2"], "--shard");
}

/// A kernel source in `LYAPSWEEP_SHADER_DIR` that is not text, or was
/// emptied, is an error naming the file before any work (it was a panic
/// when the kernels were composed).
#[test]
fn a_shader_folder_with_a_broken_source_names_the_file() {
    let shaders = Path::new(env!("CARGO_MANIFEST_DIR")).join("shaders");
    for (broken, bytes) in [
        ("shared/dispatch.wgsl", &b"fn \xff\xfe broken"[..]),
        ("shared/stops.wgsl", &b"\n"[..]),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let copy = dir.path().join("shaders");
        copy_folder(&shaders, &copy);
        std::fs::write(copy.join(broken), bytes).unwrap();
        let path = dir.path().join("scene.toml");
        std::fs::write(&path, BASE).unwrap();
        let out = Command::new(env!("CARGO_BIN_EXE_lyapsweep"))
            .args(["run", path.to_str().unwrap(), "--backend", "gpu", "--out"])
            .arg(dir.path().join("out"))
            .env("LYAPSWEEP_SHADER_DIR", &copy)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{broken}: {stderr}");
        assert!(
            stderr.contains("LYAPSWEEP_SHADER_DIR") && stderr.contains(broken),
            "{stderr}"
        );
        assert!(!stderr.contains("panicked"), "{stderr}");
        assert!(!dir.path().join("out").exists());
    }
}

/// A kernel source in `LYAPSWEEP_SHADER_DIR` that does not parse is an
/// error naming the folder and naga's message, before the device compiles
/// it (it was a panic in the pipeline's creation).
#[test]
fn a_shader_folder_whose_kernels_do_not_parse_is_refused() {
    if !common::gpu_or_skip(
        "a_shader_folder_whose_kernels_do_not_parse_is_refused",
        Precision::F64,
    ) {
        return;
    }
    let shaders = Path::new(env!("CARGO_MANIFEST_DIR")).join("shaders");
    let dir = tempfile::tempdir().unwrap();
    let copy = dir.path().join("shaders");
    copy_folder(&shaders, &copy);
    let dispatch = copy.join("shared/dispatch.wgsl");
    let text = std::fs::read_to_string(&dispatch).unwrap();
    std::fs::write(&dispatch, text + "\nfn broken( {\n").unwrap();
    let path = dir.path().join("scene.toml");
    std::fs::write(&path, BASE).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_lyapsweep"))
        .args(["run", path.to_str().unwrap(), "--backend", "gpu", "--out"])
        .arg(dir.path().join("out"))
        .env("LYAPSWEEP_SHADER_DIR", &copy)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("LYAPSWEEP_SHADER_DIR") && stderr.contains("not valid WGSL"),
        "{stderr}"
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(!dir.path().join("out").exists());
}

/// A C compiler that fails (or is missing) leaves the model to the
/// interpreter, 8 to 10 times slower: the run says so on stderr, naming
/// the compiler and its error, and in its summary, and still runs.
#[test]
fn a_failing_c_compiler_is_named_on_stderr_and_in_the_summary() {
    let cache = tempfile::tempdir().unwrap();
    for (cc, error) in [
        ("/bin/false", "/bin/false failed (exit status: 1"),
        ("/no/such/compiler", "/no/such/compiler: No such file"),
    ] {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("scene.toml"), BASE).unwrap();
        let out = Command::new(env!("CARGO_BIN_EXE_lyapsweep"))
            .args(["run", "--quiet", "--backend", "cpu", "--out"])
            .arg(dir.path().join("out"))
            .arg(dir.path().join("scene.toml"))
            .env("CC", cc)
            .env("XDG_CACHE_HOME", cache.path())
            .env_remove("LYAPSWEEP_STEP_LOOPS")
            .output()
            .unwrap();
        let (stdout, stderr) = (
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr),
        );
        assert_eq!(out.status.code(), Some(0), "{cc}: {stderr}");
        let warning = stderr
            .lines()
            .find(|l| l.contains("warning"))
            .unwrap_or_else(|| panic!("{cc}: no warning on stderr: {stderr}"));
        assert!(warning.contains(&format!("CC = {cc}")), "{warning}");
        assert!(warning.contains("interpreter"), "{warning}");
        assert!(warning.contains(error), "{warning}");
        let line = stdout
            .lines()
            .find(|l| l.trim_start().starts_with("interpreter"))
            .unwrap_or_else(|| panic!("{cc}: not in the summary: {stdout}"));
        assert!(line.contains(error), "{line}");
    }
    // The host's compiler builds it: neither says a word.
    let dir = tempfile::tempdir().unwrap();
    let out = lyapsweep(dir.path(), BASE, &["--quiet", "--backend", "cpu"]);
    assert!(out.status.success());
    assert!(!String::from_utf8_lossy(&out.stderr).contains("warning"));
    assert!(!String::from_utf8_lossy(&out.stdout).contains("interpreter"));
}
