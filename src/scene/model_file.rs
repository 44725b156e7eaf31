//! A model named by file (`model = "file.toml"`): found relative to the
//! scene, and inlined into the scene's table before anything reads it.

use std::path::{Path, PathBuf};

use crate::error::Result;

/// A scene's `model = "file.toml"` replaced by the file's model table (its
/// `[model]`, or the whole file), read relative to `base`, so that
/// overrides and the written scene see the model itself; returns the
/// file's path.
pub(super) fn inline_model_file(
    table: &mut toml::Table,
    base: Option<&Path>,
) -> Result<Option<PathBuf>> {
    let Some(toml::Value::String(file)) = table.get("model") else {
        return Ok(None);
    };
    let path = model_path(file, base);
    let model = crate::model::read_table(&path)?;
    table.insert("model".into(), model);
    Ok(Some(path))
}

/// The model file a scene's `model = "file"` names, relative to the
/// scene's folder `base` (the working directory when `None`).
pub fn model_path(file: &str, base: Option<&Path>) -> PathBuf {
    base.map_or_else(|| Path::new(file).to_owned(), |b| b.join(file))
}
