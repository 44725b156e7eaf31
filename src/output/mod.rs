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
//! A run's files are one set (see [`set`]): written into a staging folder
//! beside the output folder, the rows streamed there batch by batch as the
//! lanes finish, and swapped in whole when complete, so the output folder
//! holds one run's files or the previous run's, never a mix.

pub mod attractor_table;
pub mod basin_files;
pub mod files;
pub mod merge;
pub mod orbit_table;
pub mod owned;
pub mod plot;
pub mod results;
pub mod set;

use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

use rayon::prelude::*;

use crate::attractor::{self, Attractors};
use crate::driver::orbits::OrbitRun;
use crate::driver::Report;
use crate::error::{Error, Result};
use crate::model::compiled::event_column;
use crate::scene::Scene;
use files::{number, write_text};
pub use files::{
    spectrum_file, ATTRACTORS_FILE, ATTRACTOR_MAP, BIFURCATIONS_FILE, BIFURCATION_FILE,
    BRANCH_COLUMN, ERROR_COLUMN, GRID_FILE, HEAT_MAP, ORBITS_FILE, SCENE_FILE, SHARD_FILE,
    SPECTRUM_FILE, SWEEP_FIGURE,
};
pub use set::Staging;

/// The header of `spectrum.csv` (`grid.csv`): the swept parameters, then
/// `lambda_1,...,lambda_N,lambda_sum,expected_sum,lambda_error,impacts_per_period`
/// (`lambda_error` the exponents' estimated error per unit time), for a
/// model one `<event>_per_period` column per event, then
/// `grazing,grazing_bound`, with `[attractors]` `start,branch`, then
/// `period,status`: `grazing` counts the averaging iterations re-estimated
/// near grazing and `grazing_bound` their estimated exponent error per unit
/// time, `start` is the lane's start among its value's (the scene's starts,
/// then the continuation seeds), `branch` the branch of the attractor it
/// ended on (empty for a lone failed lane), `period` its orbit's period in
/// map iterations (empty when aperiodic or longer than `max_period`).
pub fn spectrum_header(scene: &Scene) -> Vec<String> {
    let mut header: Vec<String> = scene.sweep.axes().map(|a| a.parameter.clone()).collect();
    header.extend((1..=scene.system.dimension()).map(|i| format!("lambda_{i}")));
    header.extend(
        [
            "lambda_sum",
            "expected_sum",
            ERROR_COLUMN,
            "impacts_per_period",
        ]
        .map(String::from),
    );
    header.extend(scene.system.events.iter().map(|e| event_column(e)));
    header.extend(["grazing", "grazing_bound"].map(String::from));
    if scene.sweep.starts.is_some() {
        header.extend([START_COLUMN, BRANCH_COLUMN].map(String::from));
    }
    header.extend([PERIOD_COLUMN, "status"].map(String::from));
    header
}

/// The column of a lane's start among its value's (with `[attractors]`).
pub const START_COLUMN: &str = "start";
/// The column of a lane orbit's period.
pub const PERIOD_COLUMN: &str = "period";

/// The header of `bifurcation.csv`: the swept parameters, then the state,
/// with `[attractors]` then the lane's start and branch.
pub fn bifurcation_header(scene: &Scene) -> Vec<String> {
    let mut header: Vec<String> = scene.sweep.axes().map(|a| a.parameter.clone()).collect();
    header.extend(scene.system.state_names.iter().map(|s| s.to_string()));
    if scene.sweep.starts.is_some() {
        header.extend([START_COLUMN, BRANCH_COLUMN].map(String::from));
    }
    header
}

/// Writes a run's set: `scene.toml` first, then the rows of each batch of
/// lanes as it finishes ([`append`](Self::append)), then with many starts
/// `attractors.csv` and the rows' branches, with `[orbits]` `orbits.csv`
/// and `bifurcations.csv` ([`set_orbits`](Self::set_orbits)), `shard.toml`
/// or the figures,
/// and the swap ([`finish`](Self::finish)).
pub struct SetWriter {
    staging: Staging,
    scene: Scene,
    spectrum: Option<fs::File>,
    bifurcation: Option<fs::File>,
    /// Rows of `bifurcation.csv` per lane so far (a shard lists them).
    bifurcation_rows: Vec<usize>,
    /// With `[attractors]`, each lane's (grid point, start) so far, in the
    /// order of its rows: their branches are filled in at the end.
    lanes: Vec<(u32, u32)>,
    /// λ1 of each row so far, for the heat map of a grid of one lane a
    /// point (8 bytes a lane, as reading it back would hold).
    lambda1: Option<Vec<f64>>,
    /// With `[orbits]`, the branches traced after the lanes.
    orbits: Option<OrbitRun>,
}

fn write_error(path: &Path) -> impl Fn(std::io::Error) -> Error + '_ {
    move |source| Error::Write {
        path: path.to_owned(),
        source,
    }
}

impl SetWriter {
    /// Starts the set of `scene` in `staging`.
    pub fn new(scene: &Scene, staging: Staging) -> Result<SetWriter> {
        set::pause(SCENE_FILE);
        write_text(&staging.dir().join(SCENE_FILE), &scene.source)?;
        let open = |name: &str, header: Vec<String>| -> Result<fs::File> {
            set::pause(name);
            let path = staging.dir().join(name);
            let mut file = fs::File::create(&path).map_err(write_error(&path))?;
            write_rows(&mut file, 1, |_| [header.clone()]).map_err(write_error(&path))?;
            Ok(file)
        };
        let spectrum = scene
            .lyapunov
            .then(|| open(spectrum_file(scene), spectrum_header(scene)))
            .transpose()?;
        let bifurcation = (scene.bifurcation_points > 0)
            .then(|| open(BIFURCATION_FILE, bifurcation_header(scene)))
            .transpose()?;
        Ok(SetWriter {
            staging,
            scene: scene.clone(),
            spectrum,
            bifurcation,
            bifurcation_rows: Vec::new(),
            lanes: Vec::new(),
            lambda1: (scene.plot
                && scene.shard.is_none()
                && scene.lyapunov
                && scene.sweep.second.is_some()
                && scene.sweep.starts.is_none())
            .then(Vec::new),
            orbits: None,
        })
    }

    /// The branches of `[orbits]`, written as `orbits.csv` and
    /// `bifurcations.csv` when the set is completed.
    pub fn set_orbits(&mut self, run: OrbitRun) {
        self.orbits = Some(run);
    }

    /// Appends the rows of one batch: `batch` is the scene restricted to
    /// the batch's lanes (see `Scene::batch`), `report` its results.
    pub fn append(&mut self, batch: &Scene, report: &Report) -> Result<()> {
        let dir = self.staging.dir().to_owned();
        let lanes = report.lanes.len();
        if let Some(w) = &mut self.spectrum {
            let path = dir.join(spectrum_file(batch));
            write_rows(w, lanes, |j| [spectrum_row(batch, report, j)])
                .map_err(write_error(&path))?;
        }
        if let Some(lambda1) = &mut self.lambda1 {
            lambda1.extend(report.lanes.iter().map(|lane| lane.exponents[0]));
        }
        if batch.sweep.starts.is_some() {
            self.lanes.extend((0..lanes).map(|j| {
                let point = batch.sweep.point_of(batch.sweep_lane(j));
                (point as u32, batch.lane_start(j) as u32)
            }));
        }
        let dim = batch.system.dimension();
        self.bifurcation_rows
            .extend(report.lanes.iter().map(|lane| lane.bifurcation.len() / dim));
        if let Some(w) = &mut self.bifurcation {
            let path = dir.join(BIFURCATION_FILE);
            write_rows(w, lanes, |j| bifurcation_rows(batch, report, j))
                .map_err(write_error(&path))?;
        }
        Ok(())
    }

    /// Completes the set (with many starts `attractors.csv` and the rows'
    /// branches from `attractors`; shard.toml for a shard, the figures
    /// otherwise) and swaps it into the output folder; returns the paths
    /// written there.
    pub fn finish(self, attractors: Option<&Attractors>) -> Result<Vec<PathBuf>> {
        self.complete(attractors)?.commit()
    }

    /// [`finish`](Self::finish) up to the swap: the staged set, complete,
    /// for a caller that may still decide against it (a stop requested
    /// while the files were written).
    pub fn complete(self, attractors: Option<&Attractors>) -> Result<Staging> {
        let dir = self.staging.dir().to_owned();
        for (writer, name) in [
            (self.spectrum, spectrum_file(&self.scene)),
            (self.bifurcation, BIFURCATION_FILE),
        ] {
            if let Some(file) = writer {
                let path = dir.join(name);
                file.sync_all().map_err(write_error(&path))?;
            }
        }
        let scene = &self.scene;
        if let Some(found) = attractors {
            let basins = basin_files::value_basins(scene, found);
            set::pause(ATTRACTORS_FILE);
            attractor_table::write_attractors(scene, found, &basins, &dir)?;
            basin_files::write_labels(&basins, &dir)?;
            if scene.plot && scene.shard.is_none() {
                basin_files::draw(scene, found, &basins, &dir)?;
            }
            let lanes = || self.lanes.iter().map(|&(g, s)| (g as usize, s as usize));
            if scene.lyapunov {
                attractor_table::fill_branches(&dir.join(spectrum_file(scene)), found, lanes())?;
            }
            if scene.bifurcation_points > 0 {
                let rows = self.bifurcation_rows.iter();
                let per_row = lanes()
                    .zip(rows)
                    .flat_map(|(lane, &n)| std::iter::repeat_n(lane, n));
                attractor_table::fill_branches(&dir.join(BIFURCATION_FILE), found, per_row)?;
            }
        }
        if let Some(run) = &self.orbits {
            orbit_table::write_orbits(scene, run, &dir)?;
        }
        if let Some(shard) = scene.shard {
            let rows: Vec<String> = self
                .bifurcation_rows
                .iter()
                .map(|n| n.to_string())
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
            set::pause(SHARD_FILE);
            write_text(&dir.join(SHARD_FILE), &text)?;
        } else if scene.plot {
            set::pause("figures");
            results::draw_with(&dir, &dir, self.lambda1)?;
        }
        Ok(self.staging)
    }
}

/// Writes the whole set of one report into `dir` (a run in one batch,
/// its attractors told apart from its own lanes, without continuation; the
/// command streams batches through [`SetWriter`] itself); returns the paths.
pub fn write(scene: &Scene, report: &Report, dir: &Path) -> Result<Vec<PathBuf>> {
    let mut writer = SetWriter::new(scene, Staging::prepare(dir, &scene.files)?)?;
    writer.append(scene, report)?;
    let found = attractor::found_in(
        scene,
        &report.lanes,
        &report.expected_sums,
        report.precision,
    );
    writer.finish(found.as_ref())
}

/// Lanes whose rows one thread formats at a time.
const LANES_PER_TASK: usize = 2048;

/// Appends the CSV records of lanes `0..lanes` (`rows(j)`: lane j's) to
/// `file`, in order. Pieces of lanes are formatted over the host's cores,
/// a few per core at a time, then written: at a million lanes the numbers'
/// formatting would otherwise be a serial step of seconds, and formatting
/// all of them first would hold the whole file's text. Each piece is what
/// a `csv::Writer` of the default settings writes.
fn write_rows<R>(
    file: &mut fs::File,
    lanes: usize,
    rows: impl Fn(usize) -> R + Sync,
) -> std::io::Result<()>
where
    R: IntoIterator<Item = Vec<String>>,
{
    let tasks = lanes.div_ceil(LANES_PER_TASK);
    let at_once = 4 * rayon::current_num_threads();
    for group in (0..tasks).step_by(at_once) {
        let pieces: Vec<Vec<u8>> = (group..tasks.min(group + at_once))
            .into_par_iter()
            .map(|task| {
                let mut w = csv::Writer::from_writer(Vec::new());
                let first = task * LANES_PER_TASK;
                for j in first..lanes.min(first + LANES_PER_TASK) {
                    for row in rows(j) {
                        w.write_record(&row).expect("a record goes into memory");
                    }
                }
                w.into_inner().expect("a record goes into memory")
            })
            .collect();
        pieces.iter().try_for_each(|piece| file.write_all(piece))?;
    }
    Ok(())
}

/// The `spectrum.csv` row of the run's lane `j`.
fn spectrum_row(scene: &Scene, report: &Report, j: usize) -> Vec<String> {
    let lane = &report.lanes[j];
    let mut row: Vec<String> = scene.lane_values(j).into_iter().map(number).collect();
    row.extend(lane.exponents.iter().map(|&e| number(e)));
    row.push(number(lane.exponent_sum()));
    row.push(number(report.expected_sums[j]));
    row.push(number(lane.error));
    row.push(number(lane.impacts_per_period));
    let events = scene.system.events.len();
    row.extend(
        lane.crossings_per_period[..events]
            .iter()
            .map(|&c| number(c)),
    );
    row.push(lane.grazing.to_string());
    row.push(number(lane.grazing_bound));
    if scene.sweep.starts.is_some() {
        // The branch is filled in when the set is finished.
        row.extend([scene.lane_start(j).to_string(), String::new()]);
    }
    row.push(lane.orbit_period.map_or(String::new(), |p| p.to_string()));
    row.push(lane.status.to_string());
    row
}

/// The `bifurcation.csv` rows of the run's lane `j`.
fn bifurcation_rows(scene: &Scene, report: &Report, j: usize) -> Vec<Vec<String>> {
    let parameters: Vec<String> = scene.lane_values(j).into_iter().map(number).collect();
    // The branch is filled in when the set is finished.
    let start = scene
        .sweep
        .starts
        .is_some()
        .then(|| [scene.lane_start(j).to_string(), String::new()]);
    report.lanes[j]
        .bifurcation
        .chunks_exact(scene.system.dimension())
        .map(|point| {
            let mut row = parameters.clone();
            row.extend(point.iter().map(|&x| number(x)));
            row.extend(start.clone().into_iter().flatten());
            row
        })
        .collect()
}
