//! Folders outside an output set that a command writes a few files into
//! (`plot --out`, `bench --out`). A file there is replaced only when
//! lyapsweep wrote it, as the folder's record [`RECORD_FILE`] lists: a
//! user's own `figure.png` or `bench.md` of the same name is refused,
//! naming it, never written over. Other files in the folder are left alone.

use std::path::{Path, PathBuf};

use crate::error::{Error, Result};

/// The names of the files lyapsweep wrote into the folder, one a line.
pub const RECORD_FILE: &str = ".lyapsweep-files";

/// That `dir` can take files named `names`: it is new, or a folder whose
/// files of those names were written by lyapsweep (its record lists them).
pub fn check(dir: &Path, names: &[&str]) -> Result<()> {
    let refuse = |path: PathBuf, reason: String| Err(Error::Output { path, reason });
    match std::fs::metadata(dir) {
        Err(_) => return Ok(()),
        Ok(m) if !m.is_dir() => {
            return refuse(
                dir.to_owned(),
                "exists and is not a folder: --out names the folder the files go into".into(),
            )
        }
        Ok(_) => {}
    }
    let recorded = recorded(dir);
    for name in names {
        let path = dir.join(name);
        if path.symlink_metadata().is_ok() && !recorded.iter().any(|r| r == name) {
            return refuse(
                path,
                format!(
                    "exists and was not written by lyapsweep (its {RECORD_FILE} there does not list it), so it is not written over: move it, or give --out a new folder"
                ),
            );
        }
    }
    Ok(())
}

/// Adds the files `written` (in `dir`) to the folder's record.
pub fn record(dir: &Path, written: &[PathBuf]) -> Result<()> {
    let mut names = recorded(dir);
    for path in written {
        if let Some(name) = path.file_name().and_then(|n| n.to_str()) {
            if !names.iter().any(|n| n == name) {
                names.push(name.to_owned());
            }
        }
    }
    let path = dir.join(RECORD_FILE);
    let text: String = names.iter().map(|n| format!("{n}\n")).collect();
    std::fs::write(&path, text).map_err(|source| Error::Write { path, source })
}

fn recorded(dir: &Path) -> Vec<String> {
    std::fs::read_to_string(dir.join(RECORD_FILE))
        .map(|t| t.lines().map(str::to_owned).collect())
        .unwrap_or_default()
}

/// Whether `inner` is `outer` or lies below it (following links, as
/// far as `inner` exists).
pub fn is_within(inner: &Path, outer: &Path) -> bool {
    let Ok(outer) = outer.canonicalize() else {
        return false;
    };
    let absolute = std::path::absolute(inner).unwrap_or_else(|_| inner.to_owned());
    // The deepest part of `inner` that exists, resolved, and the rest.
    let mut rest = Vec::new();
    let mut existing = absolute.as_path();
    loop {
        if let Ok(resolved) = existing.canonicalize() {
            let whole: PathBuf = resolved.join(rest.iter().rev().collect::<PathBuf>());
            return whole.starts_with(&outer);
        }
        match (existing.parent(), existing.file_name()) {
            (Some(parent), Some(name)) => {
                rest.push(name.to_owned());
                existing = parent;
            }
            _ => return false,
        }
    }
}
