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
//! - Minimal critical shock of an attractor: the smallest kick of its
//!   state, in the box's scaled max norm (each state's change over the
//!   box's width along it), that sends it to another attractor, searched
//!   over the image itself: the nearest start, from any of the attractor's
//!   points, labelled with another attractor. Its resolution is the grid's
//!   (half a cell's width either way: the true boundary lies between that
//!   start and its neighbour); only the image's two states are kicked.
//!
//! Lanes that failed, or whose motion the method does not resolve, are
//! labelled [`FAILED`] and count as one more label in the entropy.

use super::Attractors;

/// The label of a start whose lane failed or is not resolved.
pub const FAILED: i32 = -1;

/// One value's labels over the grid: `labels[j * nx + i]` for the start at
/// the i-th value of the first state and the j-th of the second.
#[derive(Clone, Debug, PartialEq)]
pub struct BasinImage {
    pub nx: usize,
    pub ny: usize,
    pub labels: Vec<i32>,
}

/// The labels of grid point `point`'s `nx × ny` starts: the branch of each
/// start's attractor, [`FAILED`] for a lone lane.
pub fn image(found: &Attractors, point: usize, (nx, ny): (usize, usize)) -> BasinImage {
    let value = &found.values[point];
    let labels = (0..nx * ny)
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
    let mut counts: Vec<(i32, usize)> = Vec::new();
    for j in 0..by {
        for i in 0..bx {
            counts.clear();
            for row in j * side..(j + 1) * side {
                for &label in &image.labels[row * image.nx + i * side..][..side] {
                    match counts.iter_mut().find(|(l, _)| *l == label) {
                        Some((_, n)) => *n += 1,
                        None => counts.push((label, 1)),
                    }
                }
            }
            let cells = (side * side) as f64;
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
    let boxes = bx * by;
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
            all += 1;
            on += usize::from(image.labels[j * image.nx + i] == label);
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
        if other == label || other == FAILED {
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

    #[test]
    fn half_resolution_takes_every_second_start() {
        let picture = image(4, 4, |i, j| i32::from(i % 2 == 1 || j % 2 == 1));
        assert_eq!(half_resolution_fraction(&picture, 0), 1.0);
        assert!((fraction_error(0.25, 16) - (0.25f64 * 0.75 / 16.0).sqrt()).abs() < 1e-18);
    }
}
