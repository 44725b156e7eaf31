//! A deserialised scene resolved: its system or model, defaults filled, the
//! run's size checked before any value is generated, then every key checked
//! against the system, each error naming its key.

use super::defaults::{
    positive, DEFAULT_ALIGN_FRACTION, DEFAULT_COUNT, DEFAULT_ITERATIONS, DEFAULT_STEPS_PER_PERIOD,
    DEFAULT_TRANSIENT, DEFAULT_VALIDATE,
};
use super::orbits::{resolve_orbits, Swept};
use super::raw::{RawAxis, RawIntegration, RawOutput, RawScene, RawSweep};
use super::starts::{resolve_starts, RawAttractors};
use super::sweep::resolve_sweep;
use super::types::{Integration, Lyapunov, Precision, Scene, Shard, Sweep};
use crate::error::{clip, number, Error, Result};
use crate::method::jacobian::Difference;
use crate::system::{self, Params, SystemInfo};

/// The scene `raw` checked and completed; `source` is its text as written
/// next to the results. The checks run in a fixed order, so that a scene
/// with several faults is always told the same one first.
pub(super) fn resolve(
    raw: RawScene,
    default_name: &str,
    source: String,
    shard: Option<Shard>,
) -> Result<Scene> {
    let (info, params) = resolve_kind(&raw)?;
    let integration = resolve_integration(info, raw.integration)?;
    let lyapunov = raw.output.lyapunov.unwrap_or_default() == Lyapunov::Spectrum;
    check_max_period(
        raw.attractors.as_ref().and_then(|a| a.max_period),
        &integration,
    )?;
    check_size(
        info,
        &raw.sweep,
        raw.attractors.as_ref(),
        &raw.output,
        &integration,
        lyapunov,
        shard,
    )?;
    let mut sweep = resolve_sweep(info, &params, raw.sweep)?;
    if let Some(delta) = integration
        .perturbation
        .filter(|d| !(d.is_finite() && *d > 0.0))
    {
        return Err(Error::invalid(
            "integration.perturbation",
            format!("must be a finite number > 0, got {}", number(delta)),
        ));
    }
    check_initial_state(info, &params, &sweep, &integration.initial_state)?;
    if let Some(attractors) = raw.attractors {
        let starts = resolve_starts(attractors, info, &integration.initial_state)?;
        // Over the host's cores (up to 2^20 starts × every value); the
        // first start refused is named, as a loop in order would. A basin
        // image's box may reach past a wall: those starts are labelled
        // apart, not refused.
        use rayon::prelude::*;
        let checked: &[Vec<f64>] = if starts.may_be_inadmissible() {
            &[]
        } else {
            &starts.states
        };
        let refused = checked.par_iter().enumerate().find_map_first(|(s, state)| {
            let refused = check_state_at_every_value(info, &params, &sweep, state).err();
            refused.map(|reason| (s, reason))
        });
        if let Some((s, reason)) = refused {
            return Err(Error::invalid(
                starts.layout.key(),
                format!("start {s} ({}): {reason}", numbers(&starts.states[s])),
            ));
        }
        sweep.starts = Some(starts);
    }
    let orbits = raw
        .orbits
        .map(|o| {
            let axis = Swept {
                parameter: &sweep.first.parameter,
                index: sweep.first.index,
                values: &sweep.first.values,
            };
            let second = sweep.second.as_ref().map(|s| Swept {
                parameter: &s.parameter,
                index: s.index,
                values: &s.values,
            });
            resolve_orbits(o, info, &params, axis, second)
        })
        .transpose()?;
    let bifurcation_points = check_output(&raw.output, &integration, lyapunov)?;
    let name = check_name(raw.name, default_name)?;
    let precision = raw.run.precision.unwrap_or_default();
    check_perturbation_resolved(&integration, precision)?;
    let plot = raw.output.plot.unwrap_or(sweep.lanes() > 1);
    Ok(Scene {
        name,
        system: info,
        params,
        sweep: std::sync::Arc::new(sweep),
        integration,
        backend: raw.run.backend.unwrap_or_default(),
        precision,
        validate: raw.run.validate.unwrap_or(DEFAULT_VALIDATE),
        lyapunov,
        bifurcation_points,
        plot,
        orbits,
        shard: None,
        batch: None,
        source,
        bifurcation_points_asked: None,
        files: Vec::new(),
    })
}

/// The system a scene runs: a built-in kind (`[system]`) or a model
/// (`[model]`), exactly one of them, with its parameters at the scene's values.
fn resolve_kind(raw: &RawScene) -> Result<(&'static SystemInfo, Params)> {
    match (&raw.system, &raw.model) {
        (Some(_), Some(_)) => Err(Error::invalid(
            "model",
            "a scene gives [system] or [model], not both",
        )),
        (Some(system), None) => resolve_system(system),
        (None, Some(model)) => resolve_model(model),
        (None, None) => Err(Error::invalid(
            "system",
            "is required: [system] with a kind, or a [model] (or model = \"file.toml\")",
        )),
    }
}

/// `[integration]` with its defaults; the counts must be positive and the
/// aligning iterations part of the transient.
fn resolve_integration(info: &'static SystemInfo, i: RawIntegration) -> Result<Integration> {
    let transient = i.transient.unwrap_or(DEFAULT_TRANSIENT);
    let align = match i.align {
        Some(align) if align > transient => {
            return Err(Error::invalid(
                "integration.align",
                format!(
                    "the aligning iterations are the transient's last ones: \
                     must not exceed integration.transient ({transient}), got {align}"
                ),
            ))
        }
        Some(align) => align,
        None => transient.div_ceil(DEFAULT_ALIGN_FRACTION),
    };
    Ok(Integration {
        steps_per_period: positive(
            "integration.steps_per_period",
            i.steps_per_period,
            DEFAULT_STEPS_PER_PERIOD,
        )?,
        transient,
        align,
        iterations: positive("integration.iterations", i.iterations, DEFAULT_ITERATIONS)?,
        initial_state: i
            .initial_state
            .unwrap_or_else(|| info.default_initial_state.to_vec()),
        perturbation: i.perturbation,
        difference: i.difference,
        impact_location: i.impact_location.unwrap_or_default(),
        submaps: match i.submaps {
            Some(n) => Some(positive("integration.submaps", Some(n), 1)?),
            None => None,
        },
    })
}

/// The run's size, checked before the sweep's values are generated: the
/// values, one lane's points, and the work of this process's lanes.
fn check_size(
    info: &'static SystemInfo,
    sweep: &RawSweep,
    attractors: Option<&RawAttractors>,
    output: &RawOutput,
    integration: &Integration,
    lyapunov: bool,
    shard: Option<Shard>,
) -> Result<()> {
    let mut counts = vec![("sweep.count".to_owned(), axis_len(&sweep.first()))];
    if let Some(second) = &sweep.second {
        counts.push(("sweep.second.count".to_owned(), axis_len(second)));
    }
    if let Some(a) = attractors {
        counts.push((a.key().to_owned(), a.count()));
    }
    let copies = if lyapunov {
        integration
            .difference
            .unwrap_or(Difference::Central)
            .copies(info.dimension())
    } else {
        0
    };
    crate::limits::check_sweep(
        &counts,
        info.dimension(),
        output.bifurcation_points.unwrap_or(0),
        attractors.and_then(|a| a.max_period),
        integration.steps_per_lane(info.is_flow, copies),
        shard.map(|s| s.count),
    )
}

/// `attractors.max_period` against the averaged iterations: a period p is
/// told from the last 2·p of them, so a longer one can never be detected
/// (and a lane would hold points for it in vain).
fn check_max_period(max_period: Option<usize>, integration: &Integration) -> Result<()> {
    let Some(max_period) = max_period else {
        return Ok(());
    };
    let most = (integration.iterations / 2).max(1);
    if max_period > most {
        return Err(Error::invalid(
            "attractors.max_period",
            format!(
                "must be at most {most}, got {max_period}: a period p is told from the last 2·p averaged iterations, and integration.iterations is {}",
                integration.iterations
            ),
        ));
    }
    Ok(())
}

/// The initial state: as many finite numbers as the system has states,
/// admissible at every swept value (the wall may be swept).
fn check_initial_state(
    info: &'static SystemInfo,
    params: &Params,
    sweep: &Sweep,
    state: &[f64],
) -> Result<()> {
    let states = info.default_initial_state.len();
    if state.len() != states {
        let names = match info.model {
            Some(code) if states != info.dimension() => format!(
                "a point of the flow from which it reaches its Poincaré section: {}",
                code.model.names.states.join(", ")
            ),
            _ => info.state_names.join(", "),
        };
        return Err(Error::invalid(
            "integration.initial_state",
            format!(
                "{} has a {states}-dimensional state ({names}), got {} numbers",
                info.kind,
                state.len()
            ),
        ));
    }
    if let Some(v) = state.iter().find(|v| !v.is_finite()) {
        return Err(Error::invalid(
            "integration.initial_state",
            format!("must be finite, got {}", number(*v)),
        ));
    }
    check_state_at_every_value(info, params, sweep, state)
        .map_err(|reason| Error::invalid("integration.initial_state", reason))
}

/// Whether `state` is admissible at every swept value: the reason it is
/// not, with the value, if it is not.
fn check_state_at_every_value(
    info: &'static SystemInfo,
    params: &Params,
    sweep: &Sweep,
    state: &[f64],
) -> std::result::Result<(), String> {
    // One copy of the parameters per axis, not per value: a sweep may have
    // 10^9 values.
    for axis in sweep.axes() {
        let mut p = params.clone();
        for (k, value) in axis.values.iter().enumerate() {
            p.set(axis.index, *value);
            (info.check_state)(&p, state).map_err(|reason| {
                let at = if axis.values.len() > 1 {
                    format!(
                        " (at {} = {}, sweep value {k})",
                        axis.parameter,
                        number(*value)
                    )
                } else {
                    String::new()
                };
                format!("{reason}{at}")
            })?;
        }
    }
    Ok(())
}

/// "[1, -0.5]": a state as a message shows it.
fn numbers(state: &[f64]) -> String {
    let parts: Vec<String> = state.iter().map(|&v| number(v)).collect();
    format!("[{}]", parts.join(", "))
}

/// `[output]`: at most one point per averaged iteration, and something to
/// compute; returns the points kept.
fn check_output(output: &RawOutput, integration: &Integration, lyapunov: bool) -> Result<usize> {
    let bifurcation_points = output.bifurcation_points.unwrap_or(0);
    if bifurcation_points > integration.iterations {
        return Err(Error::invalid(
            "output.bifurcation_points",
            format!(
                "must not exceed integration.iterations ({}), got {bifurcation_points}",
                integration.iterations
            ),
        ));
    }
    if !lyapunov && bifurcation_points == 0 {
        return Err(Error::invalid(
            "output.lyapunov",
            "\"none\" with bifurcation_points = 0 leaves nothing to compute",
        ));
    }
    Ok(bifurcation_points)
}

/// The scene's name, or `default_name`: it names the output folder, so it
/// must be a plain folder name.
fn check_name(name: Option<String>, default_name: &str) -> Result<String> {
    let name = name.unwrap_or_else(|| default_name.to_owned());
    if name.is_empty() || name.contains(['/', '\\']) || name == "." || name == ".." {
        return Err(Error::invalid(
            "name",
            format!("must be a plain folder name, got {:?}", clip(&name)),
        ));
    }
    Ok(name)
}

/// A δ below a few units of rounding starts the copies where the
/// reference is: every column would be 0/0.
fn check_perturbation_resolved(integration: &Integration, precision: Precision) -> Result<()> {
    let unit = precision.rounding_unit();
    if let Some(delta) = integration.perturbation.filter(|&d| d < 4.0 * unit) {
        return Err(Error::invalid(
            "integration.perturbation",
            format!(
                "{delta:e} is below what {} resolves (x + δ·max(1, |x|) would round to x): it must be at least {:.1e}",
                precision.name(),
                4.0 * unit
            ),
        ));
    }
    Ok(())
}

/// The values an axis will have (its checks come later).
fn axis_len(raw: &RawAxis) -> usize {
    match (&raw.values, raw.from, raw.to) {
        (Some(values), _, _) => values.len(),
        (None, Some(_), Some(_)) => raw.count.unwrap_or(DEFAULT_COUNT),
        _ => 1,
    }
}

/// A `[model]` table: parsed, compiled, and checked at its defaults.
fn resolve_model(table: &toml::Value) -> Result<(&'static SystemInfo, Params)> {
    let model = crate::model::Model::parse(table, "model")?;
    let info = system::model::info_of(&format!("{table:?}"), || {
        crate::model::compiled::Code::compile(model, "model")
    })?;
    let params = Params::defaults(info);
    (info.check)(&params).map_err(|(name, reason)| Error::invalid(info.key(name), reason))?;
    Ok((info, params))
}

/// A built-in kind (`[system]`) and its parameters, each key a parameter
/// of that kind.
fn resolve_system(table: &toml::Table) -> Result<(&'static SystemInfo, Params)> {
    let kinds = || {
        system::kinds()
            .map(|kind| format!("\"{kind}\""))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let kind = match table.get("kind") {
        None => {
            return Err(Error::invalid(
                "system.kind",
                format!("is required (one of {})", kinds()),
            ))
        }
        Some(toml::Value::String(k)) => k,
        Some(other) => {
            return Err(Error::invalid(
                "system.kind",
                format!("expected a string, got {other}"),
            ))
        }
    };
    let info = system::by_kind(kind).ok_or_else(|| {
        Error::invalid(
            "system.kind",
            format!("unknown system \"{}\" (known: {})", clip(kind), kinds()),
        )
    })?;
    let mut params = Params::defaults(info);
    for (key, value) in table {
        if key == "kind" {
            continue;
        }
        let index = info.parameter_index(key).ok_or_else(|| {
            Error::invalid(
                format!("system.{}", clip(key)),
                format!(
                    "{kind} has no parameter `{}` (its parameters: {})",
                    clip(key),
                    info.parameter_names()
                ),
            )
        })?;
        let number = match value {
            toml::Value::Float(v) => *v,
            toml::Value::Integer(v) => *v as f64,
            other => {
                return Err(Error::invalid(
                    format!("system.{key}"),
                    format!("expected a number, got {other}"),
                ))
            }
        };
        params.set(index, number);
    }
    (info.check)(&params).map_err(|(name, reason)| Error::invalid(info.key(name), reason))?;
    Ok((info, params))
}
