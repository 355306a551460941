//! [`IoError`], the one error type of this crate: every error about a file names it.

use std::path::{Path, PathBuf};

/// Errors of the file formats of this crate.
#[derive(Debug, thiserror::Error)]
pub enum IoError {
    /// An operating-system I/O operation on `path` failed.
    #[error("{action} '{path}': {source}", path = path.display())]
    Io {
        /// The file (or directory) involved.
        path: PathBuf,
        /// What was being done, e.g. "cannot create".
        action: &'static str,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// A file exists but its content is not valid: truncated, damaged or not of the expected
    /// format.
    #[error("'{path}' is corrupt or truncated: {reason}", path = path.display())]
    Corrupt {
        /// The file that was read.
        path: PathBuf,
        /// What is wrong with it.
        reason: String,
    },
    /// A file (or in-memory buffer) is valid but uses a feature that this module does not
    /// support, such as an unsupported dtype or ZIP compression method.
    #[error("'{path}': unsupported: {reason}", path = path.display())]
    Unsupported {
        /// The file that was read (`<memory>` for in-memory buffers).
        path: PathBuf,
        /// What is not supported.
        reason: String,
    },
    /// An in-memory `.npy` buffer given to [`crate::npy::read_npy_bytes`] is invalid.
    #[error("invalid .npy data: {reason}")]
    InvalidNpy {
        /// What is wrong with it.
        reason: String,
    },
    /// An array's shape does not match the number of elements of its data.
    #[error("array shape {shape:?} does not fit data of {len} elements")]
    ShapeMismatch {
        /// The shape.
        shape: Vec<usize>,
        /// The number of elements in the data.
        len: usize,
    },
    /// An archive has no array of the name asked for.
    #[error("'{path}' has no array named '{name}'", path = path.display())]
    MissingArray {
        /// The archive.
        path: PathBuf,
        /// The name of the array.
        name: String,
    },
    /// The arguments of a function are inconsistent (wrong lengths, bad names, ...).
    #[error("invalid input: {0}")]
    InvalidInput(String),
}

impl IoError {
    /// Wraps an I/O error with the path and the action that failed.
    pub fn io(path: &Path, action: &'static str, source: std::io::Error) -> Self {
        IoError::Io {
            path: path.to_path_buf(),
            action,
            source,
        }
    }

    /// A [`IoError::Corrupt`] error for `path`.
    pub fn corrupt(path: &Path, reason: impl Into<String>) -> Self {
        IoError::Corrupt {
            path: path.to_path_buf(),
            reason: reason.into(),
        }
    }
}
