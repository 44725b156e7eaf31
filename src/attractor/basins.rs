//! The basins of a value's attractors over a grid of starts spanning two
//! states: every start labelled with the branch of the attractor its lane
//! ended on, and the measures read from the labels.
//!
//! - Basin entropy (Daza, Wagemakers, Georgeot, Guéry-Odelin and Sanjuán,
//!   Sci. Rep. 6, 31416, 2016): the image is cut into boxes of n × n cells
//!   (the cells left over at the right and top edges are left out); a box
//!   whose cells end on attractors with shares p_j has the entropy
//!   S = -Σ p_j ln p_j. `S_b` is its mean over all boxes, `S_bb` over the
//!   boxes that hold more than one label (the boundary's). `S_bb > ln 2` is
//!   a sufficient condition for a fractal boundary; boxes can exceed ln 2
//!   only where three labels or more meet, so a boundary between two
//!   basins alone is never declared fractal by it.
//! - A fraction's binomial standard error √(f(1-f)/N), and the fraction on
//!   the grid at half the resolution (every second start along both
//!   states): where the two differ by much more than the error, the grid
//!   is too coarse for the boundary.
//!
//! - The uncertainty exponent α (Grebogi, McDonald, Ott and Yorke,
//!   Phys. Lett. A 99, 415, 1983): a start is ε-uncertain when a start ε
//!   away ends on another attractor; the fraction f(ε) of uncertain starts
//!   scales as ε^α, and the boundary's box-counting dimension is D - α
//!   (D = 2, the image's states). On the image, the pairs are the starts s
//!   cells apart along either state, for s = 1, 2, 4, ... up to an eighth
//!   of the grid's shorter side (beyond it f saturates as s nears the
//!   basins' own size: on the seed's 512 × 512 image at η = 0.6 the slope
//!   from s = 64 to 128 is 0.77, from 1 to 64 0.97), from the same starts at every shift (those
//!   with a partner at the largest); f(s) is the share of those pairs whose
//!   labels differ (a failed start's label counting as one more), and α
//!   the least-squares slope of ln f against ln s over the shifts with
//!   f > 0. A smooth boundary has α = 1; a fractal one α < 1. Shifts of
//!   whole cells resolve nothing finer than a cell: an α near 1 says the
//!   boundary is smooth down to the grid's cell.
//!
//! - Minimal critical shock of an attractor: the smallest kick of its
//!   state, in the box's scaled max norm (each state's change over the
//!   box's width along it), that sends it to another attractor, searched
//!   over the image itself: the nearest start, from any of the attractor's
//!   points, labelled with another attractor. Its resolution is the grid's
//!   (half a cell's width either way: the true boundary lies between that
//!   start and its neighbour); only the image's two states are kicked.
//!
//! Lanes that failed, or whose motion the method does not resolve, are
//! labelled [`FAILED`] and count as one more label in the entropy. Starts
//! outside the admissible states (behind a wall the box reaches past) are
//! labelled [`INADMISSIBLE`] and left out of every measure: the wall's
//! edge is not a boundary between basins, and those starts are no motion's.

use super::Attractors;

/// The label of a start whose lane failed or is not resolved.
pub const FAILED: i32 = -1;

/// The label of a start outside the admissible states (not run).
pub const INADMISSIBLE: i32 = -2;

/// One value's labels over the grid: `labels[j * nx + i]` for the start at
/// the i-th value of the first state and the j-th of the second.
#[derive(Clone, Debug, PartialEq)]
pub struct BasinImage {
    pub nx: usize,
    pub ny: usize,
    pub labels: Vec<i32>,
}

/// The labels of grid point `point`'s `nx × ny` starts: the branch of each
/// start's attractor, [`FAILED`] for a lone lane, [`INADMISSIBLE`] for a
/// start not run.
pub fn image(found: &Attractors, point: usize, (nx, ny): (usize, usize)) -> BasinImage {
    let value = &found.values[point];
    let mut labels: Vec<i32> = (0..nx * ny)
        .map(|s| {
            value
                .of_start
                .get(s)
                .copied()
                .flatten()
                .and_then(|a| value.attractors[a].branch)
                .map_or(FAILED, |b| b as i32)
        })
        .collect();
    for &s in &value.inadmissible {
        if let Some(label) = labels.get_mut(s) {
            *label = INADMISSIBLE;
        }
    }
    BasinImage { nx, ny, labels }
}

/// The basin entropy of an image and its boundary's (see the module's
/// header).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Entropy {
    /// S_b: the mean entropy over all boxes.
    pub basin: f64,
    /// S_bb: the mean over the boxes with more than one label (0 where
    /// there are none).
    pub boundary: f64,
    /// The boxes, and those on a boundary.
    pub boxes: usize,
    pub boundary_boxes: usize,
}

impl Entropy {
    /// Whether `S_bb > ln 2`: the sufficient condition for a fractal
    /// boundary.
    pub fn fractal(&self) -> bool {
        self.boundary > std::f64::consts::LN_2
    }
}

/// The basin entropy over boxes of `side × side` cells.
///
/// # Panics
/// If `side` is 0.
pub fn entropy(image: &BasinImage, side: usize) -> Entropy {
    assert!(side > 0, "boxes of at least one cell");
    let (bx, by) = (image.nx / side, image.ny / side);
    let (mut sum, mut boundary_sum, mut boundary_boxes) = (0.0, 0.0, 0);
    let mut boxes = 0;
    let mut counts: Vec<(i32, usize)> = Vec::new();
    for j in 0..by {
        for i in 0..bx {
            counts.clear();
            for row in j * side..(j + 1) * side {
                for &label in &image.labels[row * image.nx + i * side..][..side] {
                    if label == INADMISSIBLE {
                        continue;
                    }
                    match counts.iter_mut().find(|(l, _)| *l == label) {
                        Some((_, n)) => *n += 1,
                        None => counts.push((label, 1)),
                    }
                }
            }
            // The shares over the box's admissible cells; a box of none
            // is no box of the basins'.
            let cells: usize = counts.iter().map(|&(_, n)| n).sum();
            if cells == 0 {
                continue;
            }
            boxes += 1;
            let cells = cells as f64;
            let s: f64 = counts
                .iter()
                .map(|&(_, n)| {
                    let p = n as f64 / cells;
                    -p * p.ln()
                })
                .sum();
            sum += s;
            if counts.len() > 1 {
                boundary_sum += s;
                boundary_boxes += 1;
            }
        }
    }
    Entropy {
        basin: if boxes > 0 { sum / boxes as f64 } else { 0.0 },
        boundary: if boundary_boxes > 0 {
            boundary_sum / boundary_boxes as f64
        } else {
            0.0
        },
        boxes,
        boundary_boxes,
    }
}

/// The uncertainty exponent of an image (see the module's header): the
/// shifts s in cells with the fractions f(s) of pairs s apart whose labels
/// differ, and α, the slope of ln f against ln s.
#[derive(Clone, Debug, PartialEq)]
pub struct Uncertainty {
    pub fractions: Vec<(usize, f64)>,
    pub exponent: f64,
}

impl Uncertainty {
    /// The boundary's dimension, 2 - α.
    pub fn boundary_dimension(&self) -> f64 {
        2.0 - self.exponent
    }
}

/// The uncertainty exponent of an image: `None` when fewer than two
/// shifts fit the grid (its shorter side under 16 cells) or have uncertain
/// pairs (a single basin).
pub fn uncertainty(image: &BasinImage) -> Option<Uncertainty> {
    let (nx, ny) = (image.nx, image.ny);
    let at = |i: usize, j: usize| image.labels[j * nx + i];
    let shifts: Vec<usize> = std::iter::successors(Some(1usize), |s| Some(2 * s))
        .take_while(|&s| 8 * s <= nx.min(ny))
        .collect();
    let largest = *shifts.last()?;
    // The same starts at every shift (those with a partner at the largest),
    // so that f(s) counts uncertain starts of one set.
    let fractions: Vec<(usize, f64)> = shifts
        .iter()
        .map(|&s| {
            let along_x = (0..ny).flat_map(|j| (0..nx - largest).map(move |i| (i, j, i + s, j)));
            let along_y = (0..ny - largest).flat_map(|j| (0..nx).map(move |i| (i, j, i, j + s)));
            let (mut pairs, mut differ) = (0usize, 0usize);
            for (i, j, k, l) in along_x.chain(along_y) {
                let (a, b) = (at(i, j), at(k, l));
                if a != INADMISSIBLE && b != INADMISSIBLE {
                    pairs += 1;
                    differ += usize::from(a != b);
                }
            }
            (s, differ as f64 / pairs.max(1) as f64)
        })
        .collect();
    let points: Vec<(f64, f64)> = fractions
        .iter()
        .filter(|&&(_, f)| f > 0.0)
        .map(|&(s, f)| ((s as f64).ln(), f.ln()))
        .collect();
    if points.len() < 2 {
        return None;
    }
    let n = points.len() as f64;
    let (mx, my) = points
        .iter()
        .fold((0.0, 0.0), |(a, b), &(x, y)| (a + x / n, b + y / n));
    let (sxy, sxx) = points.iter().fold((0.0, 0.0), |(a, b), &(x, y)| {
        (a + (x - mx) * (y - my), b + (x - mx) * (x - mx))
    });
    Some(Uncertainty {
        fractions,
        exponent: sxy / sxx,
    })
}

/// The binomial standard error of a fraction `f` of `n` starts.
pub fn fraction_error(f: f64, n: usize) -> f64 {
    (f * (1.0 - f) / n as f64).sqrt()
}

/// The share of `label` on the grid at half the resolution: the starts at
/// even positions along both states.
pub fn half_resolution_fraction(image: &BasinImage, label: i32) -> f64 {
    let (mut on, mut all) = (0usize, 0usize);
    for j in (0..image.ny).step_by(2) {
        for i in (0..image.nx).step_by(2) {
            let at = image.labels[j * image.nx + i];
            all += usize::from(at != INADMISSIBLE);
            on += usize::from(at == label);
        }
    }
    on as f64 / all as f64
}

/// Where the image's starts lie: the grid's values of its two states
/// (nx and ny of them), with the box's widths along them.
pub struct Grid<'a> {
    pub x: &'a [f64],
    pub y: &'a [f64],
}

/// The minimal critical shock of the attractor labelled `label` whose
/// points (in the image's two states) are `points`: the smallest scaled
/// distance from a point to a start labelled with another attractor
/// (`None` when no start is).
pub fn critical_shock(
    image: &BasinImage,
    grid: &Grid,
    label: i32,
    points: &[[f64; 2]],
) -> Option<f64> {
    let width = |v: &[f64]| {
        let w = v.iter().fold(f64::NEG_INFINITY, |m, &a| m.max(a))
            - v.iter().fold(f64::INFINITY, |m, &a| m.min(a));
        if w > 0.0 {
            w
        } else {
            1.0
        }
    };
    let (wx, wy) = (width(grid.x), width(grid.y));
    let mut best: Option<f64> = None;
    for (k, &other) in image.labels.iter().enumerate() {
        if other == label || other == FAILED || other == INADMISSIBLE {
            continue;
        }
        let (x, y) = (grid.x[k % image.nx], grid.y[k / image.nx]);
        for p in points {
            let d = ((x - p[0]).abs() / wx).max((y - p[1]).abs() / wy);
            if best.is_none_or(|b| d < b) {
                best = Some(d);
            }
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(nx: usize, ny: usize, label: impl Fn(usize, usize) -> i32) -> BasinImage {
        let labels = (0..nx * ny).map(|k| label(k % nx, k / nx)).collect();
        BasinImage { nx, ny, labels }
    }

    /// One basin: no entropy. Two halves split along a box edge: none
    /// either; split through the middle of a column of boxes: those boxes
    /// hold ln 2 at an even split. A checkerboard of three labels: ln 3 in
    /// every box, fractal by the criterion.
    #[test]
    fn entropy_of_known_pictures() {
        let one = entropy(&image(10, 10, |_, _| 0), 5);
        assert_eq!((one.basin, one.boundary, one.boxes), (0.0, 0.0, 4));
        let edge = entropy(&image(10, 10, |i, _| i32::from(i >= 5)), 5);
        assert_eq!(edge.boundary_boxes, 0);
        let split = entropy(&image(8, 8, |i, _| i32::from(i >= 2)), 4);
        // Boxes (0, j) hold 8 cells of 0 and 8 of 1.
        assert_eq!(split.boundary_boxes, 2);
        assert!((split.boundary - std::f64::consts::LN_2).abs() < 1e-15);
        assert!((split.basin - std::f64::consts::LN_2 / 2.0).abs() < 1e-15);
        assert!(!split.fractal());
        let three = entropy(&image(9, 9, |i, j| ((i + j) % 3) as i32 - 1), 3);
        assert!((three.boundary - 3f64.ln()).abs() < 1e-12);
        assert!(three.fractal());
    }

    /// A start of the other basin 0.3 along x from the attractor's point,
    /// over a box 2 wide: a shock of 0.15.
    #[test]
    fn critical_shock_is_the_nearest_other_start() {
        let x = [0.0, 1.0, 2.0];
        let y = [0.0, 1.0];
        let picture = image(3, 2, |i, _| i32::from(i == 2));
        let grid = Grid { x: &x, y: &y };
        let shock = critical_shock(&picture, &grid, 0, &[[1.7, 0.0]]).unwrap();
        assert!((shock - 0.15).abs() < 1e-15, "{shock}");
        assert_eq!(critical_shock(&picture, &grid, 0, &[]), None);
    }

    /// A straight boundary: f(s) = s·(rows)/(pairs), α = 1 exactly; a
    /// single basin
    /// and a grid too small for two shifts have none; a boundary that
    /// crosses every cell pair at every shift (a checkerboard of period 1
    /// along x) has f constant in s at the odd shift and 0 at the even:
    /// only s = 1 fits, so none.
    #[test]
    fn uncertainty_exponent_of_known_pictures() {
        let edge = uncertainty(&image(64, 64, |i, _| i32::from(i >= 40))).unwrap();
        let shifts: Vec<usize> = edge.fractions.iter().map(|f| f.0).collect();
        assert_eq!(shifts, [1, 2, 4, 8]);
        for &(s, f) in &edge.fractions {
            // The starts i < 56 of each row (the largest shift is 8): s of
            // them straddle i = 40; along y none of the 56 × 64 differ.
            let want = (s * 64) as f64 / (2 * 56 * 64) as f64;
            assert!((f - want).abs() < 1e-15, "{s}: {f} against {want}");
        }
        assert!((edge.exponent - 1.0).abs() < 1e-12, "{}", edge.exponent);
        assert!((edge.boundary_dimension() - 1.0).abs() < 1e-12);
        assert_eq!(uncertainty(&image(64, 64, |_, _| 3)), None);
        assert_eq!(uncertainty(&image(15, 64, |i, _| i32::from(i > 3))), None);
        assert_eq!(uncertainty(&image(64, 64, |i, _| (i % 2) as i32)), None);
    }

    #[test]
    fn half_resolution_takes_every_second_start() {
        let picture = image(4, 4, |i, j| i32::from(i % 2 == 1 || j % 2 == 1));
        assert_eq!(half_resolution_fraction(&picture, 0), 1.0);
        assert!((fraction_error(0.25, 16) - (0.25f64 * 0.75 / 16.0).sqrt()).abs() < 1e-18);
    }
}
