//! The kernels' step programs of the step loop that resolves a step's
//! events (in the language of `model::ir::step`): a mass held on a stop
//! and its release, the first stop or surface met in a step, an impact and
//! a crossing applied, and the loop over a step's events. Printed to WGSL
//! by `model::codegen::step` for a model with stops; the CPU runs their
//! Rust twins, which are the oracle (`integrate::impact`'s resolve,
//! stuck_step and cross).
//!
//! What differs between the kernels' variants (general surfaces or not,
//! Newton's location or the linear one) is chosen here, where the
//! program is built ([`functions`]), not in the text: the kernels' old
//! `#ifdef`s.
//!
//! Two things the kernels do differently from the CPU, kept as they are:
//! after a release from a stop, the rest of the step is one plain RK4 step
//! (WGSL has no recursion), and bounces accumulate by the kernels' own
//! test (`ACCUMULATION`).

use super::step::build::*;
use super::step::{Cmp, Expr, Extern, Function, Stmt, Structure, Ty};

/// The fraction of a step within which bounces that accumulate end at
/// rest: the CPU's `ACCUMULATION_FRACTION` (`integrate::impact::hold`),
/// which the kernels have always read as a 32-bit float.
const ACCUMULATION: f64 = 1e-3f32 as f64;

/// What the step loop's functions use of the kernels: `NO_IMPACT`, the
/// slowest impact speed of a step without impacts (the trajectory
/// buffer's reading of "none").
pub fn kernels() -> Vec<Extern> {
    vec![Extern::Const("NO_IMPACT", Ty::Real)]
}

/// The names of every function [`functions`] gives, in any variant.
pub const FUNCTIONS: [&str; 11] = [
    "held_for",
    "stuck_step",
    "locate",
    "locate_stop",
    "earlier",
    "first_met",
    "impact",
    "resolved",
    "cross_surface",
    "resolve_impacts",
    "neutral_crossed",
];

/// The names of every structure [`structures`] gives.
pub const STRUCTURES: [&str; 4] = ["WallStep", "Met", "Resolution", "Crossed"];

/// The structures of the step loop (with general surfaces where
/// `surfaces`):
///
/// - `Crossed`: what a step did to the surfaces, beside its stops: the
///   region it ends in, Σ ln |det S| of its crossings, whether one could
///   not be resolved (sliding), and the sliding phases entered
///   (IterationStats::sliding_phases).
/// - `WallStep`: a step's outcome: its end `y`, its impacts and, per
///   event, its crossings; whether it chattered; the dimensions collapsed
///   (`rank_loss`: 1 after an impact with e = 0, 2 after sticking, all of
///   them with two states); the slowest approach speed of its impacts
///   (`NO_IMPACT` if none); from resolve_impacts, the stop the mass came
///   to rest on (`stuck`, `WALLS`: none) `rest_at` into the step at
///   `rest_phase`, in the state `y` (its stop's reset not applied), from
///   where stuck_step takes the rest of the step; and `crossed`.
/// - `Met`: the first stop (or surface) met in a step, and where.
/// - `Resolution`: resolve_impacts' account of its step so far (the locals
///   of the CPU's resolve): how far into the step its events reach
///   (`done`), the phase and state there, what they did; `restep`: the
///   rest of the step from there is to be stepped at the top of the next
///   pass; with surfaces, `unresolved` (a crossing flagged, which ends the
///   step once its rest is taken), whether it was a chattering one, and
///   `crossed`.
pub fn structures(surfaces: bool) -> Vec<Structure> {
    use Ty::{Bool, Count, CountTable, Pair, Real, State};
    let crossed = Structure {
        name: "Crossed",
        members: vec![
            ("region", Count),
            ("log_flux", Real),
            ("sliding", Bool),
            ("sliding_phases", Count),
        ],
    };
    let mut wall_step = Structure {
        name: "WallStep",
        members: vec![
            ("y", State),
            ("impacts", Count),
            ("crossings", CountTable),
            ("chattering", Bool),
            ("rank_loss", Count),
            ("slowest", Real),
            ("stuck", Count),
            ("rest_at", Real),
            ("rest_phase", Pair),
        ],
    };
    let met = Structure {
        name: "Met",
        members: vec![("hit", Ty::Struct("Hit")), ("stop", Count)],
    };
    let mut resolution = Structure {
        name: "Resolution",
        members: vec![
            ("done", Real),
            ("phase0", Pair),
            ("y0", State),
            ("impacts", Count),
            ("crossings", CountTable),
            ("slowest", Real),
            ("rank_loss", Count),
            ("stuck", Count),
            ("restep", Bool),
        ],
    };
    let mut all = Vec::new();
    if surfaces {
        wall_step.members.push(("crossed", Ty::Struct("Crossed")));
        resolution.members.extend([
            ("unresolved", Bool),
            ("chattering", Bool),
            ("crossed", Ty::Struct("Crossed")),
        ]);
        all.push(crossed);
    }
    all.extend([wall_step, met, resolution]);
    all
}

/// Every function of the step loop, callees first, for a kernel with
/// general surfaces (`surfaces`) and Newton's location (`newton`, else
/// the linear one):
///
/// - `held_for(p, w, omega, phase, rest, s)`: the state held on stop w
///   for s from `rest` at `phase`: `rest` itself with two states, else one
///   RK4 step of the held flow for the others (the CPU's rk4::step of
///   Held).
/// - `stuck_step(p, walls, j, omega, phase, y, h)`: see [`stuck_step`].
/// - `locate(p, omega, walls, which, phase0, y0, h, y1, start, end)`:
///   event `which`'s crossing in the rest of a step, given its value and
///   rate at both ends (Newton's or the linear location).
/// - `locate_stop(p, omega, walls, j, phase0, y0, h, y1)`: stop j's.
/// - `earlier(met, found, j)`: `met`, or event j's hit if found earlier
///   (on a tie the lower index, as on the CPU).
/// - `first_met(p, walls, omega, phase0, y0, h, y1)`: the first stop or
///   surface met in the step [0, h] (none: `WALLS + SURFACES`).
/// - `impact`, `cross_surface`, `resolved`, `resolve_impacts`: see
///   [`impact`], [`cross_surface`], [`resolved`], [`resolve_impacts`].
pub fn functions(surfaces: bool, newton: bool) -> Vec<Function> {
    let mut all = vec![held_for(), stuck_step(surfaces)];
    all.extend(locate(newton));
    all.extend(met(surfaces));
    all.push(impact());
    all.push(resolved(surfaces));
    if surfaces {
        all.push(neutral_crossed());
        all.push(cross_surface());
    }
    all.push(resolve_impacts(surfaces));
    all
}

/// The lane's parameters, the stops and the forcing's ω.
fn params() -> Ty {
    Ty::Struct("Params")
}

fn stops() -> Ty {
    Ty::Struct("Stops")
}

/// `held_for` (see [`functions`]).
fn held_for() -> Function {
    use Ty::{Pair, Real, State};
    let held = apply(
        "held_sub_step",
        vec![var("omega"), var("phase"), var("rest"), var("s")],
    );
    Function::one(
        "held_for",
        vec![
            ("p", params()),
            ("w", Ty::Struct("Stop")),
            ("omega", Real),
            ("phase", Pair),
            ("rest", State),
            ("s", Real),
        ],
        vec![
            Stmt::Var("out", var("rest")),
            Stmt::If(
                cmp(Cmp::NotEqual, var("DIM"), count(2)),
                vec![Stmt::Set("out", member(held, "y"))],
                Vec::new(),
            ),
        ],
        ("y", var("out")),
    )
}

/// A crossing of no surface: the region it starts in, nothing else (what
/// a step that meets no surface leaves).
fn neutral_crossed() -> Function {
    Function::one(
        "neutral_crossed",
        vec![("region", Ty::Count)],
        Vec::new(),
        (
            "crossed",
            make(
                "Crossed",
                vec![var("region"), num(0.0), truth(false), count(0)],
            ),
        ),
    )
}

/// A `WallStep` of these members, `crossed` last with surfaces.
fn wall_step(surfaces: bool, mut members: Vec<Expr>, crossed: Expr) -> Expr {
    if surfaces {
        members.push(crossed);
    }
    make("WallStep", members)
}

/// `pressing(w, phase, y) > 0`, negated as the CPU's `<= 0` (NaN takes
/// the same branch).
fn presses(phase: Expr, y: Expr) -> Expr {
    not(cmp(
        Cmp::LessEq,
        apply("pressing", vec![var("w"), phase, y]),
        num(0.0),
    ))
}

/// The phase turned through ω·s from `phase`.
fn turned(phase: Expr, s: Expr) -> Expr {
    apply(
        "rotate",
        vec![phase, apply("cos_sin", vec![var("omega") * s])],
    )
}

/// The state held on the stop for s from rest (`held_for`).
fn held_at(s: Expr) -> Expr {
    apply(
        "held_for",
        vec![
            var("p"),
            var("w"),
            var("omega"),
            var("phase"),
            var("rest"),
            s,
        ],
    )
}

/// stuck_step's release: the force reverses inside the step, found by
/// bisection, and the plain step starts there.
fn release() -> Vec<Stmt> {
    vec![
        Stmt::Var("lo", num(0.0)),
        Stmt::Var("hi", var("h")),
        Stmt::Var("k", count(0)),
        Stmt::Loop(vec![
            break_unless(less(var("k"), count(64))),
            Stmt::Let("mid", num(0.5) * (var("lo") + "hi")),
            Stmt::Let("at", turned(var("phase"), var("mid"))),
            Stmt::If(
                greater(
                    apply("pressing", vec![var("w"), var("at"), held_at(var("mid"))]),
                    num(0.0),
                ),
                vec![Stmt::Set("lo", var("mid"))],
                vec![Stmt::Set("hi", var("mid"))],
            ),
            Stmt::If(
                cmp(Cmp::LessEq, var("hi") - "lo", var("EPSILON") * "h"),
                vec![Stmt::Break],
                Vec::new(),
            ),
            Stmt::Set("k", var("k") + count(1)),
        ]),
        Stmt::Set("start_phase", turned(var("phase"), var("hi"))),
        Stmt::Set("start", held_at(var("hi"))),
        Stmt::Set("left", var("h") - "hi"),
    ]
}

/// A step of size h from rest on stop j (y moved onto it): the mass stays
/// while the force presses it there (the other coordinates move on) and
/// leaves when the force reverses (bisection for the release, at most 64
/// halvings). Twin of stuck_step in `integrate::impact::resolve`, except
/// that the rest of the step after a release (or a free departure) is one
/// plain RK4 step held off the stops (WGSL has no recursion; the force
/// pulls away right after a release); that step is the one call of
/// sub_step (NIR inlines every call site).
fn stuck_step(surfaces: bool) -> Function {
    use Ty::{Count, Pair, Real, State};
    let pressed = vec![
        Stmt::Set(
            "rank_loss",
            select(less(var("DIM"), count(2)), var("DIM"), count(2)),
        ),
        Stmt::Let("held", held_at(var("h"))),
        Stmt::If(
            presses(turned(var("phase"), var("h")), var("held")),
            vec![
                Stmt::Set("out", var("held")),
                Stmt::Set("stays", truth(true)),
            ],
            release(),
        ),
    ];
    let step = member(
        apply(
            "sub_step",
            vec![var("omega"), var("start_phase"), var("start"), var("left")],
        ),
        "y",
    );
    let body = vec![
        Stmt::Let("w", apply("stop", vec![var("walls"), var("j")])),
        Stmt::Let("rest", apply("on_stop", vec![var("w"), var("y"), num(0.0)])),
        // The plain step that ends the step, from `start` at
        // `start_phase` for `left`: of the whole step on a free
        // departure, of its rest after a release.
        Stmt::Var("start", var("rest")),
        Stmt::Var("start_phase", var("phase")),
        Stmt::Var("left", var("h")),
        Stmt::Var("rank_loss", count(0)),
        Stmt::Var("out", var("rest")),
        // Held on the stop for the whole step.
        Stmt::Var("stays", truth(false)),
        Stmt::If(presses(var("phase"), var("rest")), pressed, Vec::new()),
        Stmt::If(
            not(var("stays")),
            vec![Stmt::Set(
                "out",
                apply("clamp_to_stops", vec![var("walls"), step]),
            )],
            Vec::new(),
        ),
    ];
    let result = wall_step(
        surfaces,
        vec![
            var("out"),
            count(0),
            zero(Ty::CountTable),
            truth(false),
            var("rank_loss"),
            var("NO_IMPACT"),
            var("WALLS"),
            var("h"),
            var("phase"),
        ],
        apply("neutral_crossed", vec![dot("p", "region")]),
    );
    Function::one(
        "stuck_step",
        vec![
            ("p", params()),
            ("walls", stops()),
            ("j", Count),
            ("omega", Real),
            ("phase", Pair),
            ("y", State),
            ("h", Real),
        ],
        body,
        ("step", result),
    )
}

/// The parameters of a location in the rest of a step [0, h] from
/// (phase0, y0) to y1.
fn rest_of_step() -> Vec<(&'static str, Ty)> {
    use Ty::{Pair, Real, State};
    vec![("phase0", Pair), ("y0", State), ("h", Real), ("y1", State)]
}

/// `locate` and `locate_stop` (see [`functions`]). Events are numbered
/// as first_met's: the stops, then the general surfaces (which - WALLS);
/// stops and surfaces share every location, and only event_at,
/// event_scale and crossing_fraction tell them apart.
fn locate(newton: bool) -> [Function; 2] {
    use Ty::{Count, Pair, Real};
    let mut params = vec![
        ("p", params()),
        ("omega", Real),
        ("walls", stops()),
        ("which", Count),
    ];
    params.extend(rest_of_step());
    params.extend([("start", Pair), ("end", Pair)]);
    let located = if newton {
        let all = [
            "p", "omega", "walls", "which", "phase0", "y0", "h", "y1", "start", "end",
        ];
        call("locate_newton", &all)
    } else {
        call(
            "locate_linear",
            &["walls", "which", "y0", "h", "y1", "start", "end"],
        )
    };
    let locate = Function::one("locate", params, Vec::new(), ("hit", located));
    let mut params = vec![
        ("p", self::params()),
        ("omega", Real),
        ("walls", stops()),
        ("j", Count),
    ];
    params.extend(rest_of_step());
    let values = |y| apply("stop_values", vec![var("w"), var(y)]);
    let hit = apply(
        "locate",
        vec![
            var("p"),
            var("omega"),
            var("walls"),
            var("j"),
            var("phase0"),
            var("y0"),
            var("h"),
            var("y1"),
            values("y0"),
            values("y1"),
        ],
    );
    let stop = Function::one(
        "locate_stop",
        params,
        lets(vec![("w", apply("stop", vec![var("walls"), var("j")]))]),
        ("hit", hit),
    );
    [locate, stop]
}

/// The index of no event: past the stops and the general surfaces.
fn none_met(surfaces: bool) -> Expr {
    if surfaces {
        var("WALLS") + "SURFACES"
    } else {
        var("WALLS")
    }
}

/// `earlier` and `first_met` (see [`functions`]), written out per stop
/// and per surface rather than as loops over them, as the step loop's
/// tests are: a loop of one pass (the seed's single stop) still cost
/// lavapipe 10% of the whole kernel's time.
fn met(surfaces: bool) -> [Function; 2] {
    use Ty::{Count, Real};
    let earlier = Function::one(
        "earlier",
        vec![
            ("met", Ty::Struct("Met")),
            ("found", Ty::Struct("Hit")),
            ("j", Count),
        ],
        vec![
            Stmt::Var("out", var("met")),
            Stmt::If(
                and(
                    dot("found", "found"),
                    or(
                        cmp(Cmp::Equal, dot("met", "stop"), none_met(surfaces)),
                        less(dot("found", "s"), member(dot("met", "hit"), "s")),
                    ),
                ),
                vec![Stmt::Set("out", make("Met", vec![var("found"), var("j")]))],
                Vec::new(),
            ),
        ],
        ("met", var("out")),
    );
    let args = |j: u32| {
        vec![
            var("p"),
            var("omega"),
            var("walls"),
            count(j),
            var("phase0"),
            var("y0"),
            var("h"),
            var("y1"),
        ]
    };
    let sooner =
        |found: Expr, j: Expr| Stmt::Set("met", apply("earlier", vec![var("met"), found, j]));
    let mut body = vec![Stmt::Var(
        "met",
        make(
            "Met",
            vec![
                make("Hit", vec![truth(false), num(0.0), var("y0")]),
                none_met(surfaces),
            ],
        ),
    )];
    for j in 0..4 {
        body.push(Stmt::If(
            greater(var("WALLS"), count(j)),
            vec![sooner(apply("locate_stop", args(j)), count(j))],
            Vec::new(),
        ));
    }
    if surfaces {
        // The surfaces' values at both ends of the rest of the step, in
        // the trajectory's region (a surface may move with the forcing).
        body.extend(lets(vec![
            (
                "before",
                apply("surface_values", vec![var("p"), var("phase0"), var("y0")]),
            ),
            (
                "after",
                apply(
                    "surface_values",
                    vec![var("p"), turned(var("phase0"), var("h")), var("y1")],
                ),
            ),
        ]));
        for j in 0..4 {
            let mut located = args(j);
            located.extend([var("before"), var("after")]);
            let at = if j == 0 {
                var("WALLS")
            } else {
                var("WALLS") + count(j)
            };
            let one = sooner(apply("locate_surface", located), at);
            body.push(if j == 0 {
                one
            } else {
                Stmt::If(greater(var("SURFACES"), count(j)), vec![one], Vec::new())
            });
        }
    }
    let mut params = vec![("p", params()), ("walls", stops()), ("omega", Real)];
    params.extend(rest_of_step());
    let first = Function::one("first_met", params, body, ("met", var("met")));
    [earlier, first]
}

/// `r.crossings[at] + 1`, set.
fn count_crossing(at: Expr) -> Vec<Stmt> {
    vec![
        Stmt::Var("crossings", dot("r", "crossings")),
        Stmt::SetAt(
            "crossings",
            at.clone(),
            index(var("crossings"), at) + count(1),
        ),
        Stmt::SetMember("r", "crossings", var("crossings")),
    ]
}

/// Stop met.stop's impact at met.hit (the stop branch of resolve): the
/// mass arriving at rest, or with bounces accumulating, stays on the stop
/// (r.stuck); else it rebounds, V -> -e·V, and the rest of the step is
/// stepped again. Bounces accumulate within a sliver of the step where
/// 2v/(a(1 - e)), all of them, is under `ACCUMULATION` of it; e = 0
/// stops the mass dead.
fn impact() -> Function {
    use Ty::Real;
    let hit = |m: &'static str| member(dot("met", "hit"), m);
    let stays = |rank_loss: bool| {
        let mut out = Vec::new();
        if rank_loss {
            out.push(Stmt::SetMember("r", "rank_loss", count(1)));
        }
        out.extend([
            Stmt::SetMember("r", "y0", hit("y")),
            Stmt::SetMember("r", "stuck", dot("met", "stop")),
        ]);
        out
    };
    let accumulate = or(
        cmp(Cmp::Equal, var("rebound"), num(0.0)),
        and(
            greater(var("push"), num(0.0)),
            less(
                num(2.0) * var("rebound"),
                num(ACCUMULATION) * "h" * "push" * (num(1.0) - "e"),
            ),
        ),
    );
    let mut rebounds = vec![Stmt::SetMember(
        "r",
        "impacts",
        dot("r", "impacts") + count(1),
    )];
    rebounds.extend(count_crossing(dot("met", "stop")));
    rebounds.push(Stmt::SetMember(
        "r",
        "slowest",
        min(dot("r", "slowest"), var("v")),
    ));
    rebounds.extend(lets(vec![
        ("e", dot("w", "restitution")),
        ("rebound", var("e") * "v"),
        (
            "push",
            apply("pressing", vec![var("w"), var("phase_c"), hit("y")]),
        ),
    ]));
    rebounds.push(Stmt::If(
        accumulate,
        stays(true),
        vec![
            Stmt::SetMember(
                "r",
                "y0",
                apply("on_stop", vec![var("w"), hit("y"), neg(var("rebound"))]),
            ),
            Stmt::SetMember("r", "restep", truth(true)),
        ],
    ));
    let body = vec![
        Stmt::Var("r", var("r_in")),
        Stmt::Let("w", apply("stop", vec![var("walls"), dot("met", "stop")])),
        Stmt::Let("phase_c", turned(dot("r", "phase0"), hit("s"))),
        Stmt::Let("v", apply("speed", vec![var("w"), hit("y")])),
        Stmt::SetMember("r", "done", dot("r", "done") + hit("s")),
        Stmt::SetMember("r", "phase0", var("phase_c")),
        // Arriving at rest, pressed into the stop: it sticks.
        Stmt::If(cmp(Cmp::LessEq, var("v"), num(0.0)), stays(false), rebounds),
    ];
    Function::one(
        "impact",
        vec![
            ("p", params()),
            ("walls", stops()),
            ("omega", Real),
            ("met", Ty::Struct("Met")),
            ("h", Real),
            ("r_in", Ty::Struct("Resolution")),
        ],
        body,
        ("r", var("r")),
    )
}

/// The step's outcome once resolve_impacts' loop has ended (`ending`:
/// 0 no further event in the step, 1 at rest on stop r.stuck, 2 out of
/// impacts): at rest on a stop, with the rest of the step to stuck_step;
/// at y1 after the last event; or, out of impacts, at rest if a force
/// presses the mass onto a stop (bounces this dense under a pressing
/// force), else chattering, clamped to the stops.
fn resolved(surfaces: bool) -> Function {
    use Ty::{Count, Real, State};
    let r = |m| dot("r", m);
    let outcome = |y: Expr, chattering: bool, stuck: Expr, at: Expr| {
        wall_step(
            surfaces,
            vec![
                y,
                r("impacts"),
                r("crossings"),
                truth(chattering),
                r("rank_loss"),
                r("slowest"),
                stuck,
                at,
                r("phase0"),
            ],
            r("crossed"),
        )
    };
    let at_y1 = outcome(var("y1"), false, var("WALLS"), var("h"));
    let at_rest = outcome(r("y0"), false, var("stuck"), r("done"));
    let clamped = apply("clamp_to_stops", vec![var("walls"), var("y1")]);
    let chattering = outcome(clamped, true, var("WALLS"), var("h"));
    let ending = |n| cmp(Cmp::Equal, var("ending"), count(n));
    let body = vec![
        Stmt::Var("ending", var("ending_in")),
        Stmt::Var("stuck", r("stuck")),
        Stmt::If(
            ending(2),
            vec![
                Stmt::Set(
                    "stuck",
                    apply("pressed_on", vec![var("walls"), r("phase0"), r("y0")]),
                ),
                Stmt::If(
                    less(var("stuck"), var("WALLS")),
                    vec![Stmt::Set("ending", count(1))],
                    Vec::new(),
                ),
            ],
            Vec::new(),
        ),
        Stmt::Var("out", at_y1),
        Stmt::If(
            ending(1),
            vec![Stmt::Set("out", at_rest)],
            vec![Stmt::If(
                not(ending(0)),
                vec![Stmt::Set("out", chattering)],
                Vec::new(),
            )],
        ),
    ];
    Function::one(
        "resolved",
        vec![
            ("p", params()),
            ("walls", stops()),
            ("h", Real),
            ("y1", State),
            ("r", Ty::Struct("Resolution")),
            ("ending_in", Count),
        ],
        body,
        ("step", var("out")),
    )
}

/// `r.crossed` with the members `changed` given new values.
fn set_crossed(changed: &[(&str, Expr)]) -> Stmt {
    let members = ["region", "log_flux", "sliding", "sliding_phases"].map(|m| {
        changed
            .iter()
            .find(|(c, _)| *c == m)
            .map(|(_, e)| e.clone())
            .unwrap_or_else(|| member(dot("r", "crossed"), m))
    });
    Stmt::SetMember("r", "crossed", make("Crossed", members.to_vec()))
}

/// General surface met.stop - WALLS crossed at met.hit (the surface
/// branch of resolve): the crossing applied, counted and, in r.crossed,
/// its region, ln |det S| and flags; the rest of the step is stepped
/// again unless the motion now slides (resolve_impacts' next pass slides
/// it). A crossing flagged unresolved takes the rest of the step in the
/// field now in force, and the step ends there.
fn cross_surface() -> Function {
    use Ty::Real;
    let hit = |m: &'static str| member(dot("met", "hit"), m);
    let crossing = |m| dot("crossing", m);
    let crossed = |m| member(dot("r", "crossed"), m);
    let body = vec![
        Stmt::Var("r", var("r_in")),
        Stmt::Let("phase_c", turned(dot("r", "phase0"), hit("s"))),
        Stmt::SetMember("r", "done", dot("r", "done") + hit("s")),
        Stmt::Let(
            "crossing",
            apply(
                "cross",
                vec![
                    var("p"),
                    dot("met", "stop") - "WALLS",
                    var("phase_c"),
                    hit("y"),
                ],
            ),
        ),
        Stmt::SetMember(
            "r",
            "slowest",
            min(dot("r", "slowest"), crossing("approach")),
        ),
        Stmt::If(
            crossing("counted"),
            count_crossing(dot("met", "stop")),
            Vec::new(),
        ),
        Stmt::If(
            and(crossing("rank_loss"), less(dot("r", "rank_loss"), count(1))),
            vec![Stmt::SetMember("r", "rank_loss", count(1))],
            Vec::new(),
        ),
        set_crossed(&[
            ("region", crossing("region")),
            ("log_flux", crossed("log_flux") + crossing("log_det")),
            ("sliding", or(crossed("sliding"), crossing("sliding"))),
        ]),
        Stmt::SetMember("r", "phase0", var("phase_c")),
        Stmt::If(
            not(crossing("resolved")),
            vec![
                Stmt::SetMember("r", "y0", hit("y")),
                Stmt::SetMember("r", "restep", truth(true)),
                Stmt::SetMember("r", "unresolved", truth(true)),
                Stmt::SetMember("r", "chattering", crossing("chattering")),
            ],
            vec![
                Stmt::If(
                    crossing("slides"),
                    vec![set_crossed(&[(
                        "sliding_phases",
                        crossed("sliding_phases") + count(1),
                    )])],
                    Vec::new(),
                ),
                Stmt::SetMember("r", "y0", crossing("y")),
                Stmt::SetMember(
                    "r",
                    "restep",
                    not(apply("is_sliding", vec![crossing("region")])),
                ),
            ],
        ),
    ];
    Function::one(
        "cross_surface",
        vec![
            ("p", params()),
            ("omega", Real),
            ("met", Ty::Struct("Met")),
            ("r_in", Ty::Struct("Resolution")),
        ],
        body,
        ("r", var("r")),
    )
}

/// A pass of resolve_impacts on a switch (twin of the sliding branch of
/// resolve): the rest of the step slides, unless the motion leaves it.
fn slides() -> Vec<Stmt> {
    let slid = |m| dot("slid", m);
    let r = |m| dot("r", m);
    let slid_to_the_end = make(
        "WallStep",
        vec![
            slid("y"),
            r("impacts"),
            r("crossings"),
            truth(false),
            r("rank_loss"),
            r("slowest"),
            var("WALLS"),
            var("h"),
            r("phase0"),
            r("crossed"),
        ],
    );
    vec![
        Stmt::Let(
            "slid",
            apply(
                "slide",
                vec![
                    var("p"),
                    var("omega"),
                    r("phase0"),
                    r("y0"),
                    var("h") - r("done"),
                ],
            ),
        ),
        set_crossed(&[(
            "sliding",
            or(member(r("crossed"), "sliding"), slid("flagged")),
        )]),
        Stmt::If(
            not(slid("leaves")),
            vec![
                Stmt::Set("out", slid_to_the_end),
                Stmt::Set("returned", truth(true)),
                Stmt::Break,
            ],
            Vec::new(),
        ),
        Stmt::SetMember("r", "done", r("done") + slid("s")),
        Stmt::SetMember("r", "phase0", turned(r("phase0"), slid("s"))),
        Stmt::SetMember("r", "y0", slid("y")),
        Stmt::SetMember("p", "region", slid("region")),
        set_crossed(&[("region", slid("region"))]),
        Stmt::SetMember("r", "restep", truth(true)),
    ]
}

/// A pass of resolve_impacts that looks for the first event and hands it
/// to impact or cross_surface.
fn meets(surfaces: bool) -> Vec<Stmt> {
    let r = |m| dot("r", m);
    let mut impact = vec![
        Stmt::Set(
            "r",
            call("impact", &["p", "walls", "omega", "met", "h", "r"]),
        ),
        Stmt::If(
            less(r("stuck"), var("WALLS")),
            vec![Stmt::Set("ending", count(1)), Stmt::Break],
            Vec::new(),
        ),
    ];
    if surfaces {
        // The rebound may jump across a switch (a velocity reversed
        // across a friction's slip): the field after it is that side's.
        impact.extend([
            Stmt::SetMember(
                "p",
                "region",
                apply(
                    "jumped",
                    vec![
                        var("p"),
                        r("phase0"),
                        member(dot("met", "hit"), "y"),
                        r("y0"),
                    ],
                ),
            ),
            set_crossed(&[("region", dot("p", "region"))]),
        ]);
    }
    let mut out = vec![
        Stmt::Let(
            "met",
            apply(
                "first_met",
                vec![
                    var("p"),
                    var("walls"),
                    var("omega"),
                    r("phase0"),
                    r("y0"),
                    var("h") - r("done"),
                    var("y1"),
                ],
            ),
        ),
        Stmt::If(
            cmp(Cmp::Equal, dot("met", "stop"), none_met(surfaces)),
            vec![Stmt::Set("ending", count(0)), Stmt::Break],
            Vec::new(),
        ),
    ];
    if surfaces {
        out.push(Stmt::If(
            cmp(Cmp::GreaterEq, dot("met", "stop"), var("WALLS")),
            vec![
                Stmt::Set("r", call("cross_surface", &["p", "omega", "met", "r"])),
                Stmt::SetMember("p", "region", member(r("crossed"), "region")),
            ],
            impact,
        ));
    } else {
        out.extend(impact);
    }
    out
}

/// The step ended at y1 after the events so far.
fn ended(surfaces: bool, chattering: Expr) -> Expr {
    let r = |m| dot("r", m);
    wall_step(
        surfaces,
        vec![
            var("y1"),
            r("impacts"),
            r("crossings"),
            chattering,
            r("rank_loss"),
            r("slowest"),
            var("WALLS"),
            var("h"),
            r("phase0"),
        ],
        r("crossed"),
    )
}

/// A pass of resolve_impacts' loop: the rest of the step stepped where
/// the last event asks, then the next event handled.
fn pass(surfaces: bool) -> Vec<Stmt> {
    let most = crate::integrate::impact::MAX_IMPACTS_PER_STEP;
    let r = |m| dot("r", m);
    let mut pass = vec![
        break_unless(cmp(Cmp::LessEq, var("n"), count(most))),
        Stmt::If(
            r("restep"),
            vec![
                Stmt::Set(
                    "y1",
                    member(
                        apply(
                            "sub_step",
                            vec![var("omega"), r("phase0"), r("y0"), var("h") - r("done")],
                        ),
                        "y",
                    ),
                ),
                Stmt::SetMember("r", "restep", truth(false)),
            ],
            Vec::new(),
        ),
    ];
    if surfaces {
        pass.push(Stmt::If(
            r("unresolved"),
            vec![
                Stmt::Set("out", ended(surfaces, r("chattering"))),
                Stmt::Set("returned", truth(true)),
                Stmt::Break,
            ],
            Vec::new(),
        ));
    }
    pass.push(Stmt::If(
        cmp(Cmp::Equal, var("n"), count(most)),
        vec![Stmt::Break],
        Vec::new(),
    ));
    if surfaces {
        pass.push(Stmt::If(
            apply("is_sliding", vec![dot("p", "region")]),
            slides(),
            meets(true),
        ));
    } else {
        pass.extend(meets(false));
    }
    pass.push(Stmt::Set("n", var("n") + count(1)));
    pass
}

/// Applies every event inside the step [0, h] from (phase, y), whose
/// plain RK4 image y1 reached a stop or turned back inside it (or may
/// cross a surface): the loop of the CPU's resolve, at most
/// `MAX_IMPACTS_PER_STEP` events. Each pass finds the first event and
/// hands it to impact or cross_surface, or slides on a switch; a mass
/// that comes to rest is handed back with `stuck`, and the integrate
/// kernel's one call of stuck_step takes the rest of the step (every
/// inlined copy of its bisection loop costs loop iterations on lavapipe,
/// whose budget per invocation is small: see loop_budget_exhausted).
///
/// The rest of the step from (phase0, y0) is stepped in one place, at
/// the top of a pass: NIR inlines every call, and each call site of
/// sub_step is a copy of the RK4 step (a kernel with switches had four
/// here). The extra pass only steps, so that the last event's rest of the
/// step is taken as before the loop ran out. With surfaces, `p` is a copy
/// of the lane's whose region follows the crossings.
fn resolve_impacts(surfaces: bool) -> Function {
    use Ty::{Pair, Real, State};
    let mut start = vec![
        num(0.0),
        var("phase"),
        var("y"),
        count(0),
        zero(Ty::CountTable),
        var("NO_IMPACT"),
        count(0),
        var("WALLS"),
        truth(false),
    ];
    let mut body = Vec::new();
    if surfaces {
        body.push(Stmt::Var("p", var("p_lane")));
        start.extend([
            truth(false),
            truth(false),
            apply("neutral_crossed", vec![dot("p", "region")]),
        ]);
    }
    body.extend([
        Stmt::Var("r", make("Resolution", start)),
        Stmt::Var("y1", var("y1_plain")),
        // How the loop ended: 0 no further event in the step, 1 at rest
        // on stop r.stuck, 2 out of impacts (see resolved).
        Stmt::Var("ending", count(2)),
        // A step ended inside the loop (flagged, or sliding to its end).
        Stmt::Var("out", ended(surfaces, truth(false))),
        Stmt::Var("returned", truth(false)),
        Stmt::Var("n", count(0)),
        Stmt::Loop(pass(surfaces)),
        Stmt::If(
            not(var("returned")),
            vec![Stmt::Set(
                "out",
                call("resolved", &["p", "walls", "h", "y1", "r", "ending"]),
            )],
            Vec::new(),
        ),
    ]);
    let lane = if surfaces { "p_lane" } else { "p" };
    Function::one(
        "resolve_impacts",
        vec![
            (lane, params()),
            ("walls", stops()),
            ("omega", Real),
            ("phase", Pair),
            ("y", State),
            ("h", Real),
            ("y1_plain", State),
        ],
        body,
        ("step", var("out")),
    )
}

#[cfg(test)]
mod tests {
    use super::super::integrator::integrator;
    use super::*;

    #[test]
    fn every_step_loop_function_is_well_typed() {
        let program = integrator();
        let structure = |name| Ty::Struct(name);
        let expected = [
            ("held_for", Ty::State),
            ("stuck_step", structure("WallStep")),
            ("locate", structure("Hit")),
            ("locate_stop", structure("Hit")),
            ("earlier", structure("Met")),
            ("first_met", structure("Met")),
            ("impact", structure("Resolution")),
            ("resolved", structure("WallStep")),
            ("neutral_crossed", structure("Crossed")),
            ("cross_surface", structure("Resolution")),
            ("resolve_impacts", structure("WallStep")),
        ];
        assert_eq!(expected.len(), FUNCTIONS.len());
        for (name, ty) in expected {
            assert!(FUNCTIONS.contains(&name), "{name}");
            assert_eq!(
                program.function(name).result_types(&program),
                [ty],
                "{name}"
            );
        }
    }

    /// Without general surfaces, neither the crossing of one nor what a
    /// step did to them; with Newton's location, no linear one.
    #[test]
    fn a_variant_has_only_its_parts() {
        let names = |surfaces, newton| -> Vec<&str> {
            functions(surfaces, newton).iter().map(|f| f.name).collect()
        };
        assert!(!names(false, true).contains(&"cross_surface"));
        assert!(names(true, false).contains(&"cross_surface"));
        let members = |s: &Structure| s.members.iter().map(|(m, _)| *m).collect::<Vec<_>>();
        for s in structures(false) {
            assert_ne!(s.name, "Crossed");
            assert!(!members(&s).contains(&"crossed"), "{}", s.name);
        }
        let linear = functions(true, false);
        let locate = linear.iter().find(|f| f.name == "locate").unwrap();
        assert!(matches!(
            locate.results[0].1,
            Expr::Call("locate_linear", _)
        ));
    }
}
