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

/// Writes `value` as pretty-printed JSON with a final newline, atomically ([`write_atomic`]).
///
/// # Errors
/// [`IoError::InvalidInput`] naming `path` when `value` cannot be encoded (a map with
/// non-string keys); [`IoError::Io`] when the file cannot be written.
pub fn write_json(path: &Path, value: &impl serde::Serialize) -> Result<(), IoError> {
    let mut text = serde_json::to_vec_pretty(value).map_err(|e| {
        IoError::InvalidInput(format!("'{}': cannot encode as JSON: {e}", path.display()))
    })?;
    text.push(b'\n');
    write_atomic(path, |w| write_all(w, &text, path))
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

/// The process id in the name of a temporary file of [`write_atomic`] (`.{filename}.tmp-{pid}`),
/// or `None` for other names.
pub fn temp_file_pid(name: &str) -> Option<u32> {
    let rest = name.strip_prefix('.')?;
    let (stem, pid) = rest.rsplit_once(".tmp-")?;
    if stem.is_empty() || pid.is_empty() || !pid.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    pid.parse().ok()
}

/// Whether the process `pid` may still be writing: true unless it is known to have ended. On
/// systems with `/proc` a process whose entry is gone has ended (this process is alive); elsewhere
/// nothing is known and every process may be alive.
fn may_be_running(pid: u32) -> bool {
    if pid == std::process::id() {
        return true;
    }
    let proc = Path::new("/proc");
    !proc.join("self").exists() || proc.join(pid.to_string()).exists()
}

/// Removes the temporary files of [`write_atomic`] in `dir` that a process which has ended left
/// behind (a killed writer leaves its `.{filename}.tmp-{pid}`, often empty); files of processes
/// that may still be running are kept. Returns the files removed, sorted. A missing `dir` holds
/// none.
///
/// # Errors
/// [`IoError::Io`] when `dir` cannot be listed or a file cannot be removed.
pub fn remove_stale_temp_files(dir: &Path) -> Result<Vec<PathBuf>, IoError> {
    let entries = match std::fs::read_dir(dir) {
        Ok(entries) => entries,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(IoError::io(dir, "cannot list", e)),
    };
    let mut removed = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|e| IoError::io(dir, "cannot list", e))?;
        let Some(pid) = entry.file_name().to_str().and_then(temp_file_pid) else {
            continue;
        };
        let path = entry.path();
        if may_be_running(pid) || !path.is_file() {
            continue;
        }
        match std::fs::remove_file(&path) {
            Ok(()) => removed.push(path),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => {
                return Err(IoError::io(
                    &path,
                    "cannot remove the stale temporary file",
                    e,
                ));
            }
        }
    }
    removed.sort();
    Ok(removed)
}

/// A fresh staging directory next to `target` (`.{name}.staging-{pid}` in its parent), for
/// [`publish_dir`]: a command that writes a whole directory fills it, then publishes it, so that
/// `target` is never left half-written. A staging directory left by an earlier attempt of this
/// process id is removed first.
///
/// # Errors
/// [`IoError::InvalidInput`] when `target` names no directory, [`IoError::Io`] when the
/// directory cannot be made.
pub fn staging_dir(target: &Path) -> Result<PathBuf, IoError> {
    let name = target.file_name().ok_or_else(|| {
        IoError::InvalidInput(format!("'{}' does not name a directory", target.display()))
    })?;
    let mut staging_name = std::ffi::OsString::from(".");
    staging_name.push(name);
    staging_name.push(format!(".staging-{}", std::process::id()));
    let staging = target.with_file_name(staging_name);
    if staging.exists() {
        std::fs::remove_dir_all(&staging)
            .map_err(|e| IoError::io(&staging, "cannot remove the old staging directory", e))?;
    }
    std::fs::create_dir_all(&staging)
        .map_err(|e| IoError::io(&staging, "cannot create the directory", e))?;
    Ok(staging)
}

/// Moves the finished directory `staging` (from [`staging_dir`]) to `target`. A `target` that
/// exists (an empty directory, or one the caller was told to replace) is first renamed aside and
/// removed only once `staging` is in place, so `target` holds either all of the old content or
/// all of the new.
///
/// # Errors
/// [`IoError::Io`] when a rename fails; `target` then still holds its old content.
pub fn publish_dir(staging: &Path, target: &Path) -> Result<(), IoError> {
    let old = if target.exists() {
        let mut old_name = staging.file_name().unwrap_or_default().to_os_string();
        old_name.push(".old");
        let old = staging.with_file_name(old_name);
        std::fs::rename(target, &old)
            .map_err(|e| IoError::io(target, "cannot move aside the old content of", e))?;
        Some(old)
    } else {
        None
    };
    if let Err(e) = std::fs::rename(staging, target) {
        if let Some(old) = &old {
            let _ = std::fs::rename(old, target);
        }
        return Err(IoError::io(target, "cannot move the new content into", e));
    }
    sync_parent_dir(target);
    if let Some(old) = old {
        std::fs::remove_dir_all(&old)
            .map_err(|e| IoError::io(&old, "cannot remove the replaced content", e))?;
    }
    Ok(())
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
    fn json_reads_back_and_an_unencodable_value_names_the_file() {
        let dir = crate::test_util::temp_dir("atomic-json");
        let path = dir.join("record.json");
        let value = std::collections::BTreeMap::from([("steps", 3.5f64), ("loss", -1e-9)]);
        write_json(&path, &value).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.ends_with("}\n"), "{text}");
        let back: std::collections::BTreeMap<String, f64> = serde_json::from_str(&text).unwrap();
        assert_eq!(back["steps"], 3.5);
        assert_eq!(back["loss"], -1e-9);
        // JSON object keys must be strings: a map keyed by tuples cannot be written, and the
        // file keeps what it held.
        let bad = std::collections::BTreeMap::from([((1, 2), 0.0)]);
        let err = write_json(&path, &bad).unwrap_err().to_string();
        assert!(err.contains("record.json") && err.contains("JSON"), "{err}");
        assert_eq!(std::fs::read_to_string(&path).unwrap(), text);
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
    fn stale_temp_files_of_ended_processes_are_removed() {
        let dir = crate::test_util::temp_dir("atomic-stale");
        // A process id above Linux's maximum (2^22) has never run; this process is running.
        let stale = dir.join(".traj_00000.npz.tmp-4194305");
        let live = dir.join(format!(".traj_00001.npz.tmp-{}", std::process::id()));
        let other = dir.join("traj_00000.npz");
        for path in [&stale, &live, &other] {
            std::fs::write(path, b"").unwrap();
        }
        let removed = remove_stale_temp_files(&dir).unwrap();
        if Path::new("/proc/self").exists() {
            assert_eq!(removed, vec![stale.clone()]);
            assert!(!stale.exists());
        } else {
            assert!(removed.is_empty());
        }
        assert!(live.exists() && other.exists());
        assert_eq!(temp_file_pid(".a.npz.tmp-12"), Some(12));
        assert_eq!(temp_file_pid("a.npz.tmp-12"), None);
        assert_eq!(temp_file_pid(".a.npz.tmp-"), None);
        assert!(
            remove_stale_temp_files(&dir.join("missing"))
                .unwrap()
                .is_empty()
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_published_directory_replaces_the_old_one_whole() {
        let dir = crate::test_util::temp_dir("atomic-publish");
        let target = dir.join("data");
        std::fs::create_dir_all(target.join("train")).unwrap();
        std::fs::write(target.join("old.txt"), b"old").unwrap();
        let staging = staging_dir(&target).unwrap();
        std::fs::write(staging.join("new.txt"), b"new").unwrap();
        assert!(target.join("old.txt").exists(), "untouched until published");
        publish_dir(&staging, &target).unwrap();
        assert!(!staging.exists());
        assert!(!target.join("old.txt").exists() && !target.join("train").exists());
        assert_eq!(std::fs::read(target.join("new.txt")).unwrap(), b"new");
        let names: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from("data")]);
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
