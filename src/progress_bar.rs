//! The command's progress display on stderr: a bar with rate and time left
//! when stderr is a terminal; otherwise (CI logs, Slurm output files) a
//! plain line every ten seconds, once a run has lasted that long.

use std::io::IsTerminal;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressStyle};
use lyapsweep::Progress;

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
    let bar = ProgressBar::new(0);
    bar.set_style(
        ProgressStyle::with_template(
            "{elapsed_precise} [{wide_bar}] {percent}%  {human_pos}/{human_len} lane-iterations  {per_sec}  {eta} left",
        )
        .expect("the template is valid")
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
    let start = Instant::now();
    let mut next = LINE_EVERY;
    while !stop.load(Ordering::Relaxed) {
        std::thread::sleep(POLL);
        let elapsed = start.elapsed();
        let (done, total) = (progress.done(), progress.total());
        if elapsed < next || total == 0 {
            continue;
        }
        next += LINE_EVERY;
        let rate = done as f64 / elapsed.as_secs_f64();
        let left = if rate > 0.0 {
            format!(
                ", about {:.0} s left",
                (total - done.min(total)) as f64 / rate
            )
        } else {
            String::new()
        };
        eprintln!(
            "progress: {:.0}% ({done} of {total} lane-iterations) after {:.0} s, {rate:.3e} per second{left}",
            100.0 * done as f64 / total as f64,
            elapsed.as_secs_f64()
        );
    }
}
