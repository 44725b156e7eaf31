//! Figures of a sweep, each written as a PNG and an SVG of the same size: the
//! bifurcation diagram above the Lyapunov exponents, both against the swept
//! parameter (the layout of the seed paper's Fig. 3), and the heat map of λ₁
//! over a two-parameter grid. With many starts per value (`[attractors]`)
//! the sweep figure colours each attractor by its branch and adds the
//! basins, and a grid gets a second map: how many attractors each point has.
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
use plotters::coord::{ReverseCoordTranslate, Shift};
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::error::{Error, Result};
use crate::output::figure::{encode_png, register_font};
use crate::output::svg_raster;

/// The sweep figure's size in pixels (the SVG's logical size too).
pub const SWEEP_SIZE: (u32, u32) = (1600, 1200);

/// The heat map's size in pixels (the SVG's logical size too), and the
/// attractor map's.
pub const HEAT_MAP_SIZE: (u32, u32) = (1500, 1200);

/// The sweep figure with `[attractors]`: taller, for its third panel.
pub const ATTRACTOR_SWEEP_SIZE: (u32, u32) = (1600, 1500);

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

/// A heat-map cell whose lane failed, and a point of a lane that found no
/// attractor.
const FAILED_COLOUR: RGBColor = RGBColor(150, 150, 150);

/// The branches' colours, cycled by branch id: the dark blue of a single
/// start's figure, then the Okabe–Ito palette (which colour-blind readers
/// can tell apart) without its yellow, too pale on white, and a brown. No
/// grey: grey is a failed lane's.
const BRANCH_COLOURS: [RGBColor; 8] = [
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
const LEGEND_BRANCHES: usize = 8;

/// A marker's radius in pixels: large enough to tell a filled one from an
/// open one, small enough that neighbouring values stay apart.
const MARKER_RADIUS: i32 = 4;

/// ColorBrewer's YlGnBu without its palest stop (too close to the page), for
/// the attractor counts: one attractor light, many dark.
const COUNT_SCALE: [RGBColor; 8] = [
    RGBColor(237, 248, 177),
    RGBColor(199, 233, 180),
    RGBColor(127, 205, 187),
    RGBColor(65, 182, 196),
    RGBColor(29, 145, 192),
    RGBColor(34, 94, 168),
    RGBColor(37, 52, 148),
    RGBColor(8, 29, 88),
];

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

/// Draws `figure` as SVG into `file` (bitmaps embedded as PNG images, see
/// [`svg_raster`]), and flushes that file to disk so that the rename that
/// follows never exposes an empty figure.
fn render_svg<F: Figure>(figure: &F, file: &Path) -> io::Result<()> {
    register_font();
    let text = svg_raster::render(F::SIZE, |root| {
        figure.draw(&root).and_then(|()| root.present())
    })
    .map_err(|e| io::Error::other(e.to_string()))?;
    let mut out = fs::File::create(file)?;
    io::Write::write_all(&mut out, text.as_bytes())?;
    out.sync_all()
}

/// Writes RGB `pixels` of `size` as a PNG file, flushed to disk.
pub fn write_png(file: &Path, pixels: &[u8], size: (u32, u32)) -> io::Result<()> {
    let encoded = encode_png(pixels, size)?;
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

/// `n` panels stacked over a shared x axis, with plots of equal height: the
/// lowest also holds the axis's labels, the others its ticks only.
fn stacked<DB: DrawingBackend>(
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

/// What a legend entry shows beside its name.
#[derive(Clone, Copy)]
enum Sample {
    /// λ_(i+1): a dot on a thin line in its colour.
    Exponent(usize),
    /// The computed sum of the exponents.
    Sum,
    /// The sum the volume law expects.
    Expected,
    /// A marker of the figure with attractors: filled or open.
    Marker { colour: RGBColor, filled: bool },
    /// Nothing: the entry is its text.
    Text,
}

impl Sample {
    /// The width the sample takes before its name, with its gap.
    fn width(self) -> i32 {
        const GAP: i32 = 10;
        match self {
            Sample::Text => 0,
            // A marker needs no line's length.
            Sample::Marker { .. } => 4 * MARKER_RADIUS + GAP,
            _ => SAMPLE_WIDTH + GAP,
        }
    }
}

/// The space between legend entries.
const LEGEND_SPACE: i32 = 40;

/// The legend's width in pixels, its entries in one row.
fn legend_width<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    entries: &[(String, Sample)],
) -> std::result::Result<i32, DrawingAreaErrorKind<DB::ErrorType>> {
    let mut total = -LEGEND_SPACE;
    for (name, sample) in entries {
        let (text, _) = area.estimate_text_size(name, &legend_style())?;
        total += sample.width() + text as i32 + LEGEND_SPACE;
    }
    Ok(total.max(0))
}

/// The legend's names: beside their samples, centred on the row.
fn legend_style() -> TextStyle<'static> {
    TextStyle::from((FONT, TICK_LABEL_PX))
        .color(&BLACK)
        .pos(Pos::new(HPos::Left, VPos::Center))
}

/// The legend as one centred row: each entry's sample, then its name.
fn draw_legend<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    entries: &[(String, Sample)],
) -> Drawn<DB> {
    let style = legend_style();
    let total = legend_width(area, entries)?;
    let (width, height) = area.dim_in_pixel();
    let (mut x, y) = ((width as i32 - total) / 2, height as i32 / 2);
    for (name, sample) in entries {
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
            Sample::Marker { colour, filled } => {
                // Twice the figure's size: a legend's marker is read alone.
                let centre = (x + 2 * MARKER_RADIUS, y);
                area.draw(&marker(centre, 2 * MARKER_RADIUS, colour, filled))?;
            }
            Sample::Text => {}
        }
        area.draw_text(name, &style, (x + sample.width(), y))?;
        let (text, _) = area.estimate_text_size(name, &style)?;
        x += sample.width() + text as i32 + LEGEND_SPACE;
    }
    Ok(())
}

/// A round marker, filled or open.
fn marker<C>(centre: C, radius: i32, colour: RGBColor, filled: bool) -> Circle<C, i32> {
    let style = if filled {
        colour.filled()
    } else {
        colour.stroke_width(2)
    };
    Circle::new(centre, radius, style)
}

/// A panel's chart over `x_range` and `y_range`; `labelled`: with room for
/// the x axis's labels (when no panel below carries them).
fn panel<'a, DB: DrawingBackend>(
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
        .build_cartesian_2d(x_range, y_range)
}

/// A panel's axes: the y axis named `y_name`, the x axis the swept
/// `parameter` where `labelled`, ticks only otherwise.
fn draw_axes<DB: DrawingBackend>(
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
fn draw_points<DB: DrawingBackend, P: Iterator<Item = (f64, f64, RGBColor)>>(
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

/// The panels of the figure with attractors, top to bottom.
#[derive(Clone, Copy)]
enum AttractorPanel {
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
fn branch_colour(id: u64) -> RGBColor {
    BRANCH_COLOURS[(id % BRANCH_COLOURS.len() as u64) as usize]
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

        // The colour bar: the same height as the map, its scale on the right.
        const BANDS: usize = 256;
        let bands = (0..BANDS).map(|band| {
            let edge = |b: usize| limit * (2.0 * b as f64 / BANDS as f64 - 1.0);
            let (low, high) = (edge(band), edge(band + 1));
            (low..high, diverging((low + high) / 2.0, limit))
        });
        let name = format!("λ₁ ({})", unit(self.per_unit_time));
        draw_colour_bar(&bar, -limit..limit, &name, &tick, bands)?;

        // Under the map, where the colours end and, if any lane failed, what
        // grey means.
        let mut note = format!("colours saturate at ±{} ({chosen_as})", three_digits(limit));
        if self.lambda1.iter().any(|v| v.is_nan()) {
            note.push_str("; grey: failed lane");
        }
        draw_caption(&caption, &note)
    }
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

/// The layout the two maps share: the title above, a caption's row below,
/// the colour bar right of the map. Returns (map, bar, caption).
#[allow(clippy::type_complexity)]
fn map_layout<DB: DrawingBackend>(
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
fn draw_cells<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    (x_name, y_name): (&str, &str),
    (x, y): (&[f64], &[f64]),
    colour: impl Fn(usize) -> RGBColor,
) -> Drawn<DB> {
    let nx = x.len();
    let (x_cells, y_cells) = (cells(x), cells(y));
    let mut chart = ChartBuilder::on(area)
        .margin(MARGIN)
        .x_label_area_size(X_LABEL_AREA)
        .y_label_area_size(Y_LABEL_AREA)
        .build_cartesian_2d(span(&x_cells), span(&y_cells))?;
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
    frame(&chart)
}

/// Cells narrower or lower than this many pixels on average are drawn as
/// one raster of the map's pixels rather than as a rectangle each: smaller
/// rectangles show nothing more, and a million-cell map's SVG would hold a
/// million of them (90 MB; see `svg_raster` for how the raster is kept).
const RASTER_CELL_PX: f64 = 3.0;

/// The cells as one bitmap of the plotting area's pixels, each pixel
/// coloured by the cell its upper-left corner falls in (white outside all).
fn draw_raster<DB: DrawingBackend>(
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
fn locate(cells: &[Range<f64>]) -> impl Fn(f64) -> Option<usize> + '_ {
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
fn draw_colour_bar<DB: DrawingBackend>(
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
        .build_cartesian_2d(0.0..1.0, range)?;
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
fn draw_caption<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, text: &str) -> Drawn<DB> {
    let style = TextStyle::from((FONT, TICK_LABEL_PX))
        .color(&BLACK)
        .pos(Pos::new(HPos::Center, VPos::Center));
    let (width, height) = area.dim_in_pixel();
    area.draw_text(text, &style, (width as i32 / 2, height as i32 / 2))
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
    along(&RED_BLUE, ((value / limit).clamp(-1.0, 1.0) + 1.0) / 2.0)
}

/// The colour of `n` attractors on the sequential scale up to `most`; none
/// is grey (every start failed).
fn count_colour(n: usize, most: usize) -> RGBColor {
    match n {
        0 => FAILED_COLOUR,
        _ if most <= 1 => COUNT_SCALE[0],
        _ => along(&COUNT_SCALE, (n - 1) as f64 / (most - 1) as f64),
    }
}

/// The colour at `t` in [0, 1] along evenly spaced `stops`, mixed linearly
/// between the two nearest.
fn along(stops: &[RGBColor], t: f64) -> RGBColor {
    let last = stops.len() - 1;
    let position = t.clamp(0.0, 1.0) * last as f64;
    let below = (position.floor() as usize).min(last - 1);
    let t = position - below as f64;
    let (RGBColor(r0, g0, b0), RGBColor(r1, g1, b1)) = (stops[below], stops[below + 1]);
    let mix = |a: u8, b: u8| (a as f64 + t * (b as f64 - a as f64)).round() as u8;
    RGBColor(mix(r0, r1), mix(g0, g1), mix(b0, b1))
}

/// The unit of the exponents.
fn unit(per_unit_time: bool) -> &'static str {
    if per_unit_time {
        "per unit time"
    } else {
        "per iteration"
    }
}
