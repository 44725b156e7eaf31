//! Lane-steps per second of the CPU and GPU paths on a 4096-value sweep of
//! the seed's oscillator, and their ratio. One lane-step is one RK4 step of
//! one trajectory (the reference or a perturbed copy).
//!
//! `cargo bench --bench lane_steps` (add `-- --quick` for fewer repeats).
//! Prints a Markdown table of medians over the repeats, after a warm-up run
//! (shader compilation, thread pool start).

use std::time::Instant;

use lyapsweep::scene::{self, Precision};
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
    lane_steps: f64,
}

fn measure(name: &str, backend: &str, precision: &str, repeats: usize) -> Option<Row> {
    let scene = scene(backend, precision);
    let run = || lyapsweep::run(&scene);
    if let Err(e) = run() {
        eprintln!("{name}: skipped ({e})");
        return None;
    }
    let (mut walls, mut computes) = (Vec::new(), Vec::new());
    let mut last: Option<Report> = None;
    for _ in 0..repeats {
        let start = Instant::now();
        let report = run().expect("runs");
        walls.push(start.elapsed().as_secs_f64());
        // Compute time: the whole run on the CPU; on the GPU the averaging
        // phase (dispatches, streaming, host QR), without shader compilation.
        computes.push(match &report.gpu {
            Some(g) => g.timings.averaging.as_secs_f64(),
            None => report.elapsed.as_secs_f64(),
        });
        last = Some(report);
    }
    let report = last.expect("at least one repeat");
    let trajectories = match (&report.gpu, report.precision) {
        (Some(_), Precision::F32) => 1 + 2 * 2, // central differences
        _ => 1 + 2,
    };
    let lane_steps = (VALUES * trajectories * STEPS * ITERATIONS) as f64;
    let name = match &report.gpu {
        Some(g) => format!("{name}: {} ({})", g.adapter, g.adapter_backend),
        None => format!("{name}: {} threads", report.threads),
    };
    Some(Row {
        name,
        wall: median(walls),
        compute: median(computes),
        lane_steps,
    })
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let repeats = if quick { 3 } else { 7 };
    if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
        std::env::set_var("XDG_RUNTIME_DIR", std::env::temp_dir());
    }
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
    println!("| path | wall s | compute s | lane-steps | lane-steps/s | vs cpu |");
    println!("|---|---|---|---|---|---|");
    let cpu_rate = rows.first().map(|r| r.lane_steps / r.compute);
    for r in &rows {
        let rate = r.lane_steps / r.compute;
        let ratio = cpu_rate.map_or(String::from("-"), |c| format!("{:.2}×", rate / c));
        println!(
            "| {} | {:.3} | {:.3} | {:.3e} | {:.3e} | {ratio} |",
            r.name, r.wall, r.compute, r.lane_steps, rate
        );
    }
}
