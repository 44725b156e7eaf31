//! Expressions of a model: the right-hand sides, event surfaces, resets and
//! map periods a scene writes as text, parsed once into a tree that every
//! backend reads (evaluated on the CPU, emitted as WGSL) and that the sum
//! rule differentiates symbolically.
//!
//! Grammar (precedence from loosest to tightest; `^` is right-associative
//! and binds tighter than a leading minus, so `-x^2` is `-(x^2)`):
//!
//! ```text
//! sum     = product (("+" | "-") product)*
//! product = unary (("*" | "/") unary)*
//! unary   = "-" unary | power
//! power   = atom ("^" unary)?
//! atom    = number | name | name "(" sum ("," sum)* ")" | "(" sum ")"
//! ```
//!
//! Names are the model's states and parameters, `t` (time) and `pi`;
//! functions are `sin cos tan exp log sqrt abs tanh atan2 min max pow`,
//! and `step(s)`, `sign(s)` of a switch s (1 or 0, ±1 by its side).
//!
//! An expression is at most [`MAX_CHARS`] characters and its tree at most
//! [`MAX_DEPTH`] levels deep (a flat sum of n terms is n levels): every pass
//! over the tree (derivatives, regions, code generation) recurses, and a
//! deeper tree would overflow the stack. Both are refused in linear time,
//! before any of those passes runs.

use std::fmt;

use crate::error::clip;

/// The most characters an expression may have.
pub const MAX_CHARS: usize = 20_000;

/// The deepest an expression's tree may be: nested parentheses, calls,
/// powers and minus signs, and the terms of a sum or factors of a product,
/// each count one level.
pub const MAX_DEPTH: usize = 1_000;

/// What a name in an expression stands for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Var {
    /// State i of the model, in its `states` order.
    State(usize),
    /// Parameter i of the model, in its `parameters` order.
    Param(usize),
    /// Time `t`.
    Time,
    /// The side of switch j (`step(name)`): 1 where its surface is > 0, 0
    /// on the other side. Constant along a step: the integrator stops at
    /// every crossing, and each region's field is compiled with its sides
    /// substituted ([`Expr::in_region`]), so nothing evaluates it from the
    /// raw state.
    Side(usize),
}

/// The functions an expression may call, with their arity. `Sign` is not
/// written by users: derivatives of `abs`, `min` and `max` use it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Func {
    Sin,
    Cos,
    Tan,
    Exp,
    Log,
    Sqrt,
    Abs,
    Tanh,
    Atan2,
    Min,
    Max,
    Pow,
    Sign,
}

impl Func {
    const NAMED: [(&'static str, Func); 12] = [
        ("sin", Func::Sin),
        ("cos", Func::Cos),
        ("tan", Func::Tan),
        ("exp", Func::Exp),
        ("log", Func::Log),
        ("sqrt", Func::Sqrt),
        ("abs", Func::Abs),
        ("tanh", Func::Tanh),
        ("atan2", Func::Atan2),
        ("min", Func::Min),
        ("max", Func::Max),
        ("pow", Func::Pow),
    ];

    fn by_name(name: &str) -> Option<Func> {
        Func::NAMED
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, f)| *f)
    }

    pub fn name(self) -> &'static str {
        match self {
            Func::Sign => "sign",
            f => Func::NAMED
                .iter()
                .find(|(_, g)| *g == f)
                .map(|(n, _)| *n)
                .expect("every user function is named"),
        }
    }

    pub fn arity(self) -> usize {
        match self {
            Func::Atan2 | Func::Min | Func::Max | Func::Pow => 2,
            _ => 1,
        }
    }

    pub(crate) fn apply(self, a: &[f64]) -> f64 {
        match self {
            // The GPU's arithmetic, to the bit (`crate::model::language::math64`).
            Func::Sin => crate::model::language::math64::sin(a[0]),
            Func::Cos => crate::model::language::math64::cos(a[0]),
            Func::Tan => crate::model::language::math64::tan(a[0]),
            Func::Exp => a[0].exp(),
            Func::Log => a[0].ln(),
            Func::Sqrt => a[0].sqrt(),
            Func::Abs => a[0].abs(),
            Func::Tanh => a[0].tanh(),
            Func::Atan2 => a[0].atan2(a[1]),
            Func::Min => a[0].min(a[1]),
            Func::Max => a[0].max(a[1]),
            Func::Pow => a[0].powf(a[1]),
            Func::Sign => {
                if a[0] > 0.0 {
                    1.0
                } else if a[0] < 0.0 {
                    -1.0
                } else {
                    0.0
                }
            }
        }
    }
}

/// A binary operator.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Op {
    Add,
    Sub,
    Mul,
    Div,
    Pow,
}

impl Op {
    fn symbol(self) -> &'static str {
        match self {
            Op::Add => "+",
            Op::Sub => "-",
            Op::Mul => "*",
            Op::Div => "/",
            Op::Pow => "^",
        }
    }

    fn precedence(self) -> u8 {
        match self {
            Op::Add | Op::Sub => 1,
            Op::Mul | Op::Div => 2,
            Op::Pow => 4,
        }
    }
}

/// A parsed expression.
#[derive(Clone, Debug, PartialEq)]
pub enum Expr {
    Num(f64),
    Var(Var),
    Neg(Box<Expr>),
    Bin(Op, Box<Expr>, Box<Expr>),
    Call(Func, Vec<Expr>),
}

/// The names an expression may use: the model's states and parameters.
#[derive(Clone, Debug, Default)]
pub struct Names {
    pub states: Vec<String>,
    pub parameters: Vec<String>,
    /// The model's switches, which `step(...)` and `sign(...)` name.
    pub switches: Vec<String>,
}

impl Names {
    fn resolve(&self, name: &str) -> Option<Expr> {
        if let Some(i) = self.states.iter().position(|s| s == name) {
            return Some(Expr::Var(Var::State(i)));
        }
        if let Some(i) = self.parameters.iter().position(|p| p == name) {
            return Some(Expr::Var(Var::Param(i)));
        }
        match name {
            "t" => Some(Expr::Var(Var::Time)),
            "pi" => Some(Expr::Num(std::f64::consts::PI)),
            _ => None,
        }
    }
}

/// Why an expression does not parse, and where: `column` counts characters
/// from 1.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ParseError {
    pub column: usize,
    pub message: String,
}

impl fmt::Display for ParseError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} (column {})", self.message, self.column)
    }
}

#[derive(Clone, Debug, PartialEq)]
enum Token {
    Num(f64),
    Name(String),
    Sym(char),
    End,
}

/// The tokens of `text`, each with its column (from 1).
fn tokenize(text: &str) -> Result<Vec<(Token, usize)>, ParseError> {
    let chars: Vec<char> = text.chars().collect();
    let mut tokens = Vec::new();
    let mut i = 0;
    while i < chars.len() {
        let c = chars[i];
        let column = i + 1;
        if c.is_whitespace() {
            i += 1;
        } else if c.is_ascii_digit()
            || (c == '.' && chars.get(i + 1).is_some_and(char::is_ascii_digit))
        {
            let start = i;
            while i < chars.len() && (chars[i].is_ascii_digit() || chars[i] == '.') {
                i += 1;
            }
            // An exponent: e or E, an optional sign, digits.
            if i < chars.len() && (chars[i] == 'e' || chars[i] == 'E') {
                let mut j = i + 1;
                if j < chars.len() && (chars[j] == '+' || chars[j] == '-') {
                    j += 1;
                }
                if j < chars.len() && chars[j].is_ascii_digit() {
                    i = j;
                    while i < chars.len() && chars[i].is_ascii_digit() {
                        i += 1;
                    }
                }
            }
            let literal: String = chars[start..i].iter().collect();
            let value = literal.parse::<f64>().map_err(|_| ParseError {
                column,
                message: format!("'{}' is not a number", clip(&literal)),
            })?;
            if value.is_infinite() {
                return Err(ParseError {
                    column,
                    message: format!(
                        "'{}' is beyond the largest number ({:e})",
                        clip(&literal),
                        f64::MAX
                    ),
                });
            }
            tokens.push((Token::Num(value), column));
        } else if c.is_alphabetic() || c == '_' {
            let start = i;
            while i < chars.len() && (chars[i].is_alphanumeric() || chars[i] == '_') {
                i += 1;
            }
            tokens.push((Token::Name(chars[start..i].iter().collect()), column));
        } else if "+-*/^(),".contains(c) {
            tokens.push((Token::Sym(c), column));
            i += 1;
        } else {
            return Err(ParseError {
                column,
                message: format!("unexpected character '{c}'"),
            });
        }
    }
    tokens.push((Token::End, chars.len() + 1));
    Ok(tokens)
}

struct Parser<'a> {
    tokens: Vec<(Token, usize)>,
    at: usize,
    names: &'a Names,
    /// How deep the parser has recursed: bounded by [`MAX_DEPTH`], so that
    /// deeply nested text is refused before it overflows the stack.
    nesting: usize,
}

impl Parser<'_> {
    fn peek(&self) -> &Token {
        &self.tokens[self.at].0
    }

    fn column(&self) -> usize {
        self.tokens[self.at].1
    }

    fn error<T>(&self, message: impl Into<String>) -> Result<T, ParseError> {
        Err(ParseError {
            column: self.column(),
            message: message.into(),
        })
    }

    fn eat(&mut self, symbol: char) -> bool {
        if *self.peek() == Token::Sym(symbol) {
            self.at += 1;
            true
        } else {
            false
        }
    }

    fn expect(&mut self, symbol: char) -> Result<(), ParseError> {
        if self.eat(symbol) {
            Ok(())
        } else {
            let found = describe(self.peek());
            self.error(format!("expected '{symbol}', found {found}"))
        }
    }

    /// Enters one more level of nesting, or refuses it.
    fn deeper(&mut self) -> Result<(), ParseError> {
        self.nesting += 1;
        if self.nesting > MAX_DEPTH {
            return self.error(format!("nested more than {MAX_DEPTH} levels deep"));
        }
        Ok(())
    }

    fn sum(&mut self) -> Result<Expr, ParseError> {
        self.deeper()?;
        let sum = self.terms();
        self.nesting -= 1;
        sum
    }

    fn terms(&mut self) -> Result<Expr, ParseError> {
        let mut left = self.product()?;
        loop {
            let op = match self.peek() {
                Token::Sym('+') => Op::Add,
                Token::Sym('-') => Op::Sub,
                _ => return Ok(left),
            };
            self.at += 1;
            left = Expr::Bin(op, Box::new(left), Box::new(self.product()?));
        }
    }

    fn product(&mut self) -> Result<Expr, ParseError> {
        let mut left = self.unary()?;
        loop {
            let op = match self.peek() {
                Token::Sym('*') => Op::Mul,
                Token::Sym('/') => Op::Div,
                _ => return Ok(left),
            };
            self.at += 1;
            left = Expr::Bin(op, Box::new(left), Box::new(self.unary()?));
        }
    }

    fn unary(&mut self) -> Result<Expr, ParseError> {
        if self.eat('-') {
            self.deeper()?;
            let operand = self.unary();
            self.nesting -= 1;
            return Ok(Expr::Neg(Box::new(operand?)));
        }
        self.power()
    }

    fn power(&mut self) -> Result<Expr, ParseError> {
        let base = self.atom()?;
        if self.eat('^') {
            self.deeper()?;
            let exponent = self.unary();
            self.nesting -= 1;
            return Ok(Expr::Bin(Op::Pow, Box::new(base), Box::new(exponent?)));
        }
        Ok(base)
    }

    fn atom(&mut self) -> Result<Expr, ParseError> {
        let column = self.column();
        match self.peek().clone() {
            Token::Num(v) => {
                self.at += 1;
                Ok(Expr::Num(v))
            }
            Token::Sym('(') => {
                self.at += 1;
                let inner = self.sum()?;
                self.expect(')')?;
                Ok(inner)
            }
            Token::Name(name) => {
                self.at += 1;
                if *self.peek() == Token::Sym('(') && (name == "step" || name == "sign") {
                    return self.side(&name);
                }
                if *self.peek() == Token::Sym('(') {
                    let Some(func) = Func::by_name(&name) else {
                        return Err(ParseError {
                            column,
                            message: format!("unknown function '{}'", clip(&name)),
                        });
                    };
                    self.at += 1;
                    let mut args = vec![self.sum()?];
                    while self.eat(',') {
                        args.push(self.sum()?);
                    }
                    self.expect(')')?;
                    if args.len() != func.arity() {
                        return Err(ParseError {
                            column,
                            message: format!(
                                "{name} takes {} argument{}, got {}",
                                func.arity(),
                                if func.arity() == 1 { "" } else { "s" },
                                args.len()
                            ),
                        });
                    }
                    return Ok(Expr::Call(func, args));
                }
                if let Some(resolved) = self.names.resolve(&name) {
                    return Ok(resolved);
                }
                let message = match Func::by_name(&name) {
                    Some(_) => format!("'{name}' is a function: write {name}(...)"),
                    None => format!("unknown name '{}'", clip(&name)),
                };
                Err(ParseError { column, message })
            }
            other => self.error(format!(
                "expected a number, a name or '(', found {}",
                describe(&other)
            )),
        }
    }
}

impl Parser<'_> {
    /// `step(s)` or `sign(s)` of a switch s, after its name: the switch's
    /// side, or 2·side - 1.
    fn side(&mut self, function: &str) -> Result<Expr, ParseError> {
        self.expect('(')?;
        let argument = self.column();
        let switch = match self.peek().clone() {
            Token::Name(n) => self.names.switches.iter().position(|s| *s == n),
            _ => None,
        };
        let Some(j) = switch else {
            let known = if self.names.switches.is_empty() {
                "the model has none: declare [[model.switches]]".to_owned()
            } else {
                format!("switches: {}", self.names.switches.join(", "))
            };
            return Err(ParseError {
                column: argument,
                message: format!("{function}(...) takes the name of a switch ({known})"),
            });
        };
        self.at += 1;
        self.expect(')')?;
        let side = Expr::Var(Var::Side(j));
        Ok(if function == "step" {
            side
        } else {
            Expr::Bin(
                Op::Sub,
                Box::new(Expr::Bin(Op::Mul, Box::new(Expr::Num(2.0)), Box::new(side))),
                Box::new(Expr::Num(1.0)),
            )
        })
    }
}

fn describe(token: &Token) -> String {
    match token {
        Token::Num(v) => format!("the number {v}"),
        Token::Name(n) => format!("'{}'", clip(n)),
        Token::Sym(c) => format!("'{c}'"),
        Token::End => "the end".to_owned(),
    }
}

impl Expr {
    /// Parses `text`, resolving its names against `names`.
    pub fn parse(text: &str, names: &Names) -> Result<Expr, ParseError> {
        if text.len() > MAX_CHARS && text.chars().count() > MAX_CHARS {
            return Err(ParseError {
                column: MAX_CHARS + 1,
                message: format!(
                    "longer than {MAX_CHARS} characters ({})",
                    text.chars().count()
                ),
            });
        }
        let mut parser = Parser {
            tokens: tokenize(text)?,
            at: 0,
            names,
            nesting: 0,
        };
        if *parser.peek() == Token::End {
            return parser.error("empty expression");
        }
        let expr = parser.sum()?;
        if *parser.peek() != Token::End {
            let found = describe(parser.peek());
            return parser.error(format!("unexpected {found}"));
        }
        let depth = expr.depth();
        if depth > MAX_DEPTH {
            return Err(ParseError {
                column: 1,
                message: format!(
                    "{depth} levels deep, more than {MAX_DEPTH} (a sum of n terms is n levels): \
                     group its terms in parentheses"
                ),
            });
        }
        Ok(expr)
    }

    /// The number of levels of the tree, counted without recursion (the
    /// tree may be too deep for it).
    pub fn depth(&self) -> usize {
        let mut deepest = 0;
        let mut stack = vec![(self, 1)];
        while let Some((e, level)) = stack.pop() {
            deepest = deepest.max(level);
            match e {
                Expr::Num(_) | Expr::Var(_) => {}
                Expr::Neg(a) => stack.push((a, level + 1)),
                Expr::Bin(_, a, b) => stack.extend([(&**a, level + 1), (&**b, level + 1)]),
                Expr::Call(_, args) => stack.extend(args.iter().map(|a| (a, level + 1))),
            }
        }
        deepest
    }

    /// The value at the given states, parameters and time.
    pub fn eval(&self, states: &[f64], params: &[f64], t: f64) -> f64 {
        match self {
            Expr::Num(v) => *v,
            Expr::Var(Var::State(i)) => states[*i],
            Expr::Var(Var::Param(i)) => params[*i],
            Expr::Var(Var::Time) => t,
            Expr::Var(Var::Side(_)) => {
                unreachable!("a switch's side is substituted per region (Expr::in_region)")
            }
            Expr::Neg(a) => -a.eval(states, params, t),
            Expr::Bin(op, a, b) => {
                let (x, y) = (a.eval(states, params, t), b.eval(states, params, t));
                match op {
                    Op::Add => x + y,
                    Op::Sub => x - y,
                    Op::Mul => x * y,
                    Op::Div => x / y,
                    Op::Pow => x.powf(y),
                }
            }
            Expr::Call(f, args) => {
                let values: Vec<f64> = args.iter().map(|a| a.eval(states, params, t)).collect();
                f.apply(&values)
            }
        }
    }

    /// The expression in region `region` of the model's switches: the side
    /// of switch j (bit j of `region`, 1 where its surface is > 0)
    /// substituted, folded where it multiplies.
    pub fn in_region(&self, region: u32) -> Expr {
        match self {
            Expr::Var(Var::Side(j)) => Expr::Num(f64::from((region >> j) & 1)),
            Expr::Num(_) | Expr::Var(_) => self.clone(),
            Expr::Neg(a) => neg(a.in_region(region)),
            Expr::Bin(op, a, b) => {
                let (a, b) = (a.in_region(region), b.in_region(region));
                match op {
                    Op::Add => add(a, b),
                    Op::Sub => sub(a, b),
                    Op::Mul => mul(a, b),
                    _ => Expr::Bin(*op, Box::new(a), Box::new(b)),
                }
            }
            Expr::Call(f, args) => {
                Expr::Call(*f, args.iter().map(|a| a.in_region(region)).collect())
            }
        }
    }

    /// Whether the expression reads a switch's side.
    pub fn reads_sides(&self) -> bool {
        match self {
            Expr::Num(_) => false,
            Expr::Var(v) => matches!(v, Var::Side(_)),
            Expr::Neg(a) => a.reads_sides(),
            Expr::Bin(_, a, b) => a.reads_sides() || b.reads_sides(),
            Expr::Call(_, args) => args.iter().any(Expr::reads_sides),
        }
    }

    /// Whether the expression reads `var`.
    pub fn uses(&self, var: Var) -> bool {
        match self {
            Expr::Num(_) => false,
            Expr::Var(v) => *v == var,
            Expr::Neg(a) => a.uses(var),
            Expr::Bin(_, a, b) => a.uses(var) || b.uses(var),
            Expr::Call(_, args) => args.iter().any(|a| a.uses(var)),
        }
    }

    /// ∂/∂var, symbolically, with constants folded: what the sum rule needs
    /// (div F = Σ ∂F_i/∂y_i, ∇g of an event surface). Where the function is
    /// not differentiable (abs, min, max at a tie) it takes the one-sided
    /// value `sign` gives there.
    pub fn derivative(&self, var: Var) -> Expr {
        use Expr::{Bin, Call, Neg, Num};
        let d = |e: &Expr| e.derivative(var);
        match self {
            Num(_) => Num(0.0),
            Expr::Var(v) => Num(if *v == var { 1.0 } else { 0.0 }),
            Neg(a) => neg(d(a)),
            Bin(Op::Add, a, b) => add(d(a), d(b)),
            Bin(Op::Sub, a, b) => sub(d(a), d(b)),
            Bin(Op::Mul, a, b) => add(mul(d(a), (**b).clone()), mul((**a).clone(), d(b))),
            Bin(Op::Div, a, b) => div(
                sub(mul(d(a), (**b).clone()), mul((**a).clone(), d(b))),
                mul((**b).clone(), (**b).clone()),
            ),
            Bin(Op::Pow, a, b) => power_derivative(a, b, d(a), d(b)),
            Call(f, args) => {
                let a = &args[0];
                let da = d(a);
                let call = |g: Func, x: Expr| Call(g, vec![x]);
                match f {
                    Func::Sin => mul(call(Func::Cos, a.clone()), da),
                    Func::Cos => neg(mul(call(Func::Sin, a.clone()), da)),
                    Func::Tan => {
                        let c = call(Func::Cos, a.clone());
                        div(da, mul(c.clone(), c))
                    }
                    Func::Exp => mul(self.clone(), da),
                    Func::Log => div(da, a.clone()),
                    Func::Sqrt => div(da, mul(Num(2.0), self.clone())),
                    Func::Abs => mul(call(Func::Sign, a.clone()), da),
                    Func::Tanh => mul(sub(Num(1.0), mul(self.clone(), self.clone())), da),
                    Func::Atan2 => {
                        // atan2(y, x): (x·dy - y·dx) / (x² + y²)
                        let (y, x) = (a, &args[1]);
                        div(
                            sub(mul(x.clone(), da), mul(y.clone(), d(x))),
                            add(mul(x.clone(), x.clone()), mul(y.clone(), y.clone())),
                        )
                    }
                    Func::Min | Func::Max => {
                        // min(a, b) = (a + b)/2 - |a - b|/2; max with +.
                        let b = &args[1];
                        let db = d(b);
                        let half_sum = mul(Num(0.5), add(da.clone(), db.clone()));
                        let half_gap = mul(
                            mul(Num(0.5), call(Func::Sign, sub(a.clone(), b.clone()))),
                            sub(da, db),
                        );
                        if *f == Func::Min {
                            sub(half_sum, half_gap)
                        } else {
                            add(half_sum, half_gap)
                        }
                    }
                    Func::Pow => power_derivative(a, &args[1], da, d(&args[1])),
                    Func::Sign => Num(0.0),
                }
            }
        }
    }
}

/// d(a^b) = b·a^(b-1)·da + a^b·ln(a)·db (the second term only where b
/// depends on the variable, so that a constant exponent needs no a > 0).
fn power_derivative(a: &Expr, b: &Expr, da: Expr, db: Expr) -> Expr {
    let power = Expr::Bin(Op::Pow, Box::new(a.clone()), Box::new(b.clone()));
    let base = mul(
        mul(b.clone(), pow(a.clone(), sub(b.clone(), Expr::Num(1.0)))),
        da,
    );
    if db == Expr::Num(0.0) {
        base
    } else {
        add(
            base,
            mul(mul(power, Expr::Call(Func::Log, vec![a.clone()])), db),
        )
    }
}

// Constructors that fold constants and drop zeros and ones, so that
// derivatives stay readable (`model check` prints them).
fn num(e: &Expr) -> Option<f64> {
    match e {
        Expr::Num(v) => Some(*v),
        _ => None,
    }
}

fn neg(a: Expr) -> Expr {
    match a {
        Expr::Num(v) => Expr::Num(-v),
        Expr::Neg(inner) => *inner,
        a => Expr::Neg(Box::new(a)),
    }
}

pub(crate) fn add(a: Expr, b: Expr) -> Expr {
    match (num(&a), num(&b)) {
        (Some(x), Some(y)) => Expr::Num(x + y),
        (Some(0.0), _) => b,
        (_, Some(0.0)) => a,
        _ => Expr::Bin(Op::Add, Box::new(a), Box::new(b)),
    }
}

fn sub(a: Expr, b: Expr) -> Expr {
    match (num(&a), num(&b)) {
        (Some(x), Some(y)) => Expr::Num(x - y),
        (Some(0.0), _) => neg(b),
        (_, Some(0.0)) => a,
        _ => Expr::Bin(Op::Sub, Box::new(a), Box::new(b)),
    }
}

pub(crate) fn mul(a: Expr, b: Expr) -> Expr {
    match (num(&a), num(&b)) {
        (Some(x), Some(y)) => Expr::Num(x * y),
        (Some(0.0), _) | (_, Some(0.0)) => Expr::Num(0.0),
        (Some(1.0), _) => b,
        (_, Some(1.0)) => a,
        (Some(-1.0), _) => neg(b),
        (_, Some(-1.0)) => neg(a),
        _ => Expr::Bin(Op::Mul, Box::new(a), Box::new(b)),
    }
}

fn div(a: Expr, b: Expr) -> Expr {
    match (num(&a), num(&b)) {
        (Some(0.0), _) => Expr::Num(0.0),
        (_, Some(1.0)) => a,
        _ => Expr::Bin(Op::Div, Box::new(a), Box::new(b)),
    }
}

fn pow(a: Expr, b: Expr) -> Expr {
    match num(&b) {
        Some(1.0) => a,
        Some(0.0) => Expr::Num(1.0),
        _ => Expr::Bin(Op::Pow, Box::new(a), Box::new(b)),
    }
}

/// Writes an expression back as text with the model's names (`model check`
/// prints the equations and their derivatives so).
pub struct Written<'a> {
    pub expr: &'a Expr,
    pub names: &'a Names,
}

impl fmt::Display for Written<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write_expr(f, self.expr, self.names, 0)
    }
}

fn write_expr(f: &mut fmt::Formatter<'_>, e: &Expr, names: &Names, outer: u8) -> fmt::Result {
    match e {
        Expr::Num(v) => {
            if *v < 0.0 {
                write!(f, "({v})")
            } else {
                write!(f, "{v}")
            }
        }
        Expr::Var(Var::State(i)) => write!(f, "{}", names.states[*i]),
        Expr::Var(Var::Param(i)) => write!(f, "{}", names.parameters[*i]),
        Expr::Var(Var::Time) => write!(f, "t"),
        Expr::Var(Var::Side(j)) => write!(f, "step({})", names.switches[*j]),
        Expr::Neg(a) => {
            // Unary minus binds like a product's operand.
            let wrap = outer > 2;
            if wrap {
                write!(f, "(")?;
            }
            write!(f, "-")?;
            write_expr(f, a, names, 3)?;
            if wrap {
                write!(f, ")")?;
            }
            Ok(())
        }
        Expr::Bin(op, a, b) => {
            let p = op.precedence();
            let wrap = p < outer;
            if wrap {
                write!(f, "(")?;
            }
            // Left-associative operators keep their left operand's level;
            // a right operand of - and / and a left operand of ^ need more.
            let (left, right) = match op {
                Op::Pow => (p + 1, p),
                _ => (p, p + 1),
            };
            write_expr(f, a, names, left)?;
            write!(f, " {} ", op.symbol())?;
            write_expr(f, b, names, right)?;
            if wrap {
                write!(f, ")")?;
            }
            Ok(())
        }
        Expr::Call(func, args) => {
            write!(f, "{}(", func.name())?;
            for (k, a) in args.iter().enumerate() {
                if k > 0 {
                    write!(f, ", ")?;
                }
                write_expr(f, a, names, 0)?;
            }
            write!(f, ")")
        }
    }
}

/// Whether `e` reads a state or the time (anything but parameters and
/// numbers).
pub(crate) fn reads_state_or_time(e: &Expr) -> bool {
    match e {
        Expr::Num(_) => false,
        Expr::Var(v) => !matches!(v, Var::Param(_)),
        Expr::Neg(a) => reads_state_or_time(a),
        Expr::Bin(_, a, b) => reads_state_or_time(a) || reads_state_or_time(b),
        Expr::Call(_, args) => args.iter().any(reads_state_or_time),
    }
}
