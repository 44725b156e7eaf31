//! shaders/shared/math64.wgsl: f64 sin, cos, tan, exp, log, tanh, atan2 and
//! pow built from arithmetic (WGSL's own are undefined on f64 under Vulkan),
//! run on the GPU adapter and compared with Rust's over the ranges the
//! model kernels will use; and the kernels' generated `cos_sin` (the
//! forcing clock's step program) against its oracle, integrate::clock,
//! to the bit. Measured on lavapipe; on a machine without an f64
//! adapter the test says SKIPPED, and fails in CI (LYAPSWEEP_REQUIRE_GPU).

mod common;

use std::sync::mpsc;

use lyapsweep::backend::gpu::context::{self, Want};
use lyapsweep::model::language::math64;
use lyapsweep::scene::Precision;
use wgpu::util::DeviceExt;

const LIBRARY: &str = include_str!("../shaders/shared/math64.wgsl");

/// Rust's value of a function at (a, b).
type Reference = fn(f64, f64) -> f64;

/// The functions the kernel evaluates, in its `op` order, with Rust's twin.
const FUNCTIONS: [(&str, Reference); 8] = [
    ("sin", |x, _| x.sin()),
    ("cos", |x, _| x.cos()),
    ("tan", |x, _| x.tan()),
    ("exp", |x, _| x.exp()),
    ("log", |x, _| x.ln()),
    ("tanh", |x, _| x.tanh()),
    ("atan2", |x, y| x.atan2(y)),
    ("pow", |x, y| x.powf(y)),
];

/// The CPU's twins of the first functions, which must give the same bits.
const TWINS: [fn(f64) -> f64; 3] = [math64::sin, math64::cos, math64::tan];

const KERNEL: &str = r#"
@group(0) @binding(0) var<storage, read> input: array<vec2<f64>>;
@group(0) @binding(1) var<storage, read_write> output: array<f64>;
@group(0) @binding(2) var<uniform> op: vec4<u32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    if (i >= arrayLength(&output)) {
        return;
    }
    let a = input[i].x;
    let b = input[i].y;
    var r = f64(0.0);
    switch op.x {
        case 0u: { r = sin64(a); }
        case 1u: { r = cos64(a); }
        case 2u: { r = tan64(a); }
        case 3u: { r = exp64(a); }
        case 4u: { r = log64(a); }
        case 5u: { r = tanh64(a); }
        case 6u: { r = atan2_64(a, b); }
        default: { r = pow64(a, b); }
    }
    output[i] = r;
}
"#;

/// The generated clock (`model::codegen::wgsl::integrator`, a map's: the
/// rotation and `cos_sin`) behind the same bindings: op 0 gives the
/// cosine of each input, op 1 its sine.
const CLOCK_KERNEL: &str = r#"
@group(0) @binding(0) var<storage, read> input: array<vec2<f64>>;
@group(0) @binding(1) var<storage, read_write> output: array<f64>;
@group(0) @binding(2) var<uniform> op: vec4<u32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    if (i >= arrayLength(&output)) {
        return;
    }
    let phase = cos_sin(input[i].x);
    output[i] = select(phase.y, phase.x, op.x == 0u);
}
"#;

/// The generated Hermite guess (`model::ir::events::location`) behind the
/// same bindings: case k reads (g0, v0), (g1, v1), (h, _) from inputs 3k
/// to 3k + 2 and writes the interpolant's peak (-1 where none), its first
/// root in [0, 1], and its first root before the peak (0 where none).
const HERMITE_KERNEL: &str = r#"
@group(0) @binding(0) var<storage, read> input: array<vec2<f64>>;
@group(0) @binding(1) var<storage, read_write> output: array<f64>;
@group(0) @binding(2) var<uniform> op: vec4<u32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let k = 3u * gid.x;
    if (k + 2u >= arrayLength(&output)) {
        return;
    }
    let c = hermite_new(input[k].x, input[k].y, input[k + 1u].x, input[k + 1u].y, input[k + 2u].x);
    let peak = hermite_peak(c);
    output[k] = peak;
    output[k + 1u] = hermite_first_root(c, 0.0, 1.0);
    output[k + 2u] = select(0.0, hermite_first_root(c, 0.0, peak), peak >= 0.0);
}
"#;

/// Evaluates function `op` of the library at `inputs` on the GPU.
fn on_gpu(gpu: &context::Gpu, op: u32, inputs: &[[f64; 2]]) -> Vec<f64> {
    run(gpu, &format!("{LIBRARY}\n{KERNEL}"), op, inputs)
}

/// Runs `source`'s kernel (the bindings of [`KERNEL`]) with `op` at `inputs`.
fn run(gpu: &context::Gpu, source: &str, op: u32, inputs: &[[f64; 2]]) -> Vec<f64> {
    let device = &gpu.device;
    let entry = |binding, ty| wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    };
    let entries = [
        entry(0, wgpu::BufferBindingType::Storage { read_only: true }),
        entry(1, wgpu::BufferBindingType::Storage { read_only: false }),
        entry(2, wgpu::BufferBindingType::Uniform),
    ];
    let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("math64"),
        entries: &entries,
    });
    // As the kernels are compiled (contraction forbidden where the driver
    // allows it to be).
    let pipeline = gpu.compute_pipeline("math64", &layout, &entries, source, &[], Precision::F64);
    let input = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: None,
        contents: bytemuck::cast_slice(inputs),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let size = (inputs.len() * 8) as u64;
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
    let uniform = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: None,
        contents: bytemuck::cast_slice(&[op, 0, 0, 0]),
        usage: wgpu::BufferUsages::UNIFORM,
    });
    let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: None,
        layout: &layout,
        entries: &[
            wgpu::BindGroupEntry {
                binding: 0,
                resource: input.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: output.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 2,
                resource: uniform.as_entire_binding(),
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
    device
        .poll(wgpu::PollType::wait_indefinitely())
        .expect("the device answers");
    receiver.recv().unwrap().expect("readback");
    let view = readable.get_mapped_range(..).expect("mapped");
    bytemuck::cast_slice::<u8, f64>(&view).to_vec()
}

/// Distance in units of the last place of `want` (0 when both are the same
/// non-finite value).
fn ulps(got: f64, want: f64) -> f64 {
    if got == want || (got.is_nan() && want.is_nan()) {
        return 0.0;
    }
    (got - want).abs() / (want.abs().max(f64::MIN_POSITIVE) * f64::EPSILON)
}

#[test]
fn f64_functions_from_arithmetic_match_rust_within_a_few_ulp() {
    if !common::gpu_or_skip(
        "f64_functions_from_arithmetic_match_rust_within_a_few_ulp",
        Precision::F64,
    ) {
        return;
    }
    let (adapter, summary) = context::choose(Want::Any, Precision::F64, None)
        .expect("an f64 adapter")
        .expect("Want::Any yields one");
    let software = summary.device_type == format!("{:?}", wgpu::DeviceType::Cpu);
    let gpu = context::open(adapter, summary, Precision::F64).expect("device");
    let spread = |from: f64, to: f64, n: usize| -> Vec<f64> {
        (0..n)
            .map(|k| from + (to - from) * (k as f64 + 0.37) / n as f64)
            .collect()
    };
    let pairs = |xs: Vec<f64>, ys: Vec<f64>| -> Vec<[f64; 2]> {
        xs.iter()
            .flat_map(|&x| ys.iter().map(move |&y| [x, y]))
            .collect()
    };
    let single = |xs: Vec<f64>| -> Vec<[f64; 2]> { xs.into_iter().map(|x| [x, 0.0]).collect() };
    // (function index, inputs, largest error allowed in ulp): the phase of
    // a period and well beyond it, exp over its whole range, log from the
    // smallest normal number to the largest. Subnormal inputs are left out:
    // a device may flush them to zero (lavapipe does, so log(1e-310) came
    // out -inf); that is the device's arithmetic, not the library's.
    let mut log_inputs = spread(1e-3, 1e3, 2000);
    log_inputs.extend([
        f64::MIN_POSITIVE,
        1e-300,
        1e-100,
        0.5,
        1.0,
        2.0,
        1e100,
        1e300,
        1.7e308,
    ]);
    let cases: Vec<(usize, Vec<[f64; 2]>, f64)> = vec![
        (0, single(spread(-7.0, 7.0, 4001)), 4.0),
        (1, single(spread(-7.0, 7.0, 4001)), 4.0),
        (0, single(spread(-2e4, 2e4, 4001)), 8.0),
        (1, single(spread(-2e4, 2e4, 4001)), 8.0),
        (2, single(spread(-1.5, 1.5, 2001)), 8.0),
        (3, single(spread(-700.0, 700.0, 4001)), 4.0),
        (3, single(spread(-1.0, 1.0, 2001)), 4.0),
        (4, single(log_inputs), 4.0),
        (5, single(spread(-20.0, 20.0, 2001)), 4.0),
        (6, pairs(spread(-3.0, 3.0, 41), spread(-3.0, 3.0, 41)), 4.0),
        (
            7,
            pairs(spread(0.01, 10.0, 45), spread(-5.0, 5.0, 45)),
            16.0,
        ),
    ];
    for (op, inputs, allowed) in cases {
        let (name, rust) = FUNCTIONS[op];
        let got = on_gpu(&gpu, op as u32, &inputs);
        let (worst, at) = got
            .iter()
            .zip(&inputs)
            .map(|(&g, &[a, b])| (ulps(g, rust(a, b)), [a, b]))
            .fold((0.0, [0.0, 0.0]), |m, e| if e.0 > m.0 { e } else { m });
        println!("{name} over {} inputs: worst {worst:.1} ulp", inputs.len());
        assert!(
            worst <= allowed,
            "{name}: {worst:.1} ulp at {at:?} (allowed {allowed})"
        );
        // sin, cos and tan are the CPU's own: the model evaluator calls
        // the same arithmetic (lyapsweep::model::language::math64). To the bit on a
        // software adapter (lavapipe, CI's) and wherever the kernels run
        // with contraction forbidden; elsewhere a hardware driver may fuse
        // a multiply-add of the series, an ulp's difference.
        if let Some(twin) = TWINS.get(op) {
            for (&g, &[a, _]) in got.iter().zip(&inputs) {
                let cpu = twin(a);
                if software || gpu.exact_rounding() {
                    assert_eq!(g.to_bits(), cpu.to_bits(), "{name}({a:e})");
                } else {
                    assert!(ulps(g, cpu) <= 2.0, "{name}({a:e}): {g} vs {cpu}");
                }
            }
        }
    }
    // The edges: exp's overflow and underflow, log of 0 and of a negative
    // number, pow of a negative base with an integer exponent.
    let edges = |op: usize, inputs: &[[f64; 2]]| on_gpu(&gpu, op as u32, inputs);
    let e = edges(3, &[[710.0, 0.0], [-746.0, 0.0]]);
    assert_eq!(e, [f64::INFINITY, 0.0]);
    let l = edges(4, &[[0.0, 0.0], [-1.0, 0.0]]);
    assert_eq!(l[0], f64::NEG_INFINITY);
    assert!(l[1].is_nan());
    let p = edges(7, &[[-2.0, 3.0], [-2.0, 2.0], [0.0, 0.0], [-2.0, 0.5]]);
    assert!(ulps(p[0], -8.0) <= 4.0 && ulps(p[1], 4.0) <= 4.0, "{p:?}");
    assert_eq!(p[2], 1.0);
    assert!(p[3].is_nan());
}

/// The kernels' `cos_sin`, generated from the step program, gives the bits
/// of its oracle, `integrate::clock::cos_sin`, on a software adapter (and
/// wherever contraction is forbidden): over the angles the clock turns
/// through (a step's, a period's), past the eight halvings' reach, and at
/// the edges (0, -0, NaN, infinities).
#[test]
fn the_generated_cos_sin_is_the_clock_s_to_the_bit() {
    if !common::gpu_or_skip(
        "the_generated_cos_sin_is_the_clock_s_to_the_bit",
        Precision::F64,
    ) {
        return;
    }
    let (adapter, summary) = context::choose(Want::Any, Precision::F64, None)
        .expect("an f64 adapter")
        .expect("Want::Any yields one");
    let software = summary.device_type == format!("{:?}", wgpu::DeviceType::Cpu);
    let gpu = context::open(adapter, summary, Precision::F64).expect("device");
    if !(software || gpu.exact_rounding()) {
        println!("SKIPPED: a hardware driver may fuse the series' multiply-adds");
        return;
    }
    let source = format!(
        "alias real = f64;\n{}\n{CLOCK_KERNEL}",
        lyapsweep::model::codegen::wgsl::integrator(false, false, false, false, false)
    );
    let mut angles: Vec<f64> = (0..4001)
        .map(|k| -7.0 + 14.0 * (k as f64 + 0.37) / 4001.0)
        .collect();
    angles.extend((0..200).map(|k| 1e-6 * 1.1f64.powi(k)));
    angles.extend([
        0.0,
        -0.0,
        1e-300,
        300.0,
        -1e5,
        f64::NAN,
        f64::INFINITY,
        -f64::INFINITY,
    ]);
    let inputs: Vec<[f64; 2]> = angles.iter().map(|&a| [a, 0.0]).collect();
    let (cos, sin) = (
        run(&gpu, &source, 0, &inputs),
        run(&gpu, &source, 1, &inputs),
    );
    for (k, &angle) in angles.iter().enumerate() {
        let [c, s] = lyapsweep::integrate::clock::cos_sin(angle);
        // A NaN's payload is the hardware's; that it is NaN is the code's.
        let bits = |x: f64| {
            if x.is_nan() {
                f64::NAN.to_bits()
            } else {
                x.to_bits()
            }
        };
        assert_eq!(
            (bits(cos[k]), bits(sin[k])),
            (bits(c), bits(s)),
            "cos_sin({angle:e}): GPU ({}, {}), CPU ({c}, {s})",
            cos[k],
            sin[k]
        );
    }
}

/// The kernels' Hermite guess of a crossing (`hermite_peak`,
/// `hermite_first_root`), generated from the step program, gives the bits
/// of its oracle, `integrate::Hermite`, on a software adapter: over steps
/// that end across, turn back short of the surface or beyond it, or start
/// on it.
#[test]
fn the_generated_hermite_guess_is_the_locate_s_to_the_bit() {
    let name = "the_generated_hermite_guess_is_the_locate_s_to_the_bit";
    if !common::gpu_or_skip(name, Precision::F64) {
        return;
    }
    let (adapter, summary) = context::choose(Want::Any, Precision::F64, None)
        .expect("an f64 adapter")
        .expect("Want::Any yields one");
    let software = summary.device_type == format!("{:?}", wgpu::DeviceType::Cpu);
    let gpu = context::open(adapter, summary, Precision::F64).expect("device");
    if !(software || gpu.exact_rounding()) {
        println!("SKIPPED: a hardware driver may fuse the cubic's multiply-adds");
        return;
    }
    let functions = [
        "hermite_new",
        "hermite_value",
        "hermite_slope",
        "hermite_peak",
        "hermite_first_root",
    ];
    let source = format!(
        "alias real = f64;\n{}\n{HERMITE_KERNEL}",
        lyapsweep::model::codegen::wgsl::step_functions(&functions, &["Hermite"])
    );
    // A fixed pseudo-random walk over (g0, v0, g1, v1, h), and flat steps.
    let mut state = 0x9e37_79b9_7f4a_7c15_u64;
    let mut next = |scale: f64| {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        scale * ((state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0)
    };
    let mut cases: Vec<[f64; 5]> = (0..2000)
        .map(|_| {
            let h = 0.5 * (next(1.0) + 1.0) + 1e-3;
            [-next(1.0).abs(), next(3.0), next(1.0), next(3.0), h]
        })
        .collect();
    // (Not a flat step at 0: -g(0)/(g(1) - g(0)) is NaN there, which
    // Rust's clamp keeps and WGSL's clamps; the location never asks, its
    // bracket has g(0) <= 0 < g(1).)
    cases.extend([[-1.0, 2.0, -1.0, -2.0, 0.1], [0.0, 1.0, 0.5, -1.0, 0.1]]);
    let inputs: Vec<[f64; 2]> = cases
        .iter()
        .flat_map(|&[g0, v0, g1, v1, h]| [[g0, v0], [g1, v1], [h, 0.0]])
        .collect();
    let got = run(&gpu, &source, 0, &inputs);
    for (k, &[g0, v0, g1, v1, h]) in cases.iter().enumerate() {
        let hermite = lyapsweep::integrate::Hermite::new(g0, v0, g1, v1, h);
        let peak = hermite.peak().unwrap_or(-1.0);
        let before = if peak >= 0.0 {
            hermite.first_root(0.0, peak)
        } else {
            0.0
        };
        let want = [peak, hermite.first_root(0.0, 1.0), before];
        let bits = |x: f64| {
            if x.is_nan() {
                f64::NAN.to_bits()
            } else {
                x.to_bits()
            }
        };
        for (i, w) in want.iter().enumerate() {
            assert_eq!(
                bits(got[3 * k + i]),
                bits(*w),
                "case {:?}, value {i}: GPU {}, CPU {w}",
                cases[k],
                got[3 * k + i]
            );
        }
    }
}
