//! Atomic file writing: a file appears complete under its name or not at all.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use crate::IoError;

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
mod tests {
    use super::*;

    #[test]
    fn atomic_write_replaces_file_and_leaves_no_temp() {
        let dir = crate::test_util::temp_dir("atomic");
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
        let dir = crate::test_util::temp_dir("atomic-fail");
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
