//! Lane-steps per second of the CPU path on the seed's oscillator.
//!
//! One lane-step is one RK4 step of one trajectory (the reference or a
//! perturbed copy). Run with `cargo bench --bench lane_steps`.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use lyapsweep::scene;

fn seed_scene(lanes: usize, location: &str) -> lyapsweep::Scene {
    let text = format!(
        r#"
[system]
kind = "impact-oscillator"
[sweep]
from = 0.8
to = 1.2
count = {lanes}
[integration]
steps_per_period = 1800
transient = 0
iterations = 10
impact_location = "{location}"
[run]
backend = "cpu"
"#
    );
    scene::parse(&text, "bench", "bench", &[]).expect("bench scene")
}

fn lane_steps(c: &mut Criterion) {
    let mut group = c.benchmark_group("cpu_lane_steps");
    group.sample_size(10);
    for location in ["newton", "linear"] {
        let lanes = 16;
        let scene = seed_scene(lanes, location);
        // Reference + 2 perturbed copies, each `steps_per_period` steps per iteration.
        let steps = lanes * 10 * 3 * 1800;
        group.throughput(Throughput::Elements(steps as u64));
        group.bench_with_input(BenchmarkId::new(location, lanes), &scene, |b, scene| {
            b.iter(|| lyapsweep::run(scene).expect("runs"))
        });
    }
    group.finish();
}

criterion_group!(benches, lane_steps);
criterion_main!(benches);
