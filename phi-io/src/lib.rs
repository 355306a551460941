//! Files: NumPy arrays and archives ([`npz`]) and the atomic writing they share.
//!
//! Every fallible function returns [`IoError`]; errors about a file name it. Files that are written
//! in one go ([`npz::write_npz`], [`npz::write_npy`], and anything written through
//! [`write_atomic`]) are written atomically: into a temporary file `.{filename}.tmp-{pid}` in the
//! same directory, which is flushed to disk and then renamed over the destination, so that readers
//! never see a half-written file.

pub mod npz;

use std::fs::File;
use std::io::{BufWriter, Write};
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
    /// An in-memory `.npy` buffer given to [`npz::read_npy_bytes`] is invalid.
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

/// The temporary file used by [`write_atomic`] for `path`: `.{filename}.tmp-{pid}` in the same
/// directory.
fn temp_path(path: &Path) -> Result<PathBuf, IoError> {
    let name = path.file_name().ok_or_else(|| {
        IoError::InvalidInput(format!("'{}' does not name a file", path.display()))
    })?;
    let mut temp_name = std::ffi::OsString::from(".");
    temp_name.push(name);
    temp_name.push(format!(".tmp-{}", std::process::id()));
    Ok(path.with_file_name(temp_name))
}

/// Writes a file atomically: `write` fills a temporary file in the destination's directory,
/// which is then flushed, synced to disk and renamed to `path`. On failure the temporary file is
/// removed and `path` is left untouched.
///
/// Generic in the error type so that callers with their own error enum (holding an
/// [`IoError`] variant) can use it with their own closures.
///
/// The temporary name depends only on the process id, so two threads of one process must not
/// write the same destination at the same time.
///
/// ```
/// # let dir = std::env::temp_dir().join(format!("phi-doc-atomic-{}", std::process::id()));
/// # std::fs::create_dir_all(&dir).unwrap();
/// use phi_io::{IoError, write_all, write_atomic};
/// let path = dir.join("hello.txt");
/// write_atomic(&path, |w| write_all(w, b"hello", &path))?;
/// assert_eq!(std::fs::read(&path).unwrap(), b"hello");
/// # std::fs::remove_dir_all(&dir).unwrap();
/// # Ok::<(), IoError>(())
/// ```
pub fn write_atomic<E: From<IoError>>(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> Result<(), E>,
) -> Result<(), E> {
    let temp = temp_path(path)?;
    let result = (|| {
        let file = File::create(&temp).map_err(|e| IoError::io(&temp, "cannot create", e))?;
        let mut writer = BufWriter::new(file);
        write(&mut writer)?;
        let file = writer
            .into_inner()
            .map_err(|e| IoError::io(&temp, "cannot write", e.into_error()))?;
        file.sync_all()
            .map_err(|e| IoError::io(&temp, "cannot sync", e))?;
        drop(file);
        std::fs::rename(&temp, path)
            .map_err(|e| IoError::io(path, "cannot rename a temporary file to", e))?;
        Ok(())
    })();
    match result {
        Ok(()) => {
            sync_parent_dir(path);
            Ok(())
        }
        Err(err) => {
            // Best effort: the temporary file may not even exist.
            let _ = std::fs::remove_file(&temp);
            Err(err)
        }
    }
}

/// Best effort: syncs the directory holding `path` so that a rename survives a power loss.
/// Errors are ignored (not every platform lets directories be opened or synced).
fn sync_parent_dir(path: &Path) {
    #[cfg(unix)]
    {
        let parent = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p,
            _ => Path::new("."),
        };
        if let Ok(dir) = File::open(parent) {
            let _ = dir.sync_all();
        }
    }
    #[cfg(not(unix))]
    let _ = path;
}

/// Writes all of `bytes`, mapping errors to [`IoError::Io`] naming `path`.
pub fn write_all(w: &mut (impl Write + ?Sized), bytes: &[u8], path: &Path) -> Result<(), IoError> {
    w.write_all(bytes)
        .map_err(|e| IoError::io(path, "cannot write", e))
}

#[cfg(test)]
pub(crate) mod test_util {
    use std::path::PathBuf;

    /// A fresh, empty directory under the system's temporary directory for one test.
    pub fn temp_dir(test: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("phi-io-test-{}-{test}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("create test directory");
        dir
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn atomic_write_replaces_file_and_leaves_no_temp() {
        let dir = test_util::temp_dir("atomic");
        let path = dir.join("out.bin");
        std::fs::write(&path, b"old").unwrap();
        write_atomic(&path, |w| write_all(w, b"new", &path)).unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"new");
        let names: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from("out.bin")]);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn failed_atomic_write_keeps_old_file() {
        let dir = test_util::temp_dir("atomic-fail");
        let path = dir.join("out.bin");
        std::fs::write(&path, b"old").unwrap();
        let err = write_atomic(&path, |_| Err(IoError::InvalidInput("boom".into())));
        assert!(err.is_err());
        assert_eq!(std::fs::read(&path).unwrap(), b"old");
        assert!(!temp_path(&path).unwrap().exists());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn io_errors_name_the_path() {
        let path = Path::new("/nonexistent-dir-for-phi-tests/x.npz");
        let err = write_atomic(path, |_| Ok::<(), IoError>(())).unwrap_err();
        let msg = err.to_string();
        assert!(msg.contains("/nonexistent-dir-for-phi-tests/"), "{msg}");
    }
}
