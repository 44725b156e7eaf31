//! A results folder read back: the scene that produced it and its CSV
//! files. The figures are always drawn from these files, after a run as by
//! `lyapsweep plot DIR`, so a redrawn figure is the figure of the run.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::files::{
    spectrum_file, ATTRACTORS_FILE, ATTRACTOR_MAP, BIFURCATION_FILE, BRANCH_COLUMN, HEAT_MAP,
    ORBITS_FILE, ORBIT_FIGURE, ORBIT_MAP, SCENE_FILE, SWEEP_FIGURE,
};
use super::plot::{self, AttractorSweepData, Branch, CountData, GridData, SweepData};
use crate::error::{Error, Result};
use crate::scene::{self, Axis, Scene};

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
        .map(|(row, r)| cell(path, r, row, k))
        .collect()
}

/// Column `k` of `record`, the file's record number `row` (from 0, after
/// the header), as a number.
fn cell(path: &Path, record: &csv::StringRecord, row: usize, k: usize) -> Result<f64> {
    record
        .get(k)
        .and_then(|t| t.parse::<f64>().ok())
        .ok_or_else(|| Error::Results {
            path: path.to_owned(),
            reason: format!("row {}: column {} is not a number", row + 2, k + 1),
        })
}

/// `lyapsweep plot DIR --out INTO`: checks that `dir` holds one complete
/// set (`set::verify`) and draws its figures into `into`; a folder this
/// call created is removed again when drawing fails.
pub fn redraw(dir: &Path, into: &Path) -> Result<Vec<PathBuf>> {
    super::set::verify(dir)?;
    // The set's own figures are redrawn in place; elsewhere the figures go
    // only where they replace no file but lyapsweep's own (`owned`), and
    // never into a folder of the set, which holds only the set's files.
    // All found before drawing: creating the folder would fail only after
    // the figures were drawn, as a failed write.
    let own = into.canonicalize().ok() == dir.canonicalize().ok();
    if !own {
        if super::owned::is_within(into, dir) {
            return Err(Error::Output {
                path: into.to_owned(),
                reason: format!(
                    "is inside the output set {}, which holds only the files a run writes (a later run would refuse the set): give --out a folder outside it, or leave --out out to redraw the set's own figures",
                    dir.display()
                ),
            });
        }
        let names: Vec<String> = super::set::FIGURE_STEMS
            .iter()
            .flat_map(|stem| [format!("{stem}.png"), format!("{stem}.svg")])
            .collect();
        super::owned::check(into, &names.iter().map(String::as_str).collect::<Vec<_>>())?;
    }
    let created = !into.exists();
    let result = draw(dir, into);
    match &result {
        Err(_) if created => {
            let _ = std::fs::remove_dir_all(into);
        }
        Ok(written) if !own => super::owned::record(into, written)?,
        _ => {}
    }
    result
}

/// Draws the figures of the results in `dir` into the folder `into`;
/// returns their paths. One parameter: the sweep figure; two: the heat map
/// of λ1. With many starts per value and their `attractors.csv`, the sweep
/// figure shows each attractor on its branch, with its basin, and a grid
/// adds the map of the attractors per point.
pub fn draw(dir: &Path, into: &Path) -> Result<Vec<PathBuf>> {
    draw_with(dir, into, None)
}

/// [`draw`], with the λ1 of a grid of one lane a point given by the run that
/// wrote its `grid.csv` (the numbers the file holds; reading a million-lane
/// grid's back takes 0.4 s).
pub fn draw_with(dir: &Path, into: &Path, lambda1: Option<Vec<f64>>) -> Result<Vec<PathBuf>> {
    let scene = scene_of(dir)?;
    std::fs::create_dir_all(into).map_err(|source| Error::Write {
        path: into.to_owned(),
        source,
    })?;
    let attractors = if scene.sweep.starts.is_some() && dir.join(ATTRACTORS_FILE).exists() {
        Some(read_attractors(dir, &scene)?)
    } else {
        None
    };
    let mut written = match (&scene.sweep.second, attractors) {
        (Some(second), attractors) => {
            draw_grid(dir, into, &scene, second, attractors.as_deref(), lambda1)
        }
        (None, Some(attractors)) => {
            let data = attractor_sweep(dir, &scene, &attractors)?;
            plot::attractor_figure(&data, into, SWEEP_FIGURE)
        }
        (None, None) => draw_sweep(dir, into, &scene),
    }?;
    if scene.orbits.is_some() && scene.sweep.second.is_none() && dir.join(ORBITS_FILE).exists() {
        let data = super::orbit_table::figure_data(dir, &scene)?;
        written.extend(plot::orbit_figure(&data, into, ORBIT_FIGURE)?);
    }
    Ok(written)
}

/// The sweep figure of one parameter, one lane per value (or many starts
/// without their `attractors.csv`: every lane's exponents).
fn draw_sweep(dir: &Path, into: &Path, scene: &Scene) -> Result<Vec<PathBuf>> {
    let axes = scene.sweep.axes().count();
    let dim = scene.system.dimension();
    let spectrum_path = dir.join(spectrum_file(scene));
    let spectrum = scene
        .lyapunov
        .then(|| read_csv(dir, spectrum_file(scene)))
        .transpose()?;
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
        per_unit_time: scene.system.is_flow,
        bifurcation,
        state_name: scene.system.state_names[0].to_owned(),
    };
    plot::sweep_figure(&data, into, SWEEP_FIGURE)
}

/// The figures of two parameters (`second` the scene's second axis): the
/// heat map of λ1 where there are exponents, with `attractors` (the rows
/// of `attractors.csv`) the map of the attractors per point, and with
/// `orbits.csv` the bifurcations over the map of λ1.
fn draw_grid(
    dir: &Path,
    into: &Path,
    scene: &Scene,
    second: &Axis,
    attractors: Option<&[Attractor]>,
    lambda1: Option<Vec<f64>>,
) -> Result<Vec<PathBuf>> {
    let (x_name, y_name) = (&scene.sweep.first.parameter, &second.parameter);
    let (x, y) = (&scene.sweep.first.values, &second.values);
    let mut written = Vec::new();
    let orbits = scene.orbits.is_some() && dir.join(ORBITS_FILE).exists();
    if scene.lyapunov || orbits {
        let (title, lambda1) = match attractors {
            _ if !scene.lyapunov => (
                format!("{} (no exponents computed)", scene.name),
                vec![0.0; x.len() * y.len()],
            ),
            Some(attractors) => {
                let lambda1 = attractors.iter().map(|a| {
                    let lambda1 = a.exponents.first().copied().unwrap_or(f64::NAN);
                    (a.at.as_slice(), lambda1)
                });
                (
                    format!("{}: the largest λ₁ of each point's attractors", scene.name),
                    largest_per_point(scene, &dir.join(ATTRACTORS_FILE), lambda1)?,
                )
            }
            None => (
                scene.name.clone(),
                lambda1.map_or_else(|| lambda1_per_point(dir, scene), Ok)?,
            ),
        };
        let data = GridData {
            title,
            x_name: x_name.clone(),
            y_name: y_name.clone(),
            x: x.clone(),
            y: y.clone(),
            lambda1,
            per_unit_time: scene.system.is_flow,
        };
        if scene.lyapunov {
            written.extend(plot::heat_map(&data, into, HEAT_MAP)?);
        }
        if orbits {
            let map = super::orbit_table::map_data(dir, scene, data)?;
            written.extend(plot::orbit_map(&map, into, ORBIT_MAP)?);
        }
    }
    if let Some(attractors) = attractors {
        let data = CountData {
            title: format!("{}: attractors per point", scene.name),
            x_name: x_name.clone(),
            y_name: y_name.clone(),
            x: x.clone(),
            y: y.clone(),
            counts: attractors_per_point(scene, &dir.join(ATTRACTORS_FILE), attractors)?,
        };
        written.extend(plot::attractor_map(&data, into, ATTRACTOR_MAP)?);
    }
    Ok(written)
}

/// λ1 at each grid point from `grid.csv` (first axis fastest). One lane per
/// point: its rows in the sweep's order. Many starts (without
/// `attractors.csv`): the largest λ1 of the point's lanes.
fn lambda1_per_point(dir: &Path, scene: &Scene) -> Result<Vec<f64>> {
    if scene.sweep.starts.is_none() {
        return lambda1_of_grid(&dir.join(spectrum_file(scene)), scene);
    }
    // Many starts a point: the largest λ₁ of its lanes.
    let table = Table::read(dir, spectrum_file(scene))?;
    let names: Vec<&str> = scene.sweep.axes().map(|a| a.parameter.as_str()).collect();
    let lambda1 = table.column("lambda_1")?;
    let lanes = (0..table.records.len())
        .map(|row| {
            let at = table.numbers(row, &names)?;
            Ok((at, table.number(row, lambda1)?))
        })
        .collect::<Result<Vec<_>>>()?;
    let at = lanes.iter().map(|(at, l)| (at.as_slice(), *l));
    largest_per_point(scene, &table.path, at)
}

/// λ₁ of each grid point, one lane a point: the column after the swept
/// values, read a record at a time, so that drawing a million-lane map
/// holds its numbers (8 bytes a point), not the file's text.
fn lambda1_of_grid(path: &Path, scene: &Scene) -> Result<Vec<f64>> {
    let bad = |reason: String| Error::Results {
        path: path.to_owned(),
        reason,
    };
    let k = scene.sweep.axes().count();
    let mut reader = csv::Reader::from_path(path).map_err(|e| bad(e.to_string()))?;
    let mut record = csv::StringRecord::new();
    let mut lambda1 = Vec::with_capacity(scene.sweep.points());
    while reader
        .read_record(&mut record)
        .map_err(|e| bad(e.to_string()))?
    {
        lambda1.push(cell(path, &record, lambda1.len(), k)?);
    }
    let points = scene.sweep.points();
    if lambda1.len() != points {
        return Err(bad(format!(
            "{} rows for a {} × {} grid",
            lambda1.len(),
            scene.sweep.first.values.len(),
            points / scene.sweep.first.values.len().max(1)
        )));
    }
    Ok(lambda1)
}

/// One row of `attractors.csv` that names an attractor (the rows of failed
/// lanes, without a branch, are left out).
#[derive(Clone, Debug, PartialEq)]
pub struct Attractor {
    /// The swept values, one per axis.
    pub at: Vec<f64>,
    /// The branch: the attractor followed across the values.
    pub branch: u64,
    /// λ₁ … λ_N; empty when the run computed no exponents.
    pub exponents: Vec<f64>,
    /// The fraction of the value's starts that end on it.
    pub basin_fraction: f64,
}

/// The attractors of `attractors.csv` in `dir`, in the file's order (which
/// is not the values' order: lanes continued from a neighbour come after
/// the sweep's own).
pub fn read_attractors(dir: &Path, scene: &Scene) -> Result<Vec<Attractor>> {
    let table = Table::read(dir, ATTRACTORS_FILE)?;
    let names: Vec<&str> = scene.sweep.axes().map(|a| a.parameter.as_str()).collect();
    let branch = table.column(BRANCH_COLUMN)?;
    let basin = table.column("basin_fraction")?;
    let lambdas: Vec<String> = if scene.lyapunov {
        (1..=scene.system.dimension())
            .map(|i| format!("lambda_{i}"))
            .collect()
    } else {
        Vec::new()
    };
    let lambdas: Vec<&str> = lambdas.iter().map(String::as_str).collect();
    let mut attractors = Vec::new();
    for row in 0..table.records.len() {
        let Some(id) = table.whole(row, branch)? else {
            continue;
        };
        attractors.push(Attractor {
            at: table.numbers(row, &names)?,
            branch: id,
            exponents: table.numbers(row, &lambdas)?,
            basin_fraction: table.number(row, basin)?,
        });
    }
    Ok(attractors)
}

/// The figure's data of a one-parameter sweep with attractors: the
/// bifurcation points with their lanes' branches, and each branch's
/// attractors in the order of their values.
pub fn attractor_sweep(
    dir: &Path,
    scene: &Scene,
    attractors: &[Attractor],
) -> Result<AttractorSweepData> {
    let bifurcation = if scene.bifurcation_points > 0 {
        let table = Table::read(dir, BIFURCATION_FILE)?;
        let at = table.column(&scene.sweep.first.parameter)?;
        let state = table.column(scene.system.state_names[0])?;
        let branch = table.column(BRANCH_COLUMN)?;
        (0..table.records.len())
            .map(|row| {
                let point = (table.number(row, at)?, table.number(row, state)?);
                Ok((point.0, point.1, table.whole(row, branch)?))
            })
            .collect::<Result<_>>()?
    } else {
        Vec::new()
    };
    let mut by_branch: BTreeMap<u64, Vec<&Attractor>> = BTreeMap::new();
    for a in attractors {
        by_branch.entry(a.branch).or_default().push(a);
    }
    let branches = by_branch
        .into_iter()
        .map(|(id, mut rows)| {
            rows.sort_by(|a, b| a.at[0].total_cmp(&b.at[0]));
            Branch {
                id,
                values: rows.iter().map(|a| a.at[0]).collect(),
                exponents: rows.iter().map(|a| a.exponents.clone()).collect(),
                basin: rows.iter().map(|a| a.basin_fraction).collect(),
            }
        })
        .collect();
    Ok(AttractorSweepData {
        title: scene.name.clone(),
        parameter: scene.sweep.first.parameter.clone(),
        values: scene.sweep.first.values.clone(),
        bifurcation,
        branches,
        per_unit_time: scene.system.is_flow,
        state_name: scene.system.state_names[0].to_owned(),
    })
}

/// The number of attractors at each grid point (first axis fastest).
/// `path` names the file they were read from, for errors.
pub fn attractors_per_point(
    scene: &Scene,
    path: &Path,
    attractors: &[Attractor],
) -> Result<Vec<usize>> {
    let mut counts = vec![0; scene.sweep.points()];
    for a in attractors {
        counts[grid_point(scene, path, &a.at)?] += 1;
    }
    Ok(counts)
}

/// The largest of the values given at each grid point (first axis
/// fastest), NaN where none is a number. `path` names the file they were
/// read from, for errors.
fn largest_per_point<'a>(
    scene: &Scene,
    path: &Path,
    values: impl Iterator<Item = (&'a [f64], f64)>,
) -> Result<Vec<f64>> {
    let mut largest = vec![f64::NAN; scene.sweep.points()];
    for (at, value) in values {
        let k = grid_point(scene, path, at)?;
        // f64::max keeps the number of a number and NaN.
        largest[k] = largest[k].max(value);
    }
    Ok(largest)
}

/// The index of the grid point at the swept values `at` (first axis
/// fastest). The files hold the values as the shortest text that reads
/// back to the same number, so they match the scene's exactly.
fn grid_point(scene: &Scene, path: &Path, at: &[f64]) -> Result<usize> {
    let mut index = 0;
    let mut stride = 1;
    for (axis, &value) in scene.sweep.axes().zip(at) {
        let Some(i) = axis.values.iter().position(|&v| v == value) else {
            return Err(Error::Results {
                path: path.to_owned(),
                reason: format!("{} = {value} is not a value of the sweep", axis.parameter),
            });
        };
        index += i * stride;
        stride *= axis.values.len();
    }
    Ok(index)
}

/// A CSV file of a results folder, its columns found by their names.
struct Table {
    path: PathBuf,
    header: csv::StringRecord,
    records: Vec<csv::StringRecord>,
}

impl Table {
    fn read(dir: &Path, name: &str) -> Result<Table> {
        let (header, records) = read_csv(dir, name)?;
        Ok(Table {
            path: dir.join(name),
            header,
            records,
        })
    }

    fn bad(&self, reason: String) -> Error {
        Error::Results {
            path: self.path.clone(),
            reason,
        }
    }

    /// The index of the column `name`.
    fn column(&self, name: &str) -> Result<usize> {
        self.header
            .iter()
            .position(|h| h == name)
            .ok_or_else(|| self.bad(format!("has no column `{name}`")))
    }

    /// The text of `column` in `row`.
    fn text(&self, row: usize, column: usize) -> &str {
        self.records[row].get(column).unwrap_or("")
    }

    /// `column` of `row` as a number ("NaN" and "inf" included).
    fn number(&self, row: usize, column: usize) -> Result<f64> {
        self.text(row, column).parse().map_err(|_| {
            // Row 1 is the header.
            let name = &self.header[column];
            self.bad(format!("row {}: `{name}` is not a number", row + 2))
        })
    }

    /// The columns `names` of `row`, as numbers.
    fn numbers(&self, row: usize, names: &[&str]) -> Result<Vec<f64>> {
        names
            .iter()
            .map(|name| self.number(row, self.column(name)?))
            .collect()
    }

    /// `column` of `row` as a whole number, `None` when empty.
    fn whole(&self, row: usize, column: usize) -> Result<Option<u64>> {
        match self.text(row, column) {
            "" => Ok(None),
            text => text.parse().map(Some).map_err(|_| {
                let name = &self.header[column];
                self.bad(format!("row {}: `{name}` is not a whole number", row + 2))
            }),
        }
    }
}

#[cfg(test)]
mod tests {
    use std::fs;

    use super::*;
    use crate::output::attractor_table::attractors_header;
    use crate::output::files::GRID_FILE;
    use crate::output::plot::{attractor_pixels, ATTRACTOR_SWEEP_SIZE, HEAT_MAP_SIZE};
    use crate::output::spectrum_header;

    /// The seed's oscillator with a 2 × 2 grid of starts per value: the
    /// scene of the folders below after their sweep's table.
    const SCENE: &str = r#"
[system]
kind = "impact-oscillator"
zeta = 0.05
f = 1.0
wall = 2.0
restitution = 1.0
[integration]
steps_per_period = 1800
transient = 300
iterations = 300
initial_state = [0.0, 0.0]
[output]
bifurcation_points = 2
[attractors]
grid = [2, 2]
box = { x = [-3, 1.9], v = [-3, 3] }
"#;

    const ONE_PARAMETER: &str = "[sweep]\nparameter = \"eta\"\nvalues = [0.6, 0.7, 0.8]\n";
    const TWO_PARAMETERS: &str = "[sweep]\nparameter = \"eta\"\nvalues = [0.6, 0.7]\n\
                                  [sweep.second]\nparameter = \"f\"\nvalues = [1.0, 2.0]\n";

    /// A results folder holding the scene `sweep` + `SCENE` (`edit`ed), and
    /// the scene read back from it.
    fn folder(sweep: &str, edit: impl Fn(String) -> String) -> (tempfile::TempDir, Scene) {
        let dir = tempfile::tempdir().unwrap();
        fs::write(dir.path().join(SCENE_FILE), edit(format!("{sweep}{SCENE}"))).unwrap();
        let scene = scene_of(dir.path()).unwrap();
        (dir, scene)
    }

    /// Writes the CSV file `name` with `header`, each row given as
    /// (column, text) pairs: the columns a row leaves out are empty, so the
    /// rows hold what the figures read whatever else the file has.
    fn write_csv(dir: &Path, name: &str, header: &[String], rows: &[Vec<(&str, String)>]) {
        let mut lines = vec![header.join(",")];
        for row in rows {
            let fields: Vec<&str> = header
                .iter()
                .map(|h| row.iter().find(|(c, _)| c == h).map_or("", |(_, t)| t))
                .collect();
            lines.push(fields.join(","));
        }
        fs::write(dir.join(name), lines.join("\n") + "\n").unwrap();
    }

    /// An `attractors.csv` row at `at` (the swept values), on `branch`
    /// ("" for a failed lane), with λ1 and λ2 and its basin fraction.
    fn attractor<'a>(
        at: &[(&'a str, f64)],
        branch: &str,
        [l1, l2]: [f64; 2],
        basin: f64,
    ) -> Vec<(&'a str, String)> {
        let mut row: Vec<(&str, String)> = at.iter().map(|&(p, v)| (p, v.to_string())).collect();
        let status = if branch.is_empty() {
            "chattering(iterations=3)"
        } else {
            "ok"
        };
        row.extend([
            ("branch", branch.to_owned()),
            ("lambda_1", l1.to_string()),
            ("lambda_2", l2.to_string()),
            ("lambda_sum", (l1 + l2).to_string()),
            ("expected_sum", "-0.1".to_owned()),
            ("basin_fraction", basin.to_string()),
            ("starts", "4".to_owned()),
            ("status", status.to_owned()),
        ]);
        row
    }

    fn png_size(path: &Path) -> (u32, u32) {
        let decoder = png::Decoder::new(fs::File::open(path).unwrap());
        let info = decoder.read_info().unwrap().info().clone();
        (info.width, info.height)
    }

    /// Two attractors at η = 0.6 and 0.7 (branch 1 continued to 0.7 after
    /// the sweep's own rows, as continuation lanes are), one at 0.8, and a
    /// failed lane at 0.7: each branch's attractors come out in the order
    /// of their values with their exponents and basins, the failed lane's
    /// bifurcation points without a branch, and the figure has a colour per
    /// branch and grey.
    #[test]
    fn one_parameter_attractors_come_out_per_branch_in_value_order() {
        let (dir, scene) = folder(ONE_PARAMETER, |s| s);
        let eta = |v| [("eta", v)];
        let nan = [f64::NAN; 2];
        let rows = [
            attractor(&eta(0.8), "0", [-0.05, -0.05], 1.0),
            attractor(&eta(0.6), "0", [-0.05, -0.05], 0.75),
            attractor(&eta(0.6), "1", [-0.02, -0.08], 0.25),
            attractor(&eta(0.7), "0", [-0.05, -0.05], 0.5),
            attractor(&eta(0.7), "", nan, 0.25),
            attractor(&eta(0.7), "1", [-0.03, -0.07], 0.25),
        ];
        write_csv(
            dir.path(),
            ATTRACTORS_FILE,
            &attractors_header(&scene),
            &rows,
        );
        let header = ["eta", "x", "v", "start", "branch"].map(String::from);
        let points = [
            (0.6, 0.5, "0"),
            (0.6, 1.5, "1"),
            (0.7, 0.4, ""),
            (0.7, 1.4, "1"),
            (0.8, 0.6, "0"),
        ];
        let points: Vec<_> = points
            .iter()
            .map(|&(eta, x, branch)| {
                let (eta, x) = (eta.to_string(), x.to_string());
                vec![
                    ("eta", eta),
                    ("x", x),
                    ("v", "0".into()),
                    ("branch", branch.into()),
                ]
            })
            .collect();
        write_csv(dir.path(), BIFURCATION_FILE, &header, &points);

        let attractors = read_attractors(dir.path(), &scene).unwrap();
        assert_eq!(attractors.len(), 5, "the failed lane's row has no branch");
        let data = attractor_sweep(dir.path(), &scene, &attractors).unwrap();
        let expected = [
            Branch {
                id: 0,
                values: vec![0.6, 0.7, 0.8],
                exponents: vec![vec![-0.05, -0.05]; 3],
                basin: vec![0.75, 0.5, 1.0],
            },
            Branch {
                id: 1,
                values: vec![0.6, 0.7],
                exponents: vec![vec![-0.02, -0.08], vec![-0.03, -0.07]],
                basin: vec![0.25, 0.25],
            },
        ];
        assert_eq!(data.branches, expected);
        assert_eq!(data.values, [0.6, 0.7, 0.8]);
        assert_eq!(
            data.bifurcation,
            [
                (0.6, 0.5, Some(0)),
                (0.6, 1.5, Some(1)),
                (0.7, 0.4, None),
                (0.7, 1.4, Some(1)),
                (0.8, 0.6, Some(0)),
            ]
        );

        // One pixel per point in the diagram's plotting area (below its
        // frame's top edge, right of its left one, above the next panel):
        // two of branch 0 in dark blue, two of branch 1 in vermillion, the
        // failed lane's in grey.
        let pixels = attractor_pixels(&data);
        let (width, height) = (
            ATTRACTOR_SWEEP_SIZE.0 as usize,
            ATTRACTOR_SWEEP_SIZE.1 as usize,
        );
        let pixel = |row: usize, column: usize| {
            let k = 3 * (row * width + column);
            [pixels[k], pixels[k + 1], pixels[k + 2]]
        };
        let frame = (0..height).find(|&row| pixel(row, 300) == [0; 3]).unwrap();
        let count = |rgb: [u8; 3]| {
            let area = (frame + 1..height / 3).flat_map(|row| (155..width).map(move |c| (row, c)));
            area.filter(|&(row, column)| pixel(row, column) == rgb)
                .count()
        };
        let colours = [[16, 52, 166], [213, 94, 0], [150, 150, 150]];
        assert_eq!(colours.map(count), [2, 2, 1]);

        let into = dir.path().join("figures");
        let written = draw(dir.path(), &into).unwrap();
        assert_eq!(written, [into.join("figure.png"), into.join("figure.svg")]);
        assert_eq!(png_size(&written[0]), ATTRACTOR_SWEEP_SIZE);
    }

    /// Without exponents the file has no λ columns: the attractors are read
    /// with their basins alone, and the figure drawn without its exponent
    /// panel.
    #[test]
    fn attractors_without_exponents_keep_their_basins() {
        let (dir, scene) = folder(ONE_PARAMETER, |s| {
            s.replace("[output]\n", "[output]\nlyapunov = \"none\"\n")
        });
        let header = attractors_header(&scene);
        assert!(!header.contains(&"lambda_1".to_owned()));
        let rows = [
            attractor(&[("eta", 0.6)], "0", [0.0; 2], 0.75),
            attractor(&[("eta", 0.6)], "1", [0.0; 2], 0.25),
        ];
        write_csv(dir.path(), ATTRACTORS_FILE, &header, &rows);
        let header = ["eta", "x", "v", "start", "branch"].map(String::from);
        let point = |x: &str, branch: &str| {
            let eta = ("eta", "0.6".to_owned());
            vec![
                eta,
                ("x", x.to_owned()),
                ("v", "0".into()),
                ("branch", branch.into()),
            ]
        };
        let points = [point("0.5", "0"), point("1.5", "1")];
        write_csv(dir.path(), BIFURCATION_FILE, &header, &points);

        let attractors = read_attractors(dir.path(), &scene).unwrap();
        let basins: Vec<(u64, f64)> = attractors
            .iter()
            .map(|a| (a.branch, a.basin_fraction))
            .collect();
        assert_eq!(basins, [(0, 0.75), (1, 0.25)]);
        assert!(attractors.iter().all(|a| a.exponents.is_empty()));
        let written = draw(dir.path(), &dir.path().join("figures")).unwrap();
        assert_eq!(png_size(&written[0]), ATTRACTOR_SWEEP_SIZE);
    }

    /// A 2 × 2 grid of (η, f): the attractors per point counted whatever
    /// the rows' order, the failed lane's row not counted, and λ1's map the
    /// largest λ1 of each point's attractors; both maps drawn.
    #[test]
    fn two_parameters_count_attractors_per_point() {
        let (dir, scene) = folder(TWO_PARAMETERS, |s| s);
        let at = |eta, f| [("eta", eta), ("f", f)];
        let rows = [
            attractor(&at(0.7, 2.0), "2", [-0.01, -0.09], 0.25),
            attractor(&at(0.6, 1.0), "0", [-0.05, -0.05], 0.5),
            attractor(&at(0.6, 1.0), "1", [-0.02, -0.08], 0.5),
            attractor(&at(0.7, 1.0), "0", [-0.05, -0.05], 1.0),
            attractor(&at(0.6, 2.0), "", [f64::NAN; 2], 1.0),
            attractor(&at(0.7, 2.0), "0", [-0.05, -0.05], 0.5),
            attractor(&at(0.7, 2.0), "1", [0.04, -0.14], 0.25),
        ];
        write_csv(
            dir.path(),
            ATTRACTORS_FILE,
            &attractors_header(&scene),
            &rows,
        );
        let path = dir.path().join(ATTRACTORS_FILE);

        let attractors = read_attractors(dir.path(), &scene).unwrap();
        // (η, f) = (0.6, 1), (0.7, 1), (0.6, 2), (0.7, 2): η fastest.
        let counts = attractors_per_point(&scene, &path, &attractors).unwrap();
        assert_eq!(counts, [2, 1, 0, 3]);
        let lambda1 = attractors.iter().map(|a| (a.at.as_slice(), a.exponents[0]));
        let largest = largest_per_point(&scene, &path, lambda1).unwrap();
        assert_eq!(largest[..2], [-0.02, -0.05]);
        assert!(largest[2].is_nan(), "no attractor: drawn as a failed cell");
        assert_eq!(largest[3], 0.04);

        let into = dir.path().join("figures");
        let written = draw(dir.path(), &into).unwrap();
        let names: Vec<_> = written.iter().map(|p| p.file_name().unwrap()).collect();
        let maps = [
            "heat-map.png",
            "heat-map.svg",
            "attractors-map.png",
            "attractors-map.svg",
        ];
        assert_eq!(names, maps);
        for png in [&written[0], &written[2]] {
            assert_eq!(png_size(png), HEAT_MAP_SIZE);
        }
    }

    /// A value that is not the sweep's is an error naming it, not a count
    /// in the wrong cell.
    #[test]
    fn an_attractor_off_the_grid_is_an_error() {
        let (dir, scene) = folder(TWO_PARAMETERS, |s| s);
        let rows = [attractor(
            &[("eta", 0.65), ("f", 1.0)],
            "0",
            [-0.05; 2],
            1.0,
        )];
        write_csv(
            dir.path(),
            ATTRACTORS_FILE,
            &attractors_header(&scene),
            &rows,
        );
        let error = draw(dir.path(), &dir.path().join("figures")).unwrap_err();
        let message = error.to_string();
        assert!(
            message.contains("eta = 0.65 is not a value of the sweep"),
            "{message}"
        );
    }

    /// Many starts on a grid without `attractors.csv`: grid.csv holds four
    /// lanes per point, and λ1's map takes each point's largest rather than
    /// refusing the row count.
    #[test]
    fn many_starts_without_attractors_map_each_points_largest_lambda1() {
        let (dir, scene) = folder(TWO_PARAMETERS, |s| s);
        let lambda1 = |point: usize, start: usize| -0.05 + 0.01 * (point * 4 + start) as f64;
        let points = [(0.6, 1.0), (0.7, 1.0), (0.6, 2.0), (0.7, 2.0)];
        let mut rows = Vec::new();
        // The starts of a point in reverse, so that its largest λ1 is not
        // its last row.
        for start in (0..4).rev() {
            for (point, &(eta, f)) in points.iter().enumerate() {
                let l1 = lambda1(point, start);
                rows.push(vec![
                    ("eta", eta.to_string()),
                    ("f", f.to_string()),
                    ("lambda_1", l1.to_string()),
                    ("lambda_2", (-0.1 - l1).to_string()),
                    ("start", start.to_string()),
                    ("status", "ok".to_owned()),
                ]);
            }
        }
        write_csv(dir.path(), GRID_FILE, &spectrum_header(&scene), &rows);

        let largest = lambda1_per_point(dir.path(), &scene).unwrap();
        let expected: Vec<f64> = (0..4).map(|point| lambda1(point, 3)).collect();
        assert_eq!(largest, expected);
        let written = draw(dir.path(), &dir.path().join("figures")).unwrap();
        assert_eq!(png_size(&written[0]), HEAT_MAP_SIZE);
    }
}
