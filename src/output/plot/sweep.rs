//! The sweep figure: the bifurcation diagram above the Lyapunov exponents,
//! both against the swept parameter (the layout of the seed paper's Fig. 3).

use std::ops::Range;
use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;

use super::legend::{draw_legend, Sample};
use super::panel::{draw_points, extent, frame, mesh, padded, segments, stacked};
use super::render::{pixels, write, Drawn, Figure};
use super::style::{
    exponent_colour, pretty, subscript, unit, DATA_COLOUR, EXPECTED_COLOUR, EXPECTED_WIDTH, FONT,
    GUIDE_COLOUR, LEGEND_ROW, MARGIN, SUM_COLOUR, SWEEP_SIZE, TITLE_PX, X_LABEL_AREA, X_PAD,
    Y_LABEL_AREA, Y_PAD,
};
use crate::error::Result;

/// One swept parameter's results, as the figure needs them.
pub struct SweepData {
    /// The figure's title, e.g. the scene name "seed-fig3".
    pub title: String,
    /// The swept parameter's name, e.g. "eta" (the x axis shows "η").
    pub parameter: String,
    /// The sweep values, one per lane, in any order.
    pub values: Vec<f64>,
    /// Per lane: λ₁ … λ_N (N = 1 to 4). NaN (a failed lane) and -∞ (a
    /// collapsed exponent) are left out of the figure.
    pub exponents: Vec<Vec<f64>>,
    /// Per lane: the sum of the exponents, NaN where unknown.
    pub sum: Vec<f64>,
    /// Per lane: the sum the volume law expects, NaN where unknown.
    pub expected_sum: Vec<f64>,
    /// Flows: exponents per unit time; maps: per iteration.
    pub per_unit_time: bool,
    /// The bifurcation diagram: (sweep value, first state coordinate) pairs.
    /// Empty: the figure has the exponent panel only.
    pub bifurcation: Vec<(f64, f64)>,
    /// The first state coordinate's name, e.g. "x".
    pub state_name: String,
}

/// Draws the sweep figure (bifurcation diagram above, exponents below,
/// sharing the x axis) as `<dir>/<stem>.png` and `<dir>/<stem>.svg`; returns
/// both paths. `dir` must exist.
pub fn sweep_figure(data: &SweepData, dir: &Path, stem: &str) -> Result<Vec<PathBuf>> {
    write(data, dir, stem)
}

/// The sweep figure as RGB pixels, row by row, `SWEEP_SIZE` of them.
pub fn sweep_pixels(data: &SweepData) -> Vec<u8> {
    pixels(data)
}

impl Figure for SweepData {
    const SIZE: (u32, u32) = SWEEP_SIZE;

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Drawn<DB> {
        root.fill(&WHITE)?;
        let body = root.titled(&self.title, (FONT, TITLE_PX))?;
        let diagram = || self.bifurcation.iter().map(|&(x, y)| (x, y, DATA_COLOUR));
        let axes = (self.parameter.as_str(), self.state_name.as_str());
        if self.exponents.is_empty() {
            // A run without exponents (`lyapunov = "none"`): the diagram
            // alone, over the values its points lie at.
            let x_range = padded(extent(self.bifurcation.iter().map(|p| p.0)), X_PAD);
            return draw_points(&body, diagram, axes, x_range, true);
        }
        // The legend has a row of its own, where it can hide no data.
        let (_, height) = body.dim_in_pixel();
        let (panels, legend) = body.split_vertically(height - LEGEND_ROW);
        draw_legend(&legend, &self.legend())?;
        let x_range = padded(extent(self.values.iter().copied()), X_PAD);
        if self.bifurcation.is_empty() {
            return draw_exponents(&panels, self, x_range);
        }
        let areas = stacked(&panels, 2);
        draw_points(&areas[0], diagram, axes, x_range.clone(), false)?;
        draw_exponents(&areas[1], self, x_range)
    }
}

impl SweepData {
    /// The number of exponents per lane.
    fn dimension(&self) -> usize {
        self.exponents.iter().map(Vec::len).max().unwrap_or(0)
    }

    /// The legend's entries, in reading order.
    fn legend(&self) -> Vec<(String, Sample)> {
        let exponents =
            (0..self.dimension()).map(|i| (format!("λ{}", subscript(i + 1)), Sample::Exponent(i)));
        exponents
            .chain([
                ("Σλ".to_owned(), Sample::Sum),
                ("expected Σλ (volume law)".to_owned(), Sample::Expected),
            ])
            .collect()
    }
}

/// The exponents, their sum and the sum the volume law expects.
pub(super) fn draw_exponents<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    data: &SweepData,
    x_range: Range<f64>,
) -> Drawn<DB> {
    let finite = data
        .exponents
        .iter()
        .flatten()
        .chain(&data.sum)
        .chain(&data.expected_sum)
        .copied();
    let y_range = padded(extent(finite), Y_PAD);
    let mut chart = ChartBuilder::on(area)
        .margin(MARGIN)
        .x_label_area_size(X_LABEL_AREA)
        .y_label_area_size(Y_LABEL_AREA)
        .build_cartesian_2d(x_range.clone(), y_range.clone())?;
    mesh(&mut chart)
        .x_desc(pretty(&data.parameter))
        .y_desc(format!("λ ({})", unit(data.per_unit_time)))
        .draw()?;
    if y_range.contains(&0.0) {
        let zero = [(x_range.start, 0.0), (x_range.end, 0.0)];
        chart.draw_series([PathElement::new(zero, GUIDE_COLOUR.stroke_width(2))])?;
    }

    // Lines join the lanes in the order of their values, whatever the order
    // of the sweep.
    let mut lanes: Vec<usize> = (0..data.values.len())
        .filter(|&k| data.values[k].is_finite())
        .collect();
    lanes.sort_by(|&a, &b| data.values[a].total_cmp(&data.values[b]));
    let curve = |y: &dyn Fn(usize) -> Option<f64>| -> Vec<(f64, f64)> {
        lanes
            .iter()
            .map(|&k| (data.values[k], y(k).unwrap_or(f64::NAN)))
            .collect()
    };

    for i in 0..data.dimension() {
        let colour = exponent_colour(i);
        let points = curve(&|k| data.exponents.get(k)?.get(i).copied());
        chart.draw_series(segments(&points).map(|s| PathElement::new(s, colour)))?;
        let finite = points.into_iter().filter(|p| p.1.is_finite());
        chart.draw_series(finite.map(|p| Circle::new(p, 2, colour.filled())))?;
    }
    let expected = curve(&|k| data.expected_sum.get(k).copied());
    let style = EXPECTED_COLOUR.stroke_width(EXPECTED_WIDTH);
    chart.draw_series(segments(&expected).map(|s| DashedPathElement::new(s, 14, 8, style)))?;
    let sum = curve(&|k| data.sum.get(k).copied());
    chart.draw_series(segments(&sum).map(|s| PathElement::new(s, SUM_COLOUR)))?;
    frame(&chart)
}
