//! What the native code of a tape is, as the rest of the tool calls it:
//! the signatures of its functions ([`Function`]) and step loops
//! ([`Walk`]), what they compute ([`Kind`]) and how their arguments are
//! laid out ([`Layout`]), the widths built, the stops a loop detects
//! ([`StopCode`]), and the functions it calls back into Rust
//! ([`callback`]). The host's C compiler builds it ([`crate::model::native::library`]);
//! where it cannot, or `LYAPSWEEP_STEP_LOOPS=interpreter` asks, the tape's
//! interpreter ([`crate::model::ir::tape::Tape::run`], the portable reference) runs
//! the model, to the same bits.

use crate::model::language::expr::Func;

/// A compiled function: reads the `[[f64; W]; D]` states at `y`, the
/// clock at `clock`, the lane constants at `lane` and the step sizes at `h`
/// (laid out as its [`Layout`] says) and writes `[[f64; W]; N]` at `out`:
/// the tape's N outputs ([`Kind::Rhs`]) or the RK4 step ([`Kind::Step`],
/// N = D).
pub type Function = unsafe extern "C" fn(
    y: *const f64,
    clock: *const f64,
    lane: *const f64,
    h: *const f64,
    out: *mut f64,
);

/// A compiled step loop (`library::Native::walk`): takes up to `steps` RK4
/// steps of the `[[f64; W]; D]` states at `y` (in place) from the forcing
/// phase `phase[0..2]`, turned by `phase[2..4]` per half step (written
/// back where the loop stopped), with the lane constants at `lane` and the
/// step size `h[0]`; stops before the first step in which a slot whose
/// mask in `live` (W `i64`, all ones or zero) is set meets one of the
/// stops compiled in (their positions at `walls`, stop after stop).
/// Returns the steps taken.
pub type Walk = unsafe extern "C" fn(
    y: *mut f64,
    phase: *mut f64,
    lane: *const f64,
    h: *const f64,
    walls: *const f64,
    live: *const i64,
    steps: u64,
) -> u64;

/// A stop as the step loop detects it (`model::compiled::Stop`): the
/// coordinate it bounds, that coordinate's velocity, and the side (±1) the
/// coordinate is kept on, compiled into the loop's comparisons.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StopCode {
    pub coordinate: usize,
    pub velocity: usize,
    pub side: f64,
}

/// What runs a model's equations on the CPU.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Loops {
    /// Native code built by the host's C compiler for the host's vectors
    /// ([`crate::model::native::library`]), the interpreter where it fails.
    CCompiler,
    /// The tape's interpreter alone: no native code.
    Interpreter,
}

/// The widths a step loop is compiled for (`library::Native::walk`): a
/// lane's reference and copies (3 to 9 trajectories) in batches of 4 or 8,
/// the trajectories of neighbouring lanes in batches of 16
/// (`integrate::LANE_BATCH`).
pub(crate) const WALK_WIDTHS: [usize; 3] = [4, 8, 16];

/// The batch widths of the functions, those of the integrator
/// (`integrate::steps`).
pub const WIDTHS: [usize; 4] = [1, 4, 8, 16];

/// What runs the equations: the C compiler's code, unless
/// `LYAPSWEEP_STEP_LOOPS=interpreter` (the portable reference path, the
/// benchmark's baseline, and a way round a C compiler that misbehaves).
pub fn step_loops() -> Loops {
    match std::env::var("LYAPSWEEP_STEP_LOOPS").as_deref() {
        Ok("interpreter") => Loops::Interpreter,
        _ => Loops::CCompiler,
    }
}

/// What a compiled function computes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// The tape's outputs at one clock phase (`clock` holds one stage): a
    /// field's right-hand side, or the surfaces' values and rates.
    Rhs,
    /// A whole RK4 step, `rk4::step_batch` operation for operation
    /// (`clock` holds the phases of its three stages): one call per step
    /// rather than per stage.
    Step,
}

/// Where a batch's clock, lane constants and step sizes come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layout {
    /// One lane's trajectories: `clock` is a phase `[cos, sin]` per stage,
    /// `lane` the L constants and `h` one step size, the same for every
    /// slot.
    Shared,
    /// One trajectory of each of W lanes: `clock` is `[cos; W]` then
    /// `[sin; W]` per stage, `lane` is `[[f64; W]; L]` and `h` `[f64; W]`.
    Each,
}

/// [`Func::apply`] behind the C calling convention, one per function, for
/// the native code to call: the same libm calls, so the same bits.
pub(crate) fn callback(f: Func) -> extern "C" fn(f64, f64) -> f64 {
    macro_rules! by_function {
        ($($f:ident)*) => {
            match f {
                $(Func::$f => {
                    extern "C" fn apply(a: f64, b: f64) -> f64 {
                        Func::$f.apply(&[a, b])
                    }
                    apply
                })*
            }
        };
    }
    by_function!(Sin Cos Tan Exp Log Sqrt Abs Tanh Atan2 Min Max Pow Sign)
}
