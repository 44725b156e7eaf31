//! The known attractors of a value indexed by where they lie, so that a
//! lane is compared only with those that could be its own: telling N
//! lanes apart then costs about N lookups, not N times the attractors
//! found so far (thousands of lanes that never settle are each an
//! attractor of their own).
//!
//! The index only proposes candidates; [`super::group`] decides with the
//! same test as before, over the candidates in the order the attractors
//! were found, so a lane joins the first attractor it matches, as when it
//! was compared with all. The proposals are conservative: every attractor
//! the test would accept is among them (the bounds below, with a margin
//! for rounding). Whatever the grids cannot place (a point or bound that
//! is not finite) is proposed for every lane, and a lane with such a point
//! is compared with all attractors.
//!
//! - A periodic attractor is filed under its period, the magnitude
//!   `m = ⌊log2 max(1, |x|∞)⌋` of its first point x and x's cell in a grid
//!   of spacing `tol·2^(m+2)` over the first two coordinates. A lane of
//!   the same period matches only if x is within `tol·max(1, |x|∞, |y|∞)`
//!   of one of its points y: the magnitudes then differ by at most one,
//!   and the distance is at most `tol·max(1, |y|∞)/(1 - tol)`.
//! - An aperiodic one is filed under the signs of its exponents, a level
//!   L with `2^L` at least its box's widest side, and the cell of the
//!   box's low corner in a grid of spacing `2^L`. A matching box lies
//!   within `T = tol·max(scale_a, scale_b)` of the lane's, and `scale_a`
//!   is at most `scale_b + T + 2^L`, which bounds T by the lane's own
//!   scale at each level.

use std::collections::{BTreeMap, HashMap};

use crate::method::LaneResult;

/// What the index reads of an aperiodic lane's shape (kept by `group`):
/// the signs of its exponents, the box around its points and its scale.
pub(super) struct Shape<'a> {
    pub(super) signs: &'a [i8],
    pub(super) bounds: &'a [(f64, f64)],
    pub(super) scale: f64,
}

/// The coordinates the grids are over (the first two; the test reads all).
const AXES: usize = 2;

type Cell = [i64; AXES];

/// The tolerances the grids hold their bounds for: beyond them every lane
/// is compared with every attractor, as without the index.
const SMALLEST_TOLERANCE: f64 = 1e-12;
const LARGEST_TOLERANCE: f64 = 0.25;

/// Relative and absolute (in units of the scale) margins on every bound,
/// for the rounding of the test's own arithmetic and of the cells'.
const RELATIVE_MARGIN: f64 = 1e-9;
const ABSOLUTE_MARGIN: f64 = 1e-15;

/// The levels below the scale's magnitude an aperiodic box is filed at,
/// at most: a box narrower than that is filed as if that wide, so its
/// cell numbers stay within 2^41.
const FINEST_LEVEL_BELOW_SCALE: i32 = 40;

#[derive(Clone, Default)]
pub(super) struct Index {
    /// Periodic attractors by (period, magnitude, cell of the first point).
    periodic: HashMap<(usize, i32, Cell), Vec<usize>>,
    /// Aperiodic ones by (signs' id, level, cell of the box's low corner).
    aperiodic: HashMap<(usize, i32, Cell), Vec<usize>>,
    /// Aperiodic ones by signs' id and level, for levels whose cells are
    /// too many to look up one by one.
    levels: Vec<BTreeMap<i32, Vec<usize>>>,
    /// The ids of the sign patterns seen.
    sign_ids: HashMap<Vec<i8>, usize>,
    /// Attractors the grids cannot place: proposed for every lane.
    unplaced: Vec<usize>,
    /// The attractors taken in so far (0..indexed).
    pub(super) indexed: usize,
}

/// The index is a function of the attractors it holds: shown as their
/// count, so that two values' attractors print alike whatever order the
/// hash maps keep.
impl std::fmt::Debug for Index {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Index")
            .field("indexed", &self.indexed)
            .finish_non_exhaustive()
    }
}

/// What a lane may be compared with.
pub(super) enum Candidates {
    /// These attractors, in the order they were found.
    Some(Vec<usize>),
    /// Every attractor: the lane has a point the grids cannot place, or
    /// the tolerance is beyond the grids' bounds.
    All,
}

/// 2^k for the exponents a finite f64's magnitude has.
fn power_of_two(k: i32) -> f64 {
    2f64.powi(k)
}

/// ⌊log2 s⌋ of a finite s ≥ 1, exactly, from its bits.
fn magnitude(s: f64) -> i32 {
    ((s.to_bits() >> 52) & 0x7ff) as i32 - 1023
}

/// max(1, |x|∞), as the test computes it.
fn scale_of(x: &[f64]) -> f64 {
    x.iter().fold(1.0_f64, |m, v| m.max(v.abs()))
}

/// The cell numbers of [lo, hi] in a grid of spacing `w` on one axis.
fn cells(lo: f64, hi: f64, w: f64) -> (i64, i64) {
    ((lo / w).floor() as i64, (hi / w).floor() as i64)
}

/// Every cell of the product of `ranges` (one per axis), with `key`.
fn each_cell(ranges: &[(i64, i64)], mut visit: impl FnMut(Cell)) {
    let (a, b) = (ranges[0], ranges.get(1).copied().unwrap_or((0, 0)));
    for i in a.0..=a.1 {
        for j in b.0..=b.1 {
            visit([i, j]);
        }
    }
}

/// The number of cells of the product of `ranges`, saturating.
fn cell_count(ranges: &[(i64, i64)]) -> u128 {
    ranges
        .iter()
        .map(|&(a, b)| (b as i128 - a as i128 + 1).max(0) as u128)
        .fold(1u128, |n, k| n.saturating_mul(k))
}

fn usable(tolerance: f64) -> bool {
    (SMALLEST_TOLERANCE..LARGEST_TOLERANCE).contains(&tolerance)
}

impl Index {
    /// Takes in attractor `index` (the next one), whose first lane is
    /// `lane` with shape `shape`. An attractor that never matches (a lone
    /// failed lane, an empty orbit) is left out.
    pub(super) fn insert(
        &mut self,
        index: usize,
        lane: &LaneResult,
        shape: &Shape<'_>,
        dim: usize,
        tolerance: f64,
        never_matches: bool,
    ) {
        debug_assert_eq!(index, self.indexed);
        self.indexed += 1;
        if never_matches || lane.orbit.is_empty() || !usable(tolerance) {
            return;
        }
        let axes = dim.min(AXES);
        match lane.orbit_period {
            Some(p) => {
                // An orbit shorter than a point has no point to file it by
                // (the test's `all` over no points is true).
                if lane.orbit.len() < dim.max(1) || lane.orbit[..dim].iter().any(|v| !v.is_finite())
                {
                    self.unplaced.push(index);
                    return;
                }
                let x = &lane.orbit[..dim];
                let m = magnitude(scale_of(x));
                let w = 4.0 * tolerance * power_of_two(m);
                let mut cell = [0; AXES];
                for (c, &v) in cell.iter_mut().zip(&x[..axes]) {
                    *c = (v / w).floor() as i64;
                }
                self.periodic.entry((p, m, cell)).or_default().push(index);
            }
            None => {
                let Some(level) = level(shape) else {
                    self.unplaced.push(index);
                    return;
                };
                let w = power_of_two(level);
                let mut cell = [0; AXES];
                for (c, &(lo, _)) in cell.iter_mut().zip(&shape.bounds[..axes]) {
                    *c = (lo / w).floor() as i64;
                }
                let next = self.sign_ids.len();
                let id = *self.sign_ids.entry(shape.signs.to_vec()).or_insert(next);
                if id == self.levels.len() {
                    self.levels.push(BTreeMap::new());
                }
                self.levels[id].entry(level).or_default().push(index);
                self.aperiodic
                    .entry((id, level, cell))
                    .or_default()
                    .push(index);
            }
        }
    }

    /// The attractors `lane` (of shape `shape`) may be on, in the order
    /// they were found.
    pub(super) fn candidates(
        &self,
        lane: &LaneResult,
        shape: &Shape<'_>,
        dim: usize,
        tolerance: f64,
        never_matches: bool,
    ) -> Candidates {
        if never_matches || lane.orbit.is_empty() {
            return Candidates::Some(Vec::new());
        }
        if !usable(tolerance) {
            return Candidates::All;
        }
        let mut found = self.unplaced.clone();
        let placed = match lane.orbit_period {
            Some(p) => self.periodic_candidates(lane, p, dim, tolerance, &mut found),
            None => self.aperiodic_candidates(shape, dim, tolerance, &mut found),
        };
        if !placed {
            return Candidates::All;
        }
        found.sort_unstable();
        found.dedup();
        Candidates::Some(found)
    }

    /// Adds the periodic attractors of period `p` whose first point may be
    /// within the tolerance of one of `lane`'s points; false if a point is
    /// not finite.
    fn periodic_candidates(
        &self,
        lane: &LaneResult,
        p: usize,
        dim: usize,
        tolerance: f64,
        found: &mut Vec<usize>,
    ) -> bool {
        let axes = dim.min(AXES);
        for y in lane.orbit.chunks_exact(dim) {
            if y.len() < axes || y.iter().any(|v| !v.is_finite()) {
                return false;
            }
            let s = scale_of(y);
            let r =
                tolerance * s / (1.0 - tolerance) * (1.0 + RELATIVE_MARGIN) + ABSOLUTE_MARGIN * s;
            let my = magnitude(s);
            for m in (my - 1).max(0)..=my + 1 {
                let w = 4.0 * tolerance * power_of_two(m);
                let ranges: Vec<(i64, i64)> =
                    y[..axes].iter().map(|&v| cells(v - r, v + r, w)).collect();
                each_cell(&ranges, |cell| {
                    if let Some(list) = self.periodic.get(&(p, m, cell)) {
                        found.extend_from_slice(list);
                    }
                });
            }
        }
        true
    }

    /// Adds the aperiodic attractors with the lane's signs whose boxes may
    /// lie within the tolerance of its box; false if a bound is not
    /// finite.
    fn aperiodic_candidates(
        &self,
        shape: &Shape<'_>,
        dim: usize,
        tolerance: f64,
        found: &mut Vec<usize>,
    ) -> bool {
        if level(shape).is_none() {
            return false;
        }
        let Some(&id) = self.sign_ids.get(shape.signs) else {
            return true;
        };
        let axes = dim.min(AXES);
        let sb = shape.scale;
        for (&level, entries) in &self.levels[id] {
            let w = power_of_two(level);
            let t = tolerance * (sb + w) / (1.0 - tolerance) * (1.0 + RELATIVE_MARGIN)
                + ABSOLUTE_MARGIN * (sb + w);
            let ranges: Vec<(i64, i64)> = shape.bounds[..axes]
                .iter()
                .map(|&(lo, hi)| cells(lo - t - w, hi + t, w))
                .collect();
            if cell_count(&ranges) > entries.len() as u128 {
                found.extend_from_slice(entries);
                continue;
            }
            each_cell(&ranges, |cell| {
                if let Some(list) = self.aperiodic.get(&(id, level, cell)) {
                    found.extend_from_slice(list);
                }
            });
        }
        true
    }
}

/// The level an aperiodic box is filed at: L with 2^L at least its widest
/// side (over all coordinates), not below the scale's magnitude less
/// [`FINEST_LEVEL_BELOW_SCALE`]; `None` when a bound or the scale is not
/// finite.
fn level(shape: &Shape<'_>) -> Option<i32> {
    let finite = shape.scale.is_finite()
        && shape
            .bounds
            .iter()
            .all(|&(lo, hi)| lo.is_finite() && hi.is_finite());
    if !finite {
        return None;
    }
    let widest = shape
        .bounds
        .iter()
        .fold(0.0_f64, |m, &(lo, hi)| m.max(hi - lo));
    if !widest.is_finite() {
        return None;
    }
    let floor = magnitude(shape.scale) - FINEST_LEVEL_BELOW_SCALE;
    if widest <= power_of_two(floor) {
        return Some(floor);
    }
    let mut level = (widest.log2().ceil() as i32).max(floor);
    while power_of_two(level) < widest {
        level += 1;
    }
    Some(level)
}
