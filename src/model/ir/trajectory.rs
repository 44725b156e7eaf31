//! The kernels' step programs on a trajectory's record (in the language
//! of `model::ir::step`): the step that meets a stop or a surface, or
//! starts at rest on a stop, resolved (`resolve_step`, the CPU's
//! `integrate::impact::step`), and what it did recorded in the trajectory
//! (`record`: its state, impacts, slowest impact, flags, region and
//! Σ ln |det S|, the CPU's iteration statistics). The integrate kernel's
//! step loop, the trajectory's layout in the buffers and the loop budget
//! stay hand-written (shaders/integrate.wgsl): they have no CPU twin.

use super::step::build::*;
use super::step::{Cmp, Expr, Extern, Function, Stmt, Structure, Ty};

/// The counts' component of the flags (`counts[t].z`), and of the
/// impacts (`.y`).
const FLAGS: u32 = 2;
const IMPACTS: u32 = 1;

/// What the trajectory's functions use of the kernels:
///
/// - `Trajectory`, a trajectory as a dispatch advances it: its state,
///   the state's compensation, the forcing phase, its counts (steps,
///   impacts, flags), the slowest impact speed of the iteration so far,
///   and with surfaces its region and the part's Σ ln |det S|;
/// - `Stepping`, a lane's step: h, the half turn (cos, sin)(ωh/2) and ω;
/// - the flags `FLAG_SLIDING` and `FLAG_CHATTERING`, and `rank_flags`,
///   the flags of the dimensions a step collapsed.
pub fn kernels() -> Vec<Extern> {
    use Ty::{Count, CountTable, Pair, Real, State};
    vec![
        Extern::Struct(
            "Trajectory",
            vec![
                ("y", State),
                ("comp", State),
                ("phase", Pair),
                ("c", CountTable),
                ("slowest", Real),
                ("region", Count),
                ("flux", Real),
            ],
        ),
        Extern::Struct(
            "Stepping",
            vec![("h", Real), ("half", Pair), ("omega", Real)],
        ),
        Extern::Const("FLAG_SLIDING", Count),
        Extern::Const("FLAG_CHATTERING", Count),
        Extern::Fn {
            name: "rank_flags",
            params: vec![Count],
            result: Count,
        },
    ]
}

/// The names of every function [`functions`] gives, in any variant.
pub const FUNCTIONS: [&str; 3] = ["with_flags", "record", "resolve_step"];

/// `Resolved`: a resolved step's trajectory, and the step's crossings
/// per event, which the kernel adds to its buffer (a vector kept live
/// across the step loop would cost every step).
pub fn structures() -> [Structure; 1] {
    [Structure {
        name: "Resolved",
        members: vec![
            ("tr", Ty::Struct("Trajectory")),
            ("crossings", Ty::CountTable),
        ],
    }]
}

/// The trajectory's functions, callees first (with general surfaces
/// where `surfaces`):
///
/// - `with_flags(c, flags)`: the counts c with the flags set.
/// - `record(tr, w, y1, comp1)`: see [`record`].
/// - `resolve_step(p, walls, step, y1, comp1, tr)`: see [`resolve_step`].
pub fn functions(surfaces: bool) -> [Function; 3] {
    let with_flags = Function {
        name: "with_flags",
        params: vec![("c", Ty::CountTable), ("flags", Ty::Count)],
        body: vec![
            Stmt::Var("out", var("c")),
            Stmt::SetAt(
                "out",
                count(FLAGS),
                bit_or(index(var("out"), count(FLAGS)), var("flags")),
            ),
        ],
        results: vec![("c", var("out"))],
        returns: None,
    };
    [with_flags, record(surfaces), resolve_step(surfaces)]
}

/// `tr.c = with_flags(tr.c, flags)`.
fn flag(flags: Expr) -> Stmt {
    Stmt::SetMember("tr", "c", apply("with_flags", vec![dot("tr", "c"), flags]))
}

/// What resolve_impacts did in the step (w), recorded in the trajectory:
/// with surfaces its region, Σ ln |det S|, the sliding flag and the
/// sliding phases entered (counted in the flags' high half); then the
/// state (whatever the stops did, the step ends where resolve_impacts
/// says, and the compensation belongs to the plain step it replaced),
/// impacts, slowest impact and flags.
fn record(surfaces: bool) -> Function {
    use Ty::State;
    let crossed = |m| member(dot("w", "crossed"), m);
    let mut body = vec![Stmt::Var("tr", var("tr_in"))];
    if surfaces {
        let flags = || index(var("phases_c"), count(FLAGS));
        body.extend([
            Stmt::SetMember("tr", "region", crossed("region")),
            Stmt::SetMember("tr", "flux", dot("tr", "flux") + crossed("log_flux")),
            Stmt::If(
                crossed("sliding"),
                vec![flag(var("FLAG_SLIDING"))],
                Vec::new(),
            ),
            Stmt::Var("phases_c", dot("tr", "c")),
            Stmt::Let("room", count(0xffff) - shr(flags(), count(16))),
            Stmt::Let("phases", crossed("sliding_phases")),
            Stmt::SetAt(
                "phases_c",
                count(FLAGS),
                flags()
                    + shl(
                        select(less(var("phases"), var("room")), var("phases"), var("room")),
                        count(16),
                    ),
            ),
            Stmt::SetMember("tr", "c", var("phases_c")),
        ]);
    }
    let mut chattering = vec![flag(var("FLAG_CHATTERING"))];
    if surfaces {
        // Crossings of a general event that accumulate (a ball locking
        // onto a vibrating table) are held on the surface by the CPU path
        // (impact::hold_step), not here: the lane is the CPU's.
        chattering.push(flag(var("FLAG_SLIDING")));
    }
    body.extend([
        Stmt::If(
            differs(dot("w", "y"), var("y1")),
            vec![
                Stmt::SetMember("tr", "y", dot("w", "y")),
                Stmt::SetMember("tr", "comp", zero(State)),
            ],
            vec![
                Stmt::SetMember("tr", "y", var("y1")),
                Stmt::SetMember("tr", "comp", var("comp1")),
            ],
        ),
        Stmt::Var("counts", dot("tr", "c")),
        Stmt::SetAt(
            "counts",
            count(IMPACTS),
            index(var("counts"), count(IMPACTS)) + dot("w", "impacts"),
        ),
        Stmt::SetMember("tr", "c", var("counts")),
        Stmt::SetMember(
            "tr",
            "slowest",
            min(dot("tr", "slowest"), dot("w", "slowest")),
        ),
        Stmt::If(dot("w", "chattering"), chattering, Vec::new()),
        flag(apply("rank_flags", vec![dot("w", "rank_loss")])),
    ]);
    Function {
        name: "record",
        params: vec![
            ("tr_in", Ty::Struct("Trajectory")),
            ("w", Ty::Struct("WallStep")),
            ("y1", State),
            ("comp1", State),
        ],
        body,
        results: vec![("tr", var("tr"))],
        returns: None,
    }
}

/// The step from tr (its plain RK4 image y1, with compensation comp1)
/// that meets a stop or surface, or starts at rest on a stop:
/// resolve_impacts applies its events, and a mass at rest, from the
/// step's start or from an impact inside it, takes (the rest of) the step
/// in stuck_step, called here only (see resolve_impacts). Released from a
/// stop in a model with surfaces, the CPU resolves the rest of the step
/// with its surfaces, where stuck_step takes one plain step: the lane is
/// the CPU's (flagged sliding), as a motion the kernels cannot slide.
fn resolve_step(surfaces: bool) -> Function {
    use Ty::{CountTable, State};
    let step = |m| dot("step", m);
    let tr = |m| dot("tr", m);
    let mut resolved = vec![
        Stmt::Let(
            "w",
            apply(
                "resolve_impacts",
                vec![
                    var("p"),
                    var("walls"),
                    step("omega"),
                    tr("phase"),
                    tr("y"),
                    step("h"),
                    var("y1"),
                ],
            ),
        ),
        Stmt::Set("tr", call("record", &["tr", "w", "y1", "comp1"])),
        Stmt::Set("crossings", dot("w", "crossings")),
    ];
    if surfaces {
        resolved.push(Stmt::SetMember("p", "region", tr("region")));
    }
    resolved.extend([
        Stmt::Set("stuck", dot("w", "stuck")),
        Stmt::Set("rest_at", dot("w", "rest_at")),
        Stmt::Set("rest_phase", dot("w", "rest_phase")),
    ]);
    let mut held = Vec::new();
    if surfaces {
        held.push(flag(var("FLAG_SLIDING")));
    }
    held.extend([
        Stmt::Let(
            "rest",
            apply(
                "stuck_step",
                vec![
                    var("p"),
                    var("walls"),
                    var("stuck"),
                    step("omega"),
                    var("rest_phase"),
                    tr("y"),
                    step("h") - var("rest_at"),
                ],
            ),
        ),
        Stmt::SetMember("tr", "y", dot("rest", "y")),
        Stmt::SetMember("tr", "comp", zero(State)),
        flag(apply("rank_flags", vec![dot("rest", "rank_loss")])),
    ]);
    let mut body = Vec::new();
    if surfaces {
        // A copy, whose region follows the crossings.
        body.push(Stmt::Var("p", var("p_lane")));
    }
    let half = || step("half");
    body.extend([
        Stmt::Var("tr", var("tr_in")),
        Stmt::Let(
            "next_phase",
            apply(
                "rotate",
                vec![apply("rotate", vec![tr("phase"), half()]), half()],
            ),
        ),
        Stmt::Var("stuck", apply("resting_on", vec![var("walls"), tr("y")])),
        Stmt::Var("rest_at", num(0.0)),
        Stmt::Var("rest_phase", tr("phase")),
        Stmt::Var("crossings", zero(CountTable)),
        Stmt::If(
            cmp(Cmp::Equal, var("stuck"), var("WALLS")),
            resolved,
            Vec::new(),
        ),
        Stmt::If(less(var("stuck"), var("WALLS")), held, Vec::new()),
        Stmt::SetMember("tr", "phase", var("next_phase")),
    ]);
    let lane = if surfaces { "p_lane" } else { "p" };
    Function {
        name: "resolve_step",
        params: vec![
            (lane, Ty::Struct("Params")),
            ("walls", Ty::Struct("Stops")),
            ("step", Ty::Struct("Stepping")),
            ("y1", State),
            ("comp1", State),
            ("tr_in", Ty::Struct("Trajectory")),
        ],
        body,
        results: vec![(
            "resolved",
            make("Resolved", vec![var("tr"), var("crossings")]),
        )],
        returns: None,
    }
}
