//! The kernels' step programs of general surfaces (events and switches)
//! and of sliding on a switch (in the language of `model::ir::step`):
//! regions, the step loop's test over every surface, a switch's two sides
//! and Filippov's equivalent control, the sliding sub-step and a
//! crossing applied. Printed to WGSL by `model::codegen::step` for a model
//! with general surfaces; the CPU runs their Rust twins, which are the
//! oracle (`integrate::surface`, `integrate::region`, the surface branch
//! of `integrate::impact`'s resolve, cross and slide).
//!
//! A region is a counter: bit b set where switch b's g > 0, and bits from
//! `SLIDING_SHIFT` up marking the switch a motion slides on. What the
//! system file gives (each surface's g, values, gradient, reset and stick
//! limit, the region's field) and what the kernels keep by hand (the
//! location, the stops) are declared as the kernels' ([`kernels`]).

use super::step::build::*;
use super::step::{Cmp, Expr, Extern, Function, Stmt, Structure, Ty};

/// What the surface functions use of the kernels and the system file:
///
/// - `SURFACES` (1 to 4), `SURFACE_BIT` (each surface's switch bit, or
///   `EVENT`), `EVENT`, and the region's layout `SLIDING_SHIFT` (the
///   sliding bits' first) and `SIDES` (the sides' bits);
/// - the lane's `Params` (its `region` read and set), `SurfaceValues`
///   (g and the rate of every surface), an event's `Reset` (the state
///   after it, its Jacobian DR by rows and ∂R/∂t);
/// - `field(p, phase, y)`, the field of p's region, and `rhs`, the field
///   RK4 steps (the sliding one on a sliding region); `surface_g`,
///   `surface_values`, `surface_gradient(p, phase, y, j)`,
///   `stick_limit(p, y, j, filippov)`, `reset(p, phase, y, j)`; `log_r`
///   and `stops_of(p)` (the location `locate(...)` is the step loop's,
///   `model::ir::impacts`).
pub fn kernels() -> Vec<Extern> {
    use Ty::{Count, CountTable, Pair, Real, State, Table};
    let (params, values) = (Ty::Struct("Params"), Ty::Struct("SurfaceValues"));
    let function = |name, params, result| Extern::Fn {
        name,
        params,
        result,
    };
    vec![
        Extern::Const("SURFACES", Count),
        Extern::Const("SURFACE_BIT", CountTable),
        Extern::Const("EVENT", Count),
        Extern::Const("SLIDING_SHIFT", Count),
        Extern::Const("SIDES", Count),
        Extern::Struct("SurfaceValues", vec![("g", Table), ("rate", Table)]),
        Extern::Struct(
            "Reset",
            vec![("y", State), ("dr", Ty::Rows), ("rate", State)],
        ),
        function("field", vec![params, Pair, State], State),
        function("rhs", vec![params, Pair, State], State),
        function("surface_g", vec![params, Pair, State], Table),
        function("surface_values", vec![params, Pair, State], values),
        function("surface_gradient", vec![params, Pair, State, Count], State),
        function("stick_limit", vec![params, State, Count, Real], Real),
        function(
            "reset",
            vec![params, Pair, State, Count],
            Ty::Struct("Reset"),
        ),
        function("log_r", vec![Real], Real),
        function("stops_of", vec![params], Ty::Struct("Stops")),
    ]
}

/// The structures of the surface functions:
///
/// - `SwitchSides`: a switch's two sides at a state, their fields `lo`
///   (g < 0) and `hi`, their rates `a` and `b` along ∇g, and the stick
///   margins (L - m, L + m), m = (a + b)/2, L the stick limit or the half
///   jump (a - b)/2: both > 0, the switch holds the motion
///   (`surface::joining_margins` and the sides of `surface::equivalent_on`
///   for one switch).
/// - `Equivalent`: the equivalent control of a motion sliding on one
///   switch, its field F₀ + α(F₁ - F₀), α and the margins.
/// - `Slid`: how a sliding sub-step ended (`Slid` in impact.rs): left the
///   switch (to `region`) after s at y, else still sliding at the end, at
///   y; `flagged` where something the kernels do not integrate was met
///   while sliding (another switch, an event, a stop): the lane is the
///   CPU's.
/// - `Crossing`: a crossing of a general surface applied (`cross` in
///   impact.rs): `resolved`, else flagged (chattering or sliding) with the
///   state left at the crossing; its region; ln |det S| (0 where none
///   applies); `counted` in the crossings (a touch in rounding is not);
///   the oriented approach rate (its "impact speed"); `rank_loss` where
///   det S = 0 or a sliding phase begins; `slides` from here.
pub fn structures() -> [Structure; 4] {
    use Ty::{Bool, Count, Pair, Real, State};
    let structure = |name, members| Structure { name, members };
    [
        structure(
            "SwitchSides",
            vec![
                ("lo", State),
                ("hi", State),
                ("a", Real),
                ("b", Real),
                ("margins", Pair),
            ],
        ),
        structure(
            "Equivalent",
            vec![("field", State), ("alpha", Real), ("margins", Pair)],
        ),
        structure(
            "Slid",
            vec![
                ("leaves", Bool),
                ("s", Real),
                ("y", State),
                ("region", Count),
                ("flagged", Bool),
            ],
        ),
        structure(
            "Crossing",
            vec![
                ("resolved", Bool),
                ("y", State),
                ("region", Count),
                ("log_det", Real),
                ("counted", Bool),
                ("approach", Real),
                ("chattering", Bool),
                ("sliding", Bool),
                ("rank_loss", Bool),
                ("slides", Bool),
            ],
        ),
    ]
}

/// Every surface function, callees first:
///
/// - `is_sliding(region)`: a motion sliding on a switch.
/// - `holds(m)`: both stick margins > 0 (the CPU's slide and cross).
/// - `surface_pair(j, v)`: surface j's (g, rate) in values v.
/// - `oriented(region, j, v)`: that pair oriented so that > 0 lies across
///   for a trajectory in `region`: what its crossing is detected and
///   located on, as a stop's (gap, speed).
/// - `may_cross(region, j, before, after, h)`, `crosses_a_surface(region,
///   before, after, h)`: the stop test of surface j (`surface::may_cross`)
///   and of every surface, written out per surface as the stops' is.
/// - `region_of(p, phase, y)`: bit b set where switch b's g > 0
///   (`surface::region_of`).
/// - `jumped(p, phase, y, after)`: the region after a reset jumps y to
///   `after` (`surface::jumped`), see [`jumped`].
/// - `dot_in_order(a, b)`: Σ a_i b_i from i = 0, as the CPU's iterator sum.
/// - `event_log_det(r, gradient, rate, before, after)`: ln |det S| of an
///   event's crossing, see [`event_log_det`].
/// - `switch_sides(p, j, phase, y)`, `equivalent(p, phase, y)`,
///   `sliding_field(p, phase, y)`: see [`sides`].
/// - `surface_at(p, omega, j, phase0, s, y)`: surface j's oriented value
///   and rate s into a step (`locate`'s `distance` and `rate`);
///   `locate_surface(...)`: its crossing in a step, see [`located`].
/// - `slide(p, omega, phase, y, h)`: see [`slide`]; `cross(p, j, phase,
///   y)`: see [`cross`].
pub fn functions() -> Vec<Function> {
    let mut all = tests();
    all.extend(regions());
    all.push(event_log_det());
    all.extend(sides());
    all.extend(located());
    all.push(slide());
    all.push(cross());
    all
}

/// `1u << bit`.
fn bit(at: Expr) -> Expr {
    shl(count(1), at)
}

/// Surface `j`'s switch bit.
fn bit_of(j: Expr) -> Expr {
    index(var("SURFACE_BIT"), j)
}

/// `is_sliding`, `holds`, `surface_pair`, `oriented`, `may_cross` and
/// `crosses_a_surface` (see [`functions`]).
fn tests() -> Vec<Function> {
    use Ty::{Count, Pair, Real};
    let values = Ty::Struct("SurfaceValues");
    let is_sliding = Function::one(
        "is_sliding",
        vec![("region", Count)],
        Vec::new(),
        (
            "sliding",
            cmp(
                Cmp::NotEqual,
                shr(var("region"), var("SLIDING_SHIFT")),
                count(0),
            ),
        ),
    );
    let holds = Function::one(
        "holds",
        vec![("m", Pair)],
        Vec::new(),
        (
            "holds",
            and(
                greater(first(var("m")), num(0.0)),
                greater(second(var("m")), num(0.0)),
            ),
        ),
    );
    let at = |of: &'static str| index(dot("v", of), var("j"));
    let surface_pair = Function::one(
        "surface_pair",
        vec![("j", Count), ("v", values)],
        Vec::new(),
        ("pair", pair(at("g"), at("rate"))),
    );
    let orientation = || apply("orientation", vec![var("region"), bit_of(var("j"))]);
    let oriented = Function::one(
        "oriented",
        vec![("region", Count), ("j", Count), ("v", values)],
        Vec::new(),
        (
            "oriented",
            apply(
                "orient",
                vec![orientation(), call("surface_pair", &["j", "v"])],
            ),
        ),
    );
    let ends =
        |j: Expr| ["before", "after"].map(|v| apply("surface_pair", vec![j.clone(), var(v)]));
    let [before, after] = ends(var("j"));
    let may_cross = Function::one(
        "may_cross",
        vec![
            ("region", Count),
            ("j", Count),
            ("before", values),
            ("after", values),
            ("h", Real),
        ],
        Vec::new(),
        (
            "crosses",
            apply(
                "oriented_may_meet",
                vec![orientation(), before, after, var("h")],
            ),
        ),
    );
    let crosses = |j: u32| {
        apply(
            "may_cross",
            vec![
                var("region"),
                count(j),
                var("before"),
                var("after"),
                var("h"),
            ],
        )
    };
    let mut any = vec![Stmt::Var("hit", crosses(0))];
    for j in 1..4 {
        any.push(Stmt::If(
            greater(var("SURFACES"), count(j)),
            vec![Stmt::Set("hit", or(var("hit"), crosses(j)))],
            Vec::new(),
        ));
    }
    let crosses_a_surface = Function::one(
        "crosses_a_surface",
        vec![
            ("region", Count),
            ("before", values),
            ("after", values),
            ("h", Real),
        ],
        any,
        ("hit", var("hit")),
    );
    vec![
        is_sliding,
        holds,
        surface_pair,
        oriented,
        may_cross,
        crosses_a_surface,
    ]
}

/// The loop `{i} = from; while {i} < below { body; {i} += 1 }`: over
/// the surfaces (`SURFACES`) or a state's components (`DIM`).
fn counted(i: &'static str, from: Expr, below: &'static str, body: Vec<Stmt>) -> Vec<Stmt> {
    let mut pass = vec![break_unless(less(var(i), var(below)))];
    pass.extend(body);
    pass.push(Stmt::Set(i, var(i) + count(1)));
    vec![Stmt::Var(i, from), Stmt::Loop(pass)]
}

/// A loop over the surfaces, `k` from 0.
fn each_surface(k: &'static str, body: Vec<Stmt>) -> Vec<Stmt> {
    counted(k, count(0), "SURFACES", body)
}

/// `region_of`, `jumped` and `dot_in_order` (see [`functions`]).
fn regions() -> Vec<Function> {
    use Ty::{Pair, State};
    let at = ("p", Ty::Struct("Params"));
    let not_event = |b: Expr| cmp(Cmp::NotEqual, b, var("EVENT"));
    let g_at = |g: &'static str| index(var(g), var("j"));
    let zero = || num(0.0);
    let mut body = vec![
        Stmt::Let("g", call("surface_g", &["p", "phase", "y"])),
        Stmt::Var("region", count(0)),
    ];
    body.extend(each_surface(
        "j",
        vec![Stmt::If(
            and(not_event(bit_of(var("j"))), greater(g_at("g"), zero())),
            vec![Stmt::Set(
                "region",
                bit_or(var("region"), bit(bit_of(var("j")))),
            )],
            Vec::new(),
        )],
    ));
    let region_of = Function::one(
        "region_of",
        vec![at, ("phase", Pair), ("y", State)],
        body,
        ("region", var("region")),
    );
    let mut sum = vec![Stmt::Var("sum", zero())];
    let product = index(var("a"), var("i")) * index(var("b"), var("i"));
    sum.extend(each_component(
        "i",
        count(0),
        vec![Stmt::Set("sum", var("sum") + product)],
    ));
    let dot_in_order = Function::one(
        "dot_in_order",
        vec![("a", State), ("b", State)],
        sum,
        ("sum", var("sum")),
    );
    vec![region_of, jumped(), dot_in_order]
}

/// `jumped(p, phase, y, after)`: a switch that the jump moves strictly
/// off its side (g from <= 0 to > 0, or from >= 0 to < 0) takes the side
/// of `after`, the others keep their bit. A sliding region is kept (a
/// reset met while sliding is flagged first).
fn jumped() -> Function {
    use Ty::{Pair, State};
    let g = |of: &'static str| index(var(of), var("j"));
    let switch = || cmp(Cmp::NotEqual, var("bit"), var("EVENT"));
    let zero = || num(0.0);
    let each = vec![
        Stmt::Let("bit", bit_of(var("j"))),
        Stmt::If(
            and(
                and(switch(), greater(g("g1"), zero())),
                cmp(Cmp::LessEq, g("g0"), zero()),
            ),
            vec![Stmt::Set("region", bit_or(var("region"), bit(var("bit"))))],
            vec![Stmt::If(
                and(
                    and(switch(), less(g("g1"), zero())),
                    cmp(Cmp::GreaterEq, g("g0"), zero()),
                ),
                vec![Stmt::Set(
                    "region",
                    bit_and(var("region"), complement(bit(var("bit")))),
                )],
                Vec::new(),
            )],
        ),
    ];
    let mut walk = lets(vec![
        ("g0", call("surface_g", &["p", "phase", "y"])),
        ("g1", call("surface_g", &["p", "phase", "after"])),
    ]);
    walk.extend(each_surface("j", each));
    let body = vec![
        Stmt::Var("region", dot("p", "region")),
        Stmt::If(
            not(apply("is_sliding", vec![dot("p", "region")])),
            walk,
            Vec::new(),
        ),
    ];
    Function::one(
        "jumped",
        vec![
            ("p", Ty::Struct("Params")),
            ("phase", Pair),
            ("y", State),
            ("after", State),
        ],
        body,
        ("region", var("region")),
    )
}

/// A loop over a state's components (or a matrix's rows), `i` from
/// `from`.
fn each_component(i: &'static str, from: Expr, body: Vec<Stmt>) -> Vec<Stmt> {
    counted(i, from, "DIM", body)
}

/// `event_log_det(r, gradient, rate, before, after)`: ln |det S| of an
/// event's crossing, S = DR + (F⁺ - DR·F⁻ - ∂R/∂t) ∇gᵀ / rate
/// (`surface::event_log_det`), det by elimination with partial pivoting;
/// -∞ where det S = 0, made at run time (a constant 1/0 is a
/// shader-creation error).
fn event_log_det() -> Function {
    use Ty::{Real, State};
    let at = |m: Expr, i: &'static str, k: &'static str| index(index(m, var(i)), var(k));
    let entry = at(dot("r", "dr"), "i", "k")
        + (index(var("after"), var("i")) - "dr_f" - index(dot("r", "rate"), var("i")))
            * index(var("gradient"), var("k"))
            / "rate";
    let mut row = vec![Stmt::Let(
        "dr_f",
        apply(
            "dot_in_order",
            vec![index(dot("r", "dr"), var("i")), var("before")],
        ),
    )];
    row.extend(each_component(
        "k",
        count(0),
        vec![Stmt::SetEntry("s", var("i"), var("k"), entry)],
    ));
    let mut body = vec![
        // Every entry is set below: the copy only gives s its type.
        Stmt::Var("s", dot("r", "dr")),
    ];
    body.extend(each_component("i", count(0), row));
    body.push(Stmt::Var("det", num(1.0)));
    body.extend(each_component("col", count(0), elimination()));
    body.extend([
        Stmt::Var("out", num(0.0)),
        Stmt::If(
            cmp(Cmp::Equal, var("det"), num(0.0)),
            vec![
                Stmt::Var("zero", num(0.0)),
                Stmt::Set("out", num(-1.0) / "zero"),
            ],
            vec![Stmt::Set("out", apply("log_r", vec![abs(var("det"))]))],
        ),
    ]);
    Function::one(
        "event_log_det",
        vec![
            ("r", Ty::Struct("Reset")),
            ("gradient", State),
            ("rate", Real),
            ("before", State),
            ("after", State),
        ],
        body,
        ("log_det", var("out")),
    )
}

/// Column `col` of the elimination: the largest pivot below swapped up
/// (det changes sign), det times it, and the rows below cleared; a zero
/// pivot ends it (det = 0).
fn elimination() -> Vec<Stmt> {
    let at = |i: &'static str, k: &'static str| index(index(var("s"), var(i)), var(k));
    let mut out = vec![Stmt::Var("pivot", var("col"))];
    out.extend(each_component(
        "row",
        var("col") + count(1),
        vec![Stmt::If(
            greater(abs(at("row", "col")), abs(at("pivot", "col"))),
            vec![Stmt::Set("pivot", var("row"))],
            Vec::new(),
        )],
    ));
    out.extend([
        Stmt::If(
            cmp(Cmp::NotEqual, var("pivot"), var("col")),
            vec![
                Stmt::Let("swap", index(var("s"), var("col"))),
                Stmt::SetAt("s", var("col"), index(var("s"), var("pivot"))),
                Stmt::SetAt("s", var("pivot"), var("swap")),
                Stmt::Set("det", neg(var("det"))),
            ],
            Vec::new(),
        ),
        Stmt::Let("d", at("col", "col")),
        Stmt::Set("det", var("det") * "d"),
        Stmt::If(
            cmp(Cmp::Equal, var("d"), num(0.0)),
            vec![Stmt::Break],
            Vec::new(),
        ),
    ]);
    let clear = vec![Stmt::SetEntry(
        "s",
        var("below"),
        var("m"),
        at("below", "m") - var("factor") * at("col", "m"),
    )];
    let mut below = vec![Stmt::Let("factor", at("below", "col") / "d")];
    below.extend(each_component("m", var("col"), clear));
    out.extend(each_component("below", var("col") + count(1), below));
    out
}

/// The lane's parameters with another region: `var {name} = from;
/// {name}.region = region;`.
fn in_region(name: &'static str, from: &'static str, region: Expr) -> [Stmt; 2] {
    [
        Stmt::Var(name, var(from)),
        Stmt::SetMember(name, "region", region),
    ]
}

/// A switch's sides and the sliding motion on it:
///
/// - `switch_sides(p, j, phase, y)`: switch j's sides at y for a
///   trajectory on either side of it or sliding on it (`SwitchSides`):
///   what a crossing decides sliding from and what the sliding motion
///   leaves by, written once.
/// - `equivalent(p, phase, y)`: the equivalent control on the switch of
///   p's sliding bits (`Equivalent`; Filippov's convex combination,
///   `surface::equivalent_on` with one switch).
/// - `sliding_field(p, phase, y)`: its field, NaN where the combination
///   does not exist (as the CPU's Sliding flow).
fn sides() -> [Function; 3] {
    use Ty::{Count, Pair, State};
    let at = ("p", Ty::Struct("Params"));
    let mut body = vec![Stmt::Let("bit", bit_of(var("j")))];
    body.extend(in_region(
        "lo_p",
        "p",
        bit_and(
            bit_and(dot("p", "region"), var("SIDES")),
            complement(bit(var("bit"))),
        ),
    ));
    body.extend(in_region(
        "hi_p",
        "lo_p",
        bit_or(dot("lo_p", "region"), bit(var("bit"))),
    ));
    body.extend(lets(vec![
        ("lo", call("field", &["lo_p", "phase", "y"])),
        ("hi", call("field", &["hi_p", "phase", "y"])),
        ("n", call("surface_gradient", &["p", "phase", "y", "j"])),
        ("a", call("dot_in_order", &["n", "lo"])),
        ("b", call("dot_in_order", &["n", "hi"])),
        ("mean", num(0.5) * (var("a") + "b")),
        (
            "limit",
            apply(
                "stick_limit",
                vec![var("p"), var("y"), var("j"), num(0.5) * (var("a") - "b")],
            ),
        ),
    ]));
    let margins = pair(var("limit") - "mean", var("limit") + "mean");
    let switch_sides = Function::one(
        "switch_sides",
        vec![at, ("j", Count), ("phase", Pair), ("y", State)],
        body,
        (
            "sides",
            make(
                "SwitchSides",
                vec![var("lo"), var("hi"), var("a"), var("b"), margins],
            ),
        ),
    );
    let sliding_on = lowest_set(shr(dot("p", "region"), var("SLIDING_SHIFT")));
    let body = lets(vec![
        (
            "s",
            apply(
                "switch_sides",
                vec![var("p"), sliding_on, var("phase"), var("y")],
            ),
        ),
        (
            "alpha",
            apply("filippov_alpha", vec![dot("s", "a"), dot("s", "b")]),
        ),
    ]);
    let field = apply(
        "filippov_field",
        vec![dot("s", "lo"), dot("s", "hi"), var("alpha")],
    );
    let equivalent = Function::one(
        "equivalent",
        vec![at, ("phase", Pair), ("y", State)],
        body,
        (
            "equivalent",
            make("Equivalent", vec![field, var("alpha"), dot("s", "margins")]),
        ),
    );
    let body = vec![
        Stmt::Let("e", call("equivalent", &["p", "phase", "y"])),
        Stmt::Var("out", dot("e", "field")),
        Stmt::If(
            not(finite(dot("e", "alpha"))),
            vec![
                // NaN made at run time (WGSL has no constant NaN).
                Stmt::Var("zero", num(0.0)),
                Stmt::Set("out", fill(var("zero") / "zero")),
            ],
            Vec::new(),
        ),
    ];
    let sliding_field = Function::one(
        "sliding_field",
        vec![at, ("phase", Pair), ("y", State)],
        body,
        ("field", var("out")),
    );
    [switch_sides, equivalent, sliding_field]
}

/// `surface_at(p, omega, j, phase0, s, y)` and `locate_surface(p, omega,
/// walls, j, phase0, y0, h, y1, before, after)`: surface j's crossing in
/// the step [0, h] from (phase0, y0) to y1, given its values at both ends,
/// the stops' location on its oriented g instead of a gap (`locate` in
/// impact.rs).
fn located() -> [Function; 2] {
    use Ty::{Count, Pair, Real, State};
    let at = ("p", Ty::Struct("Params"));
    let values = Ty::Struct("SurfaceValues");
    let phase = apply(
        "rotate",
        vec![var("phase0"), apply("cos_sin", vec![var("omega") * "s"])],
    );
    let surface_at = Function::one(
        "surface_at",
        vec![
            at,
            ("omega", Real),
            ("j", Count),
            ("phase0", Pair),
            ("s", Real),
            ("y", State),
        ],
        Vec::new(),
        (
            "oriented",
            apply(
                "oriented",
                vec![
                    dot("p", "region"),
                    var("j"),
                    apply("surface_values", vec![var("p"), phase, var("y")]),
                ],
            ),
        ),
    );
    let oriented = |v: &'static str| apply("oriented", vec![dot("p", "region"), var("j"), var(v)]);
    let mut args: Vec<Expr> = ["p", "omega", "walls"].map(var).to_vec();
    args.push(var("WALLS") + "j");
    args.extend(["phase0", "y0", "h", "y1"].map(var));
    args.extend([oriented("before"), oriented("after")]);
    let locate_surface = Function::one(
        "locate_surface",
        vec![
            at,
            ("omega", Real),
            ("walls", Ty::Struct("Stops")),
            ("j", Count),
            ("phase0", Pair),
            ("y0", State),
            ("h", Real),
            ("y1", State),
            ("before", values),
            ("after", values),
        ],
        Vec::new(),
        ("hit", apply("locate", args)),
    );
    [surface_at, locate_surface]
}

/// `slide(p, omega, phase, y, h)`: slides on the switch of p's sliding
/// bits for up to h from (phase, y), the twin of `slide` in impact.rs for
/// one switch. Another surface crossed on the way, or a stop reached, is
/// flagged rather than located; an exit (a stick margin reaching 0) is
/// bisected on RK4 re-stepped along the sliding field, and the region
/// leaves to the side whose margin ran out (`surface::leaving`). One
/// re-step for the whole slide (one call site, as `locate_newton`): its
/// first pass to the step's end, then the bisection's midpoints; a
/// bisection to EPSILON·h takes 53 midpoints, and 128 bounds the loop for
/// lavapipe's iteration cap whatever the margins do.
fn slide() -> Function {
    use Ty::{Pair, Real, State};
    let step = apply(
        "sub_step",
        vec![var("omega"), var("phase"), var("y"), var("to")],
    );
    let turned = apply(
        "rotate",
        vec![var("phase"), apply("cos_sin", vec![var("omega") * "to"])],
    );
    let mut first_pass = slide_flags();
    first_pass.extend([
        Stmt::Set("exit", var("y_to")),
        Stmt::Set("m", var("m_to")),
        Stmt::If(
            call("holds", &["m_to"]),
            vec![Stmt::Set("held", truth(true)), Stmt::Break],
            Vec::new(),
        ),
    ]);
    let bisect = vec![Stmt::If(
        call("holds", &["m_to"]),
        vec![Stmt::Set("lo", var("to"))],
        vec![
            Stmt::Set("hi", var("to")),
            Stmt::Set("exit", var("y_to")),
            Stmt::Set("m", var("m_to")),
        ],
    )];
    let pass = vec![
        Stmt::Let("y_to", member(step, "y")),
        Stmt::Let("phase_to", turned),
        Stmt::Let(
            "m_to",
            margins_of(apply(
                "equivalent",
                vec![var("p"), var("phase_to"), var("y_to")],
            )),
        ),
        Stmt::If(cmp(Cmp::Equal, var("passes"), count(0)), first_pass, bisect),
        Stmt::If(
            or(
                cmp(Cmp::Equal, var("passes"), count(128)),
                not(greater(var("hi") - "lo", var("EPSILON") * "h")),
            ),
            vec![Stmt::Break],
            Vec::new(),
        ),
        Stmt::Set("passes", var("passes") + count(1)),
        Stmt::Set("to", num(0.5) * (var("lo") + "hi")),
    ];
    let slid = |leaves: bool, s: Expr, region: Expr| {
        make(
            "Slid",
            vec![truth(leaves), s, var("exit"), region, var("flagged")],
        )
    };
    let leaves = vec![
        Stmt::Let("bit", bit_of(var("j"))),
        Stmt::Var(
            "region",
            bit_and(
                dot("p", "region"),
                complement(bit(var("SLIDING_SHIFT") + "j")),
            ),
        ),
        Stmt::If(
            cmp(Cmp::LessEq, first(var("m")), second(var("m"))),
            vec![Stmt::Set("region", bit_or(var("region"), bit(var("bit"))))],
            vec![Stmt::Set(
                "region",
                bit_and(var("region"), complement(bit(var("bit")))),
            )],
        ),
        Stmt::Set("out", slid(true, var("hi"), var("region"))),
    ];
    let body = vec![
        Stmt::Let(
            "j",
            lowest_set(shr(dot("p", "region"), var("SLIDING_SHIFT"))),
        ),
        Stmt::Var("lo", num(0.0)),
        Stmt::Var("hi", var("h")),
        Stmt::Var("exit", var("y")),
        Stmt::Var("m", pair(num(0.0), num(0.0))),
        Stmt::Var("flagged", truth(false)),
        Stmt::Var("held", truth(false)),
        Stmt::Var("to", var("h")),
        Stmt::Var("passes", count(0)),
        Stmt::Loop(pass),
        Stmt::Var("out", slid(false, var("h"), dot("p", "region"))),
        Stmt::If(not(var("held")), leaves, Vec::new()),
    ];
    Function::one(
        "slide",
        vec![
            ("p", Ty::Struct("Params")),
            ("omega", Real),
            ("phase", Pair),
            ("y", State),
            ("h", Real),
        ],
        body,
        ("slid", var("out")),
    )
}

/// An equivalent control's margins.
fn margins_of(e: Expr) -> Expr {
    member(e, "margins")
}

/// The first pass of a slide: every other surface the step ends across
/// (an event already across at its start excepted) flags the slide, and
/// so does a stop reached (a motion along the switch and into the stop at
/// once, flagged as on the CPU).
fn slide_flags() -> Vec<Stmt> {
    let g = |of: &'static str| index(dot(of, "g"), var("k"));
    let o_times = |of: &'static str| var("o") * g(of);
    let other = vec![
        Stmt::Let(
            "o",
            apply(
                "orientation",
                vec![dot("sides", "region"), bit_of(var("k"))],
            ),
        ),
        Stmt::If(
            and(
                greater(o_times("after"), num(0.0)),
                not(and(
                    cmp(Cmp::Equal, bit_of(var("k")), var("EVENT")),
                    greater(o_times("before"), num(0.0)),
                )),
            ),
            vec![Stmt::Set("flagged", truth(true))],
            Vec::new(),
        ),
    ];
    let mut out = in_region("sides", "p", bit_and(dot("p", "region"), var("SIDES"))).to_vec();
    out.extend(lets(vec![
        ("before", call("surface_values", &["sides", "phase", "y"])),
        (
            "after",
            call("surface_values", &["sides", "phase_to", "y_to"]),
        ),
    ]));
    out.extend(each_surface(
        "k",
        vec![Stmt::If(
            cmp(Cmp::NotEqual, var("k"), var("j")),
            other,
            Vec::new(),
        )],
    ));
    out.push(Stmt::If(
        apply(
            "behind_a_stop",
            vec![apply("stops_of", vec![var("p")]), var("y_to")],
        ),
        vec![Stmt::Set("flagged", truth(true))],
        Vec::new(),
    ));
    out
}

/// `cross(p, j, phase, y)`: crosses general surface j at y (on it, at
/// `phase`) for a trajectory in p's region: an event's reset, a switch's
/// flip of the region with its ln |det S|, or the start of a sliding phase
/// on a switch both fields point into (or its stick limit holds).
fn cross() -> Function {
    use Ty::{Count, Pair, State};
    let approach =
        apply("orientation", vec![dot("p", "region"), bit_of(var("j"))]) * "approach_rate";
    let body = vec![
        Stmt::Let("bit", bit_of(var("j"))),
        Stmt::Let("before", call("surface_values", &["p", "phase", "y"])),
        Stmt::Let("approach_rate", index(dot("before", "rate"), var("j"))),
        Stmt::Var(
            "out",
            make(
                "Crossing",
                vec![
                    truth(false),
                    var("y"),
                    dot("p", "region"),
                    num(0.0),
                    truth(true),
                    approach,
                    truth(false),
                    truth(false),
                    truth(false),
                    truth(false),
                ],
            ),
        ),
        Stmt::If(
            cmp(Cmp::Equal, var("bit"), var("EVENT")),
            reset_crossed(),
            switch_crossed(),
        ),
    ];
    Function::one(
        "cross",
        vec![
            ("p", Ty::Struct("Params")),
            ("j", Count),
            ("phase", Pair),
            ("y", State),
        ],
        body,
        ("crossing", var("out")),
    )
}

/// `out.{member} = true;`.
fn set_true(member: &'static str) -> Stmt {
    Stmt::SetMember("out", member, truth(true))
}

/// An event crossed: its reset applied, which may jump across a switch
/// (what follows is that side's field: F⁺ of the saltation, the rate
/// leaving), where the motion is back where it lives and leaving the
/// surface; else chattering.
fn reset_crossed() -> Vec<Stmt> {
    let now = |of: &'static str| index(dot("now", of), var("j"));
    let mut out = vec![Stmt::Let("r", call("reset", &["p", "phase", "y", "j"]))];
    out.extend(in_region(
        "after",
        "p",
        apply(
            "jumped",
            vec![var("p"), var("phase"), var("y"), dot("r", "y")],
        ),
    ));
    out.extend(lets(vec![
        (
            "now",
            apply(
                "surface_values",
                vec![var("after"), var("phase"), dot("r", "y")],
            ),
        ),
        ("scale", call("state_scale", &["y"])),
    ]));
    let log_det = apply(
        "event_log_det",
        vec![
            var("r"),
            call("surface_gradient", &["p", "phase", "y", "j"]),
            var("approach_rate"),
            call("rhs", &["p", "phase", "y"]),
            apply("rhs", vec![var("after"), var("phase"), dot("r", "y")]),
        ],
    );
    let back = and(
        cmp(Cmp::LessEq, now("g"), num(4.0) * "EPSILON" * "scale"),
        less(now("rate"), num(0.0)),
    );
    out.push(Stmt::If(
        not(back),
        vec![set_true("chattering")],
        vec![
            Stmt::SetMember("out", "region", dot("after", "region")),
            Stmt::SetMember("out", "log_det", log_det),
            Stmt::SetMember("out", "rank_loss", not(finite(dot("out", "log_det")))),
            set_true("resolved"),
            Stmt::SetMember("out", "y", dot("r", "y")),
        ],
    ));
    out
}

/// A switch crossed, decided by its stick margins (`joining_margins`: the
/// stick limit, or Filippov's, the half jump). The trajectory is on one
/// side (resolve_impacts slides a sliding one before it looks for
/// crossings). Both fields pointing into the switch (or the stick limit
/// holding the motion): it slides, where its Filippov combination
/// exists, and forgets how far from the surface it came (one direction;
/// ln |det S| NaN, the volume law no longer applies). Else it crosses to
/// the side the margins say, det S = (∇g·F⁺)/(∇g·F⁻), unless it only
/// touched the surface in rounding (no crossing), or the rate does not
/// carry it across (sliding, flagged).
fn switch_crossed() -> Vec<Stmt> {
    let mut joins = in_region(
        "joined",
        "p",
        bit_or(dot("p", "region"), bit(var("SLIDING_SHIFT") + "j")),
    )
    .to_vec();
    let alpha = member(
        apply("equivalent", vec![var("joined"), var("phase"), var("y")]),
        "alpha",
    );
    joins.push(Stmt::If(
        not(finite(alpha)),
        vec![set_true("sliding")],
        vec![
            Stmt::SetMember("out", "region", dot("joined", "region")),
            set_true("resolved"),
            set_true("slides"),
            set_true("rank_loss"),
            // NaN made at run time (WGSL has no constant NaN).
            Stmt::Var("zero", num(0.0)),
            Stmt::SetMember("out", "log_det", var("zero") / "zero"),
        ],
    ));
    let mut flips =
        in_region("flipped", "p", bit_xor(dot("p", "region"), bit(var("bit")))).to_vec();
    flips.extend([
        Stmt::SetMember("out", "region", dot("flipped", "region")),
        Stmt::Let(
            "leaving",
            index(
                rates_of(apply(
                    "surface_values",
                    vec![var("flipped"), var("phase"), var("y")],
                )),
                var("j"),
            ),
        ),
        Stmt::If(
            cmp(Cmp::LessEq, var("leaving") * "approach_rate", num(0.0)),
            vec![set_true("sliding")],
            vec![
                Stmt::SetMember(
                    "out",
                    "log_det",
                    apply("log_r", vec![var("leaving") / "approach_rate"]),
                ),
                set_true("resolved"),
            ],
        ),
    ]);
    let on_plus = cmp(
        Cmp::Equal,
        bit_and(shr(dot("p", "region"), var("bit")), count(1)),
        count(1),
    );
    let to_plus = cmp(Cmp::LessEq, first(var("margins")), second(var("margins")));
    // Only touched the surface (in rounding): the margins send it back to
    // the side it is on.
    let touched = or(
        and(to_plus.clone(), on_plus.clone()),
        and(not(to_plus), not(on_plus)),
    );
    vec![
        Stmt::Let(
            "margins",
            member(
                apply(
                    "switch_sides",
                    vec![var("p"), var("j"), var("phase"), var("y")],
                ),
                "margins",
            ),
        ),
        Stmt::If(
            call("holds", &["margins"]),
            joins,
            vec![Stmt::If(
                touched,
                vec![
                    Stmt::SetMember("out", "counted", truth(false)),
                    set_true("resolved"),
                ],
                flips,
            )],
        ),
    ]
}

/// Surface values' rates.
fn rates_of(e: Expr) -> Expr {
    member(e, "rate")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::ir::integrator::integrator;

    #[test]
    fn every_surface_function_is_well_typed() {
        let program = integrator();
        let expected = [
            ("is_sliding", Ty::Bool),
            ("holds", Ty::Bool),
            ("surface_pair", Ty::Pair),
            ("oriented", Ty::Pair),
            ("may_cross", Ty::Bool),
            ("crosses_a_surface", Ty::Bool),
            ("region_of", Ty::Count),
            ("jumped", Ty::Count),
            ("dot_in_order", Ty::Real),
            ("event_log_det", Ty::Real),
            ("switch_sides", Ty::Struct("SwitchSides")),
            ("equivalent", Ty::Struct("Equivalent")),
            ("sliding_field", Ty::State),
            ("surface_at", Ty::Pair),
            ("locate_surface", Ty::Struct("Hit")),
            ("slide", Ty::Struct("Slid")),
            ("cross", Ty::Struct("Crossing")),
        ];
        assert_eq!(functions().len(), expected.len());
        for (name, ty) in expected {
            assert_eq!(
                program.function(name).result_types(&program),
                [ty],
                "{name}"
            );
        }
    }
}
