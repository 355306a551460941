//! Writing `.npz` archives through the zip crate's writer: STORED entries with a fixed date, ZIP64
//! size fields where an entry may reach 4 GiB.

use std::collections::HashSet;
use std::io::{self, Seek, Write};
use std::path::Path;

use zip::result::ZipError;
use zip::write::FileOptions;
use zip::{CompressionMethod, DateTime, ZipWriter};

use crate::npy::{NpyArray, npy_header};
use crate::pickle::object_array_npy;
use crate::{IoError, write_all, write_atomic};

/// Where an archive is written: the zip crate seeks back to fill in each entry's CRC-32 and sizes
/// once its data is written, so the sink must seek.
pub(crate) trait Sink: Write + Seek {}

impl<T: Write + Seek> Sink for T {}

/// The `.npy` size from which an entry needs the ZIP64 size fields: the 32-bit fields top out
/// below it, and `0xFFFF_FFFF` itself is the marker that sends readers to the ZIP64 fields.
const ZIP64_ENTRY_SIZE: u64 = u32::MAX as u64;

/// The options of every entry: STORED, so that the bytes of an array lie in the file as they are
/// and can be read (or mapped) without inflating; dated 1980-01-01 00:00:00 (the earliest date a
/// ZIP can hold), so that the same arrays always give the same bytes; `rw-r--r--`.
fn entry_options(zip64: bool) -> FileOptions {
    FileOptions::default()
        .compression_method(CompressionMethod::Stored)
        .last_modified_time(DateTime::default())
        .unix_permissions(0o644)
        .large_file(zip64)
}

/// A failed write of the zip crate as an [`IoError::Io`] naming `path`.
fn write_error(path: &Path, err: ZipError) -> IoError {
    let source = match err {
        ZipError::Io(e) => e,
        other => io::Error::other(other.to_string()),
    };
    IoError::io(path, "cannot write", source)
}

/// Writes a `.npz` archive one array at a time, so that an archive larger than memory can be
/// written: each [`NpzWriter::add`] writes one STORED entry, and the central directory (a few
/// dozen bytes per entry) is kept until the end. Get one from [`write_npz_streamed`].
pub struct NpzWriter<'a> {
    zip: ZipWriter<&'a mut dyn Sink>,
    path: &'a Path,
    /// Every entry carries ZIP64 size fields, needed or not (tests use this to exercise ZIP64 on
    /// small files).
    force_zip64: bool,
    names: HashSet<String>,
}

impl<'a> NpzWriter<'a> {
    pub(crate) fn new(sink: &'a mut dyn Sink, path: &'a Path, force_zip64: bool) -> Self {
        NpzWriter {
            zip: ZipWriter::new(sink),
            path,
            force_zip64,
            names: HashSet::new(),
        }
    }

    /// Appends the array `array` as the entry `name.npy`.
    ///
    /// Fails on an empty, too long or repeated name, on an array whose shape does not fit its
    /// data, and on I/O errors (naming the path).
    pub fn add(&mut self, name: &str, array: &NpyArray) -> Result<(), IoError> {
        let path = self.path;
        check_entry(name, array, path)?;
        if !self.names.insert(name.to_string()) {
            return Err(IoError::InvalidInput(format!(
                "'{}': array name '{name}' appears twice",
                path.display()
            )));
        }
        let header = npy_header(array);
        let size = array.npy_size(&header).ok_or_else(|| {
            IoError::InvalidInput(format!("'{}': archive too large", path.display()))
        })?;
        let zip64 = self.force_zip64 || size >= ZIP64_ENTRY_SIZE;
        self.zip
            .start_file(format!("{name}.npy"), entry_options(zip64))
            .map_err(|e| write_error(path, e))?;
        write_all(&mut self.zip, &header, path)?;
        array
            .data
            .for_each_le_chunk(|chunk| write_all(&mut self.zip, chunk, path))
    }

    /// Appends a one-dimensional array of Python objects holding the numeric arrays `items` as
    /// the entry `name.npy` (see [`crate::pickle`]); `numpy.load(path, allow_pickle=True)[name]`
    /// gives an object array of `len(items)` numpy arrays.
    ///
    /// Fails as [`NpzWriter::add`] does, and as [`crate::pickle::object_array_npy`] does.
    pub fn add_object_array(&mut self, name: &str, items: &[&NpyArray]) -> Result<(), IoError> {
        let path = self.path;
        let bytes = object_array_npy(items).map_err(|e| {
            IoError::InvalidInput(format!("'{}': array '{name}': {e}", path.display()))
        })?;
        check_name(name, path)?;
        if !self.names.insert(name.to_string()) {
            return Err(IoError::InvalidInput(format!(
                "'{}': array name '{name}' appears twice",
                path.display()
            )));
        }
        let zip64 = self.force_zip64 || bytes.len() as u64 >= ZIP64_ENTRY_SIZE;
        self.zip
            .start_file(format!("{name}.npy"), entry_options(zip64))
            .map_err(|e| write_error(path, e))?;
        write_all(&mut self.zip, &bytes, path)
    }

    /// Writes the central directory and the end records (ZIP64 ones past 4 GiB or 65,535
    /// entries).
    pub(crate) fn finish(mut self) -> Result<(), IoError> {
        self.zip.finish().map_err(|e| write_error(self.path, e))?;
        Ok(())
    }
}

/// Writes the `.npz` archive `path` atomically, array by array: `fill` calls
/// [`NpzWriter::add`] for each array, and only one array needs to be in memory at a time.
/// On any error (of `fill` or of writing) `path` is left untouched.
///
/// ```
/// # let dir = std::env::temp_dir().join(format!("phi-doc-npz-streamed-{}", std::process::id()));
/// # std::fs::create_dir_all(&dir).unwrap();
/// use phi_io::npz::{NpyArray, read_npz, write_npz_streamed};
/// let path = dir.join("many.npz");
/// write_npz_streamed(&path, |npz| {
///     for i in 0..3i64 {
///         npz.add(&format!("a{i}"), &NpyArray::from_vec(vec![i]))?;
///     }
///     Ok::<(), phi_io::IoError>(())
/// })?;
/// assert_eq!(read_npz(&path)?.len(), 3);
/// # std::fs::remove_dir_all(&dir).unwrap();
/// # Ok::<(), phi_io::IoError>(())
/// ```
pub fn write_npz_streamed<E: From<IoError>>(
    path: impl AsRef<Path>,
    fill: impl FnOnce(&mut NpzWriter<'_>) -> Result<(), E>,
) -> Result<(), E> {
    let path = path.as_ref();
    write_atomic(path, |w| {
        let mut npz = NpzWriter::new(w, path, false);
        fill(&mut npz)?;
        npz.finish()?;
        Ok(())
    })
}

/// Checks an entry's name: not empty, not too long for a ZIP entry.
fn check_name(name: &str, path: &Path) -> Result<(), IoError> {
    let bad = |why: &str| {
        IoError::InvalidInput(format!("'{}': array name '{name}' {why}", path.display()))
    };
    if name.is_empty() {
        return Err(bad("is empty"));
    }
    if name.len() + 4 > usize::from(u16::MAX) {
        return Err(bad("is too long"));
    }
    Ok(())
}

/// Checks one array and its name before it is written.
fn check_entry(name: &str, array: &NpyArray, path: &Path) -> Result<(), IoError> {
    check_name(name, path)?;
    array
        .validate()
        .map_err(|e| IoError::InvalidInput(format!("'{}': array '{name}': {e}", path.display())))
}

/// Checks the arrays and their names before anything is written.
fn check_entries(entries: &[(&str, &NpyArray)], path: &Path) -> Result<(), IoError> {
    let mut seen = HashSet::new();
    for &(name, array) in entries {
        check_entry(name, array, path)?;
        if !seen.insert(name) {
            return Err(IoError::InvalidInput(format!(
                "'{}': array name '{name}' appears twice",
                path.display()
            )));
        }
    }
    Ok(())
}

/// Writes the arrays to the `.npz` archive `path`, one STORED entry `name.npy` each, in order,
/// as `numpy.savez(path, name=array, ...)` would; `numpy.load(path)[name]` gives them back.
///
/// The file is written atomically: into `.{filename}.tmp-{pid}` in the same directory, synced,
/// then renamed to `path`. ZIP64 extensions are used for entries or archives of 4 GiB and more.
/// The same arrays always give the same bytes. Fails on empty or duplicate names, on arrays whose
/// shape does not fit their data, and on I/O errors (naming the path); on failure `path` is left
/// untouched.
pub fn write_npz<S: AsRef<str>>(
    path: impl AsRef<Path>,
    arrays: &[(S, &NpyArray)],
) -> Result<(), IoError> {
    write_npz_impl(path.as_ref(), arrays, false)
}

/// [`write_npz`], with ZIP64 size fields on every entry when `force_zip64` is set.
pub(crate) fn write_npz_impl<S: AsRef<str>>(
    path: &Path,
    arrays: &[(S, &NpyArray)],
    force_zip64: bool,
) -> Result<(), IoError> {
    let entries: Vec<(&str, &NpyArray)> = arrays
        .iter()
        .map(|(name, array)| (name.as_ref(), *array))
        .collect();
    check_entries(&entries, path)?;
    write_atomic(path, |w| write_archive(w, &entries, path, force_zip64))
}

/// Writes the arrays to `sink` as a `.npz` (ZIP) archive.
pub(crate) fn write_archive(
    sink: &mut dyn Sink,
    entries: &[(&str, &NpyArray)],
    path: &Path,
    force_zip64: bool,
) -> Result<(), IoError> {
    let mut npz = NpzWriter::new(sink, path, force_zip64);
    for &(name, array) in entries {
        npz.add(name, array)?;
    }
    npz.finish()
}
