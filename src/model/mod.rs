//! A system as data (the models issue): what a scene's `[model]` table
//! says, parsed once and read by every backend.
//!
//! The expression tree ([`expr`]), with its parser, evaluation, symbolic
//! derivatives (for the sum rule) and text form; the `[model]` table
//! checked and parsed into a [`Model`] ([`table`]); the CPU's compiled
//! evaluator ([`tape`], and its native code as [`native`] describes it:
//! its C text [`c_source`], built by [`c_compiler`], loaded by [`c_loop`])
//! and the GPU's generated system file ([`wgsl`]), both printed from the
//! lowered tapes by one printer ([`print`]), with
//! sin, cos and tan computed by the same arithmetic on both ([`math64`]); and
//! `model check`'s report ([`describe`]). `system::model` and
//! `system::section` make a compiled model a system like the hand-written
//! one (Hénon's map).

pub mod c_compiler;
pub mod c_loop;
pub mod c_source;
pub mod code;
pub mod describe;
pub mod expr;
pub mod math64;
pub mod native;
pub mod print;
pub mod table;
pub mod tape;
pub mod wgsl;

pub use table::{Event, Map, Model};

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
