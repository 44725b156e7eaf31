//! The output set's file names, and the writers that put a file in place
//! whole: under a temporary name, renamed when complete.

use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::scene::Scene;

/// The scene as run, next to its results.
pub const SCENE_FILE: &str = "scene.toml";
/// Which part of the sweep a shard holds (see [`merge`]).
pub const SHARD_FILE: &str = "shard.toml";
pub const SPECTRUM_FILE: &str = "spectrum.csv";
pub const GRID_FILE: &str = "grid.csv";
pub const BIFURCATION_FILE: &str = "bifurcation.csv";
/// With `[attractors]`: one row per attractor found at a swept value.
pub const ATTRACTORS_FILE: &str = "attractors.csv";
/// With `[orbits]`: a row per point of every periodic orbit's branch.
pub const ORBITS_FILE: &str = "orbits.csv";
/// With `[orbits]`: a row per bifurcation located on the branches.
pub const BIFURCATIONS_FILE: &str = "bifurcations.csv";
/// The column naming the branch an attractor (or a lane's) belongs to: one
/// attractor followed across the swept values.
pub const BRANCH_COLUMN: &str = "branch";
/// The column of a row's estimated exponent error (see
/// `LaneResult::error`).
pub const ERROR_COLUMN: &str = "lambda_error";

/// `spectrum.csv` for one swept parameter, `grid.csv` for two.
pub fn spectrum_file(scene: &Scene) -> &'static str {
    if scene.sweep.second.is_some() {
        GRID_FILE
    } else {
        SPECTRUM_FILE
    }
}

/// The figures' file stems (each drawn as .png and .svg).
pub const SWEEP_FIGURE: &str = "figure";
pub const HEAT_MAP: &str = "heat-map";
/// With `[orbits]`: the branches over the sweep's points.
pub const ORBIT_FIGURE: &str = "orbits";
/// With `[orbits]` over two parameters: the bifurcations over λ₁'s map.
pub const ORBIT_MAP: &str = "orbits-map";
/// With `[attractors]` over two parameters: the attractors found per cell.
pub const ATTRACTOR_MAP: &str = "attractors-map";

/// The shortest text that reads back to the same number: full precision
/// without trailing noise, with an exponent only for extreme magnitudes
/// (see [`crate::error::number`]).
pub(crate) fn number(v: f64) -> String {
    crate::error::number(v)
}

/// Writes a text file under a temporary name and renames it into place.
pub(crate) fn write_text(path: &Path, text: &str) -> Result<()> {
    write_file(path, |file| file.write_all(text.as_bytes()))
}

/// Writes a CSV file under a temporary name and renames it into place.
pub(crate) fn write_atomically(
    path: &Path,
    fill: impl FnOnce(&mut csv::Writer<&mut fs::File>) -> csv::Result<()>,
) -> Result<()> {
    write_file(path, |file| {
        let mut writer = csv::Writer::from_writer(file);
        fill(&mut writer).map_err(csv_to_io)?;
        writer.flush()
    })
}

/// The temporary name a file is written under before it is renamed to `path`
/// (a hidden name with the process id, so that runs sharing a folder do not
/// collide, and with `path`'s extension, which some writers go by).
pub(crate) fn temporary_name(path: &Path) -> PathBuf {
    let file_name = path
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or("output");
    let extension = path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| format!(".{e}"))
        .unwrap_or_default();
    path.with_file_name(format!(
        ".{file_name}.{}.partial{extension}",
        std::process::id()
    ))
}

pub(crate) fn write_file(
    path: &Path,
    fill: impl FnOnce(&mut fs::File) -> std::io::Result<()>,
) -> Result<()> {
    let temporary = temporary_name(path);
    let result = (|| {
        let mut file = fs::File::create(&temporary)?;
        fill(&mut file)?;
        file.sync_all()?;
        fs::rename(&temporary, path)
    })();
    if result.is_err() {
        let _ = fs::remove_file(&temporary);
    }
    result.map_err(|source| Error::Write {
        path: path.to_owned(),
        source,
    })
}

pub(crate) fn csv_to_io(e: csv::Error) -> std::io::Error {
    match e.into_kind() {
        csv::ErrorKind::Io(io) => io,
        other => std::io::Error::other(format!("{other:?}")),
    }
}
