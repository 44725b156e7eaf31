//! The progress display on stderr, the command line's and the Python
//! package's: a bar with rate and time left when stderr is a terminal;
//! otherwise (CI logs, Slurm output files) a plain line every ten seconds,
//! once a run has lasted that long.

use std::io::IsTerminal;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::backend::Progress;
use indicatif::{ProgressBar, ProgressStyle};

/// How often a plain line is printed.
const LINE_EVERY: Duration = Duration::from_secs(10);
/// How often the counts are read.
const POLL: Duration = Duration::from_millis(100);

/// A display thread following a run's [`Progress`].
pub struct Watcher {
    stop: Arc<AtomicBool>,
    thread: JoinHandle<()>,
}

/// Starts displaying `progress` until [`Watcher::finish`].
pub fn watch(progress: &Progress) -> Watcher {
    let stop = Arc::new(AtomicBool::new(false));
    let progress = progress.clone();
    let stopped = stop.clone();
    let thread = std::thread::spawn(move || {
        if std::io::stderr().is_terminal() {
            bar(&progress, &stopped);
        } else {
            lines(&progress, &stopped);
        }
    });
    Watcher { stop, thread }
}

impl Watcher {
    /// Stops the display (clearing the bar) once the run is over.
    pub fn finish(self) {
        self.stop.store(true, Ordering::Relaxed);
        let _ = self.thread.join();
    }
}

fn bar(progress: &Progress, stop: &AtomicBool) {
    // Nothing until the run has counted its work: a bar of 0/0 reads 100%.
    while progress.total() == 0 {
        if stop.load(Ordering::Relaxed) {
            return;
        }
        std::thread::sleep(POLL);
    }
    let bar = ProgressBar::new(progress.total());
    bar.set_style(
        ProgressStyle::with_template(
            "{elapsed_precise} [{wide_bar}] {percent}%  {human_pos}/{human_len} lane-iterations  {rate}  {eta} left",
        )
        .expect("the template is valid")
        // indicatif's own {per_sec} prints four decimals of a rate in the
        // millions; three significant digits say as much.
        .with_key("rate", |state: &indicatif::ProgressState, w: &mut dyn std::fmt::Write| {
            let _ = write!(w, "{:.3e} per second", state.per_sec());
        })
        .progress_chars("=> "),
    );
    while !stop.load(Ordering::Relaxed) {
        bar.set_length(progress.total());
        bar.set_position(progress.done());
        std::thread::sleep(POLL);
    }
    bar.finish_and_clear();
}

fn lines(progress: &Progress, stop: &AtomicBool) {
    // LYAPSWEEP_PROGRESS_SECONDS sets the interval (the tests use 0).
    // (checked with the other variables before the run: `environment`).
    let every = crate::environment::progress_interval()
        .ok()
        .flatten()
        .unwrap_or(LINE_EVERY);
    let start = Instant::now();
    let mut next = every;
    loop {
        let stopping = stop.load(Ordering::Relaxed);
        if !stopping {
            std::thread::sleep(POLL);
        }
        let elapsed = start.elapsed();
        // A run long enough to have had a line gets a last one when it ends.
        let due = elapsed >= next || (stopping && elapsed >= every);
        if due && progress.total() > 0 {
            next = elapsed + every;
            line(progress, elapsed);
        }
        if stopping {
            return;
        }
    }
}

fn line(progress: &Progress, elapsed: Duration) {
    let (done, total) = (progress.done(), progress.total());
    let rate = done as f64 / elapsed.as_secs_f64();
    let left = if rate > 0.0 && done < total {
        format!(", about {:.0} s left", (total - done) as f64 / rate)
    } else {
        String::new()
    };
    eprintln!(
        "progress: {:.0}% ({done} of {total} lane-iterations) after {:.1} s, {rate:.3e} per second{left}",
        100.0 * done as f64 / total as f64,
        elapsed.as_secs_f64()
    );
}
