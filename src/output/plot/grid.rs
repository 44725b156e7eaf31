//! What the two maps over a two-parameter grid share: the layout (map,
//! colour bar, caption), the cells, drawn as rectangles or as one raster,
//! and the colour bar.

use std::ops::Range;

use plotters::coord::{ReverseCoordTranslate, Shift};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::panel::{drawable, frame, mesh, padded, Chart};
use super::render::Drawn;
use super::style::{
    pretty, BAR_WIDTH, COLOUR_BAR_AREA, FONT, LEGEND_ROW, MARGIN, TICK_LABEL_PX, TITLE_PX,
    X_LABEL_AREA, X_PAD, Y_LABEL_AREA,
};

/// The layout the two maps share: the title above, a caption's row below,
/// the colour bar right of the map. Returns (map, bar, caption).
#[allow(clippy::type_complexity)]
pub(super) fn map_layout<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    title: &str,
) -> std::result::Result<
    (
        DrawingArea<DB, Shift>,
        DrawingArea<DB, Shift>,
        DrawingArea<DB, Shift>,
    ),
    DrawingAreaErrorKind<DB::ErrorType>,
> {
    root.fill(&WHITE)?;
    let body = root.titled(title, (FONT, TITLE_PX))?;
    let (_, height) = body.dim_in_pixel();
    let (panels, caption) = body.split_vertically(height - LEGEND_ROW);
    let (width, _) = panels.dim_in_pixel();
    let (map, bar) = panels.split_horizontally(width - COLOUR_BAR_AREA);
    Ok((map, bar, caption))
}

/// A map's cells over the grid `(x, y)`, cell (i, j) filled with
/// `colour(j * nx + i)` (x fastest); `axes` names x and y.
pub(super) fn draw_cells<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    axes: (&str, &str),
    grid: (&[f64], &[f64]),
    colour: impl Fn(usize) -> RGBColor,
) -> Drawn<DB> {
    frame(&cells_chart(area, axes, grid, colour)?)
}

/// [`draw_cells`]' chart before its frame, for a figure that draws over
/// the cells in the grid's coordinates.
pub(super) fn cells_chart<'a, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
    (x_name, y_name): (&str, &str),
    (x, y): (&[f64], &[f64]),
    colour: impl Fn(usize) -> RGBColor,
) -> std::result::Result<Chart<'a, DB>, DrawingAreaErrorKind<DB::ErrorType>> {
    let nx = x.len();
    let (x_cells, y_cells) = (cells(x), cells(y));
    let mut chart = ChartBuilder::on(area)
        .margin(MARGIN)
        .x_label_area_size(X_LABEL_AREA)
        .y_label_area_size(Y_LABEL_AREA)
        .build_cartesian_2d(drawable(span(&x_cells)), drawable(span(&y_cells)))?;
    // Grid lines over a heat map are noise: axes only.
    mesh(&mut chart)
        .disable_mesh()
        .x_desc(pretty(x_name))
        .y_desc(pretty(y_name))
        .draw()?;
    let (width, height) = chart.plotting_area().dim_in_pixel();
    let small = |pixels: u32, cells: usize| f64::from(pixels) < RASTER_CELL_PX * cells as f64;
    if small(width, nx) || small(height, y.len()) {
        draw_raster(&chart, (&x_cells, &y_cells), colour)?;
    } else {
        let grid = y_cells.iter().enumerate().flat_map(|(j, ys)| {
            x_cells
                .iter()
                .enumerate()
                .map(move |(i, xs)| (i, j, xs, ys))
        });
        chart.draw_series(grid.map(|(i, j, xs, ys)| {
            let corners = [(xs.start, ys.start), (xs.end, ys.end)];
            Rectangle::new(corners, colour(j * nx + i).filled())
        }))?;
    }
    Ok(chart)
}

/// Cells narrower or lower than this many pixels on average are drawn as
/// one raster of the map's pixels rather than as a rectangle each: smaller
/// rectangles show nothing more, and a million-cell map's SVG would hold a
/// million of them (90 MB; see `svg_raster` for how the raster is kept).
pub(super) const RASTER_CELL_PX: f64 = 3.0;

/// The cells as one bitmap of the plotting area's pixels, each pixel
/// coloured by the cell its upper-left corner falls in (white outside all).
pub(super) fn draw_raster<DB: DrawingBackend>(
    chart: &Chart<'_, DB>,
    (x_cells, y_cells): (&[Range<f64>], &[Range<f64>]),
    colour: impl Fn(usize) -> RGBColor,
) -> Drawn<DB> {
    let area = chart.plotting_area();
    let (columns, rows) = area.get_pixel_range();
    let spec = chart.as_coord_spec();
    let (in_x, in_y) = (locate(x_cells), locate(y_cells));
    let column_cells: Vec<Option<usize>> = columns
        .clone()
        .map(|px| in_x(spec.reverse_translate((px, rows.start))?.0))
        .collect();
    let row_cells: Vec<Option<usize>> = rows
        .clone()
        .map(|py| in_y(spec.reverse_translate((columns.start, py))?.1))
        .collect();
    let nx = x_cells.len();
    let mut pixels = Vec::with_capacity(3 * column_cells.len() * row_cells.len());
    for j in &row_cells {
        for i in &column_cells {
            let RGBColor(r, g, b) = match (i, j) {
                (Some(i), Some(j)) => colour(j * nx + i),
                _ => WHITE,
            };
            pixels.extend([r, g, b]);
        }
    }
    let size = (column_cells.len() as u32, row_cells.len() as u32);
    let bitmap = BitMapElement::with_owned_buffer((0, 0), size, pixels)
        .expect("three bytes a pixel of the plotting area");
    area.strip_coord_spec().draw(&bitmap)
}

/// Which of `cells` holds a value: the cells tile their span (see [`cells`])
/// in any order.
pub(super) fn locate(cells: &[Range<f64>]) -> impl Fn(f64) -> Option<usize> + '_ {
    let mut order: Vec<usize> = (0..cells.len()).collect();
    order.sort_by(|&a, &b| cells[a].start.total_cmp(&cells[b].start));
    move |v| {
        let k = order[order
            .partition_point(|&k| cells[k].start <= v)
            .checked_sub(1)?];
        (v <= cells[k].end).then_some(k)
    }
}

/// A colour bar over `range`, its scale on the right named `name` and
/// labelled by `label`: each band a (range, colour) pair.
pub(super) fn draw_colour_bar<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    range: Range<f64>,
    name: &str,
    label: &dyn Fn(&f64) -> String,
    bands: impl Iterator<Item = (Range<f64>, RGBColor)>,
) -> Drawn<DB> {
    let mut chart = ChartBuilder::on(area)
        .margin(MARGIN)
        .x_label_area_size(X_LABEL_AREA)
        .right_y_label_area_size(COLOUR_BAR_AREA - 2 * MARGIN - BAR_WIDTH)
        .build_cartesian_2d(0.0..1.0, drawable(range))?;
    mesh(&mut chart)
        .disable_mesh()
        .disable_x_axis()
        .y_label_formatter(label)
        .y_desc(name)
        .draw()?;
    chart.draw_series(bands.map(|(band, colour)| {
        Rectangle::new([(0.0, band.start), (1.0, band.end)], colour.filled())
    }))?;
    frame(&chart)
}

/// One line of text, centred in `area`.
pub(super) fn draw_caption<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    text: &str,
) -> Drawn<DB> {
    let style = TextStyle::from((FONT, TICK_LABEL_PX))
        .color(&BLACK)
        .pos(Pos::new(HPos::Center, VPos::Center));
    let (width, height) = area.dim_in_pixel();
    area.draw_text(text, &style, (width as i32 / 2, height as i32 / 2))
}

/// Each grid value's cell along one axis: from halfway to its lower
/// neighbour to halfway to its upper one, the end cells as wide as their
/// neighbours' half-steps. The values need not be sorted; a lone value gets
/// the width `padded` gives it.
pub(super) fn cells(values: &[f64]) -> Vec<Range<f64>> {
    let mut order: Vec<usize> = (0..values.len()).collect();
    order.sort_by(|&a, &b| values[a].total_cmp(&values[b]));
    let sorted: Vec<f64> = order.iter().map(|&k| values[k]).collect();
    let mut cells = vec![0.0..0.0; values.len()];
    for (rank, &k) in order.iter().enumerate() {
        let v = sorted[rank];
        cells[k] = match (rank.checked_sub(1).map(|r| sorted[r]), sorted.get(rank + 1)) {
            (None, None) => padded(Some((v, v)), X_PAD),
            (Some(below), None) => (v + below) / 2.0..v + (v - below) / 2.0,
            (None, Some(&above)) => v - (above - v) / 2.0..(v + above) / 2.0,
            (Some(below), Some(&above)) => (v + below) / 2.0..(v + above) / 2.0,
        };
    }
    cells
}

/// The range the cells cover; [-1, 1] for no cells.
pub(super) fn span(cells: &[Range<f64>]) -> Range<f64> {
    let low = cells.iter().map(|c| c.start).fold(f64::INFINITY, f64::min);
    let high = cells
        .iter()
        .map(|c| c.end)
        .fold(f64::NEG_INFINITY, f64::max);
    if low < high {
        low..high
    } else {
        -1.0..1.0
    }
}
