//! The error-against-time study (`lyapsweep bench`): a grid of
//! configurations (backend and precision, RK4 steps, impact location, δ,
//! difference scheme) on fixed parameter values of the seed's oscillator,
//! or on a scene whose system has an exact backend (`lyapsweep bench
//! SCENE`: a piecewise-linear model), each timed and compared with the
//! exact backend.
//!
//! Error of a configuration: the largest of (a) |λ_i - λ_i,exact| at the
//! periodic points, the exact backend run with the same transient,
//! iterations and start, (b) |λ_sum - expected_sum| at the chaotic point, at
//! a near-grazing point and over a sweep. On a scene, the periodic points
//! are its values where the exact backend finds λ1 < 0, and the sum rule is
//! checked at all of them (the seed's chaotic and near-grazing points have
//! no counterpart). Time: the median wall time of several runs after a
//! warm-up, and on a GPU with timestamp queries the median device time of
//! its compute passes.

use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::backend::RunOptions;
use crate::driver;
use crate::error::{Error, Result};
use crate::integrate::ImpactLocation;
use crate::method::jacobian::Difference;
use crate::scene::{self, Backend, Precision, Scene};

/// Periodic points of the seed's oscillator (compared per exponent with exact).
pub const PERIODIC: [f64; 5] = [0.8, 0.95, 1.1, 1.25, 1.5];
/// A chaotic point in the window where impacts begin (compared by its sum).
pub const CHAOTIC: f64 = 0.715;
/// Value 867 of the seed's 4096-value sweep: one iteration meets the wall at
/// speed 1e-3, the hardest case for a finite difference (compared by its sum).
pub const GRAZING: f64 = 0.7117216117216117;

/// One configuration of the grid.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Config {
    pub backend: Backend,
    pub precision: Precision,
    pub steps: usize,
    pub location: ImpactLocation,
    pub perturbation: f64,
    pub difference: Difference,
}

impl Config {
    fn cpu(
        steps: usize,
        location: ImpactLocation,
        perturbation: f64,
        difference: Difference,
    ) -> Self {
        Config {
            backend: Backend::Cpu,
            precision: Precision::F64,
            steps,
            location,
            perturbation,
            difference,
        }
    }

    /// `cpu-f64`, `gpu-f32`, `exact`.
    pub fn path(&self) -> String {
        match self.backend {
            Backend::Exact => "exact".into(),
            b => format!("{}-{}", b.name(), self.precision.name()),
        }
    }

    fn overrides(&self) -> Vec<String> {
        vec![
            format!("run.backend=\"{}\"", self.backend.name()),
            format!("run.precision=\"{}\"", self.precision.name()),
            format!("integration.steps_per_period={}", self.steps),
            format!("integration.impact_location=\"{}\"", self.location.name()),
            format!("integration.perturbation={:e}", self.perturbation),
            format!("integration.difference=\"{}\"", self.difference.name()),
            "run.validate=0".into(),
        ]
    }
}

/// What a study runs on.
#[derive(Clone, Debug, PartialEq)]
pub enum Subject {
    /// The seed's oscillator at [`PERIODIC`], [`CHAOTIC`], [`GRAZING`] and
    /// the plan's sweep.
    Seed,
    /// A scene file, as it is (its values, transient and iterations).
    Scene(PathBuf),
}

/// The fixed part of a study: where and how long.
#[derive(Clone, Debug)]
pub struct Plan {
    pub subject: Subject,
    pub transient: usize,
    pub iterations: usize,
    /// The sum-rule sweep over [0.5, 1.5].
    pub sweep: Vec<f64>,
    pub repeats: usize,
    pub configs: Vec<Config>,
}

impl Plan {
    /// The full study, or a CI-sized one with `quick`; GPU configurations
    /// only for the precisions an adapter offers.
    pub fn new(quick: bool, gpu_f64: bool, gpu_f32: bool) -> Self {
        use Difference::{Central, Forward};
        use ImpactLocation::{Linear, Newton};
        let mut configs = Vec::new();
        let (steps, deltas): (&[usize], &[f64]) = if quick {
            (&[100, 400], &[1e-4, 1e-8])
        } else {
            (
                &[100, 200, 450, 900, 1800, 3600],
                &[1e-2, 1e-4, 1e-6, 1e-8, 1e-10, 1e-12],
            )
        };
        let reference_steps = if quick { 400 } else { 1800 };
        // Steps against impact location with the paper's forward differences
        // at δ = 1e-8; then, with the default location, central differences
        // at two δ (the candidates for the defaults).
        for &s in steps {
            for location in [Linear, Newton] {
                configs.push(Config::cpu(s, location, 1e-8, Forward));
            }
            let central: &[f64] = if quick { &[1e-6] } else { &[1e-6, 1e-8] };
            for &d in central {
                configs.push(Config::cpu(s, Newton, d, Central));
            }
        }
        // δ against the difference scheme at the reference step count.
        for &d in deltas {
            for difference in [Forward, Central] {
                let c = Config::cpu(reference_steps, Newton, d, difference);
                if !configs.contains(&c) {
                    configs.push(c);
                }
            }
        }
        let gpu = |precision, steps, perturbation, difference| Config {
            backend: Backend::Gpu,
            precision,
            steps,
            location: Newton,
            perturbation,
            difference,
        };
        let gpu_steps: &[usize] = if quick { &[400] } else { &[450, 1800] };
        for &s in gpu_steps {
            if gpu_f64 {
                configs.push(gpu(
                    Precision::F64,
                    s,
                    scene::DEFAULT_PERTURBATION_F64,
                    Forward,
                ));
            }
            if gpu_f32 {
                for d in [1e-3, scene::DEFAULT_PERTURBATION_F32] {
                    configs.push(gpu(Precision::F32, s, d, Central));
                }
                configs.push(gpu(Precision::F32, s, 1e-3, Forward));
            }
        }
        configs.push(Config {
            backend: Backend::Exact,
            ..Config::cpu(
                reference_steps,
                Newton,
                scene::DEFAULT_PERTURBATION_F64,
                Forward,
            )
        });
        let (transient, iterations, count, repeats) = if quick {
            (50, 100, 3, 1)
        } else {
            (500, 1000, 11, 3)
        };
        let sweep = (0..count)
            .map(|k| 0.5 + k as f64 / (count - 1) as f64)
            .collect();
        Plan {
            subject: Subject::Seed,
            transient,
            iterations,
            sweep,
            repeats,
            configs,
        }
    }

    /// The study of [`new`](Self::new) on a scene instead of the seed's
    /// oscillator: its system must have the exact backend (the ground
    /// truth), and GPU configurations stay only where its kernels run it.
    pub fn on_scene(quick: bool, gpu_f64: bool, gpu_f32: bool, path: &Path) -> Result<Self> {
        let scene = scene::load(path, &[])?;
        if !scene.system.has_exact {
            return Err(Error::invalid(
                "bench",
                format!(
                    "{}: {} has no exact backend to measure errors against \
                     (piecewise-linear models and the impact oscillator have one)",
                    path.display(),
                    scene.system.kind
                ),
            ));
        }
        let kernels = scene.system.wgsl.is_some();
        let mut plan = Plan::new(quick, gpu_f64 && kernels, gpu_f32 && kernels);
        plan.subject = Subject::Scene(path.to_owned());
        plan.transient = scene.integration.transient;
        plan.iterations = scene.integration.iterations;
        plan.sweep = Vec::new();
        Ok(plan)
    }

    /// The η values of one run: periodic points, the chaotic and the
    /// grazing point, the sweep.
    fn values(&self) -> Vec<f64> {
        let mut v = PERIODIC.to_vec();
        v.extend([CHAOTIC, GRAZING]);
        v.extend(&self.sweep);
        v
    }

    fn scene(&self, overrides: &[String]) -> Result<Scene> {
        if let Subject::Scene(path) = &self.subject {
            // Figures and progress are not what is timed.
            let mut all = vec!["output.plot=false".to_owned()];
            all.extend_from_slice(overrides);
            return scene::load(path, &all);
        }
        let values: Vec<String> = self.values().iter().map(|v| format!("{v}")).collect();
        let text = format!(
            "[system]\nkind = \"impact-oscillator\"\n[sweep]\nvalues = [{}]\n[integration]\ntransient = {}\niterations = {}\ninitial_state = [0.0, 0.0]\n",
            values.join(", "),
            self.transient,
            self.iterations
        );
        scene::parse(&text, "bench", "bench", overrides)
    }
}

/// What one configuration measured.
#[derive(Clone, Debug)]
pub struct Measurement {
    pub config: Config,
    /// Largest |λ_i - λ_i,exact| over the periodic points.
    pub periodic_error: f64,
    /// |λ_sum - expected_sum| at the chaotic point (NaN on a scene).
    pub chaotic_sum_error: f64,
    /// |λ_sum - expected_sum| at the near-grazing point (NaN on a scene).
    pub grazing_sum_error: f64,
    /// Largest |λ_sum - expected_sum| over the sweep.
    pub sweep_sum_error: f64,
    /// Median wall time of the repeats, seconds.
    pub seconds: f64,
    /// Median device time of the GPU's compute passes (timestamp queries),
    /// seconds; `None` off the GPU or without timestamp queries.
    pub device_seconds: Option<f64>,
    /// Lane-steps per repeat (RK4 steps of all trajectories).
    pub lane_steps: f64,
    /// On the Pareto front of (seconds, error).
    pub pareto: bool,
}

impl Measurement {
    /// The headline error: the largest of the four (of the two on a
    /// scene: `max` passes over NaN).
    pub fn error(&self) -> f64 {
        self.periodic_error
            .max(self.chaotic_sum_error)
            .max(self.grazing_sum_error)
            .max(self.sweep_sum_error)
    }
}

/// Runs the study, reporting progress on stderr.
pub fn run(plan: &Plan) -> Result<Vec<Measurement>> {
    let exact_scene = plan.scene(&["run.backend=\"exact\"".into()])?;
    let exact = driver::run(&exact_scene)?;
    // Lanes compared per exponent with exact, and lanes whose sum rule counts.
    let (periodic, sums): (Vec<usize>, Vec<usize>) = match plan.subject {
        Subject::Seed => (
            (0..PERIODIC.len()).collect(),
            (PERIODIC.len() + 2..exact.lanes.len()).collect(),
        ),
        Subject::Scene(_) => (
            (0..exact.lanes.len())
                .filter(|&k| exact.lanes[k].exponents.first().is_some_and(|&l| l < 0.0))
                .collect(),
            (0..exact.lanes.len()).collect(),
        ),
    };
    let seed = plan.subject == Subject::Seed;
    let mut out = Vec::new();
    for (k, config) in plan.configs.iter().enumerate() {
        let scene = plan.scene(&config.overrides())?;
        eprintln!(
            "bench {}/{}: {}",
            k + 1,
            plan.configs.len(),
            describe(config)
        );
        // The warm-up: shader compilation, thread pool, caches.
        let mut report = driver::run_with(&scene, &RunOptions::default())?;
        let (mut times, mut device) = (Vec::new(), Vec::new());
        for _ in 0..plan.repeats {
            let start = Instant::now();
            report = driver::run_with(&scene, &RunOptions::default())?;
            times.push(start.elapsed().as_secs_f64());
            device.extend(
                report
                    .gpu
                    .as_ref()
                    .and_then(|g| g.timings.gpu_busy)
                    .map(|d| d.as_secs_f64()),
            );
        }
        times.sort_by(f64::total_cmp);
        device.sort_by(f64::total_cmp);
        let sum_error = |k: usize| (report.lanes[k].exponent_sum() - report.expected_sums[k]).abs();
        let periodic_error = periodic
            .iter()
            .flat_map(|&k| {
                report.lanes[k]
                    .exponents
                    .iter()
                    .zip(&exact.lanes[k].exponents)
                    .map(|(a, b)| (a - b).abs())
            })
            .fold(0.0, f64::max);
        let trajectories = match config.backend {
            Backend::Exact => 1,
            _ => 1 + config.difference.copies(2),
        };
        // The transient's aligning iterations carry the copies too.
        let i = &scene.integration;
        let lane_steps = (report.lanes.len()
            * config.steps
            * (i.transient - i.align + (i.align + i.iterations) * trajectories))
            as f64;
        out.push(Measurement {
            config: *config,
            periodic_error,
            chaotic_sum_error: if seed {
                sum_error(PERIODIC.len())
            } else {
                f64::NAN
            },
            grazing_sum_error: if seed {
                sum_error(PERIODIC.len() + 1)
            } else {
                f64::NAN
            },
            sweep_sum_error: sums.iter().map(|&k| sum_error(k)).fold(0.0, f64::max),
            seconds: times[times.len() / 2],
            device_seconds: device.get(device.len() / 2).copied(),
            lane_steps,
            pareto: false,
        });
    }
    mark_pareto(&mut out);
    Ok(out)
}

fn describe(c: &Config) -> String {
    if c.backend == Backend::Exact {
        return "exact".into();
    }
    format!(
        "{} steps={} {} δ={:e} {}",
        c.path(),
        c.steps,
        c.location.name(),
        c.perturbation,
        c.difference.name()
    )
}

/// Marks the measurements no other one beats in both time and error. The
/// exact backend (error 0 by definition) does not compete.
fn mark_pareto(ms: &mut [Measurement]) {
    let points: Vec<Option<(f64, f64)>> = ms
        .iter()
        .map(|m| (m.config.backend != Backend::Exact).then(|| (m.seconds, m.error())))
        .collect();
    for (m, &point) in ms.iter_mut().zip(&points) {
        m.pareto = point.is_some_and(|(t, e)| {
            !points
                .iter()
                .flatten()
                .any(|&(t2, e2)| t2 <= t && e2 <= e && (t2 < t || e2 < e))
        });
    }
}

/// The fastest configuration whose error is at most `target`.
pub fn best_for(ms: &[Measurement], target: f64) -> Option<&Measurement> {
    ms.iter()
        .filter(|m| m.config.backend != Backend::Exact && m.error() <= target)
        .min_by(|a, b| a.seconds.total_cmp(&b.seconds))
}

/// The files [`write`] writes into its folder.
pub const FILES: [&str; 3] = ["bench.csv", "bench.md", "bench.png"];

/// That `dir` can take the files (see `output::owned`): checked before
/// the measurements, which take minutes.
pub fn check_folder(dir: &Path) -> Result<()> {
    crate::output::owned::check(dir, &FILES)
}

/// Writes bench.csv, bench.md and bench.png into `dir` (refusing to
/// write over files lyapsweep did not write there).
pub fn write(dir: &Path, plan: &Plan, ms: &[Measurement], machine: &str) -> Result<Vec<PathBuf>> {
    check_folder(dir)?;
    let fail = |path: &Path, e: std::io::Error| Error::Write {
        path: path.to_owned(),
        source: e,
    };
    std::fs::create_dir_all(dir).map_err(|e| fail(dir, e))?;
    let csv_path = dir.join(FILES[0]);
    crate::output::files::write_atomically(&csv_path, |w| {
        w.write_record([
            "path",
            "steps_per_period",
            "impact_location",
            "perturbation",
            "difference",
            "periodic_error",
            "chaotic_sum_error",
            "grazing_sum_error",
            "sweep_sum_error",
            "error",
            "seconds",
            "device_seconds",
            "lane_steps",
            "pareto",
        ])?;
        for m in ms {
            let c = &m.config;
            w.write_record([
                c.path(),
                c.steps.to_string(),
                c.location.name().to_owned(),
                format!("{:e}", c.perturbation),
                c.difference.name().to_owned(),
                format!("{:e}", m.periodic_error),
                format!("{:e}", m.chaotic_sum_error),
                format!("{:e}", m.grazing_sum_error),
                format!("{:e}", m.sweep_sum_error),
                format!("{:e}", m.error()),
                m.seconds.to_string(),
                m.device_seconds.map_or(String::new(), |d| d.to_string()),
                m.lane_steps.to_string(),
                m.pareto.to_string(),
            ])?;
        }
        Ok(())
    })?;

    let md_path = dir.join(FILES[1]);
    std::fs::write(&md_path, markdown(plan, ms, machine)).map_err(|e| fail(&md_path, e))?;
    let png_path = dir.join(FILES[2]);
    let caption = match &plan.subject {
        Subject::Seed => "seed oscillator".to_owned(),
        Subject::Scene(path) => path.display().to_string(),
    };
    plot(&png_path, ms, &caption).map_err(|e| fail(&png_path, std::io::Error::other(e)))?;
    let written = vec![csv_path, md_path, png_path];
    crate::output::owned::record(dir, &written)?;
    Ok(written)
}

/// The Markdown report: every configuration, then the best per error target.
pub fn markdown(plan: &Plan, ms: &[Measurement], machine: &str) -> String {
    let subject = match &plan.subject {
        Subject::Seed => format!(
            "Seed oscillator (ζ = 0.05, f = 1, X_w = 2, e = 1, start (0, 0)), transient {}, iterations {}; \
             periodic points η = {:?}, chaotic η = {CHAOTIC}, near-grazing η = {GRAZING}, sum-rule sweep of {} values over [0.5, 1.5].",
            plan.transient,
            plan.iterations,
            PERIODIC,
            plan.sweep.len(),
        ),
        Subject::Scene(path) => format!(
            "Scene {} as written (transient {}, iterations {}): per exponent against the exact backend at its values \
             where exact finds λ1 < 0 (periodic), the sum rule at all of them; the chaotic and grazing columns are the seed's only.",
            path.display(),
            plan.transient,
            plan.iterations,
        ),
    };
    let mut s = format!(
        "{subject} Time: median of {} runs after a warm-up (device: the GPU's compute passes by timestamp queries). Machine: {machine}.\n\n",
        plan.repeats
    );
    s += "| path | steps | impacts | δ | difference | periodic \\|Δλ\\| | chaotic \\|Δsum\\| | grazing \\|Δsum\\| | sweep \\|Δsum\\| | time s | device s | Pareto |\n";
    s += "|---|---|---|---|---|---|---|---|---|---|---|---|\n";
    for m in ms {
        let c = &m.config;
        s += &format!(
            "| {} | {} | {} | {:.0e} | {} | {} | {} | {} | {} | {:.3} | {} | {} |\n",
            c.path(),
            c.steps,
            c.location.name(),
            c.perturbation,
            c.difference.name(),
            cell(m.periodic_error),
            cell(m.chaotic_sum_error),
            cell(m.grazing_sum_error),
            cell(m.sweep_sum_error),
            m.seconds,
            m.device_seconds.map_or("–".into(), |d| format!("{d:.3}")),
            if m.pareto { "★" } else { "" }
        );
    }
    s += "\nFastest configuration per error target (error = the largest of the four error columns):\n\n";
    s += "| target | configuration | error | time s |\n|---|---|---|---|\n";
    for target in [1e-3, 1e-5, 1e-7] {
        match best_for(ms, target) {
            Some(m) => {
                s += &format!(
                    "| {target:.0e} | {} | {:.1e} | {:.3} |\n",
                    describe(&m.config),
                    m.error(),
                    m.seconds
                )
            }
            None => s += &format!("| {target:.0e} | none reached it | | |\n"),
        }
    }
    s
}

/// An error in the report's table; "–" where it has no meaning.
fn cell(error: f64) -> String {
    if error.is_nan() {
        "–".into()
    } else {
        format!("{error:.1e}")
    }
}

fn plot(path: &Path, ms: &[Measurement], subject: &str) -> std::result::Result<(), String> {
    use plotters::prelude::*;
    crate::output::plot::figure::register_font();
    let points: Vec<&Measurement> = ms
        .iter()
        .filter(|m| m.config.backend != Backend::Exact)
        .collect();
    let smallest = ms
        .iter()
        .filter(|m| m.config.backend != Backend::Exact && m.error() > 0.0)
        .fold(f64::INFINITY, |a, m| a.min(m.error()));
    let floor: f64 = if smallest.is_finite() {
        smallest / 3.0
    } else {
        1e-12
    };
    let (t_min, t_max) = points.iter().fold((f64::INFINITY, 0.0_f64), |(a, b), m| {
        (a.min(m.seconds), b.max(m.seconds))
    });
    let e_max = points.iter().fold(floor, |a, m| a.max(m.error()));
    const SIZE: (u32, u32) = (1000, 700);
    let mut pixels = vec![0; SIZE.0 as usize * SIZE.1 as usize * 3];
    let root = BitMapBackend::with_buffer(&mut pixels, SIZE).into_drawing_area();
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!("Error against run time ({subject})"),
            ("sans-serif", 26),
        )
        .margin(20)
        .x_label_area_size(50)
        .y_label_area_size(80)
        .build_cartesian_2d(
            (t_min * 0.7..t_max * 1.4).log_scale(),
            (floor..e_max * 3.0).log_scale(),
        )
        .map_err(|e| e.to_string())?;
    chart
        .configure_mesh()
        .x_desc("median wall time per run [s]")
        .y_desc("error (largest |Δλ| or |Δsum|)")
        .x_labels(6)
        .x_label_formatter(&|t| format!("{t:.2}"))
        .y_label_formatter(&|e| format!("{e:.0e}"))
        .label_style(("sans-serif", 16))
        .draw()
        .map_err(|e| e.to_string())?;
    let series = [
        ("cpu-f64 linear", RGBColor(200, 80, 40)),
        ("cpu-f64 newton", RGBColor(40, 90, 200)),
        ("gpu-f64", RGBColor(30, 150, 60)),
        ("gpu-f32", RGBColor(150, 60, 170)),
    ];
    for (name, color) in series {
        let selected: Vec<(f64, f64)> = points
            .iter()
            .filter(|m| {
                let label = match (m.config.backend, m.config.location) {
                    (Backend::Cpu, ImpactLocation::Linear) => "cpu-f64 linear".to_owned(),
                    (Backend::Cpu, _) => "cpu-f64 newton".to_owned(),
                    _ => m.config.path(),
                };
                label == name
            })
            .map(|m| (m.seconds, m.error().max(floor)))
            .collect();
        if selected.is_empty() {
            continue;
        }
        chart
            .draw_series(selected.iter().map(|&p| Circle::new(p, 5, color.filled())))
            .map_err(|e| e.to_string())?
            .label(name)
            .legend(move |(x, y)| Circle::new((x + 10, y), 5, color.filled()));
    }
    let mut front: Vec<(f64, f64)> = points
        .iter()
        .filter(|m| m.pareto)
        .map(|m| (m.seconds, m.error().max(floor)))
        .collect();
    front.sort_by(|a, b| a.0.total_cmp(&b.0));
    chart
        .draw_series(LineSeries::new(front, BLACK.stroke_width(2)))
        .map_err(|e| e.to_string())?
        .label("Pareto front")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.stroke_width(2)));
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerRight)
        .background_style(WHITE.mix(0.9))
        .border_style(BLACK)
        .label_font(("sans-serif", 16))
        .draw()
        .map_err(|e| e.to_string())?;
    root.present().map_err(|e| e.to_string())?;
    drop(chart);
    drop(root);
    crate::output::plot::write_png(path, &pixels, SIZE).map_err(|e| e.to_string())
}
