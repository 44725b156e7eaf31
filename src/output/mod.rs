//! Writing results: `spectrum.csv` and `bifurcation.csv`, and the figures of
//! [`plot`].
//!
//! Each file is written under a temporary name in the output folder and
//! renamed into place when complete, so a file appears whole or not at all.

pub mod figure;
pub mod plot;

use std::fs;
use std::path::{Path, PathBuf};

use crate::backend::Report;
use crate::error::{Error, Result};
use crate::scene::Scene;

/// The header of `spectrum.csv`:
/// `<parameter>,lambda_1,...,lambda_N,lambda_sum,expected_sum,impacts_per_period,grazing,grazing_bound,status`:
/// `grazing` counts the averaging iterations re-estimated near grazing and
/// `grazing_bound` their estimated exponent error per unit time.
pub fn spectrum_header(scene: &Scene) -> Vec<String> {
    let mut header = vec![scene.sweep.parameter.clone()];
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

/// Writes the files the scene asks for into `dir`; returns their paths.
pub fn write(scene: &Scene, report: &Report, dir: &Path) -> Result<Vec<PathBuf>> {
    fs::create_dir_all(dir).map_err(|source| Error::Write {
        path: dir.to_owned(),
        source,
    })?;
    let mut written = Vec::new();
    if scene.lyapunov {
        let path = dir.join("spectrum.csv");
        write_atomically(&path, |w| write_spectrum(scene, report, w))?;
        written.push(path);
    }
    if scene.bifurcation_points > 0 {
        let path = dir.join("bifurcation.csv");
        write_atomically(&path, |w| write_bifurcation(scene, report, w))?;
        written.push(path);
    }
    Ok(written)
}

/// Rust's `{}` for f64 is the shortest text that reads back to the same
/// number: full precision without trailing noise.
fn number(v: f64) -> String {
    format!("{v}")
}

fn write_spectrum(
    scene: &Scene,
    report: &Report,
    w: &mut csv::Writer<fs::File>,
) -> csv::Result<()> {
    w.write_record(spectrum_header(scene))?;
    for (k, lane) in report.lanes.iter().enumerate() {
        let mut row = vec![number(scene.sweep.values[k])];
        row.extend(lane.exponents.iter().map(|&e| number(e)));
        row.push(number(lane.exponent_sum()));
        row.push(number(report.expected_sums[k]));
        row.push(number(lane.impacts_per_period));
        row.push(lane.grazing.to_string());
        row.push(number(lane.grazing_bound));
        row.push(lane.status.to_string());
        w.write_record(&row)?;
    }
    Ok(())
}

fn write_bifurcation(
    scene: &Scene,
    report: &Report,
    w: &mut csv::Writer<fs::File>,
) -> csv::Result<()> {
    let dim = scene.system.dimension();
    let mut header = vec![scene.sweep.parameter.as_str()];
    header.extend_from_slice(scene.system.state_names);
    w.write_record(&header)?;
    for (k, lane) in report.lanes.iter().enumerate() {
        let parameter = number(scene.sweep.values[k]);
        for point in lane.bifurcation.chunks_exact(dim) {
            let mut row = vec![parameter.clone()];
            row.extend(point.iter().map(|&x| number(x)));
            w.write_record(&row)?;
        }
    }
    Ok(())
}

/// Writes a CSV file under a temporary name and renames it into place.
pub(crate) fn write_atomically(
    path: &Path,
    fill: impl FnOnce(&mut csv::Writer<fs::File>) -> csv::Result<()>,
) -> Result<()> {
    let file_name = path
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or("output");
    let temporary = path.with_file_name(format!(".{file_name}.{}.partial", std::process::id()));
    let fail = |source: std::io::Error| Error::Write {
        path: path.to_owned(),
        source,
    };
    let result = (|| {
        let mut writer = csv::Writer::from_path(&temporary).map_err(csv_to_io)?;
        fill(&mut writer).map_err(csv_to_io)?;
        let file = writer.into_inner().map_err(|e| e.into_error())?;
        file.sync_all()?;
        fs::rename(&temporary, path)
    })();
    if result.is_err() {
        let _ = fs::remove_file(&temporary);
    }
    result.map_err(fail)
}

fn csv_to_io(e: csv::Error) -> std::io::Error {
    match e.into_kind() {
        csv::ErrorKind::Io(io) => io,
        other => std::io::Error::other(format!("{other:?}")),
    }
}
