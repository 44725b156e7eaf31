//! `[orbits]` run from a scene: the table's keys checked before any work,
//! the branches traced after the sweep, written as `orbits.csv` and
//! `bifurcations.csv`.

mod common;

use std::collections::BTreeMap;
use std::path::Path;
use std::process::{Command, Output};

const ZETA: f64 = 0.05;
/// Where the seed's non-impacting period-1 orbit grazes the wall: its
/// linear amplitude f/√((1-η²)² + (2ζη)²) equals X_w = 2.
const GRAZING: [f64; 2] = [0.7106873690939233, 1.2185743569476413];

fn seed_path() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/seed-fig3.toml")
}

fn lyapsweep(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_lyapsweep"))
        .args(args)
        .output()
        .expect("the binary runs")
}

fn stderr(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).into_owned()
}

/// A CSV file as rows of named cells.
fn read(path: &Path) -> Vec<BTreeMap<String, String>> {
    let mut reader = csv::Reader::from_path(path).expect("the file reads");
    let header = reader.headers().unwrap().clone();
    reader
        .records()
        .map(|r| {
            let r = r.unwrap();
            header
                .iter()
                .zip(r.iter())
                .map(|(h, v)| (h.to_owned(), v.to_owned()))
                .collect()
        })
        .collect()
}

fn value(row: &BTreeMap<String, String>, column: &str) -> f64 {
    row[column]
        .parse()
        .unwrap_or_else(|_| panic!("{column}: {:?}", row[column]))
}

/// The seed's scene over η ∈ [0.5, 1.5] at 21 values (1800 steps per
/// period, as committed), with `[orbits]` at its defaults.
#[test]
fn the_seed_s_branches_are_written_with_their_grazing_points_and_exponents() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let output = lyapsweep(&[
        "run",
        seed_path().to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--set",
        "sweep.count=21",
        "--set",
        "orbits={}",
        "--set",
        "run.backend=\"cpu\"",
    ]);
    assert_eq!(output.status.code(), Some(0), "{}", stderr(&output));
    let manifest = std::fs::read_to_string(out.join("manifest.toml")).unwrap();
    assert!(manifest.contains("\"orbits.csv\""), "{manifest}");
    assert!(manifest.contains("\"bifurcations.csv\""), "{manifest}");

    let bifurcations = read(&out.join("bifurcations.csv"));
    let grazing: Vec<f64> = bifurcations
        .iter()
        .filter(|r| r["kind"] == "grazing")
        .map(|r| value(r, "eta"))
        .collect();
    for exact in GRAZING {
        let nearest = grazing
            .iter()
            .map(|g| (g - exact).abs())
            .fold(f64::INFINITY, f64::min);
        assert!(
            nearest < 1e-8,
            "grazing at {exact}: {nearest:e} off ({grazing:?})"
        );
    }

    let orbits = read(&out.join("orbits.csv"));
    // The non-impacting period-1 branches: the lanes at both ends of the
    // range start them.
    let free: Vec<_> = orbits
        .iter()
        .filter(|r| {
            r["period"] == "1" && r["impacts_per_period"] == "0" && !r["lambda_1"].is_empty()
        })
        .collect();
    assert!(free.len() > 20, "{} non-impacting rows", free.len());
    for row in &free {
        let eta = value(row, "eta");
        assert!(
            eta <= GRAZING[0] + 1e-8 || eta >= GRAZING[1] - 1e-8,
            "η = {eta}"
        );
        for column in ["lambda_1", "lambda_2"] {
            let error = (value(row, column) + ZETA).abs();
            assert!(error < 1e-10, "η = {eta}: {column} off -ζ by {error:e}");
        }
        assert_eq!(row["status"], "ok", "η = {eta}");
        assert_eq!(row["stable"], "true");
    }
    // Both ends of the range are reached, and the grazing ends say why.
    let etas: Vec<f64> = free.iter().map(|r| value(r, "eta")).collect();
    assert!(etas.contains(&0.5) && etas.contains(&1.5), "{etas:?}");
    // A row is `ok` only where its exponents meet the sum rule.
    for row in &orbits {
        if row["status"] == "ok" {
            let miss = value(row, "lambda_sum") - value(row, "expected_sum");
            assert!(miss.abs() <= 1e-8, "{row:?}");
            assert!(!row["multiplier_1_modulus"].is_empty());
        } else if row["lambda_1"].is_empty() {
            assert!(
                row["status"].starts_with("no-orbit")
                    || row["status"].starts_with("period-above-max"),
                "{row:?}"
            );
        }
    }
    // Every branch's rows are in one run of the file, the first and last
    // saying how the branch ended there.
    let branches: Vec<&str> = orbits.iter().map(|r| r["branch"].as_str()).collect();
    let mut seen = Vec::new();
    for (k, b) in branches.iter().enumerate() {
        let first = k == 0 || branches[k - 1] != *b;
        let last = k + 1 == branches.len() || branches[k + 1] != *b;
        if first {
            assert!(!seen.contains(b), "branch {b} split");
            seen.push(b);
        }
        if (first || last) && !orbits[k]["lambda_1"].is_empty() {
            assert!(!orbits[k]["branch_end"].is_empty(), "{:?}", orbits[k]);
        }
    }
}

/// Each bad key refused by name, exit code 2, nothing written.
#[test]
fn bad_orbits_keys_are_refused_by_name_before_any_work() {
    let cases: [(&str, &str); 14] = [
        ("orbits={ max_period = 0 }", "orbits.max_period"),
        ("orbits={ max_points = 1 }", "orbits.max_points"),
        ("orbits={ min_step = -1.0 }", "orbits.min_step"),
        ("orbits={ max_step = 5.0 }", "orbits.max_step"),
        (
            "orbits={ min_step = 0.1, max_step = 0.01 }",
            "orbits.min_step",
        ),
        ("orbits={ tolerance = 0.5 }", "orbits.tolerance"),
        ("orbits={ tolerance = nan }", "orbits.tolerance"),
        (
            "orbits={ locate_tolerance = 1.0 }",
            "orbits.locate_tolerance",
        ),
        ("orbits={ typo = 1 }", "typo"),
        (
            "orbits={ list = [{ value = 2.0, state = [0.0, 0.0], period = 1 }] }",
            "orbits.list[0].value",
        ),
        (
            "orbits={ list = [{ value = 0.8, state = [0.0], period = 1 }] }",
            "orbits.list[0].state",
        ),
        (
            "orbits={ list = [{ value = 0.8, state = [2.5, 0.0], period = 1 }] }",
            "orbits.list[0].state",
        ),
        (
            "orbits={ list = [{ value = 0.8, state = [0.0, 0.0], period = 0 }] }",
            "orbits.list[0].period",
        ),
        (
            "orbits={ list = [{ value = 0.8, state = [0.0, 0.0] }] }",
            "orbits.list[0]",
        ),
    ];
    for (set, key) in cases {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out");
        let output = lyapsweep(&[
            "run",
            seed_path().to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--set",
            set,
        ]);
        let text = stderr(&output);
        assert_eq!(output.status.code(), Some(2), "{set}: {text}");
        assert!(text.contains(key), "{set}: {key} not in {text}");
        assert!(!out.exists(), "{set}: wrote {out:?}");
        let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert!(left.is_empty(), "{set}: left {left:?}");
    }
}

/// A shard cannot follow branches over the whole range: refused naming
/// `--shard`. With two swept parameters a listed orbit names its value of
/// the second (`second`, in its range), and with one it names none: each
/// refused naming the key, as an input error, before any work.
#[test]
fn orbits_need_the_whole_sweep_and_listed_orbits_their_second_value() {
    let two = |list: &str| {
        format!(
            "{}[sweep]\nparameter = \"eta\"\nvalues = [0.8, 0.9]\n[sweep.second]\nparameter = \"f\"\nvalues = [1.0, 2.0]\n[orbits]\n{list}",
            common::SEED
        )
    };
    let scene = lyapsweep::scene::parse(&two(""), "t", "t", &[]).expect("two parameters");
    assert!(scene.orbits.is_some());
    let listed = "list = [{ value = 0.8, second = 1.5, state = [0.0, 0.0], period = 1 }]\n";
    let scene = lyapsweep::scene::parse(&two(listed), "t", "t", &[]).expect("second in range");
    assert_eq!(scene.orbits.unwrap().list[0].second, Some(1.5));
    for list in [
        "list = [{ value = 0.8, state = [0.0, 0.0], period = 1 }]\n",
        "list = [{ value = 0.8, second = 2.5, state = [0.0, 0.0], period = 1 }]\n",
        "list = [{ value = 0.8, second = nan, state = [0.0, 0.0], period = 1 }]\n",
    ] {
        let error = lyapsweep::scene::parse(&two(list), "t", "t", &[]).unwrap_err();
        assert!(
            error.to_string().contains("orbits.list[0].second"),
            "{error}"
        );
        assert!(lyapsweep::Error::is_input_error(&error), "{error}");
    }
    let one = |list: &str| {
        format!(
            "{}[sweep]\nparameter = \"eta\"\nvalues = [0.8, 0.9]\n[orbits]\n{list}",
            common::SEED
        )
    };
    let list = "list = [{ value = 0.8, second = 1.0, state = [0.0, 0.0], period = 1 }]\n";
    let error = lyapsweep::scene::parse(&one(list), "t", "t", &[]).unwrap_err();
    assert!(
        error.to_string().contains("orbits.list[0].second"),
        "{error}"
    );
    let shard = lyapsweep::scene::Shard { index: 0, count: 2 };
    for text in [one(""), two("")] {
        let error = lyapsweep::scene::parse_shard(&text, "t", "t", &[], Some(shard)).unwrap_err();
        assert!(error.to_string().contains("--shard"), "{error}");
    }
    // A range of one value has nothing to follow.
    let single = format!(
        "{}[sweep]\nparameter = \"eta\"\nvalues = [0.8]\n[orbits]\n",
        common::SEED
    );
    let error = lyapsweep::scene::parse(&single, "t", "t", &[]).unwrap_err();
    assert!(error.to_string().contains("orbits"), "{error}");
}

/// A start whose branch cannot be traced (its period above `max_period`)
/// is a row of its own with the reason, and the other branches are traced
/// as without it.
#[test]
fn a_start_that_gives_no_branch_is_a_row_with_its_reason_and_the_others_go_on() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let output = lyapsweep(&[
        "run",
        seed_path().to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--set",
        "sweep.count=11",
        "--set",
        "orbits={ max_period = 1 }",
        "--set",
        "run.backend=\"cpu\"",
    ]);
    assert_eq!(output.status.code(), Some(0), "{}", stderr(&output));
    let orbits = read(&out.join("orbits.csv"));
    let refused: Vec<_> = orbits
        .iter()
        .filter(|r| r["status"].starts_with("period-above-max"))
        .collect();
    assert!(!refused.is_empty(), "no start above max_period");
    for row in &refused {
        assert!(
            row["lambda_1"].is_empty() && row["stable"].is_empty(),
            "{row:?}"
        );
        assert_ne!(row["period"], "1");
    }
    assert!(orbits
        .iter()
        .all(|r| r["period"] != "1" || !r["lambda_1"].is_empty()));
    // The free orbit's two grazings, each located once: the impacting
    // period-1 orbit beyond the first (its impact's speed falling to 0
    // there) is the branch switched past it, not a second grazing.
    let grazing: Vec<f64> = read(&out.join("bifurcations.csv"))
        .iter()
        .filter(|r| r["kind"] == "grazing")
        .map(|r| r["eta"].parse().unwrap())
        .collect();
    assert_eq!(grazing.len(), 2, "{grazing:?}");
    for exact in GRAZING {
        assert!(
            grazing.iter().any(|eta| (eta - exact).abs() < 1e-8),
            "{grazing:?}"
        );
    }
    let past: Vec<_> = orbits
        .iter()
        .filter(|r| r["branch_end"].starts_with("grazing(from-branch="))
        .collect();
    assert!(
        past.iter()
            .any(|r| r["impacts_per_period"] == "1" && value(r, "eta") > GRAZING[0]),
        "{past:?}"
    );
}

/// The rows of branch `branch` of `orbits.csv`, in order.
fn rows_of<'a>(
    orbits: &'a [BTreeMap<String, String>],
    branch: &str,
) -> Vec<&'a BTreeMap<String, String>> {
    orbits.iter().filter(|r| r["branch"] == branch).collect()
}

/// The seed's run switches branches: at the impacting period-1 orbit's
/// period doubling (η ≈ 0.9863) the doubled branch is traced from the
/// doubling point itself, a genuine period-2 orbit away from it; and the
/// non-impacting orbit's grazing at η = 0.7106873690939233 is continued
/// past, as the impacting orbit on the wall's side. Each such branch is a
/// branch of its own whose first row says where it came from.
#[test]
fn the_seed_s_run_switches_at_its_period_doubling_and_goes_on_past_its_grazing() {
    use lyapsweep::orbit::{evaluate, relative_residual};
    use lyapsweep::plan::method_settings;
    use lyapsweep::scene::{Backend, Precision};
    use lyapsweep::system::System;

    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let output = lyapsweep(&[
        "run",
        seed_path().to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--set",
        "sweep.count=21",
        "--set",
        "orbits={}",
        "--set",
        "run.backend=\"cpu\"",
    ]);
    assert_eq!(output.status.code(), Some(0), "{}", stderr(&output));
    let orbits = read(&out.join("orbits.csv"));
    let bifurcations = read(&out.join("bifurcations.csv"));
    let period = |branch: &str| rows_of(&orbits, branch)[0]["period"].clone();

    // The period-1 orbit's doubling, and the branch switched there.
    let doubling = bifurcations
        .iter()
        .find(|r| r["kind"] == "period-doubling" && period(&r["branch"]) == "1")
        .expect("a period doubling of a period-1 branch");
    let at = value(doubling, "eta");
    let from = format!("period-doubling(from-branch={})", doubling["branch"]);
    let doubled = orbits
        .iter()
        .find(|r| r["branch_end"] == from)
        .map(|r| rows_of(&orbits, &r["branch"]))
        .unwrap_or_else(|| panic!("no branch starts with {from}"));
    let first = value(doubled[0], "eta");
    assert!((first - at).abs() < 1e-8, "{first} against {at}");
    assert!(doubled.iter().all(|r| r["period"] == "2"));
    // Away from the doubling point it is a genuine period-2 orbit: U(x) is
    // not x, U²(x) is.
    let scene = lyapsweep::scene::parse(
        &std::fs::read_to_string(seed_path()).unwrap(),
        "seed",
        "seed",
        &["sweep.count=2".to_owned()],
    )
    .unwrap();
    let settings = method_settings(&scene, Backend::Cpu, Precision::F64);
    let index = scene.system.parameter_index("eta").expect("eta");
    let away = doubled
        .iter()
        .max_by(|a, b| {
            let d = |r: &&&BTreeMap<String, String>| (value(r, "eta") - at).abs();
            d(a).total_cmp(&d(b))
        })
        .unwrap();
    let eta = value(away, "eta");
    let params = lyapsweep::orbit::params_at(&scene.lane_params(0), index, eta);
    let system = lyapsweep::system::model::ModelFlow::<2>::new(&params);
    let x = [value(away, "x"), value(away, "v")];
    let once = evaluate(&system, &settings, &x, 1, false).image;
    let twice = evaluate(&system, &settings, &x, 2, false).image;
    let (apart, closed) = (relative_residual(&x, &once), relative_residual(&x, &twice));
    eprintln!("doubled branch at η = {eta}: |U(x) - x| = {apart:e}, |U²(x) - x| = {closed:e}");
    assert!(apart > 1e-2 && closed < 1e-10, "{apart:e} {closed:e}");

    // The free orbit's grazing, continued past on the wall's side.
    let grazing = bifurcations
        .iter()
        .find(|r| r["kind"] == "grazing" && (value(r, "eta") - GRAZING[0]).abs() < 1e-8)
        .expect("the free orbit's grazing");
    let free = rows_of(&orbits, &grazing["branch"]);
    assert!(free.iter().all(|r| r["impacts_per_period"] == "0"));
    let from = format!("grazing(from-branch={})", grazing["branch"]);
    let past = orbits
        .iter()
        .find(|r| r["branch_end"] == from)
        .map(|r| rows_of(&orbits, &r["branch"]))
        .unwrap_or_else(|| panic!("no branch starts with {from}"));
    let first = value(past[0], "eta");
    eprintln!(
        "past the grazing: first point at η = {first}, {} points",
        past.len()
    );
    assert!(first > GRAZING[0] && first - GRAZING[0] < 1e-3, "{first}");
    assert!(past.len() > 20);
    assert!(past.iter().all(|r| r["impacts_per_period"] == "1"));
    // Every row is of its least period: no branch runs into a shorter
    // orbit counted over (but for a doubled branch's first row, the
    // doubling point itself).
    for row in orbits.iter().filter(|r| !r["x"].is_empty()) {
        let p: usize = row["period"].parse().unwrap();
        if p == 1 || row["branch_end"].starts_with("period-doubling(") {
            continue;
        }
        let params = lyapsweep::orbit::params_at(&scene.lane_params(0), index, value(row, "eta"));
        let system = lyapsweep::system::model::ModelFlow::<2>::new(&params);
        let x = [value(row, "x"), value(row, "v")];
        for d in (1..p).filter(|d| p % d == 0) {
            let apart = relative_residual(&x, &evaluate(&system, &settings, &x, d, false).image);
            let branch = &row["branch"];
            assert!(
                apart > 1e-6,
                "branch {branch} (period {p}) is of period {d}: {apart:e}"
            );
        }
    }
    // Each branch once: no two branches share a point.
    let mut seen = BTreeMap::new();
    for r in orbits.iter().filter(|r| !r["lambda_1"].is_empty()) {
        let key = (r["eta"].clone(), r["x"].clone(), r["period"].clone());
        let branch = seen.entry(key).or_insert_with(|| r["branch"].clone());
        assert_eq!(*branch, r["branch"], "{r:?} on two branches");
    }
}

/// The wall oscillator of docs/python.md (the seed's system with the wall
/// at X_w = 1 and e = 0.8): its impacting period-1 orbit's impact passes
/// through the map's section at η ≈ 0.90318, where the orbit's point
/// jumps from just after the impact (v < 0) to just before it (v > 0,
/// -e·v the same speed after). The orbit does not change there: traced
/// from the lanes at η = 0.8, 0.9031 and 1.0062, it is one branch with
/// points on both sides, whose exponents on either side are the exact
/// backend's tangent's (the closed form's Jacobian at the row's own point)
/// to 1e-10; the lane at 0.9031, between the two rows the point jumps
/// between, is on that branch, not the start of a second one.
#[test]
fn an_impact_at_the_section_s_time_leaves_the_orbit_one_branch() {
    use lyapsweep::system::{Part, System};

    let keys = [
        "system.wall=1.0",
        "system.restitution=0.8",
        "sweep.from=0.8",
        "sweep.to=1.0062",
        "sweep.count=3",
        "orbits={ max_period = 1 }",
        "run.backend=\"cpu\"",
    ];
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let seed = seed_path();
    let mut args = vec!["run", seed.to_str().unwrap(), "--out"];
    args.push(out.to_str().unwrap());
    for key in &keys {
        args.extend(["--set", key]);
    }
    let output = lyapsweep(&args);
    assert_eq!(output.status.code(), Some(0), "{}", stderr(&output));
    let orbits = read(&out.join("orbits.csv"));
    let scene = lyapsweep::scene::parse(
        &std::fs::read_to_string(seed_path()).unwrap(),
        "seed",
        "seed",
        &keys[..4].iter().map(|k| k.to_string()).collect::<Vec<_>>(),
    )
    .unwrap();
    let index = scene.system.parameter_index("eta").expect("eta");
    // The signed time from the row's point to the wall, in periods: > 0
    // moving towards it, < 0 just away from it.
    let clearance = |r: &BTreeMap<String, String>| {
        let period = std::f64::consts::TAU / value(r, "eta");
        -(value(r, "x") - 1.0) / value(r, "v") / period
    };
    let impacting: Vec<_> = orbits
        .iter()
        .filter(|r| r["period"] == "1" && r["impacts_per_period"] == "1")
        .collect();
    let crossing = impacting
        .windows(2)
        .find(|pair| {
            pair[0]["branch"] == pair[1]["branch"]
                && clearance(pair[0]).signum() != clearance(pair[1]).signum()
        })
        .unwrap_or_else(|| {
            let ends: Vec<_> = impacting
                .iter()
                .filter(|r| !r["branch_end"].is_empty())
                .map(|r| (&r["branch"], &r["eta"], &r["branch_end"]))
                .collect();
            panic!("no branch goes through the section's impact: {ends:?}")
        });
    let branches: std::collections::BTreeSet<_> = impacting.iter().map(|r| &r["branch"]).collect();
    assert_eq!(
        branches.len(),
        1,
        "the impacting orbit on branches {branches:?}"
    );
    let (before, after) = (value(crossing[0], "eta"), value(crossing[1], "eta"));
    eprintln!(
        "section crossed between η = {before} (v = {}) and {after} (v = {})",
        crossing[0]["v"], crossing[1]["v"]
    );
    assert!(before.min(after) < 0.90318 && before.max(after) > 0.90318);
    // The branch's rows near the crossing, on both sides, against the
    // closed form's tangent at their own points.
    let rows = rows_of(&orbits, &crossing[0]["branch"]);
    let near: Vec<_> = rows
        .iter()
        .filter(|r| (value(r, "eta") - 0.90318).abs() < 0.05)
        .collect();
    let sides = near.iter().filter(|r| clearance(r) > 0.0).count();
    assert!(sides >= 2 && near.len() - sides >= 2, "{} rows", near.len());
    let mut worst = 0.0_f64;
    for row in &near {
        let eta = value(row, "eta");
        let params = lyapsweep::orbit::params_at(&scene.lane_params(0), index, eta);
        let system = lyapsweep::system::model::ModelFlow::<2>::new(&params);
        let x = [value(row, "x"), value(row, "v")];
        let (_, j) = system
            .iterate_exact(&x, Part::WHOLE, &mut Default::default())
            .expect("the seed's closed form");
        let m = nalgebra::DMatrix::from_fn(2, 2, |r, c| j[(r, c)]);
        let mut exact: Vec<f64> = m
            .complex_eigenvalues()
            .iter()
            .map(|e| e.norm().ln() / system.period())
            .collect();
        exact.sort_by(|a, b| b.total_cmp(a));
        for (k, column) in ["lambda_1", "lambda_2"].iter().enumerate() {
            let error = (value(row, column) - exact[k]).abs();
            assert!(error < 1e-10, "η = {eta}: {column} off by {error:e}");
            worst = worst.max(error);
        }
        assert_eq!(row["status"], "ok", "η = {eta}");
    }
    eprintln!(
        "{} rows within 0.05 of the crossing: exponents off the closed form's tangent by {worst:e}",
        near.len()
    );
}

/// Where the free period-1 orbit of the seed at forcing `f` grazes the
/// wall X_w = 2 over η ∈ [0.5, 1.5]: the roots of the linear amplitude
/// f/√((1-η²)² + (2ζη)²) - 2, each bracketed on a fine grid and bisected
/// to the last bit (the closed form, not the tool's code).
fn free_grazings(f: f64) -> Vec<f64> {
    let excess = |eta: f64| {
        let d = (1.0 - eta * eta).powi(2) + (2.0 * ZETA * eta).powi(2);
        f / d.sqrt() - 2.0
    };
    let grid: Vec<f64> = (0..=10_000).map(|k| 0.5 + k as f64 * 1e-4).collect();
    let mut roots = Vec::new();
    for pair in grid.windows(2) {
        let (mut a, mut b) = (pair[0], pair[1]);
        if excess(a).signum() == excess(b).signum() {
            continue;
        }
        for _ in 0..200 {
            let m = 0.5 * (a + b);
            if m <= a || m >= b {
                break;
            }
            if excess(m).signum() == excess(a).signum() {
                a = m;
            } else {
                b = m;
            }
        }
        roots.push(0.5 * (a + b));
    }
    roots
}

/// The seed run over two parameters, `[orbits]` at its defaults: the
/// one-parameter stage at each value of f, written in one file.
fn two_parameter_run(out: &Path, forcings: &str, threads: &str) -> Output {
    Command::new(env!("CARGO_BIN_EXE_lyapsweep"))
        .args([
            "run",
            seed_path().to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--set",
            "sweep.count=21",
            "--set",
            &format!("sweep.second={{ parameter = \"f\", values = [{forcings}] }}"),
            "--set",
            "orbits={}",
            "--set",
            "run.backend=\"cpu\"",
        ])
        .env("RAYON_NUM_THREADS", threads)
        .output()
        .expect("the binary runs")
}

/// With `[sweep.second]`, branches are followed in η at each value of f:
/// every free orbit's grazing at each f is located within 1e-8 of the
/// closed form; the rows carry f as spectrum.csv names it, numbered
/// through the file; the files do not depend on the number of threads;
/// and the orbits map is drawn.
#[test]
fn two_parameters_trace_branches_at_each_second_value_and_grazings_match_the_closed_form() {
    // At f = 1.6 no lane ends on the free orbit above its grazing at
    // η = 1.3374 (each ends on an impacting one), so no branch of it is
    // traced there: the starts are the lanes'.
    let forcings = [0.6, 0.8, 1.0];
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let output = two_parameter_run(&out, "0.6, 0.8, 1.0", "2");
    assert_eq!(output.status.code(), Some(0), "{}", stderr(&output));
    let header = std::fs::read_to_string(out.join("orbits.csv")).unwrap();
    assert!(
        header.starts_with("branch,eta,f,x,v,period,"),
        "{header:.80}"
    );
    let header = std::fs::read_to_string(out.join("bifurcations.csv")).unwrap();
    assert!(header.starts_with("branch,kind,eta,f,x,v,"), "{header:.80}");
    // Named as the sweep's own file (grid.csv for two parameters) names them.
    let grid = std::fs::read_to_string(out.join("grid.csv")).unwrap();
    assert!(grid.starts_with("eta,f,"), "{grid:.40}");
    for name in ["orbits-map.png", "orbits-map.svg", "heat-map.png"] {
        assert!(out.join(name).is_file(), "{name} not written");
    }
    assert!(!out.join("orbits.png").exists());

    let bifurcations = read(&out.join("bifurcations.csv"));
    for f in forcings {
        let exact = free_grazings(f);
        assert!(!exact.is_empty(), "f = {f}: no grazing in range");
        let found: Vec<f64> = bifurcations
            .iter()
            .filter(|r| r["kind"] == "grazing" && value(r, "f") == f)
            .map(|r| value(r, "eta"))
            .collect();
        for eta in exact {
            let nearest = found
                .iter()
                .map(|g| (g - eta).abs())
                .fold(f64::INFINITY, f64::min);
            eprintln!("f = {f}: grazing at η = {eta}, located {nearest:.1e} off");
            assert!(
                nearest < 1e-8,
                "f = {f}: {eta} is {nearest:e} off ({found:?})"
            );
        }
    }
    // Each branch at one f, in one run of rows, the rows in f's order; a
    // switched branch names a branch of its own f.
    let orbits = read(&out.join("orbits.csv"));
    let mut last = (f64::NEG_INFINITY, -1i64);
    let f_of = |b: &str| value(rows_of(&orbits, b)[0], "f");
    for row in &orbits {
        let (f, b): (f64, i64) = (value(row, "f"), row["branch"].parse().unwrap());
        assert!(forcings.contains(&f), "{row:?}");
        assert!(
            f >= last.0 && (b == last.1 || b == last.1 + 1),
            "{row:?} after {last:?}"
        );
        assert!(b != last.1 || f == last.0, "branch {b} at two f");
        last = (f, b);
        if let Some(from) = row["branch_end"]
            .split("from-branch=")
            .nth(1)
            .map(|s| s.trim_end_matches(')'))
        {
            assert_eq!(f_of(from), f, "{row:?}");
        }
    }
    assert!(forcings
        .iter()
        .all(|f| orbits.iter().any(|r| value(r, "f") == *f)));

    // One thread gives the same files to the byte.
    let single = dir.path().join("single");
    let output = two_parameter_run(&single, "0.6, 0.8, 1.0", "1");
    assert_eq!(output.status.code(), Some(0), "{}", stderr(&output));
    for name in ["orbits.csv", "bifurcations.csv"] {
        let (a, b) = (out.join(name), single.join(name));
        assert!(
            std::fs::read(&a).unwrap() == std::fs::read(&b).unwrap(),
            "{name} differs between 2 threads and 1"
        );
    }
}

/// The two-parameter run's row at f = 1 is the one-parameter run's (the
/// seed's own f): the same bifurcations, folds and period doublings
/// included, at the same η to the bit.
#[test]
fn a_two_parameter_row_locates_the_one_parameter_run_s_folds_and_doublings() {
    let dir = tempfile::tempdir().unwrap();
    let two = dir.path().join("two");
    let output = two_parameter_run(&two, "0.8, 1.0", "2");
    assert_eq!(output.status.code(), Some(0), "{}", stderr(&output));
    let one = dir.path().join("one");
    let output = lyapsweep(&[
        "run",
        seed_path().to_str().unwrap(),
        "--out",
        one.to_str().unwrap(),
        "--set",
        "sweep.count=21",
        "--set",
        "orbits={}",
        "--set",
        "run.backend=\"cpu\"",
    ]);
    assert_eq!(output.status.code(), Some(0), "{}", stderr(&output));
    let key = |r: &BTreeMap<String, String>| {
        let cells = ["kind", "eta", "x", "v", "period"].map(|c| r[c].clone());
        cells.join(",")
    };
    let expected: Vec<String> = read(&one.join("bifurcations.csv"))
        .iter()
        .map(key)
        .collect();
    let row: Vec<String> = read(&two.join("bifurcations.csv"))
        .iter()
        .filter(|r| r["f"] == "1")
        .map(key)
        .collect();
    let folds_and_doublings = expected
        .iter()
        .filter(|k| k.starts_with("fold,") || k.starts_with("period-doubling,"))
        .count();
    eprintln!("{folds_and_doublings} folds and period doublings at f = 1: {expected:#?}");
    assert!(folds_and_doublings >= 2, "{expected:?}");
    assert_eq!(row, expected);
}
