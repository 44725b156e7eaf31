//! A field's step loop ([`Walk`]) written in C and built by the host's C
//! compiler for the host's own vector width; and for a model with general
//! surfaces, the loop over its regions that also detects them
//! ([`SwitchWalk`]).
//!
//! Cranelift emits 128-bit vectors only: its loop over eight slots ran 9.2
//! ns per slot-step on the seed's oscillator (an AVX-512 Xeon), the same
//! operations as C loops over the slots that GCC vectorises for the host
//! (`-march=native`) 3.8 to 4.5 ns (docs/BENCHMARKS.md, "The step loop
//! built by the host's C compiler"). The C here is the cranelift loop's
//! twin, operation for operation: every tape instruction one IEEE operation
//! in the tape's order, no contraction into fused multiply-adds
//! (`-ffp-contract=off`) and no reassociation (no `-ffast-math`), so the
//! bits are those of [`Native::walk`](super::jit::Native::walk), which the
//! tests check.
//!
//! Where there is no C compiler (`cc`, or `$CC`), or it fails, the loop is
//! cranelift's. The shared objects are cached in the user's cache
//! directory by the hash of their source, compiler, flags and the
//! processor `-march=native` resolves to, each checked against the digest
//! written with it before it is loaded, so a model is built once per
//! processor, not once per run.

use super::expr::Func;
use super::jit::{callback, Layout, StopCode, Walk, WALK_WIDTHS};
use super::tape::{Code, Tape};
use crate::integrate::impact::TURN_REACH;
use crate::integrate::surface::Surface;
use std::fmt::Write as _;
use std::path::PathBuf;

/// The flags: the host's vectors, the IEEE operations as written (no
/// fused multiply-adds, no reassociation), `sqrt` as the instruction.
const FLAGS: [&str; 6] = [
    "-O3",
    "-march=native",
    "-ffp-contract=off",
    "-fno-math-errno",
    "-fPIC",
    "-shared",
];

/// Step loops built by the C compiler, by width (4 and 8) and
/// layout; the library that holds their code.
pub struct CLoops {
    pub walks: [[Walk; 2]; WALK_WIDTHS.len()],
    _library: libloading::Library,
}

impl std::fmt::Debug for CLoops {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("CLoops")
    }
}

impl CLoops {
    /// The step loops of `tape` detecting `stops`, or why not (no C
    /// compiler, or it failed).
    pub fn build(tape: &Tape, stops: &[StopCode]) -> Result<CLoops, String> {
        // The functions called back into Rust, by their index in `calls`:
        // the source holds no address, so one object serves every process.
        let fields = [Region {
            field: tape,
            surfaces: None,
        }];
        let (library, walks) = built::<Walk>(&fields, stops, &[])?;
        Ok(CLoops {
            walks,
            _library: library,
        })
    }
}

/// The step loops of a model with general surfaces (events and switches)
/// built by the C compiler ([`SwitchWalk`]), by width and layout.
pub struct SwitchLoops {
    walks: [[SwitchWalk; 2]; WALK_WIDTHS.len()],
    /// How many regions, surfaces and stops the loops were built for.
    regions: usize,
    surfaces: usize,
    stops: usize,
    /// One RK4 step sliding on one switch or two (`slides`), at base
    /// region · regions + the switches' bits as a mask; each region's
    /// count of field constants.
    slides: Vec<Option<SlideStep>>,
    constants: Vec<usize>,
    states: usize,
    _library: libloading::Library,
}

/// One RK4 step of one trajectory sliding on one switch or two (see
/// `slide_step`): from `y` (D values) with the three stages' phases in
/// `clock` (6 values) and step `h`, the constants of the fields F₀, F₁
/// (and F₂) (`f0`, `f1`, `f2`) and the switches' constant gradients
/// (`g0`, `g1`, D values each; the last of each null with one switch),
/// into `out` (D values). (The pointers one by one: passed in an array
/// that Rust had just written, they cost the step a third more on the
/// friction belt, measured.)
pub type SlideStep = unsafe extern "C" fn(
    y: *const f64,
    clock: *const f64,
    h: f64,
    f0: *const f64,
    f1: *const f64,
    f2: *const f64,
    g0: *const f64,
    g1: *const f64,
    out: *mut f64,
);

impl std::fmt::Debug for SwitchLoops {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("SwitchLoops")
    }
}

/// A step loop of a model with general surfaces: [`Walk`]'s, with every
/// slot in its own region of the switches (`region`, W `i64`) and the
/// surfaces' values and rates at the states' start (`values`, rows 2j
/// and 2j + 1 of W for surface j: `surface::SurfaceBatch`'s), read and
/// written back where the loop stopped. `lanes` holds, region by region,
/// a pointer to the field's constants and one to its surfaces'. It also
/// stops before the first step in which a live slot may cross a surface
/// (`surface::may_cross`); the caller never hands it a slot that slides
/// or is held.
pub type SwitchWalk = unsafe extern "C" fn(
    y: *mut f64,
    phase: *mut f64,
    lanes: *const *const f64,
    h: *const f64,
    walls: *const f64,
    live: *const i64,
    steps: u64,
    region: *const i64,
    values: *mut f64,
) -> u64;

impl SwitchLoops {
    /// The step loops of a model whose region r has the field `fields[r].0`
    /// and the surfaces' tape (values and rates) `fields[r].1`, with
    /// `stops` and general surfaces of `kinds`; or why not.
    pub fn build(
        fields: &[(&Tape, &Tape)],
        stops: &[StopCode],
        kinds: &[Surface],
    ) -> Result<SwitchLoops, String> {
        let regions: Vec<Region> = fields
            .iter()
            .map(|&(field, surfaces)| Region {
                field,
                surfaces: Some(surfaces),
            })
            .collect();
        let (library, walks) = built::<SwitchWalk>(&regions, stops, kinds)?;
        let regions = fields.len();
        let mut steps = vec![None; regions * regions];
        for (base, bits) in slides(regions, kinds) {
            let name = slide_name(base, &bits);
            // SAFETY: `built` defined `name` with `SlideStep`'s signature
            // (C calling convention); the library is kept with the
            // function.
            let f = unsafe { *library.get::<SlideStep>(name.as_bytes()).expect("defined") };
            steps[base * regions + bits.iter().fold(0, |m, &b| m | 1 << b)] = Some(f);
        }
        Ok(SwitchLoops {
            walks,
            regions: fields.len(),
            surfaces: kinds.len(),
            stops: stops.len(),
            slides: steps,
            constants: fields.iter().map(|f| f.0.lane_constants.len()).collect(),
            states: fields[0].0.states,
            _library: library,
        })
    }
}

impl SwitchLoops {
    /// One RK4 step (`rk4::step_at`) of a trajectory sliding on the
    /// switches of bits `bits` at once (one or two), from region `base`
    /// (their bits clear), at the stage phases `stages`: the field is the
    /// equivalent control's, `surface::equivalent_on`'s to the bit, from
    /// the constants of F₀ (region `base`) and of each F_m (`base` with
    /// bit m set) in `fields`, and each switch's constant gradient in
    /// `grads`. `None` where the library has no such step.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    pub fn slide_step<const D: usize>(
        &self,
        base: u32,
        bits: &[u32],
        stages: &[[f64; 2]; 3],
        y: &[f64; D],
        h: f64,
        fields: &[&[f64]],
        grads: &[&[f64]],
    ) -> Option<[f64; D]> {
        let base = base as usize;
        let mask = bits.iter().fold(0, |m, &b| m | 1 << b);
        let f = (*self.slides.get(base * self.regions + mask)?)?;
        let regions = std::iter::once(base).chain(bits.iter().map(|&b| base | 1 << b));
        assert!(
            D == self.states
                && fields.len() == bits.len() + 1
                && grads.len() == bits.len()
                && regions
                    .zip(fields)
                    .all(|(r, c)| c.len() >= self.constants[r])
                && grads.iter().all(|g| g.len() >= D)
        );
        let field = |m: usize| fields.get(m).map_or(std::ptr::null(), |c| c.as_ptr());
        let grad = |m: usize| grads.get(m).map_or(std::ptr::null(), |g| g.as_ptr());
        let mut out = [0.0; D];
        // SAFETY: the step reads D states, 6 clock values, the regions'
        // constants and D values of each gradient (counts and lengths
        // checked), and writes D values; it was compiled for this model's
        // D states and this set of switches.
        unsafe {
            f(
                y.as_ptr(),
                stages.as_flattened().as_ptr(),
                h,
                field(0),
                field(1),
                field(2),
                grad(0),
                grad(1),
                out.as_mut_ptr(),
            )
        };
        Some(out)
    }

    /// [`Native::walk`](super::jit::Native::walk) for a model with general
    /// surfaces: up to `steps` steps of W trajectories, slot k in region
    /// `regions[k]` (none sliding or held), stopping before the first step
    /// in which a live slot meets a stop or may cross a surface; `values`
    /// holds the surfaces' values and rates at the states (read, and
    /// written back where the loop stopped). `lanes` gives, for each region
    /// present, its field's constants and its surfaces' (by `layout`, as
    /// `Native::walk` takes `lane`); the others are never read. `None`
    /// where there is no loop for W.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    pub fn walk<const W: usize, const D: usize>(
        &self,
        layout: Layout,
        y: &mut [[f64; W]; D],
        clock: &mut [f64],
        lanes: &[[*const f64; 2]],
        h: &[f64],
        walls: &[f64],
        live: u32,
        steps: usize,
        regions: &[u32; W],
        values: &mut [[f64; W]],
    ) -> Option<usize> {
        let w = WALK_WIDTHS.iter().position(|&w| w == W)?;
        let f = self.walks[w][layout as usize];
        let per_slot = if layout == Layout::Shared { 1 } else { W };
        assert!(
            clock.len() >= 4
                && lanes.len() == self.regions
                && regions.iter().all(|&r| (r as usize) < self.regions)
                && regions
                    .iter()
                    .all(|&r| lanes[r as usize].iter().all(|p| !p.is_null()))
                && h.len() >= per_slot
                && walls.len() >= self.stops * per_slot
                && values.len() >= 2 * self.surfaces
        );
        let live: [i64; W] = std::array::from_fn(|k| -i64::from(live >> k & 1 == 1));
        let region: [i64; W] = regions.map(i64::from);
        // SAFETY: the loop reads and writes D·W states in `y`, the phase in
        // `clock` and 2·surfaces rows of W in `values`; reads W regions
        // (each below `self.regions`, checked), W masks, the step sizes and
        // the stops' positions as `layout` lays them out, and the
        // constants of the regions present (non-null, checked) through
        // `lanes`; it was compiled for W, `layout`, this model's D states,
        // regions, surfaces and stops.
        let taken = unsafe {
            f(
                y.as_mut_ptr().cast(),
                clock.as_mut_ptr(),
                lanes.as_ptr().cast(),
                h.as_ptr(),
                walls.as_ptr(),
                live.as_ptr(),
                steps as u64,
                region.as_ptr(),
                values.as_mut_ptr().cast(),
            )
        };
        Some(taken as usize)
    }
}

/// One region's tapes: the field, and where the model has general
/// surfaces, their values and rates along it.
struct Region<'a> {
    field: &'a Tape,
    surfaces: Option<&'a Tape>,
}

/// The library of the step loops of `regions` (every width and layout),
/// loaded with its callbacks set, and the loops, of type `T`.
fn built<T: Copy>(
    regions: &[Region],
    stops: &[StopCode],
    kinds: &[Surface],
) -> Result<(libloading::Library, [[T; 2]; WALK_WIDTHS.len()]), String> {
    let (source, calls) = source_of(regions, stops, kinds);
    loaded(compiled(&source)?, &calls)
}

/// The C source of the step loops of `regions` (every width and layout)
/// and of their slides, and the functions it calls back into Rust, by
/// their index in its table (the source holds no address, so one object
/// serves every process).
fn source_of(regions: &[Region], stops: &[StopCode], kinds: &[Surface]) -> (String, Vec<Func>) {
    let mut calls: Vec<Func> = Vec::new();
    let tapes = regions
        .iter()
        .flat_map(|r| std::iter::once(r.field).chain(r.surfaces));
    for tape in tapes {
        for ins in tape.lowered().0 {
            if let Code::Call(f) = ins.code {
                if !matches!(f, Func::Sqrt | Func::Abs) && !calls.contains(&f) {
                    calls.push(f);
                }
            }
        }
    }
    let mut source = format!(
        "#include <stdint.h>\ntypedef double (*apply)(double, double);\n\
         static apply calls[{n}];\n\
         void set_calls(const apply *t) {{ for (int i = 0; i < {n}; i++) calls[i] = t[i]; }}\n",
        n = calls.len().max(1)
    );
    for &w in &WALK_WIDTHS {
        for layout in [Layout::Shared, Layout::Each] {
            walk(&mut source, regions, &calls, stops, kinds, w, layout);
        }
    }
    for (base, bits) in slides(regions.len(), kinds) {
        let tapes: Vec<&Tape> = std::iter::once(base)
            .chain(bits.iter().map(|b| base | 1 << b))
            .map(|r| regions[r].field)
            .collect();
        slide_step(
            &mut source,
            &calls,
            &slide_name(base, &bits),
            &tapes,
            sum_start(),
        );
    }
    (source, calls)
}

/// The library built from [`source_of`]'s source with its callbacks
/// (`calls`) set, and its step loops, of type `T`.
fn loaded<T: Copy>(
    library: libloading::Library,
    calls: &[Func],
) -> Result<(libloading::Library, [[T; 2]; WALK_WIDTHS.len()]), String> {
    let table: Vec<extern "C" fn(f64, f64) -> f64> = calls.iter().map(|&f| callback(f)).collect();
    // SAFETY: `set_calls` is defined by the source, reads `calls.len()`
    // function pointers (C calling convention, two f64 to one) from the
    // table; objects loaded twice share `calls`, and the same source sets
    // the same table.
    unsafe {
        let set = library
            .get::<unsafe extern "C" fn(*const extern "C" fn(f64, f64) -> f64)>(b"set_calls")
            .map_err(|e| e.to_string())?;
        set(table.as_ptr());
    }
    let walks = WALK_WIDTHS.map(|w| {
        [Layout::Shared, Layout::Each].map(|layout| {
            let name = format!("walk{w}{layout:?}");
            // SAFETY: the source defines `name` with the signature of `T`
            // (`Walk`, or `SwitchWalk` where the regions have surfaces;
            // C calling convention), and the library stays loaded while
            // the loops' owner lives.
            unsafe {
                *library
                    .get::<T>(name.as_bytes())
                    .expect("defined by the source")
            }
        })
    });
    Ok((library, walks))
}

/// The slides a model's library has a step for: on one switch or two at
/// once (their bits, in the order of their surfaces, as
/// `surface::SlidingSet` lists them), from each base region without
/// their bits.
fn slides(regions: usize, kinds: &[Surface]) -> Vec<(usize, Vec<usize>)> {
    let bits: Vec<usize> = kinds
        .iter()
        .filter_map(|k| match *k {
            Surface::Switch { bit } => Some(bit as usize),
            _ => None,
        })
        .collect();
    let sets = bits.iter().map(|&b| vec![b]).chain(
        (0..bits.len())
            .flat_map(|p| (p + 1..bits.len()).map(move |q| (p, q)))
            .map(|(p, q)| vec![bits[p], bits[q]]),
    );
    sets.flat_map(|set| {
        (0..regions)
            .filter(|base| set.iter().all(|b| base >> b & 1 == 0))
            .map(|base| (base, set.clone()))
            .collect::<Vec<_>>()
    })
    .collect()
}

/// The C name of a slide's step.
fn slide_name(base: usize, bits: &[usize]) -> String {
    let bits: Vec<String> = bits.iter().map(|b| b.to_string()).collect();
    format!("slide{base}_{}", bits.join("_"))
}

/// The value Rust's `f64` sum starts from (-0.0 in recent releases, 0.0
/// before), which a sum of terms that are all -0.0 shows.
fn sum_start() -> f64 {
    std::iter::once(-0.0_f64).sum()
}

/// The cached shared object built from `source` for this machine, loaded.
fn compiled(source: &str) -> Result<libloading::Library, String> {
    let cc = std::env::var("CC").unwrap_or_else(|_| "cc".into());
    compiled_in(&cache_dir()?, &cc, cpu_target(&cc), source)
}

/// The name of the object built by `cc` for the processor `cpu` from
/// `source`: the hash of all three and the flags. `-march=native` makes
/// the code the host's, so a cache shared by machines of different
/// processors (a cluster's nodes with one home directory) keeps one
/// object for each, and none loads another's instructions.
fn object_key(cc: &str, cpu: &str, source: &str) -> String {
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
fn digest(bytes: &[u8]) -> String {
    use sha2::{Digest, Sha256};
    hex(&Sha256::digest(bytes))
}

/// [`compiled`] in the directory `dir`, by the compiler `cc`, for the
/// processor `cpu` (the key's part that [`cpu_target`] gives). Each
/// object is kept with the SHA-256 of its bytes (`.sha256` beside it): an
/// object that does not match it (cut short, overwritten) is built again,
/// never loaded. Both are written under names of this thread's, then
/// renamed: runs and threads at the same time never load a half-written
/// object.
fn compiled_in(
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
    if !intact() {
        static BUILDS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
        let build = BUILDS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let unique = |ext: &str| -> PathBuf {
            dir.join(format!("{key}.{}-{build}.{ext}", std::process::id()))
        };
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
                .and_then(|()| std::fs::rename(&so, &object))
                .and_then(|()| std::fs::rename(&so_sum, &sum))
                .map_err(|e| format!("{}: {e}", object.display()))
        } else {
            Err(format!(
                "{cc} failed: {}",
                String::from_utf8_lossy(&output.stderr)
            ))
        };
        if written.is_err() {
            let _ = std::fs::remove_file(&so);
            let _ = std::fs::remove_file(&so_sum);
        }
        written?;
    }
    // SAFETY: the object is ours (built above or earlier from the same
    // source for this processor, named by its hash, its bytes checked
    // against the digest written with it) and has no initialisers.
    unsafe { libloading::Library::new(&object) }.map_err(|e| format!("{}: {e}", object.display()))
}

/// The processor `cc` builds for under `-march=native`, once per process:
/// the target options its driver resolves `-march=native` to (GCC's
/// `-march=`, `-mtune=` and every `-m` feature flag; clang's
/// `-target-cpu` and `-target-feature`s, in `cc -###`'s commands), else
/// the processor the system describes (`/proc/cpuinfo`'s model and
/// features), else only the architecture.
fn cpu_target(cc: &str) -> &'static str {
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

/// Off Unix, no directory is known to be the user's alone: the loops are
/// cranelift's.
#[cfg(not(unix))]
fn cache_dir() -> Result<PathBuf, String> {
    Err("the C compiler's loops are built on Unix only".into())
}

/// Appends `walk{w}{layout:?}`: `jit::walk`'s loop (the phase turned, the
/// RK4 step, the stops detected) over `w` slots, a loop over the slots per
/// step for the compiler to vectorise. Where the regions have surfaces it
/// is a [`SwitchWalk`]: each slot steps its own region's field (every
/// region present computed over the batch, each slot keeping its own's,
/// as `ModelFlow::step_each_in` does), the surfaces' values and rates are
/// taken at each step's end as `Flow::surface_values` takes them, and a
/// step that may cross a surface (`surface::may_cross`) stops the loop.
fn walk(
    out: &mut String,
    regions: &[Region],
    calls: &[Func],
    stops: &[StopCode],
    kinds: &[Surface],
    w: usize,
    layout: Layout,
) {
    let d = regions[0].field.states;
    let each = layout == Layout::Each;
    let switching = regions[0].surfaces.is_some();
    let rows = 2 * kinds.len();
    // A value per slot (`Each`) or one for all (`Shared`), at row `r`.
    let row = |base: &str, r: usize| {
        if each {
            format!("{base}[{} + k]", r * w)
        } else {
            format!("{base}[{r}]")
        }
    };
    let (lanes, extra) = if switching {
        (
            "const double *const *restrict lanes",
            ", const int64_t *restrict region, double *restrict values",
        )
    } else {
        ("const double *restrict lane", "")
    };
    let _ = writeln!(
        out,
        "uint64_t walk{w}{layout:?}(double *restrict y, double *restrict clock, \
         {lanes}, const double *restrict h, \
         const double *restrict walls, const int64_t *restrict live, uint64_t steps{extra}) {{"
    );
    for i in 0..d {
        let _ = writeln!(out, "  double y{i}[{w}];");
        let _ = writeln!(
            out,
            "  for (int k = 0; k < {w}; k++) y{i}[k] = y[{} + k];",
            i * w
        );
    }
    if switching {
        // Each region's constants: its field's (`lf`) and its surfaces'
        // (`ls`); the regions present (fixed while the loop runs: a slot
        // changes region only at a crossing, which stops it); each
        // surface's orientation in each slot's region
        // (`Surface::orientation`); the surfaces' values and rates at the
        // step's start (`sb`) and end (`sa`), and the step's end (`z`).
        for r in 0..regions.len() {
            let _ = writeln!(
                out,
                "  const double *restrict lf{r} = lanes[{}], *restrict ls{r} = lanes[{}];",
                2 * r,
                2 * r + 1
            );
        }
        let _ = writeln!(
            out,
            "  int64_t present = 0;\n  for (int k = 0; k < {w}; k++) present |= (int64_t)1 << region[k];"
        );
        for (j, kind) in kinds.iter().enumerate() {
            let o = match kind {
                Surface::Switch { bit } => format!("((region[k] >> {bit}) & 1) ? -1.0 : 1.0"),
                Surface::Event => "1.0".into(),
            };
            let _ = writeln!(
                out,
                "  double so{j}[{w}];\n  for (int k = 0; k < {w}; k++) so{j}[k] = {o};"
            );
        }
        for m in 0..rows {
            let _ = writeln!(
                out,
                "  double sb{m}[{w}], sa{m}[{w}] = {{0}};\n  \
                 for (int k = 0; k < {w}; k++) sb{m}[k] = values[{} + k];",
                m * w
            );
        }
        for i in 0..d {
            let _ = writeln!(out, "  double z{i}[{w}] = {{0}};");
        }
    }
    out.push_str(
        "  double c = clock[0], s = clock[1];\n  const double hc = clock[2], hs = clock[3];\n  uint64_t n = 0;\n  for (; n < steps; n++) {\n",
    );
    // `clock::rotate`, as `jit::walk` turns it.
    for (from, to) in [(("c", "s"), ("mc", "ms")), (("mc", "ms"), ("ec", "es"))] {
        let ((c, s), (c1, s1)) = (from, to);
        let _ = writeln!(
            out,
            "    double {c1}_ = {c} * hc - {s} * hs, {s1}_ = {s} * hc + {c} * hs;\n    \
             double {c1}n = 1.5 - 0.5 * ({c1}_ * {c1}_ + {s1}_ * {s1}_);\n    \
             double {c1} = {c1}_ * {c1}n, {s1} = {s1}_ * {c1}n;"
        );
    }
    let step_sizes = |out: &mut String, indent: &str| {
        let _ = writeln!(
            out,
            "{indent}const double hh = {}, h2 = 0.5 * hh, sixth = hh / 6.0;",
            row("h", 0)
        );
    };
    let state: Vec<String> = (0..d).map(|i| format!("y{i}[k]")).collect();
    if !switching {
        for i in 0..d {
            let _ = writeln!(out, "    double z{i}[{w}];");
        }
        let _ = writeln!(
            out,
            "    int64_t hit = 0;\n    for (int k = 0; k < {w}; k++) {{"
        );
        step_sizes(out, "      ");
        let lane = |_: &str, j: usize| row("lane", j);
        let end = rk4(out, regions[0].field, calls, "", &state, &lane);
        for (i, end) in end.iter().enumerate() {
            let _ = writeln!(out, "      z{i}[k] = {end};");
        }
    } else {
        // Every region present steps the whole batch; each slot keeps its
        // own region's step, then its surfaces' values at the step's end.
        let several = regions.len() > 1;
        let guard = |r: usize| {
            if several {
                format!("if (present >> {r} & 1) ")
            } else {
                String::new()
            }
        };
        let keep = |r: usize, value: &str, into: &str| {
            if several {
                format!("{into} = region[k] == {r} ? {value} : {into};")
            } else {
                format!("{into} = {value};")
            }
        };
        for (r, region) in regions.iter().enumerate() {
            let _ = writeln!(out, "    {}for (int k = 0; k < {w}; k++) {{", guard(r));
            step_sizes(out, "      ");
            let lane = |_: &str, j: usize| row(&format!("lf{r}"), j);
            let end = rk4(out, region.field, calls, &format!("r{r}"), &state, &lane);
            for (i, end) in end.iter().enumerate() {
                let _ = writeln!(out, "      {}", keep(r, end, &format!("z{i}[k]")));
            }
            out.push_str("    }\n");
        }
        let at_end: Vec<String> = (0..d).map(|i| format!("z{i}[k]")).collect();
        for (r, region) in regions.iter().enumerate() {
            let tape = region.surfaces.expect("regions with surfaces");
            let _ = writeln!(out, "    {}for (int k = 0; k < {w}; k++) {{", guard(r));
            let lane = |_: &str, j: usize| row(&format!("ls{r}"), j);
            let values = rhs(
                out,
                tape,
                calls,
                &format!("q{r}_"),
                &at_end,
                ("ec", "es"),
                &lane,
            );
            for (m, value) in values.iter().enumerate() {
                let _ = writeln!(out, "      {}", keep(r, value, &format!("sa{m}[k]")));
            }
            out.push_str("    }\n");
        }
        let _ = writeln!(
            out,
            "    int64_t hit = 0;\n    for (int k = 0; k < {w}; k++) {{"
        );
    }
    // As `jit::walk` (and `integrate::steps`), in two passes: the plain
    // test in the loop over the slots (at rest on the stop, beyond it
    // after the step, or turning back inside it), and where that fires
    // (a few steps in a hundred), the turns again, only those within reach
    // of the stop (`impact::may_turn_past`). Its arithmetic in every
    // step cost the seed's oscillator a fifth of the loop. A surface's
    // test (`surface::may_cross`) is the same: the plain one first.
    let crossing = |j: usize| {
        let (g, rate) = (2 * j, 2 * j + 1);
        format!(
            "(((so{j}[k] * sa{g}[k]) > 0.0) | (((so{j}[k] * sb{rate}[k]) > 0.0) \
             & ((so{j}[k] * sa{rate}[k]) < 0.0)))"
        )
    };
    for (j, stop) in stops.iter().enumerate() {
        let (ci, vi) = (stop.coordinate, stop.velocity);
        let (out_of, into) = if stop.side > 0.0 {
            (">", "<")
        } else {
            ("<", ">")
        };
        let _ = writeln!(
            out,
            "      {{ const double p = {p};\n        \
             hit |= (((y{ci}[k] == p) & (y{vi}[k] == 0.0)) | ((z{ci}[k] - p) {out_of} 0.0) \
             | ((y{vi}[k] {out_of} 0.0) & (z{vi}[k] {into} 0.0))) & live[k]; }}",
            p = row("walls", j)
        );
    }
    for j in 0..kinds.len() {
        let _ = writeln!(out, "      hit |= {} & live[k];", crossing(j));
    }
    // The second pass: the gaps and speeds side·(x - p) and side·v are
    // exact for a side of ±1.
    let _ = writeln!(
        out,
        "    }}\n    if (hit) {{\n      int64_t near = 0;\n      \
         for (int k = 0; k < {w}; k++) {{\n        const double hh = {};",
        row("h", 0)
    );
    for (j, stop) in stops.iter().enumerate() {
        let (ci, vi) = (stop.coordinate, stop.velocity);
        let _ = writeln!(
            out,
            "        {{ const double p = {p}, side = {side};\n          \
             const double g0 = side * (y{ci}[k] - p), s0 = side * y{vi}[k];\n          \
             const double g1 = side * (z{ci}[k] - p), s1 = side * z{vi}[k];\n          \
             near |= (((y{ci}[k] == p) & (y{vi}[k] == 0.0)) | {crosses}) & live[k]; }}",
            p = row("walls", j),
            side = literal(stop.side),
            crosses = reaches_across(),
        );
    }
    // A surface's turn counts, as a stop's, only within reach of it
    // (`surface::may_cross`, the same operations).
    for j in 0..kinds.len() {
        let (g, rate) = (2 * j, 2 * j + 1);
        let _ = writeln!(
            out,
            "        {{ const double o = so{j}[k];\n          \
             const double g0 = o * sb{g}[k], s0 = o * sb{rate}[k];\n          \
             const double g1 = o * sa{g}[k], s1 = o * sa{rate}[k];\n          \
             near |= {crosses} & live[k]; }}",
            crosses = reaches_across(),
        );
    }
    out.push_str("      }\n      if (near) break;\n    }\n");
    for i in 0..d {
        let _ = writeln!(out, "    for (int k = 0; k < {w}; k++) y{i}[k] = z{i}[k];");
    }
    for m in 0..rows {
        let _ = writeln!(
            out,
            "    for (int k = 0; k < {w}; k++) sb{m}[k] = sa{m}[k];"
        );
    }
    out.push_str("    c = ec;\n    s = es;\n  }\n");
    for i in 0..d {
        let _ = writeln!(
            out,
            "  for (int k = 0; k < {w}; k++) y[{} + k] = y{i}[k];",
            i * w
        );
    }
    for m in 0..rows {
        let _ = writeln!(
            out,
            "  for (int k = 0; k < {w}; k++) values[{} + k] = sb{m}[k];",
            m * w
        );
    }
    out.push_str("  clock[0] = c;\n  clock[1] = s;\n  return n;\n}\n");
}

/// Whether a step whose oriented distance and rate go from `g0`, `s0` to
/// `g1`, `s1` (C values in scope, as `hh`) ends across, or turns back
/// within reach (`impact::may_turn_past`): the same operations, a C
/// expression of 0 or 1.
fn reaches_across() -> String {
    format!(
        "((g1 > 0.0) | ((s0 > 0.0) & (s1 < 0.0) \
         & !((g0 + {reach} * hh * (s0 - s1) < 0.0) & (g1 + {reach} * hh * (s0 - s1) < 0.0))))",
        reach = literal(TURN_REACH)
    )
}

/// `rk4::step_batch`'s step of the slot whose states are `state`, with
/// the field `tape` (its constants from `row`, its values named after
/// `prefix`), inside a loop over the slots that has set `hh`, `h2` and
/// `sixth`; gives each state's value after the step as a C expression.
fn rk4(
    out: &mut String,
    tape: &Tape,
    calls: &[Func],
    prefix: &str,
    state: &[String],
    row: &dyn Fn(&str, usize) -> String,
) -> Vec<String> {
    rk4_of(out, prefix, state, &mut |out, prefix, state, clock| {
        rhs(out, tape, calls, prefix, state, clock, row)
    })
}

/// A field's values at a state and clock, written as C values named after
/// a prefix (`rhs`, or the sliding field of `slide_step`).
type FieldCode<'a> = dyn FnMut(&mut String, &str, &[String], (&str, &str)) -> Vec<String> + 'a;

/// [`rk4`] with the field given as code.
fn rk4_of(out: &mut String, prefix: &str, state: &[String], field: &mut FieldCode) -> Vec<String> {
    let name = |p: &str| format!("{prefix}{p}");
    let k1 = field(out, &name("a"), state, ("c", "s"));
    let y2 = axpy(out, &name("b"), state, "h2", &k1);
    let k2 = field(out, &name("c"), &y2, ("mc", "ms"));
    let y3 = axpy(out, &name("d"), state, "h2", &k2);
    let k3 = field(out, &name("e"), &y3, ("mc", "ms"));
    let y4 = axpy(out, &name("f"), state, "hh", &k3);
    let k4 = field(out, &name("g"), &y4, ("ec", "es"));
    // y + h/6·(k1 + 2(k2 + k3) + k4)
    (0..state.len())
        .map(|i| {
            format!(
                "{y} + sixth * ((({k1} + 2.0 * ({k2} + {k3}))) + {k4})",
                y = state[i],
                k1 = k1[i],
                k2 = k2[i],
                k3 = k3[i],
                k4 = k4[i],
            )
        })
        .collect()
}

/// One RK4 step of one trajectory sliding on the switches `bits` at
/// once (one or two), from the region `base` (their bits clear), whose
/// field is F₀, F_m the field with bit m set: `rk4::step_at` of
/// `surface::Sliding`, whose field is `surface::equivalent_on`'s,
/// operation for operation. One switch: a = ∇g·F₀ and b = ∇g·F₁ (summed
/// as Rust's `sum` does, from `zero`), α = a/(a - b), F₀ + α(F₁ - F₀).
/// Two: `surface::solve`'s elimination with partial pivoting of
/// (a_j - c_jk) u = a (a_j = ∇g_j·F₀, c_jk = ∇g_j·F_k), then F₀ +
/// u₀(F₁ - F₀) + u₁(F₂ - F₀). NaN where the control is singular or not
/// finite. `lc{m}` points to the constants of F_m, `g{m}` to switch m's
/// constant gradient (the last ones unused with one switch); the clock
/// holds the three stages' phases.
fn slide_step(out: &mut String, calls: &[Func], name: &str, tapes: &[&Tape], zero: f64) {
    let d = tapes[0].states;
    let n = tapes.len() - 1;
    assert!((1..=2).contains(&n));
    let _ = writeln!(
        out,
        "void {name}(const double *restrict y, const double *restrict clock, double hh, \
         const double *restrict lc0, const double *restrict lc1, const double *restrict lc2, \
         const double *restrict g0, const double *restrict g1, double *restrict out) {{\n  \
         const double c = clock[0], s = clock[1], mc = clock[2], ms = clock[3], \
         ec = clock[4], es = clock[5];\n  \
         const double h2 = 0.5 * hh, sixth = hh / 6.0;"
    );
    let state: Vec<String> = (0..d).map(|i| format!("y[{i}]")).collect();
    let dot = |m: usize, f: &[String]| {
        (0..d).fold(literal(zero), |sum, i| {
            format!("({sum} + g{m}[{i}] * {})", f[i])
        })
    };
    let end = rk4_of(out, "", &state, &mut |out, prefix, state, clock| {
        let f: Vec<Vec<String>> = (0..=n)
            .map(|m| {
                let row = move |_: &str, j: usize| format!("lc{m}[{j}]");
                rhs(
                    out,
                    tapes[m],
                    calls,
                    &format!("{prefix}f{m}_"),
                    state,
                    clock,
                    &row,
                )
            })
            .collect();
        let v = |x: &str| format!("{prefix}{x}");
        // C statements with this stage's names: `$x` is `{prefix}x`.
        let mut line = |text: &str| {
            let _ = writeln!(out, "      {}", text.replace('$', prefix));
        };
        if n == 1 {
            line(&format!("const double $p = {};", dot(0, &f[0])));
            line(&format!("const double $q = {};", dot(0, &f[1])));
            line("const double $u0 = $p / ($p - $q);");
            line("const int $ok = __builtin_isfinite($u0);");
        } else {
            // a_j, and the matrix M = a_j - c_jk, as equivalent_on.
            for j in 0..2 {
                line(&format!("const double $a{j} = {};", dot(j, &f[0])));
                for k in 0..2 {
                    line(&format!(
                        "const double $m{j}{k} = $a{j} - {};",
                        dot(j, &f[k + 1])
                    ));
                }
            }
            // The pivot of column 0: the row with the larger |M_j0| in
            // `total_cmp`'s order (NaN above all), the second on a tie
            // (`max_by` keeps the last maximum); after the swap the
            // pivot's row is [p0 p1 | pr], the other's [q0 q1 | qr].
            line("const double $x0 = __builtin_fabs($m00), $x1 = __builtin_fabs($m10);");
            line("const int $sw = __builtin_isnan($x1) || (!__builtin_isnan($x0) && $x1 >= $x0);");
            line("const double $p0 = $sw ? $m10 : $m00, $p1 = $sw ? $m11 : $m01, $pr = $sw ? $a1 : $a0;");
            line("const double $q0 = $sw ? $m00 : $m10, $q1 = $sw ? $m01 : $m11, $qr = $sw ? $a0 : $a1;");
            // Elimination, then back-substitution, in solve's order.
            line("const double $k = $q0 / $p0;");
            line("const double $e1 = $q1 - $k * $p1, $er = $qr - $k * $pr;");
            line("const double $u1 = $er / $e1;");
            line("const double $u0 = ($pr - $p1 * $u1) / $p0;");
            line(
                "const int $ok = $p0 != 0.0 && $e1 != 0.0 \
                 && __builtin_isfinite($u0) && __builtin_isfinite($u1);",
            );
        }
        (0..d)
            .map(|i| {
                let name = v(&format!("v{i}"));
                let mut field = f[0][i].clone();
                for m in 0..n {
                    field = format!(
                        "({field} + {u} * ({} - {}))",
                        f[m + 1][i],
                        f[0][i],
                        u = v(&format!("u{m}"))
                    );
                }
                line(&format!(
                    "const double $v{i} = $ok ? {field} : {};",
                    literal(f64::NAN)
                ));
                name
            })
            .collect()
    });
    for (i, v) in end.iter().enumerate() {
        let _ = writeln!(out, "  out[{i}] = {v};");
    }
    let _ = writeln!(out, "}}");
}

/// y + a·k, named `{prefix}{i}`.
fn axpy(out: &mut String, prefix: &str, y: &[String], a: &str, k: &[String]) -> Vec<String> {
    (0..y.len())
        .map(|i| {
            let name = format!("{prefix}{i}");
            let _ = writeln!(
                out,
                "      const double {name} = {} + {a} * {};",
                y[i], k[i]
            );
            name
        })
        .collect()
}

/// The tape at `state` and clock `(cos, sin)` (`Tape::run`'s register
/// file as C values named `{prefix}{slot}`); gives its outputs.
fn rhs(
    out: &mut String,
    tape: &Tape,
    calls: &[Func],
    prefix: &str,
    state: &[String],
    (cos, sin): (&str, &str),
    row: &dyn Fn(&str, usize) -> String,
) -> Vec<String> {
    let (lowered, numbers, outputs) = tape.lowered();
    let mut slots: Vec<String> = state.to_vec();
    slots.extend([cos.to_string(), sin.to_string()]);
    slots.extend((0..tape.lane_constants.len()).map(|j| row("lane", j)));
    slots.extend(numbers.iter().map(|&v| literal(v)));
    for ins in lowered {
        let (a, b, c) = (
            &slots[ins.a as usize],
            &slots[ins.b as usize],
            &slots[ins.c as usize],
        );
        let value = match ins.code {
            Code::Neg => format!("-{a}"),
            Code::Add => format!("{a} + {b}"),
            Code::Sub => format!("{a} - {b}"),
            Code::Mul => format!("{a} * {b}"),
            Code::Div => format!("{a} / {b}"),
            Code::MulAdd => format!("{a} * {b} + {c}"),
            Code::MulSub => format!("{a} * {b} - {c}"),
            Code::SubMul => format!("{c} - {a} * {b}"),
            Code::Call(Func::Sqrt) => format!("__builtin_sqrt({a})"),
            Code::Call(Func::Abs) => format!("__builtin_fabs({a})"),
            // The same Rust functions as the cranelift code calls.
            Code::Call(f) => {
                let i = calls.iter().position(|&g| g == f).expect("listed");
                format!("calls[{i}]({a}, {b})")
            }
        };
        let name = format!("{prefix}{}", slots.len());
        let _ = writeln!(out, "      const double {name} = {value};");
        slots.push(name);
    }
    outputs.iter().map(|&s| slots[s as usize].clone()).collect()
}

/// `v` as a C expression of the same bits: Rust's shortest round-trip
/// digits, which C reads back correctly rounded.
fn literal(v: f64) -> String {
    if v.is_nan() {
        "__builtin_nan(\"\")".into()
    } else if v.is_infinite() {
        format!("({}__builtin_inf())", if v < 0.0 { "-" } else { "" })
    } else {
        format!("({v:?})")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::expr::{Expr, Names};
    use crate::model::jit::{Loops, Native};

    /// A field with every kind of instruction: fused products, a division,
    /// numbers, the exact functions and a call back into Rust.
    fn tape() -> Tape {
        let names = Names {
            states: vec!["x".into(), "v".into()],
            parameters: vec!["zeta".into(), "f".into(), "eta".into()],
            switches: Vec::new(),
        };
        let parse = |t: &str| Expr::parse(t, &names).unwrap();
        let exprs = [
            parse("v"),
            parse("-2*zeta*v - x + f*cos(eta*t) - 0.1*sin(3*x) + sqrt(abs(v))/(3 + x*x)"),
        ];
        Tape::compile(&exprs, 2, Some(parse("eta"))).unwrap()
    }

    /// Both compilers' loops for W slots in `layout` from the same states,
    /// with a stop at `wall` on `side`: the steps taken, the states and the
    /// phase, to the bit, runs that stop at the wall and runs that do not.
    fn same_walks<const W: usize>(
        c: &Native,
        cranelift: &Native,
        layout: Layout,
        stop: (f64, f64),
    ) {
        let tape = tape();
        let (wall, side) = stop;
        let each = layout == Layout::Each;
        let etas: Vec<f64> = (0..W)
            .map(|k| 0.8 + if each { 0.01 * k as f64 } else { 0.0 })
            .collect();
        let per_slot = if each { W } else { 1 };
        let constants: Vec<Vec<f64>> = etas
            .iter()
            .map(|&eta| tape.lane_values(&[0.05, 2.5, eta]).constants)
            .collect();
        let lane: Vec<f64> = (0..constants[0].len())
            .flat_map(|j| constants[..per_slot].iter().map(move |c| c[j]))
            .collect();
        let h: Vec<f64> = etas[..per_slot]
            .iter()
            .map(|eta| std::f64::consts::TAU / eta / 200.0)
            .collect();
        let walls = vec![wall; per_slot];
        let half = crate::integrate::clock::cos_sin(std::f64::consts::PI / 200.0);
        let start: [[f64; W]; 2] = [
            std::array::from_fn(|k| 0.05 * k as f64 - 0.1),
            std::array::from_fn(|k| 0.02 * k as f64),
        ];
        let bits = |y: &[[f64; W]; 2], clock: &[f64; 4]| {
            let mut b: Vec<u64> = y.as_flattened().iter().map(|v| v.to_bits()).collect();
            b.extend(clock.iter().map(|v| v.to_bits()));
            b
        };
        let mut stopped = 0;
        for (live, steps) in [(0u32, 3000), ((1 << W) - 1, 3000), (0b10, 3000)] {
            let run = |native: &Native| {
                let (mut y, mut clock) = (start, [0.3f64.cos(), 0.3f64.sin(), half[0], half[1]]);
                let mut taken = Vec::new();
                // Walk on from each stop, one step at a time past it.
                let mut left = steps;
                while left > 0 {
                    let n = native
                        .walk(layout, &mut y, &mut clock, &lane, &h, &walls, live, left)
                        .expect("a loop for W");
                    taken.push(n);
                    left -= n;
                    if left > 0 {
                        let n = native
                            .walk(layout, &mut y, &mut clock, &lane, &h, &walls, 0, 1)
                            .expect("a loop for W");
                        left -= n;
                    }
                }
                (taken, bits(&y, &clock))
            };
            let (c_taken, c_bits) = run(c);
            let (cranelift_taken, cranelift_bits) = run(cranelift);
            assert_eq!(
                c_taken, cranelift_taken,
                "W = {W}, {layout:?}, side {side}, live {live:b}"
            );
            assert_eq!(
                c_bits, cranelift_bits,
                "W = {W}, {layout:?}, side {side}, live {live:b}"
            );
            stopped += c_taken.len() - 1;
        }
        assert!(stopped > 10, "the stop was met {stopped} times");
    }

    #[test]
    #[cfg(unix)]
    fn the_c_compiler_s_step_loops_are_cranelift_s_to_the_bit() {
        let tape = tape();
        // Stops met early and often, and one (at 4) far above the first
        // turns of the oscillation, which grows past it later.
        for (wall, side) in [(0.9, 1.0), (-0.7, -1.0), (4.0, 1.0)] {
            let stops = [StopCode {
                coordinate: 0,
                velocity: 1,
                side,
            }];
            let c = Native::compile_stepping_by(&tape, Some(&stops), Loops::CCompiler).unwrap();
            // Not a skip where there is no C compiler: the test then fails
            // and says why.
            assert_eq!(
                c.loops(),
                Some(Loops::CCompiler),
                "{:?}",
                c.c_compiler_failure()
            );
            let cranelift =
                Native::compile_stepping_by(&tape, Some(&stops), Loops::Cranelift).unwrap();
            assert_eq!(cranelift.loops(), Some(Loops::Cranelift));
            for layout in [Layout::Shared, Layout::Each] {
                same_walks::<4>(&c, &cranelift, layout, (wall, side));
                same_walks::<8>(&c, &cranelift, layout, (wall, side));
                same_walks::<16>(&c, &cranelift, layout, (wall, side));
            }
        }
    }

    /// The objects are kept by processor: two identities, two objects; and
    /// an object cut short or overwritten in the cache is built again,
    /// not loaded, and runs as before, to the bit.
    #[test]
    #[cfg(unix)]
    fn objects_are_kept_by_processor_and_a_damaged_one_is_built_again() {
        let dir = tempfile::tempdir().unwrap();
        let tape = tape();
        let stops = [StopCode {
            coordinate: 0,
            velocity: 1,
            side: 1.0,
        }];
        let regions = [Region {
            field: &tape,
            surfaces: None,
        }];
        let (source, calls) = source_of(&regions, &stops, &[]);
        let cc = std::env::var("CC").unwrap_or_else(|_| "cc".into());
        let objects = || -> Vec<PathBuf> {
            let mut found: Vec<PathBuf> = std::fs::read_dir(dir.path())
                .unwrap()
                .map(|e| e.unwrap().path())
                .filter(|p| p.extension().is_some_and(|e| e == "so"))
                .collect();
            found.sort();
            found
        };
        // 300 steps of the loop for 8 slots (shared layout), the library
        // then dropped (unmapped) before its file is touched.
        let run = |library: libloading::Library| -> Vec<u64> {
            let (library, walks) = loaded::<Walk>(library, &calls).unwrap();
            let constants = tape.lane_values(&[0.05, 2.5, 0.8]).constants;
            let h = [std::f64::consts::TAU / 0.8 / 200.0];
            let half = crate::integrate::clock::cos_sin(std::f64::consts::PI / 200.0);
            let mut y: [[f64; 8]; 2] = [std::array::from_fn(|k| 0.05 * k as f64), [0.0; 8]];
            let mut clock = [1.0, 0.0, half[0], half[1]];
            let live = [0i64; 8];
            // SAFETY: the loop for 8 slots, shared layout, of this tape's
            // two states and one stop, reads and writes what it was
            // compiled for.
            let n = unsafe {
                walks[1][Layout::Shared as usize](
                    y.as_mut_ptr().cast(),
                    clock.as_mut_ptr(),
                    constants.as_ptr(),
                    h.as_ptr(),
                    [0.9].as_ptr(),
                    live.as_ptr(),
                    300,
                )
            };
            drop(library);
            let mut bits: Vec<u64> = y.as_flattened().iter().map(|v| v.to_bits()).collect();
            bits.extend(clock.iter().map(|v| v.to_bits()));
            bits.push(n);
            bits
        };
        let a = run(compiled_in(dir.path(), &cc, "processor a", &source).unwrap());
        assert_eq!(objects().len(), 1);
        let b = run(compiled_in(dir.path(), &cc, "processor b", &source).unwrap());
        assert_eq!(objects().len(), 2, "one object per processor");
        assert_eq!(a, b);
        let object = dir
            .path()
            .join(format!("{}.so", object_key(&cc, "processor a", &source)));
        let good = std::fs::read(&object).unwrap();
        let cut: Vec<u8> = good[..good.len() / 2].to_vec();
        let garbage: Vec<u8> = (0..good.len()).map(|i| (i * 7 + 3) as u8).collect();
        for damaged in [cut, garbage, Vec::new()] {
            std::fs::write(&object, &damaged).unwrap();
            let library = compiled_in(dir.path(), &cc, "processor a", &source).unwrap();
            let rebuilt = std::fs::read(&object).unwrap();
            assert_ne!(rebuilt, damaged, "the damaged object was replaced");
            assert_eq!(rebuilt.len(), good.len());
            assert_eq!(run(library), a);
        }
        assert_eq!(objects().len(), 2);
        // And the processor resolved for this machine names one.
        let target = cpu_target(&cc);
        assert!(!target.is_empty() && !target.contains("native"), "{target}");
    }

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

    /// Two switches (four regions), a stop and an event on a surface that
    /// moves with the clock.
    const SWITCHING: &str = r#"
name = "switching"
states = ["x", "v"]
[parameters]
zeta = 0.05
f = 2.5
eta = 0.8
ks = 4.0
mu = 0.1
[[switches]]
name = "contact"
surface = "x - 0.5"
[[switches]]
name = "moving"
surface = "v - 0.3"
[equations]
x = "v"
v = "-2*zeta*v - x - ks*(x - 0.5)*step(contact) - mu*sign(moving) + f*cos(eta*t)"
[map]
period = "2*pi/eta"
[[events]]
name = "stop"
surface = "x - 1.5"
reset = { v = "-0.8*v" }
[[events]]
name = "floor"
surface = "-1.2 - x + 0.1*cos(eta*t)"
reset = { v = "-0.9*v" }
"#;

    /// The regions' loop for W slots in `layout`, slot k in its own
    /// region, against each slot stepped alone by its region's native
    /// step (cranelift's: `ModelFlow::step_each_in`'s) with its surfaces'
    /// values at each step's end and the integrator's detection (at rest
    /// on or reaching a stop, `impact::reaches_wall`; crossing a surface,
    /// `surface::may_cross`): the steps taken, the states, the phase and
    /// the surfaces' values where it stopped, to the bit; walked on from
    /// each stop one plain step at a time, as the integrator does.
    fn same_as_stepped<const W: usize>(code: &crate::model::code::Code, layout: Layout) {
        use crate::integrate::{impact, rk4, surface};
        use crate::model::jit::Kind;
        let loops = code
            .switch_loops
            .as_ref()
            .expect("a period map with surfaces")
            .as_ref()
            .expect("built by the C compiler");
        let each = layout == Layout::Each;
        let per_slot = if each { W } else { 1 };
        let defaults = &code.model.defaults;
        let params: Vec<Vec<f64>> = (0..per_slot)
            .map(|k| {
                let mut p = defaults.clone();
                p[2] = 0.8 + 0.01 * k as f64;
                p
            })
            .collect();
        let walls = crate::model::code::walls_at(code, &params[0]);
        let regions = code.regions.len();
        // Each region's constants, per slot of the layout; then side by
        // side (row j: constant j of every slot) for `Each`.
        let constants = |r: usize, surfaces: bool| -> Vec<Vec<f64>> {
            let field = &code.regions[r];
            let tape = if surfaces {
                &field.surfaces
            } else {
                &field.equations
            };
            params
                .iter()
                .map(|p| tape.lane_values(p).constants)
                .collect()
        };
        let laid_out = |c: &[Vec<f64>]| -> Vec<f64> {
            (0..c[0].len())
                .flat_map(|j| c.iter().map(move |slot| slot[j]))
                .collect()
        };
        let field_constants: Vec<Vec<Vec<f64>>> =
            (0..regions).map(|r| constants(r, false)).collect();
        let surface_constants: Vec<Vec<Vec<f64>>> =
            (0..regions).map(|r| constants(r, true)).collect();
        let laid: Vec<[Vec<f64>; 2]> = (0..regions)
            .map(|r| {
                [
                    laid_out(&field_constants[r]),
                    laid_out(&surface_constants[r]),
                ]
            })
            .collect();
        let lanes: Vec<[*const f64; 2]> =
            laid.iter().map(|[a, b]| [a.as_ptr(), b.as_ptr()]).collect();
        let h: Vec<f64> = (0..per_slot)
            .map(|k| std::f64::consts::TAU / params[k][2] / 200.0)
            .collect();
        let positions: Vec<f64> = walls
            .iter()
            .flat_map(|w| std::iter::repeat_n(w.position, per_slot))
            .collect();
        let half = crate::integrate::clock::cos_sin(std::f64::consts::PI / 200.0);
        let slot = |k: usize| if each { k } else { 0 };
        // One slot's step and its surfaces' values at the end, alone.
        let step = |r: usize, k: usize, phase: &[f64; 2], y: &[f64; 2]| {
            let field = &code.regions[r];
            let stages = rk4::stage_phases(phase, &half);
            let y: [[f64; 1]; 2] = [[y[0]], [y[1]]];
            let z: [[f64; 1]; 2] = field.native.as_ref().unwrap().call(
                Kind::Step,
                Layout::Shared,
                &y,
                stages.as_flattened(),
                &field_constants[r][slot(k)],
                &[h[slot(k)]],
            );
            let values: [[f64; 1]; 8] = field.surfaces_native.as_ref().unwrap().call(
                Kind::Rhs,
                Layout::Shared,
                &z,
                &stages[2],
                &surface_constants[r][slot(k)],
                &[],
            );
            ([z[0][0], z[1][0]], values.map(|v| v[0]), stages[2])
        };
        let values_at = |r: usize, k: usize, phase: &[f64; 2], y: &[f64; 2]| -> [f64; 8] {
            let field = &code.regions[r];
            let y: [[f64; 1]; 2] = [[y[0]], [y[1]]];
            let values: [[f64; 1]; 8] = field.surfaces_native.as_ref().unwrap().call(
                Kind::Rhs,
                Layout::Shared,
                &y,
                phase,
                &surface_constants[r][slot(k)],
                &[],
            );
            values.map(|v| v[0])
        };
        let mut stopped = 0;
        for region_of in [
            |_: usize| 0u32,
            |k: usize| (k % 4) as u32,
            |k: usize| 3 - (k % 3) as u32,
        ] {
            let region: [u32; W] = std::array::from_fn(region_of);
            for live in [(1u32 << W) - 1, 0b1010] {
                let start: [[f64; W]; 2] = [
                    std::array::from_fn(|k| 0.05 * k as f64 - 0.3),
                    std::array::from_fn(|k| 0.02 * k as f64 - 0.1),
                ];
                let phase0 = [0.3f64.cos(), 0.3f64.sin()];
                // The walk, from every stop on by one plain step.
                let (mut y, mut clock) = (start, [phase0[0], phase0[1], half[0], half[1]]);
                let mut values = [[0.0; W]; 8];
                for k in 0..W {
                    let v = values_at(region[k] as usize, k, &phase0, &[y[0][k], y[1][k]]);
                    for m in 0..8 {
                        values[m][k] = v[m];
                    }
                }
                // The reference, slot by slot.
                let mut reference_y = start;
                let mut reference_phase = phase0;
                let mut reference_values = values;
                for _ in 0..6 {
                    let taken = loops
                        .walk(
                            layout,
                            &mut y,
                            &mut clock,
                            &lanes,
                            &h,
                            &positions,
                            live,
                            400,
                            &region,
                            &mut values,
                        )
                        .expect("a loop for W");
                    // The reference to the step where a live slot stops.
                    let mut steps = 0;
                    loop {
                        let mut next_y = reference_y;
                        let mut next_values = reference_values;
                        let mut end = reference_phase;
                        let mut meets = false;
                        for k in 0..W {
                            let r = region[k] as usize;
                            let y0 = [reference_y[0][k], reference_y[1][k]];
                            let (z, after, e) = step(r, k, &reference_phase, &y0);
                            end = e;
                            next_y[0][k] = z[0];
                            next_y[1][k] = z[1];
                            for m in 0..8 {
                                next_values[m][k] = after[m];
                            }
                            let hit = impact::resting_on(&walls, &y0).is_some()
                                || walls
                                    .iter()
                                    .any(|w| impact::reaches_wall(w, &y0, h[slot(k)], &z))
                                || code.kinds.iter().enumerate().any(|(j, &kind)| {
                                    surface::may_cross(
                                        kind,
                                        region[k],
                                        (
                                            reference_values[2 * j][k],
                                            reference_values[2 * j + 1][k],
                                        ),
                                        (after[2 * j], after[2 * j + 1]),
                                        h[slot(k)],
                                    )
                                });
                            meets |= hit && live >> k & 1 == 1;
                        }
                        if meets || steps == 400 {
                            break;
                        }
                        reference_y = next_y;
                        reference_values = next_values;
                        reference_phase = end;
                        steps += 1;
                    }
                    let bits = |y: &[[f64; W]; 2], p: &[f64], v: &[[f64; W]; 8]| -> Vec<u64> {
                        let mut b: Vec<u64> =
                            y.as_flattened().iter().map(|v| v.to_bits()).collect();
                        b.extend(p[..2].iter().map(|v| v.to_bits()));
                        b.extend(
                            v[..2 * code.kinds.len()]
                                .as_flattened()
                                .iter()
                                .map(|v| v.to_bits()),
                        );
                        b
                    };
                    let context = format!("W = {W}, {layout:?}, regions {region:?}, live {live:b}");
                    assert_eq!(taken, steps, "{context}");
                    assert_eq!(
                        bits(&y, &clock, &values),
                        bits(&reference_y, &reference_phase, &reference_values),
                        "{context}"
                    );
                    if taken == 400 {
                        break;
                    }
                    stopped += 1;
                    // One plain step past the stop, on both.
                    for k in 0..W {
                        let r = region[k] as usize;
                        let (z, after, end) = step(r, k, &reference_phase, &[y[0][k], y[1][k]]);
                        y[0][k] = z[0];
                        y[1][k] = z[1];
                        for m in 0..8 {
                            values[m][k] = after[m];
                        }
                        clock[0] = end[0];
                        clock[1] = end[1];
                    }
                    reference_y = y;
                    reference_values = values;
                    reference_phase = [clock[0], clock[1]];
                }
            }
        }
        assert!(stopped > 10, "the loop stopped {stopped} times");
    }

    #[test]
    #[cfg(all(unix, target_arch = "x86_64"))]
    fn the_regions_step_loop_is_each_region_s_step_to_the_bit() {
        let table: toml::Value = toml::from_str(SWITCHING).unwrap();
        let model = crate::model::Model::parse(&table, "model").unwrap();
        let code = crate::model::code::Code::compile(model, "model").unwrap();
        assert_eq!(code.regions.len(), 4);
        assert_eq!(code.walls.len(), 1);
        assert_eq!(code.kinds.len(), 3);
        for layout in [Layout::Shared, Layout::Each] {
            same_as_stepped::<4>(&code, layout);
            same_as_stepped::<8>(&code, layout);
            same_as_stepped::<16>(&code, layout);
        }
    }

    /// The regions' native fields with the switches' constant gradients:
    /// what `surface::Sliding` reads of `ModelFlow`.
    struct Fields<'a> {
        code: &'a crate::model::code::Code,
        constants: Vec<Vec<f64>>,
        gradients: Vec<Vec<f64>>,
    }

    impl<const D: usize> crate::integrate::Flow<D> for Fields<'_> {
        fn rhs(&self, phase: &[f64; 2], y: &[f64; D]) -> [f64; D] {
            self.rhs_in(0, phase, y)
        }

        fn rhs_in(&self, region: u32, phase: &[f64; 2], y: &[f64; D]) -> [f64; D] {
            use crate::model::jit::Kind;
            let native = self.code.regions[region as usize].native.as_ref().unwrap();
            let c = &self.constants[region as usize];
            let y: [[f64; 1]; D] = std::array::from_fn(|i| [y[i]]);
            let out: [[f64; 1]; D] = native.call(Kind::Rhs, Layout::Shared, &y, phase, c, &[]);
            std::array::from_fn(|i| out[i][0])
        }

        fn surfaces(&self) -> &[Surface] {
            &self.code.kinds
        }

        fn surface_gradient(&self, j: usize, _phase: &[f64; 2], _y: &[f64; D]) -> [f64; D] {
            std::array::from_fn(|i| self.gradients[j][i])
        }
    }

    /// The C compiler's steps of every slide on one switch or two of
    /// `code` (`slide_step`) against `rk4::step_at` of `surface::Sliding`
    /// (the equivalent control of `equivalent_on`) on the regions' native
    /// fields, over states on and off the surfaces, forcing phases and
    /// step sizes, to the bit. Gives the steps compared: finite, and NaN
    /// (the control singular) in both.
    fn same_slides<const D: usize>(code: &crate::model::code::Code) -> (usize, usize) {
        use crate::integrate::clock::cos_sin;
        use crate::integrate::{rk4, surface};
        let loops = code.switch_loops.as_ref().unwrap().as_ref().unwrap();
        let params = &code.model.defaults;
        let flow = Fields {
            code,
            constants: (code.regions.iter())
                .map(|f| f.equations.lane_values(params).constants)
                .collect(),
            gradients: (code.surfaces.iter())
                .map(|s| {
                    s.gradient
                        .iter()
                        .map(|e| e.eval(&[], params, 0.0))
                        .collect()
                })
                .collect(),
        };
        let switches: Vec<usize> = (0..code.kinds.len())
            .filter(|&j| matches!(code.kinds[j], Surface::Switch { .. }))
            .collect();
        let sets = switches.iter().map(|&j| vec![j]).chain(
            (0..switches.len())
                .flat_map(|p| (p + 1..switches.len()).map(move |q| (p, q)))
                .map(|(p, q)| vec![switches[p], switches[q]]),
        );
        let (mut finite, mut singular) = (0, 0);
        for set in sets {
            let regions = code.regions.len() as u32;
            for base in
                (0..regions).filter(|r| set.iter().all(|&j| code.kinds[j].orientation(*r) > 0.0))
            {
                let region = set.iter().fold(base, |r, &j| surface::sliding_on(r, j));
                let sliding = surface::Sliding::new::<D>(&flow, region);
                let members = sliding.set.members().to_vec();
                assert_eq!(members.iter().map(|m| m.0).collect::<Vec<_>>(), set);
                assert_eq!(sliding.set.base(), base);
                let bits: Vec<u32> = members.iter().map(|m| m.1).collect();
                let fields: Vec<&[f64]> = std::iter::once(base)
                    .chain(bits.iter().map(|b| base | 1 << b))
                    .map(|r| flow.constants[r as usize].as_slice())
                    .collect();
                let grads: Vec<&[f64]> =
                    set.iter().map(|&j| flow.gradients[j].as_slice()).collect();
                for k in 0..200 {
                    let y: [f64; D] = std::array::from_fn(|i| {
                        0.2 + 0.7 * (0.37 * k as f64 + 1.3 * i as f64).sin()
                    });
                    let h = 0.002 + 0.0007 * (k % 11) as f64;
                    let phase = cos_sin(0.1 * k as f64);
                    let stages = rk4::stage_phases(&phase, &cos_sin(0.4 * h));
                    let expected = rk4::step_at(&sliding, &stages, &y, h);
                    let got = loops
                        .slide_step::<D>(base, &bits, &stages, &y, h, &fields, &grads)
                        .expect("a step for every slide on one switch or two");
                    assert_eq!(
                        got.map(f64::to_bits),
                        expected.map(f64::to_bits),
                        "switches {set:?}, base {base}, k {k}: {got:?} against {expected:?}"
                    );
                    if got.iter().all(|v| v.is_nan()) {
                        singular += 1;
                    } else {
                        assert!(got.iter().all(|v| v.is_finite()));
                        finite += 1;
                    }
                }
            }
        }
        (finite, singular)
    }

    /// `same_slides` on a model with two switches and on the two blocks on
    /// a belt (models/two-block-belt.toml), which slide on both at once
    /// when they stick together. A perturbed α or u in the generated C
    /// fails it.
    #[test]
    #[cfg(all(unix, target_arch = "x86_64"))]
    fn a_slide_s_c_step_is_the_sliding_flow_s_step_to_the_bit() {
        let compile = |text: &str, at: &str| {
            let table: toml::Value = toml::from_str(text).unwrap();
            let table = table.get("model").cloned().unwrap_or(table);
            let model = crate::model::Model::parse(&table, at).unwrap();
            crate::model::code::Code::compile(model, at).unwrap()
        };
        // The contact (x - 0.5) is crossed at the rate v on both sides: its
        // control is singular everywhere, alone or with the moving belt;
        // the belt's alone never is. One switch from two bases each, and
        // both from one.
        let switching = compile(SWITCHING, "model");
        assert_eq!(same_slides::<2>(&switching), (2 * 200, 3 * 200));
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/models/two-block-belt.toml");
        let blocks = compile(&std::fs::read_to_string(path).unwrap(), "two-block-belt");
        assert_eq!(same_slides::<4>(&blocks), (5 * 200, 0));
    }

    #[test]
    fn numbers_are_written_with_their_bits() {
        for v in [
            0.1,
            -0.0,
            1e-310,
            f64::MAX,
            1.0 / 3.0,
            f64::INFINITY,
            -f64::INFINITY,
        ] {
            let text = literal(v);
            let parsed = if text.contains("inf") {
                if text.contains('-') {
                    f64::NEG_INFINITY
                } else {
                    f64::INFINITY
                }
            } else {
                text.trim_matches(['(', ')']).parse::<f64>().unwrap()
            };
            assert_eq!(parsed.to_bits(), v.to_bits(), "{text}");
        }
    }
}
