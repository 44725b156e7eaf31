//! The scene file: the TOML contract between users, documentation, tests and
//! outside checks.
//!
//! ```toml
//! name = "seed-fig3"              # default: the scene file's stem; output goes to out/<name>/
//! [system]                        # kind is the only required key
//! kind = "impact-oscillator"      # or "henon", "lorenz"; then that system's parameters
//! zeta = 0.05
//! [sweep]
//! parameter = "eta"               # default: the system's usual control parameter
//! from = 0.5                      # from, to, count (inclusive, evenly spaced; count default 101)
//! to = 1.5                        # ... or values = [..]; neither: the [system] value alone
//! count = 4096
//! [sweep.second]                  # optional: a second parameter, for a map over the grid
//! parameter = "f"                 #   (same keys; lanes run over the grid, first axis fastest)
//! values = [0.5, 1.0, 2.0]
//! [integration]
//! steps_per_period = 450          # RK4 steps per map period (flows; raised where a lane's
//!                                 #   fastest time scale needs it, and the summary says so)
//! transient = 500                 # iterations discarded before averaging
//! align = 50                      # of those, the last ones whose Jacobians turn the
//!                                 #   QR frame (default: a tenth of the transient)
//! iterations = 1000               # iterations averaged
//! initial_state = [0.0, 0.0]      # default: the system's (Lorenz: [1, 1, 1])
//! perturbation = 1e-6             # δ, relative to max(1, |x|) (f32: 2e-4)
//! difference = "central"          # or "forward" (the paper's)
//! impact_location = "newton"      # or "linear" (the paper's)
//! submaps = 1                     # parts per iteration; default: as many as the
//!                                 #   fastest contraction needs (CPU path)
//! [run]
//! backend = "auto"                # "cpu", "gpu", "exact"
//! precision = "f64"               # or "f32" (gpu only)
//! validate = 4                    # GPU runs: sweep values recomputed on the CPU
//! [output]
//! lyapunov = "spectrum"           # or "none"
//! bifurcation_points = 0          # last reference points kept per parameter value
//! plot = true                     # figures (PNG and SVG); default: when the sweep has
//!                                 #   more than one value
//! ```
//!
//! Unknown keys, wrong types and impossible values are errors that name the key.
//!
//! The steps, one file each: `raw` (the file's shape, deserialised with
//! unknown keys refused), `overrides` (`--set`, and which errors are an
//! override's), `model_file` (a model named by file), `resolve` (defaults
//! filled and the scene checked), `sweep` (the `[sweep]` axes), with the
//! checked scene's types in `types` and the defaults in `defaults`.

mod defaults;
mod distribution;
mod model_file;
mod orbits;
mod overrides;
mod raw;
mod resolve;
mod starts;
mod sweep;
mod types;

use std::path::Path;

use crate::error::{clip_quoted, Error, Result};

pub use defaults::{
    DEFAULT_ALIGN_FRACTION, DEFAULT_COUNT, DEFAULT_ITERATIONS, DEFAULT_PERTURBATION_F32,
    DEFAULT_PERTURBATION_F64, DEFAULT_STEPS_PER_PERIOD, DEFAULT_TRANSIENT, DEFAULT_VALIDATE,
};
pub use distribution::Distribution;
pub use model_file::model_path;
pub use orbits::{ListedOrbit, Orbits, DEFAULT_MAX_POINTS, DEFAULT_ORBIT_MAX_PERIOD};
pub use starts::{Basins, Continuation};
pub use types::{
    Axis, Backend, Integration, Layout, Lyapunov, Precision, Scene, Seed, Shard, Starts, Sweep,
};

/// Reads and checks a scene file, applying `--set key.path=value` overrides first.
pub fn load(path: &Path, overrides: &[String]) -> Result<Scene> {
    load_shard(path, overrides, None)
}

/// [`load`], restricted to `shard` of the sweep: the run's size is checked
/// for the shard's lanes (see `limits::check_sweep`).
pub fn load_shard(path: &Path, overrides: &[String], shard: Option<Shard>) -> Result<Scene> {
    let text = std::fs::read_to_string(path).map_err(|source| Error::ReadScene {
        path: path.to_owned(),
        source,
    })?;
    let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("scene");
    let mut scene = parse_in(
        &text,
        &path.display().to_string(),
        stem,
        overrides,
        shard,
        path.parent(),
    )?;
    scene.files.insert(0, path.to_owned());
    Ok(scene)
}

/// Parses scene text; `origin` names it in messages, `default_name` is the
/// name when the scene gives none.
pub fn parse(text: &str, origin: &str, default_name: &str, overrides: &[String]) -> Result<Scene> {
    parse_shard(text, origin, default_name, overrides, None)
}

/// [`parse`], restricted to `shard` (see [`load_shard`]).
pub fn parse_shard(
    text: &str,
    origin: &str,
    default_name: &str,
    overrides: &[String],
    shard: Option<Shard>,
) -> Result<Scene> {
    parse_in(text, origin, default_name, overrides, shard, None)
}

/// [`parse_shard`] of a scene whose `model = "file"` is relative to `base`
/// (the working directory when `None`): the text parsed as TOML, the model
/// file inlined, the overrides applied, then deserialised and resolved.
fn parse_in(
    text: &str,
    origin: &str,
    default_name: &str,
    overrides: &[String],
    shard: Option<Shard>,
    base: Option<&Path>,
) -> Result<Scene> {
    let mut table: toml::Table = text.parse().map_err(|e: toml::de::Error| {
        let at = e.span().map(|span| {
            let line = text[..span.start].matches('\n').count() + 1;
            format!("line {line}: ")
        });
        Error::Syntax {
            path: origin.to_owned(),
            key: None,
            message: format!(
                "{}{}",
                at.unwrap_or_default(),
                clip_quoted(e.message().trim())
            ),
        }
    })?;
    let model_file = model_file::inline_model_file(&mut table, base)?;
    let overridden = overrides::apply_overrides(&mut table, overrides, model_file.as_deref())?;
    let bifurcation_points_asked = overrides::lower_for_quick_look(&mut table, &overridden);
    // The name goes into the written scene, so that it reads back the same
    // wherever the file lies.
    table
        .entry("name")
        .or_insert_with(|| toml::Value::String(default_name.to_owned()));
    let source = toml::to_string(&table).expect("a parsed table serialises");
    let raw = raw::deserialize(table, origin, &overridden)?;
    let mut scene = resolve::resolve(raw, default_name, source, shard)
        .map_err(|e| overrides::model_error(e, model_file.as_deref(), &overridden))?;
    scene.bifurcation_points_asked = bifurcation_points_asked;
    scene.files.extend(model_file);
    match shard {
        Some(shard) => scene.sharded(shard),
        None => Ok(scene),
    }
}
