//! The commands' work, for every front end: the command line prints what
//! these return, the Python package hands it to its caller. There is one
//! way to run a scene into an output folder and one way to check a model,
//! so that both front ends refuse, write and describe alike.

pub mod progress_bar;
pub mod summary;

use std::path::{Path, PathBuf};

use crate::attractor::Attractors;
use crate::backend::gpu::context::{self, AdapterSummary};
use crate::backend::RunOptions;
use crate::driver::orbits::{self, OrbitRun, OrbitStarts};
use crate::driver::{run_streaming, Summary};
use crate::error::{clip, Error, Result};
use crate::model::{self, compiled::Code, Model};
use crate::output::{SetWriter, Staging};
use crate::plan;
use crate::scene::{self, Scene};

/// A run whose output folder has taken it: nothing has been computed yet.
pub struct Prepared {
    scene: Scene,
    writer: SetWriter,
    large: Option<String>,
}

/// What a run produced: its summary, with `[attractors]` the attractors,
/// and the paths of the set written into the output folder.
pub struct Outcome {
    pub summary: Summary,
    pub attractors: Option<Attractors>,
    /// With `[orbits]`, the branches traced.
    pub orbits: Option<OrbitRun>,
    pub written: Vec<PathBuf>,
}

/// Prepares the run of `scene` into the output folder `dir`. Everything
/// that can refuse the run does so here, before the first step: its size
/// (when the scene was read), then the output folder, which must be able
/// to take a new set (see [`Staging::prepare`]).
pub fn prepare(scene: &Scene, dir: &Path) -> Result<Prepared> {
    crate::environment::check()?;
    let large = plan::large_run(scene);
    let writer = SetWriter::new(scene, Staging::prepare(dir, &scene.files)?)?;
    Ok(Prepared {
        scene: scene.clone(),
        writer,
        large,
    })
}

impl Prepared {
    /// A line saying what the run will take, when it is large enough that
    /// its user should know before it starts.
    pub fn large(&self) -> Option<&str> {
        self.large.as_deref()
    }

    /// Runs the scene, streaming each batch's rows into the staged set,
    /// and swaps the complete set into the output folder. On an error the
    /// staged files are removed and the folder keeps what it held.
    pub fn run(self, options: &RunOptions) -> Result<Outcome> {
        let Prepared {
            scene, mut writer, ..
        } = self;
        let batch = plan::batch_lanes(&scene);
        let mut starts = OrbitStarts::default();
        let tracing = scene.orbits.is_some();
        let (summary, attractors) = run_streaming(&scene, options, batch, |batch, report| {
            if tracing {
                starts.absorb(batch, report);
            }
            writer.append(batch, report)
        })?;
        let orbits = orbits::trace(&scene, starts, options);
        if let Some(run) = &orbits {
            writer.set_orbits(run.clone());
        }
        // A stop asked for while the files were written (Ctrl-C after the
        // lanes), up to the swap, still leaves the folder as it was.
        let staged = writer.complete(attractors.as_ref())?;
        let written = staged.commit_unless(&|| options.stop.requested())?;
        Ok(Outcome {
            summary,
            attractors,
            orbits,
            written,
        })
    }
}

impl Outcome {
    /// The run's result as a whole: an error when every lane failed (the
    /// files were written, with each lane's status, but hold no exponents).
    pub fn result(&self) -> Result<()> {
        if !self.summary.all_failed() {
            return Ok(());
        }
        Err(Error::AllLanesFailed {
            reasons: Summary::by_status(&self.summary.failures),
        })
    }
}

/// A model checked by [`check_model`].
pub struct ModelCheck {
    /// What `model check` prints: the equations, the derivatives the sum
    /// rule uses, the events, what each backend runs, the generated WGSL.
    pub description: String,
    /// When the file given was a scene naming its model file, that file.
    pub named: Option<PathBuf>,
}

/// Checks the model file `file`: its `[model]` table, or the whole file
/// as one. A scene file given instead is told apart: one naming its model
/// file (`model = "file.toml"`, relative to the scene) has that file
/// checked; one with a built-in `[system]`, or no model, is refused.
pub fn check_model(file: &Path) -> Result<ModelCheck> {
    let table = model::read_table(file)?;
    check_model_table(table, file, file.parent())
}

/// [`check_model`] of a model's table, read from `origin` (which names it
/// in messages); a scene's `model = "file.toml"` is relative to `base`,
/// the working directory when `None`.
pub fn check_model_table(
    mut table: toml::Value,
    origin: &Path,
    base: Option<&Path>,
) -> Result<ModelCheck> {
    let mut named = None;
    if let toml::Value::String(name) = &table {
        let path = scene::model_path(name, base);
        table = model::read_table(&path)?;
        named = Some(path);
    }
    // Keys a scene has and a model does not.
    let scene_keys = ["system", "sweep", "integration", "run", "output"];
    if let Some(key) = scene_keys.iter().find(|k| table.get(k).is_some()) {
        let reason = match table.get("system").and_then(|s| s.get("kind")) {
            Some(kind) => format!(
                "is a scene file whose [system] is built into lyapsweep (kind = {}), not a model: it names no model file to check; `model check` reads a model file (a [model] table, or the whole file as one), or a scene with model = \"file.toml\"",
                clip(&kind.to_string())
            ),
            None => format!(
                "is a scene file (it has [{key}]) with no [model] and no model = \"file.toml\": there is no model in it to check; `model check` reads a model file (a [model] table, or the whole file as one)"
            ),
        };
        return Err(Error::NotAModel {
            path: origin.to_owned(),
            reason,
        });
    }
    let compiled = (|| {
        let model = Model::parse(&table, "model")?;
        // A run checks the period at every swept value; at the defaults, here.
        model.check_period(&model.defaults, "model", "the model's defaults")?;
        Code::compile(model, "model")
    })();
    // A scene's model file is named in its errors, as a run names it.
    let code = compiled.map_err(|e| match (e, &named) {
        (Error::Invalid { key, reason }, Some(file)) => {
            Error::invalid(format!("{} in {}", clip(&key), file.display()), reason)
        }
        (e, _) => e,
    })?;
    Ok(ModelCheck {
        description: model::describe::describe(&code),
        named,
    })
}

/// The GPU adapters wgpu finds, with what the backend needs of them.
/// `WGPU_BACKEND` is checked first: a name wgpu does not know is an error.
pub fn devices() -> Result<Vec<AdapterSummary>> {
    crate::environment::wgpu_backends()?;
    Ok(context::list())
}
