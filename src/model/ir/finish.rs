//! The finish kernel's step program (in the language of `model::ir::step`):
//! the end of a part of a map iteration, per lane. Averaging, the part's
//! Jacobian columns from the perturbed copies (with the copies' flags and
//! how far they left the linear regime); always, the reference restarted
//! at the end of an iteration and the copies re-seeded from it. Printed to
//! WGSL by `model::codegen::step` for `shaders/finish.wgsl`, whose entry
//! point calls `finish_lane`; what it leaves written by hand is the
//! kernels' buffer access it calls (`load_state`, `store_state`,
//! `write_summary`) and the dispatch.
//!
//! The CPU runs the Rust twins, which are the oracle:
//! `method::jacobian::Copies::difference` (the columns, `same`, the
//! departure and asymmetry of a central column's copies),
//! `perturbation` (where the copies start), `System::admits` and
//! `check_state` (a copy seeded behind a stop or beyond an event's
//! surface).
//!
//! The kernel's variants (`#ifdef` in the hand-written kernels) choose
//! the program's statements here, at generation: see [`Options`].

use super::step::build::*;
use super::step::{Cmp, Expr, Extern, Function, Program, Stmt, Structure, Ty};

/// What a finish kernel is built for (the kernels' defines of the same
/// names).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Options {
    /// Perturbed copies and their Jacobian (`LYAPUNOV`).
    pub lyapunov: bool,
    /// Central differences, 2D copies (`CENTRAL`), else forward, D.
    pub central: bool,
    /// f32 states with their compensation (`COMPENSATED`).
    pub compensated: bool,
    /// Stops and impacts (`WALL`): the copies' crossings counted per stop.
    pub wall: bool,
    /// General surfaces (`SURFACES`, with `WALL`): events and switches.
    pub surfaces: bool,
    /// Angles wrapped into [-π, π) at the end of an iteration (`WRAP`).
    pub wrap: bool,
}

/// What the finish functions use of the kernels:
///
/// - the layout's constants: `DIM`, trajectories per lane `TRAJ`, a
///   trajectory's `TRAJ_STRIDE` and its slots `TRAJ_SLOWEST` (the slowest
///   impact speed, `NO_IMPACT` for none) and `TRAJ_FLUX` (Σ ln |det S|),
///   a lane's `LANE_STRIDE` and its δ at `LANE_DELTA`; the flags
///   (`FLAG_*`); the stops' and surfaces' `WALLS`, `SURFACES`,
///   `SURFACE_BIT` and `EVENT`;
/// - the uniform `control` (the period's steps, the part's, the parts,
///   the ring, the lanes, and whether the transient runs);
/// - the buffers `lanes` (read), `traj`, `counts` (per trajectory: the
///   part's steps, its impacts, its flags, the lane's iterations),
///   `deltas`, `jac`, `crossings` (per stop);
/// - `load_state(at)`, `store_state(at, y)`, `wrap_angles(y)`,
///   `load_params(lane)`, `stops_of(p)`, `stop(walls, j)`, `gap(w, y)`,
///   `surface_g(p, phase, y)`, and `write_summary(r, slot, y, impacts,
///   flags, nonlinearity)`, the part's record of a reference.
pub fn kernels() -> Vec<Extern> {
    use Ty::{Count, CountTable, Pair, Real, State};
    let (params, stops) = (Ty::Struct("Params"), Ty::Struct("Stops"));
    let counts = [
        "DIM",
        "TRAJ",
        "TRAJ_STRIDE",
        "TRAJ_SLOWEST",
        "TRAJ_FLUX",
        "LANE_STRIDE",
        "LANE_DELTA",
        "WALLS",
        "SURFACES",
        "EVENT",
        "FLAG_NONFINITE",
        "FLAG_STICKY",
        "FLAG_CHATTERING",
        "FLAG_TRUNCATED",
        "FLAG_SLIDING",
        "FLAG_TOO_MANY_EVENTS",
        "FLAG_BEHIND_WALL",
    ];
    let buffer = |name, element, writable| Extern::Buffer {
        name,
        element,
        writable,
    };
    let function = |name, params, result| Extern::Fn {
        name,
        params,
        result,
    };
    let control = [
        "lane_count",
        "steps_per_period",
        "transient",
        "part_steps",
        "parts",
        "ring",
    ];
    let mut externs: Vec<Extern> = counts.map(|c| Extern::Const(c, Count)).into();
    externs.extend([
        Extern::Const("NO_IMPACT", Real),
        Extern::Const("SURFACE_BIT", CountTable),
        Extern::Struct("Control", control.map(|m| (m, Count)).into()),
        Extern::Const("control", Ty::Struct("Control")),
        buffer("lanes", Real, false),
        buffer("traj", Real, true),
        buffer("counts", CountTable, true),
        buffer("deltas", Real, true),
        buffer("jac", Real, true),
        buffer("crossings", CountTable, true),
        function("load_state", vec![Count], State),
        function("wrap_angles", vec![State], State),
        function("load_params", vec![Count], params),
        function("stops_of", vec![params], stops),
        function("stop", vec![stops, Count], Ty::Struct("Stop")),
        function("gap", vec![Ty::Struct("Stop"), State], Real),
        function("surface_g", vec![params, Pair, State], Ty::Table),
        Extern::Proc {
            name: "store_state",
            params: vec![Count, State],
        },
        Extern::Proc {
            name: "write_summary",
            params: vec![Count, Count, State, Count, Count, Ty::Single],
        },
    ]);
    externs
}

/// The finish kernel's program for `options`: the functions its variant
/// calls, in order (see [`functions`]).
pub fn program(options: Options) -> Program {
    let opaque = |name| Structure {
        name,
        members: Vec::new(),
    };
    Program {
        functions: functions(options),
        structures: vec![opaque("Params"), opaque("Stops"), opaque("Stop")],
        externs: kernels(),
    }
}

/// The functions, each the twin of the hand-written kernel's of the same
/// name that it replaced:
///
/// - `same_impacts(r, t)`: trajectory t met each stop as often as the
///   reference r (`same` in `method::jacobian`).
/// - `departure(r, t)`: a copy's departure from r at the stops, the
///   relative difference of their slowest impact speeds, or 1e30 where
///   they met a stop a different number of times or the copy started
///   behind one (0 for r itself, or without impacts).
/// - `asymmetry(r, plus, minus)`: how far a central column's copies left
///   the linear regime, |U₊ + U₋ - 2U₀| / |U₊ - U₋| in max norms.
/// - `behind_wall(p, y)`: `FLAG_BEHIND_WALL` for a copy seeded at y
///   behind a stop or beyond an event's surface (at t = 0), else 0.
/// - `restart(at, y, phase, comp)`: a trajectory starting a part at y,
///   with its phase and compensation and no impact yet.
/// - `write_columns(lane, r, slot)`: the part's Jacobian into ring slot
///   `slot`, column i from the copy at x + δe_i and the reference, or
///   (central) the copy at x - δe_i, one-sided where one copy met a stop
///   a different number of times; the copies' flags and nonlinearity.
/// - `reseed_copies(lane, r, y, phase, comp, cr)`: the copies seeded from
///   the reference's state y, δ·max(1, ‖y‖∞) from it.
/// - `finish_lane(lane)`: the whole end of a part (see the kernel).
pub fn functions(options: Options) -> Vec<Function> {
    let mut out = Vec::new();
    if options.lyapunov {
        out.push(same_impacts(options));
        if options.wall {
            out.push(departure(options));
        }
        if options.central {
            out.push(asymmetry(options));
        }
        out.push(behind_wall(options));
    }
    out.push(restart(options));
    if options.lyapunov {
        out.push(write_columns(options));
        out.push(reseed_copies(options));
    }
    out.push(finish_lane(options));
    out
}

/// `t * TRAJ_STRIDE + offset`: where trajectory t's `offset` lies in
/// `traj`.
fn slot_of(t: Expr, offset: Option<Expr>) -> Expr {
    let at = t * var("TRAJ_STRIDE");
    match offset {
        Some(offset) => at + offset,
        None => at,
    }
}

/// Trajectory t's state (`comp`: its compensation).
fn state_of(t: &'static str, comp: bool) -> Expr {
    let offset = comp.then(|| var("DIM"));
    apply("load_state", vec![slot_of(var(t), offset)])
}

/// Counter `k` of trajectory t's counts (0: the part's steps, 1: its
/// impacts, 2: its flags, 3: the lane's iterations).
fn counts_of(t: Expr, k: u32) -> Expr {
    index(index(var("counts"), t), count(k))
}

fn equal(a: Expr, b: Expr) -> Expr {
    cmp(Cmp::Equal, a, b)
}

fn not_equal(a: Expr, b: Expr) -> Expr {
    cmp(Cmp::NotEqual, a, b)
}

/// Whether `flags` has the bits `flag` (a constant's name).
fn has(flags: Expr, flag: &'static str) -> Expr {
    not_equal(bit_and(flags, var(flag)), count(0))
}

/// `for name in 0..bound { body }`.
fn for_each(name: &'static str, bound: Expr, mut body: Vec<Stmt>) -> Vec<Stmt> {
    let mut block = vec![break_unless(less(var(name), bound))];
    block.append(&mut body);
    block.push(Stmt::Set(name, var(name) + count(1)));
    vec![Stmt::Var(name, count(0)), Stmt::Loop(block)]
}

/// A function without results.
fn procedure(name: &'static str, params: Vec<(&'static str, Ty)>, body: Vec<Stmt>) -> Function {
    Function {
        name,
        params,
        body,
        results: Vec::new(),
        returns: None,
    }
}

fn same_impacts(options: Options) -> Function {
    let params = vec![("r", Ty::Count), ("t", Ty::Count)];
    if !options.wall {
        let same = equal(counts_of(var("t"), 1), counts_of(var("r"), 1));
        return Function::one("same_impacts", params, Vec::new(), ("same", same));
    }
    let body = lets(vec![
        ("mine", index(var("crossings"), var("t"))),
        ("theirs", index(var("crossings"), var("r"))),
    ]);
    let stop = |k| equal(index(var("mine"), count(k)), index(var("theirs"), count(k)));
    let same = and(and(stop(0), stop(1)), and(stop(2), stop(3)));
    Function::one("same_impacts", params, body, ("same", same))
}

fn departure(options: Options) -> Function {
    let slowest = |t| index(var("traj"), slot_of(var(t), Some(var("TRAJ_SLOWEST"))));
    // No crossing of any kind (with surfaces, their count is beside the
    // impacts, so the slowest speed tells).
    let none = if options.surfaces {
        equal(slowest("r"), var("NO_IMPACT"))
    } else {
        equal(counts_of(var("r"), 1), count(0))
    };
    let far = || Stmt::Set("d", single(num(1e30)));
    let relative = vec![
        Stmt::Let("vr", slowest("r")),
        Stmt::Let("vt", slowest("t")),
        Stmt::Set("d", single(abs(var("vt") - "vr") / "vr")),
    ];
    let met = vec![Stmt::If(
        not(none),
        vec![Stmt::If(
            apply("same_impacts", vec![var("r"), var("t")]),
            relative,
            vec![far()],
        )],
        Vec::new(),
    )];
    let body = vec![
        Stmt::Var("d", single(num(0.0))),
        Stmt::If(
            not_equal(var("t"), var("r")),
            vec![Stmt::If(
                has(counts_of(var("t"), 2), "FLAG_BEHIND_WALL"),
                vec![far()],
                met,
            )],
            Vec::new(),
        ),
    ];
    let params = vec![("r", Ty::Count), ("t", Ty::Count)];
    Function::one("departure", params, body, ("departure", var("d")))
}

fn asymmetry(options: Options) -> Function {
    let mut body = vec![
        Stmt::Var("up", state_of("plus", false) - state_of("r", false)),
        Stmt::Var("down", state_of("minus", false) - state_of("r", false)),
    ];
    if options.compensated {
        // The compensations' difference too (see `write_columns`).
        for (name, t) in [("up", "plus"), ("down", "minus")] {
            let comp = state_of(t, true) - state_of("r", true);
            body.push(Stmt::Set(name, var(name) - comp));
        }
    }
    let at = |y| index(var(y), var("k"));
    body.extend([Stmt::Var("even", num(0.0)), Stmt::Var("odd", num(0.0))]);
    body.extend(for_each(
        "k",
        var("DIM"),
        vec![
            Stmt::Set("even", max(var("even"), abs(at("up") + at("down")))),
            Stmt::Set("odd", max(var("odd"), abs(at("up") - at("down")))),
        ],
    ));
    body.extend([
        Stmt::Var("ratio", single(num(0.0))),
        Stmt::If(
            cmp(Cmp::NotEqual, var("even"), num(0.0)),
            vec![Stmt::Set("ratio", single(var("even") / "odd"))],
            Vec::new(),
        ),
    ]);
    let params = vec![("r", Ty::Count), ("plus", Ty::Count), ("minus", Ty::Count)];
    Function::one("asymmetry", params, body, ("asymmetry", var("ratio")))
}

fn behind_wall(options: Options) -> Function {
    let mut body = vec![Stmt::Var("flag", count(0))];
    let found = || vec![Stmt::Set("flag", var("FLAG_BEHIND_WALL")), Stmt::Break];
    if options.wall {
        body.push(Stmt::Let("walls", apply("stops_of", vec![var("p")])));
        let w = apply("stop", vec![var("walls"), var("j")]);
        let behind = greater(apply("gap", vec![w, var("y")]), num(0.0));
        body.extend(for_each(
            "j",
            var("WALLS"),
            vec![Stmt::If(behind, found(), Vec::new())],
        ));
    }
    if options.surfaces {
        // Beyond an event's surface (at t = 0, as the CPU's check_state).
        let start = pair(num(1.0), num(0.0));
        let g = apply("surface_g", vec![var("p"), start, var("y")]);
        let event = equal(index(var("SURFACE_BIT"), var("s")), var("EVENT"));
        let beyond = and(event, greater(index(var("g"), var("s")), num(0.0)));
        let mut test = vec![Stmt::Let("g", g)];
        test.extend(for_each(
            "s",
            var("SURFACES"),
            vec![Stmt::If(beyond, found(), Vec::new())],
        ));
        body.push(Stmt::If(equal(var("flag"), count(0)), test, Vec::new()));
    }
    let params = vec![("p", Ty::Struct("Params")), ("y", Ty::State)];
    Function::one("behind_wall", params, body, ("flag", var("flag")))
}

fn restart(options: Options) -> Function {
    let two_dim = || count(2) * var("DIM");
    let at = |offset: Expr| var("at") + offset;
    let mut body = vec![
        perform("store_state", vec![var("at"), var("y")]),
        perform("store_state", vec![at(var("DIM")), var("comp")]),
        Stmt::SetAt("traj", at(two_dim()), first(var("phase"))),
        Stmt::SetAt("traj", at(two_dim() + count(1)), second(var("phase"))),
        Stmt::SetAt("traj", at(var("TRAJ_SLOWEST")), var("NO_IMPACT")),
    ];
    if options.surfaces {
        body.push(Stmt::SetAt("traj", at(var("TRAJ_FLUX")), num(0.0)));
    }
    let params = vec![
        ("at", Ty::Count),
        ("y", Ty::State),
        ("phase", Ty::Pair),
        ("comp", Ty::State),
    ];
    procedure("restart", params, body)
}

/// The flags a copy passes on to its lane's part.
fn copy_flags() -> Expr {
    let flags = ["FLAG_TRUNCATED", "FLAG_SLIDING", "FLAG_TOO_MANY_EVENTS"];
    let first = var("FLAG_CHATTERING");
    flags.iter().fold(first, |all, flag| bit_or(all, var(flag)))
}

/// Column i's two trajectories (`plus`, `minus`) and step, and the flags
/// its copies raise: central differences on the side where the map is
/// smooth.
fn column_copies(options: Options) -> Vec<Stmt> {
    let i = || var("i");
    let copy = |k: Expr| var("r") + count(1) + k;
    if !options.central {
        return vec![
            Stmt::Let("plus", copy(i())),
            Stmt::Let("minus", var("r")),
            Stmt::Let("step", index(var("deltas"), var("lane") * var("DIM") + i())),
            Stmt::Set(
                "flags",
                bit_or(
                    var("flags"),
                    bit_and(counts_of(var("plus"), 2), copy_flags()),
                ),
            ),
        ];
    }
    let row = || var("lane") * count(2) * var("DIM");
    // A copy that met a stop a different number of times than the
    // reference crossed a grazing boundary: its difference is O(1) wrong.
    let same = |t: &'static str| {
        and(
            apply("same_impacts", vec![var("r"), var(t)]),
            not(has(counts_of(var(t), 2), "FLAG_BEHIND_WALL")),
        )
    };
    let both = bit_or(counts_of(var("plus"), 2), counts_of(var("minus"), 2));
    vec![
        Stmt::Var("plus", copy(i())),
        Stmt::Var("minus", copy(var("DIM") + i())),
        Stmt::Let("step_plus", index(var("deltas"), row() + i())),
        Stmt::Let("step_minus", index(var("deltas"), row() + var("DIM") + i())),
        Stmt::Set("flags", bit_or(var("flags"), bit_and(both, copy_flags()))),
        Stmt::Let("same_plus", same("plus")),
        Stmt::Let("same_minus", same("minus")),
        Stmt::Var("step", var("step_plus") + "step_minus"),
        Stmt::If(
            and(not(var("same_plus")), var("same_minus")),
            vec![
                Stmt::Set("plus", var("r")),
                Stmt::Set("step", var("step_minus")),
            ],
            vec![Stmt::If(
                and(var("same_plus"), not(var("same_minus"))),
                vec![
                    Stmt::Set("minus", var("r")),
                    Stmt::Set("step", var("step_plus")),
                ],
                Vec::new(),
            )],
        ),
    ]
}

fn write_columns(options: Options) -> Function {
    let mut column = column_copies(options);
    // The two images are close, so their difference is exact; their low
    // bits are what the column is made of.
    column.push(Stmt::Var(
        "difference",
        state_of("plus", false) - state_of("minus", false),
    ));
    if options.compensated {
        // Each compensation holds the rounding its state still owes (the
        // exact sum is y - comp): without it, f32 would round every
        // column by up to ulp(y)/δ.
        let comp = state_of("plus", true) - state_of("minus", true);
        column.push(Stmt::Set("difference", var("difference") - comp));
    }
    let entry = var("slot") * var("DIM") * var("DIM") + var("k") * var("DIM") + var("i");
    let quotient = index(var("difference"), var("k")) / "step";
    column.extend(for_each(
        "k",
        var("DIM"),
        vec![Stmt::SetAt("jac", entry, quotient)],
    ));
    let worst = |a: Expr| Stmt::Set("nonlinearity", max(var("nonlinearity"), a));
    if options.wall {
        let departure = |t| apply("departure", vec![var("r"), var(t)]);
        column.push(worst(max(departure("plus"), departure("minus"))));
    }
    if options.central {
        let both = and(
            not_equal(var("plus"), var("r")),
            not_equal(var("minus"), var("r")),
        );
        let asymmetry = apply("asymmetry", vec![var("r"), var("plus"), var("minus")]);
        column.push(Stmt::If(both, vec![worst(asymmetry)], Vec::new()));
    }
    let mut body = vec![
        Stmt::Var("flags", count(0)),
        Stmt::Var("nonlinearity", single(num(0.0))),
    ];
    body.extend(for_each("i", var("DIM"), column));
    Function {
        name: "write_columns",
        params: vec![("lane", Ty::Count), ("r", Ty::Count), ("slot", Ty::Count)],
        body,
        results: vec![
            ("flags", var("flags")),
            ("nonlinearity", var("nonlinearity")),
        ],
        returns: Some("Columns"),
    }
}

/// Copy `k` of the reference r (its index among the lane's), seeded at
/// the state `y` (a name) with δ `step` into `deltas` at `at`.
fn seed(options: Options, k: Expr, y: &'static str, step: Expr, at: Expr) -> Vec<Stmt> {
    let t = || var("r") + count(1) + k.clone();
    let behind = apply("behind_wall", vec![var("p"), var(y)]);
    let flags = bit_or(index(var("cr"), count(2)), behind);
    let mut out = vec![
        Stmt::SetAt("deltas", at, step),
        perform(
            "restart",
            vec![t() * var("TRAJ_STRIDE"), var(y), var("phase"), var("comp")],
        ),
        Stmt::SetAt(
            "counts",
            t(),
            counters([index(var("cr"), count(0)), count(0), flags, count(0)]),
        ),
    ];
    if options.wall {
        out.push(Stmt::SetAt("crossings", t(), no_crossings()));
    }
    out
}

fn no_crossings() -> Expr {
    counters([count(0), count(0), count(0), count(0)])
}

fn reseed_copies(options: Options) -> Function {
    let mut body = vec![Stmt::Var("size", num(1.0))];
    body.extend(for_each(
        "k",
        var("DIM"),
        vec![Stmt::Set(
            "size",
            max(var("size"), abs(index(var("y"), var("k")))),
        )],
    ));
    let delta = index(
        var("lanes"),
        var("lane") * var("LANE_STRIDE") + var("LANE_DELTA"),
    );
    body.extend(lets(vec![
        ("delta", delta * "size"),
        ("p", apply("load_params", vec![var("lane")])),
    ]));
    let y_i = || index(var("y"), var("i"));
    let at = |y| index(var(y), var("i"));
    let copies = if options.central { 2 } else { 1 };
    let row = || var("lane") * count(copies) * var("DIM");
    let mut copy = vec![
        Stmt::Var("yi", var("y")),
        Stmt::SetAt("yi", var("i"), y_i() + "delta"),
    ];
    copy.extend(seed(
        options,
        var("i"),
        "yi",
        at("yi") - y_i(),
        row() + var("i"),
    ));
    if options.central {
        copy.extend([
            Stmt::Var("ym", var("y")),
            Stmt::SetAt("ym", var("i"), y_i() - "delta"),
        ]);
        let k = var("DIM") + var("i");
        let at_minus = row() + var("DIM") + var("i");
        copy.extend(seed(options, k, "ym", y_i() - at("ym"), at_minus));
    }
    body.extend(for_each("i", var("DIM"), copy));
    let params = vec![
        ("lane", Ty::Count),
        ("r", Ty::Count),
        ("y", Ty::State),
        ("phase", Ty::Pair),
        ("comp", Ty::State),
        ("cr", Ty::CountTable),
    ];
    procedure("reseed_copies", params, body)
}

/// The part's record, averaging: the Jacobian's columns, the summary,
/// and the lane's iterations counted at the end of one.
fn record(options: Options) -> Vec<Stmt> {
    let cr = |k| index(var("cr"), count(k));
    let control = |m| dot("control", m);
    let part = select(
        var("last"),
        control("parts") - count(1),
        cr(0) / control("part_steps") - count(1),
    );
    let slot =
        (rem(cr(3), control("ring")) * control("parts") + "part") * control("lane_count") + "lane";
    let mut out = lets(vec![("part", part), ("slot", slot)]);
    // How far the copies left the linear regime at the wall (see
    // IterationStats::nonlinearity): the host re-estimates the
    // iterations where that matters (grazing).
    out.push(Stmt::Var("nonlinearity", single(num(0.0))));
    if options.lyapunov {
        out.extend([
            Stmt::Let("columns", call("write_columns", &["lane", "r", "slot"])),
            Stmt::Set("flags", bit_or(var("flags"), dot("columns", "flags"))),
            Stmt::Set("nonlinearity", dot("columns", "nonlinearity")),
        ]);
    }
    out.extend([
        perform(
            "write_summary",
            vec![
                var("r"),
                var("slot"),
                var("y"),
                cr(1),
                var("flags"),
                var("nonlinearity"),
            ],
        ),
        Stmt::If(
            var("last"),
            vec![Stmt::SetAt("cr", count(3), cr(3) + count(1))],
            Vec::new(),
        ),
    ]);
    out
}

/// The end of a whole iteration (always, in the transient), or of a
/// part (a sub-map), after which the reference runs on at its phase. A
/// failed reference stopped where it failed: its iterations end at
/// once, each reporting the failure in its last part. The copies start
/// where the reference is: the next iteration's step 0 and phase 0, or
/// the next part's first step at the reference's phase and with its
/// compensation (so that a copy's exact start is the reference's plus
/// exactly its δ).
fn finish_lane(options: Options) -> Function {
    let cr = |k| index(var("cr"), count(k));
    let at = |offset| slot_of(var("r"), Some(offset));
    let last = or(
        cmp(Cmp::GreaterEq, cr(0), dot("control", "steps_per_period")),
        has(cr(2), "FLAG_NONFINITE"),
    );
    // A model's angles into [-π, π) at the end of an iteration (twin of
    // System::wrap): the point, the restart and the copies' seeds, not
    // the Jacobian, whose columns are differences of the copies'
    // unwrapped images.
    let reference = || state_of("r", false);
    let y = if options.wrap {
        let wrapped = apply("wrap_angles", vec![reference()]);
        select(var("last"), wrapped, reference())
    } else {
        reference()
    };
    let mut body = lets(vec![("r", var("lane") * var("TRAJ"))]);
    body.extend([
        Stmt::Var("cr", index(var("counts"), var("r"))),
        Stmt::Var("flags", cr(2)),
        Stmt::Let("last", last),
        Stmt::Let("y", y),
        Stmt::If(
            equal(dot("control", "transient"), count(0)),
            record(options),
            Vec::new(),
        ),
        Stmt::Var("phase", pair(num(1.0), num(0.0))),
        Stmt::Var("comp", fill(num(0.0))),
    ]);
    let two_dim = || count(2) * var("DIM");
    let mut goes_on = vec![
        Stmt::Set(
            "phase",
            pair(
                index(var("traj"), at(two_dim())),
                index(var("traj"), at(two_dim() + count(1))),
            ),
        ),
        Stmt::Set("comp", state_of("r", true)),
        Stmt::SetAt("traj", at(var("TRAJ_SLOWEST")), var("NO_IMPACT")),
    ];
    if options.surfaces {
        goes_on.push(Stmt::SetAt("traj", at(var("TRAJ_FLUX")), num(0.0)));
    }
    let restarts = vec![
        Stmt::SetAt("cr", count(0), count(0)),
        perform(
            "restart",
            vec![slot_of(var("r"), None), var("y"), var("phase"), var("comp")],
        ),
    ];
    body.extend([
        Stmt::If(var("last"), restarts, goes_on),
        Stmt::SetAt("cr", count(1), count(0)),
        Stmt::SetAt("cr", count(2), bit_and(var("flags"), var("FLAG_STICKY"))),
        Stmt::SetAt("counts", var("r"), var("cr")),
    ]);
    if options.wall {
        body.push(Stmt::SetAt("crossings", var("r"), no_crossings()));
    }
    if options.lyapunov {
        let args = ["lane", "r", "y", "phase", "comp", "cr"];
        body.push(perform("reseed_copies", args.map(var).into()));
    }
    procedure("finish_lane", vec![("lane", Ty::Count)], body)
}

/// Every variant's options: the kernels' defines in every combination
/// they occur in (surfaces with a wall, central with copies).
pub fn variants() -> Vec<Options> {
    let mut out = Vec::new();
    for bits in 0u32..64 {
        let bit = |b: u32| bits >> b & 1 == 1;
        let options = Options {
            lyapunov: bit(0),
            central: bit(1),
            compensated: bit(2),
            wall: bit(3),
            surfaces: bit(4),
            wrap: bit(5),
        };
        if (options.surfaces && !options.wall) || (options.central && !options.lyapunov) {
            continue;
        }
        out.push(options);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_variant_s_finish_functions_are_well_typed() {
        for options in variants() {
            let program = program(options);
            for f in &program.functions {
                f.result_types(&program);
            }
            assert_eq!(program.functions.last().unwrap().name, "finish_lane");
        }
    }
}
