//! The C source of a tape's native code (`model::native::library`): the functions
//! of a field's tape ([`Kind`]), the step loops between stops, over the
//! regions of a model with general surfaces too, and the steps of its
//! slides, each a loop over the slots that the C compiler vectorises.
//! The tapes themselves are printed by `model::codegen::print` with C's
//! [`Syntax`] (numbers of the same bits, the exact functions as builtins,
//! every other function a call back into Rust), the text around them
//! here: the same operations in the same order as the interpreter
//! (`Tape::run`), `rk4::step_batch` and `integrate::steps`.

use crate::integrate::surface::Surface;
use crate::model::codegen::print::{self, Inputs, Syntax};
use crate::model::codegen::step::{self, CField, CValue};
use crate::model::ir::integrator::integrator;
use crate::model::ir::tape::{Code, Tape};
use crate::model::language::expr::Func;
use crate::model::native::abi::{Kind, Layout, StopCode, WALK_WIDTHS, WIDTHS};
use std::fmt::Write as _;

/// C's [`Syntax`]: `calls` are the functions called back into Rust, by
/// their index in the source's table.
struct C<'a> {
    calls: &'a [Func],
}

impl Syntax for C<'_> {
    fn literal(&self, v: f64) -> String {
        literal(v)
    }

    fn declare(&self, name: &str, value: &str) -> String {
        format!("const double {name} = {value};")
    }

    fn call(&self, f: Func, a: &str, b: &str) -> String {
        match f {
            Func::Sqrt => format!("__builtin_sqrt({a})"),
            Func::Abs => format!("__builtin_fabs({a})"),
            // The same Rust functions as the interpreter calls.
            f => {
                let i = self.calls.iter().position(|&g| g == f).expect("listed");
                format!("calls[{i}]({a}, {b})")
            }
        }
    }
}

/// One region's tapes: the field, and where the model has general
/// surfaces, their values and rates along it.
pub(crate) struct Region<'a> {
    pub(crate) field: &'a Tape,
    pub(crate) surfaces: Option<&'a Tape>,
}

/// The C source of `regions`' code, and the functions it calls back into
/// Rust, by their index in its table (the source holds no address, so one
/// object serves every process): the first region's functions of
/// `functions`' kinds ([`function`], every width and layout), where
/// `stops` are given the step loops of `regions` ([`walk`], every width
/// and layout), and the steps of their slides on the switches of `kinds`.
pub(crate) fn source_of(
    regions: &[Region],
    stops: Option<&[StopCode]>,
    kinds: &[Surface],
    functions: &[Kind],
) -> (String, Vec<Func>) {
    let mut calls: Vec<Func> = Vec::new();
    let tapes = regions
        .iter()
        .flat_map(|r| std::iter::once(r.field).chain(r.surfaces));
    for tape in tapes {
        for ins in tape.lowered().0 {
            if let Code::Call(f) = ins.code {
                if !matches!(f, Func::Sqrt | Func::Abs) && !calls.contains(&f) {
                    calls.push(f);
                }
            }
        }
    }
    let mut source = format!(
        "#include <stdint.h>\ntypedef double (*apply)(double, double);\n\
         static apply calls[{n}];\n\
         void set_calls(const apply *t) {{ for (int i = 0; i < {n}; i++) calls[i] = t[i]; }}\n",
        n = calls.len().max(1)
    );
    for &kind in functions {
        for &w in &WIDTHS {
            for layout in [Layout::Shared, Layout::Each] {
                function(&mut source, regions[0].field, &calls, kind, w, layout);
            }
        }
    }
    if let Some(stops) = stops {
        for &w in &WALK_WIDTHS {
            for layout in [Layout::Shared, Layout::Each] {
                walk(&mut source, regions, &calls, stops, kinds, w, layout);
            }
        }
    }
    for (base, bits) in slides(regions.len(), kinds) {
        let tapes: Vec<&Tape> = std::iter::once(base)
            .chain(bits.iter().map(|b| base | 1 << b))
            .map(|r| regions[r].field)
            .collect();
        slide_step(
            &mut source,
            &calls,
            &slide_name(base, &bits),
            &tapes,
            sum_start(),
        );
    }
    (source, calls)
}

/// Appends `{kind:?}{w}{layout:?}`, the [`Function`] of `kind` of `tape`
/// for batches of `w` in `layout`: a loop over the slots, each the tape's
/// outputs at one clock phase ([`Kind::Rhs`], `Tape::run`) or one RK4 step
/// (`rk4::step_batch`, the phases of its three stages in the clock), the
/// same operations in the same order as the interpreter's and the step
/// loops'.
fn function(out: &mut String, tape: &Tape, calls: &[Func], kind: Kind, w: usize, layout: Layout) {
    let d = tape.states;
    let each = layout == Layout::Each;
    // A value per slot (`Each`) or one for all (`Shared`), at row `r`.
    let row = |base: &str, r: usize| {
        if each {
            format!("{base}[{} + k]", r * w)
        } else {
            format!("{base}[{r}]")
        }
    };
    let _ = writeln!(
        out,
        "void {kind:?}{w}{layout:?}(const double *restrict y, const double *restrict clock, \
         const double *restrict lane, const double *restrict h, double *restrict out) {{\n  \
         for (int k = 0; k < {w}; k++) {{"
    );
    let state: Vec<String> = (0..d).map(|i| format!("y[{} + k]", i * w)).collect();
    let lane = |_: &str, j: usize| row("lane", j);
    let values = match kind {
        Kind::Rhs => {
            let _ = writeln!(
                out,
                "      const double c = {}, s = {};",
                row("clock", 0),
                row("clock", 1)
            );
            rhs(out, tape, calls, "v", &state, ("c", "s"), &lane)
        }
        Kind::Step => {
            let names = ["c", "s", "mc", "ms", "ec", "es"];
            for (r, name) in names.iter().enumerate() {
                let _ = writeln!(out, "      const double {name} = {};", row("clock", r));
            }
            let _ = writeln!(out, "      const double hh = {};", row("h", 0));
            rk4(out, tape, calls, "q", &state, &lane)
        }
    };
    for (m, value) in values.iter().enumerate() {
        let _ = writeln!(out, "      out[{} + k] = {value};", m * w);
    }
    out.push_str("  }\n}\n");
}

/// The slides a model's library has a step for: on one switch or two at
/// once (their bits, in the order of their surfaces, as
/// `surface::SlidingSet` lists them), from each base region without
/// their bits.
pub(crate) fn slides(regions: usize, kinds: &[Surface]) -> Vec<(usize, Vec<usize>)> {
    let bits: Vec<usize> = kinds
        .iter()
        .filter_map(|k| match *k {
            Surface::Switch { bit } => Some(bit as usize),
            _ => None,
        })
        .collect();
    let sets = bits.iter().map(|&b| vec![b]).chain(
        (0..bits.len())
            .flat_map(|p| (p + 1..bits.len()).map(move |q| (p, q)))
            .map(|(p, q)| vec![bits[p], bits[q]]),
    );
    sets.flat_map(|set| {
        (0..regions)
            .filter(|base| set.iter().all(|b| base >> b & 1 == 0))
            .map(|base| (base, set.clone()))
            .collect::<Vec<_>>()
    })
    .collect()
}

/// The C name of a slide's step.
pub(crate) fn slide_name(base: usize, bits: &[usize]) -> String {
    let bits: Vec<String> = bits.iter().map(|b| b.to_string()).collect();
    format!("slide{base}_{}", bits.join("_"))
}

/// The value Rust's `f64` sum starts from (-0.0 in recent releases, 0.0
/// before), which a sum of terms that are all -0.0 shows.
fn sum_start() -> f64 {
    std::iter::once(-0.0_f64).sum()
}

/// Appends `walk{w}{layout:?}`: the step loop (the phase turned, the
/// RK4 step, the stops detected, as `integrate::steps` does) over `w`
/// slots, a loop over the slots per step for the compiler to vectorise.
/// Where the regions have surfaces it is a `library::SwitchWalk`: each slot
/// steps its own region's field (every region present computed over the
/// batch, each slot keeping its own's, as `ModelFlow::step_each_in`
/// does), the surfaces' values and rates are taken at each step's end as
/// `Flow::surface_values` takes them, and a step that may cross a surface
/// (`surface::may_cross`) stops the loop.
fn walk(
    out: &mut String,
    regions: &[Region],
    calls: &[Func],
    stops: &[StopCode],
    kinds: &[Surface],
    w: usize,
    layout: Layout,
) {
    let text = WalkText {
        regions,
        calls,
        stops,
        kinds,
        w,
        each: layout == Layout::Each,
        d: regions[0].field.states,
        switching: regions[0].surfaces.is_some(),
    };
    text.start(out, layout);
    text.turn_clock(out);
    if text.switching {
        text.step_regions(out);
    } else {
        text.step(out);
    }
    text.detect(out);
    text.turn_back(out);
    text.end(out);
}

/// What a step loop's text is written from (see [`walk`]).
struct WalkText<'a> {
    regions: &'a [Region<'a>],
    calls: &'a [Func],
    stops: &'a [StopCode],
    kinds: &'a [Surface],
    w: usize,
    /// Whether the layout is `Each` (a value per slot).
    each: bool,
    /// The states.
    d: usize,
    /// Whether the regions have surfaces (a `SwitchWalk`).
    switching: bool,
}

impl WalkText<'_> {
    /// A value per slot (`Each`) or one for all (`Shared`), at row `r`.
    fn row(&self, base: &str, r: usize) -> String {
        if self.each {
            format!("{base}[{} + k]", r * self.w)
        } else {
            format!("{base}[{r}]")
        }
    }

    /// The surfaces' rows of values and rates: g and its rate per surface.
    fn rows(&self) -> usize {
        2 * self.kinds.len()
    }

    /// The signature, the states copied in, and for a model with surfaces
    /// what its regions' steps and tests read.
    fn start(&self, out: &mut String, layout: Layout) {
        let (w, d) = (self.w, self.d);
        let (lanes, extra) = if self.switching {
            (
                "const double *const *restrict lanes",
                ", const int64_t *restrict region, double *restrict values",
            )
        } else {
            ("const double *restrict lane", "")
        };
        let _ = writeln!(
            out,
            "uint64_t walk{w}{layout:?}(double *restrict y, double *restrict clock, \
             {lanes}, const double *restrict h, \
             const double *restrict walls, const int64_t *restrict live, uint64_t steps{extra}) {{"
        );
        for i in 0..d {
            let _ = writeln!(out, "  double y{i}[{w}];");
            let _ = writeln!(
                out,
                "  for (int k = 0; k < {w}; k++) y{i}[k] = y[{} + k];",
                i * w
            );
        }
        if self.switching {
            self.start_regions(out);
        }
        out.push_str(
            "  double c = clock[0], s = clock[1];\n  const double hc = clock[2], hs = clock[3];\n  uint64_t n = 0;\n  for (; n < steps; n++) {\n",
        );
    }

    /// Each region's constants: its field's (`lf`) and its surfaces'
    /// (`ls`); the regions present (fixed while the loop runs: a slot
    /// changes region only at a crossing, which stops it); each surface's
    /// orientation in each slot's region (`Surface::orientation`); the
    /// surfaces' values and rates at the step's start (`sb`) and end
    /// (`sa`), and the step's end (`z`).
    fn start_regions(&self, out: &mut String) {
        let (w, d) = (self.w, self.d);
        for r in 0..self.regions.len() {
            let _ = writeln!(
                out,
                "  const double *restrict lf{r} = lanes[{}], *restrict ls{r} = lanes[{}];",
                2 * r,
                2 * r + 1
            );
        }
        let _ = writeln!(
            out,
            "  int64_t present = 0;\n  for (int k = 0; k < {w}; k++) present |= (int64_t)1 << region[k];"
        );
        for (j, kind) in self.kinds.iter().enumerate() {
            let _ = writeln!(
                out,
                "  double so{j}[{w}];\n  for (int k = 0; k < {w}; k++) {{"
            );
            // An event is +1 in every region: its bit, `EVENT`, is no
            // shift C may compute.
            let o = match kind {
                Surface::Switch { bit } => {
                    let args = vec![
                        CValue::Count("region[k]".into()),
                        CValue::Count(format!("{bit}u")),
                    ];
                    let o = inline(
                        out,
                        self.calls,
                        "orientation",
                        args,
                        &format!("so{j}_"),
                        "    ",
                    );
                    let CValue::Real(o) = o else {
                        unreachable!("an orientation is a number")
                    };
                    o
                }
                Surface::Event => "1.0".into(),
            };
            let _ = writeln!(out, "    so{j}[k] = {o};\n  }}");
        }
        for m in 0..self.rows() {
            let _ = writeln!(
                out,
                "  double sb{m}[{w}], sa{m}[{w}] = {{0}};\n  \
                 for (int k = 0; k < {w}; k++) sb{m}[k] = values[{} + k];",
                m * w
            );
        }
        for i in 0..d {
            let _ = writeln!(out, "  double z{i}[{w}] = {{0}};");
        }
    }

    /// The phases of the step's middle and end (`rk4::stage_phases`):
    /// the step program's `rotate`, once for every slot.
    fn turn_clock(&self, out: &mut String) {
        let half = CValue::Pair("hc".into(), "hs".into());
        for ((c, s), (c1, s1)) in [(("c", "s"), ("mc", "ms")), (("mc", "ms"), ("ec", "es"))] {
            let phase = CValue::Pair(c.into(), s.into());
            let turned = inline(
                out,
                self.calls,
                "rotate",
                vec![phase, half.clone()],
                &format!("{c1}_"),
                "    ",
            );
            let CValue::Pair(tc, ts) = turned else {
                unreachable!("rotate gives a phase")
            };
            let _ = writeln!(out, "    const double {c1} = {tc}, {s1} = {ts};");
        }
    }

    fn step_sizes(&self, out: &mut String) {
        let _ = writeln!(out, "      const double hh = {};", self.row("h", 0));
    }

    fn state(&self) -> Vec<String> {
        (0..self.d).map(|i| format!("y{i}[k]")).collect()
    }

    /// The step of a model without surfaces, into `z`, opening the loop
    /// over the slots that tests it.
    fn step(&self, out: &mut String) {
        let w = self.w;
        for i in 0..self.d {
            let _ = writeln!(out, "    double z{i}[{w}];");
        }
        let _ = writeln!(
            out,
            "    int64_t hit = 0;\n    for (int k = 0; k < {w}; k++) {{"
        );
        self.step_sizes(out);
        let lane = |_: &str, j: usize| self.row("lane", j);
        let end = rk4(
            out,
            self.regions[0].field,
            self.calls,
            "q",
            &self.state(),
            &lane,
        );
        for (i, end) in end.iter().enumerate() {
            let _ = writeln!(out, "      z{i}[k] = {end};");
        }
    }

    /// Every region present steps the whole batch; each slot keeps its
    /// own region's step, then its surfaces' values at the step's end;
    /// then the loop over the slots that tests them opens.
    fn step_regions(&self, out: &mut String) {
        let w = self.w;
        let several = self.regions.len() > 1;
        let guard = |r: usize| {
            if several {
                format!("if (present >> {r} & 1) ")
            } else {
                String::new()
            }
        };
        let keep = |r: usize, value: &str, into: &str| {
            if several {
                format!("{into} = region[k] == {r} ? {value} : {into};")
            } else {
                format!("{into} = {value};")
            }
        };
        let state = self.state();
        for (r, region) in self.regions.iter().enumerate() {
            let _ = writeln!(out, "    {}for (int k = 0; k < {w}; k++) {{", guard(r));
            self.step_sizes(out);
            let lane = |_: &str, j: usize| self.row(&format!("lf{r}"), j);
            let end = rk4(
                out,
                region.field,
                self.calls,
                &format!("r{r}"),
                &state,
                &lane,
            );
            for (i, end) in end.iter().enumerate() {
                let _ = writeln!(out, "      {}", keep(r, end, &format!("z{i}[k]")));
            }
            out.push_str("    }\n");
        }
        let at_end: Vec<String> = (0..self.d).map(|i| format!("z{i}[k]")).collect();
        for (r, region) in self.regions.iter().enumerate() {
            let tape = region.surfaces.expect("regions with surfaces");
            let _ = writeln!(out, "    {}for (int k = 0; k < {w}; k++) {{", guard(r));
            let lane = |_: &str, j: usize| self.row(&format!("ls{r}"), j);
            let values = rhs(
                out,
                tape,
                self.calls,
                &format!("q{r}_"),
                &at_end,
                ("ec", "es"),
                &lane,
            );
            for (m, value) in values.iter().enumerate() {
                let _ = writeln!(out, "      {}", keep(r, value, &format!("sa{m}[k]")));
            }
            out.push_str("    }\n");
        }
        let _ = writeln!(
            out,
            "    int64_t hit = 0;\n    for (int k = 0; k < {w}; k++) {{"
        );
    }

    /// The tests, as `integrate::steps` does them, in two passes: the
    /// plain test in the loop over the slots (at rest on the stop, beyond
    /// it after the step, or turning back inside it), and where that fires
    /// (a few steps in a hundred), the turns again, only those within
    /// reach of the stop (`impact::may_turn_past`). Its arithmetic in
    /// every step cost the seed's oscillator a fifth of the loop. A
    /// surface's test (`surface::may_cross`) is the same: the plain one
    /// first. Breaks out of the loop over the steps where one fires.
    fn detect(&self, out: &mut String) {
        for (j, stop) in self.stops.iter().enumerate() {
            let (ci, vi) = (stop.coordinate, stop.velocity);
            let (out_of, into) = if stop.side > 0.0 {
                (">", "<")
            } else {
                ("<", ">")
            };
            let _ = writeln!(
                out,
                "      {{ const double p = {p};\n        \
                 hit |= (((y{ci}[k] == p) & (y{vi}[k] == 0.0)) | ((z{ci}[k] - p) {out_of} 0.0) \
                 | ((y{vi}[k] {out_of} 0.0) & (z{vi}[k] {into} 0.0))) & live[k]; }}",
                p = self.row("walls", j)
            );
        }
        for j in 0..self.kinds.len() {
            let test = self.surface_test(out, j, "oriented_ends_across", false, "      ");
            let _ = writeln!(out, "      hit |= {test} & live[k];");
        }
        let _ = writeln!(
            out,
            "    }}\n    if (hit) {{\n      int64_t near = 0;\n      \
             for (int k = 0; k < {}; k++) {{\n        const double hh = {};",
            self.w,
            self.row("h", 0)
        );
        self.detect_near(out);
        out.push_str("      }\n      if (near) break;\n    }\n");
    }

    /// The second pass of [`detect`](Self::detect): the gaps and speeds
    /// side·(x - p) and side·v, exact for a side of ±1; a surface's turn
    /// counts, as a stop's, only within reach of it (`surface::may_cross`,
    /// the same operations).
    fn detect_near(&self, out: &mut String) {
        for (j, stop) in self.stops.iter().enumerate() {
            let (ci, vi) = (stop.coordinate, stop.velocity);
            let _ = writeln!(
                out,
                "        {{ const double p = {p}, side = {side};\n          \
                 const double g0 = side * (y{ci}[k] - p), s0 = side * y{vi}[k];\n          \
                 const double g1 = side * (z{ci}[k] - p), s1 = side * z{vi}[k];",
                p = self.row("walls", j),
                side = literal(stop.side),
            );
            let crosses = self.may_meet(out);
            let _ = writeln!(
                out,
                "          near |= (((y{ci}[k] == p) & (y{vi}[k] == 0.0)) | {crosses}) & live[k]; }}"
            );
        }
        for j in 0..self.kinds.len() {
            let crosses = self.surface_test(out, j, "oriented_may_meet", true, "        ");
            let _ = writeln!(out, "        near |= {crosses} & live[k];");
        }
    }

    /// The step program's surface test `name` of surface j in slot k
    /// (`oriented_ends_across`, or with the step `hh`, `with_step`,
    /// `oriented_may_meet`): its orientation, and its value and rate at
    /// the step's start and end, as a C int.
    fn surface_test(
        &self,
        out: &mut String,
        j: usize,
        name: &str,
        with_step: bool,
        indent: &str,
    ) -> String {
        let (g, rate) = (2 * j, 2 * j + 1);
        let at = |row: &str| CValue::Pair(format!("{row}{g}[k]"), format!("{row}{rate}[k]"));
        let mut args = vec![CValue::Real(format!("so{j}[k]")), at("sb"), at("sa")];
        if with_step {
            args.push(CValue::Real("hh".into()));
        }
        let prefix = format!("{}{j}_", if with_step { "near" } else { "plain" });
        match inline(out, self.calls, name, args, &prefix, indent) {
            CValue::Bool(test) => test,
            other => unreachable!("{name} gives a truth value, not {other:?}"),
        }
    }

    /// The step program's `may_meet` of the values and rates `g0`, `s0`
    /// to `g1`, `s1` over the step `hh` (C values in scope): whether the
    /// step ends across or turns back within reach, a C int.
    fn may_meet(&self, out: &mut String) -> String {
        let pair = |g: &str, s: &str| CValue::Pair(g.into(), s.into());
        let args = vec![
            pair("g0", "s0"),
            pair("g1", "s1"),
            CValue::Real("hh".into()),
        ];
        match inline(out, self.calls, "may_meet", args, "m", "          ") {
            CValue::Bool(meets) => meets,
            other => unreachable!("may_meet gives a truth value, not {other:?}"),
        }
    }

    /// The step taken: its end is the next step's start, the surfaces'
    /// values with it, and the clock turned on; closes the loop over the
    /// steps.
    fn turn_back(&self, out: &mut String) {
        let w = self.w;
        for i in 0..self.d {
            let _ = writeln!(out, "    for (int k = 0; k < {w}; k++) y{i}[k] = z{i}[k];");
        }
        for m in 0..self.rows() {
            let _ = writeln!(
                out,
                "    for (int k = 0; k < {w}; k++) sb{m}[k] = sa{m}[k];"
            );
        }
        out.push_str("    c = ec;\n    s = es;\n  }\n");
    }

    /// The states, the surfaces' values and the phase written back where
    /// the loop stopped, and the steps taken returned.
    fn end(&self, out: &mut String) {
        let w = self.w;
        for i in 0..self.d {
            let _ = writeln!(
                out,
                "  for (int k = 0; k < {w}; k++) y[{} + k] = y{i}[k];",
                i * w
            );
        }
        for m in 0..self.rows() {
            let _ = writeln!(
                out,
                "  for (int k = 0; k < {w}; k++) values[{} + k] = sb{m}[k];",
                m * w
            );
        }
        out.push_str("  clock[0] = c;\n  clock[1] = s;\n  return n;\n}\n");
    }
}

/// The step program's function `name`, one that reads no field (the
/// clock's rotation, the stop test, the sliding field's algebra), inlined
/// at `args` with its values named after `prefix`: its one result.
fn inline(
    out: &mut String,
    calls: &[Func],
    name: &str,
    args: Vec<CValue>,
    prefix: &str,
    indent: &str,
) -> CValue {
    let mut no_field = |_: &mut String, _: &str, _: &[String], _: (&str, &str)| -> Vec<String> {
        unreachable!("{name} reads no field")
    };
    let mut text = step::C {
        syntax: &C { calls },
        field: &mut no_field,
        indent,
    };
    text.inline(out, &integrator(), name, args, prefix)
        .remove(0)
}

/// `rk4::step_batch`'s step of the slot whose states are `state`, with
/// the field `tape` (its constants from `row`, its values named after
/// `prefix`), inside a loop over the slots that has set `hh`; gives each
/// state's value after the step as a C expression.
fn rk4(
    out: &mut String,
    tape: &Tape,
    calls: &[Func],
    prefix: &str,
    state: &[String],
    row: &dyn Fn(&str, usize) -> String,
) -> Vec<String> {
    rk4_of(
        out,
        calls,
        prefix,
        state,
        &mut |out, prefix, state, clock| rhs(out, tape, calls, prefix, state, clock, row),
    )
}

/// [`rk4`] with the field given as code: the step program's
/// `rk4_update`, at the phases `c, s` (the step's start), `mc, ms` and
/// `ec, es` and the step `hh`.
fn rk4_of(
    out: &mut String,
    calls: &[Func],
    prefix: &str,
    state: &[String],
    field: &mut CField,
) -> Vec<String> {
    let phase = |c: &str, s: &str| CValue::Pair(c.into(), s.into());
    let args = vec![
        phase("c", "s"),
        phase("mc", "ms"),
        phase("ec", "es"),
        CValue::State(state.to_vec()),
        CValue::Real("hh".into()),
    ];
    let mut text = step::C {
        syntax: &C { calls },
        field,
        indent: "      ",
    };
    match text
        .inline(out, &integrator(), "rk4_update", args, prefix)
        .remove(0)
    {
        CValue::State(end) => end,
        other => unreachable!("rk4_update gives a state, not {other:?}"),
    }
}

/// One RK4 step of one trajectory sliding on the switches `bits` at
/// once (one or two), from the region `base` (their bits clear), whose
/// field is F₀, F_m the field with bit m set: `rk4::step_at` of
/// `surface::Sliding`, whose field is `surface::equivalent_on`'s,
/// operation for operation: the rates of the fields along the gradients
/// (∇g_j·F_m, summed as Rust's `sum` does, from `zero`), then the step
/// program's `sliding_field_1` or `sliding_field_2` of them (Filippov's
/// combination on one switch, the elimination on two; NaN where the
/// control is singular or not finite). `lc{m}` points to the constants of
/// F_m, `g{m}` to switch m's constant gradient (the last ones unused with
/// one switch); the clock holds the three stages' phases.
fn slide_step(out: &mut String, calls: &[Func], name: &str, tapes: &[&Tape], zero: f64) {
    let d = tapes[0].states;
    let n = tapes.len() - 1;
    assert!((1..=2).contains(&n));
    let _ = writeln!(
        out,
        "void {name}(const double *restrict y, const double *restrict clock, double hh, \
         const double *restrict lc0, const double *restrict lc1, const double *restrict lc2, \
         const double *restrict g0, const double *restrict g1, double *restrict out) {{\n  \
         const double c = clock[0], s = clock[1], mc = clock[2], ms = clock[3], \
         ec = clock[4], es = clock[5];"
    );
    let state: Vec<String> = (0..d).map(|i| format!("y[{i}]")).collect();
    let dot = |m: usize, f: &[String]| {
        (0..d).fold(literal(zero), |sum, i| {
            format!("({sum} + g{m}[{i}] * {})", f[i])
        })
    };
    let end = rk4_of(
        out,
        calls,
        "rk",
        &state,
        &mut |out, prefix, state, clock| {
            let f: Vec<Vec<String>> = (0..=n)
                .map(|m| {
                    let row = move |_: &str, j: usize| format!("lc{m}[{j}]");
                    rhs(
                        out,
                        tapes[m],
                        calls,
                        &format!("{prefix}f{m}_"),
                        state,
                        clock,
                        &row,
                    )
                })
                .collect();
            // The rates along the switches' constant gradients, named:
            // a_j of F₀, and with two switches d_jk of F_{k+1}.
            let mut rate = |name: String, m: usize, f: &[String]| {
                let _ = writeln!(out, "      const double {name} = {};", dot(m, f));
                CValue::Real(name)
            };
            let state = |m: usize| CValue::State(f[m].clone());
            let args = if n == 1 {
                let a = rate(format!("{prefix}a"), 0, &f[0]);
                let b = rate(format!("{prefix}b"), 0, &f[1]);
                vec![state(0), state(1), a, b]
            } else {
                let mut args = vec![state(0), state(1), state(2)];
                for j in 0..2 {
                    args.push(rate(format!("{prefix}a{j}"), j, &f[0]));
                }
                for j in 0..2 {
                    for k in 0..2 {
                        args.push(rate(format!("{prefix}d{j}{k}"), j, &f[k + 1]));
                    }
                }
                args
            };
            let name = if n == 1 {
                "sliding_field_1"
            } else {
                "sliding_field_2"
            };
            match inline(out, calls, name, args, prefix, "      ") {
                CValue::State(v) => v,
                other => unreachable!("{name} gives a state, not {other:?}"),
            }
        },
    );
    for (i, v) in end.iter().enumerate() {
        let _ = writeln!(out, "  out[{i}] = {v};");
    }
    let _ = writeln!(out, "}}");
}

/// The tape at `state` and clock `(cos, sin)` (`Tape::run`'s register
/// file as C values named `{prefix}{slot}`, lane constant j at
/// `row("lane", j)`); gives its outputs.
fn rhs(
    out: &mut String,
    tape: &Tape,
    calls: &[Func],
    prefix: &str,
    state: &[String],
    clock: (&str, &str),
    row: &dyn Fn(&str, usize) -> String,
) -> Vec<String> {
    let lane = |j: usize| row("lane", j);
    let inputs = Inputs {
        states: state,
        clock,
        lane: &lane,
    };
    print::print(out, &C { calls }, tape, &inputs, prefix, "      ")
}

/// `v` as a C expression of the same bits: Rust's shortest round-trip
/// digits, which C reads back correctly rounded.
fn literal(v: f64) -> String {
    if v.is_nan() {
        "__builtin_nan(\"\")".into()
    } else if v.is_infinite() {
        format!("({}__builtin_inf())", if v < 0.0 { "-" } else { "" })
    } else {
        format!("({v:?})")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_are_written_with_their_bits() {
        for v in [
            0.1,
            -0.0,
            1e-310,
            f64::MAX,
            1.0 / 3.0,
            f64::INFINITY,
            -f64::INFINITY,
        ] {
            let text = literal(v);
            let parsed = if text.contains("inf") {
                if text.contains('-') {
                    f64::NEG_INFINITY
                } else {
                    f64::INFINITY
                }
            } else {
                text.trim_matches(['(', ')']).parse::<f64>().unwrap()
            };
            assert_eq!(parsed.to_bits(), v.to_bits(), "{text}");
        }
    }
}
