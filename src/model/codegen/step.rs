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
use crate::model::ir::step::{Bits, Expr, Field, Function, Math, Op, Program, Stmt, Ty};
use crate::model::language::expr::Func;

/// How tightly an operation binds, for parentheses. The bit operations
/// bind least: C and WGSL order them differently among themselves and
/// against comparisons (WGSL refuses them mixed), so every operation that
/// is an operand of one, or one of them that is an operand, is
/// parenthesised.
fn precedence(op: Op) -> u8 {
    match op {
        Op::Shr | Op::Shl | Op::BitAnd | Op::BitOr | Op::BitXor => 0,
        Op::Add | Op::Sub => 1,
        Op::Mul | Op::Div | Op::Rem => 2,
    }
}

/// `a op b` from the operands' text, parenthesised where the order of
/// operations needs it: a left operand that binds less tightly, a right
/// one that binds as tightly or less (floating-point sums and products
/// do not reassociate).
fn binary(op: Op, a: (&str, Option<Op>), b: (&str, Option<Op>)) -> String {
    let p = precedence(op);
    let left = match a.1 {
        Some(_) if op.is_bitwise() => format!("({})", a.0),
        Some(o) if precedence(o) < p => format!("({})", a.0),
        _ => a.0.to_string(),
    };
    let right = match b.1 {
        Some(_) if op.is_bitwise() => format!("({})", b.0),
        Some(o) if precedence(o) <= p => format!("({})", b.0),
        _ => b.0.to_string(),
    };
    format!("{left} {} {right}", op.symbol())
}

/// `text` in parentheses where it is an operation.
fn wrap(text: &str, op: Option<Op>) -> String {
    match op {
        Some(_) => format!("({text})"),
        None => text.to_string(),
    }
}

/// A comparison's side: a bit operation in parentheses (C's `==` binds
/// tighter than `&`; WGSL refuses the two unparenthesised).
fn side((text, op): (String, Option<Op>)) -> String {
    match op {
        Some(o) if o.is_bitwise() => format!("({text})"),
        _ => text,
    }
}

/// `e`'s text as an `if`'s condition: truth operations print in
/// parentheses whole already, anything else gets them.
fn condition(e: &Expr, text: String) -> String {
    match e {
        Expr::Cmp(..) | Expr::And(..) | Expr::Or(..) => text,
        _ => format!("({text})"),
    }
}

/// The WGSL type of `ty`.
fn wgsl_type(ty: Ty) -> &'static str {
    match ty {
        Ty::Real => "real",
        Ty::State => "State",
        Ty::Pair => "vec2<real>",
        Ty::Bool => "bool",
        Ty::Count => "u32",
        Ty::Struct(name) => name,
        Ty::Table => "vec4<real>",
        Ty::CountTable => "vec4<u32>",
        Ty::Rows => "array<State, DIM>",
        Ty::Single => "f32",
    }
}

/// Whether `name` is a function the kernels define.
fn is_extern(program: &Program, name: &str) -> bool {
    use crate::model::ir::step::Extern;
    program.externs.iter().any(
        |e| matches!(e, Extern::Fn { name: n, .. } | Extern::Proc { name: n, .. } if *n == name),
    )
}

/// What a WGSL function takes before its own parameters, as (name,
/// type): the lane's `Params` where it evaluates a field, and the stop
/// `w` too where it evaluates the held flow, itself or through a function
/// it calls that takes them so. A function that takes `p` (or `w`) as a
/// parameter of its own, or names one in its body (a stop it reads, a
/// copy of the lane's parameters in another region), passes it on by
/// name, and its callers need not have one.
fn context(program: &Program, f: &Function) -> Vec<(&'static str, &'static str)> {
    fn needs(program: &Program, e: &Expr, out: &mut Vec<&'static str>) {
        let implied: Vec<&'static str> = match e {
            Expr::Field {
                of: Field::Held, ..
            } => vec!["p", "w"],
            Expr::Field { .. } => vec!["p"],
            Expr::Call(name, _) if !is_extern(program, name) => {
                let callee = program.function(name);
                context(program, callee).iter().map(|(n, _)| *n).collect()
            }
            _ => Vec::new(),
        };
        out.extend(implied);
        for a in e.operands() {
            needs(program, a, out);
        }
    }
    let mut names = Vec::new();
    for e in f.exprs() {
        needs(program, e, &mut names);
    }
    let declared = |n: &str| {
        f.params.iter().any(|(p, _)| *p == n)
            || f.body
                .iter()
                .any(|s| matches!(s, Stmt::Let(d, _) | Stmt::Var(d, _) if *d == n))
    };
    [("p", "Params"), ("w", "Stop")]
        .into_iter()
        .filter(|(n, _)| names.contains(n) && !declared(n))
        .collect()
}

/// The program's functions in WGSL, and the structures of their results;
/// the model's field is the system file's `rhs(p, phase, y)`, the held
/// flow the kernels' `held_rhs(p, w, phase, y)`.
pub fn wgsl(program: &Program, syntax: &dyn Syntax) -> String {
    let mut out = String::new();
    for s in program.structures.iter().filter(|s| !s.members.is_empty()) {
        let _ = writeln!(out, "struct {} {{", s.name);
        for (member, ty) in &s.members {
            let _ = writeln!(out, "    {member}: {},", wgsl_type(*ty));
        }
        out.push_str("}\n\n");
    }
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
        let params: Vec<String> = context(program, f)
            .iter()
            .map(|(n, t)| format!("{n}: {t}"))
            .chain(
                f.params
                    .iter()
                    .map(|(n, t)| format!("{n}: {}", wgsl_type(*t))),
            )
            .collect();
        // A function without results returns nothing.
        let returns = match (f.returns, types.first()) {
            (Some(name), _) => format!(" -> {name}"),
            (None, Some(ty)) => format!(" -> {}", wgsl_type(*ty)),
            (None, None) => String::new(),
        };
        let _ = writeln!(out, "fn {}({}){returns} {{", f.name, params.join(", "));
        let text = Wgsl { program, syntax };
        text.block(&mut out, &f.body, "    ");
        let results: Vec<String> = f.results.iter().map(|(_, e)| text.expr(e).0).collect();
        match (f.returns, &results[..]) {
            (Some(name), _) => {
                let _ = writeln!(out, "    return {name}({});", results.join(", "));
            }
            (None, [one]) => {
                let _ = writeln!(out, "    return {one};");
            }
            (None, _) => {}
        }
        out.push_str("}\n\n");
    }
    out
}

/// A program's text in WGSL.
struct Wgsl<'a> {
    program: &'a Program,
    syntax: &'a dyn Syntax,
}

impl Wgsl<'_> {
    /// `block`'s statements, one a line at `indent`.
    fn block(&self, out: &mut String, block: &[Stmt], indent: &str) {
        let inner = format!("{indent}    ");
        for stmt in block {
            let _ = match stmt {
                Stmt::Let(name, e) => writeln!(out, "{indent}let {name} = {};", self.expr(e).0),
                Stmt::Var(name, e) => writeln!(out, "{indent}var {name} = {};", self.expr(e).0),
                Stmt::Set(name, e) => writeln!(out, "{indent}{name} = {};", self.expr(e).0),
                Stmt::If(cond, then, otherwise) => {
                    let cond = condition(cond, self.expr(cond).0);
                    let _ = writeln!(out, "{indent}if {cond} {{");
                    self.block(out, then, &inner);
                    if !otherwise.is_empty() {
                        let _ = writeln!(out, "{indent}}} else {{");
                        self.block(out, otherwise, &inner);
                    }
                    writeln!(out, "{indent}}}")
                }
                Stmt::Loop(body) => {
                    let _ = writeln!(out, "{indent}loop {{");
                    self.block(out, body, &inner);
                    writeln!(out, "{indent}}}")
                }
                Stmt::Break => writeln!(out, "{indent}break;"),
                Stmt::SetAt(name, i, e) => {
                    let (i, e) = (self.expr(i).0, self.expr(e).0);
                    writeln!(out, "{indent}{name}[{i}] = {e};")
                }
                Stmt::SetMember(name, member, e) => {
                    writeln!(out, "{indent}{name}.{member} = {};", self.expr(e).0)
                }
                Stmt::SetEntry(name, row, col, e) => {
                    let (row, col, e) = (self.expr(row).0, self.expr(col).0, self.expr(e).0);
                    writeln!(out, "{indent}{name}[{row}][{col}] = {e};")
                }
                Stmt::Do(call) => writeln!(out, "{indent}{};", self.expr(call).0),
            };
        }
    }

    /// `e` in WGSL, and its outermost operation (for parentheses).
    fn expr(&self, e: &Expr) -> (String, Option<Op>) {
        let text = |e: &Expr| self.expr(e).0;
        match e {
            Expr::Var(name) => (name.to_string(), None),
            // A constant that is not finite is a shader-creation error.
            Expr::Num(v) if !v.is_finite() => panic!("WGSL has no constant {v}"),
            Expr::Num(v) => (self.syntax.literal(*v), None),
            Expr::Count(n) => (format!("{n}u"), None),
            Expr::Bin(op, a, b) => {
                let (a, b) = (self.expr(a), self.expr(b));
                (binary(*op, (&a.0, a.1), (&b.0, b.1)), Some(*op))
            }
            Expr::Abs(a) => (self.syntax.call(Func::Abs, &text(a), ""), None),
            // The kernels' prelude defines MAX_REAL, the largest `real`.
            Expr::Finite(a) => (
                format!(
                    "({} <= MAX_REAL)",
                    self.syntax.call(Func::Abs, &text(a), "")
                ),
                None,
            ),
            Expr::Fill(a) => (format!("State({})", text(a)), None),
            Expr::First(a) => (format!("{}.x", text(a)), None),
            Expr::Second(a) => (format!("{}.y", text(a)), None),
            Expr::Pair(c, s) => (format!("vec2<real>({}, {})", text(c), text(s)), None),
            // Truth values in parentheses whole: no precedence to get wrong.
            Expr::Cmp(cmp, a, b) => {
                let (a, b) = (side(self.expr(a)), side(self.expr(b)));
                (format!("({a} {} {b})", cmp.symbol()), None)
            }
            Expr::And(a, b) => (format!("({} && {})", text(a), text(b)), None),
            Expr::Or(a, b) => (format!("({} || {})", text(a), text(b)), None),
            Expr::Not(a) => (format!("!{}", text(a)), None),
            Expr::Select {
                cond,
                then,
                otherwise,
            } => (
                format!(
                    "select({}, {}, {})",
                    text(otherwise),
                    text(then),
                    text(cond)
                ),
                None,
            ),
            Expr::Field { of, phase, state } => {
                let f = match of {
                    Field::Model => "rhs(p",
                    Field::Held => "held_rhs(p, w",
                };
                (format!("{f}, {}, {})", text(phase), text(state)), None)
            }
            Expr::Call(name, args) => {
                let before = if is_extern(self.program, name) {
                    Vec::new()
                } else {
                    context(self.program, self.program.function(name))
                };
                let list: Vec<String> = before
                    .iter()
                    .map(|(n, _)| n.to_string())
                    .chain(args.iter().map(text))
                    .collect();
                (format!("{name}({})", list.join(", ")), None)
            }
            Expr::Truth(v) => (v.to_string(), None),
            Expr::Neg(a) => {
                let (a, op) = self.expr(a);
                (format!("-{}", wrap(&a, op)), None)
            }
            Expr::Math(f, args) => {
                let list: Vec<String> = args.iter().map(text).collect();
                (format!("{}({})", f.name(), list.join(", ")), None)
            }
            Expr::Member(a, member) => {
                let (a, op) = self.expr(a);
                (format!("{}.{member}", wrap(&a, op)), None)
            }
            Expr::Make(name, args) => {
                let list: Vec<String> = args.iter().map(text).collect();
                (format!("{name}({})", list.join(", ")), None)
            }
            Expr::Index(y, i) => {
                let (y, op) = self.expr(y);
                (format!("{}[{}]", wrap(&y, op), text(i)), None)
            }
            Expr::Zero(ty) => (format!("{}()", wgsl_type(*ty)), None),
            Expr::Differs(a, b) => (format!("any({} != {})", text(a), text(b)), None),
            Expr::Bits(bits, a) => {
                let (a, op) = self.expr(a);
                match bits {
                    Bits::Complement => (format!("~{}", wrap(&a, op)), None),
                    Bits::LowestSet => (format!("firstTrailingBit({a})"), None),
                }
            }
            // A constant converted from WGSL's abstract float, as an
            // `f32` literal is.
            Expr::Single(a) => match **a {
                Expr::Num(v) if v.is_finite() => (format!("f32({v:?})"), None),
                _ => (format!("f32({})", text(a)), None),
            },
            Expr::Counters(args) => {
                let list: Vec<String> = args.iter().map(text).collect();
                (format!("vec4<u32>({})", list.join(", ")), None)
            }
        }
    }
}

/// A value of C text: a number, one a state component, a pair's two
/// numbers (a phase's cosine and sine), a truth value (an `int`), or a
/// counter (a `uint32_t`).
#[derive(Clone, Debug, PartialEq)]
pub enum CValue {
    Real(String),
    State(Vec<String>),
    Pair(String, String),
    Bool(String),
    Count(String),
}

impl CValue {
    /// The C text of each number.
    fn parts(&self) -> Vec<&str> {
        match self {
            CValue::Real(v) | CValue::Bool(v) | CValue::Count(v) => vec![v],
            CValue::State(vs) => vs.iter().map(String::as_str).collect(),
            CValue::Pair(c, s) => vec![c, s],
        }
    }

    /// The same kind of value with these parts.
    fn with_parts(&self, parts: Vec<String>) -> CValue {
        let mut parts = parts.into_iter();
        let mut next = || parts.next().expect("as many parts");
        match self {
            CValue::Real(_) => CValue::Real(next()),
            CValue::Bool(_) => CValue::Bool(next()),
            CValue::Count(_) => CValue::Count(next()),
            CValue::Pair(..) => CValue::Pair(next(), next()),
            CValue::State(vs) => CValue::State(vs.iter().map(|_| next()).collect()),
        }
    }
}

/// The field as C statements: appends the field's values at `state` and
/// `clock` (atoms), its own values named after `prefix`, and gives its
/// outputs.
pub type CField<'a> = dyn FnMut(&mut String, &str, &[String], (&str, &str)) -> Vec<String> + 'a;

/// Where a program is inlined into C. The native step loops are loops
/// over the slots that the C compiler vectorises: what they inline is
/// straight-line code (a branch or a loop per slot would keep the loop
/// scalar), and a choice in it a [`Expr::Select`]; the statements with
/// branches and loops are for the C that runs one trajectory at a time.
pub struct C<'a> {
    pub syntax: &'a dyn Syntax,
    pub field: &'a mut CField<'a>,
    pub indent: &'a str,
}

/// The C names in scope while a function is inlined.
type Scope = HashMap<&'static str, CValue>;

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
        let mut scope: Scope = f.params.iter().map(|(n, _)| *n).zip(args).collect();
        let indent = self.indent.to_string();
        self.block(out, program, &mut scope, &f.body, prefix, &indent);
        f.results
            .iter()
            .map(|(result, e)| self.value(out, program, &scope, e, &format!("{prefix}{result}")))
            .collect()
    }

    /// Appends `block`'s statements at `indent`, adding what it declares
    /// to `scope`. A value set by a call or a field names that call's
    /// values after its statement's place in the block, so that two sets
    /// of one name do not declare the same C names.
    fn block(
        &mut self,
        out: &mut String,
        program: &Program,
        scope: &mut Scope,
        block: &[Stmt],
        prefix: &str,
        indent: &str,
    ) {
        let inner = format!("{indent}  ");
        for (place, stmt) in block.iter().enumerate() {
            match stmt {
                Stmt::Let(name, e) | Stmt::Var(name, e) => {
                    let named = format!("{prefix}{name}");
                    let value = self.value(out, program, scope, e, &named);
                    let mutable = matches!(stmt, Stmt::Var(..));
                    let value = self.declare(out, indent, &named, value, mutable);
                    scope.insert(name, value);
                }
                Stmt::Set(name, e) => {
                    let at = format!("{prefix}{name}_{}_{place}", indent.len());
                    let value = self.value(out, program, scope, e, &at);
                    assign(out, self.syntax, indent, &scope[name], &value);
                }
                Stmt::If(cond, then, otherwise) => {
                    let text = match self.expr(scope, cond).0 {
                        CValue::Bool(c) => c,
                        other => panic!("{other:?} is not a truth value"),
                    };
                    let _ = writeln!(out, "{indent}if {} {{", condition(cond, text));
                    self.block(out, program, &mut scope.clone(), then, prefix, &inner);
                    if !otherwise.is_empty() {
                        let _ = writeln!(out, "{indent}}} else {{");
                        self.block(out, program, &mut scope.clone(), otherwise, prefix, &inner);
                    }
                    let _ = writeln!(out, "{indent}}}");
                }
                Stmt::Loop(body) => {
                    let _ = writeln!(out, "{indent}for (;;) {{");
                    self.block(out, program, &mut scope.clone(), body, prefix, &inner);
                    let _ = writeln!(out, "{indent}}}");
                }
                Stmt::Break => {
                    let _ = writeln!(out, "{indent}break;");
                }
                Stmt::SetAt(..) => panic!("C's programs set no component (the kernels' stops do)"),
                Stmt::SetMember(..) => panic!("C's programs hold no structures to set"),
                Stmt::SetEntry(..) => panic!("C's programs hold no matrices"),
                Stmt::Do(..) => panic!("C's programs call no function for its effect"),
            }
        }
    }

    /// Names `value` `name` (components `{name}{i}`, `{name}_c`,
    /// `{name}_s`), fixed or, `mutable`, for later statements to set.
    fn declare(
        &self,
        out: &mut String,
        indent: &str,
        name: &str,
        value: CValue,
        mutable: bool,
    ) -> CValue {
        let names: Vec<String> = match &value {
            CValue::State(vs) => (0..vs.len()).map(|i| format!("{name}{i}")).collect(),
            CValue::Pair(..) => vec![format!("{name}_c"), format!("{name}_s")],
            _ => vec![name.to_string()],
        };
        for (n, v) in names.iter().zip(value.parts()) {
            let line = match (&value, mutable) {
                (CValue::Bool(_), m) => format!("{}int {n} = {v};", if m { "" } else { "const " }),
                (CValue::Count(_), m) => {
                    format!("{}uint32_t {n} = {v};", if m { "" } else { "const " })
                }
                (_, true) => format!("double {n} = {v};"),
                (_, false) => self.syntax.declare(n, v),
            };
            let _ = writeln!(out, "{indent}{line}");
        }
        value.with_parts(names)
    }

    /// `e` as C text; a field or a call it makes is written out first, its
    /// values named after `prefix`.
    fn value(
        &mut self,
        out: &mut String,
        program: &Program,
        scope: &Scope,
        e: &Expr,
        prefix: &str,
    ) -> CValue {
        match e {
            Expr::Field { of, phase, state } => {
                assert_eq!(
                    *of,
                    Field::Model,
                    "C evaluates the model's field only (the CPU holds a mass in Rust)"
                );
                let (Some(CValue::Pair(c, s)), Some(CValue::State(y))) =
                    (named(scope, phase), named(scope, state))
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
}

/// `target = value`: at once for one number; for several, each new
/// number named first, so that none is read after it was set (a phase's
/// doubling reads both old numbers).
fn assign(out: &mut String, syntax: &dyn Syntax, indent: &str, target: &CValue, value: &CValue) {
    let (targets, values) = (target.parts(), value.parts());
    assert_eq!(targets.len(), values.len(), "{target:?} = {value:?}");
    if let ([t], [v]) = (&targets[..], &values[..]) {
        let _ = writeln!(out, "{indent}{t} = {v};");
        return;
    }
    let _ = writeln!(out, "{indent}{{");
    for (t, v) in targets.iter().zip(&values) {
        let _ = writeln!(out, "{indent}  {}", syntax.declare(&format!("{t}_new"), v));
    }
    for t in &targets {
        let _ = writeln!(out, "{indent}  {t} = {t}_new;");
    }
    let _ = writeln!(out, "{indent}}}");
}

impl C<'_> {
    /// `e`, an operation of named values and numbers, as C text per
    /// component, with its outermost operation.
    fn expr(&self, scope: &Scope, e: &Expr) -> (CValue, Option<Op>) {
        match e {
            Expr::Var(name) => (scope[name].clone(), None),
            Expr::Num(v) => (CValue::Real(self.syntax.literal(*v)), None),
            Expr::Count(n) => (CValue::Count(format!("{n}u")), None),
            Expr::Abs(a) => match self.expr(scope, a).0 {
                CValue::Real(a) => (CValue::Real(self.syntax.call(Func::Abs, &a, "0.0")), None),
                other => panic!("|{other:?}|"),
            },
            Expr::Finite(a) => match self.expr(scope, a).0 {
                CValue::Real(a) => (CValue::Bool(format!("__builtin_isfinite({a})")), None),
                other => panic!("finite {other:?}"),
            },
            // As many components as a state in scope has (a program's
            // states have the model's dimension).
            Expr::Fill(a) => match self.operand(scope, a) {
                CValue::Real(a) => {
                    let d = scope
                        .values()
                        .find_map(|v| match v {
                            CValue::State(y) => Some(y.len()),
                            _ => None,
                        })
                        .expect("a filled state where a state is in scope");
                    (CValue::State(vec![a; d]), None)
                }
                other => panic!("a state filled with {other:?}"),
            },
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
                (CValue::Real(a), CValue::Real(b)) | (CValue::Count(a), CValue::Count(b)) => {
                    (CValue::Bool(format!("({a} {} {b})", cmp.symbol())), None)
                }
                _ => panic!("a comparison of two numbers or two counters"),
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
            Expr::Select {
                cond,
                then,
                otherwise,
            } => self.select(scope, cond, then, otherwise),
            Expr::Bin(op, a, b) => {
                let ((a, oa), (b, ob)) = (self.expr(scope, a), self.expr(scope, b));
                let both = |x: &str, y: &str| binary(*op, (x, oa), (y, ob));
                let value = match (a, b) {
                    (CValue::Real(x), CValue::Real(y)) => CValue::Real(both(&x, &y)),
                    (CValue::Count(x), CValue::Count(y)) => CValue::Count(both(&x, &y)),
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
            Expr::Truth(v) => (CValue::Bool(if *v { "1" } else { "0" }.into()), None),
            Expr::Neg(a) => match self.operand(scope, a) {
                CValue::Real(a) => (CValue::Real(format!("-{a}")), None),
                other => panic!("-{other:?}"),
            },
            Expr::Math(Math::Sqrt, args) => match self.expr(scope, &args[0]).0 {
                CValue::Real(a) => (CValue::Real(self.syntax.call(Func::Sqrt, &a, "")), None),
                other => panic!("sqrt {other:?}"),
            },
            // What only the kernels' programs use (their stops and Newton
            // brackets): the C step loops hold no structures.
            Expr::Math(..) | Expr::Member(..) | Expr::Make(..) | Expr::Index(..) => {
                panic!("C's step programs have no {e:?}")
            }
            Expr::Single(..) | Expr::Counters(..) | Expr::Zero(..) | Expr::Differs(..) => {
                panic!("C's step programs have no {e:?}")
            }
            // All ones for 0, as WGSL's firstTrailingBit (C's ctz of 0 is
            // undefined).
            Expr::Bits(bits, a) => match self.operand(scope, a) {
                CValue::Count(a) => (
                    CValue::Count(match bits {
                        Bits::Complement => format!("~{a}"),
                        Bits::LowestSet => {
                            format!("({a} == 0u ? 0xffffffffu : (uint32_t)__builtin_ctz({a}))")
                        }
                    }),
                    None,
                ),
                other => panic!("the bits of {other:?}"),
            },
        }
    }

    /// `cond ? then : otherwise`, per component: C's choice without a
    /// branch, which the compiler vectorises as a blend.
    fn select(
        &self,
        scope: &Scope,
        cond: &Expr,
        then: &Expr,
        otherwise: &Expr,
    ) -> (CValue, Option<Op>) {
        let CValue::Bool(c) = self.expr(scope, cond).0 else {
            panic!("a selection's condition is a truth value")
        };
        let ((a, oa), (b, ob)) = (self.expr(scope, then), self.expr(scope, otherwise));
        let parts = a
            .parts()
            .iter()
            .zip(b.parts())
            .map(|(x, y)| format!("({c} ? {} : {})", wrap(x, oa), wrap(y, ob)))
            .collect();
        (a.with_parts(parts), None)
    }

    /// `e` as an operand: its text, in parentheses where it is an
    /// operation (a number's or a counter's only; a call's arguments and a
    /// comparison's sides are read where they are used).
    fn operand(&self, scope: &Scope, e: &Expr) -> CValue {
        match self.expr(scope, e) {
            (CValue::Real(v), Some(_)) => CValue::Real(format!("({v})")),
            (CValue::Count(v), Some(_)) => CValue::Count(format!("({v})")),
            (value, _) => value,
        }
    }
}

fn named(scope: &Scope, e: &Expr) -> Option<CValue> {
    match e {
        Expr::Var(name) => scope.get(name).cloned(),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::ir::integrator::integrator;
    use crate::model::ir::step::build::{
        abs, and, bit_and, bit_or, bit_xor, break_unless, cmp, count, first, greater, less, lets,
        num, pair, second, select, shr, var,
    };

    struct Plain;

    impl Syntax for Plain {
        fn literal(&self, v: f64) -> String {
            format!("{v:?}")
        }
        fn declare(&self, name: &str, value: &str) -> String {
            format!("{name} = {value};")
        }
        fn call(&self, f: Func, a: &str, _: &str) -> String {
            format!("{}({a})", f.name())
        }
    }

    /// The integrator's program as the kernels print it.
    fn kernels() -> Program {
        let mut program = integrator();
        let c_only = crate::model::ir::integrator::C_ONLY;
        program.functions.retain(|f| !c_only.contains(&f.name));
        program
    }

    #[test]
    #[should_panic(expected = "WGSL has no constant NaN")]
    fn wgsl_refuses_a_constant_nan() {
        wgsl(&integrator(), &Plain);
    }

    #[test]
    fn rk4_prints_its_sum_in_the_reference_order() {
        let wgsl = wgsl(&kernels(), &Plain);
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

    /// A program with every statement: a counted loop that halves a
    /// number, a branch, a selection of states and a phase set from its
    /// own old value.
    fn counted() -> Program {
        let body = vec![
            Stmt::Var("x", var("a")),
            Stmt::Var("n", count(0)),
            Stmt::Loop(vec![
                break_unless(and(
                    greater(abs(var("x")), num(0.5)),
                    less(var("n"), count(8)),
                )),
                Stmt::Set("x", var("x") * 0.5),
                Stmt::Set("n", var("n") + count(1)),
            ]),
            Stmt::Var("q", pair(var("x"), var("a"))),
            Stmt::If(
                cmp(crate::model::ir::step::Cmp::Equal, var("n"), count(0)),
                vec![Stmt::Set("q", pair(second(var("q")), first(var("q"))))],
                vec![Stmt::Set("x", num(2.0) * "x")],
            ),
            Stmt::Let(
                "z",
                select(greater(var("x"), num(0.0)), var("y") + "y", var("y")),
            ),
        ];
        Program {
            functions: vec![Function {
                name: "f",
                params: vec![("a", Ty::Real), ("y", Ty::State)],
                body,
                results: vec![("r", var("x") * "z")],
                returns: None,
            }],
            ..Program::default()
        }
    }

    #[test]
    fn statements_print_as_wgsl_statements() {
        let text = wgsl(&counted(), &Plain);
        let expected = "\
fn f(a: real, y: State) -> State {
    var x = a;
    var n = 0u;
    loop {
        if (!((abs(x) > 0.5) && (n < 8u))) {
            break;
        }
        x = x * 0.5;
        n = n + 1u;
    }
    var q = vec2<real>(x, a);
    if (n == 0u) {
        q = vec2<real>(q.y, q.x);
    } else {
        x = 2.0 * x;
    }
    let z = select(y, y + y, (x > 0.0));
    return x * z;
}

";
        assert_eq!(text, expected);
    }

    #[test]
    fn statements_inline_into_c_with_every_component_named() {
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
        let results = c.inline(&mut out, &counted(), "f", args, "f_");
        let expected = "\
double f_x = A;
uint32_t f_n = 0u;
for (;;) {
  if (!((abs(f_x) > 0.5) & (f_n < 8u))) {
    break;
  }
  f_x = f_x * 0.5;
  f_n = f_n + 1u;
}
double f_q_c = f_x;
double f_q_s = A;
if (f_n == 0u) {
  {
    f_q_c_new = f_q_s;
    f_q_s_new = f_q_c;
    f_q_c = f_q_c_new;
    f_q_s = f_q_s_new;
  }
} else {
  f_x = 2.0 * f_x;
}
f_z0 = ((f_x > 0.0) ? (Y0 + Y0) : Y0);
f_z1 = ((f_x > 0.0) ? (Y1 + Y1) : Y1);
";
        assert_eq!(out, expected);
        assert_eq!(
            results,
            vec![CValue::State(vec![
                "f_x * f_z0".into(),
                "f_x * f_z1".into()
            ])]
        );
    }

    /// A function of a region's bits: a bit tested, a bit flipped, a
    /// bit operation inside a sum and a sum inside a bit operation.
    fn bits() -> Program {
        use crate::model::ir::step::Cmp;
        let side = bit_and(shr(var("region"), var("bit")), count(1));
        let flipped = bit_xor(var("region"), shr(var("region"), var("bit") + count(1)));
        let body = vec![
            Stmt::Let("up", cmp(Cmp::Equal, side, count(1))),
            Stmt::Let("moved", bit_or(flipped, count(2)) + count(1)),
        ];
        let result = select(var("up"), var("moved"), var("region"));
        let program = Program {
            functions: vec![Function {
                name: "f",
                params: vec![("region", Ty::Count), ("bit", Ty::Count)],
                body,
                results: vec![("r", result)],
                returns: None,
            }],
            ..Program::default()
        };
        assert_eq!(program.function("f").result_types(&program), [Ty::Count]);
        program
    }

    #[test]
    fn bit_operations_print_in_parentheses_in_wgsl() {
        let text = wgsl(&bits(), &Plain);
        let expected = "\
fn f(region: u32, bit: u32) -> u32 {
    let up = (((region >> bit) & 1u) == 1u);
    let moved = ((region ^ (region >> (bit + 1u))) | 2u) + 1u;
    return select(region, moved, up);
}
";
        assert!(text.contains(expected), "{text}");
    }

    #[test]
    fn bit_operations_inline_into_c_in_parentheses() {
        let mut field = |_: &mut String, _: &str, _: &[String], _: (&str, &str)| Vec::new();
        let mut c = C {
            syntax: &Plain,
            field: &mut field,
            indent: "",
        };
        let mut out = String::new();
        let args = vec![CValue::Count("R".into()), CValue::Count("B".into())];
        let results = c.inline(&mut out, &bits(), "f", args, "f_");
        let expected = "\
const int f_up = (((R >> B) & 1u) == 1u);
const uint32_t f_moved = ((R ^ (R >> (B + 1u))) | 2u) + 1u;
";
        assert_eq!(out, expected);
        assert_eq!(results, vec![CValue::Count("(f_up ? f_moved : R)".into())]);
    }

    #[test]
    fn the_region_walk_s_orientation_prints_its_bit_test() {
        let text = wgsl(&kernels(), &Plain);
        let expected = "\
fn orientation(region: u32, bit: u32) -> real {
    return select(1.0, -1.0, ((bit != 4294967295u) && (((region >> bit) & 1u) == 1u)));
}
";
        assert!(text.contains(expected), "{text}");
    }

    #[test]
    fn the_clock_s_cos_sin_prints_its_loops() {
        let text = wgsl(&kernels(), &Plain);
        assert!(
            text.contains("fn cos_sin(angle: real) -> vec2<real> {"),
            "{text}"
        );
        assert!(text.contains("        phi = phi * 0.5;\n"), "{text}");
        assert!(
            text.contains("    c = 1.0 - x2 * c;\n    s = 1.0 - x2 * s;\n"),
            "{text}"
        );
        assert!(
            text.contains("result = vec2<real>(rc * rc - rs * rs, 2.0 * rs * rc);"),
            "{text}"
        );
        // The held flow's RK4 takes the stop.
        assert!(
            text.contains("fn held_step(p: Params, w: Stop, phase: vec2<real>, half: vec2<real>, y: State, h: real) -> Stepped {"),
            "{text}"
        );
        assert!(
            text.contains("let k1 = held_rhs(p, w, phase, y);"),
            "{text}"
        );
        assert!(
            text.contains("return Stepped(held_update(p, w, phase, mid, end, y, h), end);"),
            "{text}"
        );
    }

    #[test]
    fn inlined_c_names_each_component_and_keeps_right_operands_apart() {
        let program = Program {
            functions: vec![Function {
                name: "f",
                params: vec![("a", Ty::Real), ("y", Ty::State)],
                body: lets(vec![("z", Expr::from("a") - (Expr::from("a") - "a") * "y")]),
                results: vec![("r", Expr::from("z") + "y")],
                returns: None,
            }],
            ..Program::default()
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

    #[test]
    fn the_stops_print_as_the_kernels_read_them() {
        let text = wgsl(&kernels(), &Plain);
        let expected = [
            "struct Stop {\n    position: real,\n    restitution: real,\n    coordinate: u32,\n    velocity: u32,\n    side: real,\n}\n",
            "fn gap(w: Stop, y: State) -> real {\n    return w.side * (y[w.coordinate] - w.position);\n}\n",
            "fn on_stop(w: Stop, y: State, v: real) -> State {\n    var out = y;\n    out[w.coordinate] = w.position;\n    out[w.velocity] = w.side * v;\n    return out;\n}\n",
            "    return may_meet(stop_values(w, y), stop_values(w, y1), h);\n",
            "    var hit = reaches(stop(walls, 0u), y, h, y1);\n    if (WALLS > 1u) {\n        hit = (hit || reaches(stop(walls, 1u), y, h, y1));\n    }\n",
            "    var on = WALLS;\n    if ((WALLS > 3u) && at_rest(stop(walls, 3u), y)) {\n        on = 3u;\n    }\n",
            "    return ((y[w.coordinate] == w.position) && (y[w.velocity] == 0.0));\n",
        ];
        for part in expected {
            assert!(text.contains(part), "{part}\nnot in\n{text}");
        }
    }

    #[test]
    fn the_location_prints_the_hermite_guess_and_the_bracket() {
        let text = wgsl(&kernels(), &Plain);
        let expected = [
            "    let c2 = 3.0 * (g1 - g0) - 2.0 * d0 - d1;\n    let c3 = 2.0 * (g0 - g1) + d0 + d1;\n    return Hermite(g0, d0, c2, c3);\n",
            "    return c.c0 + th * (c.c1 + th * (c.c2 + th * c.c3));\n",
            "    return c.c1 + th * (2.0 * c.c2 + th * 3.0 * c.c3);\n",
            "        let root = sqrt(max(b * b - 4.0 * a * c.c1, 0.0));\n",
            "            th = -0.5 * (b + root) / a;\n",
            "            th = c.c1 / (-0.5 * (b - root));\n",
            "        peak = clamp(th, 0.0, 1.0);\n",
            "    var th = a + (b - a) * clamp(-ga / (gb - ga), 0.0, 1.0);\n",
            "        let next = th - g / hermite_slope(c, th);\n",
            "        if ((next > a) && (next < b)) {\n            th = next;\n        } else {\n            th = 0.5 * (a + b);\n        }\n",
            "    var out = Bracket(false, false, 0.0, 0.0, 0.0);\n",
            "        out = Bracket(true, false, 0.0, h, hermite_first_root(herm, 0.0, 1.0) * h);\n",
            "            if (!(peak < 0.0)) {\n                out = Bracket(true, true, 0.0, peak * h, hermite_first_root(herm, 0.0, peak) * h);\n",
            "    let newton = b.s - g / rate;\n",
            "    return Bracket(b.found, b.at_peak, lo, hi, s);\n",
        ];
        for part in expected {
            assert!(text.contains(part), "{part}\nnot in\n{text}");
        }
    }

    #[test]
    fn a_call_with_several_results_is_read_by_member() {
        use crate::model::ir::step::build::dot;
        let mut program = kernels();
        program.functions.push(Function {
            name: "f",
            params: vec![("omega", Ty::Real), ("phase", Ty::Pair), ("y", Ty::State)],
            body: lets(vec![(
                "stepped",
                Expr::Call(
                    "sub_step",
                    vec![var("omega"), var("phase"), var("y"), num(0.5)],
                ),
            )]),
            results: vec![("y", dot("stepped", "y"))],
            returns: None,
        });
        assert_eq!(program.function("f").result_types(&program), [Ty::State]);
        let text = wgsl(&program, &Plain);
        let expected = "fn f(p: Params, omega: real, phase: vec2<real>, y: State) -> State {\n    let stepped = sub_step(p, omega, phase, y, 0.5);\n    return stepped.y;\n}\n";
        assert!(text.contains(expected), "{text}");
    }

    #[test]
    fn the_surfaces_print_their_regions_and_members_as_the_kernels_read_them() {
        let text = wgsl(&kernels(), &Plain);
        let expected = [
            "fn is_sliding(region: u32) -> bool {\n    return ((region >> SLIDING_SHIFT) != 0u);\n}\n",
            "fn surface_pair(j: u32, v: SurfaceValues) -> vec2<real> {\n    return vec2<real>(v.g[j], v.rate[j]);\n}\n",
            "    var hit = may_cross(region, 0u, before, after, h);\n    if (SURFACES > 1u) {\n        hit = (hit || may_cross(region, 1u, before, after, h));\n    }\n",
            "            region = region | (1u << SURFACE_BIT[j]);\n",
            "    var lo_p = p;\n    lo_p.region = (p.region & SIDES) & ~(1u << bit);\n    var hi_p = lo_p;\n    hi_p.region = lo_p.region | (1u << bit);\n",
            "    let s = switch_sides(p, firstTrailingBit(p.region >> SLIDING_SHIFT), phase, y);\n",
            "        let y_to = sub_step(p, omega, phase, y, to).y;\n",
            "        joined.region = p.region | (1u << (SLIDING_SHIFT + j));\n",
            "            out.log_det = log_r(leaving / approach_rate);\n",
            "struct Crossing {\n    resolved: bool,\n    y: State,\n    region: u32,\n",
            "fn event_log_det(r: Reset, gradient: State, rate: real, before: State, after: State) -> real {\n    var s = r.dr;\n",
            "            s[i][k] = r.dr[i][k] + (after[i] - dr_f - r.rate[i]) * gradient[k] / rate;\n",
            "            let swap = s[col];\n            s[col] = s[pivot];\n            s[pivot] = swap;\n            det = -det;\n",
            "                s[below][m] = s[below][m] - factor * s[col][m];\n",
            "        out = -1.0 / zero;\n",
        ];
        for part in expected {
            assert!(text.contains(part), "{part}\nnot in\n{text}");
        }
        // The kernels' structures are theirs: not printed.
        assert!(!text.contains("struct Params"), "{text}");
        assert!(!text.contains("struct SurfaceValues"), "{text}");
    }

    #[test]
    fn the_step_loop_prints_as_the_kernels_read_it() {
        let text = wgsl(&kernels(), &Plain);
        let expected = [
            // A stop the function reads itself is not a parameter.
            "fn stuck_step(p: Params, walls: Stops, j: u32, omega: real, phase: vec2<real>, y: State, h: real) -> WallStep {\n    let w = stop(walls, j);\n",
            "        out = held_sub_step(p, w, omega, phase, rest, s).y;\n",
            "        let held = held_for(p, w, omega, phase, rest, h);\n        if (!(pressing(p, w, rotate(phase, cos_sin(omega * h)), held) <= 0.0)) {\n",
            "                if (hi - lo <= EPSILON * h) {\n                    break;\n",
            "        out = clamp_to_stops(walls, sub_step(p, omega, start_phase, start, left).y);\n",
            "        var crossings = r.crossings;\n        crossings[met.stop] = crossings[met.stop] + 1u;\n        r.crossings = crossings;\n",
            "        if ((rebound == 0.0) || ((push > 0.0) && (2.0 * rebound < 0.0010000000474974513 * h * push * (1.0 - e)))) {\n",
            "    var r = Resolution(0.0, phase, y, 0u, vec4<u32>(), NO_IMPACT, 0u, WALLS, false, false, false, neutral_crossed(p.region));\n",
            "            y1 = sub_step(p, omega, r.phase0, r.y0, h - r.done).y;\n",
            "    if (found.found && ((met.stop == WALLS + SURFACES) || (found.s < met.hit.s))) {\n",
            "    r.crossed = Crossed(crossing.region, r.crossed.log_flux + crossing.log_det, (r.crossed.sliding || crossing.sliding), r.crossed.sliding_phases);\n",
        ];
        for part in expected {
            assert!(text.contains(part), "{part}\nnot in\n{text}");
        }
    }

    #[test]
    fn a_resolved_step_prints_as_the_integrate_kernel_reads_it() {
        let text = wgsl(&kernels(), &Plain);
        let expected = [
            // A stop read inside a branch is not taken from the callers.
            "fn resolve_step(p_lane: Params, walls: Stops, step: Stepping, y1: State, comp1: State, tr_in: Trajectory) -> Resolved {\n    var p = p_lane;\n",
            "        let w = resolve_impacts(p, walls, step.omega, tr.phase, tr.y, step.h, y1);\n        tr = record(tr, w, y1, comp1);\n",
            "    if (any(w.y != y1)) {\n        tr.y = w.y;\n        tr.comp = State();\n",
            "    phases_c[2u] = phases_c[2u] + (select(room, phases, (phases < room)) << 16u);\n",
            "    let room = 65535u - (phases_c[2u] >> 16u);\n",
            "    return Resolved(tr, crossings);\n",
        ];
        for part in expected {
            assert!(text.contains(part), "{part}\nnot in\n{text}");
        }
    }

    #[test]
    fn a_zero_prints_as_its_type_s_zero() {
        let program = Program {
            functions: vec![Function {
                name: "f",
                params: vec![("j", Ty::Count)],
                body: vec![
                    Stmt::Var("n", Expr::Zero(Ty::CountTable)),
                    Stmt::SetAt("n", var("j"), count(1)),
                ],
                results: vec![("n", var("n"))],
                returns: None,
            }],
            ..Program::default()
        };
        let text = wgsl(&program, &Plain);
        assert!(
            text.contains(
                "fn f(j: u32) -> vec4<u32> {\n    var n = vec4<u32>();\n    n[j] = 1u;\n"
            ),
            "{text}"
        );
    }

    #[test]
    fn a_counter_s_bits_inline_into_c() {
        use crate::model::ir::step::build::{complement, lowest_set, shl};
        let program = Program {
            functions: vec![Function {
                name: "f",
                params: vec![("region", Ty::Count), ("bit", Ty::Count)],
                body: lets(vec![(
                    "cleared",
                    bit_and(var("region"), complement(shl(count(1), var("bit")))),
                )]),
                results: vec![("r", lowest_set(var("cleared")))],
                returns: None,
            }],
            ..Program::default()
        };
        let mut field = |_: &mut String, _: &str, _: &[String], _: (&str, &str)| Vec::new();
        let mut c = C {
            syntax: &Plain,
            field: &mut field,
            indent: "",
        };
        let mut out = String::new();
        let args = vec![CValue::Count("R".into()), CValue::Count("B".into())];
        let results = c.inline(&mut out, &program, "f", args, "f_");
        assert_eq!(out, "const uint32_t f_cleared = R & ~(1u << B);\n");
        assert_eq!(
            results,
            vec![CValue::Count(
                "(f_cleared == 0u ? 0xffffffffu : (uint32_t)__builtin_ctz(f_cleared))".into()
            )]
        );
    }

    /// A procedure over the kernels' buffers: an element read and one
    /// set, a procedure of theirs called, a single, four counters and a
    /// remainder.
    fn stores() -> Program {
        use crate::model::ir::step::build::{counters, index, max, perform, rem, single};
        use crate::model::ir::step::Extern;
        let buffer = |name, element| Extern::Buffer {
            name,
            element,
            writable: true,
        };
        let body = vec![
            Stmt::Var("c", index(var("counts"), var("t"))),
            Stmt::SetAt(
                "c",
                count(3),
                rem(index(var("c"), count(3)) + count(1), count(4)),
            ),
            Stmt::SetAt("counts", var("t") * count(2), var("c")),
            Stmt::SetAt(
                "counts",
                var("t"),
                counters([count(0), count(1), count(2), count(3)]),
            ),
            Stmt::Let(
                "x",
                max(
                    single(num(1e30)),
                    single(index(var("traj"), var("t")) * 2.0),
                ),
            ),
            perform("store", vec![var("t"), var("x")]),
        ];
        let program = Program {
            functions: vec![Function {
                name: "f",
                params: vec![("t", Ty::Count)],
                body,
                results: Vec::new(),
                returns: None,
            }],
            structures: Vec::new(),
            externs: vec![
                buffer("traj", Ty::Real),
                buffer("counts", Ty::CountTable),
                Extern::Proc {
                    name: "store",
                    params: vec![Ty::Count, Ty::Single],
                },
            ],
        };
        assert!(program.function("f").result_types(&program).is_empty());
        program
    }

    #[test]
    fn procedures_and_buffers_print_as_wgsl() {
        let text = wgsl(&stores(), &Plain);
        let expected = "\
fn f(t: u32) {
    var c = counts[t];
    c[3u] = (c[3u] + 1u) % 4u;
    counts[t * 2u] = c;
    counts[t] = vec4<u32>(0u, 1u, 2u, 3u);
    let x = max(f32(1e30), f32(traj[t] * 2.0));
    store(t, x);
}

";
        assert_eq!(text, expected);
    }
}
