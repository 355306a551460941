//! Reading `.npz` archives through the zip crate's reader, with the directory checked first
//! ([`super::integrity`]).

use std::fs::File;
use std::io::{self, BufReader, Read};
use std::path::Path;

use zip::ZipArchive;
use zip::result::ZipError;

use super::integrity::{self, CheckedEntry, FLAG_ENCRYPTED, RawFile, ZipEntry};
use crate::IoError;
use crate::npy::{
    NPY_PREAMBLE_MAX, NpyArray, NpyHeader, npy_issue_error, parse_npy, parse_npy_header,
};

const METHOD_STORED: u16 = 0;
const METHOD_DEFLATED: u16 = 8;

/// One `.npy` entry of an archive.
struct Entry {
    /// Its index in the zip crate's list.
    index: usize,
    /// The entry's name, `name.npy`.
    name: String,
    method: u16,
    compressed_size: u64,
    size: u64,
    /// Where its data starts in the file.
    data_start: u64,
    /// The CRC-32 of its uncompressed bytes, as the directory records it.
    crc32: u32,
}

/// An error of the zip crate while reading the archive `path`.
fn zip_error(path: &Path, err: ZipError) -> IoError {
    match err {
        // A regular file gives these for reads past its end and seeks to offsets no file has.
        ZipError::Io(e) if e.kind() == io::ErrorKind::UnexpectedEof => {
            IoError::corrupt(path, "unexpected end of file")
        }
        ZipError::Io(e) if e.kind() == io::ErrorKind::InvalidInput => {
            IoError::corrupt(path, format!("an offset lies outside any file ({e})"))
        }
        ZipError::Io(e) => IoError::io(path, "cannot read", e),
        ZipError::InvalidArchive(why) => IoError::corrupt(path, why),
        ZipError::UnsupportedArchive(why) => IoError::Unsupported {
            path: path.to_path_buf(),
            reason: why.to_string(),
        },
        ZipError::FileNotFound => {
            IoError::corrupt(path, "an entry of the central directory cannot be found")
        }
    }
}

/// Random access to the arrays of one `.npz` archive: the central directory is read and checked
/// on [`NpzReader::open`], and [`NpzReader::read`] then reads (and CRC-checks) only the entry
/// asked for, so a few small arrays of a large archive cost a few small reads.
///
/// ```
/// # let dir = std::env::temp_dir().join(format!("phi-doc-npz-reader-{}", std::process::id()));
/// # std::fs::create_dir_all(&dir).unwrap();
/// use phi_io::npz::{NpyArray, NpzReader, write_npz};
/// let path = dir.join("a.npz");
/// let big = NpyArray::from_vec(vec![0f32; 1000]);
/// let small = NpyArray::from_vec(vec![7i64]);
/// write_npz(&path, &[("big", &big), ("small", &small)])?;
/// let mut npz = NpzReader::open(&path)?;
/// assert_eq!(npz.names().collect::<Vec<_>>(), ["big", "small"]);
/// assert_eq!(npz.read("small")?.as_i64(), Some(&[7i64][..]));
/// # std::fs::remove_dir_all(&dir).unwrap();
/// # Ok::<(), phi_io::IoError>(())
/// ```
pub struct NpzReader {
    zip: ZipArchive<BufReader<File>>,
    /// The same open file, for the checks and for reading `.npy` headers in place.
    raw: RawFile,
    /// The `.npy` entries (directory entries left out), in archive order.
    entries: Vec<Entry>,
}

impl NpzReader {
    /// Opens the archive, reads its central directory and checks it against the end records and
    /// every entry's local header.
    ///
    /// Fails with [`IoError::Corrupt`] (naming the file) on truncated or damaged archives,
    /// including a damaged central directory, [`IoError::Unsupported`] on entries that are not
    /// `.npy` arrays or are encrypted, and [`IoError::Io`] on I/O errors.
    pub fn open(path: impl AsRef<Path>) -> Result<Self, IoError> {
        let path = path.as_ref();
        let file = File::open(path).map_err(|e| IoError::io(path, "cannot open", e))?;
        // One open file for both readers, so that both read the same file even if `path` is
        // replaced meanwhile.
        let zip_file = file
            .try_clone()
            .map_err(|e| IoError::io(path, "cannot open", e))?;
        let mut raw = RawFile::new(file, path)?;
        let directory = integrity::read_directory_span(&mut raw)?;
        let mut zip = ZipArchive::new(BufReader::new(zip_file)).map_err(|e| zip_error(path, e))?;
        if zip.len() as u64 != directory.count {
            return Err(raw.corrupt(format!(
                "the central directory holds {} entries, the end record counts {}",
                zip.len(),
                directory.count
            )));
        }
        let mut entries = Vec::with_capacity(zip.len());
        let mut next_record = directory.offset;
        for index in 0..zip.len() {
            let entry = {
                let file = zip.by_index_raw(index).map_err(|e| zip_error(path, e))?;
                ZipEntry {
                    name_raw: file.name_raw().to_vec(),
                    name: file.name().to_string(),
                    central_header_start: file.central_header_start(),
                    header_start: file.header_start(),
                    data_start: file.data_start(),
                    compressed_size: file.compressed_size(),
                    size: file.size(),
                    crc32: file.crc32(),
                }
            };
            let CheckedEntry {
                method,
                flags,
                central_end,
            } = integrity::check_entry(&mut raw, &directory, &entry, next_record)?;
            next_record = central_end;
            // Directory entries hold nothing.
            if entry.name.ends_with('/') {
                continue;
            }
            if !entry.name.ends_with(".npy") {
                return Err(IoError::Unsupported {
                    path: path.to_path_buf(),
                    reason: format!("entry '{}' is not a .npy array", entry.name),
                });
            }
            if flags & FLAG_ENCRYPTED != 0 {
                return Err(IoError::Unsupported {
                    path: path.to_path_buf(),
                    reason: format!("entry '{}' is encrypted", entry.name),
                });
            }
            entries.push(Entry {
                index,
                name: entry.name,
                method,
                compressed_size: entry.compressed_size,
                size: entry.size,
                data_start: entry.data_start,
                crc32: entry.crc32,
            });
        }
        integrity::check_directory_filled(&raw, &directory, next_record)?;
        Ok(NpzReader { zip, raw, entries })
    }

    /// The file this reader reads.
    pub fn path(&self) -> &Path {
        self.raw.path()
    }

    /// The names of the arrays (without the `.npy` suffix), in archive order.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.entries
            .iter()
            .map(|entry| entry.name.strip_suffix(".npy").unwrap_or(&entry.name))
    }

    /// Whether the archive holds an array called `name`.
    pub fn contains(&self, name: &str) -> bool {
        self.names().any(|n| n == name)
    }

    /// Reads the array `name`, checking the entry's CRC-32.
    ///
    /// Fails with [`IoError::MissingArray`] when there is no such array, and otherwise as
    /// [`read_npz`] does.
    pub fn read(&mut self, name: &str) -> Result<NpyArray, IoError> {
        let index = self.index_of(name)?;
        self.read_index(index)
    }

    /// The `.npy` bytes of the entry `name` as they are (header and data), its CRC-32 checked:
    /// for entries [`NpzReader::read`] does not decode, such as object arrays.
    ///
    /// Fails with [`IoError::MissingArray`] when there is no such array.
    pub fn read_npy_bytes(&mut self, name: &str) -> Result<Vec<u8>, IoError> {
        let index = self.index_of(name)?;
        self.entry_bytes(index)
    }

    /// Reads the `index`-th array in archive order.
    fn read_index(&mut self, index: usize) -> Result<NpyArray, IoError> {
        let bytes = self.entry_bytes(index)?;
        let entry = &self.entries[index];
        parse_npy(&bytes).map_err(|issue| {
            npy_issue_error(self.raw.path(), &format!("entry '{}'", entry.name), issue)
        })
    }

    /// Reads and inflates one entry; the zip crate checks its CRC-32 at its end.
    fn entry_bytes(&mut self, index: usize) -> Result<Vec<u8>, IoError> {
        let entry = &self.entries[index];
        let name = &entry.name;
        match entry.method {
            METHOD_STORED if entry.size != entry.compressed_size => {
                return Err(self.raw.corrupt(format!(
                    "stored entry '{name}' has different compressed ({}) and uncompressed ({}) \
                     sizes",
                    entry.compressed_size, entry.size
                )));
            }
            METHOD_STORED => {}
            // Deflate expands at most ~1032:1; a larger claim is damage.
            METHOD_DEFLATED
                if entry.size
                    > entry
                        .compressed_size
                        .saturating_mul(1032)
                        .saturating_add(1024) =>
            {
                return Err(self.raw.corrupt(format!(
                    "entry '{name}' claims {} bytes from {} compressed bytes",
                    entry.size, entry.compressed_size
                )));
            }
            METHOD_DEFLATED => {}
            method => {
                return Err(IoError::Unsupported {
                    path: self.raw.path().to_path_buf(),
                    reason: format!(
                        "entry '{name}' uses ZIP compression method {method} (only stored and \
                         deflate are supported)"
                    ),
                });
            }
        }
        let path = self.raw.path();
        let mut file = self
            .zip
            .by_index(entry.index)
            .map_err(|e| zip_error(path, e))?;
        // A stored entry's size is bounded by the file's length; a deflated one's claim is only
        // believed as far as the data inflates.
        let capacity = match entry.method {
            METHOD_STORED => entry.size,
            _ => entry.size.min(entry.compressed_size.saturating_mul(8)),
        };
        let mut out = Vec::with_capacity(capacity as usize);
        (&mut file)
            .take(entry.size.saturating_add(1))
            .read_to_end(&mut out)
            .map_err(|e| entry_read_error(path, entry, e))?;
        if out.len() as u64 != entry.size {
            return Err(IoError::corrupt(
                path,
                format!(
                    "entry '{name}' holds {} bytes instead of {}",
                    out.len(),
                    entry.size
                ),
            ));
        }
        Ok(out)
    }

    /// The dtype and shape of the array `name`, without reading its data when the entry is
    /// stored (not compressed): only the `.npy` header is read, and the entry's size is checked
    /// against it, but its CRC-32 is not (that needs all the data; [`NpzReader::read`] checks it).
    pub fn header(&mut self, name: &str) -> Result<NpyHeader, IoError> {
        let index = self.index_of(name)?;
        let entry = &self.entries[index];
        let what = format!("entry '{}'", entry.name);
        let (prefix, size) = if entry.method == METHOD_STORED {
            let (offset, size) = (entry.data_start, entry.compressed_size);
            let header_of = format!("header of {what}");
            let preamble =
                self.raw
                    .read_at(offset, size.min(NPY_PREAMBLE_MAX as u64), &header_of)?;
            let header_end = match preamble.get(6..12) {
                Some([1, _, a, b, ..]) => 10 + u64::from(u16::from_le_bytes([*a, *b])),
                Some([2 | 3, _, a, b, c, d]) => {
                    12 + u64::from(u32::from_le_bytes([*a, *b, *c, *d]))
                }
                _ => preamble.len() as u64,
            };
            let prefix = self.raw.read_at(offset, header_end.min(size), &header_of)?;
            (prefix, size)
        } else {
            let bytes = self.entry_bytes(index)?;
            let size = bytes.len() as u64;
            (bytes, size)
        };
        let path = self.raw.path();
        let parsed =
            parse_npy_header(&prefix).map_err(|issue| npy_issue_error(path, &what, issue))?;
        if parsed.encoded_len() != Some(size) {
            return Err(IoError::corrupt(
                path,
                format!(
                    "{what}: shape {:?} of '{}' does not fit the entry's {size} bytes",
                    parsed.shape, parsed.descr
                ),
            ));
        }
        Ok(NpyHeader {
            descr: parsed.descr,
            shape: parsed.shape,
        })
    }

    fn index_of(&self, name: &str) -> Result<usize, IoError> {
        self.names()
            .position(|n| n == name)
            .ok_or_else(|| IoError::MissingArray {
                path: self.raw.path().to_path_buf(),
                name: name.to_string(),
            })
    }

    /// Reads every array, in archive order, named without the `.npy` suffix.
    pub fn read_all(&mut self) -> Result<Vec<(String, NpyArray)>, IoError> {
        let names: Vec<String> = self.names().map(str::to_string).collect();
        let mut arrays = Vec::with_capacity(names.len());
        for (index, name) in names.into_iter().enumerate() {
            arrays.push((name, self.read_index(index)?));
        }
        Ok(arrays)
    }
}

/// An error while reading the data of entry `name`. The zip crate reports a CRC-32 mismatch as
/// an error of kind `Other` ("Invalid checksum") and bad deflate data as `InvalidInput` or
/// `InvalidData`; the operating system's errors have kinds of their own.
fn entry_read_error(path: &Path, entry: &Entry, err: io::Error) -> IoError {
    let name = &entry.name;
    match err.kind() {
        io::ErrorKind::Other if err.to_string() == "Invalid checksum" => IoError::corrupt(
            path,
            format!(
                "entry '{name}': CRC-32 mismatch (the data does not give the recorded {:#010x})",
                entry.crc32
            ),
        ),
        io::ErrorKind::Other
        | io::ErrorKind::InvalidInput
        | io::ErrorKind::InvalidData
        | io::ErrorKind::UnexpectedEof => {
            IoError::corrupt(path, format!("entry '{name}': invalid data: {err}"))
        }
        _ => IoError::io(path, "cannot read", err),
    }
}

/// Reads the `.npz` archive `path`: its arrays in archive order, named without the `.npy`
/// suffix.
///
/// Reads what [`super::write_npz`], `numpy.savez` and `numpy.savez_compressed` write: STORED or
/// deflate-compressed entries, with or without ZIP64 extensions. Every entry's CRC-32 is checked.
/// Fails with [`IoError::Corrupt`] (naming the file) on truncated or damaged archives,
/// [`IoError::Unsupported`] on entries that are not `.npy` arrays of a supported dtype or use
/// another compression method, and [`IoError::Io`] on I/O errors.
pub fn read_npz(path: impl AsRef<Path>) -> Result<Vec<(String, NpyArray)>, IoError> {
    NpzReader::open(path)?.read_all()
}
