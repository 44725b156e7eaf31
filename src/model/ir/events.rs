//! The kernels' step programs around an event (in the language of
//! `model::ir::step`): a stop's values and the stop test over every stop
//! (`integrate::wall`), and where a crossing lies, the cubic Hermite
//! interpolant's guess and the safeguarded Newton's bracket
//! (`integrate::locate`). Printed to WGSL by `model::codegen::step`; the
//! CPU runs their Rust twins, which are the oracle.
//!
//! Only the kernels print these: the native step loops test their stops
//! with the surfaces' `oriented_*` functions and leave locating to Rust.

use super::step::build::*;
use super::step::{Cmp, Expr, Extern, Function, Stmt, Structure, Ty};

/// The stop (`integrate::wall::Wall`) as the kernels read it: stop j of
/// `WALLS` acts on coordinate `coordinate` (its position X), whose rate is
/// coordinate `velocity`, from side `side` (+1 confines X <= the
/// position, -1 X >= it).
pub fn stop() -> Structure {
    Structure {
        name: "Stop",
        members: vec![
            ("position", Ty::Real),
            ("restitution", Ty::Real),
            ("coordinate", Ty::Count),
            ("velocity", Ty::Count),
            ("side", Ty::Real),
        ],
    }
}

/// A crossing located in a step: whether there is one, how far into
/// the step, and the state there.
pub fn hit() -> Structure {
    Structure {
        name: "Hit",
        members: vec![("found", Ty::Bool), ("s", Ty::Real), ("y", Ty::State)],
    }
}

/// What the events' functions use of the kernels: the lane's `Params`
/// (of which only a trajectory's `region` is read) and every stop's
/// values at them (`Stops`, opaque), the number of stops
/// `WALLS` (a constant of the system file, 0 to 4), the precision's
/// `EPSILON`, `stop(walls, j)`, stop j (shaders/shared/stops.wgsl reads
/// the system file's tables), and an event's value and rate and its
/// scale, `event_at` and `event_scale` (shaders/shared/locate.wgsl: a
/// stop's, or a general surface's where the kernels have them).
pub fn kernels() -> (Vec<Structure>, Vec<Extern>) {
    use Ty::{Count, Pair, Real, State};
    let opaque = |name| Structure {
        name,
        members: Vec::new(),
    };
    let (params, stops) = (Ty::Struct("Params"), Ty::Struct("Stops"));
    let function = |name, params, result| Extern::Fn {
        name,
        params,
        result,
    };
    let externs = vec![
        // The lane's parameters: a trajectory's region is read and set
        // (the surfaces' functions), the rest passed on.
        Extern::Struct("Params", vec![("region", Count)]),
        Extern::Const("DIM", Count),
        Extern::Const("WALLS", Count),
        Extern::Const("EPSILON", Real),
        function("stop", vec![stops, Count], Ty::Struct("Stop")),
        function(
            "event_at",
            vec![params, Real, stops, Count, Pair, Real, State],
            Pair,
        ),
        function("event_scale", vec![stops, Count, State], Pair),
    ];
    (vec![opaque("Stops")], externs)
}

/// The functions of the stops (twins of `Wall`'s and of the step loop's
/// stop test, `integrate::wall`):
///
/// - `gap(w, y)`: how far y lies beyond the stop (> 0: behind it).
/// - `speed(w, y)`: the speed towards it (> 0: approaching).
/// - `on_stop(w, y, v)`: y moved onto it with approach speed v.
/// - `stop_values(w, y)`: (gap, speed), the value and rate its impact is
///   detected and located on, as a surface's oriented (g, rate) is.
/// - `reaches(w, y, h, y1)`: whether the step from y to y1 may meet it
///   (`may_meet`, the stop test shared with the surfaces).
/// - `at_rest(w, y)`: the sticking state, X on the stop and V = 0.
/// - `reaches_a_stop(walls, y, h, y1)`, `resting_on(walls, y)`: the step
///   loop's two tests over every stop, written out per stop rather than
///   as a loop (`WALLS` is a constant, so the branches of absent stops
///   fold away, and a loop inside the step loop would cost every step on
///   lavapipe: docs/BENCHMARKS-GPU.md, "What lavapipe runs"). `resting_on`
///   gives the first stop y rests on, or `WALLS`.
pub fn stops() -> Vec<Function> {
    use Ty::{Real, State};
    let w = ("w", Ty::Struct("Stop"));
    let one =
        |name, params: Vec<(&'static str, Ty)>, body, result: (&'static str, Expr)| Function {
            name,
            params,
            body,
            results: vec![result],
            returns: None,
        };
    let side = || dot("w", "side");
    let gap = one(
        "gap",
        vec![w, ("y", State)],
        Vec::new(),
        (
            "gap",
            side() * (index(var("y"), dot("w", "coordinate")) - dot("w", "position")),
        ),
    );
    let speed = one(
        "speed",
        vec![w, ("y", State)],
        Vec::new(),
        ("speed", side() * index(var("y"), dot("w", "velocity"))),
    );
    let on_stop = one(
        "on_stop",
        vec![w, ("y", State), ("v", Real)],
        vec![
            Stmt::Var("out", var("y")),
            Stmt::SetAt("out", dot("w", "coordinate"), dot("w", "position")),
            Stmt::SetAt("out", dot("w", "velocity"), side() * "v"),
        ],
        ("y", var("out")),
    );
    let values = one(
        "stop_values",
        vec![w, ("y", State)],
        Vec::new(),
        (
            "values",
            pair(call("gap", &["w", "y"]), call("speed", &["w", "y"])),
        ),
    );
    let reaches = one(
        "reaches",
        vec![w, ("y", State), ("h", Real), ("y1", State)],
        Vec::new(),
        (
            "meets",
            apply(
                "may_meet",
                vec![
                    call("stop_values", &["w", "y"]),
                    call("stop_values", &["w", "y1"]),
                    var("h"),
                ],
            ),
        ),
    );
    let at_rest = one(
        "at_rest",
        vec![w, ("y", State)],
        Vec::new(),
        (
            "rests",
            and(
                cmp(
                    Cmp::Equal,
                    index(var("y"), dot("w", "coordinate")),
                    dot("w", "position"),
                ),
                cmp(Cmp::Equal, index(var("y"), dot("w", "velocity")), num(0.0)),
            ),
        ),
    );
    let mut all = vec![gap, speed, on_stop, values, reaches, at_rest];
    all.extend(every_stop());
    all.extend(clamps());
    all.extend(held());
    all
}

/// The state moved back onto the stops (`integrate::impact`'s
/// clamp_to_wall), and its size:
///
/// - `clamp_to(w, y)`: y moved back onto a stop it lies behind, moving
///   towards it at most.
/// - `clamp_to_stops(walls, y)`: onto every stop it lies behind, in their
///   order.
/// - `behind_a_stop(walls, y)`: whether y lies behind a stop (a sliding
///   motion meeting one is flagged, as in the CPU's slide).
/// - `state_scale(y)`: max(1, |y_i|), the size a surface's tolerances are
///   relative to (the CPU's fold over the state).
fn clamps() -> Vec<Function> {
    use Ty::State;
    let walls = ("walls", Ty::Struct("Stops"));
    let behind = |w: Expr, y: &'static str| greater(apply("gap", vec![w, var(y)]), num(0.0));
    let clamp_to = Function {
        name: "clamp_to",
        params: vec![("w", Ty::Struct("Stop")), ("y", State)],
        body: vec![
            Stmt::Var("out", var("y")),
            Stmt::If(
                behind(var("w"), "y"),
                vec![Stmt::Set(
                    "out",
                    apply(
                        "on_stop",
                        vec![
                            var("w"),
                            var("y"),
                            min(call("speed", &["w", "y"]), num(0.0)),
                        ],
                    ),
                )],
                Vec::new(),
            ),
        ],
        results: vec![("y", var("out"))],
        returns: None,
    };
    let mut every = vec![Stmt::Var("out", apply("clamp_to", vec![nth(0), var("y")]))];
    let mut any = vec![Stmt::Var(
        "behind",
        and(greater(var("WALLS"), count(0)), behind(nth(0), "y")),
    )];
    for j in 1..4 {
        let present = greater(var("WALLS"), count(j));
        every.push(Stmt::If(
            present.clone(),
            vec![Stmt::Set(
                "out",
                apply("clamp_to", vec![nth(j), var("out")]),
            )],
            Vec::new(),
        ));
        any.push(Stmt::If(
            present,
            vec![Stmt::Set("behind", or(var("behind"), behind(nth(j), "y")))],
            Vec::new(),
        ));
    }
    let one = |name, body, result: (&'static str, Expr)| Function {
        name,
        params: vec![walls, ("y", State)],
        body,
        results: vec![result],
        returns: None,
    };
    let scale = Function {
        name: "state_scale",
        params: vec![("y", State)],
        body: vec![
            Stmt::Var("scale", num(1.0)),
            Stmt::Var("i", count(0)),
            Stmt::Loop(vec![
                break_unless(less(var("i"), var("DIM"))),
                Stmt::Set("scale", max(var("scale"), abs(index(var("y"), var("i"))))),
                Stmt::Set("i", var("i") + count(1)),
            ]),
        ],
        results: vec![("scale", var("scale"))],
        returns: None,
    };
    vec![
        clamp_to,
        one("clamp_to_stops", every, ("y", var("out"))),
        one("behind_a_stop", any, ("behind", var("behind"))),
        scale,
    ]
}

/// A mass on a stop (`integrate::impact`'s hold):
///
/// - `held_rhs(w, phase, y)`: the flow with the mass held at rest on the
///   stop (`Held`): its position and velocity do not move.
/// - `pressing(w, phase, y)`: the acceleration towards the stop at rest
///   on it (y moved onto it at speed 0): > 0 presses the mass into it.
/// - `pressed(w, phase, y)`: y on the stop, pressed into it.
/// - `pressed_on(walls, phase, y)`: the first stop y lies on with a force
///   pressing it there, or `WALLS`.
fn held() -> Vec<Function> {
    use Ty::{Pair, State};
    let w = ("w", Ty::Struct("Stop"));
    let field = |state: Expr| Expr::Field {
        of: super::step::Field::Model,
        phase: Box::new(var("phase")),
        state: Box::new(state),
    };
    let held_rhs = Function {
        name: "held_rhs",
        params: vec![w, ("phase", Pair), ("y", State)],
        body: vec![
            Stmt::Var("f", field(var("y"))),
            Stmt::SetAt("f", dot("w", "coordinate"), num(0.0)),
            Stmt::SetAt("f", dot("w", "velocity"), num(0.0)),
        ],
        results: vec![("f", var("f"))],
        returns: None,
    };
    let at_rest = apply("on_stop", vec![var("w"), var("y"), num(0.0)]);
    let pressing = Function {
        name: "pressing",
        params: vec![w, ("phase", Pair), ("y", State)],
        body: Vec::new(),
        results: vec![(
            "pressing",
            dot("w", "side") * index(field(at_rest), dot("w", "velocity")),
        )],
        returns: None,
    };
    let pressed = Function {
        name: "pressed",
        params: vec![w, ("phase", Pair), ("y", State)],
        body: Vec::new(),
        results: vec![(
            "pressed",
            and(
                cmp(
                    Cmp::Equal,
                    index(var("y"), dot("w", "coordinate")),
                    dot("w", "position"),
                ),
                greater(call("pressing", &["w", "phase", "y"]), num(0.0)),
            ),
        )],
        returns: None,
    };
    let press = |j: u32| apply("pressed", vec![nth(j), var("phase"), var("y")]);
    let mut first = vec![Stmt::Var("on", var("WALLS"))];
    for j in (1..4).rev() {
        first.push(Stmt::If(
            and(greater(var("WALLS"), count(j)), press(j)),
            vec![Stmt::Set("on", count(j))],
            Vec::new(),
        ));
    }
    first.push(Stmt::If(
        press(0),
        vec![Stmt::Set("on", count(0))],
        Vec::new(),
    ));
    let pressed_on = Function {
        name: "pressed_on",
        params: vec![
            ("walls", Ty::Struct("Stops")),
            ("phase", Pair),
            ("y", State),
        ],
        body: first,
        results: vec![("on", var("on"))],
        returns: None,
    };
    vec![held_rhs, pressing, pressed, pressed_on]
}

/// Stop j of the lane's stops.
fn nth(j: u32) -> Expr {
    apply("stop", vec![var("walls"), count(j)])
}

/// `reaches_a_stop` and `resting_on` (see [`stops`]).
fn every_stop() -> [Function; 2] {
    use Ty::{Real, State};
    let walls = ("walls", Ty::Struct("Stops"));
    let present = |j: u32| greater(var("WALLS"), count(j));
    let reaches = |j: u32| apply("reaches", vec![nth(j), var("y"), var("h"), var("y1")]);
    let mut any = vec![Stmt::Var("hit", reaches(0))];
    for j in 1..4 {
        any.push(Stmt::If(
            present(j),
            vec![Stmt::Set("hit", or(var("hit"), reaches(j)))],
            Vec::new(),
        ));
    }
    let reaches_a_stop = Function {
        name: "reaches_a_stop",
        params: vec![walls, ("y", State), ("h", Real), ("y1", State)],
        body: any,
        results: vec![("hit", var("hit"))],
        returns: None,
    };
    let rests = |j: u32| apply("at_rest", vec![nth(j), var("y")]);
    let mut first = vec![Stmt::Var("on", var("WALLS"))];
    for j in (1..4).rev() {
        first.push(Stmt::If(
            and(present(j), rests(j)),
            vec![Stmt::Set("on", count(j))],
            Vec::new(),
        ));
    }
    first.push(Stmt::If(
        rests(0),
        vec![Stmt::Set("on", count(0))],
        Vec::new(),
    ));
    let resting_on = Function {
        name: "resting_on",
        params: vec![walls, ("y", State)],
        body: first,
        results: vec![("on", var("on"))],
        returns: None,
    };
    [reaches_a_stop, resting_on]
}

/// The structures of the location: the Hermite interpolant's
/// coefficients, and the safeguarded Newton's bracket (whether the step
/// crosses, whether its upper end is the interpolant's peak of an
/// excursion that turns back, the bracket [lo, hi] and the iterate s).
pub fn location_structures() -> [Structure; 2] {
    use Ty::{Bool, Real};
    [
        Structure {
            name: "Hermite",
            members: vec![("c0", Real), ("c1", Real), ("c2", Real), ("c3", Real)],
        },
        Structure {
            name: "Bracket",
            members: vec![
                ("found", Bool),
                ("at_peak", Bool),
                ("lo", Real),
                ("hi", Real),
                ("s", Real),
            ],
        },
    ]
}

/// Where a crossing lies inside a step (`integrate::locate`, the Newton
/// location's guess and update):
///
/// - `hermite_new(g0, v0, g1, v1, h)`: the cubic Hermite interpolant of
///   g over the step, θ in [0, 1], g(θ) = c0 + c1 θ + c2 θ² + c3 θ³
///   (`Hermite::new`); `hermite_value`, `hermite_slope` at θ.
/// - `hermite_peak(c)`: where the slope turns from positive to negative
///   inside (0, 1), or -1 (`Hermite::peak`, in closed form).
/// - `hermite_first_root(c, a, b)`: the first upward root of the cubic
///   in [a, b], Newton's starting guess (`Hermite::first_root`).
/// - `bracket_of(start, end, h)`: the bracket of a step whose (value,
///   rate) goes from start to end, the interpolant's first root the first
///   guess; not found where the step cannot cross (the peak short of 0;
///   a NaN peak counts as found, as the CPU's does).
/// - `newton_update(b, g, rate)`: the bracket shrunk to the side of the
///   root from the value g and rate at b.s, s moved by Newton where that
///   stays inside, else to the middle (`newton_from`'s update).
/// - `locate_newton(p, omega, walls, which, phase0, y0, h, y1, start,
///   end)`: event `which`'s crossing (`locate_newton`, `locate` and
///   `newton_from` in integrate::locate, the same steps in the same
///   order), see [`locate_newton`].
pub fn location() -> Vec<Function> {
    let mut all = hermite();
    all.extend([
        peak(),
        first_root(),
        bracket_of(),
        newton_update(),
        locate_newton(),
    ]);
    all
}

/// The paper's location, linear interpolation between the step's ends
/// (`locate_linear` and the linear branch of `locate` in
/// integrate::locate):
///
/// - `crossing_fraction(walls, which, y0, y1, start, end)`: where the
///   straight line from y0 to y1 crosses event `which`, as a fraction of
///   the step: a stop's from its coordinate and position, a surface's from
///   its values at the ends.
/// - `locate_linear(walls, which, y0, h, y1, start, end)`: the crossing
///   there, if the step ends across.
pub fn linear_location() -> [Function; 2] {
    use Ty::{Count, Pair, Real, State};
    let stops = ("walls", Ty::Struct("Stops"));
    let at_c = |y: &'static str| index(var(y), var("c"));
    let fraction = Function {
        name: "crossing_fraction",
        params: vec![
            stops,
            ("which", Count),
            ("y0", State),
            ("y1", State),
            ("start", Pair),
            ("end", Pair),
        ],
        body: vec![
            Stmt::Var("fraction", num(0.0)),
            Stmt::If(
                less(var("which"), var("WALLS")),
                vec![
                    Stmt::Let("w", apply("stop", vec![var("walls"), var("which")])),
                    Stmt::Let("c", dot("w", "coordinate")),
                    Stmt::Set(
                        "fraction",
                        (dot("w", "position") - at_c("y0")) / (at_c("y1") - at_c("y0")),
                    ),
                ],
                vec![Stmt::Set(
                    "fraction",
                    neg(cos("start")) / (cos("end") - cos("start")),
                )],
            ),
        ],
        results: vec![("fraction", var("fraction"))],
        returns: None,
    };
    let args = ["walls", "which", "y0", "y1", "start", "end"];
    let across = vec![
        Stmt::Let(
            "theta",
            clamp(call("crossing_fraction", &args), num(0.0), num(1.0)),
        ),
        Stmt::Set(
            "out",
            make(
                "Hit",
                vec![
                    truth(true),
                    var("theta") * "h",
                    var("y0") + var("theta") * (var("y1") - "y0"),
                ],
            ),
        ),
    ];
    let linear = Function {
        name: "locate_linear",
        params: vec![
            stops,
            ("which", Count),
            ("y0", State),
            ("h", Real),
            ("y1", State),
            ("start", Pair),
            ("end", Pair),
        ],
        body: vec![
            Stmt::Var("out", miss()),
            Stmt::If(
                not(cmp(Cmp::LessEq, cos("end"), num(0.0))),
                across,
                Vec::new(),
            ),
        ],
        results: vec![("hit", var("out"))],
        returns: None,
    };
    [fraction, linear]
}

/// No crossing: the step's start.
fn miss() -> Expr {
    make("Hit", vec![truth(false), num(0.0), var("y0")])
}

/// `locate_newton` (see [`location`]): where the stop test lets the step
/// through and the bracket is found, safeguarded Newton on g(s) = the
/// event's value at RK4(y0, s), g'(s) ≈ its rate. Turning back inside the
/// step, the first re-step, to the Hermite peak, decides whether the
/// excursion crosses (more than `event_scale`'s depth); then the step to
/// s and, at most 32 times, a Newton update and the step to the new s.
/// Every re-step is the one call of `sub_step`: NIR inlines every call,
/// and each call site of it is a copy of the RK4 step and its right-hand
/// sides in the compiled kernel.
fn locate_newton() -> Function {
    use Ty::{Count, Pair, Real, State};
    let event = |at: Expr| {
        apply(
            "event_at",
            vec![
                var("p"),
                var("omega"),
                var("walls"),
                var("which"),
                var("phase0"),
                at,
                var("y"),
            ],
        )
    };
    let brk = |cond: Expr| Stmt::If(cond, vec![Stmt::Break], Vec::new());
    let to_peak = vec![
        Stmt::If(
            cmp(Cmp::LessEq, first(event(var("to"))), second(var("fine"))),
            vec![Stmt::Set("crosses", truth(false)), Stmt::Break],
            Vec::new(),
        ),
        Stmt::Set("at_peak", truth(false)),
        Stmt::Set("to", dot("b", "s")),
    ];
    let update = vec![
        brk(cmp(Cmp::Equal, var("updates"), count(32))),
        Stmt::Set("updates", var("updates") + count(1)),
        Stmt::Let("v", event(dot("b", "s"))),
        brk(cmp(Cmp::LessEq, abs(first(var("v"))), var("tolerance"))),
        Stmt::Set(
            "b",
            apply(
                "newton_update",
                vec![var("b"), first(var("v")), second(var("v"))],
            ),
        ),
        // As the CPU: s updated, y the last step's.
        brk(cmp(
            Cmp::LessEq,
            dot("b", "hi") - dot("b", "lo"),
            var("EPSILON") * abs(dot("b", "hi")),
        )),
        Stmt::Set("to", dot("b", "s")),
    ];
    let step = member(
        apply(
            "sub_step",
            vec![var("omega"), var("phase0"), var("y0"), var("to")],
        ),
        "y",
    );
    let newton = vec![
        Stmt::Var("at_peak", dot("b", "at_peak")),
        Stmt::Let(
            "tolerance",
            num(4.0) * "EPSILON" * max(abs(first(var("fine"))), num(1.0)),
        ),
        Stmt::Var("to", select(var("at_peak"), dot("b", "hi"), dot("b", "s"))),
        Stmt::Var("y", var("y0")),
        Stmt::Var("updates", count(0)),
        Stmt::Var("crosses", truth(true)),
        Stmt::Loop(vec![
            Stmt::Set("y", step),
            Stmt::If(var("at_peak"), to_peak, update),
        ]),
        Stmt::If(
            var("crosses"),
            vec![Stmt::Set(
                "out",
                make("Hit", vec![truth(true), dot("b", "s"), var("y")]),
            )],
            Vec::new(),
        ),
    ];
    let body = vec![
        Stmt::Let("fine", call("event_scale", &["walls", "which", "y0"])),
        Stmt::Var("out", miss()),
        // A step the stop test rules out has no crossing (the CPU's
        // resolve locates only the events that test lets through).
        Stmt::If(
            call("may_meet", &["start", "end", "h"]),
            vec![
                Stmt::Var("b", call("bracket_of", &["start", "end", "h"])),
                Stmt::If(dot("b", "found"), newton, Vec::new()),
            ],
            Vec::new(),
        ),
    ];
    Function {
        name: "locate_newton",
        params: vec![
            ("p", Ty::Struct("Params")),
            ("omega", Real),
            ("walls", Ty::Struct("Stops")),
            ("which", Count),
            ("phase0", Pair),
            ("y0", State),
            ("h", Real),
            ("y1", State),
            ("start", Pair),
            ("end", Pair),
        ],
        body,
        results: vec![("hit", var("out"))],
        returns: None,
    }
}

/// `hermite_new`, `hermite_value`, `hermite_slope` (see [`location`]).
fn hermite() -> Vec<Function> {
    use Ty::Real;
    let c = |k| dot("c", k);
    let new = Function {
        name: "hermite_new",
        params: vec![
            ("g0", Real),
            ("v0", Real),
            ("g1", Real),
            ("v1", Real),
            ("h", Real),
        ],
        body: lets(vec![
            ("d0", var("v0") * "h"),
            ("d1", var("v1") * "h"),
            ("c2", num(3.0) * (var("g1") - "g0") - num(2.0) * "d0" - "d1"),
            ("c3", num(2.0) * (var("g0") - "g1") + "d0" + "d1"),
        ]),
        results: vec![(
            "c",
            make("Hermite", vec![var("g0"), var("d0"), var("c2"), var("c3")]),
        )],
        returns: None,
    };
    let at = vec![("c", Ty::Struct("Hermite")), ("th", Real)];
    let value = Function {
        name: "hermite_value",
        params: at.clone(),
        body: Vec::new(),
        results: vec![(
            "g",
            c("c0") + var("th") * (c("c1") + var("th") * (c("c2") + var("th") * c("c3"))),
        )],
        returns: None,
    };
    let slope = Function {
        name: "hermite_slope",
        params: at,
        body: Vec::new(),
        results: vec![(
            "slope",
            c("c1") + var("th") * (num(2.0) * c("c2") + var("th") * num(3.0) * c("c3")),
        )],
        returns: None,
    };
    vec![new, value, slope]
}

/// `hermite_peak` (see [`location`]): the root formula that does not
/// cancel, q/a where b >= 0, else c/q.
fn peak() -> Function {
    let slope = |th: f64| apply("hermite_slope", vec![var("c"), num(th)]);
    let turns = and(greater(slope(0.0), num(0.0)), less(slope(1.0), num(0.0)));
    let mut inside = lets(vec![
        ("a", num(3.0) * dot("c", "c3")),
        ("b", num(2.0) * dot("c", "c2")),
        (
            "root",
            sqrt(max(
                var("b") * "b" - num(4.0) * "a" * dot("c", "c1"),
                num(0.0),
            )),
        ),
    ]);
    inside.extend([
        Stmt::Var("th", num(0.0)),
        Stmt::If(
            cmp(Cmp::GreaterEq, var("b"), num(0.0)),
            vec![Stmt::Set("th", num(-0.5) * (var("b") + "root") / "a")],
            vec![Stmt::Set(
                "th",
                dot("c", "c1") / (num(-0.5) * (var("b") - "root")),
            )],
        ),
        Stmt::Set("peak", clamp(var("th"), num(0.0), num(1.0))),
    ]);
    Function {
        name: "hermite_peak",
        params: vec![("c", Ty::Struct("Hermite"))],
        body: vec![
            Stmt::Var("peak", num(-1.0)),
            Stmt::If(turns, inside, Vec::new()),
        ],
        results: vec![("peak", var("peak"))],
        returns: None,
    }
}

/// `hermite_first_root` (see [`location`]): 8 passes of bisection
/// refined with Newton.
fn first_root() -> Function {
    use Ty::Real;
    let value = |at: &'static str| apply("hermite_value", vec![var("c"), var(at)]);
    let body = vec![
        Stmt::Var("a", var("a_in")),
        Stmt::Var("b", var("b_in")),
        Stmt::Let("ga", value("a")),
        Stmt::Let("gb", value("b")),
        Stmt::Var(
            "th",
            var("a")
                + (var("b") - "a") * clamp(neg(var("ga")) / (var("gb") - "ga"), num(0.0), num(1.0)),
        ),
        Stmt::Var("k", count(0)),
        Stmt::Loop(vec![
            break_unless(less(var("k"), count(8))),
            Stmt::Let("g", value("th")),
            Stmt::If(
                greater(var("g"), num(0.0)),
                vec![Stmt::Set("b", var("th"))],
                vec![Stmt::Set("a", var("th"))],
            ),
            Stmt::Let(
                "next",
                var("th") - var("g") / apply("hermite_slope", vec![var("c"), var("th")]),
            ),
            Stmt::If(
                and(greater(var("next"), var("a")), less(var("next"), var("b"))),
                vec![Stmt::Set("th", var("next"))],
                vec![Stmt::Set("th", num(0.5) * (var("a") + "b"))],
            ),
            Stmt::Set("k", var("k") + count(1)),
        ]),
    ];
    Function {
        name: "hermite_first_root",
        params: vec![("c", Ty::Struct("Hermite")), ("a_in", Real), ("b_in", Real)],
        body,
        results: vec![("th", var("th"))],
        returns: None,
    }
}

/// `bracket_of` (see [`location`]).
fn bracket_of() -> Function {
    use Ty::{Pair, Real};
    let bracket = |found, at_peak, hi: Expr, s: Expr| {
        make(
            "Bracket",
            vec![truth(found), truth(at_peak), num(0.0), hi, s],
        )
    };
    let root = |to: Expr| apply("hermite_first_root", vec![var("herm"), num(0.0), to]);
    let turning = vec![
        Stmt::Let("peak", apply("hermite_peak", vec![var("herm")])),
        Stmt::If(
            not(less(var("peak"), num(0.0))),
            vec![Stmt::Set(
                "out",
                bracket(true, true, var("peak") * "h", root(var("peak")) * "h"),
            )],
            Vec::new(),
        ),
    ];
    let body = vec![
        Stmt::Let(
            "herm",
            apply(
                "hermite_new",
                vec![cos("start"), sin("start"), cos("end"), sin("end"), var("h")],
            ),
        ),
        Stmt::Var("out", bracket(false, false, num(0.0), num(0.0))),
        Stmt::If(
            greater(cos("end"), num(0.0)),
            vec![Stmt::Set(
                "out",
                bracket(true, false, var("h"), root(num(1.0)) * "h"),
            )],
            vec![Stmt::If(
                and(greater(sin("start"), num(0.0)), less(sin("end"), num(0.0))),
                turning,
                Vec::new(),
            )],
        ),
    ];
    Function {
        name: "bracket_of",
        params: vec![("start", Pair), ("end", Pair), ("h", Real)],
        body,
        results: vec![("bracket", var("out"))],
        returns: None,
    }
}

/// `newton_update` (see [`location`]).
fn newton_update() -> Function {
    use Ty::Real;
    let body = vec![
        Stmt::Var("lo", dot("b", "lo")),
        Stmt::Var("hi", dot("b", "hi")),
        Stmt::If(
            greater(var("g"), num(0.0)),
            vec![Stmt::Set("hi", dot("b", "s"))],
            vec![Stmt::Set("lo", dot("b", "s"))],
        ),
        Stmt::Let("newton", dot("b", "s") - var("g") / "rate"),
        Stmt::Var("s", num(0.0)),
        Stmt::If(
            and(
                greater(var("newton"), var("lo")),
                less(var("newton"), var("hi")),
            ),
            vec![Stmt::Set("s", var("newton"))],
            vec![Stmt::Set("s", num(0.5) * (var("lo") + "hi"))],
        ),
    ];
    let bracket = make(
        "Bracket",
        vec![
            dot("b", "found"),
            dot("b", "at_peak"),
            var("lo"),
            var("hi"),
            var("s"),
        ],
    );
    Function {
        name: "newton_update",
        params: vec![("b", Ty::Struct("Bracket")), ("g", Real), ("rate", Real)],
        body,
        results: vec![("bracket", bracket)],
        returns: None,
    }
}
