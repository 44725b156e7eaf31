//! The model language's expressions (src/model/language/expr.rs): they evaluate as
//! the same formulas written in Rust, report errors at their column, differentiate
//! symbolically to what finite differences give, and read back from their
//! text form to the same values.

use lyapsweep::model::language::expr::{Expr, Names, Var, Written};

fn names() -> Names {
    Names {
        states: vec!["x".into(), "v".into()],
        parameters: vec!["zeta".into(), "f".into(), "eta".into()],
        switches: Vec::new(),
    }
}

/// (text, the same formula in Rust of x, v, zeta, f, eta, t)
type Formula = (&'static str, fn(f64, f64, f64, f64, f64, f64) -> f64);

const FORMULAS: &[Formula] = &[
    ("-2*zeta*v - x + f*cos(eta*t)", |x, v, z, f, e, t| {
        -2.0 * z * v - x + f * (e * t).cos()
    }),
    ("x^2^3", |x, _, _, _, _, _| x.powf(8.0)),
    ("-x^2", |x, _, _, _, _, _| -(x * x)),
    ("2*-x + 3", |x, _, _, _, _, _| -2.0 * x + 3.0),
    ("x - v - zeta", |x, v, z, _, _, _| x - v - z),
    ("x / v / f", |x, v, _, f, _, _| x / v / f),
    ("atan2(v, x) + min(x, v)*max(x, v)", |x, v, _, _, _, _| {
        v.atan2(x) + x.min(v) * x.max(v)
    }),
    ("pow(abs(x), 3) + 1e-3*x + .5*v", |x, v, _, _, _, _| {
        x.abs().powf(3.0) + 1e-3 * x + 0.5 * v
    }),
    ("sqrt(abs(x))*tanh(v)/exp(zeta)", |x, v, z, _, _, _| {
        x.abs().sqrt() * v.tanh() / z.exp()
    }),
    ("log(f + x*x)*sin(t) - tan(v/4)", |x, v, _, f, _, t| {
        (f + x * x).ln() * t.sin() - (v / 4.0).tan()
    }),
    ("2*pi/eta", |_, _, _, _, e, _| {
        2.0 * std::f64::consts::PI / e
    }),
    ("(x + v)*(x - v)^2", |x, v, _, _, _, _| {
        (x + v) * (x - v).powi(2)
    }),
    ("f^x", |x, _, _, f, _, _| f.powf(x)),
];

/// Points away from the functions' kinks and poles.
const POINTS: &[[f64; 6]] = &[
    [0.7, -0.3, 0.05, 1.3, 0.8, 2.1],
    [-1.2, 0.9, 0.2, 2.0, 1.4, 0.4],
    [2.5, 1.7, 0.01, 0.6, 0.5, 7.3],
];

fn eval(e: &Expr, p: &[f64; 6]) -> f64 {
    e.eval(&p[..2], &p[2..5], p[5])
}

fn close(a: f64, b: f64, tolerance: f64) -> bool {
    (a - b).abs() <= tolerance * a.abs().max(b.abs()).max(1.0)
}

#[test]
fn expressions_evaluate_as_the_same_formula_in_rust() {
    let names = names();
    for (text, rust) in FORMULAS {
        let e = Expr::parse(text, &names).unwrap_or_else(|err| panic!("{text}: {err}"));
        for p in POINTS {
            let (got, want) = (eval(&e, p), rust(p[0], p[1], p[2], p[3], p[4], p[5]));
            assert!(close(got, want, 1e-15), "{text} at {p:?}: {got} vs {want}");
        }
    }
}

#[test]
fn errors_name_the_column() {
    let names = names();
    for (text, column, needle) in [
        ("-2*zeta2*v", 4, "unknown name 'zeta2'"),
        ("x + ", 5, "expected a number, a name or '(', found the end"),
        ("(x + v", 7, "expected ')', found the end"),
        ("x $ v", 3, "unexpected character '$'"),
        ("x v", 3, "unexpected 'v'"),
        ("", 1, "empty expression"),
        ("atan2(x)", 1, "atan2 takes 2 arguments, got 1"),
        ("sin(x, v)", 1, "sin takes 1 argument, got 2"),
        ("x + foo(v)", 5, "unknown function 'foo'"),
        ("cos*x", 1, "'cos' is a function: write cos(...)"),
        ("1..2", 1, "'1..2' is not a number"),
        ("x * )", 5, "found ')'"),
    ] {
        let err = Expr::parse(text, &names).expect_err(text);
        assert_eq!(err.column, column, "{text}: {err}");
        assert!(err.message.contains(needle), "{text}: {err}");
        assert!(err.to_string().ends_with(&format!("(column {column})")));
    }
}

#[test]
fn symbolic_derivatives_match_finite_differences() {
    let names = names();
    let vars = [
        Var::State(0),
        Var::State(1),
        Var::Param(0),
        Var::Param(1),
        Var::Param(2),
        Var::Time,
    ];
    for (text, _) in FORMULAS {
        let e = Expr::parse(text, &names).unwrap();
        for (slot, &var) in vars.iter().enumerate() {
            let d = e.derivative(var);
            for p in POINTS {
                // Central difference, step relative to the coordinate: error
                // O(h²) ≈ 1e-10 against rounding ε/h ≈ 1e-11.
                let h = 1e-5 * p[slot].abs().max(1.0);
                let (mut up, mut down) = (*p, *p);
                up[slot] += h;
                down[slot] -= h;
                let numeric = (eval(&e, &up) - eval(&e, &down)) / (up[slot] - down[slot]);
                let symbolic = eval(&d, p);
                assert!(
                    close(symbolic, numeric, 1e-6),
                    "d/d{var:?} of {text} at {p:?}: {symbolic} vs {numeric}"
                );
            }
            if !e.uses(var) {
                assert_eq!(d, Expr::Num(0.0), "{text} does not use {var:?}");
            }
        }
    }
}

#[test]
fn an_expression_reads_back_from_its_text() {
    let names = names();
    for (text, _) in FORMULAS {
        let e = Expr::parse(text, &names).unwrap();
        let written = Written {
            expr: &e,
            names: &names,
        }
        .to_string();
        let again = Expr::parse(&written, &names)
            .unwrap_or_else(|err| panic!("{text} written as {written}: {err}"));
        for p in POINTS {
            assert_eq!(
                eval(&e, p).to_bits(),
                eval(&again, p).to_bits(),
                "{text} written as {written}"
            );
        }
    }
    // A derivative prints readably, without zeros and ones.
    let e = Expr::parse("-2*zeta*v - x + f*cos(eta*t)", &names).unwrap();
    let d = e.derivative(Var::State(1));
    assert_eq!(
        Written {
            expr: &d,
            names: &names
        }
        .to_string(),
        "-2 * zeta"
    );
}
