//! A panel's axes and what every panel draws the same way: its chart and
//! mesh, the frame around it, the data's ranges, panels stacked over one
//! axis, and a bifurcation diagram's points.

use std::ops::Range;

use plotters::chart::MeshStyle;
use plotters::coord::ranged1d::ValueFormatter;
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;

use super::render::Drawn;
use super::style::{
    pretty, AXIS_LABEL_PX, FONT, GUIDE_COLOUR, MARGIN, TICKS_ONLY_AREA, TICK_LABEL_PX,
    X_LABEL_AREA, Y_LABEL_AREA, Y_PAD,
};

/// A panel with numbers on both axes.
pub(super) type Chart<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// `n` panels stacked over a shared x axis, with plots of equal height: the
/// lowest also holds the axis's labels, the others its ticks only.
pub(super) fn stacked<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    n: usize,
) -> Vec<DrawingArea<DB, Shift>> {
    let (_, height) = area.dim_in_pixel();
    let plot = (height + TICKS_ONLY_AREA - X_LABEL_AREA) / n as u32 - TICKS_ONLY_AREA;
    let mut panels = Vec::with_capacity(n);
    let mut rest = area.clone();
    for _ in 1..n {
        let (panel, below) = rest.split_vertically(plot + TICKS_ONLY_AREA);
        panels.push(panel);
        rest = below;
    }
    panels.push(rest);
    panels
}

/// A panel's chart over `x_range` and `y_range`; `labelled`: with room for
/// the x axis's labels (when no panel below carries them).
pub(super) fn panel<'a, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
    x_range: Range<f64>,
    y_range: Range<f64>,
    labelled: bool,
) -> std::result::Result<Chart<'a, DB>, DrawingAreaErrorKind<DB::ErrorType>> {
    ChartBuilder::on(area)
        .margin(MARGIN)
        .x_label_area_size(if labelled {
            X_LABEL_AREA
        } else {
            TICKS_ONLY_AREA
        })
        .y_label_area_size(Y_LABEL_AREA)
        .build_cartesian_2d(drawable(x_range), drawable(y_range))
}

/// `range` as an axis can draw it. plotters looks for its ticks by
/// halving a step until enough fit, which never ends on an axis whose
/// end or span is not finite (a swept value near f64::MAX, padded) or
/// whose span is below the rounding of its values (two neighbouring
/// floats): the ends are held within ±f64::MAX/4, so the span stays
/// finite, and a span under 1e-12 of the values' magnitude (a few
/// thousand roundings) is widened to that about its middle. An ordinary range comes back as it is.
pub(super) fn drawable(range: Range<f64>) -> Range<f64> {
    const LIMIT: f64 = f64::MAX / 4.0;
    let (low, high) = (
        range.start.clamp(-LIMIT, LIMIT),
        range.end.clamp(-LIMIT, LIMIT),
    );
    let magnitude = low.abs().max(high.abs());
    if magnitude == 0.0 {
        return -1.0..1.0;
    }
    let least = 1e-12 * magnitude;
    if high - low >= least {
        return low..high;
    }
    let middle = 0.5 * low + 0.5 * high;
    middle - 0.5 * least..middle + 0.5 * least
}

/// A panel's axes: the y axis named `y_name`, the x axis the swept
/// `parameter` where `labelled`, ticks only otherwise.
pub(super) fn draw_axes<DB: DrawingBackend>(
    chart: &mut Chart<'_, DB>,
    parameter: &str,
    y_name: &str,
    labelled: bool,
) -> Drawn<DB> {
    let mut axes = mesh(chart);
    axes.y_desc(y_name);
    if labelled {
        axes.x_desc(pretty(parameter));
    } else {
        axes.x_label_formatter(&|_| String::new());
    }
    axes.draw()
}

/// A bifurcation diagram: every point one pixel of its colour, the later
/// point's where two share a pixel. `axes` names the swept parameter and the
/// state.
///
/// The points are first gathered on the panel's pixel grid and each column's
/// runs of pixels of one colour drawn as one rectangle, so that the SVG holds
/// a few thousand rectangles rather than one per point (hundreds of
/// thousands), and the PNG is the same drawing.
pub(super) fn draw_points<DB: DrawingBackend, P: Iterator<Item = (f64, f64, RGBColor)>>(
    area: &DrawingArea<DB, Shift>,
    points: impl Fn() -> P,
    (parameter, state_name): (&str, &str),
    x_range: Range<f64>,
    labelled: bool,
) -> Drawn<DB> {
    let finite = || points().filter(|(x, y, _)| x.is_finite() && y.is_finite());
    let y_range = padded(extent(finite().map(|p| p.1)), Y_PAD);
    let mut chart = panel(area, x_range, y_range, labelled)?;
    draw_axes(&mut chart, parameter, state_name, labelled)?;

    let plot = chart.plotting_area();
    let (width, height) = plot.dim_in_pixel();
    let (width, height) = (width as i32, height as i32);
    let (left, top) = plot.get_base_pixel();
    // Column by column, so that each column's runs lie together.
    let mut lit: Vec<Option<RGBColor>> = vec![None; (width * height) as usize];
    for (x, y, colour) in finite() {
        let (x, y) = chart.backend_coord(&(x, y));
        let (column, row) = (x - left, y - top);
        if (0..width).contains(&column) && (0..height).contains(&row) {
            lit[(column * height + row) as usize] = Some(colour);
        }
    }
    let canvas = plot.strip_coord_spec();
    for (column, rows) in lit.chunks_exact(height as usize).enumerate() {
        let column = column as i32;
        let mut row = 0;
        while let Some(&pixel) = rows.get(row) {
            let first = row;
            while rows.get(row) == Some(&pixel) {
                row += 1;
            }
            if let Some(colour) = pixel {
                let corners = [(column, first as i32), (column + 1, row as i32)];
                canvas.draw(&Rectangle::new(corners, colour.filled()))?;
            }
        }
    }
    frame(&chart)
}

/// The mesh every panel shares: readable labels, a light grid of major ticks.
pub(super) fn mesh<'a, 'b, DB: DrawingBackend>(
    chart: &'b mut Chart<'a, DB>,
) -> MeshStyle<'a, 'b, RangedCoordf64, RangedCoordf64, DB> {
    let mut mesh = chart.configure_mesh();
    mesh.label_style((FONT, TICK_LABEL_PX))
        .axis_desc_style((FONT, AXIS_LABEL_PX))
        .x_label_formatter(&tick)
        .y_label_formatter(&tick)
        .bold_line_style(GUIDE_COLOUR.mix(0.5))
        .light_line_style(TRANSPARENT);
    mesh
}

/// plotters' tick label, without the minus of a tick that misses zero by a
/// rounding error ("-0.0").
pub(super) fn tick(value: &f64) -> String {
    let label = RangedCoordf64::format(value);
    match label.strip_prefix('-') {
        Some(magnitude) if magnitude.chars().all(|c| c == '0' || c == '.') => magnitude.to_owned(),
        _ => label,
    }
}

/// Closes the plotting area into a box, as in a paper's figures (plotters
/// draws the left and bottom axes only).
pub(super) fn frame<DB: DrawingBackend>(chart: &Chart<'_, DB>) -> Drawn<DB> {
    let (x, y) = (chart.x_range(), chart.y_range());
    let corners = [(x.start, y.start), (x.end, y.end)];
    chart.plotting_area().draw(&Rectangle::new(corners, BLACK))
}

/// The smallest and largest finite values, if any.
pub(super) fn extent(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    values
        .filter(|v| v.is_finite())
        .fold(None, |range, v| match range {
            None => Some((v, v)),
            Some((low, high)) => Some((v.min(low), v.max(high))),
        })
}

/// An axis range around `extent`, widened by `fraction` of its span on each
/// side; a single value is widened by that fraction of itself (±0.5 around
/// zero), and no value at all gives [-1, 1]; always a range an axis can
/// draw ([`drawable`]).
pub(super) fn padded(extent: Option<(f64, f64)>, fraction: f64) -> Range<f64> {
    let Some((low, high)) = extent else {
        return -1.0..1.0;
    };
    let pad = if high > low {
        fraction * (high - low)
    } else if low != 0.0 {
        fraction * low.abs()
    } else {
        0.5
    };
    drawable(low - pad..high + pad)
}

/// The lines through `points`, broken wherever a value is missing: a failed
/// lane shows as a gap rather than a line through a value never computed.
pub(super) fn segments(points: &[(f64, f64)]) -> impl Iterator<Item = Vec<(f64, f64)>> + '_ {
    points
        .split(|p| !p.1.is_finite())
        .filter(|segment| segment.len() > 1)
        .map(<[_]>::to_vec)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_ordinary_range_is_drawn_as_it_is() {
        for range in [0.5..1.5, -3.0..-2.0, -1e-12..1e-12, 1e300..2e300] {
            assert_eq!(drawable(range.clone()), range);
        }
    }

    #[test]
    fn an_axis_plotters_cannot_tick_is_made_one_it_can() {
        let max = f64::MAX;
        // Ends beyond f64::MAX (a padded extreme value), and a span that
        // overflows.
        let r = drawable(4.6e16..f64::INFINITY);
        assert_eq!(r, 4.6e16..max / 4.0);
        let r = drawable(-max..max);
        assert!((r.end - r.start).is_finite());
        // Two neighbouring floats, and one value.
        let r = drawable(1e17..1e17 + 16.0);
        assert!(r.end - r.start >= 1e5 - 16.0 && r.start < 1e17 && r.end > 1e17);
        assert_eq!(drawable(0.0..0.0), -1.0..1.0);
        // plotters finds their ticks (it looped for ever on each).
        for range in [
            4.6e16..f64::INFINITY,
            -max..max,
            1e17..1e17 + 16.0,
            1.0..1.0 + 1e-13,
        ] {
            let r = drawable(range);
            let ticks = plotters::coord::ranged1d::Ranged::key_points(
                &plotters::coord::types::RangedCoordf64::from(r.clone()),
                10,
            );
            assert!(!ticks.is_empty() && ticks.len() <= 10, "{r:?}: {ticks:?}");
        }
    }
}
