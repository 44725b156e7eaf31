//! Step programs (`model::ir::step`) as source text: WGSL functions for
//! the kernels, and C inlined into the native step loops, one scalar a
//! state component (the loops are vectorised over the slots, not over a
//! state).
//!
//! Both printers write every operation as the program states it, with
//! the parentheses its order needs and no other rewriting, so the two
//! targets perform the same IEEE operations in the same order; numbers
//! are written by the target's [`Syntax`].

use std::collections::HashMap;
use std::fmt::Write as _;

use super::print::Syntax;
use crate::model::ir::step::{Expr, Function, Op, Program, Ty};

/// How tightly an operation binds, for parentheses.
fn precedence(op: Op) -> u8 {
    match op {
        Op::Add | Op::Sub => 1,
        Op::Mul | Op::Div => 2,
    }
}

/// `a op b` from the operands' text, parenthesised where the order of
/// operations needs it: a left operand that binds less tightly, a right
/// one that binds as tightly or less (floating-point sums and products
/// do not reassociate).
fn binary(op: Op, a: (&str, Option<Op>), b: (&str, Option<Op>)) -> String {
    let p = precedence(op);
    let left = match a.1 {
        Some(o) if precedence(o) < p => format!("({})", a.0),
        _ => a.0.to_string(),
    };
    let right = match b.1 {
        Some(o) if precedence(o) <= p => format!("({})", b.0),
        _ => b.0.to_string(),
    };
    format!("{left} {} {right}", op.symbol())
}

/// The WGSL type of `ty`.
fn wgsl_type(ty: Ty) -> &'static str {
    match ty {
        Ty::Real => "real",
        Ty::State => "State",
        Ty::Pair => "vec2<real>",
        Ty::Bool => "bool",
    }
}

/// Whether `f` evaluates the field, itself or through the functions it
/// calls: a WGSL function that does takes the lane's `Params`.
fn reads_field(program: &Program, f: &Function) -> bool {
    fn reads(program: &Program, e: &Expr) -> bool {
        match e {
            Expr::Var(_) | Expr::Num(_) => false,
            Expr::Field { .. } => true,
            Expr::Bin(_, a, b)
            | Expr::Pair(a, b)
            | Expr::Cmp(_, a, b)
            | Expr::And(a, b)
            | Expr::Or(a, b) => reads(program, a) || reads(program, b),
            Expr::First(a) | Expr::Second(a) | Expr::Not(a) => reads(program, a),
            Expr::Call(name, args) => {
                reads_field(program, program.function(name))
                    || args.iter().any(|a| reads(program, a))
            }
        }
    }
    f.body
        .iter()
        .chain(&f.results)
        .any(|(_, e)| reads(program, e))
}

/// The program's functions in WGSL, and the structures of their results;
/// the field is the system file's `rhs(p, phase, y)`.
pub fn wgsl(program: &Program, syntax: &dyn Syntax) -> String {
    let mut out = String::new();
    let mut structures: Vec<&str> = Vec::new();
    for f in &program.functions {
        let types = f.result_types(program);
        if let Some(name) = f.returns.filter(|n| !structures.contains(n)) {
            structures.push(name);
            let _ = writeln!(out, "struct {name} {{");
            for ((field, _), ty) in f.results.iter().zip(&types) {
                let _ = writeln!(out, "    {field}: {},", wgsl_type(*ty));
            }
            out.push_str("}\n\n");
        }
        let mut params: Vec<String> = Vec::new();
        if reads_field(program, f) {
            params.push("p: Params".into());
        }
        params.extend(
            f.params
                .iter()
                .map(|(n, t)| format!("{n}: {}", wgsl_type(*t))),
        );
        let returns = f.returns.unwrap_or_else(|| wgsl_type(types[0]));
        let _ = writeln!(out, "fn {}({}) -> {returns} {{", f.name, params.join(", "));
        for (name, value) in &f.body {
            let _ = writeln!(
                out,
                "    let {name} = {};",
                wgsl_expr(program, syntax, value).0
            );
        }
        let results: Vec<String> = f
            .results
            .iter()
            .map(|(_, e)| wgsl_expr(program, syntax, e).0)
            .collect();
        match f.returns {
            Some(name) => {
                let _ = writeln!(out, "    return {name}({});", results.join(", "));
            }
            None => {
                let _ = writeln!(out, "    return {};", results[0]);
            }
        }
        out.push_str("}\n\n");
    }
    out
}

/// `e` in WGSL, and its outermost operation (for parentheses).
fn wgsl_expr(program: &Program, syntax: &dyn Syntax, e: &Expr) -> (String, Option<Op>) {
    let text = |e: &Expr| wgsl_expr(program, syntax, e).0;
    match e {
        Expr::Var(name) => (name.to_string(), None),
        Expr::Num(v) => (syntax.literal(*v), None),
        Expr::Bin(op, a, b) => {
            let (a, b) = (wgsl_expr(program, syntax, a), wgsl_expr(program, syntax, b));
            (binary(*op, (&a.0, a.1), (&b.0, b.1)), Some(*op))
        }
        Expr::First(a) => (format!("{}.x", text(a)), None),
        Expr::Second(a) => (format!("{}.y", text(a)), None),
        Expr::Pair(c, s) => (format!("vec2<real>({}, {})", text(c), text(s)), None),
        // Truth values in parentheses whole: no precedence to get wrong.
        Expr::Cmp(cmp, a, b) => (format!("({} {} {})", text(a), cmp.symbol(), text(b)), None),
        Expr::And(a, b) => (format!("({} && {})", text(a), text(b)), None),
        Expr::Or(a, b) => (format!("({} || {})", text(a), text(b)), None),
        Expr::Not(a) => (format!("!{}", text(a)), None),
        Expr::Field { phase, state } => (format!("rhs(p, {}, {})", text(phase), text(state)), None),
        Expr::Call(name, args) => {
            let mut list: Vec<String> = Vec::new();
            if reads_field(program, program.function(name)) {
                list.push("p".into());
            }
            list.extend(args.iter().map(text));
            (format!("{name}({})", list.join(", ")), None)
        }
    }
}

/// A value of C text: a number, one a state component, a pair's two
/// numbers (a phase's cosine and sine), or a truth value (an `int`).
#[derive(Clone, Debug, PartialEq)]
pub enum CValue {
    Real(String),
    State(Vec<String>),
    Pair(String, String),
    Bool(String),
}

/// The field as C statements: appends the field's values at `state` and
/// `clock` (atoms), its own values named after `prefix`, and gives its
/// outputs.
pub type CField<'a> = dyn FnMut(&mut String, &str, &[String], (&str, &str)) -> Vec<String> + 'a;

/// Where a program is inlined into C.
pub struct C<'a> {
    pub syntax: &'a dyn Syntax,
    pub field: &'a mut CField<'a>,
    pub indent: &'a str,
}

impl C<'_> {
    /// Appends `name`'s statements at `args`, every value it names
    /// `{prefix}{name}` (components `{prefix}{name}{i}`, a phase's
    /// `{prefix}{name}_c` and `_s`), and gives its results.
    pub fn inline(
        &mut self,
        out: &mut String,
        program: &Program,
        name: &str,
        args: Vec<CValue>,
        prefix: &str,
    ) -> Vec<CValue> {
        let f = program.function(name);
        assert_eq!(f.params.len(), args.len(), "{name}'s arguments");
        let mut scope: HashMap<&str, CValue> = f.params.iter().map(|(n, _)| *n).zip(args).collect();
        for (value_name, value) in &f.body {
            let value = self.value(
                out,
                program,
                &scope,
                value,
                &format!("{prefix}{value_name}"),
            );
            let named = self.declare(out, &format!("{prefix}{value_name}"), value);
            scope.insert(value_name, named);
        }
        f.results
            .iter()
            .map(|(result, e)| self.value(out, program, &scope, e, &format!("{prefix}{result}")))
            .collect()
    }

    /// Names `value` `name` (components `{name}{i}`, `{name}_c`, `{name}_s`).
    fn declare(&self, out: &mut String, name: &str, value: CValue) -> CValue {
        let mut one = |n: String, v: &str| {
            let _ = writeln!(out, "{}{}", self.indent, self.syntax.declare(&n, v));
            n
        };
        match value {
            CValue::Real(v) => CValue::Real(one(name.to_string(), &v)),
            CValue::State(vs) => CValue::State(
                vs.iter()
                    .enumerate()
                    .map(|(i, v)| one(format!("{name}{i}"), v))
                    .collect(),
            ),
            CValue::Pair(c, s) => {
                CValue::Pair(one(format!("{name}_c"), &c), one(format!("{name}_s"), &s))
            }
            CValue::Bool(v) => {
                let _ = writeln!(out, "{}const int {name} = {v};", self.indent);
                CValue::Bool(name.to_string())
            }
        }
    }

    /// `e` as C text; a field or a call it makes is written out first, its
    /// values named after `prefix`.
    fn value(
        &mut self,
        out: &mut String,
        program: &Program,
        scope: &HashMap<&str, CValue>,
        e: &Expr,
        prefix: &str,
    ) -> CValue {
        match e {
            Expr::Field { phase, state } => {
                let (Some(CValue::Pair(c, s)), Some(CValue::State(y))) =
                    (var(scope, phase), var(scope, state))
                else {
                    panic!("the field is evaluated at a named phase and state")
                };
                CValue::State((self.field)(out, &format!("{prefix}_"), &y, (&c, &s)))
            }
            Expr::Call(name, args) => {
                let args = args.iter().map(|a| self.operand(scope, a)).collect();
                let mut results = self.inline(out, program, name, args, &format!("{prefix}_"));
                assert_eq!(results.len(), 1, "{name} has one result");
                results.remove(0)
            }
            _ => {
                let (text, _) = self.expr(scope, e);
                text
            }
        }
    }

    /// `e`, an operation of named values and numbers, as C text per
    /// component, with its outermost operation.
    fn expr(&self, scope: &HashMap<&str, CValue>, e: &Expr) -> (CValue, Option<Op>) {
        match e {
            Expr::Var(name) => (scope[name].clone(), None),
            Expr::Num(v) => (CValue::Real(self.syntax.literal(*v)), None),
            Expr::First(a) | Expr::Second(a) => match self.expr(scope, a).0 {
                CValue::Pair(c, s) => (
                    CValue::Real(if matches!(e, Expr::First(_)) { c } else { s }),
                    None,
                ),
                other => panic!("{other:?} is not a pair"),
            },
            Expr::Pair(c, s) => match (self.operand(scope, c), self.operand(scope, s)) {
                (CValue::Real(c), CValue::Real(s)) => (CValue::Pair(c, s), None),
                _ => panic!("a pair of two numbers"),
            },
            // Truth values as C ints, in parentheses whole; `&` and `|`
            // compute both operands, as `integrate::wall::may_reach` does.
            Expr::Cmp(cmp, a, b) => match (self.operand(scope, a), self.operand(scope, b)) {
                (CValue::Real(a), CValue::Real(b)) => {
                    (CValue::Bool(format!("({a} {} {b})", cmp.symbol())), None)
                }
                _ => panic!("a comparison of two numbers"),
            },
            Expr::And(a, b) | Expr::Or(a, b) => {
                let symbol = if matches!(e, Expr::And(..)) { '&' } else { '|' };
                match (self.expr(scope, a).0, self.expr(scope, b).0) {
                    (CValue::Bool(a), CValue::Bool(b)) => {
                        (CValue::Bool(format!("({a} {symbol} {b})")), None)
                    }
                    _ => panic!("{symbol} of two truth values"),
                }
            }
            Expr::Not(a) => match self.expr(scope, a).0 {
                CValue::Bool(a) => (CValue::Bool(format!("!{a}")), None),
                other => panic!("{other:?} is not a truth value"),
            },
            Expr::Bin(op, a, b) => {
                let ((a, oa), (b, ob)) = (self.expr(scope, a), self.expr(scope, b));
                let both = |x: &str, y: &str| binary(*op, (x, oa), (y, ob));
                let value = match (a, b) {
                    (CValue::Real(x), CValue::Real(y)) => CValue::Real(both(&x, &y)),
                    (CValue::State(x), CValue::State(y)) => {
                        CValue::State(x.iter().zip(&y).map(|(x, y)| both(x, y)).collect())
                    }
                    (CValue::Real(x), CValue::State(y)) => {
                        CValue::State(y.iter().map(|y| both(&x, y)).collect())
                    }
                    (a, b) => panic!("{a:?} {} {b:?}", op.symbol()),
                };
                (value, Some(*op))
            }
            Expr::Field { .. } | Expr::Call(..) => {
                panic!("a field or a call is a named value of its own")
            }
        }
    }
}

impl C<'_> {
    /// `e` as an operand: its text, in parentheses where it is an
    /// operation (a number's only; a call's arguments and a comparison's
    /// sides are read where they are used).
    fn operand(&self, scope: &HashMap<&str, CValue>, e: &Expr) -> CValue {
        match self.expr(scope, e) {
            (CValue::Real(v), Some(_)) => CValue::Real(format!("({v})")),
            (value, _) => value,
        }
    }
}

fn var(scope: &HashMap<&str, CValue>, e: &Expr) -> Option<CValue> {
    match e {
        Expr::Var(name) => scope.get(name).cloned(),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::ir::step::integrator;

    struct Plain;

    impl Syntax for Plain {
        fn literal(&self, v: f64) -> String {
            format!("{v:?}")
        }
        fn declare(&self, name: &str, value: &str) -> String {
            format!("{name} = {value};")
        }
        fn call(&self, _: crate::model::language::expr::Func, _: &str, _: &str) -> String {
            unreachable!()
        }
    }

    #[test]
    fn rk4_prints_its_sum_in_the_reference_order() {
        let wgsl = wgsl(&integrator(), &Plain);
        assert!(
            wgsl.contains("let increment = rk4_stages(p, phase, mid, end, y, h);"),
            "{wgsl}"
        );
        assert!(wgsl.contains("return Stepped(rk4_update(p, phase, mid, end, y, h), end);"));
        assert!(
            wgsl.contains("return sixth * (k1 + 2.0 * (k2 + k3) + k4);"),
            "{wgsl}"
        );
        assert!(wgsl.contains("fn rotate(phase: vec2<real>, by: vec2<real>) -> vec2<real> {"));
        assert!(
            wgsl.contains("let scale = 1.5 - 0.5 * (c * c + s * s);"),
            "{wgsl}"
        );
    }

    #[test]
    fn inlined_c_names_each_component_and_keeps_right_operands_apart() {
        let program = Program {
            functions: vec![Function {
                name: "f",
                params: vec![("a", Ty::Real), ("y", Ty::State)],
                body: vec![("z", Expr::from("a") - (Expr::from("a") - "a") * "y")],
                results: vec![("r", Expr::from("z") + "y")],
                returns: None,
            }],
        };
        let mut field = |_: &mut String, _: &str, _: &[String], _: (&str, &str)| Vec::new();
        let mut c = C {
            syntax: &Plain,
            field: &mut field,
            indent: "",
        };
        let mut out = String::new();
        let args = vec![
            CValue::Real("A".into()),
            CValue::State(vec!["Y0".into(), "Y1".into()]),
        ];
        let results = c.inline(&mut out, &program, "f", args, "q");
        assert_eq!(out, "qz0 = A - (A - A) * Y0;\nqz1 = A - (A - A) * Y1;\n");
        assert_eq!(
            results,
            vec![CValue::State(vec!["qz0 + Y0".into(), "qz1 + Y1".into()])]
        );
    }
}
