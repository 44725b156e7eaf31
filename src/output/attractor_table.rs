//! `attractors.csv`, one row per (value, attractor) of a sweep with many
//! starts, and the `branch` column of `spectrum.csv` and
//! `bifurcation.csv`, filled in once the branches are known (after the
//! last continuation pass, so after the rows were streamed).

use std::path::Path;

use super::basin_files::ValueBasins;
use super::files::{number, write_atomically, BRANCH_COLUMN, ERROR_COLUMN};
use crate::attractor::basins;
use crate::attractor::group::Attractor;
use crate::attractor::Attractors;
use crate::error::{Error, Result};
use crate::model::compiled::event_column;
use crate::scene::Scene;

/// The header of `attractors.csv`: the swept parameters, `branch` (empty
/// for a lone failed lane), `period` (empty when aperiodic),
/// `impacts_per_period` and for a model one `<event>_per_period` column
/// per event, with exponents `lambda_1..N,lambda_sum,expected_sum,lambda_error`, then
/// `basin_fraction` (the share of the value's starts that end on it),
/// `starts` (their count), with random starts from a named distribution
/// (`attractors.distribution`) `basin_fraction_error`, with basin images
/// (`attractors.basins`)
/// `basin_fraction_error` (the fraction's binomial standard error),
/// `basin_fraction_half` (on the grid at half the resolution),
/// `basin_entropy`, `boundary_basin_entropy`, `fractal_boundary`,
/// `uncertainty_exponent` and `boundary_dimension` (the value's, repeated
/// on its rows) and `critical_shock` (the attractor's; all empty beyond
/// the values with an image), and `convergence_mean`,
/// `convergence_median` and `convergence_max` (its starts' convergence
/// times in iterations, at every value), then the final state of the
/// lane that found it, and its `status`.
pub fn attractors_header(scene: &Scene) -> Vec<String> {
    let mut header: Vec<String> = scene.sweep.axes().map(|a| a.parameter.clone()).collect();
    header.extend([BRANCH_COLUMN, "period", "impacts_per_period"].map(String::from));
    header.extend(scene.system.events.iter().map(|e| event_column(e)));
    if scene.lyapunov {
        header.extend((1..=scene.system.dimension()).map(|i| format!("lambda_{i}")));
        header.extend(["lambda_sum", "expected_sum", ERROR_COLUMN].map(String::from));
    }
    header.extend(["basin_fraction", "starts"].map(String::from));
    if has_images(scene) {
        header.extend(BASIN_COLUMNS.map(String::from));
    } else if has_distribution(scene) {
        header.push(BASIN_COLUMNS[0].into());
    }
    header.extend(scene.system.state_names.iter().map(|s| s.to_string()));
    header.push("status".into());
    header
}

/// The columns of the basin measures.
const BASIN_COLUMNS: [&str; 11] = [
    "basin_fraction_error",
    "basin_fraction_half",
    "basin_entropy",
    "boundary_basin_entropy",
    "fractal_boundary",
    "uncertainty_exponent",
    "boundary_dimension",
    "critical_shock",
    "convergence_mean",
    "convergence_median",
    "convergence_max",
];

/// Whether the scene asks for basin images (and so their columns).
fn has_images(scene: &Scene) -> bool {
    scene
        .sweep
        .starts
        .as_ref()
        .is_some_and(|s| s.basins.values > 0)
}

/// Whether the scene names the distribution of its random starts
/// (`attractors.distribution`): its fractions are basin stability, with
/// their standard errors.
fn has_distribution(scene: &Scene) -> bool {
    scene
        .sweep
        .starts
        .as_ref()
        .is_some_and(|s| s.distribution_given)
}

/// The basin columns of an attractor's row: `fraction` of `starts`, with
/// the value's image if it has one.
fn basin_cells(
    scene: &Scene,
    fraction: f64,
    starts: usize,
    image: Option<&ValueBasins>,
    attractor: &Attractor,
) -> Vec<String> {
    let label = attractor.branch.map_or(basins::FAILED, |b| b as i32);
    let mut cells = vec![number(basins::fraction_error(fraction, starts))];
    match image {
        Some(v) => {
            let shock = (label != basins::FAILED)
                .then(|| critical_shock(scene, v, attractor, label))
                .flatten();
            let uncertainty = v.uncertainty.as_ref();
            cells.extend([
                number(basins::half_resolution_fraction(&v.image, label)),
                number(v.entropy.basin),
                number(v.entropy.boundary),
                v.entropy.fractal().to_string(),
                uncertainty.map_or(String::new(), |u| number(u.exponent)),
                uncertainty.map_or(String::new(), |u| number(u.boundary_dimension())),
                shock.map_or(String::new(), number),
            ])
        }
        None => cells.extend((0..7).map(|_| String::new())),
    }
    match attractor.convergence() {
        Some((mean, median, largest)) => {
            cells.extend([number(mean), number(median), largest.to_string()])
        }
        None => cells.extend((0..3).map(|_| String::new())),
    }
    cells
}

/// The attractor's minimal critical shock over its value's image (see
/// `attractor::basins`): from each of its orbit's points.
fn critical_shock(scene: &Scene, v: &ValueBasins, a: &Attractor, label: i32) -> Option<f64> {
    let starts = scene.sweep.starts.as_ref()?;
    let [ax, ay] = starts.basins.axes;
    let (nx, ny) = (v.image.nx, v.image.ny);
    let x: Vec<f64> = (0..nx).map(|i| starts.states[i][ax]).collect();
    let y: Vec<f64> = (0..ny).map(|j| starts.states[j * nx][ay]).collect();
    let dim = scene.system.dimension();
    let points: Vec<[f64; 2]> = a
        .first
        .lane
        .orbit
        .chunks_exact(dim)
        .map(|p| [p[ax], p[ay]])
        .filter(|p| p.iter().all(|c| c.is_finite()))
        .collect();
    basins::critical_shock(&v.image, &basins::Grid { x: &x, y: &y }, label, &points)
}

/// The rows of `attractors.csv`, value by value in the grid's order, with
/// the basin images of the first values.
pub fn attractor_rows<'a>(
    scene: &'a Scene,
    found: &'a Attractors,
    images: &'a [ValueBasins],
) -> impl Iterator<Item = Vec<String>> + 'a {
    let with_images = has_images(scene);
    let with_error = has_distribution(scene);
    let dim = scene.system.dimension();
    let events = scene.system.events.len();
    found
        .values
        .iter()
        .enumerate()
        .flat_map(move |(point, value)| {
            let at: Vec<String> = scene
                .sweep
                .values_at_point(point)
                .into_iter()
                .map(number)
                .collect();
            value.attractors.iter().map(move |a| {
                let lane = &a.first.lane;
                let mut row = at.clone();
                row.push(a.branch.map_or(String::new(), |b| b.to_string()));
                row.push(lane.orbit_period.map_or(String::new(), |p| p.to_string()));
                row.push(number(lane.impacts_per_period));
                row.extend(
                    lane.crossings_per_period[..events]
                        .iter()
                        .map(|&c| number(c)),
                );
                if scene.lyapunov {
                    row.extend(lane.exponents.iter().map(|&e| number(e)));
                    row.push(number(lane.exponent_sum()));
                    row.push(number(a.first.expected_sum));
                    row.push(number(lane.error));
                }
                // Of the starts that are motions (a basin image's box may
                // reach past a wall: those starts are no basin's).
                let starts = found.starts - value.inadmissible.len();
                let fraction = a.starts as f64 / starts as f64;
                row.push(number(fraction));
                row.push(a.starts.to_string());
                if with_images {
                    row.extend(basin_cells(scene, fraction, starts, images.get(point), a));
                } else if with_error {
                    row.push(number(basins::fraction_error(fraction, starts)));
                }
                let last = lane.orbit.len().saturating_sub(dim);
                match lane.orbit.get(last..).filter(|p| p.len() == dim) {
                    Some(point) => row.extend(point.iter().map(|&x| number(x))),
                    None => row.extend((0..dim).map(|_| String::new())),
                }
                row.push(lane.status.to_string());
                row
            })
        })
}

/// Writes `attractors.csv` into `dir`.
pub fn write_attractors(
    scene: &Scene,
    found: &Attractors,
    images: &[ValueBasins],
    dir: &Path,
) -> Result<()> {
    write_atomically(&dir.join(super::ATTRACTORS_FILE), |w| {
        w.write_record(attractors_header(scene))?;
        for row in attractor_rows(scene, found, images) {
            w.write_record(&row)?;
        }
        Ok(())
    })
}

/// Fills the `branch` column of the CSV file `path` (written with the
/// column empty): record r gets the branch of lane `lane_of[r]`, a
/// (grid point, start) pair.
pub fn fill_branches(
    path: &Path,
    found: &Attractors,
    lane_of: impl Iterator<Item = (usize, usize)>,
) -> Result<()> {
    let bad = |reason: String| Error::Results {
        path: path.to_owned(),
        reason,
    };
    let mut reader = csv::Reader::from_path(path).map_err(|e| bad(e.to_string()))?;
    let header = reader.headers().map_err(|e| bad(e.to_string()))?.clone();
    let column = header
        .iter()
        .position(|h| h == BRANCH_COLUMN)
        .ok_or_else(|| bad(format!("has no {BRANCH_COLUMN} column")))?;
    let mut lanes = lane_of;
    write_atomically(path, |w| {
        w.write_record(&header)?;
        for record in reader.records() {
            let record = record?;
            let (point, start) = lanes.next().expect("a lane for every row");
            let branch = found
                .branch_of(point, start)
                .map_or(String::new(), |b| b.to_string());
            w.write_record(record.iter().enumerate().map(|(k, field)| {
                if k == column {
                    branch.as_str()
                } else {
                    field
                }
            }))?;
        }
        Ok(())
    })
}
