//! Device probe (not kept in the build): do the kernels' NaN and infinity
//! tests hold on this adapter? Compiled as the kernels are
//! (`Gpu::compute_pipeline`: on Vulkan, naga's SPIR-V passed through, f64
//! without contraction), each test on 0/0, ±1/0 and finite quotients,
//! against Rust's answers.
use lyapsweep::backend::gpu::context::{self, Want};
use lyapsweep::scene::Precision;
use std::sync::mpsc;
use wgpu::util::DeviceExt;

const TESTS: [&str; 8] = [
    "!(abs(x) <= BIG)",
    "!(x <= 0)",
    "x != x",
    "!(x > 0) && !(x <= 0)",
    "max(x, 0)",
    "min(x, 1)",
    "clamp(x, 0, 1)",
    "x",
];

fn kernel(ty: &str, big: &str) -> String {
    format!(
        r#"
@group(0) @binding(0) var<storage, read> input: array<{ty}>;
@group(0) @binding(1) var<storage, read_write> output: array<{ty}>;
@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {{
    let i = gid.x;
    if (i >= arrayLength(&output) / 8u) {{ return; }}
    let x = input[2u * i] / input[2u * i + 1u];
    let big = {ty}({big});
    let zero = {ty}(0.0);
    let one = {ty}(1.0);
    output[8u * i] = select(zero, one, !(abs(x) <= big));
    output[8u * i + 1u] = select(zero, one, !(x <= zero));
    output[8u * i + 2u] = select(zero, one, x != x);
    output[8u * i + 3u] = select(zero, one, !(x > zero) && !(x <= zero));
    output[8u * i + 4u] = max(x, zero);
    output[8u * i + 5u] = min(x, one);
    output[8u * i + 6u] = clamp(x, zero, one);
    output[8u * i + 7u] = x;
}}
"#
    )
}

fn rust(x: f64) -> [f64; 8] {
    let b = |c: bool| if c { 1.0 } else { 0.0 };
    [
        b(!(x.abs() <= f64::MAX)),
        b(!(x <= 0.0)),
        b(x.is_nan()),
        b(!(x > 0.0) && !(x <= 0.0)),
        x.max(0.0),
        x.min(1.0),
        x.clamp(0.0, 1.0),
        x,
    ]
}

fn run<T: bytemuck::Pod>(gpu: &context::Gpu, source: &str, inputs: &[T], precision: Precision) -> Vec<T> {
    let device = &gpu.device;
    let entry = |binding, read_only| wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    };
    let entries = [entry(0, true), entry(1, false)];
    let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: None,
        entries: &entries,
    });
    let pipeline = gpu.compute_pipeline("probe", &layout, &entries, source, &[], precision);
    let input = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: None,
        contents: bytemuck::cast_slice(inputs),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let size = (std::mem::size_of_val(inputs) * 4) as u64;
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
        layout: &layout,
        entries: &[
            wgpu::BindGroupEntry { binding: 0, resource: input.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 1, resource: output.as_entire_binding() },
        ],
    });
    let mut encoder = device.create_command_encoder(&Default::default());
    {
        let mut pass = encoder.begin_compute_pass(&Default::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.dispatch_workgroups(1, 1, 1);
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
    let pairs: [(f64, f64); 5] = [(0.0, 0.0), (1.0, 0.0), (-1.0, 0.0), (1.0, 2.0), (-3.0, 2.0)];
    for precision in [Precision::F64, Precision::F32] {
        let (adapter, summary) = context::choose(Want::Any, precision, None).unwrap().unwrap();
        println!("adapter {} ({}), {precision:?}", summary.name, summary.device_type);
        let gpu = context::open(adapter, summary, precision).unwrap();
        let got: Vec<f64> = match precision {
            Precision::F64 => {
                let input: Vec<f64> = pairs.iter().flat_map(|&(a, b)| [a, b]).collect();
                run(&gpu, &kernel("f64", "1.7976931348623157e308"), &input, precision)
            }
            Precision::F32 => {
                let input: Vec<f32> = pairs.iter().flat_map(|&(a, b)| [a as f32, b as f32]).collect();
                run(&gpu, &kernel("f32", "3.4028234663852886e38"), &input, precision)
                    .into_iter()
                    .map(f64::from)
                    .collect()
            }
        };
        for (k, &(a, b)) in pairs.iter().enumerate() {
            let want = rust(a / b);
            for (t, name) in TESTS.iter().enumerate() {
                let g = got[8 * k + t];
                let same = g == want[t] || (g.is_nan() && want[t].is_nan());
                if !same {
                    println!("  x = {a}/{b}: {name} gave {g}, Rust {}", want[t]);
                }
            }
        }
        println!("  (every other test as Rust)");
    }
}
