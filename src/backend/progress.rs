//! How far a run has come, shared between the backend that advances it and
//! whoever displays it (the command's progress bar).

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

/// Work done and in all, in lane-iterations (one map iteration of one
/// sweep value). Clones share the same counts.
#[derive(Clone, Debug, Default)]
pub struct Progress(Arc<Counts>);

#[derive(Debug, Default)]
struct Counts {
    done: AtomicU64,
    total: AtomicU64,
}

impl Progress {
    /// A run of `total` lane-iterations begins.
    pub fn start(&self, total: u64) {
        self.0.done.store(0, Ordering::Relaxed);
        self.0.total.store(total, Ordering::Relaxed);
    }

    /// `n` more lane-iterations join the run (a continuation pass).
    pub fn extend(&self, n: u64) {
        self.0.total.fetch_add(n, Ordering::Relaxed);
    }

    /// `n` more lane-iterations are done.
    pub fn advance(&self, n: u64) {
        self.0.done.fetch_add(n, Ordering::Relaxed);
    }

    /// An attempt at part of the run whose progress may have to be taken
    /// back (a GPU batch that is redone with shorter dispatches).
    pub fn attempt(&self) -> Attempt<'_> {
        Attempt {
            progress: self,
            reported: 0,
        }
    }

    pub fn done(&self) -> u64 {
        self.0.done.load(Ordering::Relaxed)
    }

    /// 0 until the run has started.
    pub fn total(&self) -> u64 {
        self.0.total.load(Ordering::Relaxed)
    }
}

/// The progress one attempt has reported (see [`Progress::attempt`]).
pub struct Attempt<'a> {
    progress: &'a Progress,
    reported: u64,
}

impl Attempt<'_> {
    pub fn advance(&mut self, n: u64) {
        self.progress.advance(n);
        self.reported += n;
    }

    /// The attempt is to be redone: its progress is taken back.
    pub fn undo(self) {
        self.progress
            .0
            .done
            .fetch_sub(self.reported, Ordering::Relaxed);
    }
}
