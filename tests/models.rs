//! The `[model]` table: the shape the models issue fixes parses as written,
//! and every malformed model is refused naming its key (and, for an
//! expression, the column).

use lyapsweep::model::language::expr::Var;
use lyapsweep::model::{Map, Model};

/// The models issue's example, exactly as written there.
const IMPACT_PAIR: &str = r#"
[model]
name = "impact-pair"
states = ["x", "v"]                  # the map's coordinates, in this order
[model.parameters]                   # name = default value; any of them can be swept
zeta = 0.05
f = 1.0
gap = 1.0
e = 0.8
eta = 0.8
[model.equations]                    # d(state)/dt, one per state; time is `t`
x = "v"
v = "-2*zeta*v - x + f*cos(eta*t)"
[model.map]
period = "2*pi/eta"                  # stroboscopic map of a forced system
[[model.events]]                     # impacts: fire when `surface` crosses 0 from below
name = "right stop"
surface = "x - gap"
reset = { v = "-e*v" }               # states not named keep their value
[[model.events]]
name = "left stop"
surface = "-gap - x"
reset = { v = "-e*v" }
"#;

fn parse(text: &str) -> lyapsweep::Result<Model> {
    let table: toml::Table = text.parse().expect("valid TOML");
    Model::parse(&table["model"], "model")
}

#[test]
fn the_issue_s_impact_pair_parses_as_written() {
    let model = parse(IMPACT_PAIR).unwrap();
    assert_eq!(model.name, "impact-pair");
    assert_eq!(model.names.states, ["x", "v"]);
    assert_eq!(model.names.parameters, ["e", "eta", "f", "gap", "zeta"]);
    assert_eq!(model.defaults, [0.8, 0.8, 1.0, 1.0, 0.05]);
    // p in the parameters' order: e, eta, f, gap, zeta.
    let p = [0.8, 0.8, 1.0, 1.0, 0.05];
    let (x, v, t) = (0.3, -0.7, 1.9);
    let v_dot = model.equations[1].eval(&[x, v], &p, t);
    assert_eq!(v_dot, -2.0 * 0.05 * v - x + 1.0 * (0.8 * t).cos());
    assert_eq!(model.equations[0].eval(&[x, v], &p, t), v);
    // div F = ∂(v)/∂x + ∂(-2ζv - x + f cos ηt)/∂v = -2ζ.
    let divergence = model.equations[0]
        .derivative(Var::State(0))
        .eval(&[x, v], &p, t)
        + model.equations[1]
            .derivative(Var::State(1))
            .eval(&[x, v], &p, t);
    assert_eq!(divergence, -0.1);
    assert_eq!(model.period(&p), Some(2.0 * std::f64::consts::PI / 0.8));
    assert_eq!(model.events.len(), 2);
    assert_eq!(model.events[0].name, "right stop");
    assert_eq!(model.events[1].surface.eval(&[x, v], &p, t), -1.0 - x);
    let (state, reset) = &model.events[1].reset[0];
    assert_eq!(*state, 1);
    assert_eq!(reset.eval(&[x, v], &p, t), -0.8 * v);
}

#[test]
fn a_section_model_parses() {
    let lorenz = r#"
[model]
states = ["x", "y", "z"]
parameters = { sigma = 10.0, rho = 28.0, beta = 2.6666666666666665 }
equations = { x = "sigma*(y - x)", y = "x*(rho - z) - y", z = "x*y - beta*z" }
map = { section = { state = "z", at = "rho - 1", direction = "decreasing" } }
"#;
    let model = parse(lorenz).unwrap();
    match &model.map {
        Map::Section {
            state,
            at,
            increasing,
        } => {
            assert_eq!(*state, 2);
            assert!(!increasing);
            assert_eq!(at.eval(&[], &[2.6666666666666665, 28.0, 10.0], 0.0), 27.0);
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(model.period(&[1.0, 28.0, 10.0]), None);
}

/// `edit` applied to the impact pair is refused with `key` and `needle` in
/// the message.
fn refused(edit: impl Fn(&str) -> String, key: &str, needle: &str) {
    let text = edit(IMPACT_PAIR);
    let err = parse(&text).expect_err(key).to_string();
    assert!(err.starts_with(&format!("{key}: ")), "{err}");
    assert!(err.contains(needle), "{needle:?} not in {err}");
    assert!(err.lines().count() == 1, "{err}");
}

#[test]
fn malformed_models_are_refused_naming_the_key() {
    refused(
        |s| s.replace("-2*zeta*v", "-2*zeta2*v"),
        "model.equations.v",
        "unknown name 'zeta2' (column 4)",
    );
    refused(
        |s| s.replace("x = \"v\"\n", ""),
        "model.equations",
        "no equation for the state 'x'",
    );
    refused(
        |s| s.replace("x = \"v\"\n", "x = \"v\"\nw = \"x\"\n"),
        "model.equations.w",
        "'w' is not a state (states: x, v)",
    );
    refused(
        |s| s.replace("gap = 1.0", "gap = 1.0\nx = 2.0"),
        "model.parameters.x",
        "'x' is both a state and a parameter",
    );
    refused(
        |s| {
            s.replace(
                "reset = { v = \"-e*v\" }               #",
                "reset = { u = \"0\" } #",
            )
        },
        "model.events[0].reset.u",
        "'u' is not a state",
    );
    refused(
        |s| s.replace("period = \"2*pi/eta\"", "period = \"2*pi/eta + x\""),
        "model.map.period",
        "may not use the state 'x'",
    );
    refused(
        |s| {
            s.replace(
                "period = \"2*pi/eta\"",
                "period = \"2*pi/eta\"\nsection = { state = \"x\", at = \"0\" }",
            )
        },
        "model.map",
        "not both",
    );
    refused(
        |s| s.replace("states = [\"x\", \"v\"]", "states = [\"x\", \"x\"]"),
        "model.states",
        "listed twice",
    );
    refused(
        |s| s.replace("states = [\"x\", \"v\"]", "states = [\"x\", \"pi\"]"),
        "model.states",
        "'pi' is reserved",
    );
    refused(
        |s| s.replace("surface = \"x - gap\"", "surface = \"x - gap)\""),
        "model.events[0].surface",
        "unexpected ')' (column 8)",
    );
    refused(
        |s| {
            s.replace(
                "name = \"impact-pair\"",
                "name = \"impact-pair\"\nkind = \"x\"",
            )
        },
        "model.kind",
        "unknown key",
    );
    refused(
        |s| s.replace("f = 1.0", "f = \"one\""),
        "model.parameters.f",
        "expected a number",
    );
    // The period must be positive at every swept value: checked per value.
    let model = parse(IMPACT_PAIR).unwrap();
    let err = model
        .check_period(
            &[0.8, -0.5, 1.0, 1.0, 0.05],
            "model",
            "eta = -0.5, sweep value 3",
        )
        .unwrap_err()
        .to_string();
    assert!(
        err.starts_with("model.map.period: must be a finite number > 0"),
        "{err}"
    );
    assert!(err.contains("(at eta = -0.5, sweep value 3)"), "{err}");
}

/// A model's description (its compiled code, native code and WGSL
/// included) is kept for the process: a scene run again and again in one
/// process (the Python package's loop) compiles and keeps it once, not
/// once per run.
#[test]
fn the_same_model_loaded_again_is_kept_once() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/duffing.toml");
    let first = lyapsweep::scene::load(&path, &[]).unwrap();
    let kept = lyapsweep::system::model::described();
    for _ in 0..20 {
        let again = lyapsweep::scene::load(&path, &[]).unwrap();
        assert!(std::ptr::eq(first.system, again.system));
    }
    assert_eq!(lyapsweep::system::model::described(), kept);
    // An override of a parameter's default is the scene's, not the model's.
    let other = lyapsweep::scene::load(&path, &["sweep.count=3".into()]).unwrap();
    assert!(std::ptr::eq(first.system, other.system));
    assert_eq!(lyapsweep::system::model::described(), kept);
}
