//! The map of how many attractors each point of a two-parameter grid has
//! (`[attractors]`), with its colour bar.

use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;

use super::grid::{draw_caption, draw_cells, draw_colour_bar, map_layout};
use super::render::{pixels, write, Drawn, Figure};
use super::style::{along, FAILED_COLOUR, HEAT_MAP_SIZE};
use crate::error::Result;

/// ColorBrewer's YlGnBu without its palest stop (too close to the page), for
/// the attractor counts: one attractor light, many dark.
pub(super) const COUNT_SCALE: [RGBColor; 8] = [
    RGBColor(237, 248, 177),
    RGBColor(199, 233, 180),
    RGBColor(127, 205, 187),
    RGBColor(65, 182, 196),
    RGBColor(29, 145, 192),
    RGBColor(34, 94, 168),
    RGBColor(37, 52, 148),
    RGBColor(8, 29, 88),
];

/// A two-parameter sweep with `[attractors]`: how many attractors each grid
/// point has.
pub struct CountData {
    /// The figure's title.
    pub title: String,
    /// The name of the parameter along the x axis.
    pub x_name: String,
    /// The name of the parameter along the y axis.
    pub y_name: String,
    /// The grid's x values (nx of them, in any order).
    pub x: Vec<f64>,
    /// The grid's y values (ny of them, in any order).
    pub y: Vec<f64>,
    /// The attractors at (x\[i\], y\[j\]) are `counts[j * nx + i]` (x
    /// fastest); 0, where every start failed, is drawn grey.
    pub counts: Vec<usize>,
}

/// Draws the map of the attractors found per grid point, with its colour
/// bar, as `<dir>/<stem>.png` and `<dir>/<stem>.svg`; returns both paths.
/// `dir` must exist.
///
/// # Panics
/// If `counts` does not hold one count per grid point.
pub fn attractor_map(data: &CountData, dir: &Path, stem: &str) -> Result<Vec<PathBuf>> {
    write(data, dir, stem)
}

/// The attractor map as RGB pixels, `HEAT_MAP_SIZE` of them.
///
/// # Panics
/// If `counts` does not hold one count per grid point.
pub fn attractor_map_pixels(data: &CountData) -> Vec<u8> {
    pixels(data)
}

impl Figure for CountData {
    const SIZE: (u32, u32) = HEAT_MAP_SIZE;

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Drawn<DB> {
        let (nx, ny) = (self.x.len(), self.y.len());
        assert_eq!(
            self.counts.len(),
            nx * ny,
            "one attractor count per grid point ({nx} × {ny})"
        );
        let (map, bar, caption) = map_layout(root, &self.title)?;
        let most = self.counts.iter().copied().max().unwrap_or(0).max(1);
        let axes = (self.x_name.as_str(), self.y_name.as_str());
        draw_cells(&map, axes, (&self.x, &self.y), |k| {
            count_colour(self.counts[k], most)
        })?;

        // One band per count, from the fewest to the most, each labelled
        // with its whole number (the ticks between them unlabelled).
        let fewest = self.counts.iter().copied().min().unwrap_or(1).min(most);
        let bands = (fewest..=most).map(|n| {
            let n_f64 = n as f64;
            (n_f64 - 0.5..n_f64 + 0.5, count_colour(n, most))
        });
        let whole = |v: &f64| {
            let n = v.round();
            if (v - n).abs() < 1e-9 {
                format!("{n}")
            } else {
                String::new()
            }
        };
        let range = fewest as f64 - 0.5..most as f64 + 0.5;
        draw_colour_bar(&bar, range, "attractors", &whole, bands)?;

        let mut note = "attractors found at each point, over all its starts".to_owned();
        if fewest == 0 {
            note.push_str("; grey: none (every start failed)");
        }
        draw_caption(&caption, &note)
    }
}

/// The colour of `n` attractors on the sequential scale up to `most`; none
/// is grey (every start failed).
pub(super) fn count_colour(n: usize, most: usize) -> RGBColor {
    match n {
        0 => FAILED_COLOUR,
        _ if most <= 1 => COUNT_SCALE[0],
        _ => along(&COUNT_SCALE, (n - 1) as f64 / (most - 1) as f64),
    }
}
