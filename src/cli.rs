//! The vocabulary every command shares, so that one word means one thing everywhere:
//!
//! - `--data DIR`: the dataset a command reads. `phi render`, `phi dataset stats`, `export` and
//!   `import` took it as a positional argument before; that form still works for this release,
//!   with a warning ([`dataset_dir`]);
//! - `--out`: what a command writes (`phi dataset merge` took it as its first positional
//!   argument before, see [`crate::dataset::cli`]);
//! - `--split NAME`: a split of the dataset, checked against the splits its `metadata.json`
//!   lists ([`split_len`]), which are `train`, `valid` and `test` for a dataset of `phi dataset
//!   generate`, and whatever an imported metadata.json lists;
//! - `--trajectories N`: how many trajectories; `--trajectory I`: which one (an index into the
//!   split); `--frame-every N`: a picture every N frames, steps or iterations.

use std::path::{Path, PathBuf};

use anyhow::{Result, bail};
use phi_gns::data::Dataset;

/// The dataset directory of a command that takes `--data DIR`, and took it as the positional
/// argument `positional` before: `--data`, else the positional one with a deprecation warning.
/// `command` is the command as users type it (`phi render`).
///
/// # Errors
/// Both given and different, or neither (clap's `required_unless_present` stops that first).
pub(crate) fn dataset_dir(
    command: &str,
    data: Option<PathBuf>,
    positional: Option<PathBuf>,
) -> Result<PathBuf> {
    match (data, positional) {
        (Some(data), None) => Ok(data),
        (None, Some(positional)) => {
            tracing::warn!(
                "`{command} DATA` is deprecated and goes in the next release: pass --data {}",
                positional.display()
            );
            Ok(positional)
        }
        (Some(data), Some(positional)) if data == positional => Ok(data),
        (Some(data), Some(positional)) => bail!(
            "--data {} and the positional dataset {} differ; pass --data only (the positional \
             form is deprecated)",
            data.display(),
            positional.display()
        ),
        (None, None) => bail!("no dataset: pass --data DIR"),
    }
}

/// The value parser of `--split`: a split is a folder of the dataset, so a name with a path
/// separator, `.` or `..` is refused before any file is read. Whether the dataset has it is
/// [`split_len`]'s question.
///
/// # Errors
/// The message clap prints after the flag.
pub(crate) fn parse_split(name: &str) -> Result<String, String> {
    if name.is_empty() || name == "." || name == ".." || name.contains(['/', '\\']) {
        return Err(format!(
            "{name:?} is not a split name; use train, valid, test or another split the \
             dataset's metadata.json lists"
        ));
    }
    Ok(name.to_string())
}

/// The number of trajectories of `--split split` in `dataset` (read from `dir`).
///
/// # Errors
/// A split the metadata does not list, naming `--split` and the splits it lists.
pub(crate) fn split_len(dataset: &Dataset, dir: &Path, split: &str) -> Result<usize> {
    match dataset.metadata().splits.get(split) {
        Some(&count) => Ok(count),
        None => {
            let known: Vec<&str> = dataset
                .metadata()
                .splits
                .keys()
                .map(String::as_str)
                .collect();
            bail!(
                "--split {split}: {} has no such split; its metadata.json lists {}",
                dir.display(),
                if known.is_empty() {
                    "none".to_string()
                } else {
                    known.join(", ")
                }
            )
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn data_wins_and_agrees_with_the_positional_form() {
        let a = PathBuf::from("a");
        assert_eq!(dataset_dir("phi x", Some(a.clone()), None).unwrap(), a);
        assert_eq!(dataset_dir("phi x", None, Some(a.clone())).unwrap(), a);
        assert_eq!(
            dataset_dir("phi x", Some(a.clone()), Some(a.clone())).unwrap(),
            a
        );
        let err = dataset_dir("phi x", Some(a), Some("b".into())).unwrap_err();
        assert!(err.to_string().contains("differ"), "{err}");
    }

    #[test]
    fn split_names_are_folder_names() {
        assert_eq!(parse_split("valid").unwrap(), "valid");
        assert_eq!(parse_split("holdout_2").unwrap(), "holdout_2");
        for bad in ["", ".", "..", "a/b", "a\\b"] {
            assert!(parse_split(bad).is_err(), "{bad:?}");
        }
    }
}
