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
//!
//! One file per figure: `sweep`, `attractor_sweep`, `heat_map`,
//! `attractor_map`, `orbit_sweep` (the branches of `[orbits]` over the
//! sweep's points), `orbit_map` (with two parameters, their bifurcations
//! over the heat map) and `basin_map` (one value's basins over its starts).
//! What they share: `style` (sizes, colours, fonts,
//! spacing), `render` (the drawing backend's choice: pixels, PNG and SVG
//! files written whole), `figure` (the embedded font and the PNG encoder),
//! `svg_raster` (the SVG backend that embeds bitmaps), `panel` (axes, ranges
//! and a bifurcation diagram's points), `legend`, and `grid` (the cells and
//! colour bar of the two maps).

mod attractor_map;
mod attractor_sweep;
mod basin_map;
pub mod figure;
mod grid;
mod heat_map;
mod legend;
mod orbit_map;
mod orbit_sweep;
mod panel;
mod render;
mod style;
pub mod svg_raster;
mod sweep;

pub use attractor_map::{attractor_map, attractor_map_pixels, CountData};
pub use attractor_sweep::{attractor_figure, attractor_pixels, AttractorSweepData, Branch};
pub use basin_map::{basin_map, basin_map_pixels, label_colour, BasinData};
pub use heat_map::{heat_map, heat_map_pixels, GridData};
pub use orbit_map::{orbit_map, orbit_map_pixels, OrbitMapData};
pub use orbit_sweep::{orbit_figure, OrbitSweepData};
pub use render::write_png;
pub use style::{ATTRACTOR_SWEEP_SIZE, DATA_COLOUR, HEAT_MAP_SIZE, SWEEP_SIZE};
pub use sweep::{sweep_figure, sweep_pixels, SweepData};
