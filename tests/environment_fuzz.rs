//! Arbitrary text in every environment variable the README names (its
//! "Environment variables" table) is a run or a refusal naming the
//! variable, never a panic or an abort: exit code 0, or 2 with a one-line
//! message naming it.

use std::process::Command;

use proptest::prelude::*;

/// A one-value scene of a model (so that `CC` and `XDG_CACHE_HOME` are
/// read), a few iterations: a run takes milliseconds.
const SCENE: &str = r#"
[model]
name = "drop"
states = ["x"]
[model.parameters]
a = 0.5
[model.equations]
x = "-a*x"
[model.map]
period = "1"
[sweep]
parameter = "a"
values = [0.5]
[integration]
steps_per_period = 10
transient = 2
iterations = 4
[run]
backend = "cpu"
"#;

const VARIABLES: [&str; 11] = [
    "WGPU_BACKEND",
    "WGPU_ADAPTER_NAME",
    "CC",
    "XDG_CACHE_HOME",
    "LYAPSWEEP_STEP_LOOPS",
    "LYAPSWEEP_NO_AVX2",
    "LYAPSWEEP_SHADER_DIR",
    "LYAPSWEEP_DISPATCH_LANE_STEPS",
    "LYAPSWEEP_PROGRESS_SECONDS",
    "RAYON_NUM_THREADS",
    "LYAPSWEEP_REQUIRE_GPU",
];

/// Text a variable may be set to: any characters but NUL (which no
/// environment holds), sometimes a number's spelling.
fn value() -> impl Strategy<Value = String> {
    prop_oneof![
        "[^\\x00]{0,12}",
        "-?[0-9]{1,25}(\\.[0-9]*)?(e-?[0-9]{1,3})?",
        Just("nan".to_owned()),
        Just("inf".to_owned()),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    #[test]
    fn any_value_is_a_run_or_a_refusal_naming_the_variable(
        variable in 0..VARIABLES.len(),
        value in value(),
    ) {
        let name = VARIABLES[variable];
        let root = tempfile::tempdir().unwrap();
        let scene = root.path().join("scene.toml");
        std::fs::write(&scene, SCENE).unwrap();
        let output = Command::new(env!("CARGO_BIN_EXE_lyapsweep"))
            // Not quiet: the progress thread reads its variable too.
            .args(["run", scene.to_str().unwrap(), "--out", "out"])
            .current_dir(root.path())
            // The step loops' cache stays in the test's folder.
            .env("XDG_CACHE_HOME", root.path().join("cache"))
            .env(name, &value)
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&output.stderr);
        match output.status.code() {
            Some(0) => {}
            Some(2) => prop_assert!(text.contains(name), "{name}={value:?}: {text}"),
            code => prop_assert!(false, "{name}={value:?}: exit {code:?}: {text}"),
        }
        prop_assert!(!text.contains("panicked"), "{name}={value:?}: {text}");
    }
}
