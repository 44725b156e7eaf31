//! The figures: both files written whole at the promised size, the data drawn
//! where the layout puts it, degenerate sweeps drawn without panicking, and a
//! failed write leaving nothing behind.

use std::fs;
use std::path::Path;

use base64::Engine;

use lyapsweep::output::plot::{
    heat_map, heat_map_pixels, orbit_map, orbit_map_pixels, sweep_figure, sweep_pixels, GridData,
    OrbitMapData, SweepData, DATA_COLOUR, HEAT_MAP_SIZE, SWEEP_SIZE,
};

/// A sweep shaped like the seed's Fig. 3: η over [0.5, 1.5], λ₁ = 0.05 sin 10η
/// and λ₂ = -0.1 - λ₁ (so the sum is the expected -0.1), and above them the
/// logistic map's attractor with r rising through its period doublings into
/// chaos.
fn sweep() -> SweepData {
    let lanes = 400;
    let values: Vec<f64> = (0..lanes)
        .map(|k| 0.5 + k as f64 / (lanes - 1) as f64)
        .collect();
    let exponents = values
        .iter()
        .map(|&eta| {
            let lambda1 = 0.05 * (10.0 * eta).sin();
            vec![lambda1, -0.1 - lambda1]
        })
        .collect();
    let bifurcation = values
        .iter()
        .flat_map(|&eta| {
            let r = 2.8 + 1.2 * (eta - 0.5);
            let step = move |x: f64| r * x * (1.0 - x);
            let settled = (0..200).fold(0.3, |x, _| step(x));
            std::iter::successors(Some(settled), move |&x| Some(step(x)))
                .take(50)
                .map(move |x| (eta, x))
        })
        .collect();
    SweepData {
        title: "seed-fig3".into(),
        parameter: "eta".into(),
        values,
        exponents,
        sum: vec![-0.1; lanes],
        expected_sum: vec![-0.1; lanes],
        per_unit_time: true,
        bifurcation,
        state_name: "x".into(),
    }
}

/// λ₁ on a 60 × 40 grid: negative on the left third, zero in the middle
/// third, positive on the right third; one failed lane, and one outlier so
/// large that a colour scale up to the maximum would wash the map out.
fn grid() -> GridData {
    let (nx, ny) = (60, 40);
    let x: Vec<f64> = (0..nx).map(|i| i as f64 / (nx - 1) as f64).collect();
    let y: Vec<f64> = (0..ny).map(|j| 2.0 + j as f64 / (ny - 1) as f64).collect();
    let mut lambda1: Vec<f64> = y
        .iter()
        .flat_map(|&y| {
            x.iter().map(move |&x| match x {
                x if x < 1.0 / 3.0 => -0.2 * y,
                x if x < 2.0 / 3.0 => 0.0,
                _ => 0.1 * y,
            })
        })
        .collect();
    lambda1[5] = f64::NAN;
    lambda1[nx * ny - 1] = 100.0;
    GridData {
        title: "zeta-eta".into(),
        x_name: "eta".into(),
        y_name: "zeta".into(),
        x,
        y,
        lambda1,
        per_unit_time: true,
    }
}

/// The width and height a PNG's header states (big-endian, bytes 16 to 23).
fn png_size(path: &Path) -> (u32, u32) {
    let bytes = fs::read(path).unwrap();
    assert_eq!(
        &bytes[..8],
        b"\x89PNG\r\n\x1a\n",
        "{} is a PNG",
        path.display()
    );
    let word = |at: usize| u32::from_be_bytes(bytes[at..at + 4].try_into().unwrap());
    (word(16), word(20))
}

/// The RGB pixels of a `width`-wide image, each with its row.
fn rows_and_pixels(pixels: &[u8], width: u32) -> impl Iterator<Item = (usize, [u8; 3])> + '_ {
    pixels
        .chunks_exact(3)
        .enumerate()
        .map(move |(k, p)| (k / width as usize, [p[0], p[1], p[2]]))
}

/// The files in `dir`, by name, sorted.
fn listing(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = fs::read_dir(dir)
        .unwrap()
        .map(|entry| entry.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

#[test]
fn sweep_figure_is_written_as_png_and_svg_at_its_size() {
    let dir = tempfile::tempdir().unwrap();
    let written = sweep_figure(&sweep(), dir.path(), "figure").unwrap();
    assert_eq!(
        written,
        [dir.path().join("figure.png"), dir.path().join("figure.svg")]
    );
    assert_eq!(png_size(&written[0]), SWEEP_SIZE);
    assert_eq!(SWEEP_SIZE, (1600, 1200));
    let svg = fs::read_to_string(&written[1]).unwrap();
    assert!(svg.contains("<svg"));
    assert!(svg.contains("seed-fig3") && svg.contains("η"));
    assert_eq!(listing(dir.path()), ["figure.png", "figure.svg"]);
}

#[test]
fn bifurcation_points_lie_above_and_exponents_below() {
    let (width, height) = SWEEP_SIZE;
    let pixels = sweep_pixels(&sweep());
    assert_eq!(pixels.len(), (width * height * 3) as usize);
    let half = height as usize / 2;
    let (mut above, mut below) = (0, 0);
    for (row, pixel) in rows_and_pixels(&pixels, width) {
        if pixel == [DATA_COLOUR.0, DATA_COLOUR.1, DATA_COLOUR.2] {
            if row < half {
                above += 1;
            } else {
                below += 1;
            }
        }
    }
    assert!(above + below > 2000, "{above} + {below} data pixels");
    assert!(above > 1000, "{above} bifurcation pixels");
    assert!(below > 500, "{below} λ1 pixels");
}

#[test]
fn without_exponents_the_diagram_takes_the_whole_figure() {
    // `lyapunov = "none"`: no exponent panel; the points spread over both
    // halves (the logistic attractor spans most of [0, 1]).
    let data = SweepData {
        values: Vec::new(),
        exponents: Vec::new(),
        sum: Vec::new(),
        expected_sum: Vec::new(),
        ..sweep()
    };
    let (width, height) = SWEEP_SIZE;
    let half = height as usize / 2;
    let (mut above, mut below) = (0, 0);
    for (row, pixel) in rows_and_pixels(&sweep_pixels(&data), width) {
        if pixel == [DATA_COLOUR.0, DATA_COLOUR.1, DATA_COLOUR.2] {
            if row < half {
                above += 1;
            } else {
                below += 1;
            }
        }
    }
    assert!(above > 1000 && below > 1000, "{above} above, {below} below");
}

#[test]
fn degenerate_sweeps_draw_without_panicking() {
    let dir = tempfile::tempdir().unwrap();
    let no_diagram = SweepData {
        bifurcation: Vec::new(),
        ..sweep()
    };
    let mut failed_lanes = sweep();
    for k in (0..failed_lanes.values.len()).step_by(7) {
        failed_lanes.exponents[k] = vec![f64::NAN, f64::NAN];
        failed_lanes.sum[k] = f64::NAN;
        failed_lanes.expected_sum[k] = f64::NAN;
    }
    for k in (3..failed_lanes.values.len()).step_by(11) {
        failed_lanes.exponents[k][1] = f64::NEG_INFINITY;
    }
    let nothing_finite = SweepData {
        exponents: vec![vec![f64::NAN, f64::NEG_INFINITY]; 400],
        sum: vec![f64::NAN; 400],
        expected_sum: vec![f64::NAN; 400],
        bifurcation: vec![(1.0, f64::NAN), (f64::NAN, 0.5)],
        ..sweep()
    };
    let one_value = SweepData {
        title: "one".into(),
        parameter: "f".into(),
        values: vec![0.0],
        exponents: vec![vec![0.0, 0.0, 0.0, -0.3]],
        sum: vec![-0.3],
        expected_sum: vec![-0.3],
        per_unit_time: false,
        bifurcation: vec![(0.0, 1.0)],
        state_name: "y".into(),
    };
    let empty = SweepData {
        values: Vec::new(),
        exponents: Vec::new(),
        sum: Vec::new(),
        expected_sum: Vec::new(),
        bifurcation: Vec::new(),
        ..sweep()
    };
    for (stem, data) in [
        ("no-diagram", &no_diagram),
        ("failed-lanes", &failed_lanes),
        ("nothing-finite", &nothing_finite),
        ("one-value", &one_value),
        ("empty", &empty),
    ] {
        sweep_pixels(data);
        let written = sweep_figure(data, dir.path(), stem).unwrap();
        assert_eq!(png_size(&written[0]), SWEEP_SIZE, "{stem}");
    }
}

#[test]
fn heat_map_diverges_from_white_at_zero() {
    let (width, height) = HEAT_MAP_SIZE;
    let pixels = heat_map_pixels(&grid());
    assert_eq!(pixels.len(), (width * height * 3) as usize);
    let (mut red, mut blue, mut near_white) = (0, 0, 0);
    for (_, [r, g, b]) in rows_and_pixels(&pixels, width) {
        let (r, g, b) = (i32::from(r), i32::from(g), i32::from(b));
        red += usize::from(r > g + 60 && r > b + 60);
        blue += usize::from(b > r + 60 && b > g + 30);
        // Not the white background: the scale's centre is a hair below it.
        near_white += usize::from(r.min(g).min(b) >= 235 && (r, g, b) != (255, 255, 255));
    }
    // Each third of the map is about 300 000 pixels; the one outlier must
    // not have paled the positive third below "reddish".
    assert!(red > 100_000, "{red} reddish pixels");
    assert!(blue > 100_000, "{blue} bluish pixels");
    assert!(near_white > 100_000, "{near_white} near-white pixels");
}

#[test]
fn heat_map_is_written_as_png_and_svg_at_its_size() {
    let dir = tempfile::tempdir().unwrap();
    let written = heat_map(&grid(), dir.path(), "lambda1").unwrap();
    assert_eq!(png_size(&written[0]), HEAT_MAP_SIZE);
    let svg = fs::read_to_string(&written[1]).unwrap();
    assert!(svg.contains("<svg") && svg.contains("ζ"));
    assert_eq!(listing(dir.path()), ["lambda1.png", "lambda1.svg"]);
}

/// λ₁ on a 700 × 600 grid, finer than the map's pixels, in blocks of
/// 100 × 100 cells: +0.1 where the block's column and row add up to an even
/// number, -0.1 elsewhere.
fn fine_grid() -> GridData {
    let (nx, ny) = (700, 600);
    let x: Vec<f64> = (0..nx).map(|i| i as f64 / (nx - 1) as f64).collect();
    let y: Vec<f64> = (0..ny).map(|j| 2.0 + j as f64 / (ny - 1) as f64).collect();
    let lambda1 = (0..nx * ny)
        .map(|k| match (k % nx / 100 + k / nx / 100) % 2 {
            0 => 0.1,
            _ => -0.1,
        })
        .collect();
    GridData {
        title: "fine".into(),
        x_name: "eta".into(),
        y_name: "zeta".into(),
        x,
        y,
        lambda1,
        per_unit_time: true,
    }
}

/// The attribute `name` of an SVG tag's text.
fn attribute<'a>(tag: &'a str, name: &str) -> &'a str {
    let start = tag.find(&format!(" {name}=\"")).unwrap() + name.len() + 3;
    &tag[start..start + tag[start..].find('"').unwrap()]
}

#[test]
fn a_map_finer_than_its_pixels_is_one_raster_that_the_svg_embeds_pixel_for_pixel() {
    let data = fine_grid();
    let dir = tempfile::tempdir().unwrap();
    let written = heat_map(&data, dir.path(), "fine").unwrap();
    let svg = fs::read_to_string(&written[1]).unwrap();
    // A rectangle a cell would be 420 000 of them, about 36 MB.
    assert!(svg.len() < 300_000, "{} bytes of SVG", svg.len());
    assert_eq!(svg.matches("<image").count(), 1);
    let tag = &svg[svg.find("<image").unwrap()..];
    let tag = &tag[..tag.find("/>").unwrap()];
    let number = |name: &str| attribute(tag, name).parse::<usize>().unwrap();
    let (left, top, width, height) = (number("x"), number("y"), number("width"), number("height"));
    let png = attribute(tag, "href")
        .strip_prefix("data:image/png;base64,")
        .unwrap();
    let png = base64::engine::general_purpose::STANDARD
        .decode(png)
        .unwrap();
    let mut reader = png::Decoder::new(std::io::Cursor::new(png))
        .read_info()
        .unwrap();
    let mut raster = vec![0; reader.output_buffer_size()];
    let frame = reader.next_frame(&mut raster).unwrap();
    assert_eq!((frame.width, frame.height), (width as u32, height as u32));
    assert_eq!(frame.color_type, png::ColorType::Rgb);

    // The SVG's image is the PNG figure's map, pixel for pixel (inside the
    // frame, which both draw over the map's edge).
    let figure = heat_map_pixels(&data);
    let figure_width = HEAT_MAP_SIZE.0 as usize;
    for row in 1..height - 1 {
        let at = 3 * ((top + row) * figure_width + left);
        let same = figure[at + 3..at + 3 * (width - 1)]
            == raster[3 * (row * width + 1)..3 * ((row + 1) * width - 1)];
        assert!(same, "row {row} of the map differs");
    }
    // And the raster is the data: each block's centre has its sign's colour
    // (the cells span the map, first row at the bottom).
    for (bi, bj) in (0..7).flat_map(|bi| (0..6).map(move |bj| (bi, bj))) {
        let column = (width as f64 * (bi as f64 * 100.0 + 50.5) / 700.0) as usize;
        let row = (height as f64 * (1.0 - (bj as f64 * 100.0 + 50.5) / 600.0)) as usize;
        let p = &raster[3 * (row * width + column)..][..3];
        let (r, b) = (i32::from(p[0]), i32::from(p[2]));
        let positive = (bi + bj) % 2 == 0;
        assert_eq!(
            (r > b + 60, b > r + 60),
            (positive, !positive),
            "block ({bi}, {bj}): {p:?}"
        );
    }
}

#[test]
fn a_map_of_few_cells_stays_a_rectangle_a_cell_in_the_svg() {
    let dir = tempfile::tempdir().unwrap();
    let written = heat_map(&grid(), dir.path(), "coarse").unwrap();
    let svg = fs::read_to_string(&written[1]).unwrap();
    assert!(!svg.contains("<image"));
    assert!(svg.matches("<rect").count() >= 60 * 40);
}

#[test]
fn a_failed_write_is_an_error_and_leaves_nothing_behind() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("not-a-folder");
    fs::write(&file, "").unwrap();
    let missing = dir.path().join("missing");
    for target in [&file, &missing] {
        let error = sweep_figure(&sweep(), target, "figure").unwrap_err();
        assert!(
            matches!(&error, lyapsweep::Error::Write { path, .. } if path == &target.join("figure.png")),
            "{error}"
        );
        let error = heat_map(&grid(), target, "map").unwrap_err();
        assert!(matches!(error, lyapsweep::Error::Write { .. }), "{error}");
    }
    assert_eq!(listing(dir.path()), ["not-a-folder"]);
}

/// The orbits map: the bifurcations over the heat map, each kind in its
/// colour (period doublings magenta, folds green) and joined into curves
/// across neighbouring values of the second parameter, written at the heat
/// map's size.
#[test]
fn orbits_map_draws_each_kind_s_points_and_curves_over_the_heat_map() {
    let grid = grid();
    let ys = grid.y.clone();
    // A period-doubling curve (kind 1) at x = 0.2 + 0.1 (y - 2), a fold
    // (kind 0) at x = 0.8 on every other value.
    let mut points: Vec<(f64, f64, usize)> =
        ys.iter().map(|&y| (0.2 + 0.1 * (y - 2.0), y, 1)).collect();
    points.extend(ys.iter().step_by(2).map(|&y| (0.8, y, 0)));
    let kinds = [
        "LP fold",
        "PD period-doubling",
        "NS neimark-sacker",
        "GR grazing",
        "SL sliding",
        "EC events-change",
    ];
    let data = OrbitMapData {
        grid,
        kinds: kinds.map(String::from).to_vec(),
        points,
    };
    let (width, _) = HEAT_MAP_SIZE;
    let pixels = orbit_map_pixels(&data);
    let count = |colour: [u8; 3]| {
        rows_and_pixels(&pixels, width)
            .filter(|(_, p)| *p == colour)
            .count()
    };
    let (magenta, green) = (count([200, 0, 200]), count([0, 160, 0]));
    // Forty markers and the line through them; twenty markers, not joined
    // (the fold is not found at every other value).
    assert!(magenta > 2_000, "{magenta} magenta pixels");
    assert!(green > 1_000, "{green} green pixels");
    let dir = tempfile::tempdir().unwrap();
    let written = orbit_map(&data, dir.path(), "orbits-map").unwrap();
    assert_eq!(png_size(&written[0]), HEAT_MAP_SIZE);
    let svg = fs::read_to_string(&written[1]).unwrap();
    assert!(svg.contains("PD period-doubling") && svg.contains("LP fold"));
    assert!(
        !svg.contains("GR grazing"),
        "a kind with no point is not in the legend"
    );
}
