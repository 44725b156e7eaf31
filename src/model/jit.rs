//! A tape compiled to native code (cranelift): the model's equations (or
//! its surfaces' values and rates) as one function per batch width, with
//! every value in a machine register.
//!
//! The interpreter ([`Tape::run`]) pays, per instruction, a dispatch, the
//! loads of its operands from the register file and the store of its
//! result; on the seed's oscillator that left the model at 0.44× the
//! (since retired) hand-written system's lane-steps per second. Here the same lowered tape becomes
//! straight-line code over SSA values: each `[f64; W]` value is W/2
//! `F64X2` vectors (or one `f64` for W = 1), the operations are the
//! tape's, one IEEE operation each in the tape's order (cranelift neither
//! fuses a multiply into an add nor reassociates), so the bits are the
//! interpreter's. The functions that are not one instruction call back
//! into `Func::apply` (the same libm calls); `sqrt`, `abs` and negation
//! are exact single instructions, the same in both.
//!
//! The interpreter stays the reference and the fallback: off x86_64, or
//! where cranelift cannot target the host, [`Native::compile`] gives
//! `None`. The step loops ([`Native::walk`]) are cranelift's only where the
//! host's C compiler does not build them for wider vectors
//! ([`super::c_loop`]), the same operations to the bit.

use super::expr::Func;
use super::tape::Tape;
#[cfg(target_arch = "x86_64")]
use super::tape::{Code, Lowered};

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

/// A compiled step loop ([`Native::walk`]): takes up to `steps` RK4 steps
/// of the `[[f64; W]; D]` states at `y` (in place) from the forcing phase
/// `phase[0..2]`, turned by `phase[2..4]` per half step (written back
/// where the loop stopped), with the lane constants at `lane` and the step
/// size `h[0]`; stops before the first step in which a slot whose mask in
/// `live` (W `i64`, all ones or zero) is set meets one of the stops
/// compiled in (their positions at `walls`, stop after stop). Returns the
/// steps taken.
pub type Walk = unsafe extern "C" fn(
    y: *mut f64,
    phase: *mut f64,
    lane: *const f64,
    h: *const f64,
    walls: *const f64,
    live: *const i64,
    steps: u64,
) -> u64;

/// A stop as the step loop detects it (`model::code::Stop`): the
/// coordinate it bounds, that coordinate's velocity, and the side (±1) the
/// coordinate is kept on, compiled into the loop's comparisons.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StopCode {
    pub coordinate: usize,
    pub velocity: usize,
    pub side: f64,
}

/// The compiler of a tape's step loops ([`Native::walk`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Loops {
    /// Cranelift, with the rest of the tape's functions: 128-bit vectors.
    Cranelift,
    /// The host's C compiler for the host's vectors ([`super::c_loop`]),
    /// cranelift where it fails.
    CCompiler,
}

/// The widths a step loop is compiled for ([`Native::walk`]): a lane's
/// reference and copies (3 to 9 trajectories) in batches of 4 or 8, the
/// trajectories of neighbouring lanes in batches of 16
/// (`integrate::LANE_BATCH`).
pub(crate) const WALK_WIDTHS: [usize; 3] = [4, 8, 16];

/// The compiler asked for the step loops: the C compiler's, unless
/// `LYAPSWEEP_STEP_LOOPS=cranelift` (the benchmark's baseline, and a way
/// round a C compiler that misbehaves; a model with general surfaces then
/// has no step loop of its own).
pub fn step_loops() -> Loops {
    match std::env::var("LYAPSWEEP_STEP_LOOPS").as_deref() {
        Ok("cranelift") => Loops::Cranelift,
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
    /// (`clock` holds the phases of its three stages). One call per step
    /// rather than per stage: the native code writes its results with
    /// 128-bit stores, and the AVX2 code that reads them back with 256-bit
    /// loads waits for each (a store-forwarding stall), so a function per
    /// stage measured no faster than the interpreter.
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

/// The batch widths compiled, those of the integrator (`integrate::steps`).
pub const WIDTHS: [usize; 4] = [1, 4, 8, 16];

/// A tape's native functions, by kind, width and layout (no
/// [`Kind::Step`] for a tape whose outputs are not a field's derivatives).
pub struct Native {
    functions: [[[Option<Function>; 2]; WIDTHS.len()]; 2],
    walks: [[Option<Walk>; 2]; WALK_WIDTHS.len()],
    stops: usize,
    states: usize,
    outputs: usize,
    constants: usize,
    /// Owns the code the functions point into; freed on drop.
    #[cfg(target_arch = "x86_64")]
    module: std::mem::ManuallyDrop<Module>,
    /// Owns the step loops' code where the C compiler built them; why
    /// not where it was asked and failed.
    #[cfg(target_arch = "x86_64")]
    c_loops: Option<Result<super::c_loop::CLoops, String>>,
}

// SAFETY: once finalised the module is never changed, only its code run
// (through `functions`, plain code pointers) until it is freed in `drop`.
unsafe impl Send for Native {}
unsafe impl Sync for Native {}

#[cfg(target_arch = "x86_64")]
impl Drop for Native {
    fn drop(&mut self) {
        // SAFETY: the functions go with `self`; nothing runs them after.
        unsafe { std::mem::ManuallyDrop::take(&mut self.module).free_memory() };
    }
}

impl std::fmt::Debug for Native {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Native {{ widths: {WIDTHS:?} }}")
    }
}

impl Native {
    /// The tape compiled for every width and layout, or `None` where no
    /// native code can be made (the interpreter then runs the tape): as
    /// [`Kind::Rhs`] always, and as [`Kind::Step`] too where it has as many
    /// outputs as states (a flow's equations).
    pub fn compile(tape: &Tape) -> Option<Native> {
        Native::compile_stepping(tape, None)
    }

    /// [`compile`](Self::compile) for a field's equations, with its step
    /// loop ([`walk`](Self::walk)) where `stops` are given: each stop's
    /// coordinate, velocity and side (±1, `model::code::Stop`), detected in
    /// the loop as the step loop of `integrate` detects them.
    ///
    /// The step loops are the host C compiler's where it builds them
    /// ([`c_loop`](super::c_loop)), cranelift's otherwise, or where
    /// `LYAPSWEEP_STEP_LOOPS=cranelift` asks for them (the benchmark's
    /// baseline, and a way round a C compiler that misbehaves).
    pub fn compile_stepping(tape: &Tape, stops: Option<&[StopCode]>) -> Option<Native> {
        Native::compile_stepping_by(tape, stops, step_loops())
    }

    /// [`compile_stepping`](Self::compile_stepping) with the step loops
    /// compiled by `loops` (cranelift's where the C compiler fails).
    pub fn compile_stepping_by(
        tape: &Tape,
        stops: Option<&[StopCode]>,
        loops: Loops,
    ) -> Option<Native> {
        #[cfg(target_arch = "x86_64")]
        {
            build(tape, stops, loops).ok()
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let _ = (tape, stops, loops);
            None
        }
    }

    /// Which compiler built the step loops ([`walk`](Self::walk)), if
    /// there are any.
    pub fn loops(&self) -> Option<Loops> {
        if self.walks.iter().flatten().all(Option::is_none) {
            return None;
        }
        #[cfg(target_arch = "x86_64")]
        if let Some(Ok(_)) = self.c_loops {
            return Some(Loops::CCompiler);
        }
        Some(Loops::Cranelift)
    }

    /// Why the C compiler did not build the step loops, where it was asked
    /// to (the loops are then cranelift's).
    pub fn c_compiler_failure(&self) -> Option<&str> {
        #[cfg(target_arch = "x86_64")]
        if let Some(Err(why)) = &self.c_loops {
            return Some(why);
        }
        None
    }

    /// Up to `steps` RK4 steps of W trajectories `y` in one loop of native
    /// code that stops before the first step in which a live slot (bit k
    /// of `live`) meets a stop: the step the step loop would hand to the
    /// impact code (`integrate::steps`'s detection, the same comparisons
    /// of the same values). Returns the steps taken, `y` and the phases in
    /// `clock` advanced by them, each step's arithmetic [`Kind::Step`]'s
    /// and `rk4::stage_phases`'s; `None` where there is no loop for W.
    ///
    /// `clock` holds cos and sin of the forcing phase (written back) and
    /// of its turn per half step, one phase for every slot: lanes stepped
    /// in lockstep share it (`clock::half_turn`), and each slot turning a
    /// copy of its own was two fifths of the loop's arithmetic. By
    /// `layout`, one value for every slot (`Shared`, a lane's
    /// trajectories) or a row of W (`Each`, trajectories of W lanes):
    /// `lane` holds the tape's constants, `h` the step size, and `walls`
    /// each stop's position.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    pub fn walk<const W: usize, const D: usize>(
        &self,
        layout: Layout,
        y: &mut [[f64; W]; D],
        clock: &mut [f64],
        lane: &[f64],
        h: &[f64],
        walls: &[f64],
        live: u32,
        steps: usize,
    ) -> Option<usize> {
        let w = WALK_WIDTHS.iter().position(|&w| w == W)?;
        let f = self.walks[w][layout as usize]?;
        let per_slot = if layout == Layout::Shared { 1 } else { W };
        assert!(
            D == self.states
                && clock.len() >= 4
                && lane.len() >= self.constants * per_slot
                && h.len() >= per_slot
                && walls.len() >= self.stops * per_slot
        );
        let live: [i64; W] = std::array::from_fn(|k| -i64::from(live >> k & 1 == 1));
        // SAFETY: the loop reads and writes D·W states in `y` and the
        // phase in `clock`, reads the tape's constants, the step sizes,
        // two rows per stop and W masks, as `layout` lays them out
        // (checked above); it was compiled for W, `layout` and this tape's
        // D states.
        let taken = unsafe {
            f(
                y.as_mut_ptr().cast(),
                clock.as_mut_ptr(),
                lane.as_ptr(),
                h.as_ptr(),
                walls.as_ptr(),
                live.as_ptr(),
                steps as u64,
            )
        };
        rewrite_as_read(y);
        Some(taken as usize)
    }

    /// Whether there is a function for batches of W.
    #[inline(always)]
    pub fn has<const W: usize>() -> bool {
        WIDTHS.contains(&W)
    }

    /// Runs the function of `kind` for W and `layout` on states `y`, with
    /// the clock (one stage for `Rhs`, three for `Step`), lane constants
    /// and step sizes laid out as `layout` says; gives the tape's outputs
    /// (the D states after the step for `Step`) in the first rows of N, the
    /// rows past them zero.
    ///
    /// # Panics
    /// If W is not a compiled width ([`has`](Self::has)), D or N are not
    /// the tape's, `Step` is asked of a tape that has none, or a slice is
    /// short.
    #[inline(always)]
    pub fn call<const W: usize, const D: usize, const N: usize>(
        &self,
        kind: Kind,
        layout: Layout,
        y: &[[f64; W]; D],
        clock: &[f64],
        lane: &[f64],
        h: &[f64],
    ) -> [[f64; W]; N] {
        let mut out = Aligned([[0.0; W]; N]);
        self.write(kind, layout, y, clock, lane, h, &mut out.0);
        read_as_written(&out)
    }

    /// [`call`](Self::call) with the outputs written into `out`, where the
    /// caller keeps them (no copy of a batch's outputs per step), and
    /// left there as the AVX2 code reads them (see `read_as_written`).
    /// Only the tape's rows are written: the rows of `out` past them keep
    /// what they held. `out` should be 32-byte aligned.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    pub fn call_into<const W: usize, const D: usize, const N: usize>(
        &self,
        kind: Kind,
        layout: Layout,
        y: &[[f64; W]; D],
        clock: &[f64],
        lane: &[f64],
        h: &[f64],
        out: &mut [[f64; W]; N],
    ) {
        self.write(kind, layout, y, clock, lane, h, out);
        rewrite_as_read(&mut out[..self.outputs]);
    }

    /// Runs the function (see [`call`](Self::call)), its outputs written
    /// into `out` by its 128-bit stores.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn write<const W: usize, const D: usize, const N: usize>(
        &self,
        kind: Kind,
        layout: Layout,
        y: &[[f64; W]; D],
        clock: &[f64],
        lane: &[f64],
        h: &[f64],
        out: &mut [[f64; W]; N],
    ) {
        let per_slot = if layout == Layout::Shared { 1 } else { W };
        let stages = if kind == Kind::Step { 3 } else { 1 };
        let w = WIDTHS
            .iter()
            .position(|&w| w == W)
            .expect("a compiled width");
        assert!(
            D == self.states
                && N >= self.outputs
                && clock.len() >= 2 * stages * per_slot
                && lane.len() >= self.constants * per_slot
                && (kind == Kind::Rhs || h.len() >= per_slot)
        );
        let f = self.functions[kind as usize][w][layout as usize]
            .expect("a step only of a tape with as many outputs as states");
        // SAFETY: the function reads D·W states, the clock of its stages,
        // L constants and a step size per slot of `layout` (checked above),
        // and writes its outputs' W values each, within `out`'s N rows
        // (checked above; D of them for a step); it was compiled for W,
        // `kind` and `layout`.
        unsafe {
            f(
                y.as_ptr().cast(),
                clock.as_ptr(),
                lane.as_ptr(),
                h.as_ptr(),
                out.as_mut_ptr().cast(),
            )
        };
    }
}

/// The native functions' results, aligned for [`read_as_written`].
#[repr(C, align(32))]
struct Aligned<T>(T);

/// The results the native code has just stored, read back at the width it
/// stored them: 128 bits (`F64X2`). Read as the 256-bit vectors the AVX2
/// step loop works in, each load waits for its two narrower stores to
/// reach the cache (a failed store forward, measured as a fifth of the
/// step loop's time); 128-bit loads forward from the stores at once, and
/// are joined in registers.
///
/// A batch of one trajectory (W = 1) is stored as scalars, which LLVM
/// read back in pairs (one 128-bit load across two stores, the same
/// stall: three fifths of a friction belt's field evaluations while it
/// slides, in `perf annotate`); each is read alone, by a volatile load
/// that LLVM may not merge.
#[inline(always)]
fn read_as_written<const W: usize, const D: usize>(out: &Aligned<[[f64; W]; D]>) -> [[f64; W]; D] {
    #[cfg(target_arch = "x86_64")]
    if W % 4 == 0 && std::is_x86_feature_detected!("avx") {
        // SAFETY: the CPU has AVX; W is a multiple of 4.
        return unsafe { joined(out) };
    }
    if W == 1 {
        let mut read = [[0.0; W]; D];
        for (row, from) in read.iter_mut().zip(&out.0) {
            // SAFETY: a reference to an f64, so valid and aligned.
            row[0] = unsafe { std::ptr::read_volatile(&from[0]) };
        }
        return read;
    }
    out.0
}

/// [`read_as_written`] with AVX: each 256-bit vector loaded as its two
/// halves, joined in a register. In assembly, because LLVM turns a join of
/// two loads into one wide load, and the store of a joined vector into
/// two narrow stores (which the next wide load would wait for in turn).
///
/// # Safety
/// The CPU has AVX, and W is a multiple of 4.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
#[inline]
unsafe fn joined<const W: usize, const D: usize>(out: &Aligned<[[f64; W]; D]>) -> [[f64; W]; D] {
    use std::arch::x86_64::__m256d;
    let mut read = Aligned([[0.0; W]; D]);
    for i in 0..D {
        for k in (0..W).step_by(4) {
            let v: __m256d;
            // SAFETY: out.0[i][k..k + 4] are four f64, read; and
            // read.0[i][k..k + 4] four f64 at a 32-byte aligned address
            // (the array is 32-aligned, W and k multiples of 4).
            unsafe {
                std::arch::asm!(
                    "vmovupd {v:x}, xmmword ptr [{p}]",
                    "vinsertf128 {v}, {v}, xmmword ptr [{p} + 16], 1",
                    p = in(reg) out.0[i][k..].as_ptr(),
                    v = out(ymm_reg) v,
                    options(pure, readonly, nostack, preserves_flags),
                );
                read.0[i][k..].as_mut_ptr().cast::<__m256d>().write(v);
            }
        }
    }
    read.0
}

/// [`read_as_written`] in place: the native code's results rewritten
/// where they lie as 256-bit vectors (each read as its two 128-bit halves),
/// so that the AVX2 loads that follow take them from the store buffer.
#[inline(always)]
fn rewrite_as_read<const W: usize>(out: &mut [[f64; W]]) {
    #[cfg(target_arch = "x86_64")]
    if W % 4 == 0 && std::is_x86_feature_detected!("avx") {
        // SAFETY: the CPU has AVX; W is a multiple of 4.
        unsafe { rejoined(out) }
    }
    let _ = out;
}

/// [`rewrite_as_read`] with AVX (in assembly, as [`joined`] is).
///
/// # Safety
/// The CPU has AVX, and W is a multiple of 4.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
#[inline]
unsafe fn rejoined<const W: usize>(out: &mut [[f64; W]]) {
    use std::arch::x86_64::__m256d;
    for row in out.iter_mut() {
        for k in (0..W).step_by(4) {
            let p = row[k..].as_mut_ptr();
            let v: __m256d;
            // SAFETY: row[k..k + 4] are four f64, read, then written as
            // one unaligned 256-bit vector.
            unsafe {
                std::arch::asm!(
                    "vmovupd {v:x}, xmmword ptr [{p}]",
                    "vinsertf128 {v}, {v}, xmmword ptr [{p} + 16], 1",
                    p = in(reg) p,
                    v = out(ymm_reg) v,
                    options(pure, readonly, nostack, preserves_flags),
                );
                p.cast::<__m256d>().write_unaligned(v);
            }
        }
    }
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

#[cfg(target_arch = "x86_64")]
use cranelift_jit::JITModule as Module;

#[cfg(target_arch = "x86_64")]
fn build<'s>(tape: &Tape, stops: Option<&'s [StopCode]>, loops: Loops) -> Result<Native, String> {
    use cranelift_codegen::settings::{self, Configurable};
    use cranelift_jit::JITBuilder;

    let mut flags = settings::builder();
    flags.set("opt_level", "speed").map_err(|e| e.to_string())?;
    // The IR verifier checks what this module generates, the same for
    // every model: in debug builds. In release it cost the start of a
    // switch model 8% (0.90 s against 0.83 s, medians of 9, the two blocks
    // on a belt: 96 functions for its four regions).
    let verify = if cfg!(debug_assertions) {
        "true"
    } else {
        "false"
    };
    flags
        .set("enable_verifier", verify)
        .map_err(|e| e.to_string())?;
    let isa = cranelift_native::builder()?
        .finish(settings::Flags::new(flags))
        .map_err(|e| e.to_string())?;
    let mut module = Module::new(JITBuilder::with_isa(
        isa,
        cranelift_module::default_libcall_names(),
    ));
    let outputs = tape.lowered().2.len();
    // A step integrates the outputs as the states' derivatives: only a
    // field's tape has one.
    let kinds: &[Kind] = if outputs == tape.states {
        &[Kind::Rhs, Kind::Step]
    } else {
        &[Kind::Rhs]
    };
    let stepping = stops.filter(|_| kinds.contains(&Kind::Step));
    // `what` for every width and layout, in the order they are read back
    // below.
    let mut define_all = |what: &dyn Fn(Layout) -> What<'s>, widths: &[usize], prefix: &str| {
        let mut ids = Vec::new();
        for &w in widths {
            for layout in [Layout::Shared, Layout::Each] {
                let name = format!("{prefix}{w}{layout:?}");
                ids.push(define(&mut module, tape, what(layout), w, &name)?);
            }
        }
        Ok::<_, String>(ids)
    };
    let mut ids = Vec::new();
    for &kind in kinds {
        let what = |layout| What::Function(kind, layout);
        ids.extend(define_all(&what, &WIDTHS, &format!("{kind:?}"))?);
    }
    // The C compiler's loops where it builds them; why not is not an error
    // (cranelift's loops are the same bits). Cranelift's are then not built
    // at all: the widest took a tenth of a 200-step sweep's half second.
    let c_loops = match (stepping, loops) {
        (Some(stops), Loops::CCompiler) => Some(super::c_loop::CLoops::build(tape, stops)),
        _ => None,
    };
    let walk_ids = match (stepping, &c_loops) {
        (Some(_), Some(Ok(_))) | (None, _) => Vec::new(),
        (Some(stops), _) => define_all(&|layout| What::Walk(stops, layout), &WALK_WIDTHS, "Walk")?,
    };
    module.finalize_definitions().map_err(|e| e.to_string())?;
    let mut walk_ids = walk_ids.into_iter();
    let mut walks = [(); WALK_WIDTHS.len()].map(|_| {
        [(); 2].map(|_| {
            let code = module.get_finalized_function(walk_ids.next()?);
            // SAFETY: the code at this address was defined with the `Walk`
            // signature in the host's default (C) calling convention.
            Some(unsafe { std::mem::transmute::<*const u8, Walk>(code) })
        })
    });
    let mut ids = ids.into_iter();
    let functions = [Kind::Rhs, Kind::Step].map(|kind| {
        [(); WIDTHS.len()].map(|_| {
            [(); 2].map(|_| {
                if !kinds.contains(&kind) {
                    return None;
                }
                let code = module.get_finalized_function(ids.next().expect("defined"));
                // SAFETY: the code at this address was defined with the
                // `Function` signature (pointer arguments, no result) in
                // the host's default (C) calling convention.
                Some(unsafe { std::mem::transmute::<*const u8, Function>(code) })
            })
        })
    });
    if let Some(Ok(c)) = &c_loops {
        walks = c.walks.map(|by_layout| by_layout.map(Some));
    }
    Ok(Native {
        functions,
        walks,
        c_loops,
        stops: stepping.map_or(0, <[_]>::len),
        states: tape.states,
        outputs,
        constants: tape.lane_constants.len(),
        module: std::mem::ManuallyDrop::new(module),
    })
}

/// What [`define`] defines.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
enum What<'a> {
    /// A [`Function`] of this kind and layout.
    Function(Kind, Layout),
    /// A step loop ([`Walk`]) detecting these stops.
    Walk(&'a [StopCode], Layout),
}

/// Defines the tape's function for batches of `w`.
#[cfg(target_arch = "x86_64")]
fn define(
    module: &mut Module,
    tape: &Tape,
    what: What,
    w: usize,
    name: &str,
) -> Result<cranelift_module::FuncId, String> {
    use cranelift_codegen::ir::immediates::Ieee64;
    use cranelift_codegen::ir::{types, AbiParam, InstBuilder, MemFlags, Value};
    use cranelift_frontend::{FunctionBuilder, FunctionBuilderContext};
    use cranelift_module::Module as _;

    let pointer = module.target_config().pointer_type();
    let mut ctx = module.make_context();
    let layout = match what {
        What::Function(_, layout) => layout,
        What::Walk(_, layout) => layout,
    };
    ctx.func.signature.params = vec![AbiParam::new(pointer); 5];
    if let What::Walk(..) = what {
        ctx.func.signature.params.push(AbiParam::new(pointer));
        ctx.func.signature.params.push(AbiParam::new(types::I64));
        ctx.func.signature.returns.push(AbiParam::new(types::I64));
    }
    let mut apply = module.make_signature();
    apply.params = vec![AbiParam::new(types::F64); 2];
    apply.returns = vec![AbiParam::new(types::F64)];

    let (lowered, numbers, outputs): (&[Lowered], &[f64], &[u16]) = tape.lowered();
    let (d, l) = (tape.states, tape.lane_constants.len());
    // Two slots per vector where the width allows.
    let per = if w % 2 == 0 { 2 } else { 1 };
    let ty = if per == 2 { types::F64X2 } else { types::F64 };
    let chunks = w / per;
    let flags = MemFlags::new().with_notrap();

    let mut fctx = FunctionBuilderContext::new();
    let mut b = FunctionBuilder::new(&mut ctx.func, &mut fctx);
    let apply = b.import_signature(apply);
    let entry = b.create_block();
    b.append_block_params_for_function_params(entry);
    b.switch_to_block(entry);
    b.seal_block(entry);
    let params = b.block_params(entry).to_vec();
    let [y, clock, lane, h, out] = <[Value; 5]>::try_from(&params[..5]).expect("5 params");

    // A row of W values at `base` + `row`·W, as `chunks` vectors.
    let load_row = |b: &mut FunctionBuilder, base: Value, row: usize| -> Vec<Value> {
        (0..chunks)
            .map(|c| {
                b.ins()
                    .load(ty, flags, base, (8 * (row * w + c * per)) as i32)
            })
            .collect()
    };
    let splat = |b: &mut FunctionBuilder, x: Value| -> Vec<Value> {
        let v = if per == 2 { b.ins().splat(ty, x) } else { x };
        vec![v; chunks]
    };
    // One value at `base` + `index`, the same in every slot.
    let load_splat = |b: &mut FunctionBuilder, base: Value, index: usize| -> Vec<Value> {
        let x = b.ins().load(types::F64, flags, base, (8 * index) as i32);
        splat(b, x)
    };
    let number = |b: &mut FunctionBuilder, v: f64| -> Vec<Value> {
        let x = b.ins().f64const(Ieee64::with_bits(v.to_bits()));
        splat(b, x)
    };
    // Clock values (cos, sin) of stage s: row 2s and 2s + 1.
    let load_clock = |b: &mut FunctionBuilder, s: usize| -> [Vec<Value>; 2] {
        std::array::from_fn(|i| match layout {
            Layout::Shared => load_splat(b, clock, 2 * s + i),
            Layout::Each => load_row(b, clock, 2 * s + i),
        })
    };

    // The register file of `Tape::run` after the clock, as SSA values:
    // lane constants and numbers, loaded once for every stage.
    let mut fixed: Vec<Vec<Value>> = Vec::with_capacity(l + numbers.len());
    for j in 0..l {
        fixed.push(match layout {
            Layout::Shared => load_splat(&mut b, lane, j),
            Layout::Each => load_row(&mut b, lane, j),
        });
    }
    for &v in numbers {
        fixed.push(number(&mut b, v));
    }
    // The tape at states `state` and clock `cos_sin`: `Tape::run`.
    let rhs = |b: &mut FunctionBuilder, state: &[Vec<Value>], cos_sin: [Vec<Value>; 2]| {
        let mut slots: Vec<Vec<Value>> = state.to_vec();
        slots.extend(cos_sin);
        slots.extend(fixed.iter().cloned());
        for ins in lowered {
            let (a, bb, c) = (
                slots[ins.a as usize].clone(),
                slots[ins.b as usize].clone(),
                slots[ins.c as usize].clone(),
            );
            let mut value = Vec::with_capacity(chunks);
            for k in 0..chunks {
                value.push(operation(
                    b, ins.code, a[k], bb[k], c[k], per, ty, apply, pointer,
                ));
            }
            slots.push(value);
        }
        outputs
            .iter()
            .map(|&slot| slots[slot as usize].clone())
            .collect::<Vec<_>>()
    };
    // The constants of a step: h, h/2, h/6 and 2.
    let step_sizes = |b: &mut FunctionBuilder| -> [Vec<Value>; 4] {
        let hs = match layout {
            Layout::Shared => load_splat(b, h, 0),
            Layout::Each => load_row(b, h, 0),
        };
        let (half, six) = (number(b, 0.5), number(b, 6.0));
        let (mut h2, mut sixth) = (Vec::new(), Vec::new());
        for k in 0..chunks {
            h2.push(b.ins().fmul(half[k], hs[k]));
            sixth.push(b.ins().fdiv(hs[k], six[k]));
        }
        [hs, h2, sixth, number(b, 2.0)]
    };
    // `rk4::step_batch`, operation for operation, from `state` with the
    // stages' clocks.
    let rk4 = |b: &mut FunctionBuilder,
               state: &[Vec<Value>],
               [hs, h2, sixth, two]: &[Vec<Value>; 4],
               [start, middle, end]: [[Vec<Value>; 2]; 3]| {
        // y + a·k
        let axpy = |b: &mut FunctionBuilder, a: &[Value], k: &[Vec<Value>]| {
            (0..d)
                .map(|i| {
                    (0..chunks)
                        .map(|c| {
                            let p = b.ins().fmul(a[c], k[i][c]);
                            b.ins().fadd(state[i][c], p)
                        })
                        .collect::<Vec<_>>()
                })
                .collect::<Vec<_>>()
        };
        let k1 = rhs(b, state, start);
        let y2 = axpy(b, h2, &k1);
        let k2 = rhs(b, &y2, middle.clone());
        let y3 = axpy(b, h2, &k2);
        let k3 = rhs(b, &y3, middle);
        let y4 = axpy(b, hs, &k3);
        let k4 = rhs(b, &y4, end);
        (0..d)
            .map(|i| {
                (0..chunks)
                    .map(|c| {
                        // y + h/6·(k1 + 2(k2 + k3) + k4)
                        let t = b.ins().fadd(k2[i][c], k3[i][c]);
                        let t = b.ins().fmul(two[c], t);
                        let t = b.ins().fadd(k1[i][c], t);
                        let t = b.ins().fadd(t, k4[i][c]);
                        let t = b.ins().fmul(sixth[c], t);
                        b.ins().fadd(state[i][c], t)
                    })
                    .collect::<Vec<_>>()
            })
            .collect::<Vec<_>>()
    };

    let state: Vec<Vec<Value>> = (0..d).map(|i| load_row(&mut b, y, i)).collect();
    let result = match what {
        What::Function(Kind::Rhs, _) => {
            let cos_sin = load_clock(&mut b, 0);
            rhs(&mut b, &state, cos_sin)
        }
        What::Function(Kind::Step, _) => {
            let sizes = step_sizes(&mut b);
            let clocks = [0, 1, 2].map(|s| load_clock(&mut b, s));
            rk4(&mut b, &state, &sizes, clocks)
        }
        What::Walk(stops, layout) => {
            // The fifth pointer is the stops', then the masks and count.
            let [live, steps] = <[Value; 2]>::try_from(&params[5..]).expect("7 params");
            walk(
                &mut b,
                Walker {
                    state,
                    y,
                    clock,
                    walls: out,
                    live,
                    steps,
                    stops,
                    layout,
                    chunks,
                    flags,
                },
                |b| step_sizes(b),
                |b, state, sizes, clocks| rk4(b, state, sizes, clocks),
            );
            b.finalize();
            return declare(module, &mut ctx, name);
        }
    };
    for (i, row) in result.iter().enumerate() {
        for (k, &v) in row.iter().enumerate() {
            b.ins().store(flags, v, out, (8 * (i * w + k * per)) as i32);
        }
    }
    b.ins().return_(&[]);
    b.finalize();
    declare(module, &mut ctx, name)
}

/// Declares and defines the function built in `ctx`.
#[cfg(target_arch = "x86_64")]
fn declare(
    module: &mut Module,
    ctx: &mut cranelift_codegen::Context,
    name: &str,
) -> Result<cranelift_module::FuncId, String> {
    use cranelift_module::{Linkage, Module as _};
    let id = module
        .declare_function(name, Linkage::Local, &ctx.func.signature)
        .map_err(|e| e.to_string())?;
    module.define_function(id, ctx).map_err(|e| e.to_string())?;
    module.clear_context(ctx);
    Ok(id)
}

/// What the step loop's code reads ([`walk`]).
#[cfg(target_arch = "x86_64")]
struct Walker<'a> {
    /// The states at the loop's start, a vector per `chunks` slots.
    state: Vec<Vec<cranelift_codegen::ir::Value>>,
    /// Pointers to the states, the (shared) phase and half-step turn, the stops'
    /// positions and sides, the slots' live masks; and the most steps to
    /// take.
    y: cranelift_codegen::ir::Value,
    clock: cranelift_codegen::ir::Value,
    walls: cranelift_codegen::ir::Value,
    live: cranelift_codegen::ir::Value,
    steps: cranelift_codegen::ir::Value,
    stops: &'a [StopCode],
    /// The layout of the lane constants, step sizes and stops.
    layout: Layout,
    chunks: usize,
    flags: cranelift_codegen::ir::MemFlags,
}

/// The step loop ([`Walk`]): a header that counts the steps, a body that
/// turns the phase (`rk4::stage_phases`), takes the RK4 step and detects
/// the stops as `integrate::steps` does, and an exit that stores the
/// states and phase where the loop stopped. The states and phase live in
/// the loop's block parameters (registers), never in memory.
///
/// Pointers: the clock holds cos, sin, and the half step's cos and sin,
/// one phase for every slot; by layout, the stops' positions are each
/// one value (`Shared`) or a row of W (`Each`), stop after stop.
/// Every slot works in `F64X2` vectors; the phase is turned in one vector
/// (the same IEEE operations in both lanes as on a scalar).
#[cfg(target_arch = "x86_64")]
fn walk<K>(
    b: &mut cranelift_frontend::FunctionBuilder,
    walker: Walker,
    step_sizes: impl Fn(
        &mut cranelift_frontend::FunctionBuilder,
    ) -> [Vec<cranelift_codegen::ir::Value>; 4],
    rk4: K,
) where
    K: Fn(
        &mut cranelift_frontend::FunctionBuilder,
        &[Vec<cranelift_codegen::ir::Value>],
        &[Vec<cranelift_codegen::ir::Value>; 4],
        [[Vec<cranelift_codegen::ir::Value>; 2]; 3],
    ) -> Vec<Vec<cranelift_codegen::ir::Value>>,
{
    use crate::integrate::impact::TURN_REACH;
    use cranelift_codegen::ir::condcodes::{FloatCC, IntCC};
    use cranelift_codegen::ir::immediates::Ieee64;
    use cranelift_codegen::ir::{types, BlockArg, InstBuilder, Value};
    type Builder<'b> = cranelift_frontend::FunctionBuilder<'b>;

    let Walker {
        state,
        y: states,
        clock,
        walls,
        live,
        steps,
        stops,
        layout,
        chunks,
        flags,
    } = walker;
    let (d, ty, w) = (state.len(), types::F64X2, 2 * chunks);
    // Row r of the slots' values at `base`: a splat of one value
    // (shared) or W values (each, a vector per chunk).
    let row = |b: &mut Builder, base: Value, r: usize| -> Vec<Value> {
        match layout {
            Layout::Shared => {
                let x = b.ins().load(types::F64, flags, base, (8 * r) as i32);
                vec![b.ins().splat(ty, x)]
            }
            Layout::Each => (0..chunks)
                .map(|c| b.ins().load(ty, flags, base, (8 * (r * w + 2 * c)) as i32))
                .collect(),
        }
    };
    // A row's vector for every chunk (a shared row's one, repeated).
    let widen = |v: &[Value]| -> Vec<Value> { (0..chunks).map(|c| v[c % v.len()]).collect() };
    let sizes = step_sizes(b);
    // The clock's values, one vector each: every chunk of slots turns
    // the same phase.
    let shared = |b: &mut Builder, r: usize| -> Value {
        let x = b.ins().load(types::F64, flags, clock, (8 * r) as i32);
        b.ins().splat(ty, x)
    };
    let (c0, s0, hc, hs) = (shared(b, 0), shared(b, 1), shared(b, 2), shared(b, 3));
    let masks: Vec<Value> = (0..chunks)
        .map(|c| b.ins().load(types::I64X2, flags, live, (16 * c) as i32))
        .collect();
    // Each stop's position and side, in every slot.
    let positions: Vec<Vec<Value>> = (0..stops.len()).map(|j| widen(&row(b, walls, j))).collect();
    let vector = |b: &mut Builder, v: f64| {
        let x = b.ins().f64const(Ieee64::with_bits(v.to_bits()));
        b.ins().splat(ty, x)
    };
    let (zero, one_half, three_halves) = (vector(b, 0.0), vector(b, 0.5), vector(b, 1.5));
    let counted = b.ins().iconst(types::I64, 0);

    // Block parameters: the states (d·chunks vectors), cos and sin (a
    // vector each), the steps taken.
    let (header, body, exit) = (b.create_block(), b.create_block(), b.create_block());
    for block in [header, exit] {
        for _ in 0..d * chunks + 2 {
            b.append_block_param(block, ty);
        }
        b.append_block_param(block, types::I64);
    }
    let args = |state: &[Vec<Value>], c: Value, s: Value, n: Value| -> Vec<BlockArg> {
        state
            .iter()
            .flatten()
            .copied()
            .chain([c, s, n])
            .map(BlockArg::Value)
            .collect()
    };
    let unpack = |at: &[Value]| -> (Vec<Vec<Value>>, Value, Value, Value) {
        let y = at[..d * chunks]
            .chunks(chunks)
            .map(<[Value]>::to_vec)
            .collect();
        let phase = &at[d * chunks..];
        (y, phase[0], phase[1], phase[2])
    };
    b.ins().jump(header, &args(&state, c0, s0, counted));

    // The header: stop after `steps` steps.
    b.switch_to_block(header);
    let (y, c, s, n) = unpack(b.block_params(header));
    let more = b.ins().icmp(IntCC::UnsignedLessThan, n, steps);
    b.ins().brif(more, body, &[], exit, &args(&y, c, s, n));

    // The body: `rk4::stage_phases`, then the step, then detection.
    b.switch_to_block(body);
    b.seal_block(body);
    // `clock::rotate`: (c, s)·(hc, hs), renormalised to first order.
    let rotate = |b: &mut Builder, c: Value, s: Value| -> (Value, Value) {
        let (p, q) = (b.ins().fmul(c, hc), b.ins().fmul(s, hs));
        let c1 = b.ins().fsub(p, q);
        let (p, q) = (b.ins().fmul(s, hc), b.ins().fmul(c, hs));
        let s1 = b.ins().fadd(p, q);
        let (cc, ss) = (b.ins().fmul(c1, c1), b.ins().fmul(s1, s1));
        let norm = b.ins().fadd(cc, ss);
        let half_norm = b.ins().fmul(one_half, norm);
        let scale = b.ins().fsub(three_halves, half_norm);
        (b.ins().fmul(c1, scale), b.ins().fmul(s1, scale))
    };
    let (mc, ms) = rotate(b, c, s);
    let (ec, es) = rotate(b, mc, ms);
    let clocks = [(c, s), (mc, ms), (ec, es)].map(|(c, s)| [vec![c; chunks], vec![s; chunks]]);
    let y1 = rk4(b, &y, &sizes, clocks);
    // As `integrate::steps`: at rest on a stop before the step, beyond it
    // after the step, or turning back inside it; in two passes, as the C
    // compiler's loop (`c_loop::walk`, which says why): the plain test,
    // then where it fires, the turns again, only those within reach of the
    // stop (`impact::may_turn_past`). The gaps and speeds side·(x - p) and
    // side·v are a negation or nothing: side is ±1, so the product is
    // exact.
    let reach = vector(b, TURN_REACH);
    let detect = |b: &mut Builder, within_reach: bool| -> Option<Value> {
        let mut hit: Option<Value> = None;
        for (stop, position) in stops.iter().zip(&positions) {
            let (ci, vi) = (stop.coordinate, stop.velocity);
            let oriented = |b: &mut Builder, v: Value| {
                if stop.side > 0.0 {
                    v
                } else {
                    b.ins().fneg(v)
                }
            };
            for k in 0..chunks {
                let at_stop = b.ins().fcmp(FloatCC::Equal, y[ci][k], position[k]);
                let still = b.ins().fcmp(FloatCC::Equal, y[vi][k], zero);
                let resting = b.ins().band(at_stop, still);
                let (x0, x1) = (
                    b.ins().fsub(y[ci][k], position[k]),
                    b.ins().fsub(y1[ci][k], position[k]),
                );
                let (g0, g1) = (oriented(b, x0), oriented(b, x1));
                let (s0, s1) = (oriented(b, y[vi][k]), oriented(b, y1[vi][k]));
                let beyond = b.ins().fcmp(FloatCC::GreaterThan, g1, zero);
                let toward = b.ins().fcmp(FloatCC::GreaterThan, s0, zero);
                let back = b.ins().fcmp(FloatCC::LessThan, s1, zero);
                let mut turning = b.ins().band(toward, back);
                if within_reach {
                    // reach·h·(s0 - s1), then whether both ends fall
                    // short by it.
                    let rise = b.ins().fmul(reach, sizes[0][k]);
                    let turn = b.ins().fsub(s0, s1);
                    let rise = b.ins().fmul(rise, turn);
                    let (r0, r1) = (b.ins().fadd(g0, rise), b.ins().fadd(g1, rise));
                    let short0 = b.ins().fcmp(FloatCC::LessThan, r0, zero);
                    let short1 = b.ins().fcmp(FloatCC::LessThan, r1, zero);
                    let short = b.ins().band(short0, short1);
                    let near = b.ins().bnot(short);
                    turning = b.ins().band(turning, near);
                }
                let any = b.ins().bor(resting, beyond);
                let any = b.ins().bor(any, turning);
                let any = b.ins().band(any, masks[k]);
                hit = Some(match hit {
                    Some(h) => b.ins().bor(h, any),
                    None => any,
                });
            }
        }
        hit
    };
    let next = b.ins().iadd_imm(n, 1);
    let stepped = args(&y1, ec, es, next);
    match detect(b, false) {
        Some(hit) => {
            let recheck = b.create_block();
            let met = b.ins().vany_true(hit);
            b.ins().brif(met, recheck, &[], header, &stepped);
            b.switch_to_block(recheck);
            b.seal_block(recheck);
            let near = detect(b, true).expect("the same stops");
            let met = b.ins().vany_true(near);
            b.ins()
                .brif(met, exit, &args(&y, c, s, n), header, &stepped);
        }
        None => {
            b.ins().jump(header, &stepped);
        }
    }
    b.seal_block(header);

    // The exit: the states and phase where the loop stopped.
    b.switch_to_block(exit);
    b.seal_block(exit);
    let (y, c, s, n) = unpack(b.block_params(exit));
    for (i, row) in y.iter().enumerate() {
        for (k, &v) in row.iter().enumerate() {
            b.ins()
                .store(flags, v, states, (8 * (i * w + 2 * k)) as i32);
        }
    }
    for (r, phase) in [c, s].into_iter().enumerate() {
        let x = b.ins().extractlane(phase, 0);
        b.ins().store(flags, x, clock, (8 * r) as i32);
    }
    b.ins().return_(&[n]);
}

/// One lowered instruction on one vector (or scalar) of each operand.
#[cfg(target_arch = "x86_64")]
#[allow(clippy::too_many_arguments)]
fn operation(
    b: &mut cranelift_frontend::FunctionBuilder,
    code: Code,
    a: cranelift_codegen::ir::Value,
    bv: cranelift_codegen::ir::Value,
    c: cranelift_codegen::ir::Value,
    per: usize,
    ty: cranelift_codegen::ir::Type,
    apply: cranelift_codegen::ir::SigRef,
    pointer: cranelift_codegen::ir::Type,
) -> cranelift_codegen::ir::Value {
    use cranelift_codegen::ir::InstBuilder;
    match code {
        Code::Neg => b.ins().fneg(a),
        Code::Add => b.ins().fadd(a, bv),
        Code::Sub => b.ins().fsub(a, bv),
        Code::Mul => b.ins().fmul(a, bv),
        Code::Div => b.ins().fdiv(a, bv),
        Code::MulAdd => {
            let p = b.ins().fmul(a, bv);
            b.ins().fadd(p, c)
        }
        Code::MulSub => {
            let p = b.ins().fmul(a, bv);
            b.ins().fsub(p, c)
        }
        Code::SubMul => {
            let p = b.ins().fmul(a, bv);
            b.ins().fsub(c, p)
        }
        // IEEE square root and sign-bit clearing: single instructions
        // with the bits of `f64::sqrt`/`f64::abs`.
        Code::Call(Func::Sqrt) => b.ins().sqrt(a),
        Code::Call(Func::Abs) => b.ins().fabs(a),
        Code::Call(f) => {
            let callee = b.ins().iconst(pointer, callback(f) as usize as i64);
            if per == 1 {
                let inst = b.ins().call_indirect(apply, callee, &[a, bv]);
                return b.inst_results(inst)[0];
            }
            let pairs: Vec<_> = (0..per as u8).collect();
            let mut results = Vec::new();
            for &lane in &pairs {
                let x = b.ins().extractlane(a, lane);
                let y = b.ins().extractlane(bv, lane);
                let inst = b.ins().call_indirect(apply, callee, &[x, y]);
                results.push(b.inst_results(inst)[0]);
            }
            let mut v = b.ins().splat(ty, results[0]);
            for (&lane, &r) in pairs.iter().zip(&results).skip(1) {
                v = b.ins().insertlane(v, r, lane);
            }
            v
        }
    }
}

#[cfg(all(test, target_arch = "x86_64"))]
mod tests {
    use super::*;
    use crate::integrate::clock::Phase;
    use crate::integrate::impact::may_turn_past;
    use crate::integrate::rk4;
    use crate::model::expr::{Expr, Names, Op};
    use crate::model::tape::Registers;

    /// Every operation and function, with operands that reach NaN, ±0 and
    /// the ties of min/max/sign.
    fn tape() -> Tape {
        Tape::compile(&expressions(), 2, None).unwrap()
    }

    /// [`tape`]'s expressions.
    fn expressions() -> Vec<Expr> {
        let names = Names {
            states: vec!["x".into(), "v".into()],
            parameters: vec!["zeta".into(), "f".into(), "eta".into()],
            switches: Vec::new(),
        };
        let texts = [
            "-2*zeta*v - x + f*cos(eta*t) + sqrt(abs(v)) - sqrt(x) + min(x, v) - max(0*x, -0*v)",
            "x^3 / v + atan2(v, x) * min(v, x) - tanh(x*v) + exp(-v) - log(x) + tan(0.3*x) \
             + pow(abs(x), 1.5) + sin(x) - cos(v) + sin(t*eta)*max(x, log(v))",
        ];
        // sign() has no name in the parser (derivatives make it): added
        // by hand, at x, v and v - v (±0).
        let sign = |text: &str| {
            let arg = Expr::parse(text, &names).unwrap();
            Box::new(Expr::Call(Func::Sign, vec![arg]))
        };
        texts
            .iter()
            .zip(["x", "v - v"])
            .map(|(t, s)| {
                let e = Box::new(Expr::parse(t, &names).unwrap());
                Expr::Bin(Op::Add, e, Box::new(Expr::Bin(Op::Mul, sign(s), sign("v"))))
            })
            .collect()
    }

    const STATES: [[f64; 8]; 2] = [
        [0.3, -0.7, 0.0, -0.0, f64::NAN, 2.5, 1e-300, -3.0],
        [-0.7, 0.4, -0.0, 0.0, 1.0, f64::NAN, 7.0, -0.0],
    ];

    fn bits<const W: usize>(a: &[[f64; W]; 2]) -> Vec<u64> {
        a.iter().flatten().map(|x| x.to_bits()).collect()
    }

    #[test]
    fn native_code_is_the_interpreter_to_the_bit() {
        let tape = tape();
        let native = Native::compile(&tape).expect("cranelift targets this host");
        let params = [[0.05, 1.2, 0.8], [0.1, -0.5, 1.3]];
        let lanes = params.map(|p| tape.lane_values(&p));
        let stages: [[Phase; 3]; 8] = std::array::from_fn(|k| {
            let t = 0.37 * k as f64;
            [0.0, 0.05, 0.1].map(|dt| [((t + dt) * 0.8).cos(), ((t + dt) * 0.8).sin()])
        });
        let h: [f64; 8] = std::array::from_fn(|k| 0.01 * (k + 1) as f64);
        // One lane, W = 1, 4 and 8.
        fn shared<const W: usize>(
            tape: &Tape,
            native: &Native,
            c: &[f64],
            st: &[Phase; 3],
            h: f64,
        ) {
            let y: [[f64; W]; 2] = std::array::from_fn(|i| std::array::from_fn(|k| STATES[i][k]));
            let mut registers = Registers::new();
            tape.prepare(&mut registers, |j| [c[j]; W]);
            let interpreted =
                rk4::step_batch(|s, y| tape.run(&mut registers, &[st[s]; W], y), &y, &[h; W]);
            let compiled = native.call(Kind::Step, Layout::Shared, &y, st.as_flattened(), c, &[h]);
            assert_eq!(bits(&interpreted), bits(&compiled), "shared, W = {W}");
            let rhs_compiled = native.call(Kind::Rhs, Layout::Shared, &y, &st[1], c, &[]);
            let rhs_interpreted: [[f64; W]; 2] = tape.run(&mut registers, &[st[1]; W], &y);
            assert_eq!(bits(&rhs_interpreted), bits(&rhs_compiled), "rhs, W = {W}");
        }
        shared::<1>(&tape, &native, &lanes[0].constants, &stages[0], h[0]);
        shared::<4>(&tape, &native, &lanes[0].constants, &stages[0], h[0]);
        shared::<8>(&tape, &native, &lanes[1].constants, &stages[3], h[3]);
        // One trajectory of each of 8 lanes, alternating parameters.
        let y = STATES;
        let constant = |j: usize, k: usize| lanes[k % 2].constants[j];
        let l = tape.lane_constants.len();
        let mut registers = Registers::new();
        tape.prepare(&mut registers, |j| std::array::from_fn(|k| constant(j, k)));
        let interpreted = rk4::step_batch(
            |s, y| tape.run(&mut registers, &std::array::from_fn(|k| stages[k][s]), y),
            &y,
            &h,
        );
        let lane: Vec<f64> = (0..l)
            .flat_map(|j| (0..8).map(move |k| constant(j, k)))
            .collect();
        let clock: Vec<f64> = (0..3)
            .flat_map(|s| (0..2).flat_map(move |i| (0..8).map(move |k| stages[k][s][i])))
            .collect();
        let compiled = native.call(Kind::Step, Layout::Each, &y, &clock, &lane, &h);
        assert_eq!(bits(&interpreted), bits(&compiled), "each, W = 8");
    }

    /// The step loop takes the steps [`Kind::Step`] takes, from the phases
    /// `rk4::stage_phases` turns, to the bit, and stops before the step in
    /// which the step loop's detection (`integrate::steps`) finds a live
    /// slot meeting the stop; a slot not live is not watched.
    #[test]
    fn the_step_loop_is_the_step_function_to_the_bit_and_stops_where_detection_does() {
        let names = Names {
            states: vec!["x".into(), "v".into()],
            parameters: vec!["zeta".into(), "f".into(), "eta".into()],
            switches: Vec::new(),
        };
        let parse = |t: &str| Expr::parse(t, &names).unwrap();
        let exprs = [parse("v"), parse("-2*zeta*v - x + f*cos(eta*t)")];
        let tape = Tape::compile(&exprs, 2, Some(parse("eta"))).unwrap();
        let stop = |side| StopCode {
            coordinate: 0,
            velocity: 1,
            side,
        };
        let native = Native::compile_stepping(&tape, Some(&[stop(1.0)]))
            .expect("cranelift targets this host");
        let (eta, steps) = (0.8, 400);
        let c = tape.lane_values(&[0.05, 1.0, eta]).constants;
        let h = std::f64::consts::TAU / eta / 200.0;
        let half = crate::integrate::clock::cos_sin(0.5 * eta * h);
        // The step loop of `integrate::steps`, one step at a time: the
        // steps taken before the first that meets the stop in a live slot.
        #[allow(clippy::too_many_arguments)]
        fn by_steps<const W: usize>(
            native: &Native,
            c: &[f64],
            (h, half): (f64, Phase),
            (wall, side): (f64, f64),
            live: u32,
            steps: usize,
            y: &mut [[f64; W]; 2],
            phase: &mut Phase,
        ) -> usize {
            for n in 0..steps {
                let stages = rk4::stage_phases(phase, &half);
                let y1: [[f64; W]; 2] = native.call(
                    Kind::Step,
                    Layout::Shared,
                    y,
                    stages.as_flattened(),
                    c,
                    &[h],
                );
                let hit = (0..W).filter(|k| live >> k & 1 == 1).any(|k| {
                    let (g0, s0) = (side * (y[0][k] - wall), side * y[1][k]);
                    let (g1, s1) = (side * (y1[0][k] - wall), side * y1[1][k]);
                    (y[0][k] == wall && y[1][k] == 0.0)
                        || g1 > 0.0
                        || (s0 > 0.0 && s1 < 0.0 && may_turn_past(g0, s0, g1, s1, h))
                });
                if hit {
                    return n;
                }
                *y = y1;
                *phase = stages[2];
            }
            steps
        }
        fn check<const W: usize>(
            native: &Native,
            c: &[f64],
            step: (f64, Phase),
            (wall, side): (f64, f64),
        ) {
            // Slots from near rest, a little apart; the last one beyond
            // the stop and not live.
            let mut y: [[f64; W]; 2] = [
                std::array::from_fn(|k| 0.01 * k as f64),
                std::array::from_fn(|k| -0.003 * k as f64),
            ];
            y[0][W - 1] = wall + 3.0 * side;
            let live = (1u32 << (W - 1)) - 1;
            let start = [0.3f64.cos(), 0.3f64.sin()];
            let (mut expected, mut phase) = (y, start);
            let stop = (wall, side);
            let taken = by_steps(native, c, step, stop, live, 400, &mut expected, &mut phase);
            let mut clock = [start[0], start[1], step.1[0], step.1[1]];
            let walls = [wall];
            let n = native
                .walk(
                    Layout::Shared,
                    &mut y,
                    &mut clock,
                    c,
                    &[step.0],
                    &walls,
                    live,
                    400,
                )
                .expect("a loop for W");
            assert_eq!(n, taken, "W = {W}, wall {wall}, side {side}");
            assert_eq!(bits(&y), bits(&expected), "W = {W}, wall {wall}");
            assert_eq!(clock[..2], phase);
            // The motion turns back about every 90 steps: those turns
            // stop the loop only within reach of the stop.
            let reached = wall.abs() < 10.0;
            assert_eq!(n < 400, reached, "W = {W}, wall {wall}: {n} steps");
        }
        // A stop reached within the steps, and one out of reach (whose
        // turns the loop walks through), from either side.
        let below = Native::compile_stepping(&tape, Some(&[stop(-1.0)]))
            .expect("cranelift targets this host");
        for wall in [0.9, 50.0] {
            check::<4>(&native, &c, (h, half), (wall, 1.0));
            check::<8>(&native, &c, (h, half), (wall, 1.0));
            check::<16>(&native, &c, (h, half), (wall, 1.0));
            check::<4>(&below, &c, (h, half), (-wall, -1.0));
            check::<8>(&below, &c, (h, half), (-wall, -1.0));
            check::<16>(&below, &c, (h, half), (-wall, -1.0));
        }
        // One trajectory of each of 8 lanes: each its own η (so its own
        // constants and step size) and wall, all with the grid's phase.
        let etas: [f64; 8] = std::array::from_fn(|k| 0.7 + 0.05 * k as f64);
        let lanes = etas.map(|eta| tape.lane_values(&[0.05, 1.0, eta]).constants);
        let hs = etas.map(|eta| std::f64::consts::TAU / eta / 200.0);
        let halves: [Phase; 8] =
            std::array::from_fn(|k| crate::integrate::clock::half_turn(etas[k], hs[k], 200));
        assert!(halves.iter().all(|h| *h == halves[0]), "one grid turn");
        let walls: [f64; 8] = std::array::from_fn(|k| 0.8 + 0.1 * k as f64);
        let l = tape.lane_constants.len();
        let lane: Vec<f64> = (0..l)
            .flat_map(|j| lanes.iter().map(move |c| c[j]))
            .collect();
        let live = 0x7f;
        let start: [[f64; 8]; 2] = [
            std::array::from_fn(|k| 0.01 * k as f64),
            std::array::from_fn(|k| if k == 7 { 9.0 } else { 0.0 }),
        ];
        let (mut expected, mut phases) = (start, [[1.0, 0.0]; 8]);
        let mut taken = steps;
        for n in 0..steps {
            let stages: [[Phase; 3]; 8] =
                std::array::from_fn(|k| rk4::stage_phases(&phases[k], &halves[k]));
            let clock: Vec<f64> = (0..3)
                .flat_map(|s| (0..2).flat_map(move |i| (0..8).map(move |k| stages[k][s][i])))
                .collect();
            let y1: [[f64; 8]; 2] =
                native.call(Kind::Step, Layout::Each, &expected, &clock, &lane, &hs);
            let y = &expected;
            let hit = (0..7).any(|k| {
                let (g0, g1) = (y[0][k] - walls[k], y1[0][k] - walls[k]);
                (y[0][k] == walls[k] && y[1][k] == 0.0)
                    || g1 > 0.0
                    || (y[1][k] > 0.0
                        && y1[1][k] < 0.0
                        && may_turn_past(g0, y[1][k], g1, y1[1][k], hs[k]))
            });
            if hit {
                taken = n;
                break;
            }
            expected = y1;
            phases = std::array::from_fn(|k| stages[k][2]);
        }
        assert!(
            taken > 0 && taken < steps,
            "a stop is met after {taken} steps"
        );
        let mut clock = [1.0, 0.0, halves[0][0], halves[0][1]];
        let bounds = walls;
        let mut y = start;
        let n = native
            .walk(
                Layout::Each,
                &mut y,
                &mut clock,
                &lane,
                &hs,
                &bounds,
                live,
                steps,
            )
            .expect("a loop for 8");
        assert_eq!(n, taken);
        assert_eq!(bits(&y), bits(&expected));
        for (k, phase) in phases.iter().enumerate() {
            assert_eq!(clock[..2], *phase, "slot {k}");
        }
        let mut y = [[0.0; 8]; 2];
        let mut phase = [1.0, 0.0];
        let n = by_steps(
            &native,
            &c,
            (h, half),
            (0.9, 1.0),
            0x7f,
            steps,
            &mut y,
            &mut phase,
        );
        assert!(n > 0 && n < steps, "the stop is met after {n} steps");
        // No loop without stops given, nor for other widths.
        let plain = Native::compile(&tape).unwrap();
        let mut clock = [1.0, 0.0, half[0], half[1]];
        let mut y = [[0.0; 4]; 2];
        assert!(plain
            .walk(Layout::Shared, &mut y, &mut clock, &c, &[h], &[], 1, 1)
            .is_none());
        let mut y = [[0.0; 1]; 2];
        assert!(native
            .walk(Layout::Shared, &mut y, &mut clock, &c, &[h], &[0.9], 1, 1)
            .is_none());
    }

    /// A tape with more outputs than states (a model's surfaces: values,
    /// then rates) compiles to its outputs alone, with no step.
    #[test]
    fn native_outputs_other_than_a_field_are_the_interpreter_to_the_bit() {
        // The two expressions of `tape`, and a padding zero (as surfaces
        // are padded).
        let mut exprs = expressions();
        exprs.push(Expr::Num(0.0));
        let tape = Tape::compile(&exprs, 2, None).unwrap();
        let native = Native::compile(&tape).expect("cranelift targets this host");
        assert!(native.functions[Kind::Step as usize]
            .iter()
            .flatten()
            .all(Option::is_none));
        fn bits<const W: usize>(a: &[[f64; W]; 3]) -> Vec<u64> {
            a.iter().flatten().map(|x| x.to_bits()).collect()
        }
        let lanes = [[0.05, 1.2, 0.8], [0.1, -0.5, 1.3]].map(|p| tape.lane_values(&p).constants);
        let phases: [Phase; 8] = std::array::from_fn(|k| {
            let t = 0.37 * k as f64;
            [t.cos(), t.sin()]
        });
        // One lane, W = 1, 4 and 8.
        fn shared<const W: usize>(tape: &Tape, native: &Native, c: &[f64], phase: &Phase) {
            let y: [[f64; W]; 2] = std::array::from_fn(|i| std::array::from_fn(|k| STATES[i][k]));
            let mut registers = Registers::new();
            tape.prepare(&mut registers, |j| [c[j]; W]);
            let interpreted: [[f64; W]; 3] = tape.run(&mut registers, &[*phase; W], &y);
            let compiled: [[f64; W]; 3] = native.call(Kind::Rhs, Layout::Shared, &y, phase, c, &[]);
            assert_eq!(bits(&interpreted), bits(&compiled), "W = {W}");
        }
        shared::<1>(&tape, &native, &lanes[0], &phases[1]);
        shared::<4>(&tape, &native, &lanes[0], &phases[2]);
        shared::<8>(&tape, &native, &lanes[1], &phases[3]);
        // One trajectory of each of 8 lanes, alternating parameters, each
        // at its own phase.
        let constant = |j: usize, k: usize| lanes[k % 2][j];
        let l = tape.lane_constants.len();
        let lane: Vec<f64> = (0..l)
            .flat_map(|j| (0..8).map(move |k| constant(j, k)))
            .collect();
        let clock: Vec<f64> = (0..2)
            .flat_map(|i| phases.iter().map(move |p| p[i]))
            .collect();
        let mut registers = Registers::new();
        tape.prepare(&mut registers, |j| std::array::from_fn(|k| constant(j, k)));
        let interpreted: [[f64; 8]; 3] = tape.run(&mut registers, &phases, &STATES);
        let compiled: [[f64; 8]; 3] =
            native.call(Kind::Rhs, Layout::Each, &STATES, &clock, &lane, &[]);
        assert_eq!(bits(&interpreted), bits(&compiled), "each, W = 8");
    }
}
