//! The extension module of the Python package: the library's `command`
//! functions called from Python, with the conversions between the two
//! (dicts and TOML, errors and the package's exceptions). The package's
//! Python files (`lyapsweep/`) wrap these functions; nothing here decides
//! what a run does, so that Python runs exactly what the command line runs.

use std::path::{Path, PathBuf};
use std::sync::mpsc::{self, RecvTimeoutError};
use std::time::Duration;

use lyapsweep::command::summary::{RunSummary, Value};
use lyapsweep::command::{self, progress_bar};
use lyapsweep::scene::{self, Scene};
use lyapsweep::{Error, Progress, RunOptions};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};

/// The compiled part of the `lyapsweep` package; its functions are
/// called by the package's Python files, which document them.
#[pymodule]
mod _lyapsweep {
    #[pymodule_export]
    use super::{check_model, copy_set, devices, run};

    use pyo3::prelude::*;

    #[pymodule_init]
    fn init(m: &Bound<'_, PyModule>) -> PyResult<()> {
        // The package's version: this crate's, which is the wheel's (maturin
        // reads it from Cargo.toml) and the library's (the tests check).
        m.add("__version__", env!("CARGO_PKG_VERSION"))
    }
}

/// Runs `scene` (a `pathlib.Path`, TOML text or a dict) with `overrides`
/// (pairs of a dotted key and a value, applied in order as the command
/// line's `--set`) into the output folder `out`, which must be new, empty
/// or a lyapsweep output folder. `progress` is False (no display), True
/// (the command line's display on stderr) or a callable given
/// `(done, total)` lane-iterations a few times a second. Returns a dict:
/// `summary`, `scene` (the resolved scene as written to scene.toml),
/// `written` (the paths), `axes` (each swept parameter's name and values,
/// in sweep order) and `starts` (the starts per value, None without
/// `[attractors]`'s).
///
/// The run has a thread of its own and the GIL is released while it runs,
/// so that other Python threads go on; the calling thread wakes every
/// [`TICK`] to run Python's signal handlers (Ctrl-C raises
/// `KeyboardInterrupt` there) and the callable. An exception from either
/// stops the run, which then writes nothing, and is raised once it has.
#[pyfunction]
fn run<'py>(
    py: Python<'py>,
    scene: &Bound<'py, PyAny>,
    overrides: Vec<(String, Bound<'py, PyAny>, String)>,
    out: PathBuf,
    progress: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyDict>> {
    let source = SceneSource::of(scene)?;
    let labelled = labelled_overrides(&overrides)?;
    let overrides: Vec<String> = labelled.iter().map(|(a, _)| a.clone()).collect();
    let report: Option<Py<PyAny>> = progress.is_callable().then(|| progress.clone().unbind());
    let own_display = report.is_none() && progress.is_truthy()?;
    let options = RunOptions {
        progress: Some(Progress::default()),
        ..Default::default()
    };
    let counts = options.progress.clone().expect("set above");
    let stop = options.stop.clone();
    let work = || {
        let scene = source.load(&overrides)?;
        let prepared = command::prepare(&scene, &out)?;
        if let Some(line) = prepared.large().filter(|_| own_display) {
            eprintln!("lyapsweep: {line}");
        }
        let outcome = prepared.run(&options)?;
        // Every lane failed: the files are written, but hold no result.
        outcome.result()?;
        Ok((scene, outcome))
    };
    let (ran, raised) = py.detach(|| {
        std::thread::scope(|threads| {
            let (done, finished) = mpsc::channel();
            threads.spawn(move || {
                // The receiver waits below until this is sent. The run's
                // own pool of threads, not rayon's global one: see `threads`.
                let _ = done.send(threads::pool().install(work));
            });
            let watcher = own_display.then(|| progress_bar::watch(&counts));
            let mut raised: Option<PyErr> = None;
            let ran = loop {
                match finished.recv_timeout(TICK) {
                    Ok(ran) => break ran,
                    Err(RecvTimeoutError::Timeout) => {}
                    Err(RecvTimeoutError::Disconnected) => {
                        panic!("the run's thread ended without its result")
                    }
                }
                if raised.is_some() {
                    continue;
                }
                raised = Python::attach(|py| {
                    py.check_signals()?;
                    match &report {
                        Some(f) if counts.total() > 0 => {
                            f.call1(py, (counts.done(), counts.total())).map(drop)
                        }
                        _ => Ok(()),
                    }
                })
                .err();
                if raised.is_some() {
                    stop.request();
                }
            };
            if let Some(w) = watcher {
                w.finish();
            }
            (ran, raised)
        })
    });
    // An interrupt (or the callable's exception) that came once the lanes
    // had finished, while the set was written, stopped nothing: the set is
    // in place, and the exception says so.
    let written = |e: PyErr, outcome: &command::Outcome| {
        let paths = outcome.written.clone();
        match e.value(py).setattr("lyapsweep_written", paths) {
            Ok(()) => e,
            Err(other) => other,
        }
    };
    match (raised, &ran) {
        (Some(e), Ok((_, outcome))) => return Err(written(e, outcome)),
        (Some(e), Err(_)) => return Err(e),
        (None, _) => {}
    }
    let (scene, outcome) = ran.map_err(|e| to_exception_labelled(py, e, &labelled))?;
    if let Some(f) = &report {
        f.call1(py, (counts.done(), counts.total()))
            .map_err(|e| written(e, &outcome))?;
    }
    let result = PyDict::new(py);
    result.set_item("summary", summary(py, &RunSummary::of(&scene, &outcome))?)?;
    result.set_item("scene", resolved(py, &scene)?)?;
    result.set_item("written", outcome.written)?;
    // The grid the lanes cover, for labelled arrays: its values as the
    // library generated them, bit for bit, rather than computed again.
    let axes: Vec<(String, Vec<f64>)> = scene
        .sweep
        .axes()
        .map(|axis| (axis.parameter.clone(), axis.values.clone()))
        .collect();
    result.set_item("axes", axes)?;
    let starts = scene.sweep.starts.as_ref().map(|s| s.states.len());
    result.set_item("starts", starts)?;
    Ok(result)
}

/// Each override as the library's assignment (`sweep.count=5`) and as the
/// caller wrote it (`set["sweep.count"] = 5`, `backend="gpu"`), for the
/// messages; `overrides` are (key, value, the keyword that gave it).
fn labelled_overrides(
    overrides: &[(String, Bound<'_, PyAny>, String)],
) -> PyResult<Vec<(String, String)>> {
    overrides
        .iter()
        .map(|(key, value, keyword)| {
            let value = to_toml(value, key)?;
            let mut label = match keyword.as_str() {
                "set" => format!("set[{key:?}] = {value}"),
                _ => format!("{keyword}={value}"),
            };
            // A whole table given as one value is clipped, as `--set`'s is.
            if label.chars().count() > 80 {
                label = label.chars().take(79).chain(['…']).collect();
            }
            Ok((format!("{key}={value}"), label))
        })
        .collect()
}

/// The threads runs compute on. rayon's global pool is made once per
/// process, and a child started by `fork` (Python's `multiprocessing` on
/// Linux) inherits it without its threads: a run there waits forever for
/// work none of them takes. So each process makes a pool of its own, a
/// forked child a new one.
mod threads {
    use std::sync::{Arc, Mutex};

    use rayon::{ThreadPool, ThreadPoolBuilder};

    static POOL: Mutex<Option<(u32, Arc<ThreadPool>)>> = Mutex::new(None);

    /// This process's pool (made on first use).
    pub fn pool() -> Arc<ThreadPool> {
        let pid = std::process::id();
        let mut pool = POOL.lock().unwrap_or_else(|e| e.into_inner());
        match pool.as_ref() {
            Some((made_in, p)) if *made_in == pid => return p.clone(),
            // The parent's pool: dropping it would signal threads this
            // process does not have.
            Some(_) => std::mem::forget(pool.take()),
            None => {}
        }
        let made = Arc::new(
            ThreadPoolBuilder::new()
                .thread_name(|i| format!("lyapsweep-{i}"))
                .build()
                .expect("the run's threads start"),
        );
        *pool = Some((pid, made.clone()));
        made
    }
}

/// How often a running scene's calling thread looks at Python's signals and
/// reports progress: Ctrl-C stops a run within about this, plus the time a
/// lane takes to finish the iteration it is in.
const TICK: Duration = Duration::from_millis(100);

/// Writes the set in the folder `from` as the set of `to`, staged and
/// swapped in whole like a run's; returns the paths written.
#[pyfunction]
fn copy_set(py: Python<'_>, from: PathBuf, to: PathBuf) -> PyResult<Vec<PathBuf>> {
    py.detach(|| lyapsweep::output::set::copy(&from, &to))
        .map_err(|e| to_exception(py, e))
}

/// What `lyapsweep model check` prints of `model` (a `pathlib.Path`, TOML
/// text or a dict), and the model file it named when it was a scene.
#[pyfunction]
fn check_model(py: Python<'_>, model: &Bound<'_, PyAny>) -> PyResult<(String, Option<PathBuf>)> {
    let source = SceneSource::of(model)?;
    let checked = py.detach(|| match &source {
        SceneSource::Path(path) => command::check_model(path),
        SceneSource::Text { text, origin } => {
            let table = lyapsweep::model::table_of_text(text, origin)?;
            command::check_model_table(table, Path::new(origin), None)
        }
    });
    let checked = checked.map_err(|e| to_exception(py, e))?;
    Ok((checked.description, checked.named))
}

/// The GPU adapters, as `lyapsweep devices` lists them: one dict each.
#[pyfunction]
fn devices(py: Python<'_>) -> PyResult<Vec<Bound<'_, PyDict>>> {
    let adapters = py
        .detach(command::devices)
        .map_err(|e| to_exception(py, e))?;
    adapters
        .into_iter()
        .map(|a| {
            let d = PyDict::new(py);
            d.set_item("name", a.name)?;
            d.set_item("backend", a.backend)?;
            d.set_item("device_type", a.device_type)?;
            d.set_item("f64", a.f64)?;
            d.set_item("timestamps", a.timestamps)?;
            d.set_item("exact_rounding", a.exact_rounding)?;
            d.set_item("max_storage_binding", a.max_storage_binding)?;
            d.set_item("max_buffer", a.max_buffer)?;
            d.set_item("max_workgroups", a.max_workgroups)?;
            Ok(d)
        })
        .collect()
}

/// Where a scene (or a model) comes from. A dict becomes TOML text, so that
/// it goes through the same parser as text and as a file.
enum SceneSource {
    Path(PathBuf),
    Text { text: String, origin: String },
}

impl SceneSource {
    fn of(scene: &Bound<'_, PyAny>) -> PyResult<SceneSource> {
        if let Ok(text) = scene.cast::<PyString>() {
            return Ok(SceneSource::Text {
                text: text.to_cow()?.into_owned(),
                origin: "<string>".into(),
            });
        }
        if scene.is_instance_of::<PyDict>() {
            let toml::Value::Table(table) = to_toml(scene, "")? else {
                unreachable!("a dict converts to a table")
            };
            return Ok(SceneSource::Text {
                text: toml::to_string(&table).map_err(|e| PyTypeError::new_err(e.to_string()))?,
                origin: "<dict>".into(),
            });
        }
        Ok(SceneSource::Path(scene.extract()?))
    }

    /// The scene, checked, with the overrides applied. A file's model path
    /// is relative to the file, text's and a dict's to the working folder.
    fn load(&self, overrides: &[String]) -> lyapsweep::Result<Scene> {
        match self {
            SceneSource::Path(path) => scene::load(path, overrides),
            SceneSource::Text { text, origin } => scene::parse(text, origin, "scene", overrides),
        }
    }
}

/// A Python value as TOML: dicts are tables (with string keys), lists and
/// tuples arrays, and str, int, float and bool themselves; numpy's numbers
/// and numeric arrays too. `key` names the value in the error for anything
/// else (None has no TOML value), for a dict or list that holds itself,
/// and for one nested deeper than [`DEEPEST`]: the conversion recurses, and
/// a Python value may be nested far deeper than a thread's stack holds.
fn to_toml(value: &Bound<'_, PyAny>, key: &str) -> PyResult<toml::Value> {
    Converter::default().value(value, key)
}

/// How deep a dict's dicts and lists may go: a scene's tables go three or
/// four levels deep.
const DEEPEST: usize = 32;

/// The conversion's way down: the dicts and lists it is inside, to tell a
/// value that holds itself.
#[derive(Default)]
struct Converter {
    inside: Vec<(usize, String)>,
}

impl Converter {
    fn value(&mut self, value: &Bound<'_, PyAny>, key: &str) -> PyResult<toml::Value> {
        let at = |inner: &str| match (key, inner) {
            ("", _) => inner.to_owned(),
            (_, "") => key.to_owned(),
            _ => format!("{key}.{inner}"),
        };
        let shown = || {
            if key.is_empty() {
                "the top".to_owned()
            } else {
                key.to_owned()
            }
        };
        // bool before int: Python's bools are ints.
        if let Ok(b) = value.cast::<PyBool>() {
            return Ok(toml::Value::Boolean(b.is_true()));
        }
        if value.is_instance_of::<PyInt>() {
            return value
                .extract::<i64>()
                .map(toml::Value::Integer)
                .map_err(|_| {
                    PyValueError::new_err(format!("{}: an integer beyond 64 bits", shown()))
                });
        }
        if value.is_instance_of::<PyFloat>() {
            return Ok(toml::Value::Float(value.extract()?));
        }
        if let Ok(text) = value.cast::<PyString>() {
            return Ok(toml::Value::String(text.to_cow()?.into_owned()));
        }
        let is_dict = value.is_instance_of::<PyDict>();
        if is_dict || value.is_instance_of::<PyList>() || value.is_instance_of::<PyTuple>() {
            let id = value.as_ptr() as usize;
            if let Some((_, outer)) = self.inside.iter().find(|(i, _)| *i == id) {
                let outer = if outer.is_empty() { "the top" } else { outer };
                return Err(PyValueError::new_err(format!(
                    "{}: holds itself (it is the {} at {outer}), which TOML cannot write",
                    shown(),
                    if is_dict { "dict" } else { "list" }
                )));
            }
            if self.inside.len() >= DEEPEST {
                return Err(PyValueError::new_err(format!(
                    "{}: nested deeper than {DEEPEST} dicts and lists (a scene's tables go a few levels deep)",
                    shown()
                )));
            }
            self.inside.push((id, key.to_owned()));
            let converted = if is_dict {
                self.table(value.cast::<PyDict>()?, key)
            } else {
                value
                    .try_iter()?
                    .enumerate()
                    .map(|(i, item)| self.value(&item?, &format!("{}[{i}]", at(""))))
                    .collect::<PyResult<Vec<_>>>()
                    .map(toml::Value::Array)
            };
            self.inside.pop();
            return converted;
        }
        if let Some(converted) = self.numpy(value, key)? {
            return Ok(converted);
        }
        let kind = value.get_type().name()?;
        Err(PyTypeError::new_err(format!(
            "{}: a {kind} has no TOML value (str, int, float, bool, list or dict, or numpy's numbers)",
            shown()
        )))
    }

    fn table(&mut self, dict: &Bound<'_, PyDict>, key: &str) -> PyResult<toml::Value> {
        let mut table = toml::Table::new();
        for (k, v) in dict.iter() {
            let name: String = k.extract().map_err(|_| {
                PyTypeError::new_err(format!(
                    "{}: a key that is not a string ({})",
                    if key.is_empty() { "the top" } else { key },
                    k.repr().map_or_else(|_| "?".into(), |r| r.to_string())
                ))
            })?;
            let inner = self.value(
                &v,
                &if key.is_empty() {
                    name.clone()
                } else {
                    format!("{key}.{name}")
                },
            )?;
            table.insert(name, inner);
        }
        Ok(toml::Value::Table(table))
    }

    /// numpy's scalars and arrays (anything with a `dtype` and an `ndim`):
    /// booleans, integers and floats, as TOML's; None when `value` is not
    /// numpy's. An array is its `tolist()`, so only of those kinds.
    fn numpy(&mut self, value: &Bound<'_, PyAny>, key: &str) -> PyResult<Option<toml::Value>> {
        let (Ok(dtype), Ok(ndim)) = (value.getattr("dtype"), value.getattr("ndim")) else {
            return Ok(None);
        };
        let (Ok(kind), Ok(ndim)) = (
            dtype.getattr("kind").and_then(|k| k.extract::<String>()),
            ndim.extract::<usize>(),
        ) else {
            return Ok(None);
        };
        let shown = if key.is_empty() { "the top" } else { key };
        let numeric = matches!(kind.as_str(), "i" | "u" | "f");
        if ndim > 0 && !numeric {
            return Err(PyTypeError::new_err(format!(
                "{shown}: a numpy array of {} has no TOML value (integers or floats)",
                dtype.str()?
            )));
        }
        let converted = match kind.as_str() {
            _ if ndim > 0 => self.value(&value.call_method0("tolist")?, key)?,
            "b" => toml::Value::Boolean(value.is_truthy()?),
            "i" | "u" => value
                .call_method0("item")?
                .extract::<i64>()
                .map(toml::Value::Integer)
                .map_err(|_| {
                    PyValueError::new_err(format!("{shown}: an integer beyond 64 bits"))
                })?,
            "f" => toml::Value::Float(value.call_method0("item")?.extract()?),
            _ => {
                return Err(PyTypeError::new_err(format!(
                    "{shown}: a numpy {} has no TOML value (a bool, an integer or a float)",
                    dtype.str()?
                )))
            }
        };
        Ok(Some(converted))
    }
}

/// A TOML value as Python's: tables are dicts, arrays lists, a date its text.
fn to_python<'py>(py: Python<'py>, value: &toml::Value) -> PyResult<Bound<'py, PyAny>> {
    Ok(match value {
        toml::Value::String(s) => s.into_pyobject(py)?.into_any(),
        toml::Value::Integer(i) => i.into_pyobject(py)?.into_any(),
        toml::Value::Float(x) => x.into_pyobject(py)?.into_any(),
        toml::Value::Boolean(b) => b.into_pyobject(py)?.to_owned().into_any(),
        toml::Value::Datetime(d) => d.to_string().into_pyobject(py)?.into_any(),
        toml::Value::Array(items) => {
            let list = PyList::empty(py);
            for item in items {
                list.append(to_python(py, item)?)?;
            }
            list.into_any()
        }
        toml::Value::Table(table) => {
            let dict = PyDict::new(py);
            for (k, v) in table {
                dict.set_item(k, to_python(py, v)?)?;
            }
            dict.into_any()
        }
    })
}

/// The scene as run (scene.toml's text) as a dict.
fn resolved<'py>(py: Python<'py>, scene: &Scene) -> PyResult<Bound<'py, PyAny>> {
    let table: toml::Table = scene
        .source
        .parse()
        .expect("the written scene is the library's own TOML");
    to_python(py, &toml::Value::Table(table))
}

/// The summary the command line prints, as a dict: its record's keys and
/// values.
fn summary<'py>(py: Python<'py>, summary: &RunSummary) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    for (key, value) in summary.record() {
        match value {
            Value::Text(text) => d.set_item(key, text)?,
            Value::Count(n) => d.set_item(key, n)?,
            Value::Number(x) => d.set_item(key, x)?,
            Value::ByStatus(counts) => d.set_item(key, counts)?,
            Value::Nothing => d.set_item(key, py.None())?,
        }
    }
    Ok(d)
}

/// The library's error as the package's exception (`lyapsweep._errors`),
/// with the command line's message: a model's as `ModelError` with its
/// column, the rest of the input's as `SceneError`, both with the key;
/// the machine's (a write failed, every lane failed) as `RunError`.
fn to_exception(py: Python<'_>, error: Error) -> PyErr {
    to_exception_labelled(py, error, &[])
}

/// [`to_exception`] for a run given `overrides`: pairs of the assignment
/// the library was given (`sweep.count=5`) and how the caller wrote it
/// (`set["sweep.count"] = 5`, `backend="gpu"`), which the message says
/// instead of the command line's `--set sweep.count=5`.
fn to_exception_labelled(py: Python<'_>, error: Error, overrides: &[(String, String)]) -> PyErr {
    let mut message = error.to_string();
    if let Some(set) = error.key().filter(|k| k.starts_with("--set ")) {
        let key = dotted_key(set);
        let label = overrides
            .iter()
            .rev()
            .find(|(assignment, _)| assignment.split('=').next() == Some(key.as_str()));
        if let Some((_, label)) = label {
            message = message.replacen(set, label, 1);
        }
    }
    let key = error.key().map(dotted_key);
    let class = if !error.is_input_error() {
        "RunError"
    } else if matches!(error, Error::NotAModel { .. })
        || key
            .as_deref()
            .is_some_and(|k| k == "model" || k.starts_with("model.") || k.starts_with("model["))
    {
        "ModelError"
    } else {
        "SceneError"
    };
    let raised = (|| {
        let kwargs = PyDict::new(py);
        kwargs.set_item("key", key.as_deref())?;
        kwargs.set_item("column", column(&message))?;
        let exception = py
            .import("lyapsweep._errors")?
            .getattr(class)?
            .call((message.as_str(),), Some(&kwargs))?;
        Ok::<_, PyErr>(PyErr::from_value(exception))
    })();
    raised.unwrap_or_else(|e| e)
}

/// The dotted key of an error's key: an override's (`--set a.b=1`) is the
/// key it set, a model file's (`model.equations.v in models/x.toml`) the
/// key without the file.
fn dotted_key(key: &str) -> String {
    match key.strip_prefix("--set ") {
        Some(assignment) => assignment.split('=').next().unwrap_or_default(),
        None => key.split(" in ").next().unwrap_or_default(),
    }
    .trim()
    .to_owned()
}

/// The column a model's message points at: "... (column 6)".
fn column(message: &str) -> Option<usize> {
    let (_, after) = message.rsplit_once("(column ")?;
    after.split(')').next()?.parse().ok()
}
