//! A system as data (the models issue): what a scene's `[model]` table
//! says, parsed once and read by every backend.
//!
//! The folders are the pipeline: the [`language`] (expressions, the
//! `[model]` table checked into a [`Model`]), lowered to the [`ir`] (the
//! instruction tape and its interpreter, the reference), printed by
//! [`codegen`] (one printer; C for the CPU, WGSL for the GPU), the C built
//! and loaded as [`native`] code; [`compiled`] joins them into the compiled
//! model every backend reads, and [`describe`] is `model check`'s report. `system::model` and
//! `system::section` make a compiled model a system like the hand-written
//! one (Hénon's map).

pub mod codegen;
pub mod compiled;
pub mod describe;
pub mod ir;
pub mod language;
pub mod native;

pub use language::{Event, Map, Model};

/// A model file's `[model]` table (or, without one, the whole file as the
/// model table), unparsed: what a scene's `model = "file"` stands for.
pub fn read_table(path: &std::path::Path) -> crate::Result<toml::Value> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| crate::Error::invalid("model", format!("{}: {e}", path.display())))?;
    table_of_text(&text, &path.display().to_string())
}

/// [`read_table`] of a model file's text; `origin` names it in messages.
pub fn table_of_text(text: &str, origin: &str) -> crate::Result<toml::Value> {
    let bad = |reason: String| crate::Error::invalid("model", format!("{origin}: {reason}"));
    let mut read: toml::Table = text.parse().map_err(|e: toml::de::Error| {
        let line = e
            .span()
            .map(|span| format!("line {}: ", text[..span.start].matches('\n').count() + 1));
        bad(format!(
            "{}{}",
            line.unwrap_or_default(),
            e.message().trim()
        ))
    })?;
    match read.remove("model") {
        Some(model) => Ok(model),
        None => Ok(toml::Value::Table(read)),
    }
}
