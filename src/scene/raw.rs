//! The scene file's shape, as serde reads it: unknown keys refused, each
//! error naming its key.

use serde::Deserialize;

use super::orbits::RawOrbits;
use super::overrides::set_key;
use super::starts::RawAttractors;
use super::types::{Backend, Lyapunov, Precision};
use crate::error::{clip, clip_quoted, Error, Result};
use crate::integrate::ImpactLocation;
use crate::method::jacobian::Difference;

// The file's shape. `[system]` is read by hand: its keys depend on `kind`.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawScene {
    pub(super) name: Option<String>,
    pub(super) system: Option<toml::Table>,
    /// A system given as data (see `crate::model`); a file's name is
    /// replaced by the file's table before anything else reads the scene.
    pub(super) model: Option<toml::Value>,
    #[serde(default)]
    pub(super) sweep: RawSweep,
    #[serde(default)]
    pub(super) integration: RawIntegration,
    #[serde(default)]
    pub(super) run: RawRun,
    #[serde(default)]
    pub(super) output: RawOutput,
    pub(super) attractors: Option<RawAttractors>,
    pub(super) orbits: Option<RawOrbits>,
}

// The first axis's keys are spelled out rather than flattened from
// RawAxis: serde's flatten loses the key of a bad value ("sweep: invalid
// type" instead of "sweep.count: invalid type").
#[derive(Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawSweep {
    pub(super) parameter: Option<String>,
    pub(super) from: Option<f64>,
    pub(super) to: Option<f64>,
    pub(super) count: Option<usize>,
    pub(super) values: Option<Vec<f64>>,
    pub(super) second: Option<RawAxis>,
}

impl RawSweep {
    pub(super) fn first(&self) -> RawAxis {
        RawAxis {
            parameter: self.parameter.clone(),
            from: self.from,
            to: self.to,
            count: self.count,
            values: self.values.clone(),
        }
    }
}

#[derive(Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawAxis {
    pub(super) parameter: Option<String>,
    pub(super) from: Option<f64>,
    pub(super) to: Option<f64>,
    pub(super) count: Option<usize>,
    pub(super) values: Option<Vec<f64>>,
}

#[derive(Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawIntegration {
    pub(super) steps_per_period: Option<usize>,
    pub(super) transient: Option<usize>,
    pub(super) align: Option<usize>,
    pub(super) iterations: Option<usize>,
    pub(super) initial_state: Option<Vec<f64>>,
    pub(super) perturbation: Option<f64>,
    pub(super) difference: Option<Difference>,
    pub(super) impact_location: Option<ImpactLocation>,
    pub(super) submaps: Option<usize>,
}

#[derive(Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawRun {
    pub(super) backend: Option<Backend>,
    pub(super) precision: Option<Precision>,
    pub(super) validate: Option<usize>,
}

#[derive(Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawOutput {
    pub(super) lyapunov: Option<Lyapunov>,
    pub(super) bifurcation_points: Option<usize>,
    pub(super) plot: Option<bool>,
}

/// The tables a scene's keys hold, as serde names them ("struct RawSweep")
/// and as its user knows them: a table, with its keys.
const TABLES: [(&str, &str); 10] = [
    ("struct RawSweep", "a table (parameter, and from, to, count or values; second)"),
    ("struct RawAxis", "a table (parameter, and from, to, count or values)"),
    ("struct RawIntegration", "a table (steps_per_period, transient, align, iterations, initial_state, perturbation, difference, impact_location, submaps)"),
    ("struct RawRun", "a table (backend, precision, validate)"),
    ("struct RawOutput", "a table (lyapunov, bifurcation_points, plot)"),
    ("struct RawAttractors", "a table (starts, seed, box, grid, list, max_period, continuation, basins, basin_box, early_stop, distribution)"),
    ("struct RawDistribution", "a table (kind, mean, sd)"),
    ("struct RawOrbits", "a table (from_sweep, list, max_period, max_points, min_step, max_step, tolerance, locate_tolerance)"),
    ("struct RawListed", "a table (value, state, period)"),
    ("struct RawScene", "a table"),
];

/// serde's message with the code's type names put in the user's words.
fn in_the_users_words(message: &str) -> String {
    TABLES.iter().fold(message.to_owned(), |m, (code, words)| {
        m.replace(code, words)
    })
}

/// The table, overrides applied, as a [`RawScene`]; a bad value is named
/// by its key, and said to be the override's when `--set` gave it.
pub(super) fn deserialize(
    table: toml::Table,
    origin: &str,
    overridden: &[(String, &String)],
) -> Result<RawScene> {
    serde_path_to_error::deserialize(toml::Value::Table(table)).map_err(|e| {
        let path = e.path().to_string();
        let key = if path == "." {
            String::new()
        } else {
            format!("{}: ", clip(&path))
        };
        // The value deserializer appends "in `path`" on a second line;
        // the path is already in front.
        let inner = e.inner().to_string();
        let first_line = clip_quoted(&in_the_users_words(
            inner.lines().next().unwrap_or_default().trim(),
        ));
        // A value an override gave is the override's fault, not the file's.
        let from = |key: &str| {
            path == key
                || path.starts_with(&format!("{key}."))
                || path.starts_with(&format!("{key}["))
        };
        match overridden.iter().rev().find(|(key, _)| from(key)) {
            Some((_, assignment)) => {
                Error::invalid(set_key(assignment), format!("{key}{first_line}"))
            }
            None => Error::Syntax {
                path: origin.to_owned(),
                key: (path != ".").then(|| path.clone()),
                message: format!("{key}{first_line}"),
            },
        }
    })
}
