//! The ways a run can fail before it produces numbers.
//!
//! Every variant names the scene key (or flag) it is about, so the message a
//! user sees points at the line to fix. Failures *inside* a lane (NaN,
//! chattering) are not errors: they are reported per lane in the `status`
//! column and never stop the other lanes.

use std::path::PathBuf;

/// An error that stops a run before anything is written.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The scene file could not be read.
    #[error("cannot read scene {path}: {source}")]
    ReadScene {
        path: PathBuf,
        source: std::io::Error,
    },
    /// The scene is not valid TOML, or a key has the wrong type or is
    /// unknown. `key` is that key, when the message names one (it also
    /// heads `message`); TOML that does not parse has none.
    #[error("scene {path}: {message}")]
    Syntax {
        path: String,
        key: Option<String>,
        message: String,
    },
    /// A key is present and well typed but its value is impossible. Both
    /// are cut to a length a message can show when written (either may
    /// quote the input), and kept whole for code that matches keys.
    #[error("{}: {}", clip_to(.key, 200), clip_to(.reason, 1000))]
    Invalid { key: String, reason: String },
    /// The requested backend cannot run this scene.
    #[error("run.backend = \"{backend}\": {reason}")]
    Backend { backend: String, reason: String },
    /// Results given to `plot` or `merge` are missing, malformed, or do not
    /// belong together.
    #[error("{path}: {reason}")]
    Results { path: PathBuf, reason: String },
    /// The output folder cannot take the run's files (found before any
    /// computation): it is a file, holds files lyapsweep does not write (or
    /// data files without a manifest), is or holds an input, or cannot be
    /// created.
    #[error("cannot write {path}: {reason}")]
    Output { path: PathBuf, reason: String },
    /// The run is larger than this machine can hold (or than one process
    /// should attempt): the keys that set its size, the estimate, and how to
    /// split it.
    #[error("{keys}: {reason}")]
    TooLarge { keys: String, reason: String },
    /// The file given to `model check` is not a model file: a scene with a
    /// built-in system, or with no model at all.
    #[error("{path}: {reason}")]
    NotAModel { path: PathBuf, reason: String },
    /// Every lane failed (no exponents from any): the files were written,
    /// with each lane's status, but the run is not a result.
    #[error("every lane failed ({reasons}): see the status column of the output")]
    AllLanesFailed { reasons: String },
    /// The run was asked to stop (see [`crate::method::Stop`]) before it
    /// ended: its lanes are not results, and nothing was written.
    #[error("the run was stopped before it ended; nothing was written")]
    Stopped,
    /// Writing the output failed.
    #[error("cannot write {path}: {source}")]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
}

impl Error {
    /// An impossible value for `key`.
    pub fn invalid(key: impl Into<String>, reason: impl Into<String>) -> Self {
        Error::Invalid {
            key: key.into(),
            reason: reason.into(),
        }
    }

    /// The scene key (or flag) the error is about, as it heads the
    /// message: for code that points at it, such as the Python package's
    /// exceptions.
    pub fn key(&self) -> Option<&str> {
        match self {
            Error::Syntax { key, .. } => key.as_deref(),
            Error::Invalid { key, .. } => Some(key),
            Error::TooLarge { keys, .. } => Some(keys),
            Error::Backend { .. } => Some("run.backend"),
            _ => None,
        }
    }

    /// Whether the error is the user's input (exit code 2) rather than the machine's.
    pub fn is_input_error(&self) -> bool {
        !matches!(
            self,
            Error::Write { .. } | Error::AllLanesFailed { .. } | Error::Stopped
        )
    }
}

pub type Result<T> = std::result::Result<T, Error>;

/// A number as messages and the output's files write it: Rust's shortest
/// text that reads back to the same f64, in exponent form where the plain
/// form would be absurdly long (|v| ≥ 1e16, or nonzero |v| < 1e-5: `1e300`,
/// not 301 digits). Ordinary numbers keep their plain form, so files of
/// ordinary runs are unchanged to the byte.
pub fn number(v: f64) -> String {
    if v.is_finite() && v != 0.0 && !(1e-5..1e16).contains(&v.abs()) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

/// Characters of the user's text (a key, a name, an assignment) a message
/// echoes: enough to recognise it, where a mistyped 1 MB key echoed whole
/// would bury the message.
pub const ECHO_CHARS: usize = 60;

/// `text` as a message echoes it: its first [`ECHO_CHARS`] characters, and
/// "…" when there were more.
pub fn clip(text: &str) -> std::borrow::Cow<'_, str> {
    clip_to(text, ECHO_CHARS)
}

/// `text` cut to its first `most` characters, and "…" when there were more.
pub fn clip_to(text: &str, most: usize) -> std::borrow::Cow<'_, str> {
    match text.char_indices().nth(most) {
        Some((end, _)) => format!("{}…", &text[..end]).into(),
        None => text.into(),
    }
}

/// A message of serde's or toml's, its quoted parts (`name`, "name")
/// clipped, as they quote the user's text, and the whole cut at twenty
/// times that.
pub fn clip_quoted(message: &str) -> String {
    let mut out = String::new();
    let mut rest = message;
    while let Some(start) = rest.find(['`', '"']) {
        let quote = rest[start..].chars().next().expect("found");
        let inner = &rest[start + 1..];
        let Some(len) = inner.find(quote) else {
            break;
        };
        out.push_str(&rest[..=start]);
        out.push_str(&clip(&inner[..len]));
        out.push(quote);
        rest = &inner[len + 1..];
    }
    out.push_str(rest);
    clip_to(&out, 20 * ECHO_CHARS).into_owned()
}
