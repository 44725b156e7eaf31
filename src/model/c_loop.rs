//! A field's step loop ([`Walk`]) written in C and built by the host's C
//! compiler for the host's own vector width.
//!
//! Cranelift emits 128-bit vectors only: its loop over eight slots ran 9.2
//! ns per slot-step on the seed's oscillator (an AVX-512 Xeon), the same
//! operations as C loops over the slots that GCC vectorises for the host
//! (`-march=native`) 3.8 to 4.5 ns (docs/BENCHMARKS.md, "The step loop
//! built by the host's C compiler"). The C here is the cranelift loop's
//! twin, operation for operation: every tape instruction one IEEE operation
//! in the tape's order, no contraction into fused multiply-adds
//! (`-ffp-contract=off`) and no reassociation (no `-ffast-math`), so the
//! bits are those of [`Native::walk`](super::jit::Native::walk), which the
//! tests check.
//!
//! Where there is no C compiler (`cc`, or `$CC`), or it fails, the loop is
//! cranelift's. The shared objects are cached by the hash of their source,
//! compiler and flags in the user's cache directory, so a model is built
//! once per machine, not once per run.

use super::expr::Func;
use super::jit::{callback, Layout, StopCode, Walk, WALK_WIDTHS};
use super::tape::{Code, Tape};
use crate::integrate::impact::TURN_REACH;
use std::fmt::Write as _;
use std::path::PathBuf;

/// The flags: the host's vectors, the IEEE operations as written (no
/// fused multiply-adds, no reassociation), `sqrt` as the instruction.
const FLAGS: [&str; 6] = [
    "-O3",
    "-march=native",
    "-ffp-contract=off",
    "-fno-math-errno",
    "-fPIC",
    "-shared",
];

/// Step loops built by the C compiler, by width (4 and 8) and
/// layout; the library that holds their code.
pub struct CLoops {
    pub walks: [[Walk; 2]; WALK_WIDTHS.len()],
    _library: libloading::Library,
}

impl std::fmt::Debug for CLoops {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("CLoops")
    }
}

impl CLoops {
    /// The step loops of `tape` detecting `stops`, or why not (no C
    /// compiler, or it failed).
    pub fn build(tape: &Tape, stops: &[StopCode]) -> Result<CLoops, String> {
        // The functions called back into Rust, by their index in `calls`:
        // the source holds no address, so one object serves every process.
        let mut calls: Vec<Func> = Vec::new();
        for ins in tape.lowered().0 {
            if let Code::Call(f) = ins.code {
                if !matches!(f, Func::Sqrt | Func::Abs) && !calls.contains(&f) {
                    calls.push(f);
                }
            }
        }
        let mut source = format!(
            "#include <stdint.h>\ntypedef double (*apply)(double, double);\n\
             static apply calls[{n}];\n\
             void set_calls(const apply *t) {{ for (int i = 0; i < {n}; i++) calls[i] = t[i]; }}\n",
            n = calls.len().max(1)
        );
        for &w in &WALK_WIDTHS {
            for layout in [Layout::Shared, Layout::Each] {
                walk(&mut source, tape, &calls, stops, w, layout);
            }
        }
        let library = compiled(&source)?;
        let table: Vec<extern "C" fn(f64, f64) -> f64> =
            calls.iter().map(|&f| callback(f)).collect();
        // SAFETY: `set_calls` is defined above, reads `calls.len()`
        // function pointers (C calling convention, two f64 to one) from
        // the table; objects loaded twice share `calls`, and the same
        // source sets the same table.
        unsafe {
            let set = library
                .get::<unsafe extern "C" fn(*const extern "C" fn(f64, f64) -> f64)>(b"set_calls")
                .map_err(|e| e.to_string())?;
            set(table.as_ptr());
        }
        let walks = WALK_WIDTHS.map(|w| {
            [Layout::Shared, Layout::Each].map(|layout| {
                let name = format!("walk{w}{layout:?}");
                // SAFETY: the source defines `name` with the `Walk`
                // signature (C calling convention), and the library stays
                // loaded while `CLoops` lives.
                unsafe { *library.get::<Walk>(name.as_bytes()).expect("defined above") }
            })
        });
        Ok(CLoops {
            walks,
            _library: library,
        })
    }
}

/// The cached shared object built from `source`, loaded.
fn compiled(source: &str) -> Result<libloading::Library, String> {
    use sha2::{Digest, Sha256};
    let cc = std::env::var("CC").unwrap_or_else(|_| "cc".into());
    let mut hash = Sha256::new();
    for part in [cc.as_str(), &FLAGS.join(" "), source] {
        hash.update(part.as_bytes());
        hash.update([0]);
    }
    let key: String = hash.finalize()[..12]
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect();
    let dir = cache_dir()?;
    let object = dir.join(format!("{key}.so"));
    if !object.exists() {
        // Built under a name of this thread's, then renamed: runs and
        // threads at the same time never load a half-written object.
        static BUILDS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
        let build = BUILDS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let unique = |ext: &str| -> PathBuf {
            dir.join(format!("{key}.{}-{build}.{ext}", std::process::id()))
        };
        let (c, so) = (unique("c"), unique("so"));
        std::fs::write(&c, source).map_err(|e| format!("{}: {e}", c.display()))?;
        let output = std::process::Command::new(&cc)
            .args(FLAGS)
            .arg("-o")
            .arg(&so)
            .arg(&c)
            .output()
            .map_err(|e| format!("{cc}: {e}"))?;
        let _ = std::fs::remove_file(&c);
        if !output.status.success() {
            let _ = std::fs::remove_file(&so);
            return Err(format!(
                "{cc} failed: {}",
                String::from_utf8_lossy(&output.stderr)
            ));
        }
        std::fs::rename(&so, &object).map_err(|e| format!("{}: {e}", object.display()))?;
    }
    // SAFETY: the object is ours (built above or earlier from the same
    // source, named by its hash) and has no initialisers.
    unsafe { libloading::Library::new(&object) }.map_err(|e| format!("{}: {e}", object.display()))
}

/// Where the shared objects are kept: the user's cache directory
/// (`$XDG_CACHE_HOME`, else `~/.cache`), else one of the user's in the
/// temporary directory. The objects are loaded and run, so only a
/// directory the user owns and no one else can write is used.
#[cfg(unix)]
fn cache_dir() -> Result<PathBuf, String> {
    use std::os::unix::fs::{DirBuilderExt, MetadataExt};
    let var = |name| {
        std::env::var_os(name)
            .filter(|v| !v.is_empty())
            .map(PathBuf::from)
    };
    // SAFETY: getuid has no preconditions and cannot fail.
    let uid = unsafe { libc::getuid() };
    let dir = match var("XDG_CACHE_HOME").or_else(|| var("HOME").map(|h| h.join(".cache"))) {
        Some(cache) => cache.join("lyapsweep").join("c-loops"),
        None => std::env::temp_dir().join(format!("lyapsweep-c-loops-{uid}")),
    };
    let shown = || dir.display().to_string();
    std::fs::DirBuilder::new()
        .recursive(true)
        .mode(0o700)
        .create(&dir)
        .map_err(|e| format!("{}: {e}", shown()))?;
    let meta = std::fs::metadata(&dir).map_err(|e| format!("{}: {e}", shown()))?;
    if meta.uid() != uid || meta.mode() & 0o022 != 0 {
        return Err(format!(
            "{}: not the user's own, or writable by others",
            shown()
        ));
    }
    Ok(dir)
}

/// Off Unix, no directory is known to be the user's alone: the loops are
/// cranelift's.
#[cfg(not(unix))]
fn cache_dir() -> Result<PathBuf, String> {
    Err("the C compiler's loops are built on Unix only".into())
}

/// Appends `walk{w}{layout:?}`: `jit::walk`'s loop (the phase turned, the
/// RK4 step, the stops detected) over `w` slots, a loop over the slots per
/// step for the compiler to vectorise.
fn walk(
    out: &mut String,
    tape: &Tape,
    calls: &[Func],
    stops: &[StopCode],
    w: usize,
    layout: Layout,
) {
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
        "uint64_t walk{w}{layout:?}(double *restrict y, double *restrict clock, \
         const double *restrict lane, const double *restrict h, \
         const double *restrict walls, const int64_t *restrict live, uint64_t steps) {{"
    );
    for i in 0..d {
        let _ = writeln!(out, "  double y{i}[{w}];");
        let _ = writeln!(
            out,
            "  for (int k = 0; k < {w}; k++) y{i}[k] = y[{} + k];",
            i * w
        );
    }
    out.push_str(
        "  double c = clock[0], s = clock[1];\n  const double hc = clock[2], hs = clock[3];\n  uint64_t n = 0;\n  for (; n < steps; n++) {\n",
    );
    // `clock::rotate`, as `jit::walk` turns it.
    for (from, to) in [(("c", "s"), ("mc", "ms")), (("mc", "ms"), ("ec", "es"))] {
        let ((c, s), (c1, s1)) = (from, to);
        let _ = writeln!(
            out,
            "    double {c1}_ = {c} * hc - {s} * hs, {s1}_ = {s} * hc + {c} * hs;\n    \
             double {c1}n = 1.5 - 0.5 * ({c1}_ * {c1}_ + {s1}_ * {s1}_);\n    \
             double {c1} = {c1}_ * {c1}n, {s1} = {s1}_ * {c1}n;"
        );
    }
    for i in 0..d {
        let _ = writeln!(out, "    double z{i}[{w}];");
    }
    let _ = writeln!(
        out,
        "    int64_t hit = 0;\n    for (int k = 0; k < {w}; k++) {{"
    );
    let _ = writeln!(
        out,
        "      const double hh = {}, h2 = 0.5 * hh, sixth = hh / 6.0;",
        row("h", 0)
    );
    let state: Vec<String> = (0..d).map(|i| format!("y{i}[k]")).collect();
    let k1 = rhs(out, tape, calls, "a", &state, ("c", "s"), &row);
    let y2 = axpy(out, "b", &state, "h2", &k1);
    let k2 = rhs(out, tape, calls, "c", &y2, ("mc", "ms"), &row);
    let y3 = axpy(out, "d", &state, "h2", &k2);
    let k3 = rhs(out, tape, calls, "e", &y3, ("mc", "ms"), &row);
    let y4 = axpy(out, "f", &state, "hh", &k3);
    let k4 = rhs(out, tape, calls, "g", &y4, ("ec", "es"), &row);
    for i in 0..d {
        // y + h/6·(k1 + 2(k2 + k3) + k4)
        let _ = writeln!(
            out,
            "      z{i}[k] = {y} + sixth * ((({k1} + 2.0 * ({k2} + {k3}))) + {k4});",
            y = state[i],
            k1 = k1[i],
            k2 = k2[i],
            k3 = k3[i],
            k4 = k4[i],
        );
    }
    // As `jit::walk` (and `integrate::steps`), in two passes: the plain
    // test in the loop over the slots (at rest on the stop, beyond it
    // after the step, or turning back inside it), and where that fires
    // (a few steps in a hundred), the turns again, only those within reach
    // of the stop (`impact::may_turn_past`). Its arithmetic in every
    // step cost the seed's oscillator a fifth of the loop.
    for (j, stop) in stops.iter().enumerate() {
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
            p = row("walls", j)
        );
    }
    // The second pass: the gaps and speeds side·(x - p) and side·v are
    // exact for a side of ±1.
    let _ = writeln!(
        out,
        "    }}\n    if (hit) {{\n      int64_t near = 0;\n      \
         for (int k = 0; k < {w}; k++) {{\n        const double hh = {};",
        row("h", 0)
    );
    for (j, stop) in stops.iter().enumerate() {
        let (ci, vi) = (stop.coordinate, stop.velocity);
        let _ = writeln!(
            out,
            "        {{ const double p = {p}, side = {side};\n          \
             const double g0 = side * (y{ci}[k] - p), s0 = side * y{vi}[k];\n          \
             const double g1 = side * (z{ci}[k] - p), s1 = side * z{vi}[k];\n          \
             const double reach = {reach} * hh * (s0 - s1);\n          \
             near |= (((y{ci}[k] == p) & (y{vi}[k] == 0.0)) | (g1 > 0.0) \
             | ((s0 > 0.0) & (s1 < 0.0) & !((g0 + reach < 0.0) & (g1 + reach < 0.0)))) & live[k]; }}",
            p = row("walls", j),
            side = literal(stop.side),
            reach = literal(TURN_REACH),
        );
    }
    out.push_str("      }\n      if (near) break;\n    }\n");
    for i in 0..d {
        let _ = writeln!(out, "    for (int k = 0; k < {w}; k++) y{i}[k] = z{i}[k];");
    }
    out.push_str("    c = ec;\n    s = es;\n  }\n");
    for i in 0..d {
        let _ = writeln!(
            out,
            "  for (int k = 0; k < {w}; k++) y[{} + k] = y{i}[k];",
            i * w
        );
    }
    out.push_str("  clock[0] = c;\n  clock[1] = s;\n  return n;\n}\n");
}

/// y + a·k, named `{prefix}{i}`.
fn axpy(out: &mut String, prefix: &str, y: &[String], a: &str, k: &[String]) -> Vec<String> {
    (0..y.len())
        .map(|i| {
            let name = format!("{prefix}{i}");
            let _ = writeln!(
                out,
                "      const double {name} = {} + {a} * {};",
                y[i], k[i]
            );
            name
        })
        .collect()
}

/// The tape at `state` and clock `(cos, sin)` (`Tape::run`'s register
/// file as C values named `{prefix}{slot}`); gives its outputs.
fn rhs(
    out: &mut String,
    tape: &Tape,
    calls: &[Func],
    prefix: &str,
    state: &[String],
    (cos, sin): (&str, &str),
    row: &dyn Fn(&str, usize) -> String,
) -> Vec<String> {
    let (lowered, numbers, outputs) = tape.lowered();
    let mut slots: Vec<String> = state.to_vec();
    slots.extend([cos.to_string(), sin.to_string()]);
    slots.extend((0..tape.lane_constants.len()).map(|j| row("lane", j)));
    slots.extend(numbers.iter().map(|&v| literal(v)));
    for ins in lowered {
        let (a, b, c) = (
            &slots[ins.a as usize],
            &slots[ins.b as usize],
            &slots[ins.c as usize],
        );
        let value = match ins.code {
            Code::Neg => format!("-{a}"),
            Code::Add => format!("{a} + {b}"),
            Code::Sub => format!("{a} - {b}"),
            Code::Mul => format!("{a} * {b}"),
            Code::Div => format!("{a} / {b}"),
            Code::MulAdd => format!("{a} * {b} + {c}"),
            Code::MulSub => format!("{a} * {b} - {c}"),
            Code::SubMul => format!("{c} - {a} * {b}"),
            Code::Call(Func::Sqrt) => format!("__builtin_sqrt({a})"),
            Code::Call(Func::Abs) => format!("__builtin_fabs({a})"),
            // The same Rust functions as the cranelift code calls.
            Code::Call(f) => {
                let i = calls.iter().position(|&g| g == f).expect("listed");
                format!("calls[{i}]({a}, {b})")
            }
        };
        let name = format!("{prefix}{}", slots.len());
        let _ = writeln!(out, "      const double {name} = {value};");
        slots.push(name);
    }
    outputs.iter().map(|&s| slots[s as usize].clone()).collect()
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
    use crate::model::expr::{Expr, Names};
    use crate::model::jit::{Loops, Native};

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

    /// Both compilers' loops for W slots in `layout` from the same states,
    /// with a stop at `wall` on `side`: the steps taken, the states and the
    /// phase, to the bit, runs that stop at the wall and runs that do not.
    fn same_walks<const W: usize>(
        c: &Native,
        cranelift: &Native,
        layout: Layout,
        stop: (f64, f64),
    ) {
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
            std::array::from_fn(|k| 0.05 * k as f64 - 0.1),
            std::array::from_fn(|k| 0.02 * k as f64),
        ];
        let bits = |y: &[[f64; W]; 2], clock: &[f64; 4]| {
            let mut b: Vec<u64> = y.as_flattened().iter().map(|v| v.to_bits()).collect();
            b.extend(clock.iter().map(|v| v.to_bits()));
            b
        };
        let mut stopped = 0;
        for (live, steps) in [(0u32, 3000), ((1 << W) - 1, 3000), (0b10, 3000)] {
            let run = |native: &Native| {
                let (mut y, mut clock) = (start, [0.3f64.cos(), 0.3f64.sin(), half[0], half[1]]);
                let mut taken = Vec::new();
                // Walk on from each stop, one step at a time past it.
                let mut left = steps;
                while left > 0 {
                    let n = native
                        .walk(layout, &mut y, &mut clock, &lane, &h, &walls, live, left)
                        .expect("a loop for W");
                    taken.push(n);
                    left -= n;
                    if left > 0 {
                        let n = native
                            .walk(layout, &mut y, &mut clock, &lane, &h, &walls, 0, 1)
                            .expect("a loop for W");
                        left -= n;
                    }
                }
                (taken, bits(&y, &clock))
            };
            let (c_taken, c_bits) = run(c);
            let (cranelift_taken, cranelift_bits) = run(cranelift);
            assert_eq!(
                c_taken, cranelift_taken,
                "W = {W}, {layout:?}, side {side}, live {live:b}"
            );
            assert_eq!(
                c_bits, cranelift_bits,
                "W = {W}, {layout:?}, side {side}, live {live:b}"
            );
            stopped += c_taken.len() - 1;
        }
        assert!(stopped > 10, "the stop was met {stopped} times");
    }

    #[test]
    #[cfg(unix)]
    fn the_c_compiler_s_step_loops_are_cranelift_s_to_the_bit() {
        let tape = tape();
        // Stops met early and often, and one (at 4) far above the first
        // turns of the oscillation, which grows past it later.
        for (wall, side) in [(0.9, 1.0), (-0.7, -1.0), (4.0, 1.0)] {
            let stops = [StopCode {
                coordinate: 0,
                velocity: 1,
                side,
            }];
            let c = Native::compile_stepping_by(&tape, Some(&stops), Loops::CCompiler).unwrap();
            // Not a skip where there is no C compiler: the test then fails
            // and says why.
            assert_eq!(
                c.loops(),
                Some(Loops::CCompiler),
                "{:?}",
                c.c_compiler_failure()
            );
            let cranelift =
                Native::compile_stepping_by(&tape, Some(&stops), Loops::Cranelift).unwrap();
            assert_eq!(cranelift.loops(), Some(Loops::Cranelift));
            for layout in [Layout::Shared, Layout::Each] {
                same_walks::<4>(&c, &cranelift, layout, (wall, side));
                same_walks::<8>(&c, &cranelift, layout, (wall, side));
                same_walks::<16>(&c, &cranelift, layout, (wall, side));
            }
        }
    }

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
