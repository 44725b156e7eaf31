//! The basins of one value's attractors over a grid of starts spanning two
//! states (`attractors.basins`): each start's cell coloured by the branch
//! of the attractor it ended on (the colours of the sweep figure's
//! branches), grey where the lane failed, dark where the start lies outside
//! the admissible states (behind a wall); the colour bar names each
//! branch, the caption its period, impacts, λ1 and basin fraction.

use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;

use super::attractor_sweep::branch_colour;
use super::grid::{draw_caption, draw_cells, draw_colour_bar, map_layout};
use super::render::{pixels, write, Drawn, Figure};
use super::style::{FAILED_COLOUR, HEAT_MAP_SIZE, INADMISSIBLE_COLOUR};
use crate::attractor::basins::INADMISSIBLE;
use crate::error::Result;

/// One value's basin image.
pub struct BasinData {
    pub title: String,
    /// The names of the states along x and y.
    pub x_name: String,
    pub y_name: String,
    /// The grid's values of the two states (nx and ny of them).
    pub x: Vec<f64>,
    pub y: Vec<f64>,
    /// The label of the start at (x\[i\], y\[j\]) is `labels[j * nx + i]`:
    /// a branch, or a negative number for a lane that failed.
    pub labels: Vec<i32>,
    /// Each label shown, in the colour bar's order, with what the caption
    /// says of it.
    pub entries: Vec<(i32, String)>,
}

/// Draws the basin image as `<dir>/<stem>.png` and `<dir>/<stem>.svg`;
/// returns both paths.
///
/// # Panics
/// If `labels` does not hold one label per start.
pub fn basin_map(data: &BasinData, dir: &Path, stem: &str) -> Result<Vec<PathBuf>> {
    write(data, dir, stem)
}

/// The basin image as RGB pixels, `HEAT_MAP_SIZE` of them.
pub fn basin_map_pixels(data: &BasinData) -> Vec<u8> {
    pixels(data)
}

/// A label's colour: its branch's, grey for a failed lane, dark for a
/// start outside the admissible states.
pub fn label_colour(label: i32) -> RGBColor {
    if label == INADMISSIBLE {
        INADMISSIBLE_COLOUR
    } else if label < 0 {
        FAILED_COLOUR
    } else {
        branch_colour(label as u64)
    }
}

impl Figure for BasinData {
    const SIZE: (u32, u32) = HEAT_MAP_SIZE;

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Drawn<DB> {
        let (nx, ny) = (self.x.len(), self.y.len());
        assert_eq!(self.labels.len(), nx * ny, "one label per start");
        let (map, bar, caption) = map_layout(root, &self.title)?;
        let axes = (self.x_name.as_str(), self.y_name.as_str());
        draw_cells(&map, axes, (&self.x, &self.y), |k| {
            label_colour(self.labels[k])
        })?;
        let name = |label: i32| {
            if label == INADMISSIBLE {
                "inadmissible".to_owned()
            } else if label < 0 {
                "failed".to_owned()
            } else {
                format!("branch {label}")
            }
        };
        let bands = self.entries.iter().enumerate().map(|(k, &(label, _))| {
            let k = k as f64;
            (k - 0.5..k + 0.5, label_colour(label))
        });
        let labels: Vec<i32> = self.entries.iter().map(|e| e.0).collect();
        let tick = |v: &f64| {
            let k = v.round();
            match labels.get(k as usize) {
                Some(&label) if (v - k).abs() < 1e-9 && k >= 0.0 => name(label),
                _ => String::new(),
            }
        };
        let range = -0.5..self.entries.len().max(1) as f64 - 0.5;
        draw_colour_bar(&bar, range, "attractor", &tick, bands)?;
        let text: Vec<&str> = self.entries.iter().map(|e| e.1.as_str()).collect();
        draw_caption(&caption, &text.join("; "))
    }
}
