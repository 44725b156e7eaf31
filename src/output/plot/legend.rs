//! A figure's legend: one centred row of entries, each a sample (a line,
//! a marker) beside its name.

use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::render::Drawn;
use super::style::{
    exponent_colour, EXPECTED_COLOUR, EXPECTED_WIDTH, FONT, MARKER_RADIUS, SAMPLE_WIDTH,
    SUM_COLOUR, TICK_LABEL_PX,
};

/// What a legend entry shows beside its name.
#[derive(Clone, Copy)]
pub(super) enum Sample {
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
pub(super) const LEGEND_SPACE: i32 = 40;

/// The legend's width in pixels, its entries in one row.
pub(super) fn legend_width<DB: DrawingBackend>(
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
pub(super) fn legend_style() -> TextStyle<'static> {
    TextStyle::from((FONT, TICK_LABEL_PX))
        .color(&BLACK)
        .pos(Pos::new(HPos::Left, VPos::Center))
}

/// The legend as one centred row: each entry's sample, then its name.
pub(super) fn draw_legend<DB: DrawingBackend>(
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
pub(super) fn marker<C>(centre: C, radius: i32, colour: RGBColor, filled: bool) -> Circle<C, i32> {
    let style = if filled {
        colour.filled()
    } else {
        colour.stroke_width(2)
    };
    Circle::new(centre, radius, style)
}
