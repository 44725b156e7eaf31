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
