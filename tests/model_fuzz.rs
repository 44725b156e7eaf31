//! Random and mutated model files through the parser, the compiler and
//! `model check`'s description: each is either a model or an input error
//! naming a key of the model, never a panic (a stack overflow would abort
//! this whole test binary, which fails it too).

use lyapsweep::model::compiled::Code;
use lyapsweep::model::describe::describe;
use lyapsweep::model::Model;
use proptest::prelude::*;

/// A model with a stop, a general event and a switch with a stick limit:
/// every table the language has, for the mutations to break.
const MODEL: &str = r#"[model]
name = "fuzzed"
states = ["x", "v"]
[model.parameters]
zeta = { value = 0.05, min = 0 }
f = 1.0
eta = 0.8
mu = 0.3
[model.equations]
x = "v"
v = "-2*zeta*v - x + f*cos(eta*t) - mu*sign(slip)"
[model.map]
period = "2*pi/eta"
[[model.switches]]
name = "slip"
surface = "v - 0.2"
stick_limit = "mu*1.5"
[[model.events]]
name = "wall"
surface = "x - 2"
reset = { v = "-0.8*v" }
[[model.events]]
name = "kick"
surface = "-x - 3 + 0.1*v^2"
reset = { v = "v + 0.1*x" }
"#;

/// What a text may break into: characters of expressions, TOML and names.
const ALPHABET: &[u8] = b"()+-*/^,.0123456789eExvtpi_ =\"[]{}#\nsincoqrtlgabmwhdf";

/// Parses, compiles and describes `text`: Ok where it is a model, the
/// error's message where it is not, which must be an input error naming
/// a key of the model.
fn through_the_checker(text: &str) -> Result<(), String> {
    let Ok(table) = text.parse::<toml::Table>() else {
        return Ok(()); // not TOML: the TOML parser's business
    };
    let Some(value) = table.get("model") else {
        return Ok(());
    };
    let result = Model::parse(value, "model")
        .and_then(|model| Code::compile(model, "model"))
        .map(|code| describe(&code));
    match result {
        Ok(text) => {
            assert!(!text.is_empty());
            Ok(())
        }
        Err(e) => {
            let message = e.to_string();
            assert!(e.is_input_error(), "not an input error: {message}");
            assert!(message.starts_with("model"), "no key named: {message}");
            assert!(
                message.len() < 2_000,
                "the message echoes the input: {message}"
            );
            Err(message)
        }
    }
}

/// Edits of one of three kinds at positions and with bytes drawn by proptest.
#[derive(Clone, Debug)]
enum Edit {
    Insert(usize, Vec<u8>),
    Delete(usize, usize),
    Replace(usize, u8),
    /// Repeats a stretch many times (deep nesting, long sums).
    Repeat(usize, usize, usize),
}

fn edit() -> impl Strategy<Value = Edit> {
    let byte = proptest::sample::select(ALPHABET);
    prop_oneof![
        (
            any::<usize>(),
            proptest::collection::vec(byte.clone(), 1..8)
        )
            .prop_map(|(at, bytes)| Edit::Insert(at, bytes)),
        (any::<usize>(), 1usize..6).prop_map(|(at, n)| Edit::Delete(at, n)),
        (any::<usize>(), byte).prop_map(|(at, b)| Edit::Replace(at, b)),
        (any::<usize>(), 1usize..6, 2usize..3000).prop_map(|(at, n, k)| Edit::Repeat(at, n, k)),
    ]
}

fn apply(text: &str, edits: &[Edit]) -> String {
    let mut bytes = text.as_bytes().to_vec();
    for e in edits {
        let len = bytes.len().max(1);
        match e {
            Edit::Insert(at, new) => {
                let at = at % len;
                bytes.splice(at..at, new.iter().copied());
            }
            Edit::Delete(at, n) => {
                let at = at % len;
                let end = (at + n).min(bytes.len());
                bytes.drain(at..end);
            }
            Edit::Replace(at, b) => {
                if !bytes.is_empty() {
                    let at = at % bytes.len();
                    bytes[at] = *b;
                }
            }
            Edit::Repeat(at, n, k) => {
                let at = at % len;
                let end = (at + n).min(bytes.len());
                let stretch = bytes[at..end].to_vec();
                let repeated: Vec<u8> = stretch
                    .iter()
                    .copied()
                    .cycle()
                    .take(stretch.len() * k)
                    .collect();
                bytes.splice(at..end, repeated);
            }
        }
    }
    String::from_utf8_lossy(&bytes).into_owned()
}

/// An expression-like string: random tokens of the language.
fn expression() -> impl Strategy<Value = String> {
    let token = proptest::sample::select(vec![
        "x", "v", "t", "pi", "zeta", "mu", "slip", "wall", "1", "0", "2.5", "1e999", "1e-320", "+",
        "-", "*", "/", "^", "(", ")", ",", "sin(", "cos(", "exp(", "log(", "sqrt(", "abs(",
        "atan2(", "min(", "max(", "pow(", "step(", "sign(", "tanh(", "nope(", "",
    ]);
    proptest::collection::vec(token, 0..40).prop_map(|t| t.concat())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2000, ..ProptestConfig::default() })]

    #[test]
    fn mutated_models_are_models_or_input_errors(edits in proptest::collection::vec(edit(), 1..4)) {
        // The interpreter: the C compiler would build an object for every
        // mutant, a second each.
        std::env::set_var("LYAPSWEEP_STEP_LOOPS", "interpreter");
        let _ = through_the_checker(&apply(MODEL, &edits));
    }

    #[test]
    fn random_expressions_anywhere_are_models_or_input_errors(
        text in expression(),
        place in 0usize..6,
    ) {
        std::env::set_var("LYAPSWEEP_STEP_LOOPS", "interpreter");
        let slots = [
            "\"-2*zeta*v - x + f*cos(eta*t) - mu*sign(slip)\"",
            "\"v - 0.2\"",
            "\"mu*1.5\"",
            "\"x - 2\"",
            "\"-0.8*v\"",
            "\"2*pi/eta\"",
        ];
        let model = MODEL.replacen(slots[place], &format!("{text:?}"), 1);
        let _ = through_the_checker(&model);
    }
}

#[test]
fn the_unmutated_model_is_a_model() {
    std::env::set_var("LYAPSWEEP_STEP_LOOPS", "interpreter");
    assert_eq!(through_the_checker(MODEL), Ok(()));
}
