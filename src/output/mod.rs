//! Writing results: the CSV files, the scene that produced them, and the
//! figures drawn from them.
//!
//! A one-parameter sweep writes `spectrum.csv`, a two-parameter one
//! `grid.csv` (the same columns after both parameters, first axis fastest);
//! `bifurcation.csv` holds the kept reference points. `scene.toml` is the
//! scene after overrides, which `plot` and `merge` read back. A shard
//! (`--shard i/n`) writes its own rows and `shard.toml`; `merge` puts shards
//! back into the files one run would have written.
//!
//! Each file is written under a temporary name in the output folder and
//! renamed into place when complete, so a file appears whole or not at all.

pub mod figure;
pub mod merge;
pub mod plot;
pub mod results;

use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

use crate::backend::Report;
use crate::error::{Error, Result};
use crate::scene::Scene;

/// The scene as run, next to its results.
pub const SCENE_FILE: &str = "scene.toml";
/// Which part of the sweep a shard holds (see [`merge`]).
pub const SHARD_FILE: &str = "shard.toml";
pub const BIFURCATION_FILE: &str = "bifurcation.csv";

/// `spectrum.csv` for one swept parameter, `grid.csv` for two.
pub fn spectrum_file(scene: &Scene) -> &'static str {
    if scene.sweep.second.is_some() {
        "grid.csv"
    } else {
        "spectrum.csv"
    }
}

/// The header of `spectrum.csv` (`grid.csv`): the swept parameters, then
/// `lambda_1,...,lambda_N,lambda_sum,expected_sum,impacts_per_period,grazing,grazing_bound,status`:
/// `grazing` counts the averaging iterations re-estimated near grazing and
/// `grazing_bound` their estimated exponent error per unit time.
pub fn spectrum_header(scene: &Scene) -> Vec<String> {
    let mut header: Vec<String> = scene.sweep.axes().map(|a| a.parameter.clone()).collect();
    header.extend((1..=scene.system.dimension()).map(|i| format!("lambda_{i}")));
    header.extend(
        [
            "lambda_sum",
            "expected_sum",
            "impacts_per_period",
            "grazing",
            "grazing_bound",
            "status",
        ]
        .map(String::from),
    );
    header
}

/// The header of `bifurcation.csv`: the swept parameters, then the state.
pub fn bifurcation_header(scene: &Scene) -> Vec<String> {
    let mut header: Vec<String> = scene.sweep.axes().map(|a| a.parameter.clone()).collect();
    header.extend(scene.system.state_names.iter().map(|s| s.to_string()));
    header
}

/// Writes the files the scene asks for into `dir` (and the figures, unless
/// this is a shard); returns their paths.
pub fn write(scene: &Scene, report: &Report, dir: &Path) -> Result<Vec<PathBuf>> {
    fs::create_dir_all(dir).map_err(|source| Error::Write {
        path: dir.to_owned(),
        source,
    })?;
    let mut written = Vec::new();
    let path = dir.join(SCENE_FILE);
    write_text(&path, &scene.source)?;
    written.push(path);
    if scene.lyapunov {
        let path = dir.join(spectrum_file(scene));
        write_atomically(&path, |w| {
            w.write_record(spectrum_header(scene))?;
            for row in spectrum_rows(scene, report) {
                w.write_record(&row)?;
            }
            Ok(())
        })?;
        written.push(path);
    }
    if scene.bifurcation_points > 0 {
        let path = dir.join(BIFURCATION_FILE);
        write_atomically(&path, |w| {
            w.write_record(bifurcation_header(scene))?;
            for j in 0..report.lanes.len() {
                for row in bifurcation_rows(scene, report, j) {
                    w.write_record(&row)?;
                }
            }
            Ok(())
        })?;
        written.push(path);
    }
    if let Some(shard) = scene.shard {
        let rows: Vec<String> = (0..report.lanes.len())
            .map(|j| (report.lanes[j].bifurcation.len() / scene.system.dimension()).to_string())
            .collect();
        let first: Vec<String> = shard
            .lanes(scene.sweep.lanes())
            .take(3)
            .map(|k| k.to_string())
            .collect();
        let text = format!(
            "# Shard {} of {} (sweep lanes {}, ...): `lyapsweep merge` combines the shards.\nindex = {}\ncount = {}\nlanes = {}\nbifurcation_rows = [{}]\n",
            shard.index,
            shard.count,
            first.join(", "),
            shard.index,
            shard.count,
            scene.sweep.lanes(),
            rows.join(", ")
        );
        let path = dir.join(SHARD_FILE);
        write_text(&path, &text)?;
        written.push(path);
    } else if scene.plot {
        written.extend(results::draw(dir, dir)?);
    }
    Ok(written)
}

/// Rust's `{}` for f64 is the shortest text that reads back to the same
/// number: full precision without trailing noise.
fn number(v: f64) -> String {
    format!("{v}")
}

/// The `spectrum.csv` rows of the run's lanes, in order.
fn spectrum_rows<'a>(
    scene: &'a Scene,
    report: &'a Report,
) -> impl Iterator<Item = Vec<String>> + 'a {
    report.lanes.iter().enumerate().map(move |(j, lane)| {
        let mut row: Vec<String> = scene.lane_values(j).into_iter().map(number).collect();
        row.extend(lane.exponents.iter().map(|&e| number(e)));
        row.push(number(lane.exponent_sum()));
        row.push(number(report.expected_sums[j]));
        row.push(number(lane.impacts_per_period));
        row.push(lane.grazing.to_string());
        row.push(number(lane.grazing_bound));
        row.push(lane.status.to_string());
        row
    })
}

/// The `bifurcation.csv` rows of the run's lane `j`.
fn bifurcation_rows(scene: &Scene, report: &Report, j: usize) -> Vec<Vec<String>> {
    let parameters: Vec<String> = scene.lane_values(j).into_iter().map(number).collect();
    report.lanes[j]
        .bifurcation
        .chunks_exact(scene.system.dimension())
        .map(|point| {
            let mut row = parameters.clone();
            row.extend(point.iter().map(|&x| number(x)));
            row
        })
        .collect()
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

fn write_file(path: &Path, fill: impl FnOnce(&mut fs::File) -> std::io::Result<()>) -> Result<()> {
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

fn csv_to_io(e: csv::Error) -> std::io::Error {
    match e.into_kind() {
        csv::ErrorKind::Io(io) => io,
        other => std::io::Error::other(format!("{other:?}")),
    }
}
