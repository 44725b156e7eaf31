//! The sweep figure of many starts per value (`[attractors]`): the
//! bifurcation diagram, the exponents and the basin fractions over the swept
//! parameter, each attractor in its branch's colour.

use std::ops::Range;
use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;

use super::legend::{draw_legend, legend_width, marker, Sample};
use super::panel::{draw_axes, draw_points, extent, frame, padded, panel, stacked};
use super::render::{pixels, write, Drawn, Figure};
use super::style::{
    subscript, unit, ATTRACTOR_SWEEP_SIZE, DATA_COLOUR, FAILED_COLOUR, FONT, GUIDE_COLOUR,
    LEGEND_ROW, MARGIN, MARKER_RADIUS, TITLE_PX, X_PAD, Y_PAD,
};
use crate::error::Result;

/// The branches' colours, cycled by branch id: the dark blue of a single
/// start's figure, then the Okabe–Ito palette (which colour-blind readers
/// can tell apart) without its yellow, too pale on white, and a brown. No
/// grey: grey is a failed lane's.
pub(super) const BRANCH_COLOURS: [RGBColor; 8] = [
    DATA_COLOUR,
    RGBColor(213, 94, 0),
    RGBColor(0, 158, 115),
    RGBColor(204, 121, 167),
    RGBColor(230, 159, 0),
    RGBColor(86, 180, 233),
    BLACK,
    RGBColor(140, 81, 10),
];

/// The most branches the legend names (it names fewer where they do not fit
/// on its row); the colours repeat beyond the palette anyway.
pub(super) const LEGEND_BRANCHES: usize = 8;

/// A one-parameter sweep with many starts per value (`[attractors]`): the
/// attractors found at each value, each on its branch (one attractor
/// followed across the values).
pub struct AttractorSweepData {
    /// The figure's title.
    pub title: String,
    /// The swept parameter's name.
    pub parameter: String,
    /// The swept values, in any order: the x axis spans them.
    pub values: Vec<f64>,
    /// The bifurcation diagram: (sweep value, first state coordinate, the
    /// branch of the lane the point is from) triples, the branch `None` for
    /// a failed lane's (drawn grey). Empty: no diagram panel.
    pub bifurcation: Vec<(f64, f64, Option<u64>)>,
    /// The branches, in the order they are drawn (the later on top).
    pub branches: Vec<Branch>,
    /// Flows: exponents per unit time; maps: per iteration.
    pub per_unit_time: bool,
    /// The first state coordinate's name.
    pub state_name: String,
}

/// One branch of attractors: where it has one, and that attractor's
/// exponents and basin there.
#[derive(Clone, Debug, PartialEq)]
pub struct Branch {
    /// The branch's id (its colour is chosen by it).
    pub id: u64,
    /// The swept values it has an attractor at, ascending.
    pub values: Vec<f64>,
    /// Per value: λ₁ … λ_N, empty when the run computed no exponents (then
    /// the figure has no exponent panel).
    pub exponents: Vec<Vec<f64>>,
    /// Per value: the fraction of the value's starts that end on it.
    pub basin: Vec<f64>,
}

/// Draws the sweep figure of many starts per value: the bifurcation diagram,
/// the exponents and the basin fractions, one above the other over the
/// swept parameter, each attractor in its branch's colour, as
/// `<dir>/<stem>.png` and `<dir>/<stem>.svg`; returns both paths. `dir` must
/// exist.
pub fn attractor_figure(data: &AttractorSweepData, dir: &Path, stem: &str) -> Result<Vec<PathBuf>> {
    write(data, dir, stem)
}

/// The attractor sweep figure as RGB pixels, `ATTRACTOR_SWEEP_SIZE` of them.
pub fn attractor_pixels(data: &AttractorSweepData) -> Vec<u8> {
    pixels(data)
}

/// The panels of the figure with attractors, top to bottom.
#[derive(Clone, Copy)]
pub(super) enum AttractorPanel {
    Diagram,
    Exponents,
    Basins,
}

impl Figure for AttractorSweepData {
    const SIZE: (u32, u32) = ATTRACTOR_SWEEP_SIZE;

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Drawn<DB> {
        root.fill(&WHITE)?;
        let body = root.titled(&self.title, (FONT, TITLE_PX))?;
        let (_, height) = body.dim_in_pixel();
        let (panels, legend) = body.split_vertically(height - LEGEND_ROW);
        draw_legend(&legend, &self.legend(&legend)?)?;
        let x_range = padded(extent(self.values.iter().copied()), X_PAD);
        let mut shown = Vec::new();
        if !self.bifurcation.is_empty() {
            shown.push(AttractorPanel::Diagram);
        }
        if self.dimension() > 0 {
            shown.push(AttractorPanel::Exponents);
        }
        shown.push(AttractorPanel::Basins);
        let areas = stacked(&panels, shown.len());
        for (k, (kind, area)) in shown.iter().zip(&areas).enumerate() {
            let labelled = k + 1 == shown.len();
            let x_range = x_range.clone();
            match kind {
                AttractorPanel::Diagram => {
                    // A failed lane's points first, so that an attractor's
                    // own are drawn over them.
                    let diagram = || {
                        let failed = self.bifurcation.iter().filter(|p| p.2.is_none());
                        let found = self.bifurcation.iter().filter(|p| p.2.is_some());
                        failed.chain(found).map(|&(x, y, branch)| {
                            (x, y, branch.map_or(FAILED_COLOUR, branch_colour))
                        })
                    };
                    let axes = (self.parameter.as_str(), self.state_name.as_str());
                    draw_points(area, diagram, axes, x_range, labelled)?;
                }
                AttractorPanel::Exponents => self.draw_exponents(area, x_range, labelled)?,
                AttractorPanel::Basins => self.draw_basins(area, x_range, labelled)?,
            }
        }
        Ok(())
    }
}

impl AttractorSweepData {
    /// The number of exponents per attractor.
    fn dimension(&self) -> usize {
        self.branches
            .iter()
            .flat_map(|b| &b.exponents)
            .map(Vec::len)
            .max()
            .unwrap_or(0)
    }

    /// The legend: the branches' colours (the first ones, as many as fit
    /// on the row beside the other entries), which marker is which exponent,
    /// and grey where a lane failed.
    fn legend<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
    ) -> std::result::Result<Vec<(String, Sample)>, DrawingAreaErrorKind<DB::ErrorType>> {
        let mut others = Vec::new();
        let dimension = self.dimension();
        if dimension > 0 {
            let filled = |filled| Sample::Marker {
                colour: BLACK,
                filled,
            };
            others.push(("λ₁".to_owned(), filled(true)));
            match dimension {
                1 => {}
                2 => others.push(("λ₂".to_owned(), filled(false))),
                n => others.push((format!("λ₂ … λ{}", subscript(n)), filled(false))),
            }
        }
        if self.bifurcation.iter().any(|p| p.2.is_none()) {
            let colour = FAILED_COLOUR;
            others.push((
                "failed lane".to_owned(),
                Sample::Marker {
                    colour,
                    filled: true,
                },
            ));
        }
        let (width, _) = area.dim_in_pixel();
        let mut named = self.branches.len().min(LEGEND_BRANCHES);
        loop {
            let mut entries: Vec<(String, Sample)> = self.branches[..named]
                .iter()
                .map(|b| {
                    let colour = branch_colour(b.id);
                    (
                        format!("branch {}", b.id),
                        Sample::Marker {
                            colour,
                            filled: true,
                        },
                    )
                })
                .collect();
            if named < self.branches.len() {
                entries.push((format!("… {} in all", self.branches.len()), Sample::Text));
            }
            entries.extend(others.iter().cloned());
            if named <= 1 || legend_width(area, &entries)? <= width as i32 - 2 * MARGIN as i32 {
                return Ok(entries);
            }
            named -= 1;
        }
    }

    /// Each attractor's exponents at its value in its branch's colour: λ₁
    /// filled, the others open, so that coexisting attractors show as
    /// colours side by side and hysteresis as two colours over one
    /// interval.
    fn draw_exponents<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        x_range: Range<f64>,
        labelled: bool,
    ) -> Drawn<DB> {
        let finite = self
            .branches
            .iter()
            .flat_map(|b| b.exponents.iter().flatten());
        let y_range = padded(extent(finite.copied()), Y_PAD);
        let mut chart = panel(area, x_range.clone(), y_range.clone(), labelled)?;
        let y_name = format!("λ ({})", unit(self.per_unit_time));
        draw_axes(&mut chart, &self.parameter, &y_name, labelled)?;
        if y_range.contains(&0.0) {
            let zero = [(x_range.start, 0.0), (x_range.end, 0.0)];
            chart.draw_series([PathElement::new(zero, GUIDE_COLOUR.stroke_width(2))])?;
        }
        for branch in &self.branches {
            let colour = branch_colour(branch.id);
            let markers = branch
                .values
                .iter()
                .zip(&branch.exponents)
                .flat_map(|(&v, l)| {
                    l.iter()
                        .enumerate()
                        .filter(move |&(_, e)| v.is_finite() && e.is_finite())
                        .map(move |(i, &e)| marker((v, e), MARKER_RADIUS, colour, i == 0))
                });
            chart.draw_series(markers)?;
        }
        frame(&chart)
    }

    /// Each attractor's basin fraction at its value, in its branch's colour.
    fn draw_basins<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        x_range: Range<f64>,
        labelled: bool,
    ) -> Drawn<DB> {
        let mut chart = panel(area, x_range, padded(Some((0.0, 1.0)), Y_PAD), labelled)?;
        draw_axes(&mut chart, &self.parameter, "basin fraction", labelled)?;
        for branch in &self.branches {
            let colour = branch_colour(branch.id);
            let points = branch.values.iter().zip(&branch.basin);
            let finite = points.filter(|(v, b)| v.is_finite() && b.is_finite());
            chart
                .draw_series(finite.map(|(&v, &b)| marker((v, b), MARKER_RADIUS, colour, true)))?;
        }
        frame(&chart)
    }
}

/// A branch's colour: the palette cycled by its id.
pub(super) fn branch_colour(id: u64) -> RGBColor {
    BRANCH_COLOURS[(id % BRANCH_COLOURS.len() as u64) as usize]
}
