//! Reading the TOML files of this crate (scenes, optimisations, random-scene parameters): phi-io's
//! reader with its errors as [`FlipError::Scene`].

use std::path::Path;

use serde::de::DeserializeOwned;

use crate::error::{FlipError, Result};

impl From<phi_io::TomlError> for FlipError {
    fn from(e: phi_io::TomlError) -> Self {
        FlipError::Scene {
            path: e.path,
            key: e.key,
            reason: e.reason,
        }
    }
}

/// The text of the file at `path` and the name its errors use.
///
/// # Errors
/// [`FlipError::Scene`] with key `(file)` when the file cannot be read.
pub(crate) fn read(path: &Path) -> Result<(String, String)> {
    Ok(phi_io::read_toml_text(path)?)
}

/// `T` from TOML `text`; `origin` names the source in errors (see [`phi_io::parse_toml`]).
///
/// # Errors
/// [`FlipError::Scene`] for a syntax error, an unknown key or a value of the wrong type.
pub(crate) fn parse<T: DeserializeOwned>(text: &str, origin: &str) -> Result<T> {
    Ok(phi_io::parse_toml(text, origin)?)
}

/// `error` with its key moved under `prefix` (`domain.resolution` → `scene.domain.resolution`),
/// for a file embedded in another.
pub(crate) fn under(prefix: &str, error: FlipError) -> FlipError {
    match error {
        FlipError::Scene { path, key, reason } => FlipError::Scene {
            path,
            key: format!("{prefix}.{key}"),
            reason,
        },
        other => other,
    }
}
