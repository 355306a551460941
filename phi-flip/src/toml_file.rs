//! Reading the TOML files of this crate (scenes, optimisations, random-scene parameters) with
//! errors that name the file, the key and the problem.

use std::path::Path;

use serde::de::DeserializeOwned;

use crate::error::{FlipError, Result};

/// The text of the file at `path` and the name its errors use.
///
/// # Errors
/// [`FlipError::Scene`] with key `(file)` when the file cannot be read.
pub(crate) fn read(path: &Path) -> Result<(String, String)> {
    let name = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| FlipError::Scene {
        path: name.clone(),
        key: "(file)".into(),
        reason: e.to_string(),
    })?;
    Ok((text, name))
}

/// `T` from TOML `text`; `origin` names the source in errors. The key of an error is the dotted
/// path of the value at fault; at the document level it is the unknown key the message names, or
/// the line and column.
///
/// # Errors
/// [`FlipError::Scene`] for a syntax error, an unknown key or a value of the wrong type.
pub(crate) fn parse<T: DeserializeOwned>(text: &str, origin: &str) -> Result<T> {
    let deserializer = toml::Deserializer::parse(text).map_err(|e| FlipError::Scene {
        path: origin.into(),
        key: location(text, e.span()),
        reason: e.message().to_string(),
    })?;
    serde_path_to_error::deserialize(deserializer).map_err(|e| {
        let path = e.path().to_string();
        let inner = e.into_inner();
        let reason = inner.message().to_string();
        let key = if path != "." {
            path
        } else if let Some(unknown) = reason
            .strip_prefix("unknown field `")
            .and_then(|rest| rest.split('`').next())
        {
            unknown.to_string()
        } else {
            location(text, inner.span())
        };
        FlipError::Scene {
            path: origin.into(),
            key,
            reason,
        }
    })
}

/// `line L, column C` of a byte span in `text`.
fn location(text: &str, span: Option<std::ops::Range<usize>>) -> String {
    match span {
        Some(span) => {
            let before = &text[..span.start.min(text.len())];
            let line = before.matches('\n').count() + 1;
            let column = before.len() - before.rfind('\n').map_or(0, |i| i + 1) + 1;
            format!("line {line}, column {column}")
        }
        None => "(document)".into(),
    }
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
