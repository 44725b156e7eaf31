//! A tape as source text: the one printer behind both generated
//! languages, the C of the CPU's native code (`model::native::library`) and the
//! WGSL of the GPU's system file (`model::codegen::wgsl`).
//!
//! It writes the tape's lowered instructions ([`Tape::lowered`], the
//! interpreter's own order) as one named value per instruction, each a
//! single IEEE operation or call of named values, inputs and numbers, and
//! gives the outputs' expressions. A fused instruction is printed unfused
//! (`a * b + c`): its two roundings, as the interpreter does them. What
//! differs between the targets is their [`Syntax`]: how a number, a
//! declaration and a function call are written; where the inputs are
//! (states, the clock, lane constants or parameters) is the caller's
//! [`Inputs`]. So the equations are lowered once, and both targets print
//! the same operations in the same order.

use std::fmt::Write as _;

use crate::model::ir::tape::{Code, Tape};
use crate::model::language::expr::Func;

/// How a target writes what a tape's text needs beyond `+ - * /` and
/// unary minus, which C and WGSL write alike.
pub trait Syntax {
    /// `v` as an expression of exactly that value.
    fn literal(&self, v: f64) -> String;
    /// A statement naming `value`: `const double x = …;`, `let x: real = …;`.
    fn declare(&self, name: &str, value: &str) -> String;
    /// `f` applied to `a`, and to `b` where it takes two arguments (a
    /// function of one gets the tape's unused second operand, `0.0`).
    fn call(&self, f: Func, a: &str, b: &str) -> String;
}

/// Where a printed tape reads its inputs: each as an expression of the
/// target, read where it is used.
pub struct Inputs<'a> {
    /// State i (`Src::State(i)`).
    pub states: &'a [String],
    /// cos ωt and sin ωt of the forcing clock.
    pub clock: (&'a str, &'a str),
    /// Lane constant j: a hoisted parameter-only value, or for a tape
    /// that reads its parameters (`Tape::compile_reading_parameters`) a
    /// parameter or a switch's side.
    pub lane: &'a dyn Fn(usize) -> String,
}

/// Appends `tape`'s instructions to `out`, one line each at `indent`, the
/// value of instruction slot s named `{prefix}{s}`; gives each output's
/// expression (a name, an input or a number).
pub fn print(
    out: &mut String,
    syntax: &dyn Syntax,
    tape: &Tape,
    inputs: &Inputs,
    prefix: &str,
    indent: &str,
) -> Vec<String> {
    let (lowered, numbers, outputs) = tape.lowered();
    // The slots in `Tape::run`'s order: states, clock, lane constants,
    // numbers, then one result per instruction.
    let mut slots: Vec<String> = inputs.states.to_vec();
    debug_assert_eq!(slots.len(), tape.states);
    slots.extend([inputs.clock.0.to_string(), inputs.clock.1.to_string()]);
    slots.extend((0..tape.lane_constants.len()).map(inputs.lane));
    slots.extend(numbers.iter().map(|&v| syntax.literal(v)));
    for ins in lowered {
        let (a, b, c) = (
            &slots[ins.a as usize],
            &slots[ins.b as usize],
            &slots[ins.c as usize],
        );
        let value = match ins.code {
            Code::Neg => format!("-{a}"),
            Code::Add => format!("{a} + {b}"),
            Code::Sub => format!("{a} - {b}"),
            Code::Mul => format!("{a} * {b}"),
            Code::Div => format!("{a} / {b}"),
            Code::MulAdd => format!("{a} * {b} + {c}"),
            Code::MulSub => format!("{a} * {b} - {c}"),
            Code::SubMul => format!("{c} - {a} * {b}"),
            Code::Call(f) => syntax.call(f, a, b),
        };
        let name = format!("{prefix}{}", slots.len());
        let _ = writeln!(out, "{indent}{}", syntax.declare(&name, &value));
        slots.push(name);
    }
    outputs.iter().map(|&s| slots[s as usize].clone()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::language::expr::{Expr, Names};

    /// A syntax that shows which hook wrote what.
    struct Plain;

    impl Syntax for Plain {
        fn literal(&self, v: f64) -> String {
            format!("#{v:?}")
        }
        fn declare(&self, name: &str, value: &str) -> String {
            format!("{name} := {value}")
        }
        fn call(&self, f: Func, a: &str, b: &str) -> String {
            match f.arity() {
                1 => format!("{}({a})", f.name()),
                _ => format!("{}({a}, {b})", f.name()),
            }
        }
    }

    #[test]
    fn each_instruction_is_one_line_and_products_print_unfused() {
        let names = Names {
            states: vec!["x".into(), "v".into()],
            parameters: vec!["zeta".into(), "f".into()],
            switches: Vec::new(),
        };
        let e = Expr::parse("-2*zeta*v - x + f*cos(t) + sqrt(abs(x))", &names).unwrap();
        let tape = Tape::compile([&e], 2, None).unwrap();
        let mut out = String::new();
        let states = ["X".to_string(), "V".to_string()];
        let lane = |j: usize| format!("L{j}");
        let inputs = Inputs {
            states: &states,
            clock: ("C", "S"),
            lane: &lane,
        };
        let values = print(&mut out, &Plain, &tape, &inputs, "r", "  ");
        let lines: Vec<&str> = out.lines().collect();
        assert_eq!(lines.len(), tape.lowered().0.len(), "{out}");
        assert!(lines.iter().all(|l| l.starts_with("  r")), "{out}");
        assert!(out.contains("L0 * V - X"), "{out}");
        assert!(out.contains(":= abs(X)") && out.contains("sqrt(r"), "{out}");
        assert_eq!(values.len(), 1);
        assert!(lines.last().unwrap().contains(&format!("{} :=", values[0])));
    }
}
