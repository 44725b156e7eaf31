//! `--set key.path=value`: overrides applied to the scene's table before
//! it is read, and the errors that are an override's rather than a file's.

use std::path::Path;

use crate::error::{clip, clip_quoted, Error, Result};

/// The keys an override set ("integration.iterations"), each with its
/// assignment as the command line gave it, for messages.
pub(super) type Overridden<'a> = Vec<(String, &'a String)>;

/// Applies the `overrides` in order, each checked first when it names a
/// model parameter; returns what each set.
pub(super) fn apply_overrides<'a>(
    table: &mut toml::Table,
    overrides: &'a [String],
    model_file: Option<&Path>,
) -> Result<Overridden<'a>> {
    let mut overridden = Vec::new();
    for o in overrides {
        check_model_override(table, o)?;
        overridden.push((apply_override(table, o, model_file)?, o));
    }
    Ok(overridden)
}

/// A quick look (`--set integration.iterations=10`) keeps the points the
/// scene asked for up to the iterations there are, rather than refusing
/// every scene that keeps points; points given by `--set`, or a scene
/// that asks for more points than its own iterations, are still refused.
/// Returns the points asked for, when lowered.
pub(super) fn lower_for_quick_look(
    table: &mut toml::Table,
    overridden: &[(String, &String)],
) -> Option<usize> {
    let overrides_set = |key: &str| {
        overridden
            .iter()
            .any(|(o, _)| key == o || key.starts_with(&format!("{o}.")))
    };
    if overrides_set("integration.iterations") && !overrides_set("output.bifurcation_points") {
        lower_bifurcation_points(table)
    } else {
        None
    }
}

/// `--set integration.iterations=2000`: the value is read as TOML, or as a
/// string when it is a bare word (so `--set run.backend=cpu` works); returns
/// the key's path ("integration.iterations"). A key of the path may index
/// an array (`model.events[0].surface`), which must hold that element;
/// `model_file` is where the scene's model came from, for messages.
fn apply_override(
    table: &mut toml::Table,
    assignment: &str,
    model_file: Option<&Path>,
) -> Result<String> {
    let bad = |reason: &str| Error::invalid(set_key(assignment), reason);
    let (path, value) = assignment
        .split_once('=')
        .ok_or_else(|| bad("expected key.path=value"))?;
    let bare_word = |v: &str| {
        v.chars().next().is_some_and(|c| c.is_ascii_alphabetic())
            && v.chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
    };
    let value: toml::Value = match format!("v = {value}").parse::<toml::Table>() {
        Ok(mut t) => t.remove("v").expect("just parsed"),
        Err(_) if bare_word(value.trim()) => toml::Value::String(value.trim().to_owned()),
        Err(e) => {
            return Err(bad(&format!(
                "the value is not TOML ({}); quote a string: key='\"text\"'",
                clip_quoted(&e.message().split_whitespace().collect::<Vec<_>>().join(" "))
            )))
        }
    };
    let steps = override_path(path.trim()).map_err(|reason| bad(&reason))?;
    // Where a key of the model is looked for, when the model is a file's.
    let of_model = |shown: &str| match model_file {
        Some(file) if shown == "model" || shown.starts_with("model.") => {
            format!(" (the scene's model is {})", file.display())
        }
        _ => String::new(),
    };
    let (last, parents) = steps.split_last().expect("a path has at least one key");
    // The root is taken out of `table` to be walked as a value, and put back
    // whatever the outcome.
    let mut root = toml::Value::Table(std::mem::take(table));
    let result = (|| {
        let mut node = &mut root;
        let mut shown = String::new();
        for (k, step) in parents.iter().enumerate() {
            let next_indexes = matches!(steps[k + 1], Step::Index(_));
            node = match step {
                Step::Key(key) => {
                    let map = node.as_table_mut().ok_or_else(|| {
                        format!("`{}` is not a table{}", clip(&shown), of_model(&shown))
                    })?;
                    let path = step.after(&shown);
                    if next_indexes && !map.contains_key(key) {
                        return Err(format!(
                            "`{}` is not in the scene: there is no array to index{}",
                            clip(&path),
                            of_model(&path)
                        ));
                    }
                    shown = path;
                    map.entry(key.clone())
                        .or_insert_with(|| toml::Value::Table(toml::Table::new()))
                }
                Step::Index(i) => {
                    let element = element(node, *i, &shown).map_err(|e| e + &of_model(&shown))?;
                    shown = step.after(&shown);
                    element
                }
            };
        }
        match last {
            Step::Key(key) => {
                let map = node.as_table_mut().ok_or_else(|| {
                    format!("`{}` is not a table{}", clip(&shown), of_model(&shown))
                })?;
                match map.get_mut(key) {
                    // A model parameter given with its range ({ value, min, max }):
                    // the override sets its value and keeps the range.
                    Some(toml::Value::Table(parameter))
                        if parameter.contains_key("value") && !value.is_table() =>
                    {
                        parameter.insert("value".into(), value);
                    }
                    _ => {
                        map.insert(key.clone(), value);
                    }
                }
            }
            Step::Index(i) => {
                *element(node, *i, &shown).map_err(|e| e + &of_model(&shown))? = value;
            }
        }
        Ok(())
    })();
    let toml::Value::Table(root) = root else {
        unreachable!("the root stays a table")
    };
    *table = root;
    result.map_err(|reason| bad(&reason))?;
    Ok(steps
        .iter()
        .fold(String::new(), |shown, step| step.after(&shown)))
}

/// One step of an override's path: a key of a table, or an element of an
/// array.
#[derive(Debug, PartialEq)]
enum Step {
    Key(String),
    Index(usize),
}

impl Step {
    /// The path `shown` followed by this step, as messages and serde's
    /// paths spell it ("model.events[0].surface").
    fn after(&self, shown: &str) -> String {
        match self {
            Step::Key(key) if shown.is_empty() => key.clone(),
            Step::Key(key) => format!("{shown}.{key}"),
            Step::Index(i) => format!("{shown}[{i}]"),
        }
    }
}

/// `model.events[0].surface` as steps: dotted keys, each followed by any
/// number of `[i]`.
fn override_path(path: &str) -> std::result::Result<Vec<Step>, String> {
    let mut steps = Vec::new();
    for part in path.split('.') {
        let (key, mut indexes) = part.split_at(part.find('[').unwrap_or(part.len()));
        if key.is_empty() {
            return Err("empty key in the path".into());
        }
        if key.contains(']') {
            return Err(format!("`{}`: a `]` without its `[`", clip(part)));
        }
        steps.push(Step::Key(key.to_owned()));
        while !indexes.is_empty() {
            let index = indexes
                .strip_prefix('[')
                .and_then(|rest| rest.split_once(']'))
                .and_then(|(number, rest)| Some((number.trim().parse::<usize>().ok()?, rest)));
            let Some((i, rest)) = index else {
                return Err(format!(
                    "`{}`: an index is written [n], n a whole number from 0",
                    clip(part)
                ));
            };
            steps.push(Step::Index(i));
            indexes = rest;
        }
    }
    Ok(steps)
}

/// Element `i` of the array `node` (at `shown`), or why there is none.
fn element<'a>(
    node: &'a mut toml::Value,
    i: usize,
    shown: &str,
) -> std::result::Result<&'a mut toml::Value, String> {
    let Some(array) = node.as_array_mut() else {
        return Err(format!(
            "`{}` is not an array, so it has no element [{i}]",
            clip(shown)
        ));
    };
    let len = array.len();
    array.get_mut(i).ok_or_else(|| match len {
        0 => format!("`{}` is empty: there is no element [{i}]", clip(shown)),
        _ => format!(
            "`{}` has {len} element{}, [0] to [{}]: there is no [{i}]",
            clip(shown),
            if len == 1 { "" } else { "s" },
            len - 1
        ),
    })
}

/// The key of an error in `--set ASSIGNMENT`, the assignment clipped.
pub(super) fn set_key(assignment: &str) -> String {
    format!("--set {}", clip(assignment))
}

/// Lowers `output.bifurcation_points` to `integration.iterations` where it
/// exceeds them; returns the points it asked for, when lowered. Values of
/// the wrong type are left for the scene's checks to name.
fn lower_bifurcation_points(table: &mut toml::Table) -> Option<usize> {
    let iterations = table
        .get("integration")
        .and_then(|i| i.get("iterations"))
        .and_then(|i| i.as_integer())
        .filter(|&i| i >= 1)?;
    let points = table
        .get_mut("output")
        .and_then(|o| o.as_table_mut())
        .and_then(|o| o.get_mut("bifurcation_points"))?;
    let asked = points.as_integer().filter(|&p| p > iterations)?;
    *points = toml::Value::Integer(iterations);
    usize::try_from(asked).ok()
}

/// An error about a key of `[model]`, its key clipped, and said to be an
/// override's when `--set` gave the key (a value of the user's command
/// line, not of a file), or else, when the model is another file's (`model
/// = "file.toml"`), that file's: the key is written there, not in the
/// scene.
pub(super) fn model_error(
    e: Error,
    file: Option<&Path>,
    overridden: &[(String, &String)],
) -> Error {
    let Error::Invalid { key, reason } = e else {
        return e;
    };
    if !key.starts_with("model.") {
        return Error::Invalid { key, reason };
    }
    let from = |o: &str| {
        key == o || key.starts_with(&format!("{o}.")) || key.starts_with(&format!("{o}["))
    };
    match (overridden.iter().rev().find(|(o, _)| from(o)), file) {
        (Some((_, assignment)), _) => {
            Error::invalid(set_key(assignment), format!("{}: {reason}", clip(&key)))
        }
        (None, Some(file)) => {
            Error::invalid(format!("{} in {}", clip(&key), file.display()), reason)
        }
        (None, None) => Error::invalid(clip(&key), reason),
    }
}

/// `--set model.parameters.NAME=...` must name a parameter the model has:
/// a new key there would be a parameter nothing reads (a typo, silently).
fn check_model_override(table: &toml::Table, assignment: &str) -> Result<()> {
    let path = assignment
        .split_once('=')
        .map_or(assignment, |(p, _)| p)
        .trim();
    let Some(name) = path.strip_prefix("model.parameters.") else {
        return Ok(());
    };
    let parameters = table
        .get("model")
        .and_then(|m| m.get("parameters"))
        .and_then(|p| p.as_table());
    match parameters {
        Some(p) if !p.contains_key(name) => Err(Error::invalid(
            set_key(assignment),
            format!(
                "the model has no parameter `{}` (its parameters: {})",
                clip(name),
                p.keys().cloned().collect::<Vec<_>>().join(", ")
            ),
        )),
        _ => Ok(()),
    }
}
