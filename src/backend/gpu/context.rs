//! Adapters and devices: listing, choosing (honouring `WGPU_BACKEND` and
//! `WGPU_ADAPTER_NAME`), and opening one with the features a sweep needs.

use std::borrow::Cow;
use std::sync::Mutex;

use super::spirv;
use crate::error::{Error, Result};
use crate::scene::Precision;

/// What `lyapsweep devices` prints about an adapter.
#[derive(Clone, Debug)]
pub struct AdapterSummary {
    pub name: String,
    pub backend: String,
    pub device_type: String,
    pub f64: bool,
    pub timestamps: bool,
    /// The driver takes SPIR-V as it is (wgpu's passthrough shaders on
    /// Vulkan), so the f64 kernels run with contraction forbidden (`spirv`).
    pub exact_rounding: bool,
    pub max_storage_binding: u64,
    pub max_buffer: u64,
    pub max_workgroups: u32,
}

impl AdapterSummary {
    fn of(adapter: &wgpu::Adapter) -> Self {
        let info = adapter.get_info();
        let limits = adapter.limits();
        let features = adapter.features();
        let exact_rounding = info.backend == wgpu::Backend::Vulkan
            && features.contains(wgpu::Features::PASSTHROUGH_SHADERS);
        AdapterSummary {
            name: info.name,
            backend: format!("{:?}", info.backend).to_lowercase(),
            device_type: format!("{:?}", info.device_type),
            f64: features.contains(wgpu::Features::SHADER_F64),
            timestamps: features.contains(wgpu::Features::TIMESTAMP_QUERY),
            exact_rounding,
            max_storage_binding: limits.max_storage_buffer_binding_size,
            max_buffer: limits.max_buffer_size,
            max_workgroups: limits.max_compute_workgroups_per_dimension,
        }
    }

    /// A hardware GPU (not a software rasteriser such as lavapipe or llvmpipe).
    pub fn is_hardware(&self) -> bool {
        matches!(
            self.device_type.as_str(),
            "DiscreteGpu" | "IntegratedGpu" | "VirtualGpu"
        )
    }
}

/// The adapters for `backends` (the descriptor from the environment would
/// take `WGPU_BACKEND` too, and the f64 message must look past it), found
/// once per process with one instance: NVIDIA's Vulkan driver on an H100
/// stopped listing the GPU after a few dozen instances in one process (the
/// benchmark's runs), where lavapipe never did; and listing them again on
/// a shared instance from several threads at once makes the GL backend's
/// context current on two threads, which EGL refuses.
fn adapters_of(backends: wgpu::Backends) -> Vec<wgpu::Adapter> {
    type Found = (wgpu::Backends, wgpu::Instance, Vec<wgpu::Adapter>);
    static FOUND: Mutex<Vec<Found>> = Mutex::new(Vec::new());
    let mut found = FOUND
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner());
    if let Some((.., adapters)) = found.iter().find(|(b, ..)| *b == backends) {
        return adapters.clone();
    }
    quiet_mesa();
    let mut descriptor = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
    descriptor.backends = backends;
    let instance = wgpu::Instance::new(descriptor);
    let adapters = pollster::block_on(instance.enumerate_adapters(backends));
    found.push((backends, instance, adapters.clone()));
    adapters
}

/// Mesa's drivers print "error: XDG_RUNTIME_DIR is invalid or not set" while
/// wgpu looks for adapters, which reads like an error of ours (and filled
/// the test log with hundreds of lines); a headless compute run needs no
/// runtime directory. Set once, before the first instance loads a driver.
fn quiet_mesa() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
            // SAFETY (edition 2024 wording): no other thread of this
            // library reads the environment while the driver is not loaded.
            std::env::set_var("XDG_RUNTIME_DIR", std::env::temp_dir());
        }
    });
}

fn all_adapters() -> Vec<wgpu::Adapter> {
    adapters_of(crate::environment::wgpu_backends().unwrap_or(wgpu::Backends::all()))
}

/// Every adapter wgpu finds (after `WGPU_BACKEND`), for `lyapsweep devices`.
pub fn list() -> Vec<AdapterSummary> {
    all_adapters().iter().map(AdapterSummary::of).collect()
}

/// An opened device and what it is.
pub struct Gpu {
    /// Which of the process's opened devices this is (compiled pipelines
    /// are kept per device: see `sweep::Pipelines::cached`).
    pub id: usize,
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub summary: AdapterSummary,
    pub limits: wgpu::Limits,
}

impl Gpu {
    /// The most bytes one buffer bound as storage may hold.
    pub fn max_binding(&self) -> u64 {
        self.limits
            .max_storage_buffer_binding_size
            .min(self.limits.max_buffer_size)
    }

    /// Whether the kernels are handed to the driver as SPIR-V with
    /// contraction forbidden (see `spirv`).
    pub fn exact_rounding(&self) -> bool {
        self.device
            .features()
            .contains(wgpu::Features::PASSTHROUGH_SHADERS)
    }

    /// The compute pipeline of WGSL `source`'s entry point `main` over the
    /// one bind group `layout`, made of `entries`, with its overridable
    /// `constants` set. Where the driver takes SPIR-V as it is, an f64
    /// kernel is compiled with contraction forbidden (see `spirv`), to round
    /// as the CPU path does; an f32 kernel is left as the driver compiles
    /// it, since no f32 bits are to be matched (the CPU path is f64). Which
    /// is the more accurate in f32 is not settled: on lavapipe, which does
    /// not fuse a·b + c but does reassociate, `NoContraction` moved an f32
    /// section's validation from within 1e-3 to 1.25e-3; on an H100, which
    /// fuses, it brought an f32 sum-rule error from 3.1e-4 to 8.1e-5 in one
    /// measurement there (the card's f32 rounding: docs/BENCHMARKS-GPU.md, "f32
    /// on NVIDIA"). Elsewhere wgpu
    /// compiles the WGSL and the driver may fuse.
    pub fn compute_pipeline(
        &self,
        label: &str,
        layout: &wgpu::BindGroupLayout,
        entries: &[wgpu::BindGroupLayoutEntry],
        source: &str,
        constants: &[(&str, f64)],
        precision: Precision,
    ) -> wgpu::ComputePipeline {
        let device = &self.device;
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(label),
            bind_group_layouts: &[Some(layout)],
            immediate_size: 0,
        });
        let (module, constants) = if self.exact_rounding() {
            let bindings: Vec<u32> = entries.iter().map(|e| e.binding).collect();
            let fusing = precision == Precision::F32;
            let words = spirv::compile(source, &bindings, constants, fusing)
                .unwrap_or_else(|e| panic!("kernel {label}: {e}"));
            let entry = wgpu::PassthroughShaderEntryPoint {
                name: "main".into(),
                workgroup_size: (1, 1, 1),
            };
            // SAFETY: the SPIR-V is naga's, from WGSL that naga validated,
            // with decorations added that only restrict how the driver may
            // compute; the bindings are where wgpu put the layout's
            // descriptors (set 0, each at its rank: `spirv::compile`).
            let module = unsafe {
                device.create_shader_module_passthrough(wgpu::ShaderModuleDescriptorPassthrough {
                    label: Some(label),
                    entry_points: Cow::Borrowed(std::slice::from_ref(&entry)),
                    spirv: Some(Cow::Owned(words)),
                    ..Default::default()
                })
            };
            // The constants are in the SPIR-V already.
            (module, &[][..])
        } else {
            let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(label),
                source: wgpu::ShaderSource::Wgsl(Cow::Borrowed(source)),
            });
            (module, constants)
        };
        device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(label),
            layout: Some(&pipeline_layout),
            module: &module,
            entry_point: Some("main"),
            compilation_options: wgpu::PipelineCompilationOptions {
                constants,
                ..Default::default()
            },
            cache: None,
        })
    }
}

/// Which adapters a request accepts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Want {
    /// `backend = "gpu"`: any adapter, software ones included.
    Any,
    /// `backend = "auto"`: hardware only.
    Hardware,
}

/// The adapter a run would use, or why there is none: `Ok(None)` when
/// `want` is `Hardware` and there is no hardware GPU. `device` picks one by
/// its number in [`list`] (identical GPUs have the same name).
pub fn choose(
    want: Want,
    precision: Precision,
    device: Option<usize>,
) -> Result<Option<(wgpu::Adapter, AdapterSummary)>> {
    super::shader::check_source_dir()?;
    let mut candidates: Vec<(wgpu::Adapter, AdapterSummary)> =
        adapters_of(crate::environment::wgpu_backends()?)
            .into_iter()
            .map(|a| {
                let s = AdapterSummary::of(&a);
                (a, s)
            })
            .collect();
    if let Some(n) = device {
        if n >= candidates.len() {
            return Err(Error::invalid(
                "--device",
                format!(
                    "there is no adapter {n}: `lyapsweep devices` lists {} (numbered from 0)",
                    candidates.len()
                ),
            ));
        }
        candidates = vec![candidates.swap_remove(n)];
    }
    let found = || {
        let names: Vec<String> = list()
            .iter()
            .map(|s| format!("{} ({})", s.name, s.backend))
            .collect();
        if names.is_empty() {
            "none".to_owned()
        } else {
            names.join(", ")
        }
    };
    if let Ok(wanted) = std::env::var("WGPU_ADAPTER_NAME") {
        let wanted_lower = wanted.to_lowercase();
        candidates.retain(|(_, s)| s.name.to_lowercase().contains(&wanted_lower));
        if candidates.is_empty() {
            return Err(Error::Backend {
                backend: "gpu".into(),
                reason: format!(
                    "WGPU_ADAPTER_NAME={wanted:?} matches no adapter (found: {})",
                    found()
                ),
            });
        }
    }
    if want == Want::Hardware {
        candidates.retain(|(_, s)| s.is_hardware());
        if candidates.is_empty() {
            return Ok(None);
        }
    }
    if candidates.is_empty() {
        return Err(Error::Backend {
            backend: "gpu".into(),
            reason: "no GPU adapter found (install a Vulkan driver, e.g. mesa-vulkan-drivers)"
                .into(),
        });
    }
    if precision == Precision::F64 {
        if !candidates.iter().any(|(_, s)| s.f64) {
            let names: Vec<String> = candidates
                .iter()
                .map(|(_, s)| format!("{} ({})", s.name, s.backend))
                .collect();
            // Adapters the selection left out may have it: say which, and
            // what selected.
            let elsewhere: Vec<String> = adapters_of(wgpu::Backends::all())
                .iter()
                .map(AdapterSummary::of)
                .filter(|s| s.f64)
                .map(|s| format!("{} ({})", s.name, s.backend))
                .collect();
            let selection: Vec<String> = [
                std::env::var("WGPU_BACKEND")
                    .ok()
                    .map(|v| format!("WGPU_BACKEND={v}")),
                std::env::var("WGPU_ADAPTER_NAME")
                    .ok()
                    .map(|v| format!("WGPU_ADAPTER_NAME={v}")),
                device.map(|n| format!("--device {n}")),
            ]
            .into_iter()
            .flatten()
            .collect();
            let reason = if elsewhere.is_empty() || selection.is_empty() {
                format!(
                    "\"f64\" needs SHADER_F64, which no adapter here has ({}); use \"f32\"",
                    names.join(", ")
                )
            } else {
                format!(
                    "\"f64\" needs SHADER_F64, which the adapters {} selects do not have ({}); {} has it: change the selection or use \"f32\"",
                    selection.join(" and "),
                    names.join(", "),
                    elsewhere.join(", ")
                )
            };
            return Err(Error::invalid("run.precision", reason));
        }
        candidates.retain(|(_, s)| s.f64);
    }
    // Prefer hardware, then discrete over integrated.
    let rank = |s: &AdapterSummary| match s.device_type.as_str() {
        "DiscreteGpu" => 0,
        "IntegratedGpu" => 1,
        "VirtualGpu" => 2,
        _ => 3,
    };
    candidates.sort_by_key(|(_, s)| rank(s));
    Ok(candidates.into_iter().next())
}

/// The device on the adapter with the features and limits a sweep needs,
/// opened once per adapter and precision in a process and shared by every
/// run after (a benchmark or a test binary makes hundreds; wgpu's device
/// and queue are shared handles, safe across threads). Opening a device
/// per run cost setup time on every driver and, on NVIDIA's, ran it out of
/// devices within one benchmark.
pub fn open(adapter: wgpu::Adapter, summary: AdapterSummary, precision: Precision) -> Result<Gpu> {
    type Opened = (String, Precision, wgpu::Device, wgpu::Queue);
    static OPENED: Mutex<Vec<Opened>> = Mutex::new(Vec::new());
    // The whole adapter description: identical GPUs differ in their bus id.
    let key = format!("{:?}", adapter.get_info());
    let mut opened = OPENED
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner());
    let found = opened
        .iter()
        .position(|(k, p, ..)| *k == key && *p == precision);
    let id = match found {
        Some(id) => id,
        None => {
            let (device, queue) = open_new(&adapter, &summary, precision)?;
            opened.push((key, precision, device, queue));
            opened.len() - 1
        }
    };
    let (.., device, queue) = &opened[id];
    Ok(Gpu {
        id,
        device: device.clone(),
        queue: queue.clone(),
        summary,
        limits: adapter.limits(),
    })
}

fn open_new(
    adapter: &wgpu::Adapter,
    summary: &AdapterSummary,
    precision: Precision,
) -> Result<(wgpu::Device, wgpu::Queue)> {
    let mut features = wgpu::Features::empty();
    if precision == Precision::F64 {
        features |= wgpu::Features::SHADER_F64;
    }
    // Device time per pass, reported beside wall time (see `stopwatch`).
    if summary.timestamps {
        features |= wgpu::Features::TIMESTAMP_QUERY;
    }
    if summary.exact_rounding {
        features |= wgpu::Features::PASSTHROUGH_SHADERS;
    }
    // Ask for everything the adapter offers: large sweeps want its largest bindings.
    let limits = adapter.limits();
    let descriptor = wgpu::DeviceDescriptor {
        label: Some("lyapsweep"),
        required_features: features,
        required_limits: limits.clone(),
        ..Default::default()
    };
    pollster::block_on(adapter.request_device(&descriptor)).map_err(|e| Error::Backend {
        backend: "gpu".into(),
        reason: format!("cannot open {}: {e}", summary.name),
    })
}
