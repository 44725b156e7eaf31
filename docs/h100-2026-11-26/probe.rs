//! Device probe (not committed): f64 sin reduction variants and f32 sin.
use lyapsweep::backend::gpu::context::{self, Want};
use lyapsweep::model::math64;
use lyapsweep::scene::Precision;
use std::sync::mpsc;
use wgpu::util::DeviceExt;

const LIBRARY: &str = include_str!("../shaders/shared/math64.wgsl");
const ORIGINAL: &str = "let r = ((x - k * PIO2_1_64) - k * PIO2_2_64) - k * PIO2_3_64;";

fn kernel(ty: &str, body: &str) -> String {
    format!(
        r#"
@group(0) @binding(0) var<storage, read> input: array<{ty}>;
@group(0) @binding(1) var<storage, read_write> output: array<{ty}>;
@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {{
    let i = gid.x;
    if (i >= arrayLength(&output)) {{ return; }}
    let a = input[i];
    {body}
}}
"#
    )
}

fn run<T: bytemuck::Pod>(gpu: &context::Gpu, source: String, inputs: &[T]) -> Vec<T> {
    let device = &gpu.device;
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: None,
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: None,
        layout: None,
        module: &module,
        entry_point: Some("main"),
        compilation_options: Default::default(),
        cache: None,
    });
    let input = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: None,
        contents: bytemuck::cast_slice(inputs),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let size = std::mem::size_of_val(inputs) as u64;
    let output = device.create_buffer(&wgpu::BufferDescriptor {
        label: None,
        size,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let readable = device.create_buffer(&wgpu::BufferDescriptor {
        label: None,
        size,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: None,
        layout: &pipeline.get_bind_group_layout(0),
        entries: &[
            wgpu::BindGroupEntry {
                binding: 0,
                resource: input.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: output.as_entire_binding(),
            },
        ],
    });
    let mut encoder = device.create_command_encoder(&Default::default());
    {
        let mut pass = encoder.begin_compute_pass(&Default::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.dispatch_workgroups((inputs.len() as u32).div_ceil(64), 1, 1);
    }
    encoder.copy_buffer_to_buffer(&output, 0, &readable, 0, size);
    gpu.queue.submit([encoder.finish()]);
    let (sender, receiver) = mpsc::channel();
    readable.map_async(wgpu::MapMode::Read, .., move |r| {
        let _ = sender.send(r);
    });
    device.poll(wgpu::PollType::wait_indefinitely()).unwrap();
    receiver.recv().unwrap().unwrap();
    let view = readable.get_mapped_range(..).unwrap();
    bytemuck::cast_slice::<u8, T>(&view).to_vec()
}

fn main() {
    for precision in [Precision::F64, Precision::F32] {
        let (adapter, summary) = context::choose(Want::Any, precision, None)
            .unwrap()
            .unwrap();
        println!("adapter {} ({})", summary.name, summary.device_type);
        let gpu = context::open(adapter, summary, precision).unwrap();
        let spread = |from: f64, to: f64, n: usize| -> Vec<f64> {
            (0..n)
                .map(|k| from + (to - from) * (k as f64 + 0.37) / n as f64)
                .collect()
        };
        if precision == Precision::F64 {
            let variants = [
                ("original", ORIGINAL.to_owned()),
                (
                    "fma chain",
                    "let r = fma(-k, PIO2_3_64, fma(-k, PIO2_2_64, fma(-k, PIO2_1_64, x)));"
                        .to_owned(),
                ),
                (
                    "one step",
                    "let r0 = x - k * PIO2_1_64;\n    let r = r0 - k * PIO2_2_64;".to_owned(),
                ),
                (
                    "two parts via fma",
                    "let r = fma(-k, PIO2_2_64, fma(-k, PIO2_1_64, x)) - k * PIO2_3_64;".to_owned(),
                ),
            ];
            for (name, line) in variants {
                let lib = LIBRARY.replace(ORIGINAL, &line);
                assert!(lib != LIBRARY || name == "original");
                for (from, to) in [(-0.78, 0.78), (-7.0, 7.0), (-2e4, 2e4)] {
                    let xs = spread(from, to, 4001);
                    let got = run(
                        &gpu,
                        format!("{lib}\n{}", kernel("f64", "output[i] = sin64(a);")),
                        &xs,
                    );
                    let (mut worst, mut at, mut differ) = (0.0f64, 0.0, 0);
                    for (g, x) in got.iter().zip(&xs) {
                        let want = x.sin();
                        let u = (g - want).abs() / (want.abs() * f64::EPSILON);
                        if u > worst {
                            worst = u;
                            at = *x;
                        }
                        if g.to_bits() != math64::sin(*x).to_bits() {
                            differ += 1;
                        }
                    }
                    println!("f64 sin {name:18} on [{from}, {to}]: worst {worst:.1} ulp at {at}, {differ} of 4001 differ from the CPU twin's bits");
                }
            }
            // products and sums: are they IEEE? (k*P1 exact, x - k*P1 exact)
            let xs = spread(-7.0, 7.0, 4001);
            let got = run(&gpu, format!("{LIBRARY}\n{}", kernel("f64", "let k = round(a * TWO_OVER_PI_64); output[i] = (a - k * PIO2_1_64) - k * PIO2_2_64;")), &xs);
            let differ = got
                .iter()
                .zip(&xs)
                .filter(|(g, x)| {
                    let k = (**x * std::f64::consts::FRAC_2_PI).round_ties_even();
                    g.to_bits()
                        != ((**x - k * 1.57079632673412561417e+00)
                            - k * 6.07710050630396597660e-11f64)
                            .to_bits()
                })
                .count();
            println!("f64 two-step reduction: {differ} of 4001 differ from the CPU's");
        } else {
            for (from, to) in [(-3.2, 3.2), (-100.0, 100.0), (-2e4, 2e4)] {
                let xs: Vec<f32> = spread(from, to, 4001)
                    .into_iter()
                    .map(|x| x as f32)
                    .collect();
                let got = run(&gpu, kernel("f32", "output[i] = sin(a);"), &xs);
                let worst_abs = got
                    .iter()
                    .zip(&xs)
                    .map(|(g, x)| (*g as f64 - (*x as f64).sin()).abs())
                    .fold(0.0, f64::max);
                println!("f32 native sin on [{from}, {to}]: worst absolute error {worst_abs:.3e}");
            }
        }
    }
}
