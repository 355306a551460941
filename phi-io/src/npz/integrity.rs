//! The checks that the zip crate leaves out.
//!
//! ZIP keeps no checksum over its central directory, and the zip crate believes it: the
//! directory alone says which entries exist, under which names, where their data lies and how it
//! is compressed. One damaged byte there would rename an array, hide it, or point at another
//! array's data, and the reader would answer "has no array named 'x'" about an array that is in
//! the file. Everything the directory says is also said by one other record, so these checks
//! compare the two and call any disagreement corruption:
//!
//! - the end records (the end-of-central-directory record and, for ZIP64 archives, its locator
//!   and the ZIP64 end record) say where the directory lies, how long it is and how many entries
//!   it holds: the entries must fill exactly that span, and the two entry counts must agree;
//! - each entry's local header, in front of its data, repeats its name, compression method,
//!   flags and CRC-32 (and its sizes, unless they follow the data).
//!
//! The end records are also read before the zip crate reads them, so that a damaged entry count
//! or ZIP64 offset is refused before the zip crate allocates for it or searches for it.

use std::fs::File;
use std::io::{self, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use crate::IoError;

const LOCAL_HEADER_SIG: u32 = 0x0403_4b50;
const CENTRAL_HEADER_SIG: u32 = 0x0201_4b50;
const EOCD_SIG: u32 = 0x0605_4b50;
const ZIP64_EOCD_SIG: u32 = 0x0606_4b50;
const ZIP64_LOCATOR_SIG: u32 = 0x0706_4b50;
/// The fixed part of an end-of-central-directory record, a central directory entry, a local
/// header, a ZIP64 end locator and a ZIP64 end record (bytes).
const EOCD_LEN: u64 = 22;
const CENTRAL_HEADER_LEN: u64 = 46;
const LOCAL_HEADER_LEN: u64 = 30;
const ZIP64_LOCATOR_LEN: u64 = 20;
const ZIP64_EOCD_LEN: u64 = 56;
/// General purpose flags: encrypted, sizes and CRC-32 in a data descriptor after the data, UTF-8
/// name.
pub(crate) const FLAG_ENCRYPTED: u16 = 1;
const FLAG_DATA_DESCRIPTOR: u16 = 1 << 3;
const FLAG_UTF8: u16 = 1 << 11;
/// A 32-bit size whose value lives in the ZIP64 extra field.
const ZIP64_MARKER: u32 = u32::MAX;

fn le16(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([b[at], b[at + 1]])
}

fn le32(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

fn le64(b: &[u8], at: usize) -> u64 {
    let mut a = [0u8; 8];
    a.copy_from_slice(&b[at..at + 8]);
    u64::from_le_bytes(a)
}

/// The archive file, read at given offsets; a read past its end is a "truncated" error.
pub(crate) struct RawFile {
    file: File,
    len: u64,
    path: PathBuf,
}

impl RawFile {
    /// `file` may share its cursor with the zip crate's reader (a cloned handle): every read here
    /// seeks first, as every read of the zip crate does.
    pub(crate) fn new(file: File, path: &Path) -> Result<Self, IoError> {
        let len = file
            .metadata()
            .map_err(|e| IoError::io(path, "cannot read the metadata of", e))?
            .len();
        Ok(RawFile {
            file,
            len,
            path: path.to_path_buf(),
        })
    }

    pub(crate) fn path(&self) -> &Path {
        &self.path
    }

    pub(crate) fn corrupt(&self, reason: impl Into<String>) -> IoError {
        IoError::corrupt(&self.path, reason)
    }

    /// The `len` bytes at `offset`.
    pub(crate) fn read_at(
        &mut self,
        offset: u64,
        len: u64,
        what: &str,
    ) -> Result<Vec<u8>, IoError> {
        if offset.checked_add(len).is_none_or(|end| end > self.len) {
            return Err(self.corrupt(format!(
                "{what} ({len} bytes at offset {offset}) extends past the end of the file ({} \
                 bytes)",
                self.len
            )));
        }
        // `len` is at most the file's length, so the buffer is bounded by real data.
        let mut buf = vec![0u8; len as usize];
        self.file
            .seek(SeekFrom::Start(offset))
            .and_then(|_| self.file.read_exact(&mut buf))
            .map_err(|e| {
                if e.kind() == io::ErrorKind::UnexpectedEof {
                    self.corrupt(format!("{what}: unexpected end of file"))
                } else {
                    IoError::io(&self.path, "cannot read", e)
                }
            })?;
        Ok(buf)
    }
}

/// Where the central directory lies, as the end records say.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Directory {
    /// The number of entries.
    pub(crate) count: u64,
    /// The offset of the first entry.
    pub(crate) offset: u64,
    /// The length in bytes; the end records start right after.
    pub(crate) size: u64,
}

/// Reads and checks the end records: the directory must end where the end records begin, hold
/// room for its entries, and count them the same way twice.
pub(crate) fn read_directory_span(raw: &mut RawFile) -> Result<Directory, IoError> {
    if raw.len < EOCD_LEN {
        return Err(raw.corrupt(format!("{} bytes are too few for a ZIP archive", raw.len)));
    }
    let tail_len = raw.len.min(EOCD_LEN + u64::from(u16::MAX));
    let tail_start = raw.len - tail_len;
    let tail = raw.read_at(tail_start, tail_len, "end of archive")?;
    let sig = EOCD_SIG.to_le_bytes();
    let eocd_len = EOCD_LEN as usize;
    // The record is followed by its comment and nothing else.
    let found = (0..=tail.len() - eocd_len).rev().find(|&i| {
        tail[i..i + 4] == sig && i + eocd_len + usize::from(le16(&tail, i + 20)) == tail.len()
    });
    let Some(i) = found else {
        return Err(
            raw.corrupt("no end-of-central-directory record (not a ZIP archive, or truncated)")
        );
    };
    let eocd = &tail[i..i + eocd_len];
    let eocd_pos = tail_start + i as u64;
    if le16(eocd, 4) != 0 || le16(eocd, 6) != 0 {
        return Err(raw.corrupt(
            "the end record names a disk other than the first (multi-disk archives are not \
             supported)",
        ));
    }
    let (on_disk, total) = (u64::from(le16(eocd, 8)), u64::from(le16(eocd, 10)));
    let mut directory = Directory {
        count: total,
        size: u64::from(le32(eocd, 12)),
        offset: u64::from(le32(eocd, 16)),
    };
    let mut counts = (on_disk, total);
    let mut end_records_start = eocd_pos;
    // Like the zip crate and Python's zipfile, a ZIP64 end locator in front of the record means
    // that the ZIP64 end record holds the real values.
    let locator_pos = eocd_pos.checked_sub(ZIP64_LOCATOR_LEN);
    let locator = match locator_pos {
        Some(pos) => Some(raw.read_at(pos, ZIP64_LOCATOR_LEN, "ZIP64 end locator")?),
        None => None,
    };
    if let Some(locator) = locator.filter(|l| le32(l, 0) == ZIP64_LOCATOR_SIG) {
        let record_pos = le64(&locator, 8);
        if le32(&locator, 4) != 0 || le32(&locator, 16) > 1 {
            return Err(raw.corrupt(
                "the ZIP64 end locator names another disk (multi-disk archives are not \
                 supported)",
            ));
        }
        // The record lies between the directory and the locator.
        if record_pos
            .checked_add(ZIP64_EOCD_LEN)
            .is_none_or(|end| end > eocd_pos - ZIP64_LOCATOR_LEN)
        {
            return Err(raw.corrupt(format!(
                "the ZIP64 end locator points at offset {record_pos}, past the end records"
            )));
        }
        let record = raw.read_at(record_pos, ZIP64_EOCD_LEN, "ZIP64 end record")?;
        if le32(&record, 0) != ZIP64_EOCD_SIG {
            return Err(raw.corrupt(format!(
                "no ZIP64 end record at offset {record_pos}, where the locator points"
            )));
        }
        if le32(&record, 16) != 0 || le32(&record, 20) != 0 {
            return Err(raw.corrupt(
                "the ZIP64 end record names another disk (multi-disk archives are not \
                 supported)",
            ));
        }
        counts = (le64(&record, 24), le64(&record, 32));
        directory = Directory {
            count: counts.1,
            size: le64(&record, 40),
            offset: le64(&record, 48),
        };
        end_records_start = record_pos;
    }
    if counts.0 != counts.1 {
        return Err(raw.corrupt(format!(
            "the end record counts {} entries on this disk but {} in all",
            counts.0, counts.1
        )));
    }
    if directory.offset.checked_add(directory.size) != Some(end_records_start) {
        return Err(raw.corrupt(format!(
            "the central directory ({} bytes at offset {}) does not end where the end records \
             begin (offset {end_records_start})",
            directory.size, directory.offset
        )));
    }
    if directory.count > directory.size / CENTRAL_HEADER_LEN {
        return Err(raw.corrupt(format!(
            "{} entries do not fit in a central directory of {} bytes",
            directory.count, directory.size
        )));
    }
    Ok(directory)
}

/// What the zip crate read of one entry from the central directory.
pub(crate) struct ZipEntry {
    /// The name as stored, undecoded.
    pub(crate) name_raw: Vec<u8>,
    /// The name, decoded (UTF-8 or code page 437, by the entry's flag).
    pub(crate) name: String,
    pub(crate) central_header_start: u64,
    pub(crate) header_start: u64,
    pub(crate) data_start: u64,
    pub(crate) compressed_size: u64,
    pub(crate) size: u64,
    pub(crate) crc32: u32,
}

/// What the checks learn of an entry beyond what the zip crate tells.
pub(crate) struct CheckedEntry {
    /// The compression method (0 stored, 8 deflate, ...).
    pub(crate) method: u16,
    /// The general purpose flags.
    pub(crate) flags: u16,
    /// Where the entry's central directory record ends: where the next one must start.
    pub(crate) central_end: u64,
}

/// Checks one entry: its directory record starts at `expected_start` (right after the previous
/// one) and its local header agrees with it; its data lies in front of the directory.
pub(crate) fn check_entry(
    raw: &mut RawFile,
    directory: &Directory,
    entry: &ZipEntry,
    expected_start: u64,
) -> Result<CheckedEntry, IoError> {
    let name = &entry.name;
    if entry.central_header_start != expected_start {
        return Err(raw.corrupt(format!(
            "the directory record of entry '{name}' starts at offset {} instead of {expected_start}",
            entry.central_header_start
        )));
    }
    let central = raw.read_at(
        entry.central_header_start,
        CENTRAL_HEADER_LEN,
        "central directory record",
    )?;
    if le32(&central, 0) != CENTRAL_HEADER_SIG {
        return Err(raw.corrupt(format!("entry '{name}': invalid central directory record")));
    }
    let (flags, method, crc) = (le16(&central, 8), le16(&central, 10), le32(&central, 16));
    let record_len = CENTRAL_HEADER_LEN
        + u64::from(le16(&central, 28))
        + u64::from(le16(&central, 30))
        + u64::from(le16(&central, 32));
    let central_end = entry.central_header_start + record_len;
    let directory_end = directory.offset + directory.size;
    if central_end > directory_end {
        return Err(raw.corrupt(format!(
            "the directory record of entry '{name}' runs past the end of the central directory"
        )));
    }

    let local = raw.read_at(entry.header_start, LOCAL_HEADER_LEN, "local file header")?;
    if le32(&local, 0) != LOCAL_HEADER_SIG {
        return Err(raw.corrupt(format!(
            "entry '{name}': no local file header at offset {}",
            entry.header_start
        )));
    }
    let local_name = raw.read_at(
        entry.header_start + LOCAL_HEADER_LEN,
        u64::from(le16(&local, 26)),
        "local file name",
    )?;
    let mismatch = |what: &str, central: String, local: String| {
        IoError::corrupt(
            &raw.path,
            format!(
                "entry '{name}': the central directory and the local header disagree on the \
                 {what} ({central} against {local})"
            ),
        )
    };
    if local_name != entry.name_raw {
        return Err(mismatch(
            "name",
            format!("'{name}'"),
            format!("'{}'", String::from_utf8_lossy(&local_name)),
        ));
    }
    let local_flags = le16(&local, 6);
    if (local_flags ^ flags) & (FLAG_ENCRYPTED | FLAG_UTF8) != 0 {
        return Err(mismatch(
            "flags",
            format!("{flags:#06x}"),
            format!("{local_flags:#06x}"),
        ));
    }
    let local_method = le16(&local, 8);
    if local_method != method {
        return Err(mismatch(
            "compression method",
            method.to_string(),
            local_method.to_string(),
        ));
    }
    // With a data descriptor the local header holds zeros; ZIP64 sizes live in its extra field.
    if local_flags & FLAG_DATA_DESCRIPTOR == 0 {
        let local_crc = le32(&local, 14);
        if local_crc != crc {
            return Err(mismatch(
                "CRC-32",
                format!("{crc:#010x}"),
                format!("{local_crc:#010x}"),
            ));
        }
        let (local_compressed, local_size) = (le32(&local, 18), le32(&local, 22));
        if local_compressed != ZIP64_MARKER
            && local_size != ZIP64_MARKER
            && (u64::from(local_compressed), u64::from(local_size))
                != (entry.compressed_size, entry.size)
        {
            return Err(mismatch(
                "sizes",
                format!("{} compressed, {}", entry.compressed_size, entry.size),
                format!("{local_compressed} compressed, {local_size}"),
            ));
        }
    }
    if entry
        .data_start
        .checked_add(entry.compressed_size)
        .is_none_or(|end| end > directory.offset)
    {
        return Err(raw.corrupt(format!(
            "the data of entry '{name}' ({} bytes at offset {}) runs into the central directory \
             at offset {}",
            entry.compressed_size, entry.data_start, directory.offset
        )));
    }
    Ok(CheckedEntry {
        method,
        flags,
        central_end,
    })
}

/// Checks that the entries filled the whole directory: `end` is where the last record ended.
pub(crate) fn check_directory_filled(
    raw: &RawFile,
    directory: &Directory,
    end: u64,
) -> Result<(), IoError> {
    let directory_end = directory.offset + directory.size;
    if end != directory_end {
        return Err(raw.corrupt(format!(
            "the {} directory records end at offset {end}, but the central directory ends at \
             offset {directory_end}",
            directory.count
        )));
    }
    Ok(())
}
