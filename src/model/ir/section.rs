//! The section kernel's step program (in the language of
//! `model::ir::step`): a Poincaré map's job of steps, advancing a
//! trajectory by its steps or seeking its next crossing of the section.
//! Printed to WGSL by `model::codegen::step` for `shaders/section.wgsl`,
//! whose entry point calls `section_job`; what it leaves written by hand is
//! the kernel's buffer access it calls (`load`, `store`) and the dispatch.
//!
//! The CPU's twins are the oracle: `integrate::section::Section::crossed`
//! (the crossing test) and the RK4 steps of `integrate::rk4` with the f32
//! kernels' compensated sum (the host, `backend::gpu::section`, runs the
//! map's algorithm).

use super::step::build::*;
use super::step::{Cmp, Expr, Extern, Function, Program, Stmt, Structure, Ty};

/// What the section's functions use of the kernel: the section
/// (`SECTION_STATE`, `SECTION_DIRECTION`, its `at` per lane at
/// `LANE_AT`), the layout (`DIM`, `LANE_STRIDE`), the job modes and ends
/// (`ADVANCE`, `SEEK`, `CROSSED`, `DONE`, `MISSED`, `TRUNCATED`), the
/// uniform `control`, the buffers `jobs` (per job: its lane, its mode,
/// its step limit, the steps taken), `steps` (its h), `lanes` and
/// `states`, and `load(at)`, `store(at, y)`, `load_params(lane)`,
/// `is_finite(y)`, `loop_budget_exhausted()` and the integrator's
/// `rk4_increment(p, phase, half, y, h)`.
pub fn kernels() -> Vec<Extern> {
    use Ty::{Bool, Count, CountTable, Pair, Real, State};
    let params = Ty::Struct("Params");
    let counts = [
        "DIM",
        "LANE_STRIDE",
        "LANE_AT",
        "SECTION_STATE",
        "ADVANCE",
        "SEEK",
        "CROSSED",
        "DONE",
        "MISSED",
        "TRUNCATED",
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
    let control = ["job_count", "chunk_steps", "opaque_zero"];
    let mut externs: Vec<Extern> = counts.map(|c| Extern::Const(c, Count)).into();
    externs.extend([
        Extern::Const("SECTION_DIRECTION", Real),
        Extern::Struct("SectionControl", control.map(|m| (m, Count)).into()),
        Extern::Const("control", Ty::Struct("SectionControl")),
        Extern::Struct("Stepped", vec![("y", State)]),
        buffer("jobs", CountTable, true),
        buffer("steps", Real, false),
        buffer("lanes", Real, false),
        function("load", vec![Count], State),
        function("load_params", vec![Count], params),
        function("is_finite", vec![State], Bool),
        function("loop_budget_exhausted", Vec::new(), Bool),
        function(
            "rk4_increment",
            vec![params, Pair, Pair, State, Real],
            Ty::Struct("Stepped"),
        ),
        Extern::Proc {
            name: "store",
            params: vec![Count, State],
        },
    ]);
    externs
}

/// The section kernel's program, f32's compensated steps where
/// `compensated`:
///
/// - `crossed(at, before, after)`: whether a step from `before` to
///   `after` crossed the section y_k = at in its direction, from behind
///   it to on or past it (`Section::crossed`).
/// - `section_job(j)`: job j's steps in this dispatch (see the kernel).
pub fn program(compensated: bool) -> Program {
    let side = |y| var("SECTION_DIRECTION") * (index(var(y), var("SECTION_STATE")) - "at");
    let crossed = Function {
        name: "crossed",
        params: vec![
            ("at", Ty::Real),
            ("before", Ty::State),
            ("after", Ty::State),
        ],
        body: lets(vec![("d0", side("before")), ("d1", side("after"))]),
        results: vec![(
            "crossed",
            and(
                less(var("d0"), num(0.0)),
                cmp(Cmp::GreaterEq, var("d1"), num(0.0)),
            ),
        )],
        returns: None,
    };
    Program {
        functions: vec![crossed, section_job(compensated)],
        structures: vec![Structure {
            name: "Params",
            members: Vec::new(),
        }],
        externs: kernels(),
    }
}

/// Job j's counter `k` (0: its lane, 1: its mode and end, 2: its limit,
/// 3: the steps taken).
fn job(k: u32) -> Expr {
    index(var("job"), count(k))
}

/// The steps of one dispatch: at most `chunk_steps` of the job's, each
/// an RK4 step of h at the still phase (an autonomous flow), until a
/// step crosses the section (SEEK), the limit, or a state that is not
/// finite (NaN crosses nothing: a failed trajectory stops, as the CPU
/// steps it to the end of its budget for the same None). f32 sums the
/// steps with Kahan's compensation: an increment is far smaller than y,
/// and f32 would drop its low bits every step; between dispatches the
/// compensation waits in the job's second state.
fn steps(compensated: bool) -> Vec<Stmt> {
    let increment = member(
        apply(
            "rk4_increment",
            vec![var("p"), var("still"), var("still"), var("y"), var("h")],
        ),
        "y",
    );
    let mut body = vec![break_unless(less(var("k"), var("end")))];
    if compensated {
        let opaque = cmp(Cmp::NotEqual, dot("control", "opaque_zero"), count(0));
        body.extend([
            Stmt::Let("corrected", increment - "comp"),
            Stmt::Set("after", select(opaque, var("y"), var("y") + "corrected")),
            Stmt::Let("next_comp", (var("after") - "y") - "corrected"),
        ]);
    } else {
        body.push(Stmt::Set("after", var("y") + increment));
    }
    let seeking = cmp(Cmp::Equal, var("mode"), var("SEEK"));
    let crosses = apply("crossed", vec![var("at"), var("y"), var("after")]);
    body.extend([
        Stmt::If(and(seeking, crosses), vec![Stmt::Break], Vec::new()),
        Stmt::Set("y", var("after")),
    ]);
    if compensated {
        body.push(Stmt::Set("comp", var("next_comp")));
    }
    body.extend([
        Stmt::If(
            not(apply("is_finite", vec![var("y")])),
            vec![Stmt::Set("k", job(2)), Stmt::Break],
            Vec::new(),
        ),
        Stmt::Set("k", var("k") + count(1)),
    ]);
    vec![Stmt::Loop(body)]
}

/// A job's end: truncated where the dispatch ran past lavapipe's loop
/// cap, crossed where a crossing left the loop before its end (the step's
/// end kept after its start), done or missed at its limit.
fn job_end(compensated: bool) -> Vec<Stmt> {
    let second = || var("base") + var("DIM");
    let mut limit = vec![Stmt::If(
        cmp(Cmp::GreaterEq, var("k"), job(2)),
        vec![Stmt::SetAt(
            "job",
            count(1),
            select(
                cmp(Cmp::Equal, var("mode"), var("SEEK")),
                var("MISSED"),
                var("DONE"),
            ),
        )],
        Vec::new(),
    )];
    if compensated {
        limit.push(perform("store", vec![second(), var("comp")]));
    }
    let ends = vec![
        Stmt::If(
            less(var("k"), var("end")),
            vec![
                Stmt::SetAt("job", count(1), var("CROSSED")),
                perform("store", vec![second(), var("after")]),
            ],
            limit,
        ),
        Stmt::SetAt("job", count(3), min(var("k"), job(2))),
        perform("store", vec![var("base"), var("y")]),
        Stmt::SetAt("jobs", var("j"), var("job")),
    ];
    let truncated = vec![
        Stmt::SetAt("job", count(1), bit_or(job(1), var("TRUNCATED"))),
        Stmt::SetAt("jobs", var("j"), var("job")),
    ];
    vec![Stmt::If(
        apply("loop_budget_exhausted", Vec::new()),
        truncated,
        ends,
    )]
}

fn section_job(compensated: bool) -> Function {
    let lane = job(0);
    let mut run = lets(vec![
        ("p", apply("load_params", vec![lane.clone()])),
        (
            "at",
            index(var("lanes"), lane * var("LANE_STRIDE") + var("LANE_AT")),
        ),
        ("h", index(var("steps"), var("j"))),
        ("base", var("j") * count(2) * var("DIM")),
    ]);
    run.extend([
        Stmt::Var("y", apply("load", vec![var("base")])),
        // An autonomous flow: the clock stands still at phase 0.
        Stmt::Let("still", pair(num(1.0), num(0.0))),
        Stmt::Let("end", min(job(3) + dot("control", "chunk_steps"), job(2))),
        Stmt::Var("k", job(3)),
        Stmt::Var("after", var("y")),
    ]);
    if compensated {
        let second = var("base") + var("DIM");
        run.push(Stmt::Var("comp", apply("load", vec![second])));
    }
    run.extend(steps(compensated));
    run.extend(job_end(compensated));
    let mode = bit_and(job(1), count(0xff));
    let runs = or(
        cmp(Cmp::Equal, var("mode"), var("ADVANCE")),
        cmp(Cmp::Equal, var("mode"), var("SEEK")),
    );
    Function {
        name: "section_job",
        params: vec![("j", Ty::Count)],
        body: vec![
            Stmt::Var("job", index(var("jobs"), var("j"))),
            Stmt::Let("mode", mode),
            Stmt::If(runs, run, Vec::new()),
        ],
        results: Vec::new(),
        returns: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_section_s_functions_are_well_typed() {
        for compensated in [false, true] {
            let program = program(compensated);
            for f in &program.functions {
                f.result_types(&program);
            }
        }
    }
}
