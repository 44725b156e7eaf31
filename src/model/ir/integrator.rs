//! The integrator's step programs (in the language of `model::ir::step`):
//! the clock's rotation and its (cos, sin), RK4 of the model's field and
//! of the held flow, the stop test of stops and of surfaces, a surface's
//! orientation in a region (the region walk's bit test), and the
//! sliding field's algebra, each written once here and printed to C and to
//! WGSL by `model::codegen::step`.
//!
//! The hand-written Rust they follow operation for operation is their
//! oracle: `integrate::clock`, `integrate::rk4`, `integrate::wall`,
//! `integrate::surface`.

use super::step::build::*;
use super::step::{Cmp, Expr, Field, Function, Program, Stmt, Ty};

/// The integrator's step: the clock (`integrate::clock`) and the
/// classical RK4 step (`integrate::rk4`), whose stages take the phases of
/// the step's start, middle and end.
///
/// - `rotate(phase, by)`: the phase turned through the angle whose (cos,
///   sin) is `by`, renormalised to the unit circle by one Newton step for
///   1/√(c² + s²), so rounding cannot make the forcing's amplitude drift.
/// - `cos_sin(angle)`: (cos, sin) of an angle from arithmetic alone (see
///   [`cos_sin`]).
/// - `rk4_stages(phase, mid, end, y, h)`: the increment y(t + h) - y(t),
///   kept apart from the update so that the f32 kernels can compensate
///   the sum.
/// - `rk4_update(phase, mid, end, y, h)`: the step's end, y + the
///   increment.
/// - `rk4_increment(phase, half, y, h)`: the phases turned through ωh/2
///   twice (`half` is its (cos, sin)), the increment and the end's phase.
/// - `rk4_step(phase, half, y, h)`: the step's end and phase.
/// - `sub_step(omega, phase, y, s)`: a step of any size s from a phase,
///   its half turn (cos, sin)(ωs/2) from [`cos_sin`]: the re-steps of a
///   crossing's location.
/// - `held_stages`, `held_update`, `held_step`, `held_sub_step`: the same
///   RK4 of the held flow ([`Field::Held`], `integrate::impact`'s
///   `rk4::step` of `Held`).
/// - the stop test, see [`crossing_tests`], and a surface's, see
///   [`surface_tests`], oriented by `orientation` (see [`orientation`]).
pub fn integrator() -> Program {
    use Ty::Pair;
    let rotate = Function {
        name: "rotate",
        params: vec![("phase", Pair), ("by", Pair)],
        body: lets(vec![
            ("c", cos("phase") * cos("by") - sin("phase") * sin("by")),
            ("s", sin("phase") * cos("by") + cos("phase") * sin("by")),
            (
                "scale",
                num(1.5) - num(0.5) * (var("c") * "c" + var("s") * "s"),
            ),
        ]),
        results: vec![("phase", pair(var("c") * "scale", var("s") * "scale"))],
        returns: None,
    };
    let [stages, update, step, sub_step] = rk4(
        Field::Model,
        ["rk4_stages", "rk4_update", "rk4_step", "sub_step"],
    );
    let increment = Function {
        name: "rk4_increment",
        body: turned(),
        results: vec![
            ("y", call("rk4_stages", &["phase", "mid", "end", "y", "h"])),
            ("phase", var("end")),
        ],
        ..step.clone()
    };
    let held = rk4(
        Field::Held,
        ["held_stages", "held_update", "held_step", "held_sub_step"],
    );
    let mut functions = vec![rotate, cos_sin(), stages, update, increment, step, sub_step];
    functions.extend(held);
    functions.extend(crossing_tests());
    functions.extend(surface_tests());
    functions.push(orientation());
    functions.extend(sliding());
    functions.extend(super::events::stops());
    functions.extend(super::events::location());
    functions.extend(super::events::linear_location());
    functions.extend(super::surfaces::functions());
    // The step loop's functions in the variant with every part (the
    // kernels print the one their scene needs).
    functions.extend(super::impacts::functions(true, true));
    functions.extend(super::trajectory::functions(true));
    let (mut structures, mut externs) = super::events::kernels();
    externs.extend(super::surfaces::kernels());
    externs.extend(super::impacts::kernels());
    externs.extend(super::trajectory::kernels());
    structures.extend(super::surfaces::structures());
    structures.extend(super::impacts::structures(true));
    structures.extend(super::trajectory::structures());
    structures.extend([super::events::stop(), super::events::hit()]);
    structures.extend(super::events::location_structures());
    Program {
        functions,
        structures,
        externs,
    }
}

/// The functions only C prints: the sliding fields, NaN where the
/// control does not exist (WGSL has no constant NaN; the kernels slide on
/// one switch only and test α where they use it).
pub const C_ONLY: [&str; 2] = ["sliding_field_1", "sliding_field_2"];

/// The sliding motion's field (`integrate::surface::equivalent_on`),
/// from the fields F₀ of the base region and F_m of the region with
/// switch m's bit set, and their rates along the switches' gradients
/// (summed by the caller, who knows where a gradient lies):
///
/// - `filippov_alpha(a, b)`: on one switch, α = a/(a - b), a = ∇g·F₀,
///   b = ∇g·F₁ (Filippov's convex combination).
/// - `filippov_field(lo, hi, alpha)`: F₀ + α(F₁ - F₀).
/// - `sliding_field_1(lo, hi, a, b)`: that field where α is finite, else
///   NaN in every component.
/// - `sliding_field_2(f0, f1, f2, a0, a1, d00, d01, d10, d11)`: on two
///   switches at once, `surface::solve`'s elimination with partial
///   pivoting of (a_j - d_jk) u = a (a_j = ∇g_j·F₀, d_jk = ∇g_j·F_{k+1}),
///   then F₀ + u₀(F₁ - F₀) + u₁(F₂ - F₀); NaN where a pivot is 0 or u is
///   not finite.
fn sliding() -> [Function; 4] {
    use Ty::{Real, State};
    let alpha = Function {
        name: "filippov_alpha",
        params: vec![("a", Real), ("b", Real)],
        body: Vec::new(),
        results: vec![("alpha", var("a") / (var("a") - "b"))],
        returns: None,
    };
    let field = Function {
        name: "filippov_field",
        params: vec![("lo", State), ("hi", State), ("alpha", Real)],
        body: Vec::new(),
        results: vec![("field", var("lo") + var("alpha") * (var("hi") - "lo"))],
        returns: None,
    };
    let one = Function {
        name: "sliding_field_1",
        params: vec![("lo", State), ("hi", State), ("a", Real), ("b", Real)],
        body: lets(vec![
            ("alpha", call("filippov_alpha", &["a", "b"])),
            ("field", call("filippov_field", &["lo", "hi", "alpha"])),
        ]),
        results: vec![(
            "sliding",
            select(finite(var("alpha")), var("field"), fill(num(f64::NAN))),
        )],
        returns: None,
    };
    [alpha, field, one, two_switches()]
}

/// `sliding_field_2` (see [`sliding`]): the pivot of column 0 is the row
/// with the larger |M_j0| in `total_cmp`'s order (NaN above all), the
/// second on a tie (`max_by` keeps the last maximum); after the swap the
/// pivot's row is [p0 p1 | pr], the other's [q0 q1 | qr]; elimination,
/// then back-substitution, in `solve`'s order. Selections, not branches:
/// every value is computed, as C's `?:` did.
fn two_switches() -> Function {
    use Ty::{Real, State};
    let is_nan = |x: &'static str| cmp(Cmp::NotEqual, var(x), var(x));
    let pick = |a: &'static str, b: &'static str| select(var("swap"), var(a), var(b));
    let mut params = vec![("f0", State), ("f1", State), ("f2", State)];
    for name in ["a0", "a1", "d00", "d01", "d10", "d11"] {
        params.push((name, Real));
    }
    Function {
        name: "sliding_field_2",
        params,
        body: lets(vec![
            ("m00", var("a0") - "d00"),
            ("m01", var("a0") - "d01"),
            ("m10", var("a1") - "d10"),
            ("m11", var("a1") - "d11"),
            ("x0", abs(var("m00"))),
            ("x1", abs(var("m10"))),
            (
                "swap",
                or(
                    is_nan("x1"),
                    and(not(is_nan("x0")), cmp(Cmp::GreaterEq, var("x1"), var("x0"))),
                ),
            ),
            ("p0", pick("m10", "m00")),
            ("p1", pick("m11", "m01")),
            ("pr", pick("a1", "a0")),
            ("q0", pick("m00", "m10")),
            ("q1", pick("m01", "m11")),
            ("qr", pick("a0", "a1")),
            ("k", var("q0") / "p0"),
            ("e1", var("q1") - var("k") * "p1"),
            ("er", var("qr") - var("k") * "pr"),
            ("u1", var("er") / "e1"),
            ("u0", (var("pr") - var("p1") * "u1") / "p0"),
            (
                "ok",
                and(
                    and(
                        cmp(Cmp::NotEqual, var("p0"), num(0.0)),
                        cmp(Cmp::NotEqual, var("e1"), num(0.0)),
                    ),
                    and(finite(var("u0")), finite(var("u1"))),
                ),
            ),
            (
                "field",
                var("f0") + var("u0") * (var("f1") - "f0") + var("u1") * (var("f2") - "f0"),
            ),
        ]),
        results: vec![(
            "sliding",
            select(var("ok"), var("field"), fill(num(f64::NAN))),
        )],
        returns: None,
    }
}

/// The phases of the step's middle and end: what every whole step takes,
/// apart from where the phases are turned (the native step loops turn
/// them once for all slots).
fn turned() -> Vec<Stmt> {
    lets(vec![
        ("mid", call("rotate", &["phase", "half"])),
        ("end", call("rotate", &["mid", "half"])),
    ])
}

/// RK4 of the field `of` (`integrate::rk4::step`), as the functions named
/// `names`: its stages (the increment at the three phases given), its
/// update (the step's end from them), its whole step (the phases turned
/// through `half` = the (cos, sin) of ωh/2, the end and its phase), and
/// its step of any size s from a phase (`half` from ω: the re-steps of a
/// crossing's location, `integrate::locate`'s `rk4::step` with
/// `cos_sin(0.5 ω s)`).
fn rk4(of: Field, [stages, update, step, sub_step]: [&'static str; 4]) -> [Function; 4] {
    use Ty::{Pair, Real, State};
    let at = [
        ("phase", Pair),
        ("mid", Pair),
        ("end", Pair),
        ("y", State),
        ("h", Real),
    ];
    let stages = Function {
        name: stages,
        params: at.to_vec(),
        body: lets(vec![
            ("h2", num(0.5) * "h"),
            ("k1", field(of, "phase", var("y"))),
            ("y2", var("y") + var("h2") * "k1"),
            ("k2", field(of, "mid", var("y2"))),
            ("y3", var("y") + var("h2") * "k2"),
            ("k3", field(of, "mid", var("y3"))),
            ("y4", var("y") + var("h") * "k3"),
            ("k4", field(of, "end", var("y4"))),
            ("sixth", var("h") / 6.0),
        ]),
        results: vec![(
            "increment",
            var("sixth") * (var("k1") + num(2.0) * (var("k2") + "k3") + "k4"),
        )],
        returns: None,
    };
    let update = Function {
        name: update,
        params: at.to_vec(),
        body: lets(vec![(
            "increment",
            call(stages.name, &["phase", "mid", "end", "y", "h"]),
        )]),
        results: vec![("y", var("y") + "increment")],
        returns: None,
    };
    let step = Function {
        name: step,
        params: vec![("phase", Pair), ("half", Pair), ("y", State), ("h", Real)],
        body: turned(),
        results: vec![
            ("y", call(update.name, &["phase", "mid", "end", "y", "h"])),
            ("phase", var("end")),
        ],
        returns: Some("Stepped"),
    };
    let mut from_omega = vec![Stmt::Let(
        "half",
        Expr::Call("cos_sin", vec![num(0.5) * "omega" * "s"]),
    )];
    from_omega.extend(turned());
    let sub_step = Function {
        name: sub_step,
        params: vec![("omega", Real), ("phase", Pair), ("y", State), ("s", Real)],
        body: from_omega,
        results: vec![
            ("y", call(update.name, &["phase", "mid", "end", "y", "s"])),
            ("phase", var("end")),
        ],
        returns: Some("Stepped"),
    };
    [stages, update, step, sub_step]
}

/// `cos_sin(angle)`: (cos φ, sin φ) by Taylor polynomials to φ^14 and
/// φ^15, halving φ (at most 8 times) until |φ| ≤ 1/2 and doubling back,
/// as `integrate::clock::cos_sin` (WGSL's transcendental builtins are
/// undefined on f64 under Vulkan). The Horner sums are written out term
/// by term (the Rust's loop over a table of 1/n!, which WGSL has no
/// constant arrays for).
fn cos_sin() -> Function {
    use crate::integrate::clock::{INV_FACT, TAYLOR_TOP};
    let mut body = vec![
        Stmt::Var("phi", var("angle")),
        Stmt::Var("halvings", count(0)),
        Stmt::Loop(vec![
            break_unless(and(
                greater(abs(var("phi")), num(0.5)),
                less(var("halvings"), count(8)),
            )),
            Stmt::Set("phi", var("phi") * 0.5),
            Stmt::Set("halvings", var("halvings") + count(1)),
        ]),
        Stmt::Let("x2", var("phi") * "phi"),
        Stmt::Var("c", num(TAYLOR_TOP[0])),
        Stmt::Var("s", num(TAYLOR_TOP[1])),
    ];
    for k in (0..7).rev() {
        body.push(Stmt::Set("c", num(INV_FACT[2 * k]) - var("x2") * "c"));
        body.push(Stmt::Set("s", num(INV_FACT[2 * k + 1]) - var("x2") * "s"));
    }
    body.extend([
        Stmt::Var("result", pair(var("c"), var("phi") * "s")),
        Stmt::Var("doublings", count(0)),
        Stmt::Loop(vec![
            break_unless(less(var("doublings"), var("halvings"))),
            Stmt::Let("rc", first(var("result"))),
            Stmt::Let("rs", second(var("result"))),
            Stmt::Set(
                "result",
                pair(var("rc") * "rc" - var("rs") * "rs", num(2.0) * "rs" * "rc"),
            ),
            Stmt::Set("doublings", var("doublings") + count(1)),
        ]),
    ]);
    Function {
        name: "cos_sin",
        params: vec![("angle", Ty::Real)],
        body,
        results: vec![("phase", var("result"))],
        returns: None,
    }
}

/// The stop test of walls and surfaces alike (`integrate::wall::may_reach`,
/// bounded):
///
/// - `may_turn_past(g0, s0, g1, s1, h)`: whether a step of size h turning
///   back inside (rate s0 > 0 to s1 < 0, values g0, g1 short of the
///   surface) may pass it in between: not when both ends fall short by
///   `TURN_REACH`·h·(s0 - s1), twice the most the step's cubic can rise
///   (`integrate::wall::may_turn_past`).
/// - `may_meet(start, end, h)`: whether a step whose (value, rate) goes
///   from `start` to `end` may cross (value > 0 across): it ends across,
///   or turns back within reach.
fn crossing_tests() -> [Function; 2] {
    use Ty::{Pair, Real};
    let turn_past = Function {
        name: "may_turn_past",
        params: vec![
            ("g0", Real),
            ("s0", Real),
            ("g1", Real),
            ("s1", Real),
            ("h", Real),
        ],
        body: lets(vec![(
            "reach",
            num(crate::integrate::wall::TURN_REACH) * "h" * (var("s0") - "s1"),
        )]),
        results: vec![(
            "passes",
            not(and(
                less(var("g0") + "reach", num(0.0)),
                less(var("g1") + "reach", num(0.0)),
            )),
        )],
        returns: None,
    };
    let meet = Function {
        name: "may_meet",
        params: vec![("start", Pair), ("end", Pair), ("h", Real)],
        body: lets(vec![(
            "turns",
            Expr::Call(
                "may_turn_past",
                vec![cos("start"), sin("start"), cos("end"), sin("end"), var("h")],
            ),
        )]),
        results: vec![(
            "meets",
            or(
                greater(cos("end"), num(0.0)),
                and(
                    and(greater(sin("start"), num(0.0)), less(sin("end"), num(0.0))),
                    var("turns"),
                ),
            ),
        )],
        returns: None,
    };
    [turn_past, meet]
}

/// A general surface's tests (`integrate::surface::may_cross`) on its
/// (value, rate) before and after a step, in the trajectory's region,
/// where the surface's orientation o (±1, `Surface::orientation`) turns
/// them so that > 0 lies across:
///
/// - `orient(o, v)`: the pair times o, exactly.
/// - `oriented_ends_across(o, before, after)`: the step ends across, or
///   its rate turns from approaching to leaving: the native step loops'
///   first, plain pass over the slots (`may_meet` without the reach,
///   which a few steps in a hundred need).
/// - `oriented_may_meet(o, before, after, h)`: `may_meet` of the
///   oriented pairs.
fn surface_tests() -> [Function; 3] {
    use Ty::{Pair, Real};
    let orient = Function {
        name: "orient",
        params: vec![("o", Real), ("v", Pair)],
        body: Vec::new(),
        results: vec![("oriented", pair(var("o") * cos("v"), var("o") * sin("v")))],
        returns: None,
    };
    let params = vec![("o", Real), ("before", Pair), ("after", Pair)];
    let oriented = lets(vec![
        ("start", call("orient", &["o", "before"])),
        ("end", call("orient", &["o", "after"])),
    ]);
    let across = Function {
        name: "oriented_ends_across",
        params: params.clone(),
        body: oriented.clone(),
        results: vec![(
            "across",
            or(
                greater(cos("end"), num(0.0)),
                and(greater(sin("start"), num(0.0)), less(sin("end"), num(0.0))),
            ),
        )],
        returns: None,
    };
    let mut with_h = params;
    with_h.push(("h", Real));
    let meet = Function {
        name: "oriented_may_meet",
        params: with_h,
        body: oriented,
        results: vec![("meets", call("may_meet", &["start", "end", "h"]))],
        returns: None,
    };
    [orient, across, meet]
}

/// A surface's bit that marks an event (WGSL's `EVENT`): no region bit.
pub const EVENT: u32 = u32::MAX;

/// `orientation(region, bit)`: +1 where the crossing to watch for is g
/// rising through 0 (an event, or a switch whose `bit` is clear in
/// `region`, on its negative side), -1 where it is g falling
/// (`Surface::orientation`): what the region walk's stop tests orient
/// their values by, in the kernels and the native step loops.
fn orientation() -> Function {
    let side = bit_and(shr(var("region"), var("bit")), count(1));
    let above = and(
        cmp(Cmp::NotEqual, var("bit"), count(EVENT)),
        cmp(Cmp::Equal, side, count(1)),
    );
    Function {
        name: "orientation",
        params: vec![("region", Ty::Count), ("bit", Ty::Count)],
        body: Vec::new(),
        results: vec![("o", select(above, num(-1.0), num(1.0)))],
        returns: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_function_is_well_typed() {
        let program = integrator();
        let expected = [
            ("rotate", vec![Ty::Pair]),
            ("cos_sin", vec![Ty::Pair]),
            ("rk4_stages", vec![Ty::State]),
            ("rk4_update", vec![Ty::State]),
            ("rk4_increment", vec![Ty::State, Ty::Pair]),
            ("rk4_step", vec![Ty::State, Ty::Pair]),
            ("sub_step", vec![Ty::State, Ty::Pair]),
            ("held_stages", vec![Ty::State]),
            ("held_update", vec![Ty::State]),
            ("held_step", vec![Ty::State, Ty::Pair]),
            ("held_sub_step", vec![Ty::State, Ty::Pair]),
            ("may_turn_past", vec![Ty::Bool]),
            ("may_meet", vec![Ty::Bool]),
            ("orient", vec![Ty::Pair]),
            ("oriented_ends_across", vec![Ty::Bool]),
            ("oriented_may_meet", vec![Ty::Bool]),
            ("orientation", vec![Ty::Real]),
            ("filippov_alpha", vec![Ty::Real]),
            ("filippov_field", vec![Ty::State]),
            ("sliding_field_1", vec![Ty::State]),
            ("sliding_field_2", vec![Ty::State]),
            ("gap", vec![Ty::Real]),
            ("speed", vec![Ty::Real]),
            ("on_stop", vec![Ty::State]),
            ("stop_values", vec![Ty::Pair]),
            ("reaches", vec![Ty::Bool]),
            ("at_rest", vec![Ty::Bool]),
            ("reaches_a_stop", vec![Ty::Bool]),
            ("resting_on", vec![Ty::Count]),
            ("clamp_to", vec![Ty::State]),
            ("clamp_to_stops", vec![Ty::State]),
            ("behind_a_stop", vec![Ty::Bool]),
            ("state_scale", vec![Ty::Real]),
            ("held_rhs", vec![Ty::State]),
            ("pressing", vec![Ty::Real]),
            ("pressed", vec![Ty::Bool]),
            ("pressed_on", vec![Ty::Count]),
            ("hermite_new", vec![Ty::Struct("Hermite")]),
            ("hermite_value", vec![Ty::Real]),
            ("hermite_slope", vec![Ty::Real]),
            ("hermite_peak", vec![Ty::Real]),
            ("hermite_first_root", vec![Ty::Real]),
            ("bracket_of", vec![Ty::Struct("Bracket")]),
            ("newton_update", vec![Ty::Struct("Bracket")]),
            ("locate_newton", vec![Ty::Struct("Hit")]),
            ("crossing_fraction", vec![Ty::Real]),
            ("locate_linear", vec![Ty::Struct("Hit")]),
        ];
        // The surfaces' and the step loop's are typed in
        // `model::ir::surfaces` and `model::ir::impacts`.
        let surfaces = super::super::surfaces::functions().len();
        let impacts =
            super::super::impacts::FUNCTIONS.len() + super::super::trajectory::FUNCTIONS.len();
        assert_eq!(program.functions.len(), expected.len() + surfaces + impacts);
        for (name, types) in expected {
            assert_eq!(
                program.function(name).result_types(&program),
                types,
                "{name}"
            );
        }
    }
}
