//! `[attractors]`: many starts per swept value, so that every attractor a
//! value holds can be found, not only the one a single start falls into.
//!
//! The starts are states, the same at every value: `starts = N` drawn
//! uniformly in a `box` over some states (reproducibly, from `seed`; the
//! states the box does not name keep `integration.initial_state`),
//! `grid = [n, …]`, a regular grid over the box with its corners (numpy's
//! `linspace` on each named state, in the model's order of states), or
//! `list`, whole states given one by one.

use std::collections::BTreeMap;

use serde::Deserialize;

use super::distribution::{Distribution, RawDistribution};
use crate::error::{Error, Result};
use crate::system::SystemInfo;

/// The default longest period a lane's orbit is tested for.
pub const DEFAULT_MAX_PERIOD: usize = 12;

/// `[attractors]` as the file gives it.
#[derive(Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawAttractors {
    pub(super) starts: Option<usize>,
    pub(super) seed: Option<u64>,
    #[serde(rename = "box")]
    pub(super) bounds: Option<BTreeMap<String, Vec<f64>>>,
    pub(super) grid: Option<Vec<usize>>,
    pub(super) list: Option<Vec<Vec<f64>>>,
    pub(super) max_period: Option<usize>,
    pub(super) continuation: Option<Continuation>,
    pub(super) basins: Option<usize>,
    pub(super) basin_box: Option<usize>,
    pub(super) early_stop: Option<usize>,
    pub(super) distribution: Option<RawDistribution>,
}

/// Which neighbours each value is also started from: the attractors found
/// at the value below (`up`, following branches as the parameter grows),
/// above (`down`), both, or neither.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Continuation {
    #[default]
    None,
    Up,
    Down,
    Both,
}

impl Continuation {
    /// Whether value i is started from value i - 1's attractors.
    pub fn up(self) -> bool {
        matches!(self, Continuation::Up | Continuation::Both)
    }

    /// Whether value i is started from value i + 1's attractors.
    pub fn down(self) -> bool {
        matches!(self, Continuation::Down | Continuation::Both)
    }
}

/// How the starts were chosen (the basin fractions of random and grid
/// starts estimate how much of the box leads to each attractor).
#[derive(Clone, Debug, PartialEq)]
pub enum Layout {
    Random { seed: u64 },
    Grid { counts: Vec<usize> },
    List,
}

/// The starts of every swept value: lane k of the sweep starts from
/// `states[k % states.len()]`.
#[derive(Clone, Debug, PartialEq)]
pub struct Starts {
    pub layout: Layout,
    /// Whole states, one per start.
    pub states: Vec<Vec<f64>>,
    /// The longest period a lane's orbit is tested for.
    pub max_period: usize,
    pub continuation: Continuation,
    /// How random starts were drawn over the box (`attractors.distribution`;
    /// uniform for a grid or a list).
    pub distribution: Distribution,
    /// Whether the scene names the distribution: its fractions are then
    /// basin stability, written with their standard errors.
    pub distribution_given: bool,
    /// The basin images: how many values (the first, in the grid's order)
    /// have every start's label written and drawn (0: none), and the side
    /// of the boxes the basin entropy is taken over, in cells.
    pub basins: Basins,
}

/// `attractors.basins` and `attractors.basin_box`, checked: images need a
/// grid over two states.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Basins {
    pub values: usize,
    pub box_side: usize,
    /// The two states the grid spans (x fastest), by index.
    pub axes: [usize; 2],
    /// Early stops: a start stops once its reference has stayed within
    /// the attractor tolerance of an orbit learned from every fourth start
    /// along both states for this many consecutive transient iterations
    /// (0: off; see `method::lane::early_stop`).
    pub early_stop: usize,
}

impl Starts {
    /// Whether some starts may lie outside the admissible states: those of
    /// a basin image's grid, whose box the wall may cut.
    pub fn may_be_inadmissible(&self) -> bool {
        self.basins.values > 0
    }
}

/// The default side of the boxes the basin entropy is taken over (Daza
/// et al. 2016 use 5 × 5 cells).
pub const DEFAULT_BASIN_BOX: usize = 5;

/// The default `early_stop`: consecutive iterations within the attractor
/// tolerance of a known orbit before a start stops on it. The labels of
/// the seed's 512 × 512 images at η = 0.6 and 1.3 with it are those of the
/// full transients (docs/BENCHMARKS.md, "Basins"); a start that close to a
/// stable orbit (1e-5 of the state, against critical shocks above 0.1 of
/// the box) stays, and the count guards against a pass near an orbit's
/// point on the way elsewhere.
pub const DEFAULT_EARLY_STOP: usize = 10;

/// Starts per value that a scene may ask for (a start is a lane at every
/// value; the run's size is checked against the budget as a whole).
const MAX_STARTS: usize = 1 << 20;

impl Layout {
    /// The key that chose the starts, for messages.
    pub fn key(&self) -> &'static str {
        match self {
            Layout::Random { .. } => "attractors.starts",
            Layout::Grid { .. } => "attractors.grid",
            Layout::List => "attractors.list",
        }
    }
}

impl RawAttractors {
    /// The key that chooses the starts (for the size check's message).
    pub(super) fn key(&self) -> &'static str {
        match (&self.starts, &self.grid) {
            (Some(_), _) => "attractors.starts",
            (None, Some(_)) => "attractors.grid",
            _ => "attractors.list",
        }
    }

    /// The number of starts the table asks for, before anything is
    /// generated (for the size check).
    pub(super) fn count(&self) -> usize {
        match (&self.starts, &self.grid, &self.list) {
            (Some(n), _, _) => *n,
            (None, Some(grid), _) => grid
                .iter()
                .try_fold(1usize, |a, &n| a.checked_mul(n))
                .unwrap_or(usize::MAX),
            (None, None, Some(list)) => list.len(),
            _ => 1,
        }
    }
}

/// The table checked against the system, and its starts generated.
pub(super) fn resolve_starts(
    raw: RawAttractors,
    info: &SystemInfo,
    initial_state: &[f64],
) -> Result<Starts> {
    let max_period = raw.max_period.unwrap_or(DEFAULT_MAX_PERIOD);
    let raw_basins = RawAttractors {
        basins: raw.basins,
        basin_box: raw.basin_box,
        early_stop: raw.early_stop,
        ..RawAttractors::default()
    };
    let continuation = raw.continuation.unwrap_or_default();
    if continuation != Continuation::None && info.model.is_some_and(|m| m.section.is_some()) {
        return Err(Error::invalid(
            "attractors.continuation",
            "needs a period map or a map: a Poincaré section's points are not whole states to start a flow from",
        ));
    }
    if max_period == 0 {
        return Err(Error::invalid(
            "attractors.max_period",
            "must be at least 1",
        ));
    }
    let given = [raw.starts.is_some(), raw.grid.is_some(), raw.list.is_some()];
    // A table that chooses no starts (only max_period or continuation)
    // asks for one: integration.initial_state, as without the table.
    if given == [false; 3] && raw.bounds.is_none() && raw.seed.is_none() {
        check_basins(&raw, None)?;
        return Ok(Starts {
            layout: Layout::List,
            states: vec![initial_state.to_vec()],
            max_period,
            continuation,
            distribution: Distribution::Uniform,
            distribution_given: false,
            basins: Basins::default(),
        });
    }
    if given.iter().filter(|&&g| g).count() != 1 {
        return Err(Error::invalid(
            "attractors",
            "give exactly one of starts = N (random in a box), grid = [n, …] (a grid over the box) or list = [[…], …]",
        ));
    }
    let names: Vec<String> = info.state_names.iter().map(|s| s.to_string()).collect();
    let distribution_given = raw.distribution.is_some();
    if distribution_given && raw.starts.is_none() {
        return Err(Error::invalid(
            "attractors.distribution",
            "applies to random starts (starts = N), not to a grid or a list",
        ));
    }
    let mut distribution = Distribution::Uniform;
    let mut box_states = Vec::new();
    let (layout, states) = if let Some(list) = raw.list {
        if raw.bounds.is_some() || raw.seed.is_some() {
            return Err(Error::invalid(
                "attractors.list",
                "gives whole states: box and seed do not apply to it",
            ));
        }
        (Layout::List, listed(list, initial_state.len(), &names)?)
    } else {
        let bounds = box_of(raw.bounds, &names, initial_state.len())?;
        box_states = bounds.iter().map(|b| b.0).collect();
        if let Some(n) = raw.starts {
            check_count(n, "attractors.starts")?;
            let seed = raw.seed.unwrap_or(1);
            if let Some(given) = raw.distribution {
                distribution = given.resolve(&bounds, &names)?;
            }
            (
                Layout::Random { seed },
                random(n, seed, &distribution, &bounds, initial_state),
            )
        } else {
            let counts = raw.grid.unwrap_or_default();
            if raw.seed.is_some() {
                return Err(Error::invalid(
                    "attractors.seed",
                    "applies to random starts (starts = N), not to a grid",
                ));
            }
            let states = grid(&counts, &bounds, initial_state)?;
            (Layout::Grid { counts }, states)
        }
    };
    let basins = check_basins(&raw_basins, Some((&layout, &box_states)))?;
    Ok(Starts {
        layout,
        states,
        max_period,
        continuation,
        distribution,
        distribution_given,
        basins,
    })
}

/// `basins` and `basin_box` against the starts' layout: images need a grid
/// over two states, boxes at least a cell and at most the grid's shorter
/// side.
fn check_basins(raw: &RawAttractors, layout: Option<(&Layout, &[usize])>) -> Result<Basins> {
    let values = raw.basins.unwrap_or(0);
    if values == 0 {
        for (given, key) in [
            (raw.basin_box.is_some(), "attractors.basin_box"),
            (raw.early_stop.is_some(), "attractors.early_stop"),
        ] {
            if given {
                return Err(Error::invalid(
                    key,
                    "applies to basin images: give attractors.basins = N too",
                ));
            }
        }
        return Ok(Basins::default());
    }
    let (counts, axes) =
        match layout {
            Some((Layout::Grid { counts }, &[a, b])) if counts.len() == 2 => (counts, [a, b]),
            _ => return Err(Error::invalid(
                "attractors.basins",
                "needs grid = [nx, ny] with a box over two states: an image has a start per cell",
            )),
        };
    let shorter = counts[0].min(counts[1]);
    let box_side = raw.basin_box.unwrap_or(DEFAULT_BASIN_BOX.min(shorter));
    if box_side == 0 || box_side > shorter {
        return Err(Error::invalid(
            "attractors.basin_box",
            format!(
                "must be between 1 and the grid's shorter side ({shorter}) cells, got {box_side}"
            ),
        ));
    }
    Ok(Basins {
        values,
        box_side,
        axes,
        early_stop: raw.early_stop.unwrap_or(DEFAULT_EARLY_STOP),
    })
}

/// A list's starts, checked: whole states of `dim` finite numbers.
fn listed(list: Vec<Vec<f64>>, dim: usize, names: &[String]) -> Result<Vec<Vec<f64>>> {
    for (s, state) in list.iter().enumerate() {
        if state.len() != dim {
            return Err(Error::invalid(
                "attractors.list",
                format!(
                    "start {s} has {} numbers; a state has {dim} ({})",
                    state.len(),
                    names.join(", ")
                ),
            ));
        }
        if let Some(v) = state.iter().find(|v| !v.is_finite()) {
            return Err(Error::invalid(
                "attractors.list",
                format!("start {s} must be finite, got {v}"),
            ));
        }
    }
    check_count(list.len(), "attractors.list")?;
    Ok(list)
}

/// `n` starts drawn from `distribution` over the box from `seed`, the
/// states the box leaves out at `initial_state`.
fn random(
    n: usize,
    seed: u64,
    distribution: &Distribution,
    bounds: &[(usize, f64, f64)],
    initial_state: &[f64],
) -> Vec<Vec<f64>> {
    let mut rng = fastrand::Rng::with_seed(seed);
    (0..n)
        .map(|_| distribution.draw(&mut rng, bounds, initial_state))
        .collect()
}

/// The grid of `counts` points over the box (corners included, the first
/// state fastest), checked.
fn grid(
    counts: &[usize],
    bounds: &[(usize, f64, f64)],
    initial_state: &[f64],
) -> Result<Vec<Vec<f64>>> {
    if counts.len() != bounds.len() {
        return Err(Error::invalid(
            "attractors.grid",
            format!(
                "needs one count per state of the box ({} states), got {}",
                bounds.len(),
                counts.len()
            ),
        ));
    }
    if let Some(n) = counts.iter().find(|&&n| n == 0) {
        return Err(Error::invalid(
            "attractors.grid",
            format!("counts must be at least 1, got {n}"),
        ));
    }
    let total = RawAttractors {
        grid: Some(counts.to_vec()),
        ..RawAttractors::default()
    }
    .count();
    check_count(total, "attractors.grid")?;
    Ok((0..total)
        .map(|mut g| {
            let mut state = initial_state.to_vec();
            for (&(i, lo, hi), &n) in bounds.iter().zip(counts) {
                let j = g % n;
                g /= n;
                state[i] = linspace(lo, hi, n, j);
            }
            state
        })
        .collect())
}

/// numpy's `linspace(lo, hi, n)[j]`: `lo + j·step`, the last point `hi`
/// exactly (one point: `lo`).
fn linspace(lo: f64, hi: f64, n: usize, j: usize) -> f64 {
    if j + 1 == n && n > 1 {
        return hi;
    }
    let step = if n > 1 {
        (hi - lo) / (n - 1) as f64
    } else {
        0.0
    };
    lo + j as f64 * step
}

fn check_count(n: usize, key: &str) -> Result<()> {
    if n == 0 || n > MAX_STARTS {
        return Err(Error::invalid(
            key,
            format!("asks for {n} starts per value: between 1 and {MAX_STARTS}"),
        ));
    }
    Ok(())
}

/// The box's (state index, low, high), in the order of the states.
fn box_of(
    bounds: Option<BTreeMap<String, Vec<f64>>>,
    names: &[String],
    states: usize,
) -> Result<Vec<(usize, f64, f64)>> {
    let bounds = bounds.ok_or_else(|| {
        Error::invalid(
            "attractors.box",
            format!(
                "is required with starts or grid: a range per state, e.g. box = {{ {} = [-3, 3] }}",
                names.first().map_or("x", |s| s.as_str())
            ),
        )
    })?;
    if bounds.is_empty() {
        return Err(Error::invalid(
            "attractors.box",
            "names no state: give a range for at least one",
        ));
    }
    let mut out = Vec::new();
    for (name, range) in bounds {
        let key = format!("attractors.box.{name}");
        let i = names
            .iter()
            .take(states)
            .position(|n| *n == name)
            .ok_or_else(|| {
                Error::invalid(
                    &key,
                    format!("is not a state (the states: {})", names.join(", ")),
                )
            })?;
        match range[..] {
            [lo, hi] if lo.is_finite() && hi.is_finite() && lo < hi => out.push((i, lo, hi)),
            _ => {
                return Err(Error::invalid(
                    &key,
                    format!("must be [low, high], finite with low < high, got {range:?}"),
                ))
            }
        }
    }
    out.sort_by_key(|&(i, _, _)| i);
    Ok(out)
}
