//! On an x86-64 CPU without AVX2 the integrator steps a lane's
//! trajectories one at a time, compiled for the baseline instruction set,
//! instead of in vector batches (`integrate::avx2`). `LYAPSWEEP_NO_AVX2`
//! runs that path here: every committed scene below must write the same
//! bytes either way.

use std::path::Path;
use std::process::Command;

/// `lyapsweep run` of a committed scene, shortened, on the CPU path; the
/// bytes of its spectrum and bifurcation files.
fn run(name: &str, overrides: &[&str], without_avx2: bool) -> Vec<Vec<u8>> {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let scene = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scenes")
        .join(name);
    let mut command = Command::new(env!("CARGO_BIN_EXE_lyapsweep"));
    command.arg("run").arg(&scene).arg("--out").arg(&out).args([
        "--set",
        "run.backend=\"cpu\"",
        "--set",
        "output.plot=false",
    ]);
    for o in overrides {
        command.args(["--set", o]);
    }
    if without_avx2 {
        command.env("LYAPSWEEP_NO_AVX2", "1");
    } else {
        command.env_remove("LYAPSWEEP_NO_AVX2");
    }
    let status = command.output().expect("the binary runs");
    assert!(
        status.status.success(),
        "{name}: {}",
        String::from_utf8_lossy(&status.stderr)
    );
    let mut files: Vec<_> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "csv"))
        .collect();
    files.sort();
    assert!(files.len() >= 2, "{name}: {files:?}");
    files.iter().map(|p| std::fs::read(p).unwrap()).collect()
}

/// The seed's oscillator (a wall), the friction belt (switches and
/// sliding), the impact pair (two stops, four states) and the Lorenz
/// section (a Poincaré map), each over a few values in lanes stepped
/// together.
#[test]
fn the_scalar_path_writes_the_batched_path_s_bytes() {
    let short = [
        "sweep.count=9",
        "integration.transient=20",
        "integration.iterations=20",
        "output.bifurcation_points=5",
    ];
    for name in [
        "seed-fig3.toml",
        "friction-belt.toml",
        "impact-pair.toml",
        "lorenz-section.toml",
    ] {
        let batched = run(name, &short, false);
        let scalar = run(name, &short, true);
        assert!(batched == scalar, "{name}: the files differ");
    }
}
