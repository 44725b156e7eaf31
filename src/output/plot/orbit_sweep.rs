//! The orbits figure of a run with `[orbits]`: the sweep's bifurcation
//! diagram (its lanes' points, faint) with the traced branches over it,
//! stable stretches solid, unstable dashed, and every located bifurcation
//! marked and labelled (LP fold, PD period doubling, NS Neimark–Sacker,
//! GR grazing, SL sliding, EC a change of the orbit's events).

use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;

use super::panel::{draw_points, extent, padded, panel, segments};
use super::render::{write, Drawn, Figure};
use super::style::{
    exponent_colour, FONT, GUIDE_COLOUR, MARKER_RADIUS, SWEEP_SIZE, TICK_LABEL_PX, TITLE_PX, X_PAD,
    Y_PAD,
};
use crate::error::Result;

/// What the orbits figure draws.
pub struct OrbitSweepData {
    pub title: String,
    pub parameter: String,
    /// The first state coordinate's name.
    pub state_name: String,
    /// The sweep's points: (value, first coordinate).
    pub points: Vec<(f64, f64)>,
    /// Each branch's points in order: (parameter, first coordinate,
    /// stable).
    pub branches: Vec<Vec<(f64, f64, bool)>>,
    /// Each bifurcation: (parameter, first coordinate, label).
    pub bifurcations: Vec<(f64, f64, String)>,
}

/// Draws the figure as `<dir>/<stem>.png` and `.svg`; returns both paths.
pub fn orbit_figure(data: &OrbitSweepData, dir: &Path, stem: &str) -> Result<Vec<PathBuf>> {
    write(data, dir, stem)
}

/// The sweep's points, light, so that the branches read over them.
const POINT_COLOUR: RGBColor = RGBColor(170, 180, 215);

impl Figure for OrbitSweepData {
    const SIZE: (u32, u32) = SWEEP_SIZE;

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Drawn<DB> {
        root.fill(&WHITE)?;
        let body = root.titled(&self.title, (FONT, TITLE_PX))?;
        let on_branches = self.branches.iter().flatten().map(|p| (p.0, p.1));
        let xs = self
            .points
            .iter()
            .map(|p| p.0)
            .chain(on_branches.clone().map(|p| p.0));
        let x_range = padded(extent(xs), X_PAD);
        // The branches' points join the diagram's (under the lines), so
        // that its y range holds them.
        let all = || {
            self.points
                .iter()
                .map(|&(x, y)| (x, y, POINT_COLOUR))
                .chain(on_branches.clone().map(|(x, y)| (x, y, GUIDE_COLOUR)))
        };
        let axes = (self.parameter.as_str(), self.state_name.as_str());
        draw_points(&body, all, axes, x_range.clone(), true)?;
        let finite = all().filter(|p| p.0.is_finite() && p.1.is_finite());
        let y_range = padded(extent(finite.map(|p| p.1)), Y_PAD);
        let mut chart = panel(&body, x_range, y_range, true)?;
        for (b, branch) in self.branches.iter().enumerate() {
            let colour = exponent_colour(b % 4).stroke_width(3);
            // Runs of one stability, each sharing its end with the next.
            let mut run: Vec<(f64, f64)> = Vec::new();
            let mut stable = branch.first().is_some_and(|p| p.2);
            for &(x, y, s) in branch {
                run.push((x, y));
                if s != stable {
                    draw_run(&mut chart, &run, stable, colour)?;
                    run = vec![(x, y)];
                    stable = s;
                }
            }
            draw_run(&mut chart, &run, stable, colour)?;
        }
        let label = (FONT, TICK_LABEL_PX).into_font().color(&BLACK);
        for (x, y, text) in &self.bifurcations {
            if !(x.is_finite() && y.is_finite()) {
                continue;
            }
            chart.draw_series([Circle::new((*x, *y), MARKER_RADIUS + 2, BLACK.filled())])?;
            chart.draw_series([Text::new(text.clone(), (*x, *y), label.clone())])?;
        }
        Ok(())
    }
}

type Chart<'a, DB> = super::panel::Chart<'a, DB>;

fn draw_run<DB: DrawingBackend>(
    chart: &mut Chart<'_, DB>,
    run: &[(f64, f64)],
    stable: bool,
    style: ShapeStyle,
) -> Drawn<DB> {
    for piece in segments(run) {
        if stable {
            chart.draw_series([PathElement::new(piece, style)])?;
        } else {
            chart.draw_series([DashedPathElement::new(piece, 12, 8, style)])?;
        }
    }
    Ok(())
}
