//! The host's C compiler, as the native code (`model::native::library`) uses it:
//! a C source built into a shared object with the flags that keep the
//! IEEE operations as written ([`FLAGS`]), and the objects cached in the
//! user's cache directory by the hash of their source, compiler, flags
//! and the processor `-march=native` resolves to, each checked against
//! the digest written with it before it is loaded, so a model is built
//! once per processor, not once per run.

use std::path::PathBuf;

/// The flags: the host's vectors, the IEEE operations as written (no
/// fused multiply-adds, no reassociation), `sqrt` as the instruction.
pub(super) const FLAGS: [&str; 6] = [
    "-O3",
    "-march=native",
    "-ffp-contract=off",
    "-fno-math-errno",
    "-fPIC",
    "-shared",
];

/// The cached shared object built from `source` for this machine, loaded.
pub(super) fn compiled(source: &str) -> Result<libloading::Library, String> {
    let cc = compiler();
    compiled_in(&cache_dir()?, &cc, cpu_target(&cc), source)
}

/// The C compiler: `$CC`, else `cc`.
pub(crate) fn compiler() -> String {
    std::env::var("CC").unwrap_or_else(|_| "cc".into())
}

/// The name of the object built by `cc` for the processor `cpu` from
/// `source`: the hash of all three and the flags. `-march=native` makes
/// the code the host's, so a cache shared by machines of different
/// processors (a cluster's nodes with one home directory) keeps one
/// object for each, and none loads another's instructions.
pub(super) fn object_key(cc: &str, cpu: &str, source: &str) -> String {
    use sha2::{Digest, Sha256};
    let mut hash = Sha256::new();
    for part in [cc, &FLAGS.join(" "), cpu, source] {
        hash.update(part.as_bytes());
        hash.update([0]);
    }
    hex(&hash.finalize()[..12])
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// The SHA-256 of `bytes`, in hex.
pub(super) fn digest(bytes: &[u8]) -> String {
    use sha2::{Digest, Sha256};
    hex(&Sha256::digest(bytes))
}

/// [`compiled`] in the directory `dir`, by the compiler `cc`, for the
/// processor `cpu` (the key's part that [`cpu_target`] gives). Each
/// object is kept with the SHA-256 of its bytes (`.sha256` beside it): an
/// object that does not match it (cut short, overwritten) is built again,
/// never loaded. One that matches it and still fails to load (garbage
/// written with its own digest) is removed and built again, once. Both
/// are written under names of this thread's, then renamed: runs and
/// threads at the same time never load a half-written object.
pub(super) fn compiled_in(
    dir: &std::path::Path,
    cc: &str,
    cpu: &str,
    source: &str,
) -> Result<libloading::Library, String> {
    let key = object_key(cc, cpu, source);
    let object = dir.join(format!("{key}.so"));
    let sum = dir.join(format!("{key}.sha256"));
    let intact = || -> bool {
        match (std::fs::read(&object), std::fs::read_to_string(&sum)) {
            (Ok(bytes), Ok(expected)) => digest(&bytes) == expected.trim(),
            _ => false,
        }
    };
    let mut built = false;
    loop {
        if !intact() {
            build(dir, &key, cc, source, (&object, &sum))?;
            built = true;
        }
        // SAFETY: the object is ours (built above or earlier from the same
        // source for this processor, named by its hash, its bytes checked
        // against the digest written with it) and has no initialisers.
        match unsafe { libloading::Library::new(&object) } {
            Ok(library) => return Ok(library),
            // The loader's message names the object.
            Err(e) if built => return Err(e.to_string()),
            // Cached, intact by its digest, and not loadable: built again.
            Err(_) => {
                let _ = std::fs::remove_file(&object);
                let _ = std::fs::remove_file(&sum);
            }
        }
    }
}

/// Builds `source` with `cc` into `object`, its digest into `sum` (the
/// pair of [`compiled_in`]).
fn build(
    dir: &std::path::Path,
    key: &str,
    cc: &str,
    source: &str,
    (object, sum): (&std::path::Path, &std::path::Path),
) -> Result<(), String> {
    static BUILDS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let build = BUILDS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let unique =
        |ext: &str| -> PathBuf { dir.join(format!("{key}.{}-{build}.{ext}", std::process::id())) };
    let (c, so, so_sum) = (unique("c"), unique("so"), unique("sha256"));
    std::fs::write(&c, source).map_err(|e| format!("{}: {e}", c.display()))?;
    let output = std::process::Command::new(cc)
        .args(FLAGS)
        .arg("-o")
        .arg(&so)
        .arg(&c)
        .output()
        .map_err(|e| format!("{cc}: {e}"));
    let _ = std::fs::remove_file(&c);
    let output = output?;
    let written = if output.status.success() {
        std::fs::read(&so)
            .and_then(|bytes| std::fs::write(&so_sum, digest(&bytes)))
            .and_then(|()| std::fs::rename(&so, object))
            .and_then(|()| std::fs::rename(&so_sum, sum))
            .map_err(|e| format!("{}: {e}", object.display()))
    } else {
        let stderr = String::from_utf8_lossy(&output.stderr);
        let stderr = stderr.trim();
        Err(match stderr.is_empty() {
            true => format!("{cc} failed ({}, nothing on stderr)", output.status),
            false => format!("{cc} failed ({}): {stderr}", output.status),
        })
    };
    if written.is_err() {
        let _ = std::fs::remove_file(&so);
        let _ = std::fs::remove_file(&so_sum);
    }
    written
}

/// The processor `cc` builds for under `-march=native`, once per process:
/// the target options its driver resolves `-march=native` to (GCC's
/// `-march=`, `-mtune=` and every `-m` feature flag; clang's
/// `-target-cpu` and `-target-feature`s, in `cc -###`'s commands), else
/// the processor the system describes (`/proc/cpuinfo`'s model and
/// features), else only the architecture.
pub(super) fn cpu_target(cc: &str) -> &'static str {
    static TARGET: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    TARGET.get_or_init(|| {
        resolved_native(cc)
            .or_else(described_cpu)
            .unwrap_or_else(|| format!("{} (unknown processor)", std::env::consts::ARCH))
    })
}

/// `-march=native` as `cc`'s driver resolves it (see [`cpu_target`]).
fn resolved_native(cc: &str) -> Option<String> {
    let output = std::process::Command::new(cc)
        .args([
            "-###",
            "-march=native",
            "-x",
            "c",
            "-c",
            "/dev/null",
            "-o",
            "/dev/null",
        ])
        .output()
        .ok()?;
    target_options(&String::from_utf8_lossy(&output.stderr))
}

/// The target options in a driver's `-###` listing of its commands:
/// those that say which instructions the code may use (no file names,
/// which change from run to run); `None` where `-march=native` was not
/// resolved.
fn target_options(listing: &str) -> Option<String> {
    let mut options = Vec::new();
    let mut words = listing
        .split_whitespace()
        .map(|w| w.trim_matches(|c| c == '"' || c == '\''));
    while let Some(word) = words.next() {
        if matches!(word, "-target-cpu" | "-target-feature" | "-triple") {
            options.push(format!("{word} {}", words.next().unwrap_or_default()));
        } else if word.starts_with("-m") {
            options.push(word.to_string());
        }
    }
    let resolved = options.iter().any(|o| {
        o.starts_with("-target-cpu ") || (o.starts_with("-march=") && o != "-march=native")
    });
    resolved.then(|| options.join(" "))
}

/// The first processor of `/proc/cpuinfo`: its model and features.
fn described_cpu() -> Option<String> {
    let info = std::fs::read_to_string("/proc/cpuinfo").ok()?;
    let keys = [
        "vendor_id",
        "model name",
        "flags",
        "CPU implementer",
        "CPU architecture",
        "CPU variant",
        "CPU part",
        "Features",
    ];
    let described: Vec<&str> = info
        .lines()
        .take_while(|line| !line.trim().is_empty())
        .filter(|line| {
            let key = line.split(':').next().unwrap_or_default().trim();
            keys.contains(&key)
        })
        .collect();
    (!described.is_empty()).then(|| format!("{} {}", std::env::consts::ARCH, described.join("\n")))
}

/// Where the shared objects are kept: the user's cache directory
/// (`$XDG_CACHE_HOME`, else `~/.cache`), else one of the user's in the
/// temporary directory. The objects are loaded and run, so only a
/// directory the user owns and no one else can write is used.
#[cfg(unix)]
fn cache_dir() -> Result<PathBuf, String> {
    use std::os::unix::fs::{DirBuilderExt, MetadataExt};
    let var = |name| {
        std::env::var_os(name)
            .filter(|v| !v.is_empty())
            .map(PathBuf::from)
    };
    // SAFETY: getuid has no preconditions and cannot fail.
    let uid = unsafe { libc::getuid() };
    let dir = match var("XDG_CACHE_HOME").or_else(|| var("HOME").map(|h| h.join(".cache"))) {
        Some(cache) => cache.join("lyapsweep").join("c-loops"),
        None => std::env::temp_dir().join(format!("lyapsweep-c-loops-{uid}")),
    };
    let shown = || dir.display().to_string();
    std::fs::DirBuilder::new()
        .recursive(true)
        .mode(0o700)
        .create(&dir)
        .map_err(|e| format!("{}: {e}", shown()))?;
    let meta = std::fs::metadata(&dir).map_err(|e| format!("{}: {e}", shown()))?;
    if meta.uid() != uid || meta.mode() & 0o022 != 0 {
        return Err(format!(
            "{}: not the user's own, or writable by others",
            shown()
        ));
    }
    Ok(dir)
}

/// Off Unix, no directory is known to be the user's alone: there, too,
/// the interpreter runs the model.
#[cfg(not(unix))]
fn cache_dir() -> Result<PathBuf, String> {
    Err("the C compiler's code is built on Unix only".into())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_driver_s_resolved_target_is_read_without_file_names() {
        let gcc = r#" "/usr/lib/gcc/x86_64-linux-gnu/12/cc1" "-quiet" /dev/null "-march=znver3" -mmmx -mno-avx512f --param "l1-cache-size=32" -o /tmp/cczYGxKF.s"#;
        assert_eq!(
            target_options(gcc).as_deref(),
            Some("-march=znver3 -mmmx -mno-avx512f")
        );
        let clang = r#" "/usr/bin/clang-16" "-cc1" "-triple" "x86_64-pc-linux-gnu" "-target-cpu" "znver3" "-target-feature" "+avx2" "-o" "/tmp/null-5e1f.o""#;
        assert_eq!(
            target_options(clang).as_deref(),
            Some("-triple x86_64-pc-linux-gnu -target-cpu znver3 -target-feature +avx2")
        );
        assert_eq!(target_options(r#" "cc1" "-march=native" "-o" "x.o""#), None);
        assert_eq!(target_options(""), None);
    }
}
