//! The environment variables lyapsweep reads (README.md's table), checked
//! together before any work: a value that is not one the variable takes is
//! refused naming the variable and why, where it was once ignored, taken
//! for another, or failed deep in a run.
//!
//! `CC`, `XDG_CACHE_HOME` and `WGPU_ADAPTER_NAME` take any text: where a
//! C compiler does not run or the cache cannot be written the interpreter
//! runs the model (the same bits, slower), and an adapter name that matches
//! nothing is an error, naming the adapters found, when a GPU is chosen.
//!
//! The GPU's variables (`WGPU_BACKEND`, `LYAPSWEEP_DISPATCH_LANE_STEPS`) are
//! parsed here, and the backend reads them through the same parsers
//! ([`wgpu_backends`], [`dispatch_lane_steps`]), so that the check and the
//! run read a value alike.

use crate::error::{clip, Error, Result};

/// Seconds between the `progress:` lines.
pub const PROGRESS_SECONDS: &str = "LYAPSWEEP_PROGRESS_SECONDS";
/// The longest interval between progress lines (about 30 years): past it a
/// run would print nothing, and far past it the interval is no duration.
pub const MOST_PROGRESS_SECONDS: f64 = 1e9;
/// What runs the models' equations (`interpreter`, or unset).
pub const STEP_LOOPS: &str = "LYAPSWEEP_STEP_LOOPS";
/// Step trajectories one at a time, without AVX2.
pub const NO_AVX2: &str = "LYAPSWEEP_NO_AVX2";
/// The threads of the CPU path (read by rayon itself).
pub const THREADS: &str = "RAYON_NUM_THREADS";
/// Threads per core `RAYON_NUM_THREADS` may ask for: past a few per core
/// more threads only add the cost of starting and switching them (100 000
/// of them made a 0.1 s run take minutes).
pub const MOST_THREADS_PER_CORE: usize = 8;

/// Every variable checked; the first bad one is the error.
pub fn check() -> Result<()> {
    progress_interval()?;
    step_loops_interpreter()?;
    without_avx2()?;
    threads()?;
    dispatch_lane_steps()?;
    wgpu_backends()?;
    text("WGPU_ADAPTER_NAME")?;
    if let Some(dir) = text("LYAPSWEEP_SHADER_DIR")? {
        if !std::path::Path::new(&dir).is_dir() {
            return Err(Error::invalid(
                "LYAPSWEEP_SHADER_DIR",
                format!("\"{}\" is not a folder (a copy of shaders/)", clip(&dir)),
            ));
        }
    }
    Ok(())
}

/// A variable's text, `None` when unset or empty (as a shell's `VAR=` is
/// read); text that is not UTF-8 is refused.
pub fn text(name: &str) -> Result<Option<String>> {
    match std::env::var(name) {
        Ok(text) if text.is_empty() => Ok(None),
        Ok(text) => Ok(Some(text)),
        Err(std::env::VarError::NotPresent) => Ok(None),
        Err(std::env::VarError::NotUnicode(_)) => Err(Error::invalid(name, "is not UTF-8 text")),
    }
}

/// The interval between `progress:` lines, when set: seconds from 0 to
/// [`MOST_PROGRESS_SECONDS`].
pub fn progress_interval() -> Result<Option<std::time::Duration>> {
    let Some(text) = text(PROGRESS_SECONDS)? else {
        return Ok(None);
    };
    match text.trim().parse::<f64>() {
        Ok(s) if (0.0..=MOST_PROGRESS_SECONDS).contains(&s) => {
            Ok(Some(std::time::Duration::from_secs_f64(s)))
        }
        _ => Err(Error::invalid(
            PROGRESS_SECONDS,
            format!(
                "\"{}\" is not a number of seconds from 0 to {MOST_PROGRESS_SECONDS:e}",
                clip(&text)
            ),
        )),
    }
}

/// Whether `LYAPSWEEP_STEP_LOOPS` asks for the interpreter (its one value).
pub fn step_loops_interpreter() -> Result<bool> {
    match text(STEP_LOOPS)? {
        None => Ok(false),
        Some(text) if text == "interpreter" => Ok(true),
        Some(text) => Err(Error::invalid(
            STEP_LOOPS,
            format!(
                "\"{}\" is not a choice: `interpreter` runs models on the tape's interpreter; unset, they run as native code",
                clip(&text)
            ),
        )),
    }
}

/// Whether `LYAPSWEEP_NO_AVX2` is set: `1` (or `true`, `yes`); a value
/// that reads as "no" would be taken for its opposite, and is refused.
pub fn without_avx2() -> Result<bool> {
    match text(NO_AVX2)? {
        None => Ok(false),
        Some(text) if ["1", "true", "yes"].contains(&text.to_lowercase().as_str()) => Ok(true),
        Some(text) => Err(Error::invalid(
            NO_AVX2,
            format!(
                "\"{}\" is not 1: set it to 1 to step without AVX2, or unset it",
                clip(&text)
            ),
        )),
    }
}

/// `RAYON_NUM_THREADS`: a whole number (0: one per core, as rayon reads
/// it), at most [`MOST_THREADS_PER_CORE`] per core.
fn threads() -> Result<()> {
    let Some(text) = text(THREADS)? else {
        return Ok(());
    };
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let most = MOST_THREADS_PER_CORE * cores;
    // As rayon reads it: untrimmed.
    match text.parse::<usize>() {
        Ok(n) if n <= most => Ok(()),
        Ok(n) => Err(Error::invalid(
            THREADS,
            format!(
                "{n} threads on {cores} cores: at most {most} ({MOST_THREADS_PER_CORE} per core); more only add the cost of starting and switching threads"
            ),
        )),
        Err(_) => Err(Error::invalid(
            THREADS,
            format!(
                "\"{}\" is not a whole number of threads (0: one per core)",
                clip(&text)
            ),
        )),
    }
}

/// RK4 lane-steps per GPU integrate dispatch at most
/// (`backend::RunOptions::dispatch_lane_steps`, which it sets when that is
/// unset).
pub const DISPATCH_LANE_STEPS: &str = "LYAPSWEEP_DISPATCH_LANE_STEPS";

/// [`DISPATCH_LANE_STEPS`], when set.
pub fn dispatch_lane_steps() -> Result<Option<usize>> {
    let text = std::env::var(DISPATCH_LANE_STEPS).unwrap_or_default();
    if text.trim().is_empty() {
        return Ok(None);
    }
    match text.trim().parse::<usize>() {
        Ok(n) if n >= 1 => Ok(Some(n)),
        _ => Err(Error::Invalid {
            key: DISPATCH_LANE_STEPS.into(),
            reason: format!(
                "\"{}\" is not a whole number of RK4 lane-steps of at least 1",
                clip(&text)
            ),
        }),
    }
}

/// The backends `WGPU_BACKEND` names (all when unset); a name wgpu does not
/// know is an error here (wgpu ignores it, finds no adapter, and the message
/// would blame the driver).
pub fn wgpu_backends() -> Result<wgpu::Backends> {
    const KNOWN: [&str; 10] = [
        "vulkan", "vk", "dx12", "d3d12", "metal", "mtl", "opengl", "gles", "gl", "webgpu",
    ];
    // Unset or empty: every backend, as wgpu reads it.
    let text = match std::env::var("WGPU_BACKEND") {
        Ok(text) if !text.trim().is_empty() => text,
        Err(std::env::VarError::NotUnicode(_)) => {
            return Err(Error::invalid("WGPU_BACKEND", "is not UTF-8 text"))
        }
        _ => return Ok(wgpu::Backends::all()),
    };
    if let Some(unknown) = text
        .split(',')
        .map(|b| b.trim().to_lowercase())
        .find(|b| !KNOWN.contains(&b.as_str()))
    {
        return Err(Error::invalid(
            "WGPU_BACKEND",
            format!("{unknown:?} is not a backend (vulkan, metal, dx12, gl or webgpu; several separated by commas)"),
        ));
    }
    Ok(wgpu::Backends::from_comma_list(&text))
}
