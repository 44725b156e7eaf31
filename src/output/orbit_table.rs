//! `orbits.csv` (a row per point of every branch `[orbits]` traced) and
//! `bifurcations.csv` (a row per bifurcation located on them), written
//! whole once the branches are traced.

use std::path::Path;

use super::files::{
    number, write_atomically, BIFURCATIONS_FILE, BIFURCATION_FILE, BRANCH_COLUMN, ORBITS_FILE,
};
use super::plot::{GridData, OrbitMapData, OrbitSweepData};
use crate::driver::orbits::OrbitRun;
use crate::error::{Error, Result};
use crate::model::compiled::event_column;
use crate::orbit::trace::Kind;
use crate::orbit::trace::TracedPoint;
use crate::scene::Scene;

/// The multipliers' columns: `multiplier_i_modulus,multiplier_i_argument`
/// (the argument in radians, in (-π, π]), largest modulus first.
fn multiplier_columns(dim: usize) -> Vec<String> {
    (1..=dim)
        .flat_map(|i| {
            [
                format!("multiplier_{i}_modulus"),
                format!("multiplier_{i}_argument"),
            ]
        })
        .collect()
}

/// The swept parameters' columns, named as in `spectrum.csv`.
fn parameter_columns(scene: &Scene) -> impl Iterator<Item = String> + '_ {
    scene.sweep.axes().map(|axis| axis.parameter.clone())
}

/// The header of `orbits.csv`: `branch`, the swept parameters (named as
/// in `spectrum.csv`: branches are followed in the first, at each value
/// of the second), the state, `period` (map iterations), `stable`
/// (`true` when every multiplier lies inside the unit circle), the
/// multipliers, `lambda_1..N,lambda_sum,expected_sum` (the exponents
/// ln|μ_i|/(p·T) and the sum rule's), `impacts_per_period` and for a model
/// one `<event>_per_period` column per event, `status` (`ok`, or why the
/// point's exponents are in doubt, or for a start that gave no branch
/// why), and `branch_end` (on a branch's first and last rows, how the
/// branch ended there: `bound`, `closed`, `max-points`,
/// `step-too-small(...)`).
pub fn orbits_header(scene: &Scene) -> Vec<String> {
    let dim = scene.system.dimension();
    let mut header = vec![BRANCH_COLUMN.to_owned()];
    header.extend(parameter_columns(scene));
    header.extend(scene.system.state_names.iter().map(|s| s.to_string()));
    header.extend(["period", "stable"].map(String::from));
    header.extend(multiplier_columns(dim));
    header.extend((1..=dim).map(|i| format!("lambda_{i}")));
    header.extend(["lambda_sum", "expected_sum", "impacts_per_period"].map(String::from));
    header.extend(scene.system.events.iter().map(|e| event_column(e)));
    header.extend(["status", "branch_end"].map(String::from));
    header
}

/// The header of `bifurcations.csv`: `branch`, `kind` (`fold`,
/// `period-doubling`, `neimark-sacker`, `grazing`, `sliding`,
/// `events-change`), the parameters as in `orbits.csv`, the orbit's
/// state there, its `period` and multipliers.
pub fn bifurcations_header(scene: &Scene) -> Vec<String> {
    let mut header = vec![BRANCH_COLUMN.to_owned(), "kind".to_owned()];
    header.extend(parameter_columns(scene));
    header.extend(scene.system.state_names.iter().map(|s| s.to_string()));
    header.push("period".into());
    header.extend(multiplier_columns(scene.system.dimension()));
    header
}

/// A point's parameters (the second swept one's value, if any, after the
/// followed one), state, period and (with `stable`) multipliers.
fn point_cells(point: &TracedPoint, second: Option<f64>, stable: bool) -> Vec<String> {
    let mut row = vec![number(point.parameter)];
    row.extend(second.map(number));
    row.extend(point.state.iter().map(|&x| number(x)));
    row.push(point.period.to_string());
    if stable {
        row.push(point.stable.to_string());
    }
    for m in &point.multipliers {
        row.push(number(m.norm()));
        row.push(number(m.arg()));
    }
    row
}

/// Writes `orbits.csv` and `bifurcations.csv` of `run` into `dir`.
pub fn write_orbits(scene: &Scene, run: &OrbitRun, dir: &Path) -> Result<()> {
    let dim = scene.system.dimension();
    let events = scene.system.events.len();
    let second = |b: usize| run.second.as_ref().map(|values| values[b]);
    super::set::pause(ORBITS_FILE);
    write_atomically(&dir.join(ORBITS_FILE), |w| {
        w.write_record(orbits_header(scene))?;
        for (b, branch) in run.branches.iter().enumerate() {
            if let Some(reason) = &branch.failure {
                // No orbit: the start as given, and why.
                let start = &branch.start;
                let mut row = vec![b.to_string(), number(start.parameter)];
                row.extend(second(b).map(number));
                row.extend(start.state.iter().map(|&x| number(x)));
                row.push(start.period.to_string());
                row.extend(std::iter::repeat_n(String::new(), 1 + 3 * dim + 3 + events));
                row.extend([reason.clone(), String::new()]);
                w.write_record(row)?;
                continue;
            }
            let last = branch.points.len() - 1;
            for (k, point) in branch.points.iter().enumerate() {
                let mut row = vec![b.to_string()];
                row.extend(point_cells(point, second(b), true));
                row.extend(point.exponents.iter().map(|&e| number(e)));
                row.push(number(point.exponents.iter().sum()));
                row.push(number(point.expected_sum));
                row.push(number(point.impacts_per_period));
                row.extend(
                    point.crossings_per_period[..events]
                        .iter()
                        .map(|&c| number(c)),
                );
                row.push(point.status.to_string());
                let end = match k {
                    0 => branch.ends[0].clone(),
                    k if k == last => branch.ends[1].clone(),
                    _ => String::new(),
                };
                row.push(end);
                w.write_record(row)?;
            }
        }
        Ok(())
    })?;
    super::set::pause(BIFURCATIONS_FILE);
    write_atomically(&dir.join(BIFURCATIONS_FILE), |w| {
        w.write_record(bifurcations_header(scene))?;
        for (b, branch) in run.branches.iter().enumerate() {
            for found in &branch.bifurcations {
                let mut row = vec![b.to_string(), found.kind.name().to_owned()];
                row.extend(point_cells(&found.point, second(b), false));
                w.write_record(row)?;
            }
        }
        Ok(())
    })
}

/// The records of the CSV file `name` of `dir` (read here rather than by
/// `results`, which draws the figure from these and so imports this file).
fn read_csv(dir: &Path, name: &str) -> Result<Vec<csv::StringRecord>> {
    let path = dir.join(name);
    let bad = |e: csv::Error| Error::Results {
        path: path.clone(),
        reason: e.to_string(),
    };
    let mut reader = csv::Reader::from_path(&path).map_err(bad)?;
    let records = reader.records().collect::<std::result::Result<Vec<_>, _>>();
    records.map_err(bad)
}

/// The orbits figure's data read back from the set in `dir`: the sweep's
/// points from `bifurcation.csv` (when kept), the branches from
/// `orbits.csv` (their first coordinate), the bifurcations from
/// `bifurcations.csv` with their figure labels.
pub fn figure_data(dir: &Path, scene: &Scene) -> Result<OrbitSweepData> {
    let bad = |name: &str, reason: String| Error::Results {
        path: dir.join(name),
        reason,
    };
    let number = |name: &str, row: usize, text: &str| {
        text.parse::<f64>()
            .map_err(|_| bad(name, format!("row {}: {text:?} is not a number", row + 2)))
    };
    let mut points = Vec::new();
    if scene.bifurcation_points > 0 && dir.join(BIFURCATION_FILE).exists() {
        let records = read_csv(dir, BIFURCATION_FILE)?;
        for (row, r) in records.iter().enumerate() {
            let at = |k: usize| number(BIFURCATION_FILE, row, r.get(k).unwrap_or(""));
            points.push((at(0)?, at(1)?));
        }
    }
    let dim = scene.system.dimension();
    let records = read_csv(dir, ORBITS_FILE)?;
    let mut branches: Vec<Vec<(f64, f64, bool)>> = Vec::new();
    let mut current = None;
    for (row, r) in records.iter().enumerate() {
        let stable = r.get(3 + dim).unwrap_or("");
        if stable.is_empty() {
            continue;
        }
        let branch = r.get(0).unwrap_or("");
        if current.as_deref() != Some(branch) {
            branches.push(Vec::new());
            current = Some(branch.to_owned());
        }
        let at = |k: usize| number(ORBITS_FILE, row, r.get(k).unwrap_or(""));
        let point = (at(1)?, at(2)?, stable == "true");
        branches.last_mut().expect("pushed").push(point);
    }
    let records = read_csv(dir, BIFURCATIONS_FILE)?;
    let mut bifurcations = Vec::new();
    for (row, r) in records.iter().enumerate() {
        let kind = r.get(1).unwrap_or("");
        let label = Kind::ALL
            .iter()
            .find(|k| k.name() == kind)
            .ok_or_else(|| {
                bad(
                    BIFURCATIONS_FILE,
                    format!("row {}: no kind {kind:?}", row + 2),
                )
            })?
            .label();
        let at = |k: usize| number(BIFURCATIONS_FILE, row, r.get(k).unwrap_or(""));
        bifurcations.push((at(2)?, at(3)?, label.to_owned()));
    }
    Ok(OrbitSweepData {
        title: format!("{}: periodic orbits", scene.name),
        parameter: scene.sweep.first.parameter.clone(),
        state_name: scene.system.state_names[0].to_owned(),
        points,
        branches,
        bifurcations,
    })
}

/// The orbits map's data (two swept parameters): the bifurcations of
/// `bifurcations.csv` in `dir` at (first, second), over `grid` (λ1's).
pub fn map_data(dir: &Path, scene: &Scene, grid: GridData) -> Result<OrbitMapData> {
    let records = read_csv(dir, BIFURCATIONS_FILE)?;
    let bad = |reason: String| Error::Results {
        path: dir.join(BIFURCATIONS_FILE),
        reason,
    };
    let mut points = Vec::with_capacity(records.len());
    for (row, r) in records.iter().enumerate() {
        let text = r.get(1).unwrap_or("");
        let kind = Kind::ALL
            .iter()
            .position(|k| k.name() == text)
            .ok_or_else(|| bad(format!("row {}: no kind {text:?}", row + 2)))?;
        let at = |k: usize| {
            let text = r.get(k).unwrap_or("");
            text.parse::<f64>()
                .map_err(|_| bad(format!("row {}: {text:?} is not a number", row + 2)))
        };
        points.push((at(2)?, at(3)?, kind));
    }
    Ok(OrbitMapData {
        grid: GridData {
            title: format!(
                "{}: bifurcations of the periodic orbits over λ₁",
                scene.name
            ),
            ..grid
        },
        kinds: Kind::ALL
            .iter()
            .map(|k| format!("{} {}", k.label(), k.name()))
            .collect(),
        points,
    })
}
