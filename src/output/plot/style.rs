//! What the figures share of their look: sizes, colours, fonts, spacing,
//! and the names and units written on their axes.

use plotters::prelude::*;

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
pub(super) const OTHER_EXPONENTS: [RGBColor; 3] = [
    RGBColor(213, 94, 0),
    RGBColor(0, 158, 115),
    RGBColor(204, 121, 167),
];

/// The expected sum of the exponents (the volume law): drawn wide and
/// dashed under the computed sum, a thin black line, so that agreement reads
/// as a black line threaded through grey dashes.
pub(super) const EXPECTED_COLOUR: RGBColor = RGBColor(120, 120, 120);
pub(super) const EXPECTED_WIDTH: u32 = 4;
pub(super) const SUM_COLOUR: RGBColor = BLACK;

/// The zero line and the grid: light enough to stay behind the data.
pub(super) const GUIDE_COLOUR: RGBColor = RGBColor(200, 200, 200);

/// A heat-map cell whose lane failed, and a point of a lane that found no
/// attractor.
pub(super) const FAILED_COLOUR: RGBColor = RGBColor(150, 150, 150);

/// A basin image's cell whose start lies outside the admissible states
/// (behind a wall): dark, apart from every branch's colour and the grey.
pub(super) const INADMISSIBLE_COLOUR: RGBColor = RGBColor(40, 40, 40);

/// A marker's radius in pixels: large enough to tell a filled one from an
/// open one, small enough that neighbouring values stay apart.
pub(super) const MARKER_RADIUS: i32 = 4;

/// The embedded font (see `figure`), and its sizes at about 1500 px wide.
/// plotters draws text at 1/1.24 of the size asked for (the SVG's
/// font-size shows it), so these ask for 1.24 times the sizes meant: 32 px
/// for the title, 28 for axis labels and 22 for ticks and legend.
pub(super) const FONT: &str = "sans-serif";
pub(super) const TITLE_PX: u32 = 40;
pub(super) const AXIS_LABEL_PX: u32 = 35;
pub(super) const TICK_LABEL_PX: u32 = 27;

/// Room around each panel, for its tick and axis labels.
pub(super) const MARGIN: u32 = 14;
pub(super) const X_LABEL_AREA: u32 = 100;
pub(super) const Y_LABEL_AREA: u32 = 135;
/// The upper panel shares the lower one's x axis: its own shows ticks only.
pub(super) const TICKS_ONLY_AREA: u32 = 10;
/// The row under the panels for the legend or the caption, and the width of
/// each legend entry's sample.
pub(super) const LEGEND_ROW: u32 = 50;
pub(super) const SAMPLE_WIDTH: i32 = 36;
/// The colour bar beside the heat map: its area, the bar's width in it.
pub(super) const COLOUR_BAR_AREA: u32 = 190;
pub(super) const BAR_WIDTH: u32 = 50;

/// Padding of the data ranges: a hair along the swept parameter, 5 % on the
/// value axes so that no point sits on the frame.
pub(super) const X_PAD: f64 = 0.01;
pub(super) const Y_PAD: f64 = 0.05;

/// The colour of λ_(i+1).
pub(super) fn exponent_colour(i: usize) -> RGBColor {
    match i {
        0 => DATA_COLOUR,
        _ => OTHER_EXPONENTS[(i - 1) % OTHER_EXPONENTS.len()],
    }
}

/// `n` in subscript digits, for "λ₁".
pub(super) fn subscript(n: usize) -> String {
    n.to_string()
        .chars()
        .map(|d| char::from_u32('₀' as u32 + d.to_digit(10).unwrap_or(0)).unwrap_or(d))
        .collect()
}

/// A parameter's name on an axis: the Greek letter where the name spells one.
pub(super) fn pretty(name: &str) -> &str {
    match name {
        "eta" => "η",
        "zeta" => "ζ",
        "sigma" => "σ",
        "rho" => "ρ",
        "beta" => "β",
        other => other,
    }
}

/// The colour at `t` in [0, 1] along evenly spaced `stops`, mixed linearly
/// between the two nearest.
pub(super) fn along(stops: &[RGBColor], t: f64) -> RGBColor {
    let last = stops.len() - 1;
    let position = t.clamp(0.0, 1.0) * last as f64;
    let below = (position.floor() as usize).min(last - 1);
    let t = position - below as f64;
    let (RGBColor(r0, g0, b0), RGBColor(r1, g1, b1)) = (stops[below], stops[below + 1]);
    let mix = |a: u8, b: u8| (a as f64 + t * (b as f64 - a as f64)).round() as u8;
    RGBColor(mix(r0, r1), mix(g0, g1), mix(b0, b1))
}

/// The unit of the exponents.
pub(super) fn unit(per_unit_time: bool) -> &'static str {
    if per_unit_time {
        "per unit time"
    } else {
        "per iteration"
    }
}
