//! The figures: both files written whole at the promised size, the data drawn
//! where the layout puts it, degenerate sweeps drawn without panicking, and a
//! failed write leaving nothing behind.

use std::fs;
use std::path::Path;

use lyapsweep::output::plot::{
    heat_map, heat_map_pixels, sweep_figure, sweep_pixels, GridData, SweepData, DATA_COLOUR,
    HEAT_MAP_SIZE, SWEEP_SIZE,
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
