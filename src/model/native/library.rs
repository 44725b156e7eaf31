//! A tape's native code, written in C and built by the host's C compiler
//! for the host's own vectors ([`Native`]): its functions (a field's
//! right-hand side or RK4 step, a model's surfaces' values and rates; see
//! [`crate::model::native::abi`]) and a field's step loop between stops ([`Walk`]);
//! and for a model with general surfaces, the loop over its regions that
//! also detects them ([`SwitchWalk`]) and the steps of its slides.
//!
//! Loops over the slots that GCC vectorises for the host
//! (`-march=native`) ran 1.6 to 2.0 times as fast as the same operations
//! in 128-bit vectors (docs/BENCHMARKS.md, "Native code built by the
//! host's C compiler"), and C compilers target every host. Every tape
//! instruction is one IEEE operation in the tape's order, with no
//! contraction into fused multiply-adds (`-ffp-contract=off`) and no
//! reassociation (no `-ffast-math`), so the bits are the interpreter's
//! ([`Tape::run`]), which the tests check.
//!
//! Where there is no C compiler (`cc`, or `$CC`), or it fails, the tape's
//! interpreter runs the model, to the same bits. The C text is
//! `model::codegen::c`'s, the compiler and its cache of shared objects
//! `model::native::compiler`'s; this module loads what they build and calls it.

use crate::integrate::surface::Surface;
use crate::model::codegen::c::{slide_name, slides, source_of, Region};
use crate::model::ir::tape::Tape;
use crate::model::language::expr::Func;
use crate::model::native::abi::{
    callback, step_loops, Function, Kind, Layout, Loops, StopCode, Walk, WALK_WIDTHS, WIDTHS,
};
use crate::model::native::compiler::compiled;

/// A tape's native code, built by the C compiler: its functions by
/// kind, width and layout (no [`Kind::Step`] for a tape whose outputs are
/// not a field's derivatives), and where stops were given, its step loops
/// by width and layout; the library that holds them.
pub struct Native {
    functions: [[[Option<Function>; 2]; WIDTHS.len()]; 2],
    walks: [[Option<Walk>; 2]; WALK_WIDTHS.len()],
    stops: usize,
    states: usize,
    outputs: usize,
    constants: usize,
    _library: libloading::Library,
}

impl std::fmt::Debug for Native {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Native {{ widths: {WIDTHS:?} }}")
    }
}

impl Native {
    /// The tape's functions for every width and layout, or why there are
    /// none (no C compiler, it failed, or `LYAPSWEEP_STEP_LOOPS=interpreter`;
    /// the interpreter then runs the tape): as [`Kind::Rhs`] always, and as
    /// [`Kind::Step`] too where it has as many outputs as states (a flow's
    /// equations).
    pub fn compile(tape: &Tape) -> Result<Native, String> {
        Native::compile_stepping(tape, None)
    }

    /// [`compile`](Self::compile) for a field's equations, with its step
    /// loops ([`walk`](Self::walk)) where `stops` are given: each stop's
    /// coordinate, velocity and side (±1, `model::compiled::Stop`), detected in
    /// the loop as the step loop of `integrate` detects them.
    pub fn compile_stepping(tape: &Tape, stops: Option<&[StopCode]>) -> Result<Native, String> {
        if step_loops() == Loops::Interpreter {
            return Err("LYAPSWEEP_STEP_LOOPS=interpreter asks for the interpreter".into());
        }
        let outputs = tape.lowered().2.len();
        // A step integrates the outputs as the states' derivatives: only a
        // field's tape has one.
        let kinds: &[Kind] = if outputs == tape.states {
            &[Kind::Rhs, Kind::Step]
        } else {
            &[Kind::Rhs]
        };
        let stops = stops.filter(|_| kinds.contains(&Kind::Step));
        let region = [Region {
            field: tape,
            surfaces: None,
        }];
        let (source, calls) = source_of(&region, stops, &[], kinds);
        let library = loaded(compiled(&source)?, &calls)?;
        let functions = [Kind::Rhs, Kind::Step].map(|kind| {
            WIDTHS.map(|w| {
                [Layout::Shared, Layout::Each].map(|layout| {
                    let name = format!("{kind:?}{w}{layout:?}");
                    // SAFETY: the source defines `name` with the `Function`
                    // signature (C calling convention) for each kind listed;
                    // the library is kept with the functions.
                    kinds.contains(&kind).then(|| unsafe {
                        *library.get::<Function>(name.as_bytes()).expect("defined")
                    })
                })
            })
        });
        let walks = match stops {
            Some(_) => walks_of::<Walk>(&library).map(|by_layout| by_layout.map(Some)),
            None => [[None; 2]; WALK_WIDTHS.len()],
        };
        Ok(Native {
            functions,
            walks,
            stops: stops.map_or(0, <[_]>::len),
            states: tape.states,
            outputs,
            constants: tape.lane_constants.len(),
            _library: library,
        })
    }

    /// Whether the step loops ([`walk`](Self::walk)) were built.
    pub fn has_loops(&self) -> bool {
        self.walks.iter().flatten().any(Option::is_some)
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
        let live: [i64; W] = crate::array::from_fn(|k| -i64::from(live >> k & 1 == 1));
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
    /// into `out` by its stores.
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

/// The results the native code has just stored, read back as 128-bit
/// halves joined in registers: where the C compiler's code stores a batch
/// in narrower pieces than the 256-bit vectors the caller's AVX2 code
/// loads, each wide load waits for its stores to reach the cache (a failed
/// store forward, measured as a fifth of the step loop's time with
/// 128-bit stores); narrower loads forward from the stores at once.
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

/// The step loops of a model with general surfaces (events and switches)
/// built by the C compiler ([`SwitchWalk`]), by width and layout.
pub struct SwitchLoops {
    walks: [[SwitchWalk; 2]; WALK_WIDTHS.len()],
    /// How many regions, surfaces and stops the loops were built for.
    regions: usize,
    surfaces: usize,
    stops: usize,
    /// One RK4 step sliding on one switch or two (`slides`), at base
    /// region · regions + the switches' bits as a mask; each region's
    /// count of field constants.
    slides: Vec<Option<SlideStep>>,
    constants: Vec<usize>,
    states: usize,
    _library: libloading::Library,
}

/// One RK4 step of one trajectory sliding on one switch or two (see
/// `slide_step`): from `y` (D values) with the three stages' phases in
/// `clock` (6 values) and step `h`, the constants of the fields F₀, F₁
/// (and F₂) (`f0`, `f1`, `f2`) and the switches' constant gradients
/// (`g0`, `g1`, D values each; the last of each null with one switch),
/// into `out` (D values). (The pointers one by one: passed in an array
/// that Rust had just written, they cost the step a third more on the
/// friction belt, measured.)
pub type SlideStep = unsafe extern "C" fn(
    y: *const f64,
    clock: *const f64,
    h: f64,
    f0: *const f64,
    f1: *const f64,
    f2: *const f64,
    g0: *const f64,
    g1: *const f64,
    out: *mut f64,
);

impl std::fmt::Debug for SwitchLoops {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("SwitchLoops")
    }
}

/// A step loop of a model with general surfaces: [`Walk`]'s, with every
/// slot in its own region of the switches (`region`, W `i64`) and the
/// surfaces' values and rates at the states' start (`values`, rows 2j
/// and 2j + 1 of W for surface j: `surface::SurfaceBatch`'s), read and
/// written back where the loop stopped. `lanes` holds, region by region,
/// a pointer to the field's constants and one to its surfaces'. It also
/// stops before the first step in which a live slot may cross a surface
/// (`surface::may_cross`); the caller never hands it a slot that slides
/// or is held.
pub type SwitchWalk = unsafe extern "C" fn(
    y: *mut f64,
    phase: *mut f64,
    lanes: *const *const f64,
    h: *const f64,
    walls: *const f64,
    live: *const i64,
    steps: u64,
    region: *const i64,
    values: *mut f64,
) -> u64;

impl SwitchLoops {
    /// The step loops of a model whose region r has the field `fields[r].0`
    /// and the surfaces' tape (values and rates) `fields[r].1`, with
    /// `stops` and general surfaces of `kinds`; or why not.
    pub fn build(
        fields: &[(&Tape, &Tape)],
        stops: &[StopCode],
        kinds: &[Surface],
    ) -> Result<SwitchLoops, String> {
        let regions: Vec<Region> = fields
            .iter()
            .map(|&(field, surfaces)| Region {
                field,
                surfaces: Some(surfaces),
            })
            .collect();
        let (source, calls) = source_of(&regions, Some(stops), kinds, &[]);
        let library = loaded(compiled(&source)?, &calls)?;
        let walks = walks_of::<SwitchWalk>(&library);
        let regions = fields.len();
        let mut steps = vec![None; regions * regions];
        for (base, bits) in slides(regions, kinds) {
            let name = slide_name(base, &bits);
            // SAFETY: `built` defined `name` with `SlideStep`'s signature
            // (C calling convention); the library is kept with the
            // function.
            let f = unsafe { *library.get::<SlideStep>(name.as_bytes()).expect("defined") };
            steps[base * regions + bits.iter().fold(0, |m, &b| m | 1 << b)] = Some(f);
        }
        Ok(SwitchLoops {
            walks,
            regions: fields.len(),
            surfaces: kinds.len(),
            stops: stops.len(),
            slides: steps,
            constants: fields.iter().map(|f| f.0.lane_constants.len()).collect(),
            states: fields[0].0.states,
            _library: library,
        })
    }
}

impl SwitchLoops {
    /// One RK4 step (`rk4::step_at`) of a trajectory sliding on the
    /// switches of bits `bits` at once (one or two), from region `base`
    /// (their bits clear), at the stage phases `stages`: the field is the
    /// equivalent control's, `surface::equivalent_on`'s to the bit, from
    /// the constants of F₀ (region `base`) and of each F_m (`base` with
    /// bit m set) in `fields`, and each switch's constant gradient in
    /// `grads`. `None` where the library has no such step.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    pub fn slide_step<const D: usize>(
        &self,
        base: u32,
        bits: &[u32],
        stages: &[[f64; 2]; 3],
        y: &[f64; D],
        h: f64,
        fields: &[&[f64]],
        grads: &[&[f64]],
    ) -> Option<[f64; D]> {
        let base = base as usize;
        let mask = bits.iter().fold(0, |m, &b| m | 1 << b);
        let f = (*self.slides.get(base * self.regions + mask)?)?;
        let regions = std::iter::once(base).chain(bits.iter().map(|&b| base | 1 << b));
        assert!(
            D == self.states
                && fields.len() == bits.len() + 1
                && grads.len() == bits.len()
                && regions
                    .zip(fields)
                    .all(|(r, c)| c.len() >= self.constants[r])
                && grads.iter().all(|g| g.len() >= D)
        );
        let field = |m: usize| fields.get(m).map_or(std::ptr::null(), |c| c.as_ptr());
        let grad = |m: usize| grads.get(m).map_or(std::ptr::null(), |g| g.as_ptr());
        let mut out = [0.0; D];
        // SAFETY: the step reads D states, 6 clock values, the regions'
        // constants and D values of each gradient (counts and lengths
        // checked), and writes D values; it was compiled for this model's
        // D states and this set of switches.
        unsafe {
            f(
                y.as_ptr(),
                stages.as_flattened().as_ptr(),
                h,
                field(0),
                field(1),
                field(2),
                grad(0),
                grad(1),
                out.as_mut_ptr(),
            )
        };
        Some(out)
    }

    /// [`Native::walk`] for a model with general
    /// surfaces: up to `steps` steps of W trajectories, slot k in region
    /// `regions[k]` (none sliding or held), stopping before the first step
    /// in which a live slot meets a stop or may cross a surface; `values`
    /// holds the surfaces' values and rates at the states (read, and
    /// written back where the loop stopped). `lanes` gives, for each region
    /// present, its field's constants and its surfaces' (by `layout`, as
    /// `Native::walk` takes `lane`); the others are never read. `None`
    /// where there is no loop for W.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    pub fn walk<const W: usize, const D: usize>(
        &self,
        layout: Layout,
        y: &mut [[f64; W]; D],
        clock: &mut [f64],
        lanes: &[[*const f64; 2]],
        h: &[f64],
        walls: &[f64],
        live: u32,
        steps: usize,
        regions: &[u32; W],
        values: &mut [[f64; W]],
    ) -> Option<usize> {
        let w = WALK_WIDTHS.iter().position(|&w| w == W)?;
        let f = self.walks[w][layout as usize];
        let per_slot = if layout == Layout::Shared { 1 } else { W };
        assert!(
            clock.len() >= 4
                && lanes.len() == self.regions
                && regions.iter().all(|&r| (r as usize) < self.regions)
                && regions
                    .iter()
                    .all(|&r| lanes[r as usize].iter().all(|p| !p.is_null()))
                && h.len() >= per_slot
                && walls.len() >= self.stops * per_slot
                && values.len() >= 2 * self.surfaces
        );
        let live: [i64; W] = crate::array::from_fn(|k| -i64::from(live >> k & 1 == 1));
        let region: [i64; W] = regions.map(i64::from);
        // SAFETY: the loop reads and writes D·W states in `y`, the phase in
        // `clock` and 2·surfaces rows of W in `values`; reads W regions
        // (each below `self.regions`, checked), W masks, the step sizes and
        // the stops' positions as `layout` lays them out, and the
        // constants of the regions present (non-null, checked) through
        // `lanes`; it was compiled for W, `layout`, this model's D states,
        // regions, surfaces and stops.
        let taken = unsafe {
            f(
                y.as_mut_ptr().cast(),
                clock.as_mut_ptr(),
                lanes.as_ptr().cast(),
                h.as_ptr(),
                walls.as_ptr(),
                live.as_ptr(),
                steps as u64,
                region.as_ptr(),
                values.as_mut_ptr().cast(),
            )
        };
        Some(taken as usize)
    }
}

/// The library built from [`source_of`]'s source with its callbacks
/// (`calls`) set.
fn loaded(library: libloading::Library, calls: &[Func]) -> Result<libloading::Library, String> {
    let table: Vec<extern "C" fn(f64, f64) -> f64> = calls.iter().map(|&f| callback(f)).collect();
    // SAFETY: `set_calls` is defined by the source, reads `calls.len()`
    // function pointers (C calling convention, two f64 to one) from the
    // table; objects loaded twice share `calls`, and the same source sets
    // the same table.
    unsafe {
        let set = library
            .get::<unsafe extern "C" fn(*const extern "C" fn(f64, f64) -> f64)>(b"set_calls")
            .map_err(|e| e.to_string())?;
        set(table.as_ptr());
    }
    Ok(library)
}

/// The step loops of a library whose source has them, by width and
/// layout, of type `T`.
fn walks_of<T: Copy>(library: &libloading::Library) -> [[T; 2]; WALK_WIDTHS.len()] {
    WALK_WIDTHS.map(|w| {
        [Layout::Shared, Layout::Each].map(|layout| {
            let name = format!("walk{w}{layout:?}");
            // SAFETY: the source defines `name` with the signature of `T`
            // (`Walk`, or `SwitchWalk` where the regions have surfaces;
            // C calling convention), and the library stays loaded while
            // the loops' owner lives.
            unsafe {
                *library
                    .get::<T>(name.as_bytes())
                    .expect("defined by the source")
            }
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::integrate::clock::Phase;
    use crate::integrate::impact::may_turn_past;
    use crate::integrate::rk4;
    use crate::model::ir::tape::Registers;
    use crate::model::language::expr::{Expr, Names, Op};
    use crate::model::native::compiler::{compiled_in, cpu_target, digest, object_key};
    use std::path::PathBuf;

    /// A field with every kind of instruction: fused products, a division,
    /// numbers, the exact functions and a call back into Rust.
    fn tape() -> Tape {
        let names = Names {
            states: vec!["x".into(), "v".into()],
            parameters: vec!["zeta".into(), "f".into(), "eta".into()],
            switches: Vec::new(),
        };
        let parse = |t: &str| Expr::parse(t, &names).unwrap();
        let exprs = [
            parse("v"),
            parse("-2*zeta*v - x + f*cos(eta*t) - 0.1*sin(3*x) + sqrt(abs(v))/(3 + x*x)"),
        ];
        Tape::compile(&exprs, 2, Some(parse("eta"))).unwrap()
    }

    /// The step loop of `integrate::steps` on the interpreter, one step at
    /// a time: up to `steps` RK4 steps (`rk4::step_batch` of `Tape::run`,
    /// the phases `rk4::stage_phases` turns) of W trajectories with the
    /// constants, step sizes and stops' positions laid out as `layout`
    /// says, stopping before the first step in which a live slot meets the
    /// stop on `side`; what [`Native::walk`] computes, as it takes them.
    #[allow(clippy::too_many_arguments)]
    fn interpreted_walk<const W: usize>(
        tape: &Tape,
        layout: Layout,
        y: &mut [[f64; W]; 2],
        clock: &mut [f64; 4],
        lane: &[f64],
        h: &[f64],
        walls: &[f64],
        side: f64,
        live: u32,
        steps: usize,
    ) -> usize {
        let each = layout == Layout::Each;
        let slot = |k: usize| if each { k } else { 0 };
        let per_slot = if each { W } else { 1 };
        let mut registers = Registers::new();
        tape.prepare(&mut registers, |j| {
            crate::array::from_fn(|k| lane[j * per_slot + slot(k)])
        });
        let hs: [f64; W] = crate::array::from_fn(|k| h[slot(k)]);
        let half = [clock[2], clock[3]];
        let mut phase = [clock[0], clock[1]];
        let mut taken = steps;
        for n in 0..steps {
            let stages = rk4::stage_phases(&phase, &half);
            let y1 = rk4::step_batch(|s, y| tape.run(&mut registers, &[stages[s]; W], y), y, &hs);
            let hit = (0..W).filter(|k| live >> k & 1 == 1).any(|k| {
                let wall = walls[slot(k)];
                let (g0, s0) = (side * (y[0][k] - wall), side * y[1][k]);
                let (g1, s1) = (side * (y1[0][k] - wall), side * y1[1][k]);
                (y[0][k] == wall && y[1][k] == 0.0)
                    || g1 > 0.0
                    || (s0 > 0.0 && s1 < 0.0 && may_turn_past(g0, s0, g1, s1, hs[k]))
            });
            if hit {
                taken = n;
                break;
            }
            *y = y1;
            phase = stages[2];
        }
        clock[0] = phase[0];
        clock[1] = phase[1];
        taken
    }

    /// The C compiler's loop for W slots in `layout` against the
    /// interpreter's steps ([`interpreted_walk`]) from the same states,
    /// with a stop at `wall` on `side`: the steps taken, the states and the
    /// phase, to the bit, runs that stop at the wall and runs that do not.
    fn same_walks<const W: usize>(c: &Native, layout: Layout, stop: (f64, f64)) {
        let tape = tape();
        let (wall, side) = stop;
        let each = layout == Layout::Each;
        let etas: Vec<f64> = (0..W)
            .map(|k| 0.8 + if each { 0.01 * k as f64 } else { 0.0 })
            .collect();
        let per_slot = if each { W } else { 1 };
        let constants: Vec<Vec<f64>> = etas
            .iter()
            .map(|&eta| tape.lane_values(&[0.05, 2.5, eta]).constants)
            .collect();
        let lane: Vec<f64> = (0..constants[0].len())
            .flat_map(|j| constants[..per_slot].iter().map(move |c| c[j]))
            .collect();
        let h: Vec<f64> = etas[..per_slot]
            .iter()
            .map(|eta| std::f64::consts::TAU / eta / 200.0)
            .collect();
        let walls = vec![wall; per_slot];
        let half = crate::integrate::clock::cos_sin(std::f64::consts::PI / 200.0);
        let start: [[f64; W]; 2] = [
            crate::array::from_fn(|k| 0.05 * k as f64 - 0.1),
            crate::array::from_fn(|k| 0.02 * k as f64),
        ];
        let bits = |y: &[[f64; W]; 2], clock: &[f64; 4]| {
            let mut b: Vec<u64> = y.as_flattened().iter().map(|v| v.to_bits()).collect();
            b.extend(clock.iter().map(|v| v.to_bits()));
            b
        };
        type Walker<'a, const W: usize> =
            dyn Fn(&mut [[f64; W]; 2], &mut [f64; 4], u32, usize) -> usize + 'a;
        let mut stopped = 0;
        for (live, steps) in [(0u32, 3000), ((1 << W) - 1, 3000), (0b10, 3000)] {
            let run = |walk: &Walker<W>| {
                let (mut y, mut clock) = (start, [0.3f64.cos(), 0.3f64.sin(), half[0], half[1]]);
                let mut taken = Vec::new();
                // Walk on from each stop, one step at a time past it.
                let mut left = steps;
                while left > 0 {
                    let n = walk(&mut y, &mut clock, live, left);
                    taken.push(n);
                    left -= n;
                    if left > 0 {
                        left -= walk(&mut y, &mut clock, 0, 1);
                    }
                }
                (taken, bits(&y, &clock))
            };
            let (c_taken, c_bits) = run(&|y, clock, live, steps| {
                c.walk(layout, y, clock, &lane, &h, &walls, live, steps)
                    .expect("a loop for W")
            });
            let (taken, expected) = run(&|y, clock, live, steps| {
                interpreted_walk(
                    &tape, layout, y, clock, &lane, &h, &walls, side, live, steps,
                )
            });
            let context = format!("W = {W}, {layout:?}, side {side}, live {live:b}");
            assert_eq!(c_taken, taken, "{context}");
            assert_eq!(c_bits, expected, "{context}");
            stopped += c_taken.len() - 1;
        }
        assert!(stopped > 10, "the stop was met {stopped} times");
    }

    #[test]
    #[cfg(unix)]
    fn the_c_compiler_s_step_loops_are_the_interpreter_s_steps_to_the_bit() {
        let tape = tape();
        // Stops met early and often, and one (at 4) far above the first
        // turns of the oscillation, which grows past it later.
        for (wall, side) in [(0.9, 1.0), (-0.7, -1.0), (4.0, 1.0)] {
            let stops = [StopCode {
                coordinate: 0,
                velocity: 1,
                side,
            }];
            // Not a skip where there is no C compiler: the test then fails
            // and says why.
            let c = Native::compile_stepping(&tape, Some(&stops)).unwrap();
            assert!(c.has_loops());
            for layout in [Layout::Shared, Layout::Each] {
                same_walks::<4>(&c, layout, (wall, side));
                same_walks::<8>(&c, layout, (wall, side));
                same_walks::<16>(&c, layout, (wall, side));
            }
        }
    }

    /// The objects are kept by processor: two identities, two objects; and
    /// an object cut short or overwritten in the cache is built again,
    /// not loaded, and runs as before, to the bit.
    #[test]
    #[cfg(unix)]
    fn objects_are_kept_by_processor_and_a_damaged_one_is_built_again() {
        let dir = tempfile::tempdir().unwrap();
        let tape = tape();
        let stops = [StopCode {
            coordinate: 0,
            velocity: 1,
            side: 1.0,
        }];
        let regions = [Region {
            field: &tape,
            surfaces: None,
        }];
        let (source, calls) = source_of(&regions, Some(&stops), &[], &[]);
        let cc = std::env::var("CC").unwrap_or_else(|_| "cc".into());
        let objects = || -> Vec<PathBuf> {
            let mut found: Vec<PathBuf> = std::fs::read_dir(dir.path())
                .unwrap()
                .map(|e| e.unwrap().path())
                .filter(|p| p.extension().is_some_and(|e| e == "so"))
                .collect();
            found.sort();
            found
        };
        // 300 steps of the loop for 8 slots (shared layout), the library
        // then dropped (unmapped) before its file is touched.
        let run = |library: libloading::Library| -> Vec<u64> {
            let library = loaded(library, &calls).unwrap();
            let walks = walks_of::<Walk>(&library);
            let constants = tape.lane_values(&[0.05, 2.5, 0.8]).constants;
            let h = [std::f64::consts::TAU / 0.8 / 200.0];
            let half = crate::integrate::clock::cos_sin(std::f64::consts::PI / 200.0);
            let mut y: [[f64; 8]; 2] = [crate::array::from_fn(|k| 0.05 * k as f64), [0.0; 8]];
            let mut clock = [1.0, 0.0, half[0], half[1]];
            let live = [0i64; 8];
            // SAFETY: the loop for 8 slots, shared layout, of this tape's
            // two states and one stop, reads and writes what it was
            // compiled for.
            let n = unsafe {
                walks[1][Layout::Shared as usize](
                    y.as_mut_ptr().cast(),
                    clock.as_mut_ptr(),
                    constants.as_ptr(),
                    h.as_ptr(),
                    [0.9].as_ptr(),
                    live.as_ptr(),
                    300,
                )
            };
            drop(library);
            let mut bits: Vec<u64> = y.as_flattened().iter().map(|v| v.to_bits()).collect();
            bits.extend(clock.iter().map(|v| v.to_bits()));
            bits.push(n);
            bits
        };
        let a = run(compiled_in(dir.path(), &cc, "processor a", &source).unwrap());
        assert_eq!(objects().len(), 1);
        let b = run(compiled_in(dir.path(), &cc, "processor b", &source).unwrap());
        assert_eq!(objects().len(), 2, "one object per processor");
        assert_eq!(a, b);
        let object = dir
            .path()
            .join(format!("{}.so", object_key(&cc, "processor a", &source)));
        let good = std::fs::read(&object).unwrap();
        let cut: Vec<u8> = good[..good.len() / 2].to_vec();
        let garbage: Vec<u8> = (0..good.len()).map(|i| (i * 7 + 3) as u8).collect();
        for damaged in [cut, garbage, Vec::new()] {
            std::fs::write(&object, &damaged).unwrap();
            let library = compiled_in(dir.path(), &cc, "processor a", &source).unwrap();
            let rebuilt = std::fs::read(&object).unwrap();
            assert_ne!(rebuilt, damaged, "the damaged object was replaced");
            assert_eq!(rebuilt.len(), good.len());
            assert_eq!(run(library), a);
        }
        // Garbage written with its own digest (a cache copied in whole, a
        // disk's error under both files): intact by the digest, it fails
        // to load, and is removed and built again once. (Not an object cut
        // short with a digest to match: the loader maps its segments past
        // the end of the file and the process dies of SIGBUS, which no
        // check after the fact catches; the digest, written after the
        // object, is what keeps a cut object from being loaded.)
        let sum = object.with_extension("sha256");
        let noise: Vec<u8> = (0..good.len()).map(|i| (i * 131 % 251) as u8).collect();
        for garbage in [vec![0x5a; 4096], noise] {
            std::fs::write(&object, &garbage).unwrap();
            std::fs::write(&sum, digest(&garbage)).unwrap();
            let library = compiled_in(dir.path(), &cc, "processor a", &source)
                .expect("the garbage is built again");
            // Rebuilt (its bytes name the build's own source file: the
            // same length as before, not the same bytes).
            let rebuilt = std::fs::read(&object).unwrap();
            assert!(rebuilt != garbage && rebuilt.len() == good.len());
            assert_eq!(std::fs::read_to_string(&sum).unwrap(), digest(&rebuilt));
            assert_eq!(run(library), a);
        }
        assert_eq!(objects().len(), 2);
        // And the processor resolved for this machine names one.
        let target = cpu_target(&cc);
        assert!(!target.is_empty() && !target.contains("native"), "{target}");
    }

    /// Two switches (four regions), a stop and an event on a surface that
    /// moves with the clock.
    const SWITCHING: &str = r#"
name = "switching"
states = ["x", "v"]
[parameters]
zeta = 0.05
f = 2.5
eta = 0.8
ks = 4.0
mu = 0.1
[[switches]]
name = "contact"
surface = "x - 0.5"
[[switches]]
name = "moving"
surface = "v - 0.3"
[equations]
x = "v"
v = "-2*zeta*v - x - ks*(x - 0.5)*step(contact) - mu*sign(moving) + f*cos(eta*t)"
[map]
period = "2*pi/eta"
[[events]]
name = "stop"
surface = "x - 1.5"
reset = { v = "-0.8*v" }
[[events]]
name = "floor"
surface = "-1.2 - x + 0.1*cos(eta*t)"
reset = { v = "-0.9*v" }
"#;

    /// What the regions' loop and its reference share: each slot's
    /// parameters (η apart), each region's constants per slot, the step
    /// sizes, the stops' positions and the grid's half turn.
    struct Switching<'a> {
        code: &'a crate::model::compiled::Code,
        each: bool,
        field_constants: Vec<Vec<Vec<f64>>>,
        surface_constants: Vec<Vec<Vec<f64>>>,
        h: Vec<f64>,
        walls: Vec<crate::integrate::wall::Wall>,
        half: Phase,
    }

    impl<'a> Switching<'a> {
        fn new(code: &'a crate::model::compiled::Code, layout: Layout, w: usize) -> Self {
            let each = layout == Layout::Each;
            let per_slot = if each { w } else { 1 };
            let params: Vec<Vec<f64>> = (0..per_slot)
                .map(|k| {
                    let mut p = code.model.defaults.clone();
                    p[2] = 0.8 + 0.01 * k as f64;
                    p
                })
                .collect();
            let constants = |surfaces: bool| -> Vec<Vec<Vec<f64>>> {
                let tape = |r: usize| {
                    let field = &code.regions[r];
                    if surfaces {
                        &field.surfaces
                    } else {
                        &field.equations
                    }
                };
                (0..code.regions.len())
                    .map(|r| {
                        let tape = tape(r);
                        params
                            .iter()
                            .map(|p| tape.lane_values(p).constants)
                            .collect()
                    })
                    .collect()
            };
            Switching {
                code,
                each,
                field_constants: constants(false),
                surface_constants: constants(true),
                h: params
                    .iter()
                    .map(|p| std::f64::consts::TAU / p[2] / 200.0)
                    .collect(),
                walls: crate::model::compiled::walls_at(code, &params[0]),
                half: crate::integrate::clock::cos_sin(std::f64::consts::PI / 200.0),
            }
        }

        /// Slot k's row of the per-slot values.
        fn slot(&self, k: usize) -> usize {
            if self.each {
                k
            } else {
                0
            }
        }

        /// Region r's constants laid out for the loop (row j: constant j
        /// of every slot), the field's then the surfaces'.
        fn laid_out(&self, r: usize) -> [Vec<f64>; 2] {
            let lay = |c: &[Vec<f64>]| -> Vec<f64> {
                (0..c[0].len())
                    .flat_map(|j| c.iter().map(move |slot| slot[j]))
                    .collect()
            };
            [
                lay(&self.field_constants[r]),
                lay(&self.surface_constants[r]),
            ]
        }

        /// The surfaces' values and rates of region r at a state, slot k.
        fn values_at(&self, r: usize, k: usize, phase: &[f64; 2], y: &[f64; 2]) -> [f64; 8] {
            let field = &self.code.regions[r];
            let y: [[f64; 1]; 2] = [[y[0]], [y[1]]];
            let values: [[f64; 1]; 8] = field.surfaces_native.as_ref().unwrap().call(
                Kind::Rhs,
                Layout::Shared,
                &y,
                phase,
                &self.surface_constants[r][self.slot(k)],
                &[],
            );
            values.map(|v| v[0])
        }

        /// One slot's step in region r alone: its end, the surfaces'
        /// values there, and the end's phase.
        fn step(
            &self,
            r: usize,
            k: usize,
            phase: &Phase,
            y: &[f64; 2],
        ) -> ([f64; 2], [f64; 8], Phase) {
            let stages = rk4::stage_phases(phase, &self.half);
            let y: [[f64; 1]; 2] = [[y[0]], [y[1]]];
            let z: [[f64; 1]; 2] = self.code.regions[r].native.as_ref().unwrap().call(
                Kind::Step,
                Layout::Shared,
                &y,
                stages.as_flattened(),
                &self.field_constants[r][self.slot(k)],
                &[self.h[self.slot(k)]],
            );
            let z = [z[0][0], z[1][0]];
            (z, self.values_at(r, k, &stages[2], &z), stages[2])
        }

        /// Whether slot k's step from `y0` (surfaces' values `before`) to
        /// `z` (values `after`) meets something, by the integrator's
        /// detection: at rest on or reaching a stop
        /// (`impact::reaches_wall`), crossing a surface
        /// (`surface::may_cross`).
        fn meets(
            &self,
            region: u32,
            k: usize,
            y0: &[f64; 2],
            z: &[f64; 2],
            before: [f64; 8],
            after: [f64; 8],
        ) -> bool {
            use crate::integrate::{impact, surface};
            let h = self.h[self.slot(k)];
            impact::resting_on(&self.walls, y0).is_some()
                || self.walls.iter().any(|w| impact::reaches_wall(w, y0, h, z))
                || self.code.kinds.iter().enumerate().any(|(j, &kind)| {
                    surface::may_cross(
                        kind,
                        region,
                        (before[2 * j], before[2 * j + 1]),
                        (after[2 * j], after[2 * j + 1]),
                        h,
                    )
                })
        }
    }

    /// The states, phase and surfaces' values of W slots.
    type Slots<const W: usize> = ([[f64; W]; 2], Phase, [[f64; W]; 8]);

    /// The reference walk: every slot stepped alone in its region, up to
    /// the step where a live slot meets something or `most` steps; the
    /// steps taken, `at` left before that step.
    fn reference_walk<const W: usize>(
        fixture: &Switching,
        region: &[u32; W],
        live: u32,
        most: usize,
        at: &mut Slots<W>,
    ) -> usize {
        let column = |v: &[[f64; W]; 8], k: usize| -> [f64; 8] { std::array::from_fn(|m| v[m][k]) };
        for steps in 0..most {
            let (y, phase, values) = &*at;
            let mut next: Slots<W> = (*y, *phase, *values);
            let mut meets = false;
            for k in 0..W {
                let r = region[k] as usize;
                let y0 = [y[0][k], y[1][k]];
                let (z, after, end) = fixture.step(r, k, phase, &y0);
                next.1 = end;
                next.0[0][k] = z[0];
                next.0[1][k] = z[1];
                for (row, a) in next.2.iter_mut().zip(after) {
                    row[k] = a;
                }
                let hit = fixture.meets(region[k], k, &y0, &z, column(values, k), after);
                meets |= hit && live >> k & 1 == 1;
            }
            if meets {
                return steps;
            }
            *at = next;
        }
        most
    }

    /// The regions' loop for W slots in `layout`, slot k in its own
    /// region, against each slot stepped alone by its region's native
    /// step (`ModelFlow::step_each_in`'s) with its surfaces' values at
    /// each step's end and the integrator's detection
    /// ([`Switching::meets`]): the steps taken, the states, the phase and
    /// the surfaces' values where it stopped, to the bit; walked on from
    /// each stop one plain step at a time, as the integrator does.
    fn same_as_stepped<const W: usize>(code: &crate::model::compiled::Code, layout: Layout) {
        let loops = code
            .switch_loops
            .as_ref()
            .expect("a period map with surfaces")
            .as_ref()
            .expect("built by the C compiler");
        let fixture = Switching::new(code, layout, W);
        let laid: Vec<[Vec<f64>; 2]> = (0..code.regions.len())
            .map(|r| fixture.laid_out(r))
            .collect();
        let lanes: Vec<[*const f64; 2]> =
            laid.iter().map(|[a, b]| [a.as_ptr(), b.as_ptr()]).collect();
        let per_slot = fixture.h.len();
        let positions: Vec<f64> = fixture
            .walls
            .iter()
            .flat_map(|w| std::iter::repeat_n(w.position, per_slot))
            .collect();
        let half = fixture.half;
        let bits = |(y, p, v): &Slots<W>| -> Vec<u64> {
            let mut b: Vec<u64> = y.as_flattened().iter().map(|v| v.to_bits()).collect();
            b.extend(p.iter().map(|v| v.to_bits()));
            b.extend(
                v[..2 * code.kinds.len()]
                    .as_flattened()
                    .iter()
                    .map(|v| v.to_bits()),
            );
            b
        };
        let mut stopped = 0;
        for region_of in [
            |_: usize| 0u32,
            |k: usize| (k % 4) as u32,
            |k: usize| 3 - (k % 3) as u32,
        ] {
            let region: [u32; W] = crate::array::from_fn(region_of);
            for live in [(1u32 << W) - 1, 0b1010] {
                let y: [[f64; W]; 2] = [
                    crate::array::from_fn(|k| 0.05 * k as f64 - 0.3),
                    crate::array::from_fn(|k| 0.02 * k as f64 - 0.1),
                ];
                let phase0 = [0.3f64.cos(), 0.3f64.sin()];
                let mut values = [[0.0; W]; 8];
                for k in 0..W {
                    let v = fixture.values_at(region[k] as usize, k, &phase0, &[y[0][k], y[1][k]]);
                    for m in 0..8 {
                        values[m][k] = v[m];
                    }
                }
                // The walk, from every stop on by one plain step, and the
                // reference, slot by slot.
                let mut walked: Slots<W> = (y, phase0, values);
                let mut reference = walked;
                for _ in 0..6 {
                    let (y, phase, values) = &mut walked;
                    let mut clock = [phase[0], phase[1], half[0], half[1]];
                    let taken = loops
                        .walk(
                            layout, y, &mut clock, &lanes, &fixture.h, &positions, live, 400,
                            &region, values,
                        )
                        .expect("a loop for W");
                    *phase = [clock[0], clock[1]];
                    let steps = reference_walk(&fixture, &region, live, 400, &mut reference);
                    let context = format!("W = {W}, {layout:?}, regions {region:?}, live {live:b}");
                    assert_eq!(taken, steps, "{context}");
                    assert_eq!(bits(&walked), bits(&reference), "{context}");
                    if taken == 400 {
                        break;
                    }
                    stopped += 1;
                    // One plain step past the stop, on both.
                    let (y, phase, values) = &mut walked;
                    let mut end = *phase;
                    for k in 0..W {
                        let r = region[k] as usize;
                        let (z, after, e) = fixture.step(r, k, phase, &[y[0][k], y[1][k]]);
                        y[0][k] = z[0];
                        y[1][k] = z[1];
                        for m in 0..8 {
                            values[m][k] = after[m];
                        }
                        end = e;
                    }
                    *phase = end;
                    reference = walked;
                }
            }
        }
        assert!(stopped > 10, "the loop stopped {stopped} times");
    }

    #[test]
    #[cfg(all(unix, target_arch = "x86_64"))]
    fn the_regions_step_loop_is_each_region_s_step_to_the_bit() {
        let table: toml::Value = toml::from_str(SWITCHING).unwrap();
        let model = crate::model::Model::parse(&table, "model").unwrap();
        let code = crate::model::compiled::Code::compile(model, "model").unwrap();
        assert_eq!(code.regions.len(), 4);
        assert_eq!(code.walls.len(), 1);
        assert_eq!(code.kinds.len(), 3);
        for layout in [Layout::Shared, Layout::Each] {
            same_as_stepped::<4>(&code, layout);
            same_as_stepped::<8>(&code, layout);
            same_as_stepped::<16>(&code, layout);
        }
    }

    /// The regions' native fields with the switches' constant gradients:
    /// what `surface::Sliding` reads of `ModelFlow`.
    struct Fields<'a> {
        code: &'a crate::model::compiled::Code,
        constants: Vec<Vec<f64>>,
        gradients: Vec<Vec<f64>>,
    }

    impl<const D: usize> crate::integrate::Flow<D> for Fields<'_> {
        fn rhs(&self, phase: &[f64; 2], y: &[f64; D]) -> [f64; D] {
            self.rhs_in(0, phase, y)
        }

        fn rhs_in(&self, region: u32, phase: &[f64; 2], y: &[f64; D]) -> [f64; D] {
            let native = self.code.regions[region as usize].native.as_ref().unwrap();
            let c = &self.constants[region as usize];
            let y: [[f64; 1]; D] = crate::array::from_fn(|i| [y[i]]);
            let out: [[f64; 1]; D] = native.call(Kind::Rhs, Layout::Shared, &y, phase, c, &[]);
            crate::array::from_fn(|i| out[i][0])
        }

        fn surfaces(&self) -> &[Surface] {
            &self.code.kinds
        }

        fn surface_gradient(&self, j: usize, _phase: &[f64; 2], _y: &[f64; D]) -> [f64; D] {
            crate::array::from_fn(|i| self.gradients[j][i])
        }
    }

    /// The C compiler's steps of every slide on one switch or two of
    /// `code` (`slide_step`) against `rk4::step_at` of `surface::Sliding`
    /// (the equivalent control of `equivalent_on`) on the regions' native
    /// fields, over states on and off the surfaces, forcing phases and
    /// step sizes, to the bit. Gives the steps compared: finite, and NaN
    /// (the control singular) in both.
    fn same_slides<const D: usize>(code: &crate::model::compiled::Code) -> (usize, usize) {
        use crate::integrate::clock::cos_sin;
        use crate::integrate::{rk4, surface};
        let loops = code.switch_loops.as_ref().unwrap().as_ref().unwrap();
        let params = &code.model.defaults;
        let flow = Fields {
            code,
            constants: (code.regions.iter())
                .map(|f| f.equations.lane_values(params).constants)
                .collect(),
            gradients: (code.surfaces.iter())
                .map(|s| {
                    s.gradient
                        .iter()
                        .map(|e| e.eval(&[], params, 0.0))
                        .collect()
                })
                .collect(),
        };
        let switches: Vec<usize> = (0..code.kinds.len())
            .filter(|&j| matches!(code.kinds[j], Surface::Switch { .. }))
            .collect();
        let sets = switches.iter().map(|&j| vec![j]).chain(
            (0..switches.len())
                .flat_map(|p| (p + 1..switches.len()).map(move |q| (p, q)))
                .map(|(p, q)| vec![switches[p], switches[q]]),
        );
        let (mut finite, mut singular) = (0, 0);
        for set in sets {
            let regions = code.regions.len() as u32;
            for base in
                (0..regions).filter(|r| set.iter().all(|&j| code.kinds[j].orientation(*r) > 0.0))
            {
                let region = set.iter().fold(base, |r, &j| surface::sliding_on(r, j));
                let sliding = surface::Sliding::new::<D>(&flow, region);
                let members = sliding.set.members().to_vec();
                assert_eq!(members.iter().map(|m| m.0).collect::<Vec<_>>(), set);
                assert_eq!(sliding.set.base(), base);
                let bits: Vec<u32> = members.iter().map(|m| m.1).collect();
                let fields: Vec<&[f64]> = std::iter::once(base)
                    .chain(bits.iter().map(|b| base | 1 << b))
                    .map(|r| flow.constants[r as usize].as_slice())
                    .collect();
                let grads: Vec<&[f64]> =
                    set.iter().map(|&j| flow.gradients[j].as_slice()).collect();
                for k in 0..200 {
                    let y: [f64; D] = crate::array::from_fn(|i| {
                        0.2 + 0.7 * (0.37 * k as f64 + 1.3 * i as f64).sin()
                    });
                    let h = 0.002 + 0.0007 * (k % 11) as f64;
                    let phase = cos_sin(0.1 * k as f64);
                    let stages = rk4::stage_phases(&phase, &cos_sin(0.4 * h));
                    let expected = rk4::step_at(&sliding, &stages, &y, h);
                    let got = loops
                        .slide_step::<D>(base, &bits, &stages, &y, h, &fields, &grads)
                        .expect("a step for every slide on one switch or two");
                    assert_eq!(
                        got.map(f64::to_bits),
                        expected.map(f64::to_bits),
                        "switches {set:?}, base {base}, k {k}: {got:?} against {expected:?}"
                    );
                    if got.iter().all(|v| v.is_nan()) {
                        singular += 1;
                    } else {
                        assert!(got.iter().all(|v| v.is_finite()));
                        finite += 1;
                    }
                }
            }
        }
        (finite, singular)
    }

    /// `same_slides` on a model with two switches and on the two blocks on
    /// a belt (models/two-block-belt.toml), which slide on both at once
    /// when they stick together. A perturbed α or u in the generated C
    /// fails it.
    #[test]
    #[cfg(all(unix, target_arch = "x86_64"))]
    fn a_slide_s_c_step_is_the_sliding_flow_s_step_to_the_bit() {
        let compile = |text: &str, at: &str| {
            let table: toml::Value = toml::from_str(text).unwrap();
            let table = table.get("model").cloned().unwrap_or(table);
            let model = crate::model::Model::parse(&table, at).unwrap();
            crate::model::compiled::Code::compile(model, at).unwrap()
        };
        // The contact (x - 0.5) is crossed at the rate v on both sides: its
        // control is singular everywhere, alone or with the moving belt;
        // the belt's alone never is. One switch from two bases each, and
        // both from one.
        let switching = compile(SWITCHING, "model");
        assert_eq!(same_slides::<2>(&switching), (2 * 200, 3 * 200));
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/models/two-block-belt.toml");
        let blocks = compile(&std::fs::read_to_string(path).unwrap(), "two-block-belt");
        assert_eq!(same_slides::<4>(&blocks), (5 * 200, 0));
    }

    /// Every operation and function, with operands that reach NaN, ±0 and
    /// the ties of min/max/sign.
    fn all_functions() -> Tape {
        Tape::compile(&expressions(), 2, None).unwrap()
    }

    /// [`all_functions`]' expressions.
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
    fn the_c_compiler_s_functions_are_the_interpreter_to_the_bit() {
        let tape = all_functions();
        let native = Native::compile(&tape).expect("the C compiler builds it");
        let params = [[0.05, 1.2, 0.8], [0.1, -0.5, 1.3]];
        let lanes = params.map(|p| tape.lane_values(&p));
        let stages: [[Phase; 3]; 8] = crate::array::from_fn(|k| {
            let t = 0.37 * k as f64;
            [0.0, 0.05, 0.1].map(|dt| [((t + dt) * 0.8).cos(), ((t + dt) * 0.8).sin()])
        });
        let h: [f64; 8] = crate::array::from_fn(|k| 0.01 * (k + 1) as f64);
        // One lane, W = 1, 4 and 8.
        fn shared<const W: usize>(
            tape: &Tape,
            native: &Native,
            c: &[f64],
            st: &[Phase; 3],
            h: f64,
        ) {
            let y: [[f64; W]; 2] =
                crate::array::from_fn(|i| crate::array::from_fn(|k| STATES[i][k]));
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
        tape.prepare(&mut registers, |j| {
            crate::array::from_fn(|k| constant(j, k))
        });
        let interpreted = rk4::step_batch(
            |s, y| tape.run(&mut registers, &crate::array::from_fn(|k| stages[k][s]), y),
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

    /// The seed's oscillator's tape, and its native code with step loops
    /// for a stop at x = wall (`side` 1: from below; -1: from above).
    fn stepping(side: f64) -> (Tape, Native) {
        let names = Names {
            states: vec!["x".into(), "v".into()],
            parameters: vec!["zeta".into(), "f".into(), "eta".into()],
            switches: Vec::new(),
        };
        let parse = |t: &str| Expr::parse(t, &names).unwrap();
        let exprs = [parse("v"), parse("-2*zeta*v - x + f*cos(eta*t)")];
        let tape = Tape::compile(&exprs, 2, Some(parse("eta"))).unwrap();
        let stop = StopCode {
            coordinate: 0,
            velocity: 1,
            side,
        };
        let native =
            Native::compile_stepping(&tape, Some(&[stop])).expect("the C compiler builds it");
        (tape, native)
    }

    /// The step loop of `integrate::steps`, one step at a time: the
    /// steps taken before the first that meets the stop in a live slot.
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

    /// The step loop of W slots against [`by_steps`]: the steps taken,
    /// the states and the phase where it stopped.
    fn check<const W: usize>(
        native: &Native,
        c: &[f64],
        step: (f64, Phase),
        (wall, side): (f64, f64),
    ) {
        // Slots from near rest, a little apart; the last one beyond
        // the stop and not live.
        let mut y: [[f64; W]; 2] = [
            crate::array::from_fn(|k| 0.01 * k as f64),
            crate::array::from_fn(|k| -0.003 * k as f64),
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

    /// The step loop takes the steps [`Kind::Step`] takes, from the phases
    /// `rk4::stage_phases` turns, to the bit, and stops before the step in
    /// which the step loop's detection (`integrate::steps`) finds a live
    /// slot meeting the stop; a slot not live is not watched.
    #[test]
    fn the_step_loop_is_the_step_function_to_the_bit_and_stops_where_detection_does() {
        let (tape, native) = stepping(1.0);
        let (_, below) = stepping(-1.0);
        let eta = 0.8;
        let c = tape.lane_values(&[0.05, 1.0, eta]).constants;
        let h = std::f64::consts::TAU / eta / 200.0;
        let half = crate::integrate::clock::cos_sin(0.5 * eta * h);
        // A stop reached within the steps, and one out of reach (whose
        // turns the loop walks through), from either side.
        for wall in [0.9, 50.0] {
            check::<4>(&native, &c, (h, half), (wall, 1.0));
            check::<8>(&native, &c, (h, half), (wall, 1.0));
            check::<16>(&native, &c, (h, half), (wall, 1.0));
            check::<4>(&below, &c, (h, half), (-wall, -1.0));
            check::<8>(&below, &c, (h, half), (-wall, -1.0));
            check::<16>(&below, &c, (h, half), (-wall, -1.0));
        }
    }

    /// The step loop of 8 lanes, each its own η (so its own constants and
    /// step size) and stop, is each lane's step to the bit, and stops where
    /// detection does; no loop is built without stops, nor for widths
    /// without one.
    #[test]
    fn the_step_loop_of_lanes_side_by_side_is_each_lane_s_step() {
        let (tape, native) = stepping(1.0);
        let steps = 400;
        let c = tape.lane_values(&[0.05, 1.0, 0.8]).constants;
        let h = std::f64::consts::TAU / 0.8 / 200.0;
        let half = crate::integrate::clock::cos_sin(0.5 * 0.8 * h);
        // All with the grid's phase.
        let etas: [f64; 8] = crate::array::from_fn(|k| 0.7 + 0.05 * k as f64);
        let lanes = etas.map(|eta| tape.lane_values(&[0.05, 1.0, eta]).constants);
        let hs = etas.map(|eta| std::f64::consts::TAU / eta / 200.0);
        let halves: [Phase; 8] =
            crate::array::from_fn(|k| crate::integrate::clock::half_turn(etas[k], hs[k], 200));
        assert!(halves.iter().all(|h| *h == halves[0]), "one grid turn");
        let walls: [f64; 8] = crate::array::from_fn(|k| 0.8 + 0.1 * k as f64);
        let l = tape.lane_constants.len();
        let lane: Vec<f64> = (0..l)
            .flat_map(|j| lanes.iter().map(move |c| c[j]))
            .collect();
        let live = 0x7f;
        let start: [[f64; 8]; 2] = [
            crate::array::from_fn(|k| 0.01 * k as f64),
            crate::array::from_fn(|k| if k == 7 { 9.0 } else { 0.0 }),
        ];
        let (mut expected, mut phases) = (start, [[1.0, 0.0]; 8]);
        let mut taken = steps;
        for n in 0..steps {
            let stages: [[Phase; 3]; 8] =
                crate::array::from_fn(|k| rk4::stage_phases(&phases[k], &halves[k]));
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
            phases = crate::array::from_fn(|k| stages[k][2]);
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
    fn c_outputs_other_than_a_field_are_the_interpreter_to_the_bit() {
        // The two expressions of `tape`, and a padding zero (as surfaces
        // are padded).
        let mut exprs = expressions();
        exprs.push(Expr::Num(0.0));
        let tape = Tape::compile(&exprs, 2, None).unwrap();
        let native = Native::compile(&tape).expect("the C compiler builds it");
        assert!(native.functions[Kind::Step as usize]
            .iter()
            .flatten()
            .all(Option::is_none));
        fn bits<const W: usize>(a: &[[f64; W]; 3]) -> Vec<u64> {
            a.iter().flatten().map(|x| x.to_bits()).collect()
        }
        let lanes = [[0.05, 1.2, 0.8], [0.1, -0.5, 1.3]].map(|p| tape.lane_values(&p).constants);
        let phases: [Phase; 8] = crate::array::from_fn(|k| {
            let t = 0.37 * k as f64;
            [t.cos(), t.sin()]
        });
        // One lane, W = 1, 4 and 8.
        fn shared<const W: usize>(tape: &Tape, native: &Native, c: &[f64], phase: &Phase) {
            let y: [[f64; W]; 2] =
                crate::array::from_fn(|i| crate::array::from_fn(|k| STATES[i][k]));
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
        tape.prepare(&mut registers, |j| {
            crate::array::from_fn(|k| constant(j, k))
        });
        let interpreted: [[f64; 8]; 3] = tape.run(&mut registers, &phases, &STATES);
        let compiled: [[f64; 8]; 3] =
            native.call(Kind::Rhs, Layout::Each, &STATES, &clock, &lane, &[]);
        assert_eq!(bits(&interpreted), bits(&compiled), "each, W = 8");
    }
}
