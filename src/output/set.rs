//! One run's files as a set: written into a fresh sibling of the output
//! folder and swapped in whole, so that the folder holds one complete set,
//! the previous one or the new one, never a mix.
//!
//! A run (or a merge) first [`prepare`](Staging::prepare)s its output folder,
//! before any computation: the folder must be new, empty, or a lyapsweep
//! output folder (one with its manifest; nothing else in it is ever
//! replaced), it must not hold the run's inputs (its scene file, say), and
//! its parent must be writable. The files go into
//! `.NAME.lyapsweep-PID-SEQ.partial` beside it (see [`staging_name`]); [`commit`](Staging::commit)
//! writes `manifest.toml` (every data file's size and SHA-256) and
//! exchanges the two folders in one `renameat2(2)` call (`RENAME_EXCHANGE`,
//! Linux), then removes the previous set. Where the
//! exchange is not available the previous set is renamed aside first, which
//! leaves a moment with no folder at all, never a mixed one. A killed run
//! leaves only its hidden sibling, which the next run into the same folder
//! removes; `plot` and `merge` read a folder only when its files match its
//! manifest ([`verify`]).

use std::fs;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use super::basin_files::is_basin_file;
use super::files::{
    write_text, ATTRACTORS_FILE, ATTRACTOR_MAP, BIFURCATIONS_FILE, BIFURCATION_FILE, GRID_FILE,
    HEAT_MAP, ORBITS_FILE, ORBIT_FIGURE, ORBIT_MAP, SCENE_FILE, SHARD_FILE, SPECTRUM_FILE,
    SWEEP_FIGURE,
};
use crate::error::{Error, Result};

/// The list of a set's data files, with their sizes and digests.
pub const MANIFEST_FILE: &str = "manifest.toml";

/// The data files a set may hold (the figures are drawn from them and are
/// not part of the manifest: `plot` redraws them in place).
const DATA_FILES: [&str; 8] = [
    SCENE_FILE,
    SHARD_FILE,
    SPECTRUM_FILE,
    GRID_FILE,
    BIFURCATION_FILE,
    ATTRACTORS_FILE,
    ORBITS_FILE,
    BIFURCATIONS_FILE,
];
pub const FIGURE_STEMS: [&str; 5] = [
    SWEEP_FIGURE,
    HEAT_MAP,
    ATTRACTOR_MAP,
    ORBIT_FIGURE,
    ORBIT_MAP,
];

/// Pauses before writing each file and before the swap, naming the step on
/// stderr, for tests that kill a run in its write phase.
const PAUSE_VARIABLE: &str = "LYAPSWEEP_TEST_WRITE_PAUSE_MS";

/// A set being written: the folder it will become and the staging folder.
#[derive(Debug)]
pub struct Staging {
    target: PathBuf,
    dir: PathBuf,
    committed: bool,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Manifest {
    files: Vec<Entry>,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Entry {
    name: String,
    bytes: u64,
    sha256: String,
}

fn unwritable(path: &Path, reason: impl Into<String>) -> Error {
    Error::Output {
        path: path.to_owned(),
        reason: reason.into(),
    }
}

/// Whether a file of this name is one of a set's data files (listed in
/// its manifest): the fixed names and the basin labels.
fn is_data_file(name: &str) -> bool {
    DATA_FILES.contains(&name) || is_basin_file(name, "npy")
}

/// Whether lyapsweep writes files of this name into an output folder.
fn is_ours(name: &str) -> bool {
    is_data_file(name)
        || name == MANIFEST_FILE
        || is_basin_file(name, "png")
        || is_basin_file(name, "svg")
        || FIGURE_STEMS
            .iter()
            .any(|stem| [".png", ".svg"].iter().any(|ext| name == format!("{stem}{ext}")))
        // A single file's temporary (see `files::temporary_name`).
        || (name.starts_with('.') && name.contains(".partial"))
}

/// Whether `input` lies in the folder `canonical` (itself canonical):
/// the input as named (a link would be replaced, not what it points to)
/// or as resolved.
fn within(input: &Path, canonical: &Path) -> bool {
    let named = match (input.parent(), input.file_name()) {
        (Some(parent), Some(name)) => {
            let parent = if parent.as_os_str().is_empty() {
                Path::new(".")
            } else {
                parent
            };
            fs::canonicalize(parent).ok().map(|p| p.join(name))
        }
        _ => None,
    };
    [named, fs::canonicalize(input).ok()]
        .into_iter()
        .flatten()
        .any(|path| path.starts_with(canonical))
}

/// The staging folders of `target` are named `.NAME.lyapsweep-PID-SEQ.partial`
/// (`NAME` shortened, see [`staging_base`]); this is what precedes the PID.
fn staging_prefix(target: &Path) -> String {
    let name = target
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or("output");
    format!(".{}.lyapsweep-", staging_base(name))
}

/// The longest output folder name kept whole in its staging folder's name:
/// the rest of that name (at most 52 bytes with a 10-digit process id and a
/// 20-digit sequence number, `.previous` being the longest ending) must fit
/// in the 255 bytes a file name may have.
const LONGEST_WHOLE_NAME: usize = 200;

/// `name` as it appears in its staging folder's name: itself when short
/// enough, else its first bytes and a digest of the whole (so that two long
/// names that share their start are still told apart).
fn staging_base(name: &str) -> String {
    if name.len() <= LONGEST_WHOLE_NAME {
        return name.to_owned();
    }
    let mut end = 120;
    while !name.is_char_boundary(end) {
        end -= 1;
    }
    let hash = Sha256::digest(name.as_bytes());
    let hex: String = hash[..8].iter().map(|b| format!("{b:02x}")).collect();
    format!("{}~{hex}", &name[..end])
}

/// A fresh staging folder's name for `target`: the process id tells a
/// killed run's folder (see [`remove_abandoned`]), and a number counted
/// within the process keeps two runs of one process (threads of a Python
/// program) in folders of their own.
fn staging_name(target: &Path) -> String {
    static SEQUENCE: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let seq = SEQUENCE.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    format!(
        "{}{}-{seq}.partial",
        staging_prefix(target),
        std::process::id()
    )
}

impl Staging {
    /// Checks that `target` can take a new set and creates the staging
    /// folder beside it. `inputs` are what the set is made from (merge's
    /// shard folders; a run's scene file and the model file it names): the
    /// target must not be one of them nor hold one, since the swap replaces
    /// the whole folder.
    pub fn prepare(target: &Path, inputs: &[PathBuf]) -> Result<Staging> {
        // A link to a folder (scratch space on a cluster) is followed: the
        // set is staged beside, and swapped into, the folder it names. So
        // are "." and "..", which name no entry of their parent.
        let is_link = fs::symlink_metadata(target).is_ok_and(|m| m.file_type().is_symlink());
        let resolved;
        let target = if is_link || target.file_name().is_none() {
            resolved = fs::canonicalize(target).map_err(|e| unwritable(target, e.to_string()))?;
            resolved.as_path()
        } else {
            target
        };
        if let Ok(meta) = fs::metadata(target) {
            if !meta.is_dir() {
                return Err(unwritable(target, "exists and is not a folder"));
            }
            let canonical = fs::canonicalize(target).ok();
            if let Some(input) = inputs
                .iter()
                .find(|i| canonical.is_some() && fs::canonicalize(i).ok() == canonical)
            {
                return Err(unwritable(
                    target,
                    format!(
                        "is also an input ({}): write the merged set to another folder",
                        input.display()
                    ),
                ));
            }
            if let Some(input) = canonical
                .as_ref()
                .and_then(|c| inputs.iter().find(|i| within(i, c)))
            {
                return Err(unwritable(
                    target,
                    format!(
                        "holds {}, which this command reads and a new set would replace: write the output to another folder",
                        input.display()
                    ),
                ));
            }
            let entries = fs::read_dir(target).map_err(|e| unwritable(target, e.to_string()))?;
            let names: Vec<String> = entries
                .filter_map(|e| e.ok())
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect();
            let mut foreign: Vec<String> = names
                .iter()
                .filter(|name| !is_ours(name))
                .cloned()
                .collect();
            if !foreign.is_empty() {
                foreign.sort();
                foreign.truncate(5);
                return Err(unwritable(
                    target,
                    format!(
                        "holds files lyapsweep does not write ({}), which a new set would replace: give a new or empty folder",
                        foreign.join(", ")
                    ),
                ));
            }
            // Every set has its manifest (written last, before the swap):
            // data files without one are someone's files of the same
            // names (a scene.toml kept with its results, say), not a set.
            let mut data: Vec<&str> = DATA_FILES
                .into_iter()
                .filter(|name| names.iter().any(|n| n == name))
                .collect();
            if !data.is_empty() && !names.iter().any(|n| n == MANIFEST_FILE) {
                data.sort();
                return Err(unwritable(
                    target,
                    format!(
                        "holds {} but no {MANIFEST_FILE}, so it is not a lyapsweep output set, and a new set would replace them: give a new or empty folder",
                        data.join(", ")
                    ),
                ));
            }
        }
        let parent = match target.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_owned(),
            _ => PathBuf::from("."),
        };
        fs::create_dir_all(&parent)
            .map_err(|e| unwritable(target, format!("cannot create {}: {e}", parent.display())))?;
        remove_abandoned(&parent, &staging_prefix(target));
        let dir = parent.join(staging_name(target));
        if dir.exists() {
            let _ = fs::remove_dir_all(&dir);
        }
        fs::create_dir(&dir).map_err(|e| {
            unwritable(target, format!("cannot write in {}: {e}", parent.display()))
        })?;
        Ok(Staging {
            target: target.to_owned(),
            dir,
            committed: false,
        })
    }

    /// The staging folder, where the set's files are written.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Writes the manifest and swaps the set in; returns the paths of its
    /// files in the output folder.
    pub fn commit(self) -> Result<Vec<PathBuf>> {
        self.commit_unless(&|| false)
    }

    /// [`commit`](Self::commit), unless `stopped` says, at the last moment
    /// before the swap, that the run was stopped meanwhile (Ctrl-C while
    /// the set was written): then `Error::Stopped`, the staged set removed
    /// and the output folder as it was.
    pub fn commit_unless(mut self, stopped: &dyn Fn() -> bool) -> Result<Vec<PathBuf>> {
        let write_error = |source| Error::Write {
            path: self.target.clone(),
            source,
        };
        let mut names: Vec<String> = fs::read_dir(&self.dir)
            .map_err(write_error)?
            .filter_map(|e| e.ok())
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| !n.starts_with('.'))
            .collect();
        names.sort();
        let mut files = Vec::new();
        for name in names.iter().filter(|n| is_data_file(n)) {
            let (bytes, sha256) = digest(&self.dir.join(name)).map_err(write_error)?;
            files.push(Entry {
                name: name.clone(),
                bytes,
                sha256,
            });
        }
        let text = toml::to_string(&Manifest { files }).expect("a manifest serialises");
        pause(MANIFEST_FILE);
        write_text(
            &self.dir.join(MANIFEST_FILE),
            &format!("# The data files of this set (lyapsweep): their sizes and SHA-256.\n{text}"),
        )?;
        fs::File::open(&self.dir)
            .and_then(|d| d.sync_all())
            .map_err(write_error)?;
        pause("swap");
        if stopped() {
            return Err(Error::Stopped);
        }
        swap_in(&self.dir, &self.target).map_err(write_error)?;
        self.committed = true;
        // The staging folder now holds the previous set, if there was one.
        let _ = fs::remove_dir_all(&self.dir);
        names.push(MANIFEST_FILE.to_owned());
        names.sort();
        Ok(names.iter().map(|n| self.target.join(n)).collect())
    }
}

impl Drop for Staging {
    fn drop(&mut self) {
        if !self.committed {
            let _ = fs::remove_dir_all(&self.dir);
        }
    }
}

/// Writes the set in `from` (checked against its manifest first) as the
/// set of `to`, staged and swapped in whole like a run's own; returns the
/// paths of its files in `to`. A front end that ran into a scratch folder
/// keeps its results there and copies them out when asked.
pub fn copy(from: &Path, to: &Path) -> Result<Vec<PathBuf>> {
    verify(from)?;
    let staging = Staging::prepare(to, &[from.to_owned()])?;
    let read_error = |source| Error::Write {
        path: from.to_owned(),
        source,
    };
    for entry in fs::read_dir(from).map_err(read_error)? {
        let name = entry.map_err(read_error)?.file_name();
        let name = name.to_string_lossy();
        // The manifest is written anew by the commit.
        if name == MANIFEST_FILE || name.starts_with('.') || !is_ours(&name) {
            continue;
        }
        let target = staging.dir().join(&*name);
        let write_error = |source| Error::Write {
            path: target.clone(),
            source,
        };
        fs::copy(from.join(&*name), &target).map_err(write_error)?;
        fs::File::open(&target)
            .and_then(|f| f.sync_all())
            .map_err(write_error)?;
    }
    staging.commit()
}

/// Before writing `what`, the pause tests ask for (see [`PAUSE_VARIABLE`]).
pub(crate) fn pause(what: &str) {
    if let Some(ms) = std::env::var(PAUSE_VARIABLE)
        .ok()
        .and_then(|v| v.parse::<u64>().ok())
    {
        eprintln!("writing: {what}");
        std::thread::sleep(std::time::Duration::from_millis(ms));
    }
}

fn digest(path: &Path) -> std::io::Result<(u64, String)> {
    let mut file = fs::File::open(path)?;
    let mut hasher = Sha256::new();
    let bytes = std::io::copy(&mut file, &mut hasher)?;
    let hash = hasher.finalize();
    Ok((bytes, hash.iter().map(|b| format!("{b:02x}")).collect()))
}

/// Replaces `target` by `staging` at once; `staging` then holds what
/// `target` held (or nothing, when there was no `target`).
fn swap_in(staging: &Path, target: &Path) -> std::io::Result<()> {
    if !target.exists() {
        return fs::rename(staging, target);
    }
    #[cfg(target_os = "linux")]
    if exchange(staging, target).is_ok() {
        return Ok(());
    }
    // Not atomic: the previous set goes aside, then the new one comes in.
    let aside = staging.with_extension("previous");
    fs::rename(target, &aside)?;
    fs::rename(staging, target)?;
    fs::rename(&aside, staging)
}

#[cfg(target_os = "linux")]
fn exchange(a: &Path, b: &Path) -> std::io::Result<()> {
    use std::ffi::CString;
    use std::os::unix::ffi::OsStrExt;
    let c = |p: &Path| CString::new(p.as_os_str().as_bytes()).map_err(std::io::Error::other);
    let (a, b) = (c(a)?, c(b)?);
    // SAFETY: both are valid NUL-terminated paths that outlive the call.
    let rc = unsafe {
        libc::renameat2(
            libc::AT_FDCWD,
            a.as_ptr(),
            libc::AT_FDCWD,
            b.as_ptr(),
            libc::RENAME_EXCHANGE,
        )
    };
    if rc == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

/// Removes staging folders of `parent` left by runs that were killed (their
/// process is gone). Without /proc nothing can be told, and they stay:
/// they are hidden and never read.
fn remove_abandoned(parent: &Path, prefix: &str) {
    if !Path::new("/proc/self").exists() {
        return;
    }
    let Ok(entries) = fs::read_dir(parent) else {
        return;
    };
    for entry in entries.filter_map(|e| e.ok()) {
        let name = entry.file_name().to_string_lossy().into_owned();
        let Some(rest) = name.strip_prefix(prefix) else {
            continue;
        };
        // `PID-SEQ.partial` (and `PID.partial`, before runs were counted).
        let pid = rest.split(['.', '-']).next().unwrap_or_default();
        if pid.parse::<u32>().is_ok() && !Path::new("/proc").join(pid).exists() {
            let _ = fs::remove_dir_all(entry.path());
        }
    }
}

/// Checks that `dir` holds one complete set: a manifest whose every file is
/// present with its size and digest, and no data file it does not list.
pub fn verify(dir: &Path) -> Result<()> {
    let bad = |path: PathBuf, reason: String| Error::Results { path, reason };
    let path = dir.join(MANIFEST_FILE);
    let text = fs::read_to_string(&path).map_err(|e| {
        bad(
            path.clone(),
            format!("cannot read it ({e}): not a complete lyapsweep output folder (an interrupted run, or one written before sets had manifests); run it again"),
        )
    })?;
    let manifest: Manifest =
        toml::from_str(&text).map_err(|e| bad(path.clone(), e.message().to_owned()))?;
    for entry in &manifest.files {
        let file = dir.join(&entry.name);
        let (bytes, sha256) = digest(&file)
            .map_err(|e| bad(file.clone(), format!("listed in {MANIFEST_FILE}, but {e}")))?;
        if bytes != entry.bytes || sha256 != entry.sha256 {
            return Err(bad(
                file,
                format!("differs from what {MANIFEST_FILE} lists ({bytes} bytes, {} listed): the folder's files are not one set", entry.bytes),
            ));
        }
    }
    for name in DATA_FILES {
        if dir.join(name).exists() && !manifest.files.iter().any(|e| e.name == name) {
            return Err(bad(
                dir.join(name),
                format!("is not listed in {MANIFEST_FILE}: the folder's files are not one set"),
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A set whose one data file says which run wrote it.
    fn stage(target: &Path, text: &str) -> Result<Staging> {
        let staging = Staging::prepare(target, &[])?;
        fs::write(staging.dir().join(SCENE_FILE), text).unwrap();
        Ok(staging)
    }

    #[test]
    fn a_long_folder_name_stages_beside_it() {
        // 240 bytes is a legal name; `.NAME.lyapsweep-PID.partial` of it
        // was not ("File name too long").
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("x".repeat(240));
        let written = stage(&target, "one").unwrap().commit().unwrap();
        assert_eq!(fs::read_to_string(&written[1]).unwrap(), "one");
        // And again over the set it wrote (the swap's own names fit too).
        stage(&target, "two").unwrap().commit().unwrap();
        assert_eq!(fs::read_to_string(target.join(SCENE_FILE)).unwrap(), "two");
        verify(&target).unwrap();
        let left: Vec<_> = fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(left.len(), 1, "only the set is left");
    }

    #[test]
    fn long_names_that_share_their_start_stage_apart() {
        let a = staging_base(&format!("{}a", "é".repeat(120)));
        let b = staging_base(&format!("{}b", "é".repeat(120)));
        assert_ne!(a, b);
        assert!(a.len() < LONGEST_WHOLE_NAME, "{}", a.len());
        assert_eq!(staging_base("short"), "short");
    }

    #[test]
    fn two_runs_of_one_process_stage_apart() {
        // Threads of one program: each its own staging folder, each set
        // whole when swapped in one after the other.
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out");
        let first = stage(&target, "first").unwrap();
        let second = stage(&target, "second").unwrap();
        assert_ne!(first.dir(), second.dir());
        first.commit().unwrap();
        assert_eq!(
            fs::read_to_string(target.join(SCENE_FILE)).unwrap(),
            "first"
        );
        verify(&target).unwrap();
        second.commit().unwrap();
        assert_eq!(
            fs::read_to_string(target.join(SCENE_FILE)).unwrap(),
            "second"
        );
        verify(&target).unwrap();
    }

    #[test]
    fn a_dead_process_staging_is_removed_a_live_one_kept() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out");
        let prefix = staging_prefix(&target);
        // No process has id 4294967295 (beyond Linux's pid_max); this one lives.
        let dead = dir.path().join(format!("{prefix}4294967295-3.partial"));
        let old = dir.path().join(format!("{prefix}4294967295.partial"));
        let live = dir.path().join(staging_name(&target));
        for d in [&dead, &old, &live] {
            fs::create_dir(d).unwrap();
        }
        remove_abandoned(dir.path(), &prefix);
        assert!(!dead.exists() && !old.exists());
        assert!(live.exists());
    }
}
