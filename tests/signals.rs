//! The `lyapsweep` binary stopped by SIGINT or SIGTERM part way through a
//! run: it ends within about a second, exits 130 or 143, removes its
//! staging folder and leaves the output folder's previous set as it was,
//! byte for byte.

mod common;

use std::collections::BTreeMap;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use lyapsweep::scene::Precision;

/// A sweep of the impact oscillator that takes a few seconds here.
const SHORT: &str = r#"
[system]
kind = "impact-oscillator"
eta = 0.8
[sweep]
from = 0.5
to = 1.5
count = 4
[integration]
steps_per_period = 100
transient = 5
iterations = 10
"#;

/// The same sweep, long: minutes on two cores, far beyond the signal.
fn long_scene() -> String {
    SHORT
        .replace("count = 4", "count = 400")
        .replace("iterations = 10", "iterations = 20000")
}

/// Every file under `dir` (relative path → bytes).
fn files(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    let mut all = BTreeMap::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let entry = entry.unwrap();
        let path = entry.path();
        let name = entry.file_name().to_string_lossy().into_owned();
        if path.is_dir() {
            for (sub, bytes) in files(&path) {
                all.insert(format!("{name}/{sub}"), bytes);
            }
        } else {
            all.insert(name, std::fs::read(&path).unwrap());
        }
    }
    all
}

/// The staging folders beside `out` (`.out.lyapsweep-PID.partial`).
fn staging(parent: &Path) -> Vec<String> {
    std::fs::read_dir(parent)
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.') && n.contains(".partial"))
        .collect()
}

/// Runs the long scene on `backend` into a folder that holds a previous
/// set, sends `signal` once the run has staged its set and taken some
/// steps, and checks the exit code, the time to exit, that no staging
/// folder is left and that the previous set is untouched.
fn stopped_by(signal: libc::c_int, code: i32, backend: &str) {
    let _alone = one_at_a_time();
    // lavapipe has no f64: the GPU runs f32 (as `gpu_or_skip` checked).
    let precision = if backend == "gpu" { "f32" } else { "f64" };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let scene = dir.path().join("scene.toml");
    std::fs::write(&scene, SHORT).unwrap();
    let previous = Command::new(env!("CARGO_BIN_EXE_lyapsweep"))
        .args(["run", "--quiet", "--backend", backend])
        .args(["--precision", precision, "--out"])
        .arg(&out)
        .arg(&scene)
        .output()
        .unwrap();
    assert!(previous.status.success(), "{previous:?}");
    let before = files(&out);
    assert!(before.contains_key("spectrum.csv"), "{:?}", before.keys());

    std::fs::write(&scene, long_scene()).unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_lyapsweep"))
        .args(["run", "--quiet", "--backend", backend])
        .args(["--precision", precision, "--out"])
        .arg(&out)
        .arg(&scene)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let started = Instant::now();
    while staging(dir.path()).is_empty() {
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "no staging folder after a minute"
        );
        assert!(child.try_wait().unwrap().is_none(), "the run ended early");
        std::thread::sleep(Duration::from_millis(10));
    }
    // Into the lanes' iterations (and, on the GPU, its dispatches).
    std::thread::sleep(Duration::from_millis(1500));
    assert!(child.try_wait().unwrap().is_none(), "the run ended early");
    // SAFETY: kill has no memory preconditions; the pid is our child's,
    // not yet waited for.
    let sent = Instant::now();
    assert_eq!(unsafe { libc::kill(child.id() as libc::pid_t, signal) }, 0);
    let output = child.wait_with_output().unwrap();
    let took = sent.elapsed();
    let stderr = String::from_utf8_lossy(&output.stderr);
    // Straight to the stream: the time is a measurement worth seeing.
    use std::io::Write;
    let _ = writeln!(
        std::io::stderr(),
        "{backend}, signal {signal}: exited {:?} {:.3} s after it",
        output.status.code(),
        took.as_secs_f64()
    );
    assert_eq!(output.status.code(), Some(code), "stderr: {stderr}");
    assert!(stderr.contains("stopped"), "stderr: {stderr}");
    // The CPU's lanes look at the stop every iteration: hundredths of a
    // second. A GPU run ends after the chunk of iterations in flight, about
    // 0.1 s of lavapipe's work (0.14 to 0.23 s measured from the signal to
    // the exit); the bound leaves room for busy cores.
    let bound = Duration::from_secs(2);
    assert!(took < bound, "took {took:?} from the signal to the exit");
    assert_eq!(staging(dir.path()), Vec::<String>::new(), "staging left");
    assert!(files(&out) == before, "the previous set changed");
}

#[test]
fn sigint_stops_a_cpu_run_and_keeps_the_previous_set() {
    stopped_by(libc::SIGINT, 130, "cpu");
}

#[test]
fn sigterm_stops_a_cpu_run_and_keeps_the_previous_set() {
    stopped_by(libc::SIGTERM, 143, "cpu");
}

#[test]
fn sigint_stops_a_gpu_run_and_keeps_the_previous_set() {
    if common::gpu_or_skip("sigint_stops_a_gpu_run", Precision::F32) {
        stopped_by(libc::SIGINT, 130, "gpu");
    }
}

#[test]
fn sigterm_stops_a_gpu_run_and_keeps_the_previous_set() {
    if common::gpu_or_skip("sigterm_stops_a_gpu_run", Precision::F32) {
        stopped_by(libc::SIGTERM, 143, "gpu");
    }
}

/// The tests of this file one at a time: each keeps the cores busy, and
/// a stop timed against the others' runs (lavapipe's above all) measures
/// the load, not the stop.
fn one_at_a_time() -> std::sync::MutexGuard<'static, ()> {
    static ALONE: std::sync::Mutex<()> = std::sync::Mutex::new(());
    ALONE.lock().unwrap_or_else(|e| e.into_inner())
}

/// A million starts per value (the most `[attractors]` takes): the run
/// plans each value once, not each of its starts, so its first progress
/// line comes within seconds (it came after 23 to 40 s at 8 values on two
/// busy cores, planning 2^20 lanes per value on one thread), and Ctrl-C
/// stops it.
#[test]
fn a_million_starts_per_value_show_progress_within_seconds() {
    let _alone = one_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("scene.toml");
    let text = SHORT.replace("count = 4", "count = 8")
        + "[attractors]\ngrid = [1024, 1024]\nbox = { x = [-3, 0.9], v = [-3, 3] }\n";
    std::fs::write(&scene, text).unwrap();
    let started = Instant::now();
    let mut child = Command::new(env!("CARGO_BIN_EXE_lyapsweep"))
        // `auto` (the default) plans the sweep for the GPU, to choose.
        .args(["run", "--out"])
        .arg(dir.path().join("out"))
        .arg(&scene)
        .env("LYAPSWEEP_PROGRESS_SECONDS", "0.2")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    use std::io::BufRead;
    let mut lines = std::io::BufReader::new(child.stderr.take().unwrap()).lines();
    let mut seen = Vec::new();
    for line in lines.by_ref() {
        let line = line.unwrap();
        let progress = line.starts_with("progress");
        seen.push(line);
        if progress {
            break;
        }
    }
    let waited = started.elapsed();
    // SAFETY: as in `stopped_by`.
    assert_eq!(
        unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGINT) },
        0
    );
    // Read to the end: the run still writes to its stderr.
    let rest: Vec<String> = lines.map(|l| l.unwrap()).collect();
    let status = child.wait().unwrap();
    assert!(
        rest.iter().any(|l| l.contains("stopped by SIGINT")),
        "{rest:?}"
    );
    use std::io::Write;
    let _ = writeln!(
        std::io::stderr(),
        "8 values × 2^20 starts: first progress after {:.2} s",
        waited.as_secs_f64()
    );
    assert!(
        seen.last().is_some_and(|l| l.starts_with("progress")),
        "{seen:?}"
    );
    assert!(waited < Duration::from_secs(6), "{waited:?}: {seen:?}");
    assert_eq!(status.code(), Some(130));
    assert_eq!(staging(dir.path()), Vec::<String>::new(), "staging left");
}
