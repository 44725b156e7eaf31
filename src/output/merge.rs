//! Shards back into one run's files (`lyapsweep merge OUT SHARD...`).
//!
//! Shard i of n holds sweep lanes i, i + n, i + 2n, … (scene::Shard). Every
//! lane is computed as in the whole sweep (the GPU takes the whole sweep's
//! plan), so the merged CSV files are, byte for byte, those of one run.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use super::files::{
    number, spectrum_file, write_atomically, write_text, BIFURCATION_FILE, SCENE_FILE, SHARD_FILE,
};
use super::results::{read_csv, scene_of};
use super::set::{self, Staging};
use crate::error::{Error, Result};
use crate::scene::Scene;

/// `shard.toml`, as [`super::write`] writes it.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ShardFile {
    index: usize,
    count: usize,
    /// Lanes of the whole sweep.
    lanes: usize,
    /// Rows of `bifurcation.csv` per lane of the shard, in order.
    bifurcation_rows: Vec<usize>,
}

/// One output file of every shard: its header, and per shard the rows of
/// each of its lanes.
struct Table {
    name: &'static str,
    header: csv::StringRecord,
    per_shard: Vec<Vec<Vec<csv::StringRecord>>>,
}

/// One shard folder, read.
struct Shard {
    dir: PathBuf,
    file: ShardFile,
    scene_text: String,
}

fn bad(path: &Path, reason: impl Into<String>) -> Error {
    Error::Results {
        path: path.to_owned(),
        reason: reason.into(),
    }
}

fn read_shard(dir: &Path) -> Result<Shard> {
    let read = |name: &str| {
        let path = dir.join(name);
        std::fs::read_to_string(&path).map_err(|e| {
            bad(
                &path,
                format!("cannot read it ({e}): is this the output of a `--shard` run?"),
            )
        })
    };
    let text = read(SHARD_FILE)?;
    let file: ShardFile =
        toml::from_str(&text).map_err(|e| bad(&dir.join(SHARD_FILE), e.message().to_owned()))?;
    // As `--shard I/N` takes them: the lanes are dealt out N ways.
    if file.count == 0 || file.index >= file.count {
        return Err(bad(
            &dir.join(SHARD_FILE),
            format!(
                "index = {}, count = {}: a shard is one of count ≥ 1, its index from 0 to count - 1",
                file.index, file.count
            ),
        ));
    }
    Ok(Shard {
        dir: dir.to_owned(),
        file,
        scene_text: read(SCENE_FILE)?,
    })
}

/// Merges the shard folders into `out`; returns the paths written.
pub fn merge(out: &Path, dirs: &[PathBuf]) -> Result<Vec<PathBuf>> {
    // The output folder is checked first (never one of the shards), and
    // every shard is read and checked before anything is written.
    let staging = Staging::prepare(out, dirs)?;
    for dir in dirs {
        set::verify(dir)?;
    }
    let mut shards = dirs
        .iter()
        .map(|d| read_shard(d))
        .collect::<Result<Vec<_>>>()?;
    shards.sort_by_key(|s| s.file.index);
    let Some(first) = shards.first() else {
        return Err(Error::invalid("merge", "give the shard folders to merge"));
    };
    let (count, lanes) = check_split(&shards)?;
    let scene = scene_of(&first.dir)?;
    let shard_lanes = |i: usize| (i..lanes).step_by(count).count();
    check_lane_lists(&shards, count, lanes)?;

    // Every file is read and checked before anything is written.
    let mut tables = Vec::new();
    if scene.lyapunov {
        tables.push(gather(&shards, spectrum_file(&scene), &|i| {
            vec![1; shard_lanes(i)]
        })?);
    }
    if scene.bifurcation_points > 0 {
        tables.push(gather(&shards, BIFURCATION_FILE, &|i| {
            shards[i].file.bifurcation_rows.clone()
        })?);
    }

    let shard_dirs: Vec<&Path> = shards.iter().map(|s| s.dir.as_path()).collect();
    for table in &tables {
        check_rows(&scene, table, &shard_dirs)?;
    }

    let dir = staging.dir().to_owned();
    set::pause(SCENE_FILE);
    write_text(&dir.join(SCENE_FILE), &first.scene_text)?;
    write_tables(&dir, &tables, count, lanes)?;
    if scene.plot {
        set::pause("figures");
        super::results::draw(&dir, &dir)?;
    }
    staging.commit()
}

/// The shards (sorted by index, at least one) come from the same scene,
/// split the same way, each once and all present; returns the split's
/// shard count and the sweep's lanes.
fn check_split(shards: &[Shard]) -> Result<(usize, usize)> {
    let first = &shards[0];
    let (count, lanes) = (first.file.count, first.file.lanes);
    for shard in shards {
        let here = |name: &str| shard.dir.join(name);
        if shard.scene_text != first.scene_text {
            return Err(bad(
                &here(SCENE_FILE),
                format!(
                    "differs from {}: shards of different scenes (or overrides) cannot be merged",
                    first.dir.join(SCENE_FILE).display()
                ),
            ));
        }
        if shard.file.count != count || shard.file.lanes != lanes {
            return Err(bad(
                &here(SHARD_FILE),
                format!(
                    "shard of {} over {} lanes, but {} is a shard of {count} over {lanes}",
                    shard.file.count,
                    shard.file.lanes,
                    first.dir.display()
                ),
            ));
        }
    }
    if let Some(pair) = shards
        .windows(2)
        .find(|w| w[0].file.index == w[1].file.index)
    {
        return Err(bad(
            &pair[1].dir,
            format!(
                "shard {} is given twice (also {})",
                pair[1].file.index,
                pair[0].dir.display()
            ),
        ));
    }
    let missing: Vec<String> = (0..count)
        .filter(|i| !shards.iter().any(|s| s.file.index == *i))
        .map(|i| i.to_string())
        .collect();
    if !missing.is_empty() {
        return Err(bad(
            &first.dir,
            format!(
                "shard(s) {} of {count} missing: merge needs all of them",
                missing.join(", ")
            ),
        ));
    }
    Ok((count, lanes))
}

/// Each shard lists the bifurcation rows of as many lanes as it has.
fn check_lane_lists(shards: &[Shard], count: usize, lanes: usize) -> Result<()> {
    let shard_lanes = |i: usize| (i..lanes).step_by(count).count();
    for (i, shard) in shards.iter().enumerate() {
        if shard.file.bifurcation_rows.len() != shard_lanes(i) {
            return Err(bad(
                &shard.dir.join(SHARD_FILE),
                format!(
                    "{} lanes listed, shard {i} of {count} over {lanes} lanes has {}",
                    shard.file.bifurcation_rows.len(),
                    shard_lanes(i)
                ),
            ));
        }
    }

    Ok(())
}

/// One file of every shard, read and checked: per shard, its rows grouped
/// by lane, `rows_of(i)` rows for each lane of shard i.
fn gather(
    shards: &[Shard],
    name: &'static str,
    rows_of: &dyn Fn(usize) -> Vec<usize>,
) -> Result<Table> {
    let mut header: Option<csv::StringRecord> = None;
    let mut per_shard = Vec::new();
    for (i, shard) in shards.iter().enumerate() {
        let (h, records) = read_csv(&shard.dir, name)?;
        if header.as_ref().is_some_and(|first| *first != h) {
            return Err(bad(
                &shard.dir.join(name),
                "its header differs from shard 0's",
            ));
        }
        header = Some(h);
        let counts = rows_of(i);
        let expected: usize = counts.iter().sum();
        if expected != records.len() {
            return Err(bad(
                &shard.dir.join(name),
                format!(
                    "{} rows, {expected} expected from {SHARD_FILE}",
                    records.len()
                ),
            ));
        }
        let mut rows = records.into_iter();
        per_shard.push(
            counts
                .iter()
                .map(|&n| rows.by_ref().take(n).collect())
                .collect(),
        );
    }
    Ok(Table {
        name,
        header: header.expect("at least one shard"),
        per_shard,
    })
}

/// The merged tables in the staging folder `dir`, in the sweep's lane
/// order: lane k of the sweep is lane k / n of shard k % n.
fn write_tables(dir: &Path, tables: &[Table], count: usize, lanes: usize) -> Result<()> {
    for table in tables {
        set::pause(table.name);
        write_atomically(&dir.join(table.name), |w| {
            w.write_record(&table.header)?;
            for k in 0..lanes {
                for record in &table.per_shard[k % count][k / count] {
                    w.write_record(record)?;
                }
            }
            Ok(())
        })?;
    }
    Ok(())
}

/// Every row of a shard's table is of the lane it stands for (its
/// parameters as the scene gives them, to the digit) and every cell but
/// the status is a number.
fn check_rows(scene: &Scene, table: &Table, dirs: &[&Path]) -> Result<()> {
    let count = dirs.len();
    let axes = scene.sweep.axes().count();
    let numeric = if table.name == BIFURCATION_FILE {
        table.header.len()
    } else {
        // The last column is the status.
        table.header.len() - 1
    };
    for (i, lanes) in table.per_shard.iter().enumerate() {
        for (j, records) in lanes.iter().enumerate() {
            let k = i + j * count;
            let expected: Vec<String> = scene.sweep.values_at(k).into_iter().map(number).collect();
            for record in records {
                let line = record.position().map_or(0, |p| p.line());
                let at = |reason: String| {
                    bad(&dirs[i].join(table.name), format!("line {line}: {reason}"))
                };
                if record.len() != table.header.len() {
                    return Err(at(format!(
                        "{} fields, the header has {}",
                        record.len(),
                        table.header.len()
                    )));
                }
                for (c, want) in expected.iter().enumerate() {
                    if &record[c] != want {
                        return Err(at(format!(
                            "{} = {} where the scene's sweep lane {k} has {want}: the row is not of this sweep",
                            &table.header[c], &record[c]
                        )));
                    }
                }
                for c in axes..numeric {
                    // An aperiodic orbit's period is empty.
                    let empty_period =
                        &table.header[c] == super::PERIOD_COLUMN && record[c].is_empty();
                    if !empty_period && record[c].parse::<f64>().is_err() {
                        return Err(at(format!(
                            "{} is not a number: {:?}",
                            &table.header[c], &record[c]
                        )));
                    }
                }
            }
        }
    }
    Ok(())
}
