//! Composing the WGSL kernels: a generated prelude (the `real` type, the
//! state dimension, which parts are present, and the binding layout
//! `bindings` states), the shared files, the system's
//! own file and the kernel, through a small preprocessor (`#include`,
//! `#ifdef`/`#ifndef`/`#else`/`#endif`) in the manner of vello's.

use std::borrow::Cow;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use super::bindings::{Bindings, SECTION, SWEEP};
use crate::integrate::ImpactLocation;
use crate::method::jacobian::Difference;
use crate::scene::Precision;
use crate::system::SystemInfo;

/// The WGSL sources, by the path kernels include them with.
const SOURCES: &[(&str, &str)] = &[
    (
        "shared/bindings.wgsl",
        include_str!("../../../shaders/shared/bindings.wgsl"),
    ),
    (
        "shared/dispatch.wgsl",
        include_str!("../../../shaders/shared/dispatch.wgsl"),
    ),
    (
        "shared/loop_budget.wgsl",
        include_str!("../../../shaders/shared/loop_budget.wgsl"),
    ),
    (
        "shared/stops.wgsl",
        include_str!("../../../shaders/shared/stops.wgsl"),
    ),
    (
        "shared/locate.wgsl",
        include_str!("../../../shaders/shared/locate.wgsl"),
    ),
    (
        "shared/math64.wgsl",
        include_str!("../../../shaders/shared/math64.wgsl"),
    ),
    (
        "shared/model_functions.wgsl",
        include_str!("../../../shaders/shared/model_functions.wgsl"),
    ),
    (
        "integrate.wgsl",
        include_str!("../../../shaders/integrate.wgsl"),
    ),
    ("finish.wgsl", include_str!("../../../shaders/finish.wgsl")),
    (
        "section.wgsl",
        include_str!("../../../shaders/section.wgsl"),
    ),
];

/// The kernels: the two of a period map's sweep, or a Poincaré map's one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kernel {
    /// Advance trajectories by a bounded number of RK4 steps.
    Integrate,
    /// End a map iteration: Jacobian, point, summary, re-seeding.
    Finish,
    /// A Poincaré map's steps: each trajectory advanced by its own steps,
    /// or to its next crossing of the section (the host does the rest).
    Section,
}

impl Kernel {
    fn file(self) -> &'static str {
        match self {
            Kernel::Integrate => "integrate.wgsl",
            Kernel::Finish => "finish.wgsl",
            Kernel::Section => "section.wgsl",
        }
    }

    /// The binding layout the kernel runs over: the period map's two
    /// share one.
    pub fn bindings(self) -> &'static Bindings {
        match self {
            Kernel::Integrate | Kernel::Finish => &SWEEP,
            Kernel::Section => &SECTION,
        }
    }
}

/// What a scene needs compiled in; everything else is left out.
#[derive(Clone, Copy, Debug)]
pub struct Variant {
    pub system: &'static SystemInfo,
    pub precision: Precision,
    /// Perturbed copies and the Jacobian buffer (`[output] lyapunov`).
    pub lyapunov: bool,
    /// Forward (D copies) or central (2D copies) differences.
    pub difference: Difference,
    /// Impact code: the system has a wall the sweep can reach.
    pub wall: bool,
    pub impact_location: ImpactLocation,
}

impl Variant {
    /// Trajectories per lane: the reference and its perturbed copies.
    pub fn trajectories(&self) -> usize {
        1 + if self.lyapunov {
            self.difference.copies(self.system.dimension())
        } else {
            0
        }
    }

    /// Whether the host re-estimates some iterations on the CPU from the
    /// reference's point (`method::lane::is_grazing`): the copies' impacts
    /// move (a wall), or a central column's copies leave the linear
    /// regime (their asymmetry, which the finish kernel measures).
    pub fn reestimates(&self) -> bool {
        self.lyapunov && (self.wall || self.difference == Difference::Central)
    }

    /// General surfaces (events, switches) in the impact code: the
    /// trajectories carry their region and the sum rule's ln |det S|.
    pub fn surfaces(&self) -> bool {
        self.wall && self.system.wgsl.is_some_and(|file| file.surfaces)
    }

    /// A Poincaré map, which the section kernel runs.
    pub fn section(&self) -> bool {
        self.system.wgsl.is_some_and(|file| file.section)
    }

    /// The kernels this variant runs.
    pub fn kernels(&self) -> &'static [Kernel] {
        if self.section() {
            &[Kernel::Section]
        } else {
            &[Kernel::Integrate, Kernel::Finish]
        }
    }

    /// A short name for the summary, e.g. `impact-oscillator/f64/wall+newton/jacobian-central`.
    pub fn name(&self) -> String {
        let mut parts = vec![
            self.system.kind.to_owned(),
            self.precision.name().to_owned(),
        ];
        if self.surfaces() {
            parts.push(format!("surfaces+{}", self.impact_location.name()));
        } else if self.wall {
            parts.push(format!("wall+{}", self.impact_location.name()));
        } else if self.section() {
            parts.push("section".into());
        } else if self.system.is_flow {
            parts.push("no-wall".into());
        }
        parts.push(if self.lyapunov {
            format!("jacobian-{}", self.difference.name())
        } else {
            "reference-only".into()
        });
        parts.join("/")
    }

    /// The names `#ifdef` tests.
    pub fn defines(&self) -> BTreeSet<&'static str> {
        let mut d = BTreeSet::new();
        if self.lyapunov {
            d.insert("LYAPUNOV");
            if self.difference == Difference::Central {
                d.insert("CENTRAL");
            }
        }
        if self.wall {
            d.insert("WALL");
            if self.impact_location == ImpactLocation::Linear {
                d.insert("IMPACT_LINEAR");
            }
            if self.surfaces() {
                d.insert("SURFACES");
            }
        }
        if !self.system.is_flow {
            d.insert("MAP");
        }
        if self.system.wgsl.is_some_and(|file| file.wraps_angles) {
            d.insert("WRAP");
        }
        match self.precision {
            Precision::F32 => {
                d.insert("COMPENSATED");
            }
            Precision::F64 => {
                d.insert("F64");
            }
        }
        d
    }

    /// The generated prelude: types and sizes of this variant.
    fn prelude(&self) -> String {
        // The flow's states: a Poincaré map's dimension and the one the
        // section fixes.
        let dim = self.system.dimension() + usize::from(self.section());
        let (real, epsilon, max) = match self.precision {
            Precision::F64 => ("f64", "2.220446049250313e-16", "1.7976931348623157e308"),
            Precision::F32 => ("f32", "1.1920929e-7", "3.4028235e38"),
        };
        let mut fields: Vec<String> = (0..self.system.parameters.len())
            .map(|i| format!("lanes[b + {i}u]"))
            .collect();
        // A model with surfaces: Params ends with the trajectory's region,
        // set by the integrate kernel (`Params()` zeroes it).
        if !fields.is_empty() && self.system.wgsl.is_some_and(|file| file.surfaces) {
            fields.push("0u".into());
        }
        format!(
            "// Generated prelude: variant {name}\n\
             alias real = {real};\n\
             alias State = vec{dim}<real>;\n\
             const DIM: u32 = {dim}u;\n\
             const TRAJ: u32 = {traj}u;\n\
             const PARAM_COUNT: u32 = {params}u;\n\
             const EPSILON: real = real({epsilon});\n\
             const MAX_REAL: real = real({max});\n\
             const MAX_EVENTS_PER_ITERATION: u32 = {max_events}u;\n\
             fn load_params(lane: u32) -> Params {{\n    let b = lane * LANE_STRIDE;\n    return Params({fields});\n}}\n",
            name = self.name(),
            traj = self.trajectories(),
            params = self.system.parameters.len(),
            max_events = crate::integrate::MAX_EVENTS_PER_ITERATION,
            fields = fields.join(", "),
        )
    }

    /// The complete WGSL of one kernel of this variant.
    pub fn source(&self, kernel: Kernel) -> String {
        assert!(
            self.kernels().contains(&kernel),
            "{} runs no {kernel:?} kernel",
            self.name()
        );
        let system = self
            .system
            .wgsl
            .expect("GPU variants exist only for systems with a WGSL twin")
            .source;
        let defines = self.defines();
        let mut out = self.prelude();
        out.push_str(&kernel.bindings().wgsl(self.system, &defines));
        out.push_str(&preprocess(system, &defines));
        // A generated model's functions (`model::codegen::wgsl`): f64 builds them
        // from arithmetic; a system that calls none gets neither file. The
        // surface code takes ln |det S| (log_r).
        if crate::model::codegen::wgsl::calls_wrappers(system) || self.surfaces() {
            if self.precision == Precision::F64 {
                out.push_str(&preprocess(&include("shared/math64.wgsl"), &defines));
            }
            out.push_str(&preprocess(
                &include("shared/model_functions.wgsl"),
                &defines,
            ));
        }
        // The clock, RK4 and the stop test (of the held flow too where
        // the impact code holds a mass on a stop), the general surfaces'
        // functions and the step loop that resolves impacts, generated.
        out.push_str(&crate::model::codegen::wgsl::integrator(
            self.system.is_flow,
            self.wall,
            self.impact_location != ImpactLocation::Linear,
            self.surfaces(),
            kernel == Kernel::Integrate,
        ));
        if self.wall {
            // What the generated step loop reads of the stops and of
            // where a crossing lies.
            for file in ["stops", "locate"] {
                let path = format!("shared/{file}.wgsl");
                out.push_str(&preprocess(&include(&path), &defines));
            }
        }
        match kernel {
            Kernel::Finish => out.push_str(&crate::model::codegen::wgsl::finish(self.finish())),
            Kernel::Section => out.push_str(&crate::model::codegen::wgsl::section(
                self.precision == Precision::F32,
            )),
            Kernel::Integrate => {}
        }
        out.push_str(&preprocess(&include(kernel.file()), &defines));
        out
    }

    /// The finish kernel's program's options: its defines.
    fn finish(&self) -> crate::model::ir::finish::Options {
        let defines = self.defines();
        crate::model::ir::finish::Options {
            lyapunov: defines.contains("LYAPUNOV"),
            central: defines.contains("CENTRAL"),
            compensated: defines.contains("COMPENSATED"),
            wall: defines.contains("WALL"),
            surfaces: defines.contains("SURFACES"),
            wrap: defines.contains("WRAP"),
        }
    }
}

/// A kernel source by its path under `shaders/`. Where `LYAPSWEEP_SHADER_DIR`
/// names a folder laid out as `shaders/`, its files replace the sources
/// compiled in: a kernel experiment then needs no rebuild (a release build
/// takes minutes on 2 cores; docs/hardware/lavapipe/masked-code.sh is one).
fn include(path: &str) -> Cow<'static, str> {
    source_in(source_dir().as_deref(), path)
}

/// The folder `LYAPSWEEP_SHADER_DIR` names, if any (see [`include`]).
pub fn source_dir() -> Option<PathBuf> {
    std::env::var_os("LYAPSWEEP_SHADER_DIR").map(PathBuf::from)
}

/// That the folder `LYAPSWEEP_SHADER_DIR` names, if any, holds every
/// kernel source, checked before a GPU run starts (`include` reads them
/// only when a kernel is composed, and can then only panic).
pub fn check_source_dir() -> Result<(), crate::Error> {
    let Some(dir) = source_dir() else {
        return Ok(());
    };
    let missing: Vec<&str> = SOURCES
        .iter()
        .map(|(path, _)| *path)
        .filter(|path| !dir.join(path).is_file())
        .collect();
    if missing.is_empty() {
        // Each read whole here, so that `include` (which can only panic)
        // finds text: one that is not UTF-8, or emptied, is named now.
        for (path, _) in SOURCES {
            let file = dir.join(path);
            let problem = match std::fs::read_to_string(&file) {
                Ok(text) if text.trim().is_empty() => {
                    "is empty: every kernel source holds code".to_owned()
                }
                Ok(_) => continue,
                Err(e) => format!("cannot be read as text ({e})"),
            };
            return Err(crate::Error::invalid(
                "LYAPSWEEP_SHADER_DIR",
                format!("{}: {problem}", file.display()),
            ));
        }
        return Ok(());
    }
    Err(crate::Error::Backend {
        backend: "gpu".into(),
        reason: format!(
            "LYAPSWEEP_SHADER_DIR={}: no {} there (the folder must be laid out as shaders/)",
            dir.display(),
            missing.join(", ")
        ),
    })
}

/// That every kernel of `variant` composed from the folder
/// `LYAPSWEEP_SHADER_DIR` names, if any, is valid WGSL, checked before the
/// device compiles it (a kernel the device refuses can only panic there).
/// The built-in kernels are validated by the tests (tests/shaders.rs).
pub fn check_composed(variant: &Variant) -> Result<(), crate::Error> {
    let Some(dir) = source_dir() else {
        return Ok(());
    };
    for &kernel in variant.kernels() {
        let source = variant.source(kernel);
        let problem = match naga::front::wgsl::parse_str(&source) {
            Err(e) => e.emit_to_string(&source),
            Ok(module) => match naga::valid::Validator::new(
                naga::valid::ValidationFlags::all(),
                naga::valid::Capabilities::all(),
            )
            .validate(&module)
            {
                Err(e) => e.emit_to_string(&source),
                Ok(_) => continue,
            },
        };
        return Err(crate::Error::invalid(
            "LYAPSWEEP_SHADER_DIR",
            format!(
                "{}: the {kernel:?} kernel of {} composed from it is not valid WGSL:\n{problem}",
                dir.display(),
                variant.name()
            ),
        ));
    }
    Ok(())
}

fn source_in(dir: Option<&Path>, path: &str) -> Cow<'static, str> {
    if let Some(dir) = dir {
        let file = dir.join(path);
        return Cow::Owned(
            std::fs::read_to_string(&file)
                .unwrap_or_else(|e| panic!("LYAPSWEEP_SHADER_DIR: {}: {e}", file.display())),
        );
    }
    SOURCES
        .iter()
        .find(|(p, _)| *p == path)
        .map(|(_, s)| Cow::Borrowed(*s))
        .unwrap_or_else(|| panic!("no shader source {path}"))
}

/// Expands `#include "path"` and keeps or drops lines by
/// `#ifdef NAME` / `#ifndef NAME` / `#else` / `#endif` (nestable).
pub fn preprocess(source: &str, defines: &BTreeSet<&str>) -> String {
    let mut out = String::with_capacity(source.len());
    // For each open #if: (whether its branch is kept, whether the enclosing ones are).
    let mut stack: Vec<(bool, bool)> = Vec::new();
    let active = |stack: &[(bool, bool)]| stack.last().is_none_or(|&(this, outer)| this && outer);
    for line in source.lines() {
        let trimmed = line.trim_start();
        if let Some(name) = trimmed.strip_prefix("#ifdef ") {
            let outer = active(&stack);
            stack.push((defines.contains(name.trim()), outer));
        } else if let Some(name) = trimmed.strip_prefix("#ifndef ") {
            let outer = active(&stack);
            stack.push((!defines.contains(name.trim()), outer));
        } else if trimmed.starts_with("#else") {
            let top = stack.last_mut().expect("#else without #ifdef");
            top.0 = !top.0;
        } else if trimmed.starts_with("#endif") {
            stack.pop().expect("#endif without #ifdef");
        } else if let Some(path) = trimmed.strip_prefix("#include ") {
            if active(&stack) {
                out.push_str(&preprocess(
                    &include(path.trim().trim_matches('"')),
                    defines,
                ));
            }
        } else if active(&stack) {
            out.push_str(line);
            out.push('\n');
        }
    }
    assert!(stack.is_empty(), "unterminated #ifdef");
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `LYAPSWEEP_SHADER_DIR` pointed at `shaders/` composes the kernels
    /// compiled in: every source's path is its path there.
    #[test]
    fn a_shader_folder_laid_out_as_shaders_gives_the_sources_compiled_in() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("shaders");
        for (path, text) in SOURCES {
            assert_eq!(source_in(Some(&dir), path), *text, "{path}");
        }
    }
}
