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

    /// `n` more lane-iterations are done.
    pub fn advance(&self, n: u64) {
        self.0.done.fetch_add(n, Ordering::Relaxed);
    }

    /// `n` lane-iterations are to be done again (a GPU batch redone with
    /// shorter dispatches).
    pub fn retreat(&self, n: u64) {
        self.0.done.fetch_sub(n, Ordering::Relaxed);
    }

    pub fn done(&self) -> u64 {
        self.0.done.load(Ordering::Relaxed)
    }

    /// 0 until the run has started.
    pub fn total(&self) -> u64 {
        self.0.total.load(Ordering::Relaxed)
    }
}
