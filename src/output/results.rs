//! A results folder read back: the scene that produced it and its CSV
//! files. The figures are always drawn from these files, after a run as by
//! `lyapsweep plot DIR`, so a redrawn figure is the figure of the run.

use std::path::{Path, PathBuf};

use super::files::{spectrum_file, BIFURCATION_FILE, HEAT_MAP, SCENE_FILE, SWEEP_FIGURE};
use super::plot::{self, GridData, SweepData};
use crate::error::{Error, Result};
use crate::scene::{self, Scene};

/// The scene of a results folder (its `scene.toml`).
pub fn scene_of(dir: &Path) -> Result<Scene> {
    let path = dir.join(SCENE_FILE);
    let text = std::fs::read_to_string(&path).map_err(|e| Error::Results {
        path: path.clone(),
        reason: format!("cannot read it ({e}): is this a lyapsweep output folder?"),
    })?;
    scene::parse(&text, &path.display().to_string(), "scene", &[])
}

/// The CSV file `name` of `dir`: its header and its records.
pub fn read_csv(dir: &Path, name: &str) -> Result<(csv::StringRecord, Vec<csv::StringRecord>)> {
    let path = dir.join(name);
    let bad = |reason: String| Error::Results {
        path: path.clone(),
        reason,
    };
    let mut reader = csv::Reader::from_path(&path).map_err(|e| bad(e.to_string()))?;
    let header = reader.headers().map_err(|e| bad(e.to_string()))?.clone();
    let records = reader
        .records()
        .collect::<std::result::Result<Vec<_>, _>>()
        .map_err(|e| bad(e.to_string()))?;
    Ok((header, records))
}

/// Column `k` of every record, as numbers.
fn column(path: &Path, records: &[csv::StringRecord], k: usize) -> Result<Vec<f64>> {
    records
        .iter()
        .enumerate()
        .map(|(row, r)| {
            r.get(k)
                .and_then(|t| t.parse::<f64>().ok())
                .ok_or_else(|| Error::Results {
                    path: path.to_owned(),
                    reason: format!("row {}: column {} is not a number", row + 2, k + 1),
                })
        })
        .collect()
}

/// `lyapsweep plot DIR --out INTO`: checks that `dir` holds one complete
/// set (`set::verify`) and draws its figures into `into`; a folder this
/// call created is removed again when drawing fails.
pub fn redraw(dir: &Path, into: &Path) -> Result<Vec<PathBuf>> {
    super::set::verify(dir)?;
    // The user's mistake, found before drawing (creating the folder would
    // fail only after the figures were drawn, as a failed write).
    if std::fs::metadata(into).is_ok_and(|m| !m.is_dir()) {
        return Err(Error::Output {
            path: into.to_owned(),
            reason: "exists and is not a folder: --out names the folder the figures go into".into(),
        });
    }
    let created = !into.exists();
    let result = draw(dir, into);
    if result.is_err() && created {
        let _ = std::fs::remove_dir_all(into);
    }
    result
}

/// Draws the figures of the results in `dir` (the sweep figure for one
/// parameter, the heat map of λ1 for two) into the folder `into`; returns
/// their paths.
pub fn draw(dir: &Path, into: &Path) -> Result<Vec<PathBuf>> {
    let scene = scene_of(dir)?;
    std::fs::create_dir_all(into).map_err(|source| Error::Write {
        path: into.to_owned(),
        source,
    })?;
    let axes = scene.sweep.axes().count();
    let dim = scene.system.dimension();
    let per_unit_time = scene.system.is_flow;
    let spectrum = scene
        .lyapunov
        .then(|| read_csv(dir, spectrum_file(&scene)))
        .transpose()?;
    let spectrum_path = dir.join(spectrum_file(&scene));
    if let Some(second) = &scene.sweep.second {
        let Some((_, records)) = spectrum else {
            // A map of λ1 needs exponents; points alone have no grid figure.
            return Ok(Vec::new());
        };
        let data = GridData {
            title: scene.name.clone(),
            x_name: scene.sweep.first.parameter.clone(),
            y_name: second.parameter.clone(),
            x: scene.sweep.first.values.clone(),
            y: second.values.clone(),
            lambda1: column(&spectrum_path, &records, axes)?,
            per_unit_time,
        };
        if data.lambda1.len() != data.x.len() * data.y.len() {
            return Err(Error::Results {
                path: spectrum_path,
                reason: format!(
                    "{} rows for a {} × {} grid",
                    data.lambda1.len(),
                    data.x.len(),
                    data.y.len()
                ),
            });
        }
        return plot::heat_map(&data, into, HEAT_MAP);
    }
    let (values, exponents, sum, expected_sum) = match &spectrum {
        Some((_, records)) => {
            let lambdas: Vec<Vec<f64>> = (0..dim)
                .map(|i| column(&spectrum_path, records, axes + i))
                .collect::<Result<_>>()?;
            (
                column(&spectrum_path, records, 0)?,
                (0..records.len())
                    .map(|row| lambdas.iter().map(|l| l[row]).collect())
                    .collect(),
                column(&spectrum_path, records, axes + dim)?,
                column(&spectrum_path, records, axes + dim + 1)?,
            )
        }
        None => Default::default(),
    };
    let bifurcation = if scene.bifurcation_points > 0 {
        let (_, records) = read_csv(dir, BIFURCATION_FILE)?;
        let path = dir.join(BIFURCATION_FILE);
        let at = column(&path, &records, 0)?;
        let x = column(&path, &records, axes)?;
        at.into_iter().zip(x).collect()
    } else {
        Vec::new()
    };
    let data = SweepData {
        title: scene.name.clone(),
        parameter: scene.sweep.first.parameter.clone(),
        values,
        exponents,
        sum,
        expected_sum,
        per_unit_time,
        bifurcation,
        state_name: scene.system.state_names[0].to_owned(),
    };
    plot::sweep_figure(&data, into, SWEEP_FIGURE)
}
