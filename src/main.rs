//! The `lyapsweep` command: parse arguments, run the library, print a summary.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicI32, Ordering};
use std::sync::Arc;

use clap::{Parser, Subcommand};
use lyapsweep::command::summary::RunSummary;
use lyapsweep::command::{self, progress_bar};
use lyapsweep::scene::{self, Backend};
use lyapsweep::{output, Error};

#[derive(Parser)]
#[command(
    name = "lyapsweep",
    version,
    about = "Lyapunov spectra and bifurcation diagrams of non-smooth oscillators over parameter sweeps"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run a scene: writes spectrum.csv (grid.csv for two parameters), bifurcation.csv when asked, the scene as run and the figures into the output folder.
    Run {
        /// The scene file (TOML).
        scene: PathBuf,
        /// Output folder [default: out/<scene name>, or out/<scene name>.shard-I-of-N].
        #[arg(long)]
        out: Option<PathBuf>,
        /// Overrides [run] backend.
        #[arg(long, value_parser = ["auto", "cpu", "gpu", "exact"])]
        backend: Option<String>,
        /// Overrides [run] precision.
        #[arg(long, value_parser = ["f64", "f32"])]
        precision: Option<String>,
        /// Overrides any scene key, e.g. --set integration.iterations=2000 (repeatable).
        #[arg(long = "set", value_name = "KEY.PATH=VALUE")]
        sets: Vec<String>,
        /// Run shard i of n (from 0): sweep values i, i + n, i + 2n, ...; `merge` combines the shards.
        // Hyphens too: `--shard -1/3` is then told what a shard is.
        #[arg(long, value_name = "I/N", allow_hyphen_values = true)]
        shard: Option<String>,
        /// No progress on stderr.
        #[arg(long, short)]
        quiet: bool,
        /// Run on adapter N of `lyapsweep devices` (e.g. one process per GPU, each with a shard); the GPU backend only.
        #[arg(long, value_name = "N")]
        device: Option<usize>,
    },
    /// Redraw the figures of an output folder from its CSV files.
    Plot {
        /// The output folder of a run (or of a merge).
        dir: PathBuf,
        /// Where the figures go [default: DIR].
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Combine the output folders of a sharded sweep into the files one run writes.
    Merge {
        /// Where the merged files go.
        #[arg(long)]
        out: PathBuf,
        /// The shards' output folders (all n of them, any order).
        #[arg(required = true)]
        shards: Vec<PathBuf>,
    },
    /// List the GPU adapters wgpu finds (honours WGPU_BACKEND and WGPU_ADAPTER_NAME for runs).
    Devices,
    /// Tools for writing models.
    Model {
        #[command(subcommand)]
        command: ModelCommand,
    },
    /// Error against run time over a grid of configurations (writes bench.csv, bench.md, bench.png).
    Bench {
        /// A scene whose system has the exact backend (a piecewise-linear model), run as written; default: the seed's oscillator at fixed values.
        scene: Option<PathBuf>,
        /// A CI-sized grid: fewer configurations, shorter runs.
        #[arg(long)]
        quick: bool,
        /// Output folder [default: out/bench, or out/bench-<scene name>].
        #[arg(long)]
        out: Option<PathBuf>,
    },
}

#[derive(Subcommand)]
enum ModelCommand {
    /// Parse and compile a model file (its [model] table, or the whole file) and print its equations, the derivatives the sum rule uses, its events, what each backend runs and the generated WGSL; problems are reported with their key and column (exit code 2).
    Check {
        /// The model file (TOML).
        file: PathBuf,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    // Every variable the README names, before any work.
    if let Err(e) = lyapsweep::environment::check() {
        return exit_code(Err(e));
    }
    match cli.command {
        Command::Devices => exit_code(print_devices()),
        Command::Model {
            command: ModelCommand::Check { file },
        } => exit_code(check_model(&file)),
        Command::Bench { scene, quick, out } => exit_code(bench(scene, quick, out)),
        Command::Run {
            scene,
            out,
            backend,
            precision,
            sets,
            shard,
            quiet,
            device,
        } => {
            let mut overrides = sets;
            // Flags are overrides of their scene keys, applied last.
            overrides.extend(backend.map(|b| format!("run.backend=\"{b}\"")));
            overrides.extend(precision.map(|p| format!("run.precision=\"{p}\"")));
            let (stop, caught) = stop_on_signals();
            let how = How {
                shard: shard.as_deref(),
                quiet,
                device,
                stop,
            };
            match run(&scene, out, &overrides, how) {
                Err(Error::Stopped) => stopped(caught.load(Ordering::SeqCst)),
                result => exit_code(result),
            }
        }
        Command::Plot { dir, out } => exit_code(plot(&dir, out.as_deref().unwrap_or(&dir))),
        Command::Merge { out, shards } => exit_code(merge(&out, &shards)),
    }
}

/// `lyapsweep model check FILE`, saying on stderr when FILE was a scene
/// whose model file was checked.
fn check_model(file: &std::path::Path) -> Result<(), Error> {
    let check = lyapsweep::command::check_model(file)?;
    if let Some(path) = &check.named {
        eprintln!(
            "lyapsweep: {} is a scene file: checked the model file it names, {}",
            file.display(),
            path.display()
        );
    }
    emit(&check.description, "the model was checked")
}

/// Success, or the error on stderr with exit code 2 for bad input, 1 otherwise.
fn exit_code(result: Result<(), Error>) -> ExitCode {
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(if e.is_input_error() { 2 } else { 1 })
        }
    }
}

/// How `run` runs a scene, besides the scene's own keys.
struct How<'a> {
    shard: Option<&'a str>,
    quiet: bool,
    device: Option<usize>,
    stop: lyapsweep::method::Stop,
}

/// SIGINT (Ctrl-C) and SIGTERM stop a run: the first asks the library to
/// stop (every lane loop and GPU dispatch loop looks at the flag, and the
/// stopped run removes its staged set, so the output folder keeps what it
/// held); a second exits at once, leaving the staging folder for the next
/// run into that folder to remove. Returns the flag and the signal caught
/// (0 until one is).
fn stop_on_signals() -> (lyapsweep::method::Stop, Arc<AtomicI32>) {
    use signal_hook::consts::{SIGINT, SIGTERM};
    let stop = lyapsweep::method::Stop::default();
    let caught = Arc::new(AtomicI32::new(0));
    match signal_hook::iterator::Signals::new([SIGINT, SIGTERM]) {
        Ok(mut signals) => {
            let (stop, caught) = (stop.clone(), caught.clone());
            std::thread::spawn(move || {
                for signal in signals.forever() {
                    if caught.swap(signal, Ordering::SeqCst) != 0 {
                        std::process::exit(128 + signal);
                    }
                    stop.request();
                }
            });
        }
        Err(e) => eprintln!(
            "lyapsweep: no handler for SIGINT and SIGTERM ({e}): they end a run without removing its staging folder"
        ),
    }
    (stop, caught)
}

/// The exit code of a run stopped by `signal`: 128 + its number (130 for
/// SIGINT, 143 for SIGTERM), as a shell reports a process it ended.
fn stopped(signal: i32) -> ExitCode {
    let name = match signal {
        signal_hook::consts::SIGINT => "SIGINT",
        signal_hook::consts::SIGTERM => "SIGTERM",
        _ => "a signal",
    };
    eprintln!("lyapsweep: stopped by {name}; the output folder keeps what it held");
    ExitCode::from(u8::try_from(128 + signal).unwrap_or(1))
}

fn run(
    path: &std::path::Path,
    out: Option<PathBuf>,
    overrides: &[String],
    how: How,
) -> Result<(), Error> {
    let shard = how.shard.map(scene::Shard::parse).transpose()?;
    let scene = scene::load_shard(path, overrides, shard)?;
    if let Some(n) = how.device {
        if matches!(scene.backend, Backend::Cpu | Backend::Exact) {
            return Err(Error::invalid(
                "--device",
                format!(
                    "--device {n} picks a GPU adapter, and run.backend is \"{}\": give --backend gpu (or auto), or leave --device out",
                    scene.backend.name()
                ),
            ));
        }
    }
    let dir = out.unwrap_or_else(|| match scene.shard {
        Some(s) => {
            PathBuf::from("out").join(format!("{}.shard-{}-of-{}", scene.name, s.index, s.count))
        }
        None => PathBuf::from("out").join(&scene.name),
    });
    let prepared = command::prepare(&scene, &dir)?;
    if let Some(warning) = scene
        .system
        .model
        .filter(|_| matches!(scene.backend, Backend::Cpu | Backend::Auto))
        .and_then(|m| m.interpreter_fallback())
    {
        eprintln!("lyapsweep: warning: {warning}");
    }
    if let Some(line) = prepared.large().filter(|_| !how.quiet) {
        eprintln!("lyapsweep: {line}");
    }
    let progress = lyapsweep::Progress::default();
    let watcher = (!how.quiet).then(|| progress_bar::watch(&progress));
    let options = lyapsweep::RunOptions {
        progress: Some(progress.clone()),
        device: how.device,
        stop: how.stop,
        ..Default::default()
    };
    let outcome = prepared.run(&options);
    if let Some(w) = watcher {
        w.finish();
    }
    let outcome = outcome?;
    emit(
        &RunSummary::of(&scene, &outcome).to_string(),
        &format!("the output set {} was written whole", dir.display()),
    )?;
    outcome.result()
}

/// Appends a line to a command's text for stdout (see [`emit`]).
macro_rules! say {
    ($out:expr, $($arg:tt)*) => {{
        use std::fmt::Write as _;
        // Writing to a String cannot fail.
        let _ = writeln!($out, $($arg)*);
    }};
}

/// Writes a command's text to stdout once its work is done. A closed pipe
/// (`lyapsweep devices | head -c0`) ends the printing quietly, as Unix
/// tools end when their reader has gone; any other failure (`> /dev/full`,
/// a full disk) is an error, exit code 1, saying what was `done` before it.
fn emit(text: &str, done: &str) -> Result<(), Error> {
    use std::io::Write;
    let mut stdout = std::io::stdout().lock();
    match stdout
        .write_all(text.as_bytes())
        .and_then(|()| stdout.flush())
    {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => Err(Error::Write {
            path: PathBuf::from("standard output"),
            source: std::io::Error::new(e.kind(), format!("{e}; {done}")),
        }),
        _ => Ok(()),
    }
}

/// "wrote PATH" lines for the files a command wrote, on stdout.
fn emit_written(paths: &[PathBuf]) -> Result<(), Error> {
    let mut text = String::new();
    for path in paths {
        say!(text, "wrote {}", path.display());
    }
    emit(&text, "the files were written whole")
}

fn plot(dir: &std::path::Path, into: &std::path::Path) -> Result<(), Error> {
    emit_written(&output::results::redraw(dir, into)?)
}

fn merge(out: &std::path::Path, shards: &[PathBuf]) -> Result<(), Error> {
    emit_written(&output::merge::merge(out, shards)?)
}

fn print_devices() -> Result<(), Error> {
    let adapters = command::devices()?;
    let out = &mut String::new();
    if adapters.is_empty() {
        say!(out, "no GPU adapters found (a Vulkan driver such as mesa-vulkan-drivers provides a software one)");
    }
    for (n, a) in adapters.iter().enumerate() {
        say!(out,
            "{n}: {} [{}] {}: f64 {}, timestamps {}, kernels without contraction {}, max storage binding {} MiB, max buffer {} MiB, max workgroups/dim {}",
            a.name,
            a.backend,
            a.device_type,
            if a.f64 { "yes" } else { "no" },
            if a.timestamps { "yes" } else { "no" },
            if a.exact_rounding { "yes" } else { "no" },
            a.max_storage_binding >> 20,
            a.max_buffer >> 20,
            a.max_workgroups
        );
    }
    emit(out, "nothing else was done")
}

fn bench(scene: Option<PathBuf>, quick: bool, out: Option<PathBuf>) -> Result<(), Error> {
    use lyapsweep::bench;
    let adapters = lyapsweep::backend::gpu::context::list();
    let gpu_f64 = adapters.iter().any(|a| a.f64);
    let (plan, default_out) = match &scene {
        None => (
            bench::Plan::new(quick, gpu_f64, !adapters.is_empty()),
            PathBuf::from("out/bench"),
        ),
        Some(path) => {
            let name = lyapsweep::scene::load(path, &[])?.name;
            (
                bench::Plan::on_scene(quick, gpu_f64, !adapters.is_empty(), path)?,
                PathBuf::from(format!("out/bench-{name}")),
            )
        }
    };
    let out = out.unwrap_or(default_out);
    bench::check_folder(&out)?;
    let measurements = bench::run(&plan)?;
    let mut machine = format!(
        "{} cores of {}",
        std::thread::available_parallelism().map_or(1, |n| n.get()),
        cpu_model()
    );
    if let Some(a) = adapters.iter().find(|a| a.f64).or(adapters.first()) {
        machine += &format!("; GPU adapter {} ({})", a.name, a.backend);
    }
    let written = bench::write(&out, &plan, &measurements, &machine)?;
    let mut text = bench::markdown(&plan, &measurements, &machine);
    for path in written {
        say!(text, "wrote {}", path.display());
    }
    emit(
        &text,
        &format!("the results were written to {}", out.display()),
    )
}

/// The CPU's model name, for naming the machine in reports.
fn cpu_model() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|info| {
            info.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|m| m.trim().to_owned())
        })
        .unwrap_or_else(|| std::env::consts::ARCH.to_owned())
}
