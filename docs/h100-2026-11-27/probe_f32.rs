//! Device probe (not kept in the build): is the adapter's f32 arithmetic
//! IEEE's? Division by a buffer value and by the literal 6, sqrt, and
//! Kahan's compensated sum, each against Rust's f32 bits.
use lyapsweep::backend::gpu::context::{self, Want};
use lyapsweep::scene::Precision;
use std::sync::mpsc;
use wgpu::util::DeviceExt;

fn kernel(body: &str) -> String {
    format!(
        r#"
@group(0) @binding(0) var<storage, read> input: array<f32>;
@group(0) @binding(1) var<storage, read_write> output: array<f32>;
@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {{
    let i = gid.x;
    if (i >= arrayLength(&output) / 2u) {{ return; }}
    let a = input[2u * i];
    let b = input[2u * i + 1u];
    var out = vec2<f32>(0.0, 0.0);
    {body}
    output[2u * i] = out.x;
    output[2u * i + 1u] = out.y;
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


fn kahan(a: f32, b: f32) -> (f32, f32) {
    let (mut y, mut comp) = (a, 0.0f32);
    for k in 0..64 {
        let _ = k;
        let inc = if k % 2 == 0 { b } else { a };
        let corrected = inc - comp;
        let y1 = y + corrected;
        comp = (y1 - y) - corrected;
        y = y1;
    }
    (y, comp)
}

fn main() {
    let (adapter, summary) = context::choose(Want::Any, Precision::F32, None)
        .unwrap()
        .unwrap();
    println!("adapter {} ({})", summary.name, summary.device_type);
    let gpu = context::open(adapter, summary, Precision::F32).unwrap();
    // Pseudo-random pairs: a in [-4, 4], b in [1e-3, 10] with either sign.
    let mut state = 0x2545F4914F6CDD1Du64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let n = 1 << 16;
    let mut input = Vec::with_capacity(2 * n);
    for _ in 0..n {
        let a = (8.0 * next() - 4.0) as f32;
        let b = (10f64.powf(4.0 * next() - 3.0) * if next() < 0.5 { -1.0 } else { 1.0 }) as f32;
        input.push(a);
        input.push(b);
    }
    let pairs: Vec<(f32, f32)> = input.chunks(2).map(|c| (c[0], c[1])).collect();
    let ulps = |g: f32, w: f32| (g as f64 - w as f64).abs() / (w.abs() as f64 * f32::EPSILON as f64);
    type Want2 = fn(f32, f32) -> (f32, f32);
    let cases: [(&str, &str, Want2); 7] = [
        ("a / b, b from a buffer", "out = vec2<f32>(a / b, b / a);", |a, b| (a / b, b / a)),
        ("a / 6 (a literal)", "out = vec2<f32>(a / 6.0, b / 6.0);", |a, b| (a / 6.0, b / 6.0)),
        (
            "a / b refined by an fma",
            "let q0 = a / b;\n    let r = fma(-q0, b, a);\n    let q1 = b / a;\n    let r1 = fma(-q1, a, b);\n    out = vec2<f32>(fma(r, 1.0 / b, q0), fma(r1, 1.0 / a, q1));",
            |a, b| (a / b, b / a),
        ),
        ("sqrt", "out = vec2<f32>(sqrt(abs(a)), sqrt(abs(b)));", |a, b| (a.abs().sqrt(), b.abs().sqrt())),
        ("a * b + a (contracted?)", "out = vec2<f32>(a * b + a, a * a - b * b);", |a, b| (a * b + a, a * a - b * b)),
        (
            "Kahan, guarded as rk4.wgsl",
            "var y = a; var comp = 0.0;\n    let opaque = arrayLength(&output) == 0u;\n    for (var k = 0; k < 64; k = k + 1) {\n        let inc = select(a, b, k % 2 == 0);\n        let corrected = inc - comp;\n        let y1 = select(y + corrected, y, opaque);\n        comp = (y1 - y) - corrected;\n        y = y1;\n    }\n    out = vec2<f32>(y, comp);",
            kahan,
        ),
        (
            "Kahan, 64 increments",
            "var y = a; var comp = 0.0;\n    for (var k = 0; k < 64; k = k + 1) {\n        let inc = select(a, b, k % 2 == 0);\n        let corrected = inc - comp;\n        let y1 = y + corrected;\n        comp = (y1 - y) - corrected;\n        y = y1;\n    }\n    out = vec2<f32>(y, comp);",
            kahan,
        ),
    ];
    for (name, body, want) in cases {
        let got = run(&gpu, kernel(body), &input);
        let (mut differ, mut worst) = (0usize, 0.0f64);
        for (g, (a, b)) in got.chunks(2).zip(&pairs) {
            let (w0, w1) = want(*a, *b);
            for (g, w) in [(g[0], w0), (g[1], w1)] {
                if g.to_bits() != w.to_bits() {
                    differ += 1;
                    if w != 0.0 {
                        worst = worst.max(ulps(g, w));
                    }
                }
            }
        }
        println!("{name:28}: {differ} of {} differ from Rust's f32 bits, worst {worst:.2} ulp", 2 * n);
    }
}
