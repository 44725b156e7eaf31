//! What the command does with the user's own input: it never writes over
//! the scene or model file it reads, indexes arrays in `--set` paths, gives
//! advice it would accept, tells a scene from a model, echoes a huge name
//! clipped, and lets a quick look lower the iterations. Every refusal is
//! exit code 2 with a message naming the key or path and why, and leaves
//! the user's files as they were.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::{Command, Output};

/// A three-value sweep of the seed's oscillator on the CPU, small enough to
/// run in milliseconds; its comments are what a rewritten scene would lose.
const BASE: &str = r#"# My sweep: comments that only this file holds.
[system]
kind = "impact-oscillator"   # the seed's oscillator
[sweep]
parameter = "eta"
from = 0.8
to = 1.2
count = 3
[integration]
steps_per_period = 100
transient = 5
iterations = 20
[run]
backend = "cpu"
"#;

/// The models issue's impact pair, as a model file: two events, so that
/// `model.events[i]` has something to index.
const PAIR_MODEL: &str = r#"# An impact pair (two rigid stops).
[model]
name = "impact-pair"
states = ["x", "v"]
[model.parameters]
zeta = 0.05
f = 1.0
eta = 1.0
gap = 1.0
e = 0.8
[model.equations]
x = "v"
v = "-2*zeta*v - x + f*cos(eta*t)"
[model.map]
period = "2*pi/eta"
[[model.events]]
name = "right stop"
surface = "x - gap"
reset = { v = "-e*v" }
[[model.events]]
name = "left stop"
surface = "-gap - x"
reset = { v = "-e*v" }
"#;

/// The rest of a scene of the impact pair: one value, a few iterations.
const PAIR_RUN: &str = r#"
[sweep]
parameter = "eta"
values = [1.0]
[integration]
transient = 5
iterations = 10
[run]
backend = "cpu"
"#;

fn lyapsweep(args: &[&str], cwd: Option<&Path>) -> Output {
    let mut command = Command::new(env!("CARGO_BIN_EXE_lyapsweep"));
    command.args(args);
    if let Some(cwd) = cwd {
        command.current_dir(cwd);
    }
    command.output().expect("the binary runs")
}

fn stderr(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).into_owned()
}

fn stdout(output: &Output) -> String {
    String::from_utf8_lossy(&output.stdout).into_owned()
}

fn ok(output: Output) -> Output {
    assert_eq!(output.status.code(), Some(0), "stderr: {}", stderr(&output));
    output
}

/// Exit code 2 and a one-line message holding every needle; returns it.
fn refused(output: &Output, needles: &[&str]) -> String {
    let text = stderr(output);
    assert_eq!(output.status.code(), Some(2), "stderr: {text}");
    for needle in needles {
        assert!(text.contains(needle), "{needle:?} not in: {text}");
    }
    assert_eq!(text.trim().lines().count(), 1, "one message: {text}");
    text
}

/// Every file below `dir` (hidden ones too), by path, with its bytes.
fn snapshot(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    let mut files = BTreeMap::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let entry = entry.unwrap();
        let name = entry.file_name().to_string_lossy().into_owned();
        if entry.file_type().unwrap().is_dir() {
            files.insert(format!("{name}/"), Vec::new());
            for (inner, bytes) in snapshot(&entry.path()) {
                files.insert(format!("{name}/{inner}"), bytes);
            }
        } else {
            files.insert(name, std::fs::read(entry.path()).unwrap());
        }
    }
    files
}

/// `dir/scenes/pair.toml` naming `../models/pair.toml`; returns the scene's path.
fn pair_in_files(dir: &Path) -> String {
    std::fs::create_dir_all(dir.join("models")).unwrap();
    std::fs::create_dir_all(dir.join("scenes")).unwrap();
    std::fs::write(dir.join("models/pair.toml"), PAIR_MODEL).unwrap();
    let scene = dir.join("scenes/pair.toml");
    std::fs::write(
        &scene,
        format!("model = \"../models/pair.toml\"\n{PAIR_RUN}"),
    )
    .unwrap();
    scene.to_str().unwrap().to_owned()
}

/// `dir/inline.toml`: the impact pair's `[model]` in the scene itself.
fn pair_inline(dir: &Path) -> String {
    let scene = dir.join("inline.toml");
    std::fs::write(&scene, format!("{PAIR_MODEL}{PAIR_RUN}")).unwrap();
    scene.to_str().unwrap().to_owned()
}

#[test]
fn the_scene_file_is_never_written_over() {
    let root = tempfile::tempdir().unwrap();
    let work = root.path().join("work");
    std::fs::create_dir(&work).unwrap();
    std::fs::write(work.join("scene.toml"), BASE).unwrap();
    let before = snapshot(root.path());
    // `--out .` in the scene's folder: a file of the name the set writes.
    let output = lyapsweep(&["run", "scene.toml", "--out", ".", "-q"], Some(&work));
    refused(
        &output,
        &["scene.toml", "which this command reads", "another folder"],
    );
    assert_eq!(
        snapshot(root.path()),
        before,
        "a file was written or changed"
    );
    // The same folder named by its path, and the scene by its own.
    let scene = work.join("scene.toml");
    let output = lyapsweep(
        &[
            "run",
            scene.to_str().unwrap(),
            "--out",
            work.to_str().unwrap(),
            "-q",
        ],
        None,
    );
    refused(&output, &["which this command reads"]);
    assert_eq!(snapshot(root.path()), before);
}

#[test]
fn a_bad_dispatch_budget_in_the_environment_is_refused_before_any_work() {
    let root = tempfile::tempdir().unwrap();
    let scene = root.path().join("base.toml");
    std::fs::write(&scene, BASE).unwrap();
    let out = root.path().join("out");
    for bad in ["0", "-5", "many", "1e6"] {
        let output = Command::new(env!("CARGO_BIN_EXE_lyapsweep"))
            .args([
                "run",
                scene.to_str().unwrap(),
                "--out",
                out.to_str().unwrap(),
            ])
            .env("LYAPSWEEP_DISPATCH_LANE_STEPS", bad)
            .output()
            .unwrap();
        refused(
            &output,
            &[
                "LYAPSWEEP_DISPATCH_LANE_STEPS",
                &format!("\"{bad}\""),
                "whole number",
            ],
        );
        assert!(!out.exists(), "{bad}: nothing written");
    }
}

#[test]
fn the_model_file_is_never_written_over() {
    let root = tempfile::tempdir().unwrap();
    let scene = pair_in_files(root.path());
    let before = snapshot(root.path());
    let models = root.path().join("models");
    let output = lyapsweep(
        &["run", &scene, "--out", models.to_str().unwrap(), "-q"],
        None,
    );
    refused(&output, &["models/pair.toml", "which this command reads"]);
    assert_eq!(snapshot(root.path()), before);
    // The model file is read relative to the scene: from the scenes
    // folder, `--out ../models` is the same folder.
    let output = lyapsweep(
        &["run", "pair.toml", "--out", "../models", "-q"],
        Some(&root.path().join("scenes")),
    );
    refused(&output, &["pair.toml", "which this command reads"]);
    assert_eq!(snapshot(root.path()), before);
}

#[test]
fn data_files_without_a_manifest_are_not_an_output_set() {
    let root = tempfile::tempdir().unwrap();
    let scene = root.path().join("base.toml");
    std::fs::write(&scene, BASE).unwrap();
    let theirs = root.path().join("theirs");
    std::fs::create_dir(&theirs).unwrap();
    std::fs::write(theirs.join("spectrum.csv"), "eta,lambda_1\n0.8,-0.05\n").unwrap();
    std::fs::write(theirs.join("scene.toml"), "# someone's notes\n").unwrap();
    let before = snapshot(root.path());
    let output = lyapsweep(
        &[
            "run",
            scene.to_str().unwrap(),
            "--out",
            theirs.to_str().unwrap(),
            "-q",
        ],
        None,
    );
    refused(
        &output,
        &[
            "theirs",
            "scene.toml, spectrum.csv but no manifest.toml",
            "not a lyapsweep output set",
        ],
    );
    assert_eq!(snapshot(root.path()), before);
    // A set the tool wrote (it has its manifest) is still replaced.
    let out = root.path().join("out");
    let run = |extra: &[&str]| {
        let args = [
            &[
                "run",
                scene.to_str().unwrap(),
                "--out",
                out.to_str().unwrap(),
                "-q",
            ][..],
            extra,
        ]
        .concat();
        ok(lyapsweep(&args, None))
    };
    run(&[]);
    run(&["--set", "sweep.count=2"]);
    let spectrum = std::fs::read_to_string(out.join("spectrum.csv")).unwrap();
    assert_eq!(spectrum.lines().count(), 3, "header and two values");
}

#[test]
fn override_paths_index_arrays() {
    let root = tempfile::tempdir().unwrap();
    let in_files = pair_in_files(root.path());
    let inline = pair_inline(root.path());
    let model_before = std::fs::read(root.path().join("models/pair.toml")).unwrap();
    for scene in [&in_files, &inline] {
        let out = root.path().join("out");
        ok(lyapsweep(
            &[
                "run",
                scene,
                "--out",
                out.to_str().unwrap(),
                "-q",
                "--set",
                "model.events[1].surface=\"-1.5 - x\"",
            ],
            None,
        ));
        // The scene as run holds the overridden element, the other as it was.
        let ran: toml::Table = std::fs::read_to_string(out.join("scene.toml"))
            .unwrap()
            .parse()
            .unwrap();
        let events = ran["model"]["events"].as_array().unwrap();
        assert_eq!(events[0]["surface"].as_str(), Some("x - gap"));
        assert_eq!(events[1]["surface"].as_str(), Some("-1.5 - x"));
        assert_eq!(events[1]["name"].as_str(), Some("left stop"));
    }
    assert_eq!(
        std::fs::read(root.path().join("models/pair.toml")).unwrap(),
        model_before,
        "the model file changed"
    );

    let refused_set = |scene: &str, assignment: &str, needles: &[&str]| {
        let out = root.path().join("refused");
        let output = lyapsweep(
            &[
                "run",
                scene,
                "--out",
                out.to_str().unwrap(),
                "-q",
                "--set",
                assignment,
            ],
            None,
        );
        refused(&output, needles);
        assert!(!out.exists(), "output written for {assignment}");
    };
    // Out of range: the key and the array's length.
    refused_set(
        &inline,
        "model.events[2].surface=\"x\"",
        &[
            "--set model.events[2].surface",
            "`model.events` has 2 elements",
        ],
    );
    // A model in another file: the message says so.
    refused_set(
        &in_files,
        "model.events[7].name=\"far\"",
        &[
            "--set model.events[7].name",
            "has 2 elements",
            "the scene's model is",
            "models/pair.toml",
        ],
    );
    refused_set(
        &in_files,
        "model.parameters[0]=1",
        &["`model.parameters` is not an array", "models/pair.toml"],
    );
    refused_set(
        &inline,
        "model.events[x].surface=1",
        &["`events[x]`", "an index is written [n]"],
    );
    // A bad value given by --set is the override's, not the file's.
    refused_set(
        &in_files,
        "model.events[0].surface=\"x +\"",
        &["--set model.events[0].surface", "model.events[0].surface: "],
    );
    refused_set(
        &in_files,
        "model.speed=1",
        &["--set model.speed=1", "unknown key"],
    );
    // A bad key written in the model file is named as that file's.
    std::fs::write(
        root.path().join("models/pair.toml"),
        PAIR_MODEL.replace(
            "name = \"impact-pair\"",
            "name = \"impact-pair\"\nspeed = 1",
        ),
    )
    .unwrap();
    let out = root.path().join("after");
    let output = lyapsweep(
        &["run", &in_files, "--out", out.to_str().unwrap(), "-q"],
        None,
    );
    refused(
        &output,
        &["model.speed in", "models/pair.toml", "unknown key"],
    );
    assert!(!out.exists());
}

/// The shard count the work-limit refusal advises (`--shard i/N`).
fn advised_shards(message: &str) -> usize {
    let at = message.find("--shard i/").expect("advice given") + "--shard i/".len();
    message[at..]
        .split(|c: char| !c.is_ascii_digit())
        .next()
        .unwrap()
        .parse()
        .unwrap()
}

#[test]
fn the_work_limit_advises_a_shard_count_it_accepts() {
    let root = tempfile::tempdir().unwrap();
    let scene = root.path().join("base.toml");
    std::fs::write(&scene, BASE).unwrap();
    // A file where the output folder goes: a run that passes the size
    // checks is refused there, before it computes anything.
    let file = root.path().join("a-file");
    std::fs::write(&file, "").unwrap();
    let run = |iterations: &str, shard: Option<String>| {
        let mut args = vec![
            "run".to_owned(),
            scene.to_str().unwrap().to_owned(),
            "--out".into(),
            file.to_str().unwrap().to_owned(),
            "-q".into(),
            "--set".into(),
            "sweep.count=5".into(),
            "--set".into(),
            format!("integration.iterations={iterations}"),
        ];
        if let Some(shard) = shard {
            args.extend(["--shard".to_owned(), shard]);
        }
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        lyapsweep(&args, None)
    };
    // Five values of about 0.4e15 lane-steps each: two shards would give
    // one of them three values, over the limit.
    let iterations = "800000000000";
    let message = refused(
        &run(iterations, None),
        &["sweep.count", "lane-steps", "--shard i/"],
    );
    let shards = advised_shards(&message);
    assert!(
        (2..=5).contains(&shards),
        "advised {shards} shards: {message}"
    );
    for index in [0, shards - 1] {
        let output = run(iterations, Some(format!("{index}/{shards}")));
        refused(&output, &["a-file", "exists and is not a folder"]);
    }
    // The advice is the fewest shards that pass.
    let output = run(iterations, Some(format!("0/{}", shards - 1)));
    refused(&output, &["lane-steps"]);

    // One value alone past the limit: no shard count helps, and the
    // message says what does.
    let message = refused(
        &run("10000000000000", None),
        &["one sweep value alone", "integration.iterations", "lower"],
    );
    assert!(!message.contains("--shard i/"), "{message}");
    assert_eq!(std::fs::read(&file).unwrap(), b"");
}

#[test]
fn model_check_tells_a_scene_from_a_model() {
    let root = tempfile::tempdir().unwrap();
    let scene = pair_in_files(root.path());
    let model = root.path().join("models/pair.toml");
    let direct = ok(lyapsweep(
        &["model", "check", model.to_str().unwrap()],
        None,
    ));
    // A scene naming its model file: that file is checked, and stderr says so.
    let through = ok(lyapsweep(&["model", "check", &scene], None));
    assert_eq!(stdout(&through), stdout(&direct));
    let note = stderr(&through);
    assert!(
        note.contains("is a scene file") && note.contains("models/pair.toml"),
        "{note}"
    );
    // A scene with a built-in system has no model file to check.
    let system = root.path().join("system.toml");
    std::fs::write(&system, BASE).unwrap();
    let output = lyapsweep(&["model", "check", system.to_str().unwrap()], None);
    refused(
        &output,
        &[
            "system.toml",
            "is a scene file",
            "built into lyapsweep",
            "impact-oscillator",
            "no model file",
        ],
    );
    assert!(stdout(&output).is_empty());
    // A scene with neither.
    let neither = root.path().join("neither.toml");
    std::fs::write(&neither, PAIR_RUN).unwrap();
    let output = lyapsweep(&["model", "check", neither.to_str().unwrap()], None);
    refused(&output, &["neither.toml", "is a scene file", "no [model]"]);
}

#[test]
fn a_huge_name_is_echoed_clipped() {
    let root = tempfile::tempdir().unwrap();
    let huge = "k".repeat(1 << 20);
    let out = root.path().join("out");
    let check = |output: Output, needles: &[&str]| {
        let text = refused(&output, needles);
        assert!(text.len() < 1000, "{} bytes of message", text.len());
        assert!(text.contains("k…"), "{text}");
        assert!(!text.contains(&"k".repeat(61)), "{text}");
        assert!(!out.exists());
    };
    let scene_with = |name: &str, text: String| {
        let path = root.path().join(name);
        std::fs::write(&path, text).unwrap();
        path.to_str().unwrap().to_owned()
    };
    let run = |scene: &str, extra: &[&str]| {
        let args = [
            &["run", scene, "--out", out.to_str().unwrap(), "-q"][..],
            extra,
        ]
        .concat();
        lyapsweep(&args, None)
    };
    // Unknown keys of the scene file: at the top, in a section, in [system].
    let top = scene_with("top.toml", format!("{huge} = 1\n{BASE}"));
    check(run(&top, &[]), &["top.toml", "unknown field"]);
    let section = scene_with(
        "section.toml",
        BASE.replace("count = 3", &format!("{huge} = 3")),
    );
    check(run(&section, &[]), &["sweep", "unknown field"]);
    let system = scene_with(
        "system.toml",
        BASE.replace("[sweep]", &format!("{huge} = 1.0\n[sweep]")),
    );
    check(run(&system, &[]), &["system.kkk", "has no parameter"]);
    let name = scene_with("name.toml", format!("name = \"{huge}/\"\n{BASE}"));
    check(run(&name, &[]), &["name", "plain folder name"]);
    // Unknown `--set` keys. One argument holds at most 128 KiB on Linux.
    let base = scene_with("base.toml", BASE.to_owned());
    let key = &huge[..100_000];
    check(
        run(&base, &["--set", &format!("integration.{key}=1")]),
        &["--set integration.kkk", "unknown field"],
    );
    check(
        run(&base, &["--set", &format!("system.{key}=1")]),
        &["system.kkk", "has no parameter"],
    );
    check(
        run(&base, &["--set", &format!("sweep.parameter={key}")]),
        &["sweep.parameter", "has no parameter"],
    );
    check(
        run(&base, &["--set", &format!("run.backend={key}")]),
        &["--set run.backend=kkk", "unknown variant"],
    );
    let inline = pair_inline(root.path());
    check(
        run(&inline, &["--set", &format!("model.{key}=1")]),
        &["--set model.kkk", "unknown key"],
    );
    check(
        run(&inline, &["--set", &format!("model.parameters.{key}=1")]),
        &["--set model.parameters.kkk", "has no parameter"],
    );
}

#[test]
fn plot_onto_a_file_is_refused() {
    let root = tempfile::tempdir().unwrap();
    let scene = root.path().join("base.toml");
    std::fs::write(&scene, BASE).unwrap();
    let out = root.path().join("out");
    ok(lyapsweep(
        &[
            "run",
            scene.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "-q",
        ],
        None,
    ));
    let file = root.path().join("figure.png");
    std::fs::write(&file, "my own figure").unwrap();
    let before = snapshot(root.path());
    let output = lyapsweep(
        &[
            "plot",
            out.to_str().unwrap(),
            "--out",
            file.to_str().unwrap(),
        ],
        None,
    );
    refused(&output, &["figure.png", "exists and is not a folder"]);
    assert_eq!(snapshot(root.path()), before);
}

#[test]
fn a_quick_look_lowers_the_points_to_the_iterations() {
    let root = tempfile::tempdir().unwrap();
    let seed = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/seed-fig3.toml");
    let out = root.path().join("quick");
    let output = ok(lyapsweep(
        &[
            "run",
            seed.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "-q",
            "--set",
            "sweep.count=2",
            "--set",
            "integration.iterations=10",
            "--backend",
            "cpu",
        ],
        None,
    ));
    let summary = stdout(&output);
    assert!(
        summary.contains("output.bifurcation_points lowered from 100 to 10"),
        "{summary}"
    );
    // min(100, 10) points of each of the two values.
    let text = std::fs::read_to_string(out.join("bifurcation.csv")).unwrap();
    let mut rows: BTreeMap<String, usize> = BTreeMap::new();
    for line in text.lines().skip(1) {
        *rows
            .entry(line.split(',').next().unwrap().to_owned())
            .or_default() += 1;
    }
    assert_eq!(rows.len(), 2, "{rows:?}");
    assert!(rows.values().all(|&n| n == 10), "{rows:?}");
    // The scene as written is the scene as run.
    let ran: toml::Table = std::fs::read_to_string(out.join("scene.toml"))
        .unwrap()
        .parse()
        .unwrap();
    assert_eq!(ran["output"]["bifurcation_points"].as_integer(), Some(10));
    assert_eq!(ran["integration"]["iterations"].as_integer(), Some(10));
    // Points asked for on the command line past the iterations are still
    // refused: that is the user's own contradiction.
    let refused_out = root.path().join("refused");
    let output = lyapsweep(
        &[
            "run",
            seed.to_str().unwrap(),
            "--out",
            refused_out.to_str().unwrap(),
            "-q",
            "--set",
            "integration.iterations=10",
            "--set",
            "output.bifurcation_points=50",
        ],
        None,
    );
    refused(&output, &["output.bifurcation_points", "must not exceed"]);
    assert!(!refused_out.exists());
}

/// Runs `scene_text` (with `args`) into `root/out`; the output.
fn run_text(root: &Path, scene_text: &str, args: &[&str]) -> Output {
    let scene = root.join("scene.toml");
    std::fs::write(&scene, scene_text).unwrap();
    let out = root.join("out");
    let mut all = vec![
        "run",
        scene.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "-q",
    ];
    all.extend_from_slice(args);
    lyapsweep(&all, None)
}

#[test]
fn a_max_period_past_the_iterations_is_refused_before_any_work() {
    // A period p is told from 2·p averaged iterations: past half of them
    // no period can be found, and a huge one once reserved its points.
    for (table, max_period) in [
        ("max_period = 1000000000000\n", "1000000000000"),
        (
            "starts = 4\nbox = { x = [0, 1] }\nmax_period = 1000000000\n",
            "1000000000",
        ),
        ("list = [[0, 0]]\nmax_period = 11\n", "11"),
    ] {
        let root = tempfile::tempdir().unwrap();
        let output = run_text(root.path(), &format!("{BASE}[attractors]\n{table}"), &[]);
        refused(
            &output,
            &[
                "attractors.max_period",
                "at most 10",
                &format!("got {max_period}"),
                "integration.iterations is 20",
            ],
        );
        assert_eq!(
            std::fs::read_dir(root.path()).unwrap().count(),
            1,
            "{table}: nothing but the scene written"
        );
    }
}

#[test]
fn a_max_period_whose_points_no_machine_holds_is_refused_before_any_work() {
    // A map may average 1e14 iterations within the work limit; holding
    // 2·5e13 points for the period test is petabytes on any machine.
    let root = tempfile::tempdir().unwrap();
    let scene = "[system]\nkind = \"henon\"\n[sweep]\nparameter = \"a\"\nvalues = [1.4]\n\
                 [integration]\ntransient = 1\niterations = 100000000000000\n\
                 [attractors]\nmax_period = 50000000000000\n";
    let output = run_text(root.path(), scene, &[]);
    refused(
        &output,
        &[
            "attractors.max_period",
            "period test",
            "this machine has free",
        ],
    );
    assert_eq!(std::fs::read_dir(root.path()).unwrap().count(), 1);
}

#[test]
fn max_period_alone_is_one_start() {
    let root = tempfile::tempdir().unwrap();
    ok(run_text(
        root.path(),
        &format!("{BASE}[attractors]\nmax_period = 10\n"),
        &[],
    ));
    let attractors = std::fs::read_to_string(root.path().join("out/attractors.csv")).unwrap();
    // A header and one attractor for each of the three values.
    assert_eq!(attractors.lines().count(), 4, "{attractors}");
}

/// Runs the base scene into `root/out` with one environment variable set.
fn run_with_variable(root: &Path, name: &str, value: &str) -> Output {
    let scene = root.join("base.toml");
    std::fs::write(&scene, BASE).unwrap();
    Command::new(env!("CARGO_BIN_EXE_lyapsweep"))
        .args([
            "run",
            scene.to_str().unwrap(),
            "--out",
            root.join("out").to_str().unwrap(),
        ])
        .env(name, value)
        .output()
        .unwrap()
}

#[test]
fn bad_environment_values_are_refused_before_any_work() {
    let cases: &[(&str, &str, &str)] = &[
        ("LYAPSWEEP_PROGRESS_SECONDS", "1e308", "from 0 to 1e9"),
        ("LYAPSWEEP_PROGRESS_SECONDS", "-1", "from 0 to 1e9"),
        ("LYAPSWEEP_PROGRESS_SECONDS", "nan", "from 0 to 1e9"),
        ("LYAPSWEEP_PROGRESS_SECONDS", "abc", "from 0 to 1e9"),
        ("LYAPSWEEP_STEP_LOOPS", "bogus", "not a choice"),
        ("LYAPSWEEP_NO_AVX2", "0", "set it to 1"),
        ("RAYON_NUM_THREADS", "100000", "per core"),
        ("RAYON_NUM_THREADS", "four", "whole number"),
        ("WGPU_BACKEND", "foo", "not a backend"),
        ("LYAPSWEEP_SHADER_DIR", "/no/such/folder", "not a folder"),
    ];
    for (name, value, reason) in cases {
        let root = tempfile::tempdir().unwrap();
        let output = run_with_variable(root.path(), name, value);
        refused(&output, &[name, value, reason]);
        assert!(
            !root.path().join("out").exists(),
            "{name}={value}: nothing written"
        );
    }
    // Good values run.
    for (name, value) in [
        ("LYAPSWEEP_PROGRESS_SECONDS", "0.5"),
        ("LYAPSWEEP_STEP_LOOPS", "interpreter"),
        ("LYAPSWEEP_NO_AVX2", "1"),
        ("RAYON_NUM_THREADS", "1"),
        ("WGPU_BACKEND", "vulkan"),
    ] {
        let root = tempfile::tempdir().unwrap();
        ok(run_with_variable(root.path(), name, value));
    }
}

#[test]
fn a_full_stdout_is_an_error_after_the_set_is_written() {
    let root = tempfile::tempdir().unwrap();
    let scene = root.path().join("base.toml");
    std::fs::write(&scene, BASE).unwrap();
    let out = root.path().join("out");
    let full = || {
        std::fs::OpenOptions::new()
            .write(true)
            .open("/dev/full")
            .unwrap()
    };
    let output = Command::new(env!("CARGO_BIN_EXE_lyapsweep"))
        .args([
            "run",
            scene.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
        .arg("-q")
        .stdout(full())
        .output()
        .unwrap();
    let text = stderr(&output);
    assert_eq!(output.status.code(), Some(1), "{text}");
    assert!(
        text.contains("standard output") && text.contains("was written whole"),
        "{text}"
    );
    assert!(!text.contains("panicked"), "{text}");
    assert!(out.join("manifest.toml").is_file(), "the set was written");
    let model = root.path().join("pair.toml");
    std::fs::write(&model, PAIR_MODEL).unwrap();
    let output = Command::new(env!("CARGO_BIN_EXE_lyapsweep"))
        .args(["model", "check", model.to_str().unwrap()])
        .stdout(full())
        .output()
        .unwrap();
    let text = stderr(&output);
    assert_eq!(output.status.code(), Some(1), "{text}");
    assert!(text.contains("standard output"), "{text}");
}

#[test]
fn a_closed_pipe_ends_the_printing_quietly() {
    use std::process::Stdio;
    let root = tempfile::tempdir().unwrap();
    let scene = root.path().join("base.toml");
    std::fs::write(&scene, BASE).unwrap();
    for args in [
        vec!["devices".to_owned()],
        vec![
            "run".to_owned(),
            scene.to_str().unwrap().to_owned(),
            "--out".to_owned(),
            root.path().join("out").to_str().unwrap().to_owned(),
            "-q".to_owned(),
        ],
    ] {
        let mut child = Command::new(env!("CARGO_BIN_EXE_lyapsweep"))
            .args(&args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        // The reader goes before a byte is read (`| head -c0`).
        drop(child.stdout.take());
        let output = child.wait_with_output().unwrap();
        let text = stderr(&output);
        assert_eq!(output.status.code(), Some(0), "{args:?}: {text}");
        assert!(text.is_empty(), "{args:?}: {text}");
    }
}

#[test]
fn plot_and_bench_write_over_no_file_of_the_users() {
    let root = tempfile::tempdir().unwrap();
    let scene = root.path().join("base.toml");
    std::fs::write(&scene, BASE).unwrap();
    let out = root.path().join("out");
    let out_s = out.to_str().unwrap();
    ok(lyapsweep(
        &["run", scene.to_str().unwrap(), "--out", out_s, "-q"],
        None,
    ));
    // The user's own figures in the folder --out names: kept, refused.
    let figures = root.path().join("figures");
    std::fs::create_dir(&figures).unwrap();
    std::fs::write(figures.join("figure.png"), "my own figure").unwrap();
    let before = snapshot(root.path());
    let output = lyapsweep(&["plot", out_s, "--out", figures.to_str().unwrap()], None);
    refused(&output, &["figure.png", "not written by lyapsweep"]);
    assert_eq!(snapshot(root.path()), before);
    // A new folder takes the figures, and takes them again.
    let fresh = root.path().join("fresh");
    for _ in 0..2 {
        let output = ok(lyapsweep(
            &["plot", out_s, "--out", fresh.to_str().unwrap()],
            None,
        ));
        assert!(
            stdout(&output).contains("figure.png"),
            "{}",
            stdout(&output)
        );
    }
    // A folder inside the set would be a foreign folder there.
    let before = snapshot(root.path());
    let inside = out.join("figures");
    let output = lyapsweep(&["plot", out_s, "--out", inside.to_str().unwrap()], None);
    refused(&output, &["inside the output set"]);
    assert_eq!(snapshot(root.path()), before);
    // bench --out: the user's bench.md, refused before any measurement.
    let reports = root.path().join("reports");
    std::fs::create_dir(&reports).unwrap();
    std::fs::write(reports.join("bench.md"), "my notes").unwrap();
    let before = snapshot(root.path());
    let output = lyapsweep(
        &["bench", "--quick", "--out", reports.to_str().unwrap()],
        None,
    );
    refused(&output, &["bench.md", "not written by lyapsweep"]);
    assert_eq!(snapshot(root.path()), before);
}

#[test]
fn flags_and_values_are_told_in_the_users_words() {
    let root = tempfile::tempdir().unwrap();
    let scene = root.path().join("base.toml");
    std::fs::write(&scene, BASE).unwrap();
    let scene = scene.to_str().unwrap();
    let out = root.path().join("out");
    let out_s = out.to_str().unwrap();
    let run = |extra: &[&str]| {
        let mut args = vec!["run", scene, "--out", out_s, "-q"];
        args.extend_from_slice(extra);
        lyapsweep(&args, None)
    };
    // A table given a number: what the table holds, not the code's type.
    let text = refused(
        &run(&["--set", "sweep=5"]),
        &["--set sweep=5", "a table (parameter"],
    );
    assert!(!text.contains("Raw"), "{text}");
    // A huge number is written with its exponent, not as 301 digits.
    let text = refused(
        &run(&["--set", "integration.perturbation=-1e300"]),
        &["integration.perturbation", "got -1e300"],
    );
    assert!(text.len() < 200, "{text}");
    // A shard that starts with a hyphen is told what a shard is.
    let text = refused(&run(&["--shard", "-1/3"]), &["-1/3"]);
    assert!(!text.contains("unexpected argument"), "{text}");
    // --device picks a GPU adapter: with the CPU backend it is refused.
    refused(
        &run(&["--device", "7", "--backend", "cpu"]),
        &["--device", "GPU", "cpu"],
    );
    assert!(!out.exists(), "nothing written");
}

#[test]
fn extreme_values_are_written_with_an_exponent_that_reads_back() {
    let root = tempfile::tempdir().unwrap();
    let scene = root.path().join("base.toml");
    std::fs::write(&scene, BASE).unwrap();
    let out = root.path().join("out");
    let output = lyapsweep(
        &[
            "run",
            scene.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "-q",
            "--set",
            "sweep.from=1e300",
            "--set",
            "sweep.to=2e300",
        ],
        None,
    );
    // Whatever the lanes make of such values, the files hold them short.
    assert!(
        matches!(output.status.code(), Some(0 | 1)),
        "{}",
        stderr(&output)
    );
    let spectrum = std::fs::read_to_string(out.join("spectrum.csv")).unwrap();
    let first: Vec<&str> = spectrum
        .lines()
        .skip(1)
        .map(|l| l.split(',').next().unwrap())
        .collect();
    assert_eq!(first, ["1e300", "1.5e300", "2e300"], "{spectrum}");
    for (text, value) in first.iter().zip([1e300, 1.5e300, 2e300]) {
        assert_eq!(text.parse::<f64>().unwrap(), value);
    }
    assert!(stdout(&output).len() < 2000, "{}", stdout(&output));
    // The model's own checks print them short too: a start behind the
    // wall, a parameter out of its range.
    for (set, needle) in [
        (
            "integration.initial_state=[1e300, 0]",
            "x = 1e300 lies behind the stop at 2",
        ),
        ("system.restitution=1e300", "must lie in [0, 1], got 1e300"),
    ] {
        let output = lyapsweep(
            &[
                "run",
                scene.to_str().unwrap(),
                "--out",
                out.to_str().unwrap(),
                "--set",
                set,
            ],
            None,
        );
        refused(&output, &[needle]);
    }
}
