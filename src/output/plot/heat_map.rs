//! The heat map of λ₁ over a two-parameter grid, with its colour bar.

use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;

use super::grid::{draw_caption, draw_cells, draw_colour_bar, map_layout};
use super::panel::tick;
use super::render::{pixels, write, Drawn, Figure};
use super::style::{along, unit, FAILED_COLOUR, HEAT_MAP_SIZE};
use crate::error::Result;

/// ColorBrewer's RdBu (C. Brewer, colorbrewer2.org) from -1 to +1: blue for
/// negative λ₁, near-white at zero, red for positive, evenly spaced stops.
pub(super) const RED_BLUE: [RGBColor; 11] = [
    RGBColor(5, 48, 97),
    RGBColor(33, 102, 172),
    RGBColor(67, 147, 195),
    RGBColor(146, 197, 222),
    RGBColor(209, 229, 240),
    RGBColor(247, 247, 247),
    RGBColor(253, 219, 199),
    RGBColor(244, 165, 130),
    RGBColor(214, 96, 77),
    RGBColor(178, 24, 43),
    RGBColor(103, 0, 31),
];

/// A two-parameter sweep's λ₁ on a grid.
pub struct GridData {
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
    /// λ₁ at (x\[i\], y\[j\]) is `lambda1[j * nx + i]` (x fastest); NaN marks a
    /// failed lane, drawn grey.
    pub lambda1: Vec<f64>,
    /// Flows: λ₁ per unit time; maps: per iteration.
    pub per_unit_time: bool,
}

/// Draws the heat map of λ₁ over the grid, with a colour bar, as
/// `<dir>/<stem>.png` and `<dir>/<stem>.svg`; returns both paths. `dir` must
/// exist.
///
/// The colours diverge from near-white at zero: blue for negative λ₁, red for
/// positive, saturating at ± the 99th percentile of |λ₁| (see
/// `colour_limit`); failed lanes are grey.
///
/// # Panics
/// If `lambda1` does not hold one value per grid point.
pub fn heat_map(data: &GridData, dir: &Path, stem: &str) -> Result<Vec<PathBuf>> {
    write(data, dir, stem)
}

/// The heat map as RGB pixels, row by row, `HEAT_MAP_SIZE` of them.
///
/// # Panics
/// If `lambda1` does not hold one value per grid point.
pub fn heat_map_pixels(data: &GridData) -> Vec<u8> {
    pixels(data)
}

impl Figure for GridData {
    const SIZE: (u32, u32) = HEAT_MAP_SIZE;

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Drawn<DB> {
        let (nx, ny) = (self.x.len(), self.y.len());
        assert_eq!(
            self.lambda1.len(),
            nx * ny,
            "λ1 holds one value per grid point ({nx} × {ny})"
        );
        let (map, bar, caption) = map_layout(root, &self.title)?;
        let (limit, chosen_as) = colour_limit(&self.lambda1);
        let axes = (self.x_name.as_str(), self.y_name.as_str());
        draw_cells(&map, axes, (&self.x, &self.y), |k| {
            diverging(self.lambda1[k], limit)
        })?;

        draw_lambda_bar(&bar, limit, self.per_unit_time)?;
        draw_caption(&caption, &self.note(limit, chosen_as))
    }
}

impl GridData {
    /// What the caption under the map says: where the colours end and,
    /// if any lane failed, what grey means.
    pub(super) fn note(&self, limit: f64, chosen_as: &str) -> String {
        let mut note = format!("colours saturate at ±{} ({chosen_as})", three_digits(limit));
        if self.lambda1.iter().any(|v| v.is_nan()) {
            note.push_str("; grey: failed lane");
        }
        note
    }
}

/// λ₁'s colour bar: the same height as the map, its scale on the right.
pub(super) fn draw_lambda_bar<DB: DrawingBackend>(
    bar: &DrawingArea<DB, Shift>,
    limit: f64,
    per_unit_time: bool,
) -> Drawn<DB> {
    const BANDS: usize = 256;
    let bands = (0..BANDS).map(|band| {
        let edge = |b: usize| limit * (2.0 * b as f64 / BANDS as f64 - 1.0);
        let (low, high) = (edge(band), edge(band + 1));
        (low..high, diverging((low + high) / 2.0, limit))
    });
    let name = format!("λ₁ ({})", unit(per_unit_time));
    draw_colour_bar(bar, -limit..limit, &name, &tick, bands)
}

/// A positive `value` to three significant digits.
pub(super) fn three_digits(value: f64) -> String {
    let decimals = (2 - value.log10().floor() as i32).max(0) as usize;
    format!("{value:.decimals$}")
}

/// The heat map's colour limit, and how it was chosen: the 99th percentile
/// of |λ₁| over finite values rather than the maximum, so that one outlying
/// lane (a grazing one, say) does not wash every other cell out to white.
/// Cells beyond it saturate but keep their sign's colour, and the sign (chaos
/// or order) is what the map is read for.
pub(super) fn colour_limit(lambda1: &[f64]) -> (f64, &'static str) {
    let mut magnitudes: Vec<f64> = lambda1
        .iter()
        .filter(|v| v.is_finite())
        .map(|v| v.abs())
        .collect();
    magnitudes.sort_by(f64::total_cmp);
    // The nearest-rank percentile.
    let rank = (0.99 * magnitudes.len() as f64).ceil() as usize;
    let percentile = magnitudes.get(rank.saturating_sub(1)).copied();
    let largest = magnitudes.last().copied();
    match (percentile, largest) {
        (Some(limit), _) if limit > 0.0 => (limit, "the 99th percentile of |λ₁|"),
        (_, Some(limit)) if limit > 0.0 => (limit, "the largest |λ₁|"),
        _ => (1.0, "no finite λ₁ differs from 0"),
    }
}

/// The colour of `value` on the diverging scale from -`limit` (blue) to
/// +`limit` (red); ±∞ saturate, NaN is a failed lane.
pub(super) fn diverging(value: f64, limit: f64) -> RGBColor {
    if value.is_nan() {
        return FAILED_COLOUR;
    }
    along(&RED_BLUE, ((value / limit).clamp(-1.0, 1.0) + 1.0) / 2.0)
}
