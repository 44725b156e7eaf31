//! Expressions compiled for the CPU: an instruction tape evaluated over a
//! batch of trajectories at once.
//!
//! Walking the expression tree per trajectory and per operation costs a
//! dispatch per node, 5-20× the arithmetic. The tape pays that dispatch
//! once per instruction for a whole batch (the trajectories of a lane, or
//! one trajectory of each of several lanes), and each instruction's loop
//! over the batch is what the compiler vectorises. Two rewrites keep the
//! tape short, both exact:
//!
//! - a subexpression of parameters alone (`-2*zeta`, `2*pi/eta`) is a *lane
//!   constant*, computed once per lane by [`Expr::eval`] with the same
//!   operations in the same order;
//! - `cos(w*t)` and `sin(w*t)`, with `w` of parameters alone, read the
//!   forcing clock (`integrate::clock`): the phase the integrator carries
//!   and rotates, restarted at t = 0 every period, so no cosine is
//!   evaluated per step and the forcing stays exact over long runs.
//!
//! A seed oscillator written as a model therefore performs, per step, the
//! very floating-point operations of the hand-written one.

use std::collections::HashMap;
use std::mem::MaybeUninit;

use crate::integrate::clock::Phase;
use crate::model::language::expr::{reads_state_or_time, Expr, Func, Op, Var};

/// Where an operand comes from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Src {
    /// The result of instruction i.
    Reg(u32),
    /// State i.
    State(u32),
    /// Lane constant i (a parameter-only subexpression).
    Lane(u32),
    Num(f64),
    /// cos(ωt) of the forcing clock.
    Cos,
    /// sin(ωt) of the forcing clock.
    Sin,
}

/// One instruction; instruction i writes register i.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Inst {
    Neg(Src),
    Bin(Op, Src, Src),
    Call(Func, Src, Src),
}

/// Why an expression cannot be compiled.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum CompileError {
    /// `t` outside `cos(w*t)`/`sin(w*t)`, or a second forcing frequency.
    Time(String),
    /// More instructions than a batch's registers hold.
    TooLong(usize),
}

impl std::fmt::Display for CompileError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            CompileError::Time(why) => write!(f, "{why}"),
            CompileError::TooLong(n) => write!(
                f,
                "compiles to {n} operations; at most {MAX_INSTRUCTIONS} are supported"
            ),
        }
    }
}

/// Instructions a tape may have.
pub const MAX_INSTRUCTIONS: usize = 256;
/// Register-file slots a batch evaluation holds on the stack: the
/// instructions' results and every operand that is not one.
const MAX_FILE: usize = 3 * MAX_INSTRUCTIONS;

/// Several expressions compiled into one tape (shared subexpressions
/// computed once), with their lane constants and forcing frequency.
#[derive(Clone, Debug, Default)]
pub struct Tape {
    pub instructions: Vec<Inst>,
    /// One operand per compiled expression, in the order compiled.
    pub outputs: Vec<Src>,
    /// The parameter-only subexpressions, evaluated once per lane.
    pub lane_constants: Vec<Expr>,
    /// ω of `cos(ω t)`/`sin(ω t)`, a parameter-only expression; `None`
    /// when no expression reads the clock.
    pub frequency: Option<Expr>,
    /// The number of states the expressions read.
    pub states: usize,
    /// The tape as [`Tape::eval`] runs it.
    lowered: Vec<Lowered>,
    numbers: Vec<f64>,
    output_slots: Vec<u16>,
}

impl Tape {
    /// Compiles `exprs` into one tape; `what(i)` names expression i in
    /// errors. Expressions compiled earlier may share subexpressions.
    pub fn compile<'a>(
        exprs: impl IntoIterator<Item = &'a Expr>,
        states: usize,
        frequency: Option<Expr>,
    ) -> Result<Tape, (usize, CompileError)> {
        Compiler::new(states, frequency, true).tape_of(exprs)
    }

    /// Compiles `exprs` for a target that reads the parameters where it
    /// runs, as the GPU's system file does (`model::codegen::wgsl`): every parameter
    /// and switch side the expressions read is a lane constant of its own
    /// (`Expr::Var`), and every operation on them, numbers' included, an
    /// instruction, in the tree's order. Hoisting them would need a second
    /// tape per function, and the GPU would still compute each one per
    /// call: read in place, the printed code computes what the tree says,
    /// the operations [`Expr::eval`] does for the CPU's lane constants, so
    /// an f64 kernel keeps the CPU's bits. Such a tape is printed
    /// (`model::codegen::print`), never run: the interpreter's register-file limits
    /// do not apply.
    pub fn compile_reading_parameters<'a>(
        exprs: impl IntoIterator<Item = &'a Expr>,
        states: usize,
    ) -> Result<Tape, (usize, CompileError)> {
        Compiler::new(states, None, false).tape_of(exprs)
    }

    /// The lane constants and clock frequency at parameter values `params`.
    pub fn lane_values(&self, params: &[f64]) -> LaneValues {
        LaneValues {
            constants: self
                .lane_constants
                .iter()
                .map(|e| e.eval(&[], params, 0.0))
                .collect(),
            frequency: self
                .frequency
                .as_ref()
                .map_or(0.0, |w| w.eval(&[], params, 0.0)),
        }
    }

    /// The outputs at W states of W trajectories, each at its own phase, in
    /// the first rows of N (the rows past them zero); `lane(j)` is lane
    /// constant j of every slot.
    #[inline(always)]
    pub fn eval<const W: usize, const D: usize, const N: usize>(
        &self,
        lane: impl Fn(usize) -> [f64; W],
        phases: &[Phase; W],
        y: &[[f64; W]; D],
    ) -> [[f64; W]; N] {
        let mut registers = Registers::new();
        self.prepare(&mut registers, lane);
        self.run(&mut registers, phases, y)
    }

    /// Puts the lane constants and numbers in place in a register file,
    /// for any number of [`run`](Self::run)s (the four stages of a step).
    #[inline(always)]
    pub fn prepare<const W: usize>(
        &self,
        registers: &mut Registers<W>,
        lane: impl Fn(usize) -> [f64; W],
    ) {
        let file = &mut registers.file;
        let constants = self.states + 2;
        for j in 0..self.lane_constants.len() {
            file[constants + j] = MaybeUninit::new(lane(j));
        }
        let numbers = constants + self.lane_constants.len();
        for (n, &v) in self.numbers.iter().enumerate() {
            file[numbers + n] = MaybeUninit::new([v; W]);
        }
    }

    /// The outputs at W states, each at its own phase, in a register file
    /// made ready by [`prepare`](Self::prepare).
    ///
    /// Every operand is a slot of one register file (states, the clock,
    /// lane constants, numbers, then the instructions' results), so an
    /// instruction is its loads, its operations and a store, with no
    /// decision on where an operand comes from; a product feeding a sum is
    /// one instruction (two roundings still, as written).
    #[inline(always)]
    pub fn run<const W: usize, const D: usize, const N: usize>(
        &self,
        registers: &mut Registers<W>,
        phases: &[Phase; W],
        y: &[[f64; W]; D],
    ) -> [[f64; W]; N] {
        debug_assert!(self.outputs.len() <= N);
        debug_assert_eq!(self.states, D);
        let file = &mut registers.file;
        for i in 0..D {
            file[i] = MaybeUninit::new(y[i]);
        }
        // Plain loops, not `array::from_fn`: its closure was left out of
        // line (and out of the AVX2 code) here, a call per element.
        let (mut cos, mut sin) = ([0.0; W], [0.0; W]);
        for k in 0..W {
            cos[k] = phases[k][0];
            sin[k] = phases[k][1];
        }
        file[D] = MaybeUninit::new(cos);
        file[D + 1] = MaybeUninit::new(sin);
        let results = D + 2 + self.lane_constants.len() + self.numbers.len();
        // SAFETY: the lowering points every operand at a slot written above
        // or by `prepare`, or at an earlier instruction's result
        // (`Tape::lower`).
        let read = |file: &[MaybeUninit<[f64; W]>], slot: u16| unsafe {
            file[slot as usize].assume_init()
        };
        for (i, ins) in self.lowered.iter().enumerate() {
            let (a, b) = (read(file, ins.a), read(file, ins.b));
            let value: [f64; W] = match ins.code {
                Code::Neg => crate::array::from_fn(|k| -a[k]),
                Code::Add => crate::array::from_fn(|k| a[k] + b[k]),
                Code::Sub => crate::array::from_fn(|k| a[k] - b[k]),
                Code::Mul => crate::array::from_fn(|k| a[k] * b[k]),
                Code::Div => crate::array::from_fn(|k| a[k] / b[k]),
                Code::MulAdd => {
                    let c = read(file, ins.c);
                    crate::array::from_fn(|k| a[k] * b[k] + c[k])
                }
                Code::MulSub => {
                    let c = read(file, ins.c);
                    crate::array::from_fn(|k| a[k] * b[k] - c[k])
                }
                Code::SubMul => {
                    let c = read(file, ins.c);
                    crate::array::from_fn(|k| c[k] - a[k] * b[k])
                }
                Code::Call(f) => crate::array::from_fn(|k| f.apply(&[a[k], b[k]])),
            };
            file[results + i] = MaybeUninit::new(value);
        }
        let mut out = [[0.0; W]; N];
        for (o, &slot) in out.iter_mut().zip(&self.output_slots) {
            *o = read(file, slot);
        }
        out
    }

    /// The tape as [`Tape::run`] runs it, for the native code (`model::native::library`): the
    /// lowered instructions, the numbers (slots after the lane constants)
    /// and the slot of each output. Slots are the states, cos and sin of
    /// the clock, the lane constants, the numbers, then one result per
    /// instruction, in that order.
    pub(crate) fn lowered(&self) -> (&[Lowered], &[f64], &[u16]) {
        (&self.lowered, &self.numbers, &self.output_slots)
    }

    /// Rewrites the instructions over register-file slots (see
    /// [`Tape::run`]), fusing each product used once, by a sum or a
    /// difference, into it. Fails when the file would need more than
    /// `limit` slots.
    fn lower(&mut self, limit: usize) -> Result<(), CompileError> {
        let d = self.states;
        let constants = d + 2;
        let mut uses = vec![0usize; self.instructions.len()];
        let mut numbers: Vec<f64> = Vec::new();
        {
            let mut note = |src: Src| match src {
                Src::Reg(r) => uses[r as usize] += 1,
                Src::Num(v) if !numbers.iter().any(|x| x.to_bits() == v.to_bits()) => {
                    numbers.push(v)
                }
                _ => {}
            };
            for inst in &self.instructions {
                match *inst {
                    Inst::Neg(a) => note(a),
                    Inst::Bin(_, a, b) | Inst::Call(_, a, b) => {
                        note(a);
                        note(b);
                    }
                }
            }
            for &o in &self.outputs {
                note(o);
            }
        }
        // A product used once, by an addition or subtraction, is fused.
        let product = |src: Src| match src {
            Src::Reg(r) if uses[r as usize] == 1 => match self.instructions[r as usize] {
                Inst::Bin(Op::Mul, x, y) => Some((r as usize, x, y)),
                _ => None,
            },
            _ => None,
        };
        let mut fused = vec![false; self.instructions.len()];
        let mut plan: Vec<(Code, Src, Src, Src)> = Vec::new();
        for inst in &self.instructions {
            plan.push(match *inst {
                Inst::Neg(a) => (Code::Neg, a, a, a),
                Inst::Bin(op @ (Op::Add | Op::Sub), a, b) => {
                    match (op, product(a), product(b)) {
                        // (x·y) + b and (x·y) - b
                        (Op::Add, Some((r, x, y)), _) => {
                            fused[r] = true;
                            (Code::MulAdd, x, y, b)
                        }
                        (Op::Sub, Some((r, x, y)), _) => {
                            fused[r] = true;
                            (Code::MulSub, x, y, b)
                        }
                        // a + (x·y) is (x·y) + a, to the bit.
                        (Op::Add, None, Some((r, x, y))) => {
                            fused[r] = true;
                            (Code::MulAdd, x, y, a)
                        }
                        (Op::Sub, None, Some((r, x, y))) => {
                            fused[r] = true;
                            (Code::SubMul, x, y, a)
                        }
                        _ => (if op == Op::Add { Code::Add } else { Code::Sub }, a, b, a),
                    }
                }
                Inst::Bin(op, a, b) => (
                    match op {
                        Op::Mul => Code::Mul,
                        Op::Div => Code::Div,
                        _ => Code::Call(Func::Pow),
                    },
                    a,
                    b,
                    a,
                ),
                Inst::Call(f, a, b) => (Code::Call(f), a, b, a),
            });
        }
        // Result slots of the instructions kept, in order.
        let results = constants + self.lane_constants.len() + numbers.len();
        let mut result_slot = vec![0usize; self.instructions.len()];
        let mut next = results;
        for (i, f) in fused.iter().enumerate() {
            result_slot[i] = next;
            if !f {
                next += 1;
            }
        }
        if next > limit {
            return Err(CompileError::TooLong(self.instructions.len()));
        }
        let slot = |src: Src| -> u16 {
            (match src {
                Src::State(i) => i as usize,
                Src::Cos => d,
                Src::Sin => d + 1,
                Src::Lane(j) => constants + j as usize,
                Src::Num(v) => {
                    constants
                        + self.lane_constants.len()
                        + numbers
                            .iter()
                            .position(|x| x.to_bits() == v.to_bits())
                            .expect("every number was noted")
                }
                Src::Reg(r) => result_slot[r as usize],
            }) as u16
        };
        self.lowered = plan
            .iter()
            .zip(&fused)
            .filter(|(_, f)| !**f)
            .map(|(&(code, a, b, c), _)| Lowered {
                code,
                a: slot(a),
                b: slot(b),
                c: slot(c),
            })
            .collect();
        self.output_slots = self.outputs.iter().map(|&o| slot(o)).collect();
        self.numbers = numbers;
        Ok(())
    }
}

/// A register file of a tape for batches of W (see [`Tape::prepare`]).
/// Made in place and never moved: it is large, and uninitialised until
/// written, so that making it costs nothing.
pub struct Registers<const W: usize> {
    file: [MaybeUninit<[f64; W]>; MAX_FILE],
}

impl<const W: usize> Registers<W> {
    #[inline(always)]
    #[allow(clippy::new_without_default)]
    pub fn new() -> Self {
        Registers {
            file: [const { MaybeUninit::uninit() }; MAX_FILE],
        }
    }
}

/// An operation of the lowered tape.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Code {
    Neg,
    Add,
    Sub,
    Mul,
    Div,
    /// a·b + c
    MulAdd,
    /// a·b - c
    MulSub,
    /// c - a·b
    SubMul,
    Call(Func),
}

/// An instruction over register-file slots (see [`Tape::run`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Lowered {
    pub(crate) code: Code,
    pub(crate) a: u16,
    pub(crate) b: u16,
    pub(crate) c: u16,
}

/// A tape's lane constants and clock frequency at one lane's parameters.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LaneValues {
    pub constants: Vec<f64>,
    pub frequency: f64,
}

struct Compiler {
    tape: Tape,
    /// Subexpressions already compiled, by their printed tree.
    seen: HashMap<String, Src>,
    /// Whether parameter-only subexpressions become lane constants (the
    /// CPU's tapes), or the parameters and sides themselves do
    /// ([`Tape::compile_reading_parameters`]).
    hoist: bool,
}

impl Compiler {
    fn new(states: usize, frequency: Option<Expr>, hoist: bool) -> Compiler {
        Compiler {
            tape: Tape {
                frequency,
                states,
                ..Tape::default()
            },
            seen: HashMap::new(),
            hoist,
        }
    }

    /// The tape of `exprs`, lowered; an error comes with the index of the
    /// expression it is in.
    fn tape_of<'a>(
        mut self,
        exprs: impl IntoIterator<Item = &'a Expr>,
    ) -> Result<Tape, (usize, CompileError)> {
        // A printed tape has no register file: only the slots' u16 bound.
        let (instructions, file) = if self.hoist {
            (MAX_INSTRUCTIONS, MAX_FILE)
        } else {
            (usize::from(u16::MAX), usize::from(u16::MAX))
        };
        for (i, e) in exprs.into_iter().enumerate() {
            let out = self.compile(e).map_err(|err| (i, err))?;
            self.tape.outputs.push(out);
            let n = self.tape.instructions.len();
            if n > instructions {
                return Err((i, CompileError::TooLong(n)));
            }
        }
        let mut tape = self.tape;
        let n = tape.instructions.len();
        tape.lower(file).map_err(|e| (n.saturating_sub(1), e))?;
        Ok(tape)
    }

    fn compile(&mut self, e: &Expr) -> Result<Src, CompileError> {
        if let Expr::Num(v) = e {
            return Ok(Src::Num(*v));
        }
        let key = format!("{e:?}");
        if let Some(src) = self.seen.get(&key) {
            return Ok(*src);
        }
        let src = self.compile_new(e)?;
        self.seen.insert(key, src);
        Ok(src)
    }

    fn compile_new(&mut self, e: &Expr) -> Result<Src, CompileError> {
        let read = !self.hoist && matches!(e, Expr::Var(Var::Param(_) | Var::Side(_)));
        if read || (self.hoist && !reads_state_or_time(e)) {
            self.tape.lane_constants.push(e.clone());
            return Ok(Src::Lane(self.tape.lane_constants.len() as u32 - 1));
        }
        let inst = match e {
            Expr::Num(_) => unreachable!("numbers are operands"),
            Expr::Var(Var::State(i)) => return Ok(Src::State(*i as u32)),
            Expr::Var(Var::Param(_)) => unreachable!("parameters are lane constants"),
            Expr::Var(Var::Time) => return Err(time_outside_clock()),
            Expr::Var(Var::Side(_)) => unreachable!(
                "each region's tape has its switches' sides substituted, and a tape that \
                 reads its parameters reads the sides too"
            ),
            Expr::Call(f @ (Func::Cos | Func::Sin), args) if args[0].uses(Var::Time) => {
                return self.clock(*f, &args[0]);
            }
            Expr::Neg(a) => Inst::Neg(self.compile(a)?),
            Expr::Bin(op, a, b) => Inst::Bin(*op, self.compile(a)?, self.compile(b)?),
            Expr::Call(f, args) => {
                let a = self.compile(&args[0])?;
                let b = match args.get(1) {
                    Some(b) => self.compile(b)?,
                    None => Src::Num(0.0),
                };
                Inst::Call(*f, a, b)
            }
        };
        self.tape.instructions.push(inst);
        Ok(Src::Reg(self.tape.instructions.len() as u32 - 1))
    }

    /// cos(w t) or sin(w t) as the clock, if `arg` is w·t (or t·w, or t)
    /// with w of parameters alone, the same w everywhere.
    fn clock(&mut self, f: Func, arg: &Expr) -> Result<Src, CompileError> {
        let w = match arg {
            Expr::Var(Var::Time) => Expr::Num(1.0),
            Expr::Bin(Op::Mul, a, b) if **b == Expr::Var(Var::Time) && !reads_state_or_time(a) => {
                (**a).clone()
            }
            Expr::Bin(Op::Mul, a, b) if **a == Expr::Var(Var::Time) && !reads_state_or_time(b) => {
                (**b).clone()
            }
            _ => return Err(time_outside_clock()),
        };
        match &self.tape.frequency {
            None => self.tape.frequency = Some(w),
            Some(known) if *known == w => {}
            Some(_) => {
                return Err(CompileError::Time(
                    "a second forcing frequency: every cos(w*t) and sin(w*t) must use the same w"
                        .into(),
                ))
            }
        }
        Ok(if f == Func::Cos { Src::Cos } else { Src::Sin })
    }
}

fn time_outside_clock() -> CompileError {
    CompileError::Time(
        "time may appear only as cos(w*t) or sin(w*t), with w a function of the parameters \
         (the forcing of a periodic map)"
            .into(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::language::expr::Names;

    fn names() -> Names {
        Names {
            states: vec!["x".into(), "v".into()],
            parameters: vec!["zeta".into(), "f".into(), "eta".into()],
            switches: Vec::new(),
        }
    }

    #[test]
    fn parameter_subexpressions_and_the_forcing_leave_the_tape() {
        let names = names();
        let e = Expr::parse("-2*zeta*v - x + f*cos(eta*t)", &names).unwrap();
        let tape = Tape::compile([&e], 2, None).unwrap();
        // (-2ζ)·v, - x, f·cos, + : four instructions; -2ζ and f are lane
        // constants; each product is fused into the sum that uses it.
        assert_eq!(tape.instructions.len(), 4, "{tape:?}");
        assert_eq!(tape.lowered.len(), 2, "{tape:?}");
        assert_eq!(tape.lane_constants.len(), 2);
        assert_eq!(tape.frequency, Some(Expr::Var(Var::Param(2))));
    }

    #[test]
    fn the_tape_computes_what_the_tree_does_to_the_bit() {
        let names = names();
        let texts = [
            "-2*zeta*v - x + f*cos(eta*t)",
            "x^3 - sqrt(abs(v)) + atan2(v, x)*min(x, v) / max(1, zeta) + tanh(x*v) - exp(-v)",
            "sin(t*eta)*x + pow(abs(x), 1.5) - log(1 + v*v) + tan(0.3*x)",
        ];
        let exprs: Vec<Expr> = texts
            .iter()
            .map(|t| Expr::parse(t, &names).unwrap())
            .collect();
        let tape = Tape::compile(&exprs, 2, None).unwrap();
        let params = [0.05, 1.2, 0.8];
        let lane = tape.lane_values(&params);
        for (x, v, t) in [(0.3, -0.7, 0.0_f64), (1.9, 0.4, 2.5), (-0.2, 3.0, 7.0)] {
            let phase = [(0.8 * t).cos(), (0.8 * t).sin()];
            let out: [[f64; 1]; 3] = tape.eval(|j| [lane.constants[j]], &[phase], &[[x], [v]]);
            for (e, o) in exprs.iter().zip(out) {
                let tree = e.eval(&[x, v], &params, t);
                assert_eq!(o[0].to_bits(), tree.to_bits(), "{e:?} at {x}, {v}, {t}");
            }
        }
    }

    #[test]
    fn a_tape_that_reads_its_parameters_computes_the_tree_to_the_bit() {
        let names = names();
        let e = Expr::parse("-2*zeta*v - x + f*cos(eta*t) + (zeta + 1)/f", &names).unwrap();
        let tape = Tape::compile_reading_parameters([&e], 2).unwrap();
        // Every lane constant is a parameter read as it is; every operation
        // on them, -2·ζ and (ζ + 1)/f among them, is an instruction.
        // (η is read by the clock alone.)
        assert_eq!(
            tape.lane_constants,
            [Expr::Var(Var::Param(0)), Expr::Var(Var::Param(1))],
            "{tape:?}"
        );
        assert_eq!(tape.frequency, Some(Expr::Var(Var::Param(2))));
        let hoisted = Tape::compile([&e], 2, None).unwrap();
        assert!(tape.instructions.len() > hoisted.instructions.len());
        let params = [0.05, 1.2, 0.8];
        let lane = tape.lane_values(&params);
        for (x, v, t) in [(0.3, -0.7, 0.0_f64), (1.9, 0.4, 2.5)] {
            let phase = [(0.8 * t).cos(), (0.8 * t).sin()];
            let out: [[f64; 1]; 1] = tape.eval(|j| [lane.constants[j]], &[phase], &[[x], [v]]);
            let tree = e.eval(&[x, v], &params, t);
            assert_eq!(out[0][0].to_bits(), tree.to_bits(), "at {x}, {v}, {t}");
        }
    }

    #[test]
    fn time_outside_a_forcing_is_refused() {
        let names = names();
        for text in [
            "x*t",
            "cos(eta*t + 1)",
            "cos(v*t)",
            "cos(eta*t) + sin(2*eta*t)",
        ] {
            let e = Expr::parse(text, &names).unwrap();
            let err = Tape::compile([&e], 2, None).unwrap_err();
            assert!(matches!(err.1, CompileError::Time(_)), "{text}");
        }
    }
}
