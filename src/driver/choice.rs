//! Which backend runs a scene: the one it asks for, or with `auto` the
//! GPU where a hardware adapter runs its kernels, else the CPU path (and
//! why, for the summary).

use crate::backend::gpu::context::{self, Want};
use crate::backend::gpu::plan::lane_plan;
use crate::error::{Error, Result};
use crate::plan::method_settings;
use crate::scene::{Backend, Precision, Scene};

/// Where a run goes.
pub(super) enum Plan {
    Cpu,
    Exact,
    Gpu(wgpu::Adapter, context::AdapterSummary),
}

/// Where `scene` runs (on adapter number `device`, if given), in which
/// precision, and why `auto` chose it.
pub(super) fn plan(
    scene: &Scene,
    device: Option<usize>,
) -> Result<(Plan, Precision, Option<String>)> {
    match scene.backend {
        Backend::Auto => {
            if let Some(why) = no_kernels(scene) {
                return Ok((
                    Plan::Cpu,
                    Precision::F64,
                    Some(format!("auto: CPU path, since {why}")),
                ));
            }
            let gpu_settings = method_settings(scene, Backend::Gpu, scene.precision);
            if let Err(Error::Invalid { reason, .. }) = lane_plan(scene, &gpu_settings) {
                return Ok((
                    Plan::Cpu,
                    Precision::F64,
                    Some(format!("auto: CPU path, since {reason}")),
                ));
            }
            let chosen = match context::choose(Want::Hardware, scene.precision, device) {
                Ok(Some(pick)) => pick,
                Ok(None) => {
                    return Ok((
                        Plan::Cpu,
                        Precision::F64,
                        Some(
                            "auto: no hardware GPU found, so the CPU reference path runs (f64)"
                                .into(),
                        ),
                    ))
                }
                Err(e @ Error::Invalid { .. }) => {
                    return Ok((
                        Plan::Cpu,
                        Precision::F64,
                        Some(format!("auto: CPU path, since {e}")),
                    ));
                }
                Err(e) => return Err(e),
            };
            let why = format!(
                "auto: hardware GPU {} ({}), {}",
                chosen.1.name,
                chosen.1.backend,
                if scene.precision == Precision::F64 {
                    "f64"
                } else {
                    "f32"
                }
            );
            Ok((Plan::Gpu(chosen.0, chosen.1), scene.precision, Some(why)))
        }
        Backend::Gpu => {
            if let Some(why) = no_kernels(scene) {
                return Err(Error::Backend {
                    backend: "gpu".into(),
                    reason: format!("{why}: use backend = \"cpu\" (\"auto\" does)"),
                });
            }
            let (adapter, summary) = context::choose(Want::Any, scene.precision, device)?
                .expect("Want::Any yields an adapter or an error");
            Ok((Plan::Gpu(adapter, summary), scene.precision, None))
        }
        Backend::Exact if !scene.system.has_exact => Err(Error::Backend {
            backend: "exact".into(),
            reason: format!(
                "{} has no closed-form tangent map; use \"cpu\"",
                scene.system.kind
            ),
        }),
        cpu_side => {
            if scene.precision == Precision::F32 {
                return Err(Error::invalid(
                    "run.precision",
                    format!(
                        "\"f32\" runs on the gpu backend only; the {} backend computes in f64",
                        cpu_side.name()
                    ),
                ));
            }
            Ok((
                if cpu_side == Backend::Exact {
                    Plan::Exact
                } else {
                    Plan::Cpu
                },
                Precision::F64,
                None,
            ))
        }
    }
}

/// Why the GPU kernels cannot run the scene's system at all, if they
/// cannot: a built-in without a WGSL twin, or a model whose generated WGSL
/// the kernels do not run yet (`model::codegen::wgsl::check`, the same for every
/// lane, so the first lane's parameters ask).
fn no_kernels(scene: &Scene) -> Option<String> {
    let system = scene.system;
    system.wgsl.is_none().then(|| {
        let why = (system.gpu_refuses)(&scene.params_at(0))
            .unwrap_or_else(|| "it has no WGSL kernel".into());
        format!("{}: {why}", system.kind)
    })
}
