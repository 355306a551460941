//! Reading TOML files (scenes, optimisations, random-scene parameters, training presets) with
//! errors that name the file, the key and the problem.

use std::path::Path;

use serde::de::DeserializeOwned;

/// A TOML file that cannot be read or parsed, or a value of the wrong type or an unknown key in
/// it.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{path}: {key}: {reason}")]
pub struct TomlError {
    /// The file (or the name given to a text).
    pub path: String,
    /// The dotted path of the value at fault (`domain.resolution`, `liquid[1].geometry`), the
    /// unknown key, `(file)` when the file cannot be read, or the line and column where the
    /// parser stopped.
    pub key: String,
    /// What is wrong.
    pub reason: String,
}

/// The text of the file at `path` and the name its errors use.
///
/// # Errors
/// [`TomlError`] with key `(file)` when the file cannot be read.
pub fn read_toml_text(path: &Path) -> Result<(String, String), TomlError> {
    let name = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| TomlError {
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
/// [`TomlError`] for a syntax error, an unknown key or a value of the wrong type.
pub fn parse_toml<T: DeserializeOwned>(text: &str, origin: &str) -> Result<T, TomlError> {
    let deserializer = toml::Deserializer::parse(text).map_err(|e| TomlError {
        path: origin.into(),
        key: location(text, e.span()),
        reason: shorten_quoted(e.message()),
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
        TomlError {
            path: origin.into(),
            key: shorten(&key, ECHO_LIMIT),
            reason: shorten_quoted(&reason),
        }
    })
}

/// The most characters of a value from the input that an error message repeats.
const ECHO_LIMIT: usize = 80;

/// `text`, or its first `max` characters and its length when longer.
fn shorten(text: &str, max: usize) -> String {
    match text.char_indices().nth(max) {
        None => text.to_string(),
        Some((cut, _)) => format!("{}… ({} bytes)", &text[..cut], text.len()),
    }
}

/// `reason` with every `quoted` value longer than [`ECHO_LIMIT`] shortened: the parsers quote
/// the unknown key or variant they met, which may be anything the file holds.
fn shorten_quoted(reason: &str) -> String {
    let mut out = String::with_capacity(reason.len().min(4 * ECHO_LIMIT));
    let mut rest = reason;
    while let Some(open) = rest.find('`') {
        out.push_str(&rest[..=open]);
        let after = &rest[open + 1..];
        match after.find('`') {
            Some(close) => {
                out.push_str(&shorten(&after[..close], ECHO_LIMIT));
                out.push('`');
                rest = &after[close + 1..];
            }
            None => {
                out.push_str(&shorten(after, ECHO_LIMIT));
                rest = "";
            }
        }
    }
    out.push_str(&shorten(rest, 4 * ECHO_LIMIT));
    out
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

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    struct Inner {
        #[allow(dead_code)]
        steps: u32,
    }

    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    struct Outer {
        #[allow(dead_code)]
        training: Inner,
    }

    #[test]
    fn errors_name_the_key_the_unknown_key_or_the_place() {
        let wrong_type = parse_toml::<Outer>("[training]\nsteps = \"many\"\n", "a.toml");
        let e = wrong_type.unwrap_err();
        assert_eq!(
            (e.path.as_str(), e.key.as_str()),
            ("a.toml", "training.steps")
        );
        let unknown = parse_toml::<Outer>("[training]\nsteps = 1\nstep = 2\n", "a.toml");
        let e = unknown.unwrap_err();
        assert!(e.reason.contains("unknown field `step`"), "{e}");
        let syntax = parse_toml::<Outer>("[training]\nsteps = = 1\n", "a.toml").unwrap_err();
        assert_eq!(syntax.key, "line 2, column 9");
        let missing = read_toml_text(Path::new("/nonexistent/phi.toml")).unwrap_err();
        assert_eq!(missing.key, "(file)");
    }

    #[test]
    fn a_huge_unknown_key_is_echoed_once_and_shortened() {
        let key = "k".repeat(1_000_000);
        let e = parse_toml::<Outer>(&format!("[training]\nsteps = 1\n{key} = 2\n"), "a.toml")
            .unwrap_err();
        let message = e.to_string();
        assert!(message.len() < 2_000, "{} bytes", message.len());
        assert!(message.contains("(1000000 bytes)"), "{message}");
        assert!(message.contains("unknown field `kkkk"), "{message}");
        let e = parse_toml::<Outer>(&format!("{key} = 2\n"), "a.toml").unwrap_err();
        assert_eq!(
            e.key,
            format!("{}… (1000000 bytes)", "k".repeat(ECHO_LIMIT))
        );
        assert!(e.to_string().len() < 2_000);
    }
}
