//! Figures of a sweep, each written as a PNG and an SVG of the same size: the
//! bifurcation diagram above the Lyapunov exponents, both against the swept
//! parameter (the layout of the seed paper's Fig. 3), and the heat map of λ₁
//! over a two-parameter grid.
//!
//! Each figure is drawn by one function generic over plotters'
//! `DrawingBackend`, so the PNG, the SVG and the in-memory pixels the tests
//! read are the same drawing. Like the CSV files, each file is drawn under a
//! temporary name in its folder and renamed into place, so it appears whole or
//! not at all.

use std::fs;
use std::io;
use std::ops::Range;
use std::path::{Path, PathBuf};

use plotters::chart::MeshStyle;
use plotters::coord::ranged1d::ValueFormatter;
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::error::{Error, Result};
use crate::output::figure::register_font;

/// The sweep figure's size in pixels (the SVG's logical size too).
pub const SWEEP_SIZE: (u32, u32) = (1600, 1200);

/// The heat map's size in pixels (the SVG's logical size too).
pub const HEAT_MAP_SIZE: (u32, u32) = (1500, 1200);

/// The colour of the bifurcation points and of λ₁: a dark blue that stays
/// legible as single pixels.
pub const DATA_COLOUR: RGBColor = RGBColor(16, 52, 166);

/// λ₂, λ₃, λ₄: from the Okabe–Ito palette, which colour-blind readers can
/// tell apart, and far from the dark blue of λ₁.
const OTHER_EXPONENTS: [RGBColor; 3] = [
    RGBColor(213, 94, 0),
    RGBColor(0, 158, 115),
    RGBColor(204, 121, 167),
];

/// The expected sum of the exponents (the volume law): drawn wide and
/// dashed under the computed sum, a thin black line, so that agreement reads
/// as a black line threaded through grey dashes.
const EXPECTED_COLOUR: RGBColor = RGBColor(120, 120, 120);
const EXPECTED_WIDTH: u32 = 4;
const SUM_COLOUR: RGBColor = BLACK;

/// The zero line and the grid: light enough to stay behind the data.
const GUIDE_COLOUR: RGBColor = RGBColor(200, 200, 200);

/// A heat-map cell whose lane failed.
const FAILED_COLOUR: RGBColor = RGBColor(150, 150, 150);

/// ColorBrewer's RdBu (C. Brewer, colorbrewer2.org) from -1 to +1: blue for
/// negative λ₁, near-white at zero, red for positive, evenly spaced stops.
const RED_BLUE: [RGBColor; 11] = [
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

/// The embedded font (see `figure`), and its sizes at about 1500 px wide.
/// plotters draws text at 1/1.24 of the size asked for (the SVG's
/// font-size shows it), so these ask for 1.24 times the sizes meant: 32 px
/// for the title, 28 for axis labels and 22 for ticks and legend.
const FONT: &str = "sans-serif";
const TITLE_PX: u32 = 40;
const AXIS_LABEL_PX: u32 = 35;
const TICK_LABEL_PX: u32 = 27;

/// Room around each panel, for its tick and axis labels.
const MARGIN: u32 = 14;
const X_LABEL_AREA: u32 = 100;
const Y_LABEL_AREA: u32 = 135;
/// The upper panel shares the lower one's x axis: its own shows ticks only.
const TICKS_ONLY_AREA: u32 = 10;
/// The row under the panels for the legend or the caption, and the width of
/// each legend entry's sample.
const LEGEND_ROW: u32 = 50;
const SAMPLE_WIDTH: i32 = 36;
/// The colour bar beside the heat map: its area, the bar's width in it.
const COLOUR_BAR_AREA: u32 = 190;
const BAR_WIDTH: u32 = 50;

/// Padding of the data ranges: a hair along the swept parameter, 5 % on the
/// value axes so that no point sits on the frame.
const X_PAD: f64 = 0.01;
const Y_PAD: f64 = 0.05;

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

/// A figure of a fixed size that any plotters backend can draw.
trait Figure {
    const SIZE: (u32, u32);
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Drawn<DB>;
}

/// What a drawing step returns: plotters' error for the backend in use.
type Drawn<DB> = std::result::Result<(), DrawingAreaErrorKind<<DB as DrawingBackend>::ErrorType>>;

/// A panel with numbers on both axes.
type Chart<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// Draws `figure` as `<dir>/<stem>.png` and `.svg`. Both are drawn under
/// temporary names before either is renamed, so a failed drawing leaves
/// neither a figure nor a temporary behind.
fn write<F: Figure>(figure: &F, dir: &Path, stem: &str) -> Result<Vec<PathBuf>> {
    let png = dir.join(format!("{stem}.png"));
    let svg = dir.join(format!("{stem}.svg"));
    let temporary = |extension: &str| {
        dir.join(format!(
            ".{stem}.{}.partial.{extension}",
            std::process::id()
        ))
    };
    let (png_partial, svg_partial) = (temporary("png"), temporary("svg"));
    let failed = |path: &Path| {
        let path = path.to_owned();
        move |source| Error::Write { path, source }
    };
    let result = write_png(&png_partial, &pixels(figure), F::SIZE)
        .map_err(failed(&png))
        .and_then(|()| render_svg(figure, &svg_partial).map_err(failed(&svg)))
        .and_then(|()| fs::rename(&png_partial, &png).map_err(failed(&png)))
        .and_then(|()| fs::rename(&svg_partial, &svg).map_err(failed(&svg)));
    if result.is_err() {
        for partial in [&png_partial, &svg_partial] {
            let _ = fs::remove_file(partial);
        }
    }
    result.map(|()| vec![png, svg])
}

/// Draws `figure` as SVG into `file`, and flushes that file to disk so that
/// the rename that follows never exposes an empty figure.
fn render_svg<F: Figure>(figure: &F, file: &Path) -> io::Result<()> {
    register_font();
    let root = SVGBackend::new(file, F::SIZE).into_drawing_area();
    figure
        .draw(&root)
        .and_then(|()| root.present())
        .map_err(|e| io::Error::other(e.to_string()))?;
    drop(root);
    fs::File::open(file)?.sync_all()
}

/// Writes RGB `pixels` of `size` as a PNG file, flushed to disk. (Encoded
/// here with the `png` crate rather than by plotters' bitmap encoder, which
/// brings the whole `image` crate and its decoders into the build.)
pub fn write_png(file: &Path, pixels: &[u8], (width, height): (u32, u32)) -> io::Result<()> {
    let mut encoded = Vec::new();
    let mut encoder = png::Encoder::new(&mut encoded, width, height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    let mut writer = encoder.write_header().map_err(io::Error::other)?;
    writer.write_image_data(pixels).map_err(io::Error::other)?;
    writer.finish().map_err(io::Error::other)?;
    let mut out = fs::File::create(file)?;
    io::Write::write_all(&mut out, &encoded)?;
    out.sync_all()
}

/// Draws `figure` into memory as RGB pixels.
fn pixels<F: Figure>(figure: &F) -> Vec<u8> {
    register_font();
    let (width, height) = F::SIZE;
    let mut buffer = vec![0; width as usize * height as usize * 3];
    let root = BitMapBackend::with_buffer(&mut buffer, F::SIZE).into_drawing_area();
    figure
        .draw(&root)
        .and_then(|()| root.present())
        .unwrap_or_else(|e| panic!("drawing into memory with the embedded font cannot fail: {e}"));
    drop(root);
    buffer
}

impl Figure for SweepData {
    const SIZE: (u32, u32) = SWEEP_SIZE;

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Drawn<DB> {
        root.fill(&WHITE)?;
        let body = root.titled(&self.title, (FONT, TITLE_PX))?;
        if self.exponents.is_empty() {
            // A run without exponents (`lyapunov = "none"`): the diagram
            // alone, over the values its points lie at.
            let x_range = padded(extent(self.bifurcation.iter().map(|p| p.0)), X_PAD);
            return draw_bifurcation(&body, self, x_range, true);
        }
        // The legend has a row of its own, where it can hide no data.
        let (_, height) = body.dim_in_pixel();
        let (panels, legend) = body.split_vertically(height - LEGEND_ROW);
        draw_legend(&legend, &self.legend())?;
        let x_range = padded(extent(self.values.iter().copied()), X_PAD);
        if self.bifurcation.is_empty() {
            return draw_exponents(&panels, self, x_range);
        }
        // Plots of equal height: the lower panel also holds the labels of
        // the shared x axis.
        let (_, height) = panels.dim_in_pixel();
        let (top, bottom) = panels.split_vertically((height + TICKS_ONLY_AREA - X_LABEL_AREA) / 2);
        draw_bifurcation(&top, self, x_range.clone(), false)?;
        draw_exponents(&bottom, self, x_range)
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

/// What a legend entry shows beside its name.
#[derive(Clone, Copy)]
enum Sample {
    /// λ_(i+1): a dot on a thin line in its colour.
    Exponent(usize),
    /// The computed sum of the exponents.
    Sum,
    /// The sum the volume law expects.
    Expected,
}

/// The legend as one centred row: each entry's sample, then its name.
fn draw_legend<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    entries: &[(String, Sample)],
) -> Drawn<DB> {
    let style = TextStyle::from((FONT, TICK_LABEL_PX))
        .color(&BLACK)
        .pos(Pos::new(HPos::Left, VPos::Center));
    let (gap, space) = (10, 40);
    let mut widths = Vec::with_capacity(entries.len());
    for (name, _) in entries {
        let (text, _) = area.estimate_text_size(name, &style)?;
        widths.push(SAMPLE_WIDTH + gap + text as i32);
    }
    let total = widths.iter().sum::<i32>() + space * (entries.len() as i32 - 1);
    let (width, height) = area.dim_in_pixel();
    let (mut x, y) = ((width as i32 - total) / 2, height as i32 / 2);
    for ((name, sample), entry_width) in entries.iter().zip(widths) {
        let line = [(x, y), (x + SAMPLE_WIDTH, y)];
        match *sample {
            Sample::Exponent(i) => {
                let colour = exponent_colour(i);
                area.draw(&PathElement::new(line, colour))?;
                area.draw(&Circle::new((x + SAMPLE_WIDTH / 2, y), 4, colour.filled()))?;
            }
            Sample::Sum => area.draw(&PathElement::new(line, SUM_COLOUR))?,
            Sample::Expected => area.draw(&DashedPathElement::new(
                line,
                8,
                4,
                EXPECTED_COLOUR.stroke_width(EXPECTED_WIDTH),
            ))?,
        }
        area.draw_text(name, &style, (x + SAMPLE_WIDTH + gap, y))?;
        x += entry_width + space;
    }
    Ok(())
}

/// The bifurcation diagram: every point one pixel of `DATA_COLOUR`.
///
/// The points are first gathered on the panel's pixel grid and each column's
/// runs of lit pixels drawn as one rectangle, so that the SVG holds a few
/// thousand rectangles rather than one per point (hundreds of thousands),
/// and the PNG is the same drawing.
/// The bifurcation diagram; `labelled`: with the x axis's labels (when no
/// exponent panel below carries them).
fn draw_bifurcation<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    data: &SweepData,
    x_range: Range<f64>,
    labelled: bool,
) -> Drawn<DB> {
    let points = || {
        data.bifurcation
            .iter()
            .filter(|(x, y)| x.is_finite() && y.is_finite())
    };
    let y_range = padded(extent(points().map(|p| p.1)), Y_PAD);
    let mut chart = ChartBuilder::on(area)
        .margin(MARGIN)
        .x_label_area_size(if labelled {
            X_LABEL_AREA
        } else {
            TICKS_ONLY_AREA
        })
        .y_label_area_size(Y_LABEL_AREA)
        .build_cartesian_2d(x_range, y_range)?;
    let mut axes = mesh(&mut chart);
    axes.y_desc(&data.state_name);
    if labelled {
        axes.x_desc(pretty(&data.parameter));
    } else {
        axes.x_label_formatter(&|_| String::new());
    }
    axes.draw()?;

    let plot = chart.plotting_area();
    let (width, height) = plot.dim_in_pixel();
    let (width, height) = (width as i32, height as i32);
    let (left, top) = plot.get_base_pixel();
    // Column by column, so that each column's runs lie together.
    let mut lit = vec![false; (width * height) as usize];
    for point in points() {
        let (x, y) = chart.backend_coord(point);
        let (column, row) = (x - left, y - top);
        if (0..width).contains(&column) && (0..height).contains(&row) {
            lit[(column * height + row) as usize] = true;
        }
    }
    let canvas = plot.strip_coord_spec();
    for (column, rows) in lit.chunks_exact(height as usize).enumerate() {
        let column = column as i32;
        let mut start = None;
        // One row past the bottom, to close a run that reaches it.
        for row in 0..=height {
            match (start, rows.get(row as usize).copied().unwrap_or(false)) {
                (None, true) => start = Some(row),
                (Some(first), false) => {
                    let corners = [(column, first), (column + 1, row)];
                    canvas.draw(&Rectangle::new(corners, DATA_COLOUR.filled()))?;
                    start = None;
                }
                _ => {}
            }
        }
    }
    frame(&chart)
}

/// The exponents, their sum and the sum the volume law expects.
fn draw_exponents<DB: DrawingBackend>(
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
    let unit = if data.per_unit_time {
        "per unit time"
    } else {
        "per iteration"
    };
    mesh(&mut chart)
        .x_desc(pretty(&data.parameter))
        .y_desc(format!("λ ({unit})"))
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

impl Figure for GridData {
    const SIZE: (u32, u32) = HEAT_MAP_SIZE;

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Drawn<DB> {
        let (nx, ny) = (self.x.len(), self.y.len());
        assert_eq!(
            self.lambda1.len(),
            nx * ny,
            "λ1 holds one value per grid point ({nx} × {ny})"
        );
        root.fill(&WHITE)?;
        let body = root.titled(&self.title, (FONT, TITLE_PX))?;
        let (_, height) = body.dim_in_pixel();
        let (panels, caption) = body.split_vertically(height - LEGEND_ROW);
        let (width, _) = panels.dim_in_pixel();
        let (map, bar) = panels.split_horizontally(width - COLOUR_BAR_AREA);
        let (limit, chosen_as) = colour_limit(&self.lambda1);
        let unit = if self.per_unit_time {
            "per unit time"
        } else {
            "per iteration"
        };

        let (x_cells, y_cells) = (cells(&self.x), cells(&self.y));
        let mut chart = ChartBuilder::on(&map)
            .margin(MARGIN)
            .x_label_area_size(X_LABEL_AREA)
            .y_label_area_size(Y_LABEL_AREA)
            .build_cartesian_2d(span(&x_cells), span(&y_cells))?;
        // Grid lines over a heat map are noise: axes only.
        mesh(&mut chart)
            .disable_mesh()
            .x_desc(pretty(&self.x_name))
            .y_desc(pretty(&self.y_name))
            .draw()?;
        let grid = y_cells.iter().enumerate().flat_map(|(j, ys)| {
            x_cells
                .iter()
                .enumerate()
                .map(move |(i, xs)| (i, j, xs, ys))
        });
        chart.draw_series(grid.map(|(i, j, xs, ys)| {
            let colour = diverging(self.lambda1[j * nx + i], limit);
            Rectangle::new([(xs.start, ys.start), (xs.end, ys.end)], colour.filled())
        }))?;
        frame(&chart)?;

        // The colour bar: the same height as the map, its scale on the right.
        const BANDS: usize = 256;
        let mut chart = ChartBuilder::on(&bar)
            .margin(MARGIN)
            .x_label_area_size(X_LABEL_AREA)
            .right_y_label_area_size(COLOUR_BAR_AREA - 2 * MARGIN - BAR_WIDTH)
            .build_cartesian_2d(0.0..1.0, -limit..limit)?;
        mesh(&mut chart)
            .disable_mesh()
            .disable_x_axis()
            .y_desc(format!("λ₁ ({unit})"))
            .draw()?;
        chart.draw_series((0..BANDS).map(|band| {
            let edge = |b: usize| limit * (2.0 * b as f64 / BANDS as f64 - 1.0);
            let (low, high) = (edge(band), edge(band + 1));
            let colour = diverging((low + high) / 2.0, limit);
            Rectangle::new([(0.0, low), (1.0, high)], colour.filled())
        }))?;
        frame(&chart)?;

        // Under the map, where the colours end and, if any lane failed, what
        // grey means.
        let mut note = format!("colours saturate at ±{} ({chosen_as})", three_digits(limit));
        if self.lambda1.iter().any(|v| v.is_nan()) {
            note.push_str("; grey: failed lane");
        }
        let style = TextStyle::from((FONT, TICK_LABEL_PX))
            .color(&BLACK)
            .pos(Pos::new(HPos::Center, VPos::Center));
        let (width, height) = caption.dim_in_pixel();
        caption.draw_text(&note, &style, (width as i32 / 2, height as i32 / 2))
    }
}

/// The mesh every panel shares: readable labels, a light grid of major ticks.
fn mesh<'a, 'b, DB: DrawingBackend>(
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
fn tick(value: &f64) -> String {
    let label = RangedCoordf64::format(value);
    match label.strip_prefix('-') {
        Some(magnitude) if magnitude.chars().all(|c| c == '0' || c == '.') => magnitude.to_owned(),
        _ => label,
    }
}

/// A positive `value` to three significant digits.
fn three_digits(value: f64) -> String {
    let decimals = (2 - value.log10().floor() as i32).max(0) as usize;
    format!("{value:.decimals$}")
}

/// Closes the plotting area into a box, as in a paper's figures (plotters
/// draws the left and bottom axes only).
fn frame<DB: DrawingBackend>(chart: &Chart<'_, DB>) -> Drawn<DB> {
    let (x, y) = (chart.x_range(), chart.y_range());
    let corners = [(x.start, y.start), (x.end, y.end)];
    chart.plotting_area().draw(&Rectangle::new(corners, BLACK))
}

/// The smallest and largest finite values, if any.
fn extent(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    values
        .filter(|v| v.is_finite())
        .fold(None, |range, v| match range {
            None => Some((v, v)),
            Some((low, high)) => Some((v.min(low), v.max(high))),
        })
}

/// An axis range around `extent`, widened by `fraction` of its span on each
/// side; a single value is widened by that fraction of itself (±0.5 around
/// zero), and no value at all gives [-1, 1].
fn padded(extent: Option<(f64, f64)>, fraction: f64) -> Range<f64> {
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
    low - pad..high + pad
}

/// The lines through `points`, broken wherever a value is missing: a failed
/// lane shows as a gap rather than a line through a value never computed.
fn segments(points: &[(f64, f64)]) -> impl Iterator<Item = Vec<(f64, f64)>> + '_ {
    points
        .split(|p| !p.1.is_finite())
        .filter(|segment| segment.len() > 1)
        .map(<[_]>::to_vec)
}

/// The colour of λ_(i+1).
fn exponent_colour(i: usize) -> RGBColor {
    match i {
        0 => DATA_COLOUR,
        _ => OTHER_EXPONENTS[(i - 1) % OTHER_EXPONENTS.len()],
    }
}

/// `n` in subscript digits, for "λ₁".
fn subscript(n: usize) -> String {
    n.to_string()
        .chars()
        .map(|d| char::from_u32('₀' as u32 + d.to_digit(10).unwrap_or(0)).unwrap_or(d))
        .collect()
}

/// A parameter's name on an axis: the Greek letter where the name spells one.
fn pretty(name: &str) -> &str {
    match name {
        "eta" => "η",
        "zeta" => "ζ",
        "sigma" => "σ",
        "rho" => "ρ",
        "beta" => "β",
        other => other,
    }
}

/// Each grid value's cell along one axis: from halfway to its lower
/// neighbour to halfway to its upper one, the end cells as wide as their
/// neighbours' half-steps. The values need not be sorted; a lone value gets
/// the width `padded` gives it.
fn cells(values: &[f64]) -> Vec<Range<f64>> {
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
fn span(cells: &[Range<f64>]) -> Range<f64> {
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

/// The heat map's colour limit, and how it was chosen: the 99th percentile
/// of |λ₁| over finite values rather than the maximum, so that one outlying
/// lane (a grazing one, say) does not wash every other cell out to white.
/// Cells beyond it saturate but keep their sign's colour, and the sign (chaos
/// or order) is what the map is read for.
fn colour_limit(lambda1: &[f64]) -> (f64, &'static str) {
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
fn diverging(value: f64, limit: f64) -> RGBColor {
    if value.is_nan() {
        return FAILED_COLOUR;
    }
    let stops = RED_BLUE.len() - 1;
    let position = ((value / limit).clamp(-1.0, 1.0) + 1.0) / 2.0 * stops as f64;
    let below = (position.floor() as usize).min(stops - 1);
    let t = position - below as f64;
    let (RGBColor(r0, g0, b0), RGBColor(r1, g1, b1)) = (RED_BLUE[below], RED_BLUE[below + 1]);
    let mix = |a: u8, b: u8| (a as f64 + t * (b as f64 - a as f64)).round() as u8;
    RGBColor(mix(r0, r1), mix(g0, g1), mix(b0, b1))
}
