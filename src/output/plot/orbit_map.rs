//! The orbits map of a two-parameter run with `[orbits]`: the bifurcation
//! points located on the branches (each followed in the first parameter at
//! one value of the second) over the heat map of λ₁, one colour and marker
//! per kind, so that a reader sees where the attractors change and why.
//!
//! The points of one kind are joined into curves across neighbouring
//! values of the second parameter, a drawing matter only (each point is a
//! located bifurcation; the lines between them are not computed): between
//! two neighbouring values of the grid's second axis, the pairs of points
//! of that kind closer than [`JOIN_REACH`] of the first parameter's range
//! are joined nearest first, each point to at most one point of each
//! neighbouring value; a kind not found at a value breaks its curves there. A curve
//! that turns back in the first parameter, or two curves that cross, may
//! so be joined wrongly over one step; the markers stay where they were
//! located.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;

use super::grid::{cells_chart, draw_caption, map_layout};
use super::heat_map::{colour_limit, diverging, draw_lambda_bar, GridData};
use super::legend::{legend_style, LEGEND_SPACE};
use super::panel::frame;
use super::render::{pixels, write, Drawn, Figure};
use super::style::{HEAT_MAP_SIZE, LEGEND_ROW, MARKER_RADIUS};
use crate::error::Result;

/// The largest distance in the first parameter, as a fraction of its
/// range, between two points of one kind at neighbouring values of the
/// second that are joined into one curve.
const JOIN_REACH: f64 = 0.05;

/// What the orbits map draws.
pub struct OrbitMapData {
    /// λ₁ over the grid (its title is the figure's).
    pub grid: GridData,
    /// Each kind's legend entry ("GR grazing"), in the order of
    /// [`KIND_STYLES`]: a point's kind is its index here.
    pub kinds: Vec<String>,
    /// Each bifurcation: (first parameter, second, kind).
    pub points: Vec<(f64, f64, usize)>,
}

/// A marker's shape.
#[derive(Clone, Copy)]
enum Shape {
    Circle,
    Triangle,
    Square,
    Diamond,
    Cross,
}

/// Each kind's colour and marker, in `orbit::trace::Kind::ALL`'s order
/// (fold, period doubling, Neimark–Sacker, grazing, sliding, events
/// change): colours that stand out on both ends of the blue–red map.
const KIND_STYLES: [(RGBColor, Shape); 6] = [
    (RGBColor(0, 160, 0), Shape::Triangle),
    (RGBColor(200, 0, 200), Shape::Square),
    (RGBColor(255, 140, 0), Shape::Diamond),
    (BLACK, Shape::Circle),
    (RGBColor(140, 80, 0), Shape::Cross),
    (RGBColor(90, 90, 90), Shape::Circle),
];

/// Draws the map as `<dir>/<stem>.png` and `.svg`; returns both paths.
pub fn orbit_map(data: &OrbitMapData, dir: &Path, stem: &str) -> Result<Vec<PathBuf>> {
    write(data, dir, stem)
}

/// The map as RGB pixels, row by row, `HEAT_MAP_SIZE` of them.
pub fn orbit_map_pixels(data: &OrbitMapData) -> Vec<u8> {
    pixels(data)
}

impl Figure for OrbitMapData {
    const SIZE: (u32, u32) = HEAT_MAP_SIZE;

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Drawn<DB> {
        let grid = &self.grid;
        let (map, bar, caption) = map_layout(root, &grid.title)?;
        let (caption, legend) = caption.split_vertically(LEGEND_ROW / 2);
        let (limit, chosen_as) = colour_limit(&grid.lambda1);
        let axes = (grid.x_name.as_str(), grid.y_name.as_str());
        let mut chart = cells_chart(&map, axes, (&grid.x, &grid.y), |k| {
            diverging(grid.lambda1[k], limit)
        })?;
        let reach = JOIN_REACH * range_of(&grid.x);
        for (kind, pairs) in curves(&self.points, &grid.y, reach) {
            let style = KIND_STYLES[kind % KIND_STYLES.len()].0.stroke_width(2);
            chart.draw_series(
                pairs
                    .into_iter()
                    .map(|(a, b)| PathElement::new([a, b], style)),
            )?;
        }
        let area = chart.plotting_area();
        let (base_x, base_y) = area.get_base_pixel();
        let plain = area.strip_coord_spec();
        for &(x, y, kind) in &self.points {
            let (px, py) = chart.backend_coord(&(x, y));
            let (colour, shape) = KIND_STYLES[kind % KIND_STYLES.len()];
            let centre = (px - base_x, py - base_y);
            // A white rim keeps a dark marker legible on the map's dark blue.
            draw_marker(&plain, centre, MARKER_RADIUS + 3, WHITE, shape)?;
            draw_marker(&plain, centre, MARKER_RADIUS + 1, colour, shape)?;
        }
        frame(&chart)?;
        draw_lambda_bar(&bar, limit, grid.per_unit_time)?;
        draw_caption(&caption, &grid.note(limit, chosen_as))?;
        self.draw_legend(&legend)
    }
}

impl OrbitMapData {
    /// One centred row: the marker and name of each kind drawn.
    fn draw_legend<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> Drawn<DB> {
        let style = legend_style();
        let mut present: Vec<usize> = self.points.iter().map(|p| p.2).collect();
        present.sort_unstable();
        present.dedup();
        let sample = 4 * MARKER_RADIUS + 10;
        let mut total = -LEGEND_SPACE;
        for &k in &present {
            let (width, _) = area.estimate_text_size(&self.kinds[k], &style)?;
            total += sample + width as i32 + LEGEND_SPACE;
        }
        let (width, height) = area.dim_in_pixel();
        let (mut x, y) = ((width as i32 - total.max(0)) / 2, height as i32 / 2);
        for &k in &present {
            let (colour, shape) = KIND_STYLES[k % KIND_STYLES.len()];
            draw_marker(
                area,
                (x + 2 * MARKER_RADIUS, y),
                2 * MARKER_RADIUS,
                colour,
                shape,
            )?;
            let text = &self.kinds[k];
            area.draw_text(text, &style, (x + sample, y))?;
            let (w, _) = area.estimate_text_size(text, &style)?;
            x += sample + w as i32 + LEGEND_SPACE;
        }
        Ok(())
    }
}

/// The span of `values` (1 when they have none).
fn range_of(values: &[f64]) -> f64 {
    let low = values.iter().copied().fold(f64::INFINITY, f64::min);
    let high = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if high > low {
        high - low
    } else {
        1.0
    }
}

/// A marker of `shape` centred at `centre` (pixels of `area`).
fn draw_marker<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    (x, y): (i32, i32),
    r: i32,
    colour: RGBColor,
    shape: Shape,
) -> Drawn<DB> {
    let fill = colour.filled();
    match shape {
        Shape::Circle => area.draw(&Circle::new((x, y), r, fill)),
        Shape::Square => area.draw(&Rectangle::new([(x - r, y - r), (x + r, y + r)], fill)),
        Shape::Triangle => {
            let corners = vec![(x, y - r - 1), (x - r - 1, y + r), (x + r + 1, y + r)];
            area.draw(&Polygon::new(corners, fill))
        }
        Shape::Diamond => {
            let r = r + 1;
            let corners = vec![(x, y - r), (x + r, y), (x, y + r), (x - r, y)];
            area.draw(&Polygon::new(corners, fill))
        }
        Shape::Cross => {
            let style = colour.stroke_width(3);
            area.draw(&PathElement::new([(x - r, y - r), (x + r, y + r)], style))?;
            area.draw(&PathElement::new([(x - r, y + r), (x + r, y - r)], style))
        }
    }
}

/// A segment of a curve: two points (first, second).
type Link = ((f64, f64), (f64, f64));

/// The segments joining `points` of each kind into curves (see the
/// module's header), by kind: only between neighbouring values of the
/// second parameter among `seconds` and the points' own, so that a curve
/// is not drawn over a value where its kind was not found. Deterministic:
/// the points' order decides only between pairs at equal distances.
fn curves(points: &[(f64, f64, usize)], seconds: &[f64], reach: f64) -> BTreeMap<usize, Vec<Link>> {
    let finite = |p: &&(f64, f64, usize)| p.0.is_finite() && p.1.is_finite();
    let mut values: Vec<u64> = seconds
        .iter()
        .filter(|y| y.is_finite())
        .map(|&y| ordered_bits(y))
        .collect();
    values.extend(points.iter().filter(finite).map(|p| ordered_bits(p.1)));
    values.sort_unstable();
    values.dedup();
    let mut by_kind: BTreeMap<usize, BTreeMap<u64, Vec<f64>>> = BTreeMap::new();
    for &(x, y, kind) in points.iter().filter(finite) {
        // Keyed by the second's value in an order of bits that is the
        // numbers' order.
        let rows = by_kind.entry(kind).or_default();
        rows.entry(ordered_bits(y)).or_default().push(x);
    }
    let mut all = BTreeMap::new();
    for (kind, rows) in by_kind {
        let mut links = Vec::new();
        for pair in values.windows(2) {
            let (Some(xs0), Some(xs1)) = (rows.get(&pair[0]), rows.get(&pair[1])) else {
                continue;
            };
            let (y0, y1) = (from_ordered_bits(pair[0]), from_ordered_bits(pair[1]));
            links.extend(
                nearest_pairs(xs0, xs1, reach)
                    .into_iter()
                    .map(|(i, j)| ((xs0[i], y0), (xs1[j], y1))),
            );
        }
        all.insert(kind, links);
    }
    all
}

/// The pairs (i, j) of `a[i]` and `b[j]` within `reach` of each other,
/// nearest first, each index in one pair at most.
fn nearest_pairs(a: &[f64], b: &[f64], reach: f64) -> Vec<(usize, usize)> {
    let mut candidates: Vec<(f64, usize, usize)> = Vec::new();
    for (i, x) in a.iter().enumerate() {
        for (j, y) in b.iter().enumerate() {
            let d = (x - y).abs();
            if d <= reach {
                candidates.push((d, i, j));
            }
        }
    }
    candidates.sort_by(|p, q| p.0.total_cmp(&q.0).then((p.1, p.2).cmp(&(q.1, q.2))));
    let (mut used_a, mut used_b) = (vec![false; a.len()], vec![false; b.len()]);
    let mut pairs = Vec::new();
    for (_, i, j) in candidates {
        if !used_a[i] && !used_b[j] {
            used_a[i] = true;
            used_b[j] = true;
            pairs.push((i, j));
        }
    }
    pairs
}

/// `v`'s bits, mapped so that their order is the numbers' order.
fn ordered_bits(v: f64) -> u64 {
    let bits = v.to_bits();
    if bits >> 63 == 1 {
        !bits
    } else {
        bits | (1 << 63)
    }
}

fn from_ordered_bits(bits: u64) -> f64 {
    f64::from_bits(if bits >> 63 == 1 {
        bits & !(1 << 63)
    } else {
        !bits
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn points_of_one_kind_are_joined_nearest_first_across_neighbouring_values() {
        // Two grazing curves (kind 3) at three values of the second, the
        // third point too far to join; a fold (kind 0) at 1.0 and 2.0,
        // not joined over 1.5 where none was found.
        let points = [
            (0.7, 1.0, 3),
            (1.2, 1.0, 3),
            (1.21, 1.5, 3),
            (0.69, 1.5, 3),
            (0.6, 2.0, 3),
            (0.9, 1.0, 0),
            (0.9, 2.0, 0),
        ];
        let curves = curves(&points, &[1.0, 1.5, 2.0], 0.05);
        let mut grazing = curves[&3].clone();
        grazing.sort_by(|a, b| a.0 .0.total_cmp(&b.0 .0));
        assert_eq!(
            grazing,
            vec![((0.7, 1.0), (0.69, 1.5)), ((1.2, 1.0), (1.21, 1.5))]
        );
        assert!(curves[&0].is_empty());
        for v in [-2.5, -0.0, 0.0, 1e-300, 3.0] {
            assert_eq!(
                from_ordered_bits(ordered_bits(v)).to_bits(),
                f64::to_bits(v)
            );
        }
        assert!(ordered_bits(-2.5) < ordered_bits(-1.0) && ordered_bits(-1.0) < ordered_bits(0.5));
    }
}
