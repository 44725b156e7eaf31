//! `lyapsweep model check FILE`: what a compiled model is, in words and
//! expressions — its equations, the derivatives the sum rule uses, its
//! events as the integrator sees them, what each backend runs, and the
//! generated WGSL — for a user writing a model to read before a sweep.

use std::fmt::Write;

use crate::integrate::surface::Surface;
use crate::model::codegen::wgsl;
use crate::model::compiled::Code;
use crate::model::language::expr::reads_state_or_time;
use crate::model::language::expr::{Expr, Op, Var, Written};

/// The report of a model that compiled: the model as written, then as the
/// integrator sees it, then what each backend runs.
pub fn describe(code: &Code) -> String {
    let names = &code.model.names;
    let show = |e: &Expr| {
        Written {
            expr: &tidy(e),
            names,
        }
        .to_string()
    };
    // Each part writes to a String, which cannot fail: the `let _ =` of
    // their writes drop no error.
    let mut out = String::new();
    write_model(&mut out, code, &show);
    write_map(&mut out, code, &show);
    write_sum_rule(&mut out, code, &show);
    write_events(&mut out, code, &show);
    write_bifurcations(&mut out, code);
    write_jacobian(&mut out, code, &show);
    write_cpu(&mut out, code);
    write_gpu(&mut out, code);
    out
}

/// The model line (states, parameters and their ranges) and the equations.
fn write_model(w: &mut String, code: &Code, show: &dyn Fn(&Expr) -> String) {
    let model = &code.model;
    let names = &model.names;
    let parameters: Vec<String> = names
        .parameters
        .iter()
        .zip(&model.defaults)
        .zip(&model.ranges)
        .map(
            |((p, v), &(min, max))| match (min.is_finite(), max.is_finite()) {
                (false, false) => format!("{p} = {v}"),
                _ => format!("{p} = {v} in [{min}, {max}]"),
            },
        )
        .collect();
    let _ = writeln!(
        w,
        "model {}: {} states ({}), parameters {}",
        model.name,
        names.states.len(),
        names.states.join(", "),
        if parameters.is_empty() {
            "none".to_owned()
        } else {
            parameters.join(", ")
        }
    );
    let _ = writeln!(w, "\nequations:");
    for (s, e) in names.states.iter().zip(&model.equations) {
        let _ = writeln!(w, "  {s}' = {}", show(e));
    }
}

/// How the flow is reduced to a map: its period or its section, and the
/// forcing read from the clock.
fn write_map(w: &mut String, code: &Code, show: &dyn Fn(&Expr) -> String) {
    let model = &code.model;
    let names = &model.names;
    let _ = writeln!(w, "\nmap:");
    match (&model.map, &code.section) {
        (crate::model::Map::Period(t), _) => {
            let _ = writeln!(
                w,
                "  stroboscopic, period T = {}; {} exponents; t restarts at 0 each period",
                show(t),
                code.dimension()
            );
        }
        (_, Some(section)) => {
            let others: Vec<&str> = names
                .states
                .iter()
                .enumerate()
                .filter(|(i, _)| *i != section.state)
                .map(|(_, s)| s.as_str())
                .collect();
            let _ = writeln!(
                w,
                "  Poincaré section {} = {}, crossed {}; coordinates {} ({} exponents, per unit of return time)",
                names.states[section.state],
                show(&section.at),
                if section.increasing { "increasing" } else { "decreasing" },
                others.join(", "),
                code.dimension()
            );
        }
        _ => unreachable!("a section map has its section"),
    }
    if let Some(w_expr) = &code.equations.frequency {
        let _ = writeln!(
            w,
            "  forcing: cos and sin of ({})·t read from the exactly rotated clock",
            show(w_expr)
        );
    }
}

/// What the exponents must add up to: the divergence, and the terms each
/// impact, crossing or section return adds.
fn write_sum_rule(w: &mut String, code: &Code, show: &dyn Fn(&Expr) -> String) {
    let model = &code.model;
    let names = &model.names;
    let _ = writeln!(w, "\nsum rule (exponents per unit time add up to):");
    match &code.divergence {
        Some(d) => {
            let _ = writeln!(w, "  div F = {} (a function of the parameters)", show(d));
        }
        None => {
            let terms: Vec<String> = (0..names.states.len())
                .map(|i| show(&model.equations[i].derivative(Var::State(i))))
                .collect();
            let _ = writeln!(
                w,
                "  div F = {} depends on the state: {}",
                terms.join(" + "),
                if code.divergence_along.is_some() {
                    "integrated along the reference (its time average)"
                } else {
                    "not integrated through events yet, so expected_sum is NaN"
                }
            );
        }
    }
    for stop in &code.walls {
        let _ = writeln!(
            w,
            "  + 2·ln({}) per impact on '{}' (its saltation determinant e²)",
            show(&stop.restitution),
            stop.name
        );
    }
    if !code.surfaces.is_empty() {
        let _ = writeln!(
            w,
            "  + ln|det S| per crossing of the other events and switches, along the reference \
             (S their saltation matrix); NaN once the motion slides on a switch"
        );
    }
    if let Some(section) = &code.section {
        let _ = writeln!(
            w,
            "  + ln|F_{0}(x_0) / F_{0}(x_n)| over the averaging time (the section's flux term)",
            names.states[section.state]
        );
    }
}

/// The events as the integrator sees them: stops, general surfaces and
/// switches, and whether the exact propagator applies.
fn write_events(w: &mut String, code: &Code, show: &dyn Fn(&Expr) -> String) {
    let model = &code.model;
    let names = &model.names;
    if !code.walls.is_empty() {
        let _ = writeln!(w, "\nevents (stops):");
        for stop in &code.walls {
            let _ = writeln!(
                w,
                "  '{}': {} {} {}, velocity {}, reset {} -> -({})·{}",
                stop.name,
                names.states[stop.coordinate],
                if stop.side > 0.0 { "<=" } else { ">=" },
                show(&stop.position),
                names.states[stop.velocity],
                names.states[stop.velocity],
                show(&stop.restitution),
                names.states[stop.velocity],
            );
        }
    }
    for s in &code.surfaces {
        match s.kind {
            crate::integrate::Surface::Event => {
                let resets: Vec<String> = s
                    .reset
                    .iter()
                    .enumerate()
                    .filter(|(i, e)| **e != Expr::Var(crate::model::language::expr::Var::State(*i)))
                    .map(|(i, e)| format!("{} -> {}", names.states[i], show(e)))
                    .collect();
                let _ = writeln!(
                    w,
                    "\nevent '{}' (a general surface): fires where {} crosses 0 from below; reset {}",
                    s.name,
                    show(&s.g),
                    resets.join(", ")
                );
            }
            crate::integrate::Surface::Switch { bit } => {
                let _ = writeln!(
                    w,
                    "\nswitch '{}': the field changes where {} crosses 0 (step = 1 above); \
                     region bit {bit}; {}",
                    s.name,
                    show(&s.g),
                    match &s.stick_limit {
                        Some(limit) => format!(
                            "slides while the mean rate of the two sides is below {} in size",
                            show(limit)
                        ),
                        None => "slides where both fields point into it (Filippov)".to_owned(),
                    }
                );
            }
        }
    }
    if code.is_piecewise_linear {
        let _ = writeln!(
            w,
            "\npiecewise linear: backend = \"exact\" propagates it in closed form{}",
            if code.model.switches.is_empty() {
                ""
            } else {
                " (sliding too, where the jump is constant and the stick limit a number)"
            }
        );
    }
}

/// Which bifurcations of periodic orbits the model's events can produce,
/// and how a run with `[orbits]` reports each.
fn write_bifurcations(w: &mut String, code: &Code) {
    let _ = writeln!(
        w,
        "\nbifurcations of periodic orbits ([orbits]):\n  fold, period-doubling, neimark-sacker: from the multipliers, in any model"
    );
    for stop in &code.walls {
        let _ = writeln!(
            w,
            "  grazing of stop '{}': located where a free orbit's branch touches it",
            stop.name
        );
    }
    for s in &code.surfaces {
        let what = match s.kind {
            crate::integrate::Surface::Event => "grazing",
            crate::integrate::Surface::Switch { .. } => "grazing or the onset of sliding",
        };
        let _ = writeln!(
            w,
            "  {what} on '{}': reported as an events-change where an orbit's crossings change",
            s.name
        );
    }
}

/// The Jacobian of the field, whose time scales set the steps.
fn write_jacobian(w: &mut String, code: &Code, show: &dyn Fn(&Expr) -> String) {
    let model = &code.model;
    let names = &model.names;
    let n = names.states.len();
    let _ = writeln!(
        w,
        "\nJacobian ∂F_i/∂x_j (the time scales that set the steps):"
    );
    for i in 0..n {
        let row: Vec<String> = (0..n).map(|j| show(&code.jacobian[i * n + j])).collect();
        let _ = writeln!(w, "  [{}]", row.join(", "));
    }
}

/// What the CPU runs: the tape, native code or the interpreter, and the
/// step loops built by the C compiler.
fn write_cpu(w: &mut String, code: &Code) {
    let _ = writeln!(
        w,
        "\nCPU: a tape of {} instructions, {} lane constants (parameter-only subexpressions, once per lane)",
        code.equations.instructions.len(),
        code.equations.lane_constants.len()
    );
    if let Some(field) = code.regions.first() {
        let native = match (&field.native, &field.native_failure) {
            (Some(native), _) if native.has_loops() => {
                "native code built by the C compiler for this machine's vectors, its step \
                 loop between stops too"
                    .into()
            }
            (Some(_), _) => "native code built by the C compiler for this machine's vectors".into(),
            (None, Some(why)) => format!("the tape's interpreter ({why})"),
            (None, None) => "the tape's interpreter".into(),
        };
        let _ = writeln!(w, "CPU: the equations run as {native}");
    }
    match &code.switch_loops {
        Some(Ok(_)) => {
            let _ = writeln!(
                w,
                "CPU: the step loop between stops and crossings is built by the C compiler for \
                 this machine's vectors"
            );
            // Slides on one or two switches whose gradients are constant
            // (the friction's v - vb) are stepped in C too (`ModelFlow::
            // slide_step`); others, and slides on three or more at once,
            // by the integrator's own evaluation of the equivalent
            // control.
            let stepped: Vec<&str> = code
                .surfaces
                .iter()
                .filter(|s| matches!(s.kind, Surface::Switch { .. }))
                .filter(|s| s.gradient.iter().all(|e| !reads_state_or_time(e)))
                .map(|s| s.name.as_str())
                .collect();
            let names: Vec<String> = stepped.iter().map(|n| format!("'{n}'")).collect();
            match names.len() {
                0 => {}
                1 => {
                    let _ = writeln!(
                        w,
                        "CPU: a slide on {} is stepped by the C compiler too",
                        names[0]
                    );
                }
                _ => {
                    let _ = writeln!(
                        w,
                        "CPU: slides on {}, one or two at once, are stepped by the C compiler too",
                        names.join(", ")
                    );
                }
            }
        }
        Some(Err(why)) => {
            let _ = writeln!(
                w,
                "CPU: the integrator's own loop takes every step (the C compiler failed: {why})"
            );
        }
        None => {}
    }
}

/// Whether the GPU runs the model, and the system file generated for it.
fn write_gpu(w: &mut String, code: &Code) {
    match wgsl::system_source(code) {
        Ok(source) => {
            let how = if code.section.is_some() {
                "runs on the section kernel (the steps on the GPU, crossings and factors on the \
                 host)"
            } else {
                "runs on the kernels"
            };
            let _ = writeln!(w, "GPU: {how}; the generated system file:\n");
            let _ = write!(w, "{source}");
        }
        Err(why) => {
            let _ = writeln!(w, "GPU: not run on the GPU kernels: {why}");
        }
    }
}

/// `e` with the zeros, ones and double negations that building
/// derivatives and stops leaves behind folded away, for reading only (the
/// integrator evaluates the trees as built, whose values these equal).
fn tidy(e: &Expr) -> Expr {
    let num = |e: &Expr| match e {
        Expr::Num(v) => Some(*v),
        _ => None,
    };
    let neg = |a: Expr| match a {
        Expr::Neg(inner) => *inner,
        Expr::Num(v) => Expr::Num(-v),
        a => Expr::Neg(Box::new(a)),
    };
    match e {
        Expr::Neg(a) => neg(tidy(a)),
        Expr::Bin(op, a, b) => {
            let (a, b) = (tidy(a), tidy(b));
            match (op, num(&a), num(&b)) {
                (Op::Add, Some(0.0), _) => b,
                (Op::Add | Op::Sub, _, Some(0.0)) => a,
                (Op::Sub, Some(0.0), _) => neg(b),
                (Op::Mul, Some(1.0), _) => b,
                (Op::Mul | Op::Div, _, Some(1.0)) => a,
                (Op::Mul, Some(-1.0), _) => neg(b),
                (Op::Mul, _, Some(-1.0)) => neg(a),
                (Op::Add, _, _) if matches!(b, Expr::Neg(_)) => {
                    let Expr::Neg(inner) = b else { unreachable!() };
                    Expr::Bin(Op::Sub, Box::new(a), inner)
                }
                _ => Expr::Bin(*op, Box::new(a), Box::new(b)),
            }
        }
        Expr::Call(f, args) => Expr::Call(*f, args.iter().map(tidy).collect()),
        e => e.clone(),
    }
}
