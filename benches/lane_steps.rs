//! Lane-steps per second of the CPU and GPU paths on a 4096-value sweep of
//! the seed's oscillator, and their ratio. One lane-step is one RK4 step of
//! one trajectory (the reference or a perturbed copy).
//!
//! `cargo bench --bench lane_steps` (add `-- --quick` for fewer repeats).
//! Prints Markdown tables of medians over the repeats, after a warm-up run
//! (shader compilation, thread pool start):
//!
//! 1. CPU against GPU on a 4096-value sweep;
//! 2. the CPU path against a plain scalar implementation of the paper's
//!    recipe (RK4 with cos(ητ) in every stage, linear interpolation at
//!    impacts, Gram–Schmidt), one thread each, with both errors against the
//!    exact backend;
//! 3. how throughput grows with the sweep (64 to 65 536 values) on one CPU
//!    thread, all threads, and the GPU adapter;
//! 4. how a run's cost grows with iterations and with steps per period;
//! 5. the GPU's workgroup size;
//! 6. impacts: the same sweep with a wall the orbits reach and one they never
//!    reach (kernels without impact code), on every path;
//! 7. models: the seed's oscillator built in against the same system written
//!    as a model, and with its wall written as a general event, on the CPU
//!    path (and the GPU where it runs them); then the models with several
//!    stops or a stop on another state (the impact pair, the two-mass
//!    chain) and the models with a switch (the soft stop, the friction
//!    belt) on the same sweep;
//! 8. the CPU path's native code built by the host's C compiler (the
//!    default) against the tape's interpreter alone
//!    (`LYAPSWEEP_STEP_LOOPS=interpreter`), whole runs alternated, on the
//!    impacts section's sweep and on the seed's at 1800 steps;
//! 9. attractors: 4096 values × 64 starts (`[attractors]`) against 262 144
//!    values × one start, the same lane count, through the command's
//!    streaming entry, on the CPU path and the GPU adapter (f64, f32).
//!
//! GPU rows also give the device time of the compute passes where the
//! adapter has timestamp queries. Name sections to run only those:
//! `-- --quick paper cost` (first, paper, scaling, cost, workgroups, impacts,
//! models, loops, attractors).

use std::time::Instant;

use lyapsweep::scene;
use lyapsweep::Report;

const VALUES: usize = 4096;
const STEPS: usize = 1800;
const ITERATIONS: usize = 3;

fn scene(backend: &str, precision: &str) -> lyapsweep::Scene {
    let text = format!(
        r#"
[system]
kind = "impact-oscillator"
[sweep]
from = 0.5
to = 1.5
count = {VALUES}
[integration]
steps_per_period = {STEPS}
transient = 0
iterations = {ITERATIONS}
[run]
backend = "{backend}"
precision = "{precision}"
validate = 0
"#
    );
    scene::parse(&text, "bench", "bench", &[]).expect("bench scene")
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

struct Row {
    name: String,
    wall: f64,
    compute: f64,
    /// Device time from timestamp queries (GPU rows on adapters that have them).
    device: Option<f64>,
    lane_steps: f64,
}

fn device_seconds(report: &Report) -> Option<f64> {
    report
        .gpu
        .as_ref()
        .and_then(|g| g.timings.gpu_busy)
        .map(|d| d.as_secs_f64())
}

fn measure(name: &str, backend: &str, precision: &str, repeats: usize) -> Option<Row> {
    let scene = scene(backend, precision);
    let run = || lyapsweep::run(&scene);
    if let Err(e) = run() {
        eprintln!("{name}: skipped ({e})");
        return None;
    }
    let (mut walls, mut computes, mut devices) = (Vec::new(), Vec::new(), Vec::new());
    let mut last: Option<Report> = None;
    for _ in 0..repeats {
        let start = Instant::now();
        let report = run().expect("runs");
        walls.push(start.elapsed().as_secs_f64());
        devices.extend(device_seconds(&report));
        // Compute time: the whole run on the CPU; on the GPU the averaging
        // phase (dispatches, streaming, host QR), without shader compilation.
        computes.push(match &report.gpu {
            Some(g) => g.timings.averaging.as_secs_f64(),
            None => report.elapsed.as_secs_f64(),
        });
        last = Some(report);
    }
    let report = last.expect("at least one repeat");
    let trajectories = 1 + scene.difference().copies(2);
    let lane_steps = (VALUES * trajectories * STEPS * ITERATIONS) as f64;
    let name = match &report.gpu {
        Some(g) => format!("{name}: {} ({})", g.adapter, g.adapter_backend),
        None => format!("{name}: {} threads", report.threads),
    };
    Some(Row {
        name,
        wall: median(walls),
        compute: median(computes),
        device: (!devices.is_empty()).then(|| median(devices)),
        lane_steps,
    })
}

/// The paper's recipe, written plainly as a researcher would: RK4 with the
/// forcing cos(ητ) evaluated in every stage, impacts by linear interpolation
/// of the crossing step, forward differences, Gram–Schmidt. One lane.
mod paper {
    const ZETA: f64 = 0.05;
    const F: f64 = 1.0;
    const WALL: f64 = 2.0;
    const E: f64 = 1.0;

    fn rhs(eta: f64, t: f64, y: [f64; 2]) -> [f64; 2] {
        [y[1], -2.0 * ZETA * y[1] - y[0] + F * (eta * t).cos()]
    }

    fn rk4(eta: f64, t: f64, y: [f64; 2], h: f64) -> [f64; 2] {
        let k1 = rhs(eta, t, y);
        let k2 = rhs(
            eta,
            t + h / 2.0,
            [y[0] + h / 2.0 * k1[0], y[1] + h / 2.0 * k1[1]],
        );
        let k3 = rhs(
            eta,
            t + h / 2.0,
            [y[0] + h / 2.0 * k2[0], y[1] + h / 2.0 * k2[1]],
        );
        let k4 = rhs(eta, t + h, [y[0] + h * k3[0], y[1] + h * k3[1]]);
        [
            y[0] + h / 6.0 * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0]),
            y[1] + h / 6.0 * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1]),
        ]
    }

    fn period_map(eta: f64, steps: usize, x: [f64; 2]) -> [f64; 2] {
        let h = std::f64::consts::TAU / eta / steps as f64;
        let mut y = x;
        for k in 0..steps {
            let t = k as f64 * h;
            let y1 = rk4(eta, t, y, h);
            y = if y1[0] > WALL {
                let s = (WALL - y[0]) / (y1[0] - y[0]);
                let impact = [WALL, -E * (y[1] + s * (y1[1] - y[1]))];
                rk4(eta, t + s * h, impact, (1.0 - s) * h)
            } else {
                y1
            };
        }
        y
    }

    /// λ1, λ2 per unit time from (0, 0).
    pub fn exponents(
        eta: f64,
        steps: usize,
        transient: usize,
        iterations: usize,
        delta: f64,
    ) -> [f64; 2] {
        let mut x = [0.0, 0.0];
        for _ in 0..transient {
            x = period_map(eta, steps, x);
        }
        // Gram–Schmidt on the columns of J·Q, Q = [q1 q2].
        let (mut q1, mut q2) = ([1.0, 0.0], [0.0, 1.0]);
        let mut sums = [0.0, 0.0];
        for _ in 0..iterations {
            let next = period_map(eta, steps, x);
            let column = |i: usize| {
                let mut p = x;
                p[i] += delta;
                let moved = period_map(eta, steps, p);
                [(moved[0] - next[0]) / delta, (moved[1] - next[1]) / delta]
            };
            let (c1, c2) = (column(0), column(1));
            let apply = |q: [f64; 2]| [c1[0] * q[0] + c2[0] * q[1], c1[1] * q[0] + c2[1] * q[1]];
            let (v1, v2) = (apply(q1), apply(q2));
            let r11 = (v1[0] * v1[0] + v1[1] * v1[1]).sqrt();
            q1 = [v1[0] / r11, v1[1] / r11];
            let r12 = q1[0] * v2[0] + q1[1] * v2[1];
            let w = [v2[0] - r12 * q1[0], v2[1] - r12 * q1[1]];
            let r22 = (w[0] * w[0] + w[1] * w[1]).sqrt();
            q2 = [w[0] / r22, w[1] / r22];
            sums[0] += r11.ln();
            sums[1] += r22.ln();
            x = next;
        }
        let time = iterations as f64 * std::f64::consts::TAU / eta;
        [sums[0] / time, sums[1] / time]
    }
}

/// The paper's configuration apart from the method's improvements: forward
/// differences at the paper's δ = 1e-8, so both sides integrate three
/// trajectories per value.
fn periodic_scene(
    backend: &str,
    steps: usize,
    transient: usize,
    iterations: usize,
) -> lyapsweep::Scene {
    let text = format!(
        "[system]\nkind = \"impact-oscillator\"\n[sweep]\nvalues = [0.8, 0.95, 1.1, 1.25, 1.5]\n[integration]\nsteps_per_period = {steps}\ntransient = {transient}\niterations = {iterations}\ndifference = \"forward\"\nperturbation = 1e-8\n[run]\nbackend = \"{backend}\"\n"
    );
    scene::parse(&text, "bench", "bench", &[]).expect("bench scene")
}

/// The CPU path against the paper's recipe, one thread each.
fn against_the_paper(repeats: usize) {
    const ETAS: [f64; 5] = [0.8, 0.95, 1.1, 1.25, 1.5];
    let (transient, iterations) = (100, 200);
    let one_thread = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a pool");
    let exact =
        lyapsweep::run(&periodic_scene("exact", 1800, transient, iterations)).expect("exact");
    let error_of = |lanes: &[[f64; 2]]| {
        lanes
            .iter()
            .zip(&exact.lanes)
            .flat_map(|(l, e)| l.iter().zip(&e.exponents).map(|(a, b)| (a - b).abs()))
            .fold(0.0, f64::max)
    };
    println!("\nThe CPU path against the paper's recipe (one thread each; η = {ETAS:?}; transient {transient}, iterations {iterations}; error = largest |λ - λ_exact|)\n");
    println!("| implementation | steps/period | time s | lane-steps/s | error | vs paper: speed per lane-step (median of rounds) | vs paper: error |");
    println!("|---|---|---|---|---|---|---|");
    let lane_steps = |steps: usize| (ETAS.len() * steps * (transient + 3 * iterations)) as f64;
    let paper = || -> Vec<[f64; 2]> {
        ETAS.iter()
            .map(|&eta| paper::exponents(eta, 1800, transient, iterations, 1e-8))
            .collect()
    };
    // Ours at the paper's 1800 steps per period and at twice that.
    let our_steps = [1800, 3600];
    let scenes = our_steps.map(|steps| periodic_scene("cpu", steps, transient, iterations));
    let ours = |scene: &lyapsweep::Scene| -> Vec<[f64; 2]> {
        one_thread.install(|| {
            lyapsweep::run(scene)
                .expect("runs")
                .lanes
                .iter()
                .map(|l| [l.exponents[0], l.exponents[1]])
                .collect()
        })
    };
    let timed = |f: &dyn Fn() -> Vec<[f64; 2]>| {
        let start = Instant::now();
        let lanes = f();
        (start.elapsed().as_secs_f64(), lanes)
    };
    // Round by round, the three runs back to back: the machine's load
    // drifts over seconds (this project's 2-core VM varied by 40%), so each
    // round's ratio is taken between neighbours in time, and the table gives
    // the medians of times and of ratios.
    paper();
    scenes.iter().for_each(|s| drop(ours(s)));
    let mut times = [Vec::new(), Vec::new(), Vec::new()];
    let mut ratios = [Vec::new(), Vec::new()];
    let mut lanes = [Vec::new(), Vec::new(), Vec::new()];
    // Short runs: three times the other sections' repeats.
    for _ in 0..3 * repeats {
        let (t, l) = timed(&paper);
        times[0].push(t);
        lanes[0] = l;
        for (k, (scene, steps)) in scenes.iter().zip(our_steps).enumerate() {
            let (t, l) = timed(&|| ours(scene));
            times[k + 1].push(t);
            lanes[k + 1] = l;
            ratios[k].push((lane_steps(steps) / t) / (lane_steps(1800) / times[0].last().unwrap()));
        }
    }
    let paper_time = median(times[0].clone());
    let paper_rate = lane_steps(1800) / paper_time;
    let paper_error = error_of(&lanes[0]);
    println!(
        "| paper's recipe (cos per stage, linear, Gram–Schmidt) | 1800 | {paper_time:.3} | {paper_rate:.3e} | {paper_error:.1e} | 1.00× | 1× |"
    );
    for (k, steps) in our_steps.into_iter().enumerate() {
        let t = median(times[k + 1].clone());
        let rate = lane_steps(steps) / t;
        let error = error_of(&lanes[k + 1]);
        let mut sorted = ratios[k].clone();
        sorted.sort_by(f64::total_cmp);
        println!(
            "| lyapsweep cpu (lockstep copies, rotation clock, newton location, Householder) | {steps} | {t:.3} | {rate:.3e} | {error:.1e} | {:.2}× (rounds {:.2} to {:.2}) | {:.0}× smaller |",
            median(ratios[k].clone()),
            sorted[0],
            sorted[sorted.len() - 1],
            paper_error / error
        );
    }
}

/// Throughput as the sweep grows.
fn scaling(quick: bool) {
    let counts: &[usize] = if quick {
        &[64, 1024]
    } else {
        &[64, 256, 1024, 4096, 16384, 65536, 262144]
    };
    let one_thread = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a pool");
    println!("\nThroughput against sweep size (lane-steps/s, median of 3; 200 steps/period, 2 iterations, no transient; GPU: from the averaging's wall time (from device time))\n");
    println!("| values | cpu 1 thread | cpu all threads | gpu f64 | gpu f32 | gpu steps per dispatch | gpu bytes per value (f64) |");
    println!("|---|---|---|---|---|---|---|");
    for &n in counts {
        let gpu_shape = std::cell::Cell::new(None);
        let rate = |backend: &str, precision: &str, one: bool| -> String {
            let text = format!(
                "[system]\nkind = \"impact-oscillator\"\n[sweep]\nfrom = 0.5\nto = 1.5\ncount = {n}\n[integration]\nsteps_per_period = 200\ntransient = 0\niterations = 2\n[run]\nbackend = \"{backend}\"\nprecision = \"{precision}\"\nvalidate = 0\n"
            );
            let scene = scene::parse(&text, "bench", "bench", &[]).expect("scene");
            let go = || {
                if one {
                    one_thread.install(|| lyapsweep::run(&scene))
                } else {
                    lyapsweep::run(&scene)
                }
            };
            if go().is_err() {
                return "–".into();
            }
            let (mut rates, mut device_rates) = (Vec::new(), Vec::new());
            for _ in 0..3 {
                let report = go().expect("runs");
                if let Some(g) = report.gpu.as_ref().filter(|_| precision == "f64") {
                    gpu_shape.set(Some((g.chunk_steps, g.bytes_per_lane)));
                }
                let seconds = report
                    .gpu
                    .as_ref()
                    .map_or(report.elapsed.as_secs_f64(), |g| {
                        g.timings.averaging.as_secs_f64()
                    });
                let lane_steps = (n * (1 + scene.difference().copies(2)) * 200 * 2) as f64;
                rates.push(lane_steps / seconds);
                // No transient: the device time is the averaging's passes.
                device_rates.extend(device_seconds(&report).map(|s| lane_steps / s));
            }
            if device_rates.is_empty() {
                format!("{:.2e}", median(rates))
            } else {
                format!("{:.2e} ({:.2e})", median(rates), median(device_rates))
            }
        };
        let cells = [
            rate("cpu", "f64", true),
            rate("cpu", "f64", false),
            rate("gpu", "f64", false),
            rate("gpu", "f32", false),
        ];
        let (chunk, bytes) = gpu_shape.get().map_or(("–".into(), "–".into()), |(c, b)| {
            (c.to_string(), b.to_string())
        });
        println!("| {n} | {} | {chunk} | {bytes} |", cells.join(" | "));
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let quick = args.iter().any(|a| a == "--quick");
    let named: Vec<&str> = args
        .iter()
        .map(String::as_str)
        .filter(|a| !a.starts_with('-'))
        .collect();
    let wanted = |section: &str| named.is_empty() || named.contains(&section);
    let repeats = if quick { 3 } else { 7 };
    if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
        std::env::set_var("XDG_RUNTIME_DIR", std::env::temp_dir());
    }
    if wanted("first") {
        cpu_against_gpu(repeats);
    }
    if wanted("paper") {
        against_the_paper(repeats);
    }
    if wanted("scaling") {
        scaling(quick);
    }
    if wanted("cost") {
        cost_growth(quick);
    }
    if wanted("workgroups") {
        workgroups(quick);
    }
    if wanted("impacts") {
        impacts(repeats);
    }
    if wanted("models") {
        models(repeats);
    }
    if wanted("loops") {
        loops(repeats);
    }
    if wanted("attractors") {
        // At most 3 rounds: a round runs 2 × 262 144 lanes of 12 iterations
        // on each of three paths, about 5 minutes on the 2-core machine.
        attractors(repeats.min(3));
    }
}

/// Section 8: the CPU path with the native code built by the host's C
/// compiler (`model::native::library`, the default) and with the tape's interpreter
/// alone (`LYAPSWEEP_STEP_LOOPS=interpreter`, the portable reference), the
/// seed's model (its code is built when the scene is parsed), whole runs
/// alternated; the speed-up is the median of the rounds' ratios. The
/// spectra are the same to the bit (tests: `model::native::library`).
fn loops(repeats: usize) {
    println!(
        "\nNative code on the CPU path, the seed's model ({} threads; medians of {repeats} alternated rounds after a warm-up)\n",
        rayon::current_num_threads()
    );
    println!("| sweep | interpreter s | C compiler s | speed-up |");
    println!("|---|---|---|---|");
    let model = format!(
        "model = {:?}\n",
        format!(
            "{}/models/impact-oscillator.toml",
            env!("CARGO_MANIFEST_DIR")
        )
    );
    let sweep = |values: usize, steps: usize, transient: usize, iterations: usize| {
        format!(
            "{model}[sweep]\nparameter = \"eta\"\nfrom = 0.5\nto = 1.5\ncount = {values}\n[integration]\nsteps_per_period = {steps}\ntransient = {transient}\niterations = {iterations}\n[run]\nbackend = \"cpu\"\nvalidate = 0\n[output]\nbifurcation_points = 0\n"
        )
    };
    let sweeps = [
        (
            "the impacts section's (4096 values, 200 steps, transient 20, iterations 20)",
            sweep(4096, 200, 20, 20),
        ),
        (
            "the seed's at 1800 steps (512 values, transient 50, iterations 100)",
            sweep(512, 1800, 50, 100),
        ),
    ];
    let options = lyapsweep::RunOptions::default();
    for (name, text) in sweeps {
        let scenes = ["interpreter", "c"].map(|loops| {
            std::env::set_var("LYAPSWEEP_STEP_LOOPS", loops);
            scene::parse(&text, "bench", "bench", &[]).expect("scene")
        });
        std::env::remove_var("LYAPSWEEP_STEP_LOOPS");
        let (mut seconds, mut ratios) = ([Vec::new(), Vec::new()], Vec::new());
        for round in 0..=repeats {
            let [a, b] = [0, 1].map(|i| {
                let report = lyapsweep::run_with(&scenes[i], &options).expect("runs");
                report.elapsed.as_secs_f64()
            });
            // Round 0 warms up.
            if round > 0 {
                seconds[0].push(a);
                seconds[1].push(b);
                ratios.push(a / b);
            }
        }
        let [a, b] = seconds.map(median);
        println!("| {name} | {a:.3} | {b:.3} | {:.2}× |", median(ratios));
    }
    loop_alone(repeats);
}

/// The C compiler's step loop alone (8 slots, one trajectory of each of 8
/// lanes, no stop met), nanoseconds per slot-step.
fn loop_alone(repeats: usize) {
    use lyapsweep::model::ir::tape::Tape;
    use lyapsweep::model::language::expr::{Expr, Names};
    use lyapsweep::model::native::abi::{Layout, StopCode};
    use lyapsweep::model::native::library::Native;
    const W: usize = 8;
    let names = Names {
        states: vec!["x".into(), "v".into()],
        parameters: vec!["zeta".into(), "f".into(), "eta".into()],
        switches: Vec::new(),
    };
    let parse = |t: &str| Expr::parse(t, &names).expect("parses");
    let field = [parse("v"), parse("-2*zeta*v - x + f*cos(eta*t)")];
    let tape = Tape::compile(&field, 2, Some(parse("eta"))).expect("compiles");
    let stop = [StopCode {
        coordinate: 0,
        velocity: 1,
        side: 1.0,
    }];
    let etas: [f64; W] = std::array::from_fn(|k| 0.5 + 0.01 * k as f64);
    let constants = etas.map(|eta| tape.lane_values(&[0.05, 1.0, eta]).constants);
    let lane: Vec<f64> = (0..constants[0].len())
        .flat_map(|j| constants.iter().map(move |c| c[j]))
        .collect();
    let h = etas.map(|eta| std::f64::consts::TAU / eta / 200.0);
    let walls = [2.0; W];
    let half = std::f64::consts::PI / 200.0;
    let native = Native::compile_stepping(&tape, Some(&stop)).expect("native code");
    let (steps, calls) = (200, 20_000);
    let mut ns = Vec::new();
    for round in 0..=repeats {
        let mut y: [[f64; W]; 2] = [std::array::from_fn(|k| 0.1 * k as f64), [0.0; W]];
        let mut clock = [1.0, 0.0, half.cos(), half.sin()];
        let start = Instant::now();
        let mut taken = 0;
        for _ in 0..calls {
            taken += native
                .walk(
                    Layout::Each,
                    &mut y,
                    &mut clock,
                    &lane,
                    &h,
                    &walls,
                    0,
                    steps,
                )
                .expect("a loop for 8 slots");
        }
        if round > 0 {
            ns.push(start.elapsed().as_secs_f64() * 1e9 / (taken * W) as f64);
        }
    }
    println!(
        "| the C compiler's loop alone, 8 lanes' slots, ns per slot-step | - | {:.2} | - |",
        median(ns)
    );
}

/// Section 7: models against the seed's oscillator (the
/// `impact-oscillator` kind, models/impact-oscillator.toml), on the CPU
/// path and on the GPU adapter (f64), on the impacts section's sweep (4096
/// values of η, 200 steps per period, transient 20, iterations 20).
fn models(repeats: usize) {
    for backend in ["cpu", "gpu"] {
        models_on(backend, repeats);
    }
}

fn models_on(backend: &str, repeats: usize) {
    let (values, steps, transient, iterations) = (4096, 200, 20, 20);
    // The reference in the transient, then it and 2D copies (central
    // differences) while averaging.
    let lane_steps =
        |dimension: usize| (values * steps * (transient + (1 + 2 * dimension) * iterations)) as f64;
    println!(
        "\nModels on the {backend} path ({values} values, {steps} steps/period, transient {transient}, iterations {iterations}, f64; {} CPU threads; medians of {repeats} interleaved rounds after a warm-up; the ratio is the median of the rounds' ratios)\n",
        rayon::current_num_threads()
    );
    println!("| system | run s | device s | lane-steps/s | vs the kind |");
    println!("|---|---|---|---|---|");
    let rest = format!(
        "[sweep]\nparameter = \"eta\"\nfrom = 0.5\nto = 1.5\ncount = {values}\n[integration]\nsteps_per_period = {steps}\ntransient = {transient}\niterations = {iterations}\n[run]\nbackend = \"{backend}\"\nprecision = \"f64\"\nvalidate = 0\n"
    );
    let model = format!(
        "{}/models/impact-oscillator.toml",
        env!("CARGO_MANIFEST_DIR")
    );
    // The same wall written `2*(x - wall)`: not a stop's shape, so a general
    // event (the surface tape at every step; on the GPU, the general
    // surfaces' code: the region, the surfaces' values at every step).
    let general = std::fs::read_to_string(&model)
        .expect("the seed model")
        .replace("surface = \"x - wall\"", "surface = \"2*(x - wall)\"");
    let scenes = [
        (
            "kind impact-oscillator (its model)",
            format!("[system]\nkind = \"impact-oscillator\"\n{rest}"),
        ),
        (
            "model, wall as a general event",
            format!("{general}\n{rest}"),
        ),
        // Not the same system: their own lane-steps per second, their time
        // against the kind's for scale.
        (
            "model impact-pair (two stops on x)",
            format!(
                "model = {:?}\n{rest}",
                format!("{}/models/impact-pair.toml", env!("CARGO_MANIFEST_DIR"))
            ),
        ),
        (
            "model two-mass-chain (4 states, a stop on x2)",
            format!(
                "model = {:?}\n{rest}",
                format!("{}/models/two-mass-chain.toml", env!("CARGO_MANIFEST_DIR"))
            ),
        ),
        // Switch models: the switch's surface and rate at every step, as
        // the general event's.
        (
            "model soft-stop (a switch of the stiffness)",
            format!(
                "model = {:?}\n{rest}",
                format!("{}/models/soft-stop.toml", env!("CARGO_MANIFEST_DIR"))
            ),
        ),
        (
            "model friction-belt (a switch with sliding)",
            format!(
                "model = {:?}\n{rest}",
                format!("{}/models/friction-belt.toml", env!("CARGO_MANIFEST_DIR"))
            ),
        ),
    ];
    let scenes: Vec<(&str, lyapsweep::Scene)> = scenes
        .iter()
        .map(|(name, text)| {
            (
                *name,
                scene::parse(text, "bench", "bench", &[]).expect("scene"),
            )
        })
        .collect();
    // The systems' runs interleaved, and each ratio taken within a round:
    // the machine's load drifts (shared cores), and a ratio of medians
    // taken minutes apart would carry the drift.
    let timed = time_interleaved(&scenes.iter().map(|(_, s)| s).collect::<Vec<_>>(), repeats);
    for ((name, scene), timing) in scenes.iter().zip(timed) {
        let Some(t) = timing else {
            println!("| {name} | – | – | – | – |");
            continue;
        };
        println!(
            "| {name} | {:.3} | {} | {:.3e} | {:.2}× |",
            t.seconds,
            t.device.map_or("–".into(), |d| format!("{d:.3}")),
            lane_steps(scene.system.dimension()) / t.seconds,
            t.speed_vs_first
        );
    }
}

/// The medians of interleaved runs of scenes (see [`time_interleaved`]).
struct Interleaved {
    seconds: f64,
    device: Option<f64>,
    /// The median over rounds of the first scene's time over this one's.
    speed_vs_first: f64,
}

/// Runs each scene once to warm up, then `repeats` rounds of one run of
/// each in turn; `None` for a scene that cannot run here (the first must).
fn time_interleaved(scenes: &[&lyapsweep::Scene], repeats: usize) -> Vec<Option<Interleaved>> {
    let options = lyapsweep::RunOptions::default();
    let runs: Vec<bool> = scenes
        .iter()
        .map(|scene| lyapsweep::run_with(scene, &options).is_ok())
        .collect();
    let mut walls = vec![Vec::new(); scenes.len()];
    let mut devices = vec![Vec::new(); scenes.len()];
    let mut ratios = vec![Vec::new(); scenes.len()];
    for _ in 0..repeats {
        let mut first = None;
        for (i, scene) in scenes.iter().enumerate().filter(|&(i, _)| runs[i]) {
            let report = lyapsweep::run_with(scene, &options).expect("runs");
            let seconds = report.elapsed.as_secs_f64();
            let reference = *first.get_or_insert(seconds);
            walls[i].push(seconds);
            devices[i].extend(device_seconds(&report));
            ratios[i].push(reference / seconds);
        }
    }
    (0..scenes.len())
        .map(|i| {
            runs[i].then(|| Interleaved {
                seconds: median(std::mem::take(&mut walls[i])),
                device: (!devices[i].is_empty()).then(|| median(std::mem::take(&mut devices[i]))),
                speed_vs_first: median(std::mem::take(&mut ratios[i])),
            })
        })
        .collect()
}

/// Section 6: the sweep of the speed issue (4096 values of η in [0.5, 1.5],
/// 200 RK4 steps per period, transient 20, iterations 20) with the wall at
/// X_w = 2, which most orbits hit, and at X_w = 100, which none reaches (the
/// GPU then compiles no impact code). Whole-run wall time (shader
/// compilation included), device time, and lane-steps per second of the
/// whole run (references only in the transient).
fn impacts(repeats: usize) {
    let (values, steps, transient, iterations) = (4096, 200, 20, 20);
    let lane_steps = (values * steps * (transient + 5 * iterations)) as f64;
    println!(
        "\nImpacts ({values} values, {steps} steps/period, transient {transient}, iterations {iterations}; {lane_steps:.3e} lane-steps; medians of {repeats} runs after a warm-up)\n"
    );
    println!("| path | wall | run s | device s | lane-steps/s | vs cpu |");
    println!("|---|---|---|---|---|---|");
    for wall in [2.0, 100.0] {
        let mut cpu_seconds = None;
        for (backend, precision) in [("cpu", "f64"), ("gpu", "f64"), ("gpu", "f32")] {
            let text = format!(
                "[system]\nkind = \"impact-oscillator\"\nwall = {wall}\n[sweep]\nfrom = 0.5\nto = 1.5\ncount = {values}\n[integration]\nsteps_per_period = {steps}\ntransient = {transient}\niterations = {iterations}\n[run]\nbackend = \"{backend}\"\nprecision = \"{precision}\"\nvalidate = 0\n"
            );
            let scene = scene::parse(&text, "bench", "bench", &[]).expect("scene");
            let Some((seconds, device)) = time_runs(&scene, &Default::default(), repeats) else {
                println!("| {backend} {precision} | {wall} | – | – | – | – |");
                continue;
            };
            let cpu = *cpu_seconds.get_or_insert(seconds);
            println!(
                "| {backend} {precision} | {wall} | {seconds:.3} | {} | {:.3e} | {:.2}× |",
                device.map_or("–".into(), |d| format!("{d:.3}")),
                lane_steps / seconds,
                cpu / seconds
            );
        }
    }
}

/// Section 1: CPU against GPU on the 4096-value sweep.
fn cpu_against_gpu(repeats: usize) {
    let rows: Vec<Row> = [
        ("cpu f64", "cpu", "f64"),
        ("gpu f64", "gpu", "f64"),
        ("gpu f32", "gpu", "f32"),
    ]
    .iter()
    .filter_map(|(name, backend, precision)| measure(name, backend, precision, repeats))
    .collect();
    println!(
        "{VALUES} values × {ITERATIONS} iterations × {STEPS} RK4 steps per period; medians of {repeats} runs after a warm-up\n"
    );
    println!("| path | wall s | compute s | device s | lane-steps | lane-steps/s | vs cpu |");
    println!("|---|---|---|---|---|---|---|");
    let cpu_rate = rows.first().map(|r| r.lane_steps / r.compute);
    for r in &rows {
        let rate = r.lane_steps / r.compute;
        let ratio = cpu_rate.map_or(String::from("-"), |c| format!("{:.2}×", rate / c));
        println!(
            "| {} | {:.3} | {:.3} | {} | {:.3e} | {:.3e} | {ratio} |",
            r.name,
            r.wall,
            r.compute,
            r.device.map_or("–".into(), |d| format!("{d:.3}")),
            r.lane_steps,
            rate
        );
    }
}

/// A sweep of `values` η in [0.5, 1.5] on the given path, no transient.
fn sweep_scene(
    values: usize,
    steps: usize,
    iterations: usize,
    backend: &str,
    precision: &str,
) -> lyapsweep::Scene {
    let text = format!(
        "[system]\nkind = \"impact-oscillator\"\n[sweep]\nfrom = 0.5\nto = 1.5\ncount = {values}\n[integration]\nsteps_per_period = {steps}\ntransient = 0\niterations = {iterations}\n[run]\nbackend = \"{backend}\"\nprecision = \"{precision}\"\nvalidate = 0\n"
    );
    scene::parse(&text, "bench", "bench", &[]).expect("scene")
}

/// Median wall seconds of a whole run (setup included) and, on a GPU with
/// timestamp queries, median device seconds; `None` when the path is absent.
fn time_runs(
    scene: &lyapsweep::Scene,
    options: &lyapsweep::RunOptions,
    repeats: usize,
) -> Option<(f64, Option<f64>)> {
    lyapsweep::run_with(scene, options).ok()?;
    let (mut walls, mut devices) = (Vec::new(), Vec::new());
    for _ in 0..repeats {
        let report = lyapsweep::run_with(scene, options).expect("runs");
        walls.push(report.elapsed.as_secs_f64());
        devices.extend(device_seconds(&report));
    }
    Some((
        median(walls),
        (!devices.is_empty()).then(|| median(devices)),
    ))
}

/// How a run's cost grows with iterations and steps per period: a fixed
/// part (thread pool, buffers and shader compilation on the GPU) plus a part
/// proportional to lane-steps.
fn cost_growth(quick: bool) {
    let values = 256;
    let repeats = 3;
    let (iterations, steps): (&[usize], &[usize]) = if quick {
        (&[10, 100], &[100, 400])
    } else {
        (&[10, 100, 1000], &[100, 450, 1800])
    };
    println!(
        "\nCost against iterations and steps ({values} values, no transient; whole-run wall s, median of {repeats}; ns per lane-step in brackets)\n"
    );
    println!("| iterations | steps | cpu f64 | gpu f64 | gpu f32 |");
    println!("|---|---|---|---|---|");
    let mut rows: Vec<(usize, usize)> = iterations.iter().map(|&i| (i, 200)).collect();
    rows.extend(steps.iter().map(|&s| (100, s)));
    for (iterations, steps) in rows {
        let lane_steps = (values * 5 * steps * iterations) as f64;
        let cell = |backend: &str, precision: &str| {
            let scene = sweep_scene(values, steps, iterations, backend, precision);
            match time_runs(&scene, &Default::default(), repeats) {
                Some((wall, _)) => format!("{wall:.3} ({:.1})", wall / lane_steps * 1e9),
                None => "–".into(),
            }
        };
        println!(
            "| {iterations} | {steps} | {} | {} | {} |",
            cell("cpu", "f64"),
            cell("gpu", "f64"),
            cell("gpu", "f32")
        );
    }
}

/// The GPU's invocations per workgroup: lane-steps per second of the whole
/// run and, with timestamp queries, of the device time alone.
fn workgroups(quick: bool) {
    let (values, steps, iterations) = (4096, 200, 3);
    let repeats = if quick { 1 } else { 3 };
    println!(
        "\nGPU workgroup size ({values} values, {steps} steps/period, {iterations} iterations; lane-steps/s from wall time, and from device time; median of {repeats})\n"
    );
    println!("| workgroup | gpu f64 wall | gpu f64 device | gpu f32 wall | gpu f32 device |");
    println!("|---|---|---|---|---|");
    let lane_steps = (values * 5 * steps * iterations) as f64;
    for size in [1, 8, 32, 64, 256] {
        let options = lyapsweep::RunOptions {
            workgroup_size: Some(size),
            ..Default::default()
        };
        let cells = |precision: &str| {
            let scene = sweep_scene(values, steps, iterations, "gpu", precision);
            match time_runs(&scene, &options, repeats) {
                Some((wall, device)) => format!(
                    "{:.2e} | {}",
                    lane_steps / wall,
                    device.map_or("–".into(), |d| format!("{:.2e}", lane_steps / d))
                ),
                None => "– | –".into(),
            }
        };
        println!("| {size} | {} | {} |", cells("f64"), cells("f32"));
    }
}

/// One whole run through the command's entry: wall seconds, device
/// seconds summed over the batches (adapters with timestamp queries), the
/// lanes the sink saw, and their mean impacts per period (which differ
/// between many starts and one: the starts reach the wall from anywhere in
/// the box).
fn timed_run(
    scene: &lyapsweep::Scene,
    options: &lyapsweep::RunOptions,
) -> lyapsweep::Result<(f64, Option<f64>, usize, f64)> {
    let (mut lanes, mut device, mut impacts) = (0, None, (0.0, 0));
    let start = Instant::now();
    let batch = lyapsweep::plan::batch_lanes(scene);
    lyapsweep::run_streaming(scene, options, batch, |_, report| {
        lanes += report.lanes.len();
        if let Some(d) = device_seconds(report) {
            *device.get_or_insert(0.0) += d;
        }
        for lane in report
            .lanes
            .iter()
            .filter(|l| l.impacts_per_period.is_finite())
        {
            impacts.0 += lane.impacts_per_period;
            impacts.1 += 1;
        }
        Ok(())
    })
    .map(|(_, _attractors)| {
        let impacts = impacts.0 / impacts.1.max(1) as f64;
        (start.elapsed().as_secs_f64(), device, lanes, impacts)
    })
}

/// Section 9: many starts per value (`[attractors]`) against one start per
/// value, at the same lane count: 4096 values of η × a grid of 8 × 8 starts
/// over x ∈ [-3, 1.9], v ∈ [-3, 3] (A), and 262 144 values of η over the
/// same [0.5, 1.5] from the one default start (B). Both run through
/// `lyapsweep::run_streaming`, the command's entry, in its batches, with a
/// sink that only counts lanes (and their impacts): whatever that entry does per value beyond
/// the lanes themselves lands in A's time and not in B's, and the ratio
/// shows it.
fn attractors(repeats: usize) {
    let (values, grid) = (4096, [8, 8]);
    let starts = grid[0] * grid[1];
    // 200 steps per period, the other sections' short sweeps': above the
    // plan's period / 0.1 (126 at η = 0.5), so no lane's steps are raised
    // and the lane-steps are the scene's. A transient of 4 and 8 averaging
    // iterations, with max_period = 4, so that every lane's period is
    // tested (that needs 2 · max_period points) and every value's lanes are
    // grouped as in a real run: 2.6e5 lanes at the defaults (450 steps,
    // transient 500, iterations 1000) would take hours on 2 cores. Few
    // lanes settle on their orbit in so few iterations; most are grouped
    // as aperiodic, by the region their points cover.
    let (steps, transient, iterations, max_period) = (200, 4, 8, 4);
    let text = |backend: &str, precision: &str, sweep: &str| {
        format!(
            "[system]\nkind = \"impact-oscillator\"\n{sweep}[integration]\nsteps_per_period = {steps}\ntransient = {transient}\niterations = {iterations}\n[run]\nbackend = \"{backend}\"\nprecision = \"{precision}\"\nvalidate = 0\n"
        )
    };
    // A at `count` values, or B at `count` × 64 values.
    let many = |count: usize| {
        format!(
            "[sweep]\nparameter = \"eta\"\nfrom = 0.5\nto = 1.5\ncount = {count}\n[attractors]\ngrid = [{}, {}]\nbox = {{ x = [-3, 1.9], v = [-3, 3] }}\nmax_period = {max_period}\n",
            grid[0], grid[1]
        )
    };
    let single = |count: usize| {
        format!(
            "[sweep]\nparameter = \"eta\"\nfrom = 0.5\nto = 1.5\ncount = {}\n",
            count * starts
        )
    };
    println!(
        "\nMany starts per value ({values} values × {starts} starts (A) against {} values × 1 start (B); {steps} steps/period, transient {transient}, iterations {iterations}, max_period {max_period}, validation off; whole runs of `run_streaming` in its batches; medians of {repeats} rounds of A and B in turn after a warm-up on 64 values, the ratio the median of the rounds' ratios; {} CPU threads)\n",
        values * starts,
        rayon::current_num_threads()
    );
    println!(
        "| path | sweep | lanes | impacts/period | run s | device s | lanes/s | lane-steps/s | A / B |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    let options = lyapsweep::RunOptions::default();
    for (backend, precision) in [("cpu", "f64"), ("gpu", "f64"), ("gpu", "f32")] {
        let scenes_of = |count: usize| {
            [many(count), single(count)].map(|sweep| {
                scene::parse(&text(backend, precision, &sweep), "bench", "bench", &[])
                    .expect("scene")
            })
        };
        let scenes = scenes_of(values);
        let timed = |scene: &lyapsweep::Scene| timed_run(scene, &options);
        let path = format!("{backend} {precision}");
        // The warm-up (kernels compiled, threads started) on 64 values:
        // whole runs take minutes.
        let warm = scenes_of(64);
        if let Err(e) = timed(&warm[0]).and_then(|_| timed(&warm[1])) {
            println!("| {path} | – | – | – | – | – | – | – | – |");
            eprintln!("attractors, {path}: skipped ({e})");
            continue;
        }
        let mut seconds = [Vec::new(), Vec::new()];
        let mut devices = [Vec::new(), Vec::new()];
        let mut ratios = Vec::new();
        let mut impacts = [0.0; 2];
        for round in 0..repeats {
            // A then B, B then A: a drift of the shared machine's load
            // within a round falls on each side in turn.
            let order = if round % 2 == 0 { [0, 1] } else { [1, 0] };
            let mut round_seconds = [0.0; 2];
            for i in order {
                let (s, device, lanes, mean_impacts) = timed(&scenes[i]).expect("runs");
                assert_eq!(lanes, values * starts, "the sink saw every lane");
                impacts[i] = mean_impacts;
                round_seconds[i] = s;
                seconds[i].push(s);
                devices[i].extend(device);
            }
            // Equal lane counts: the ratio of lanes per second is B's time
            // over A's.
            ratios.push(round_seconds[1] / round_seconds[0]);
        }
        let ratio = median(ratios);
        for (i, name) in ["A: many starts", "B: one start"].into_iter().enumerate() {
            let scene = &scenes[i];
            let s = median(std::mem::take(&mut seconds[i]));
            let device = (!devices[i].is_empty()).then(|| median(std::mem::take(&mut devices[i])));
            println!(
                "| {path} | {name} | {} | {:.2} | {s:.3} | {} | {:.3e} | {:.3e} | {} |",
                scene.lane_count(),
                impacts[i],
                device.map_or("–".into(), |d| format!("{d:.3}")),
                scene.lane_count() as f64 / s,
                lyapsweep::plan::lane_steps(scene) / s,
                if i == 0 {
                    format!("{ratio:.2}×")
                } else {
                    "1.00×".into()
                }
            );
        }
    }
}
