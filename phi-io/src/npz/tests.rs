//! Tests of `.npz` writing and reading: round trips, determinism, ZIP64, files of the earlier
//! writer and of numpy, and damaged files (truncated, flipped bytes anywhere, in particular in
//! the central directory).

use std::io::{Cursor, Read, Seek, SeekFrom, Write};
use std::process::Command;

use zip::write::FileOptions;
use zip::{CompressionMethod, DateTime, ZipArchive, ZipWriter};

use super::writer::{write_archive, write_npz_impl};
use super::*;
use crate::IoError;
use crate::test_util::{as_refs, sample_arrays, temp_dir};

/// The archives that the earlier hand-written ZIP writer made of [`sample_arrays`], plain and with
/// every ZIP64 field forced; and numpy 2.4's `savez` and `savez_compressed` of the arrays that
/// [`assert_numpy_sample`] expects.
const OLD_WRITER: &[u8] = include_bytes!("../../tests/data/old_writer.npz");
const OLD_WRITER_ZIP64: &[u8] = include_bytes!("../../tests/data/old_writer_zip64.npz");
const NUMPY_SAVEZ: &[u8] = include_bytes!("../../tests/data/numpy_savez.npz");
const NUMPY_SAVEZ_COMPRESSED: &[u8] = include_bytes!("../../tests/data/numpy_savez_compressed.npz");

/// Checks the arrays of the numpy sample: Fortran-ordered, big-endian, bool and scalar arrays
/// among them.
fn assert_numpy_sample(back: &[(String, NpyArray)], what: &str) {
    let names: Vec<&str> = back.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(names, ["a", "b", "c", "d", "e", "f"], "{what}");
    let get = |n: &str| &back.iter().find(|(k, _)| k == n).unwrap().1;
    let a = get("a");
    assert_eq!(a.shape, vec![3, 4]);
    assert_eq!(
        a.as_f32().unwrap(),
        (0..12).map(|i| i as f32).collect::<Vec<_>>()
    );
    let b = get("b");
    assert_eq!(b.shape, vec![2, 3]);
    assert_eq!(b.as_i64().unwrap(), &[0, 1, 2, 3, 4, 5]);
    assert_eq!(get("c").as_f64().unwrap(), &[1.5, -2.5]);
    assert_eq!(get("d").as_u8().unwrap(), &[1, 0, 1]);
    let e = get("e").as_i32().unwrap();
    assert_eq!(e.len(), 1000);
    assert!(e.iter().enumerate().all(|(i, &v)| v == (i % 7) as i32));
    let f = get("f");
    assert!(f.shape.is_empty());
    assert_eq!(f.as_u8().unwrap(), &[7]);
}

/// The offset of the central directory of the archive `bytes` (without a comment), from its end
/// record or, where that holds the ZIP64 marker, from the ZIP64 end record.
fn central_directory_offset(bytes: &[u8]) -> usize {
    let le32 = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap());
    let le64 = |at: usize| u64::from_le_bytes(bytes[at..at + 8].try_into().unwrap());
    let eocd = bytes.len() - 22;
    assert_eq!(le32(eocd), 0x0605_4b50);
    match le32(eocd + 16) {
        u32::MAX => {
            assert_eq!(le32(eocd - 20), 0x0706_4b50);
            let record = le64(eocd - 20 + 8) as usize;
            assert_eq!(le32(record), 0x0606_4b50);
            le64(record + 48) as usize
        }
        offset => offset as usize,
    }
}

/// Damages the archive `bytes` (written to `path`) one byte of `range` at a time, with each of
/// [`MASKS`], and checks that reading it then either gives `expected` or fails with a "corrupt or
/// truncated" error naming the file: never an error about a missing array, an unsupported
/// feature or an I/O error, never other arrays, never a panic. Each damaged archive is read as a
/// dataset reads one: the array `probe` first, then all of them.
fn assert_damage_is_caught(
    path: &std::path::Path,
    bytes: &[u8],
    range: std::ops::Range<usize>,
    expected: &[(String, NpyArray)],
    probe: &str,
) {
    std::fs::write(path, bytes).unwrap();
    let mut file = std::fs::OpenOptions::new().write(true).open(path).unwrap();
    let mut poke = |at: usize, byte: u8| {
        file.seek(SeekFrom::Start(at as u64)).unwrap();
        file.write_all(&[byte]).unwrap();
    };
    let file_name = path.file_name().unwrap().to_str().unwrap();
    let want = &expected.iter().find(|(n, _)| n == probe).unwrap().1;
    for at in range {
        for mask in MASKS {
            poke(at, bytes[at] ^ mask);
            let read =
                NpzReader::open(path).and_then(|mut npz| Ok((npz.read(probe)?, npz.read_all()?)));
            match read {
                Ok((array, all)) => {
                    assert_eq!(&array, want, "byte {at} ^ {mask:#04x}: other '{probe}'");
                    assert_eq!(all, expected, "byte {at} ^ {mask:#04x}: other arrays");
                }
                Err(err @ IoError::Corrupt { .. }) => {
                    let msg = err.to_string();
                    assert!(
                        msg.contains(file_name) && msg.contains("corrupt or truncated"),
                        "byte {at} ^ {mask:#04x}: {msg}"
                    );
                }
                Err(err) => panic!("byte {at} ^ {mask:#04x}: not reported as corrupt: {err}"),
            }
            poke(at, bytes[at]);
        }
    }
}

/// Flipped bits of every kind: the lowest, one in the middle, the highest, all of them.
const MASKS: [u8; 4] = [0x01, 0x10, 0x80, 0xFF];

/// Statistics-like arrays, named as a dataset names them.
fn stats_arrays() -> Vec<(&'static str, NpyArray)> {
    vec![
        (
            "stats_velocity",
            NpyArray::new(vec![2, 2], vec![0.5f64, 1.5, -2.0, 3.0]).unwrap(),
        ),
        (
            "stats_acceleration",
            NpyArray::new(vec![2, 2], vec![0.25f64, -0.75, 4.0, 8.0]).unwrap(),
        ),
        ("index", NpyArray::from_vec(vec![3i64])),
    ]
}

fn owned(arrays: &[(&str, NpyArray)]) -> Vec<(String, NpyArray)> {
    arrays
        .iter()
        .map(|(n, a)| (n.to_string(), a.clone()))
        .collect()
}

#[test]
fn constructors_check_shape() {
    assert!(NpyArray::new(vec![2, 3], vec![0f32; 6]).is_ok());
    let err = NpyArray::new(vec![2, 3], vec![0f32; 5]).unwrap_err();
    assert!(
        matches!(err, IoError::ShapeMismatch { len: 5, .. }),
        "{err}"
    );
    assert!(NpyArray::new(vec![usize::MAX, 3], vec![0u8; 3]).is_err());
    assert_eq!(NpyArray::from_vec(vec![1i64, 2]).shape, vec![2]);
    let bad = NpyArray {
        shape: vec![4],
        data: ArrayData::U8(vec![1]),
    };
    assert!(write_npy_bytes(&bad).is_err());
    let dir = temp_dir("bad-shape");
    let err = write_npz(dir.join("x.npz"), &[("x", &bad)]).unwrap_err();
    assert!(err.to_string().contains("array 'x'"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn npz_round_trip_every_dtype() {
    let dir = temp_dir("npz-round-trip");
    let arrays = sample_arrays();
    for force_zip64 in [false, true] {
        let path = dir.join(format!("data-{force_zip64}.npz"));
        write_npz_impl(&path, &as_refs(&arrays), force_zip64).unwrap();
        let back = read_npz(&path).unwrap();
        assert_eq!(back.len(), arrays.len());
        for ((name, array), (back_name, back_array)) in arrays.iter().zip(&back) {
            assert_eq!(name, back_name);
            assert_eq!(array, back_array, "{name}");
        }
    }
    // An archive with no arrays is valid too.
    let path = dir.join("empty.npz");
    write_npz::<&str>(&path, &[]).unwrap();
    assert!(read_npz(&path).unwrap().is_empty());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn npz_rejects_bad_names() {
    let dir = temp_dir("npz-names");
    let a = NpyArray::from_vec(vec![1u8]);
    let path = dir.join("x.npz");
    assert!(write_npz(&path, &[("a", &a), ("a", &a)]).is_err());
    assert!(write_npz(&path, &[("", &a)]).is_err());
    assert!(!path.exists());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn truncated_npz_is_reported_with_its_path() {
    let dir = temp_dir("npz-truncated");
    let path = dir.join("trunc.npz");
    let arrays = sample_arrays();
    write_npz(&path, &as_refs(&arrays)).unwrap();
    let full = std::fs::read(&path).unwrap();
    for len in 0..full.len() {
        std::fs::write(&path, &full[..len]).unwrap();
        let err = read_npz(&path).expect_err("a truncated archive must not load");
        let msg = err.to_string();
        assert!(msg.contains("trunc.npz"), "{msg}");
        assert!(matches!(err, IoError::Corrupt { .. }), "{msg}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn flipped_byte_is_reported_with_its_path() {
    let dir = temp_dir("npz-flipped");
    let path = dir.join("flip.npz");
    let array = NpyArray::new(vec![4, 2], (0..8).map(|i| i as f32).collect::<Vec<_>>()).unwrap();
    write_npz(&path, &[("x", &array)]).unwrap();
    let good = std::fs::read(&path).unwrap();
    // The data of the only entry starts after the local header (30 bytes + "x.npy") and the
    // 64-byte .npy header.
    let data_start = 30 + 5 + 64;
    let mut bad = good.clone();
    bad[data_start + 5] ^= 0x10;
    std::fs::write(&path, &bad).unwrap();
    let msg = read_npz(&path).unwrap_err().to_string();
    assert!(msg.contains("flip.npz") && msg.contains("CRC-32"), "{msg}");

    // Any single damaged byte either loads (a field the reader ignores, like a timestamp)
    // or gives an error naming the file; it never panics.
    for i in 0..good.len() {
        let mut bad = good.clone();
        bad[i] ^= 0xA5;
        std::fs::write(&path, &bad).unwrap();
        match read_npz(&path) {
            Ok(arrays) if (30 + 5..30 + 5 + 64 + 32).contains(&i) => {
                panic!("damage to the entry at byte {i} went unnoticed: {arrays:?}")
            }
            Ok(_) => {}
            Err(e) => assert!(e.to_string().contains("flip.npz"), "{e}"),
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn missing_file_is_reported_with_its_path() {
    let err = read_npz("/nonexistent/phi-missing.npz")
        .unwrap_err()
        .to_string();
    assert!(err.contains("/nonexistent/phi-missing.npz"), "{err}");
}

fn numpy_available() -> bool {
    Command::new("python3")
        .args(["-c", "import numpy"])
        .output()
        .is_ok_and(|o| o.status.success())
}

fn python(script: &str) -> String {
    let out = Command::new("python3")
        .args(["-c", script])
        .output()
        .expect("run python3");
    assert!(
        out.status.success(),
        "python failed:\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[test]
fn numpy_interop() {
    if !numpy_available() {
        println!("note: skipping numpy_interop, `python3 -c 'import numpy'` failed");
        return;
    }
    let dir = temp_dir("npz-numpy");
    let arrays = sample_arrays();

    // numpy reads what we write, plain and with ZIP64 records.
    for force_zip64 in [false, true] {
        let path = dir.join(format!("ours-{force_zip64}.npz"));
        write_npz_impl(&path, &as_refs(&arrays), force_zip64).unwrap();
        let script = format!(
            r#"
import numpy as np
d = np.load({path:?})
f32 = np.float32
exp = {{
    'positions': np.array([[0.5, -1.25, 3.0], [np.finfo(f32).max, np.finfo(f32).tiny, -0.0]], dtype=f32),
    'f64': np.array([np.pi, -1e300, 1e-300]),
    'i32': np.array([[-2**31, -1], [0, 2**31 - 1]], dtype=np.int32),
    'i64': np.array([[[-2**63, -7], [7, 2**63 - 1]]], dtype=np.int64),
    'kinds': np.array([0, 1, 2, 254, 255], dtype=np.uint8),
    'scalar': np.array(42.0),
    'empty': np.zeros((0, 3), dtype=f32),
}}
assert list(d.keys()) == list(exp.keys()), list(d.keys())
for k, v in exp.items():
    a = d[k]
    assert a.dtype == v.dtype and a.shape == v.shape, (k, a.dtype, a.shape)
    assert np.array_equal(a, v), (k, a, v)
    assert a.flags['C_CONTIGUOUS']
print('ok')
"#,
            path = path.display().to_string()
        );
        assert_eq!(python(&script).trim(), "ok");
    }

    // We read what numpy writes, compressed or not, including Fortran-ordered, big-endian
    // and bool arrays.
    for (func, file) in [("savez", "np.npz"), ("savez_compressed", "npc.npz")] {
        let path = dir.join(file);
        let script = format!(
            r#"
import numpy as np
np.{func}({path:?},
    a=np.arange(12, dtype=np.float32).reshape(3, 4),
    b=np.asfortranarray(np.arange(6, dtype=np.int64).reshape(2, 3)),
    c=np.array([1.5, -2.5], dtype='>f8'),
    d=np.array([True, False, True]),
    e=np.arange(1000, dtype=np.int32) % 7,
    f=np.array(7, dtype=np.uint8))
"#,
            path = path.display().to_string()
        );
        python(&script);
        assert_numpy_sample(&read_npz(&path).unwrap(), func);
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn reader_reads_single_arrays_and_headers() {
    let dir = temp_dir("npz-reader");
    let arrays = sample_arrays();
    for force_zip64 in [false, true] {
        let path = dir.join(format!("r-{force_zip64}.npz"));
        write_npz_impl(&path, &as_refs(&arrays), force_zip64).unwrap();
        let mut npz = NpzReader::open(&path).unwrap();
        let names: Vec<&str> = npz.names().collect();
        assert_eq!(names, arrays.iter().map(|(n, _)| *n).collect::<Vec<_>>());
        // Out of order, one at a time.
        for (name, array) in arrays.iter().rev() {
            assert_eq!(&npz.read(name).unwrap(), array);
            let header = npz.header(name).unwrap();
            assert_eq!(header.shape, array.shape);
            assert_eq!(header.descr, array.data.descr());
        }
        assert!(npz.contains("i64") && !npz.contains("nope"));
        let err = npz.read("nope").unwrap_err();
        assert!(matches!(err, IoError::MissingArray { .. }), "{err}");
        assert!(err.to_string().contains("r-"), "{err}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn header_checks_the_entry_size() {
    let dir = temp_dir("npz-header-size");
    let path = dir.join("h.npz");
    let array = NpyArray::new(vec![4, 2], vec![1.5f32; 8]).unwrap();
    write_npz(&path, &[("a", &array)]).unwrap();
    let mut bytes = std::fs::read(&path).unwrap();
    // Claim a shape of (5, 2) in the header: same header length, wrong data size.
    let at = bytes.windows(6).position(|w| w == b"(4, 2)").unwrap();
    bytes[at + 1] = b'5';
    std::fs::write(&path, &bytes).unwrap();
    let err = NpzReader::open(&path).unwrap().header("a").unwrap_err();
    assert!(matches!(err, IoError::Corrupt { .. }), "{err}");
    assert!(err.to_string().contains("h.npz"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn streamed_writing_matches_write_npz_and_is_atomic() {
    let dir = temp_dir("npz-streamed");
    let arrays = sample_arrays();
    let (one_go, streamed) = (dir.join("one.npz"), dir.join("streamed.npz"));
    write_npz(&one_go, &as_refs(&arrays)).unwrap();
    write_npz_streamed(&streamed, |npz| {
        for (name, array) in &arrays {
            npz.add(name, array)?;
        }
        Ok::<(), IoError>(())
    })
    .unwrap();
    assert_eq!(read_npz(&one_go).unwrap(), read_npz(&streamed).unwrap());

    // A failure half-way leaves the old file in place and no temporary file.
    let err = write_npz_streamed(&streamed, |npz| {
        npz.add("x", &arrays[0].1)?;
        npz.add("x", &arrays[1].1)
    })
    .unwrap_err();
    assert!(err.to_string().contains("appears twice"), "{err}");
    assert_eq!(read_npz(&streamed).unwrap().len(), arrays.len());
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 2);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn same_arrays_give_the_same_bytes_in_stored_entries_of_a_fixed_date() {
    let dir = temp_dir("npz-deterministic");
    let arrays = sample_arrays();
    let (first, second) = (dir.join("first.npz"), dir.join("second.npz"));
    write_npz(&first, &as_refs(&arrays)).unwrap();
    // A second later: no clock may reach the bytes.
    std::thread::sleep(std::time::Duration::from_millis(1100));
    write_npz_streamed(&second, |npz| {
        for (name, array) in &arrays {
            npz.add(name, array)?;
        }
        Ok::<(), IoError>(())
    })
    .unwrap();
    let bytes = std::fs::read(&first).unwrap();
    assert_eq!(bytes, std::fs::read(&second).unwrap());

    // Every entry is STORED, dated 1980-01-01 00:00:00, and its data is the array's .npy
    // encoding as it is, at the offset the directory gives.
    let mut zip = ZipArchive::new(Cursor::new(&bytes)).unwrap();
    assert_eq!(zip.len(), arrays.len());
    for (i, (name, array)) in arrays.iter().enumerate() {
        let entry = zip.by_index_raw(i).unwrap();
        assert_eq!(entry.name(), format!("{name}.npy"));
        assert_eq!(entry.compression(), CompressionMethod::Stored);
        let date = entry.last_modified();
        assert_eq!(
            (date.year(), date.month(), date.day()),
            (1980, 1, 1),
            "{name}"
        );
        assert_eq!((date.hour(), date.minute(), date.second()), (0, 0, 0));
        assert_eq!(entry.unix_mode(), Some(0o100644));
        let npy = write_npy_bytes(array).unwrap();
        let start = entry.data_start() as usize;
        assert_eq!(&bytes[start..start + npy.len()], npy, "{name}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn files_of_the_earlier_writer_and_of_numpy_still_read() {
    let dir = temp_dir("npz-earlier-files");
    let expected = owned(&sample_arrays());
    for (file, bytes) in [("old.npz", OLD_WRITER), ("old-zip64.npz", OLD_WRITER_ZIP64)] {
        let path = dir.join(file);
        std::fs::write(&path, bytes).unwrap();
        assert_eq!(read_npz(&path).unwrap(), expected, "{file}");
        let mut npz = NpzReader::open(&path).unwrap();
        for (name, array) in &expected {
            assert_eq!(npz.header(name).unwrap().shape, array.shape, "{file}");
        }
    }
    for (file, bytes) in [
        ("savez.npz", NUMPY_SAVEZ),
        ("savez_compressed.npz", NUMPY_SAVEZ_COMPRESSED),
    ] {
        let path = dir.join(file);
        std::fs::write(&path, bytes).unwrap();
        assert_numpy_sample(&read_npz(&path).unwrap(), file);
        let mut npz = NpzReader::open(&path).unwrap();
        assert_eq!(npz.header("b").unwrap().shape, vec![2, 3], "{file}");
    }

    // The layout is the earlier writer's but for the "version made by" of each directory record
    // (ZIP 4.6 instead of 4.5, both Unix).
    let path = dir.join("new.npz");
    write_npz(&path, &as_refs(&sample_arrays())).unwrap();
    let new = std::fs::read(&path).unwrap();
    assert_eq!(new.len(), OLD_WRITER.len());
    let differing: Vec<usize> = (0..new.len())
        .filter(|&i| new[i] != OLD_WRITER[i])
        .collect();
    let records: Vec<usize> = new
        .windows(4)
        .enumerate()
        .filter(|(_, w)| *w == b"PK\x01\x02")
        .map(|(i, _)| i + 4)
        .collect();
    assert_eq!(differing, records);
    assert!(records.iter().all(|&i| (OLD_WRITER[i], new[i]) == (45, 46)));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn forced_zip64_archives_are_valid() {
    let dir = temp_dir("npz-zip64");
    let arrays = sample_arrays();
    let path = dir.join("zip64.npz");
    write_npz_impl(&path, &as_refs(&arrays), true).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    // Every local header saturates its sizes and carries the ZIP64 extra field (id 1, 16 bytes:
    // the sizes).
    let mut zip = ZipArchive::new(Cursor::new(&bytes)).unwrap();
    for i in 0..zip.len() {
        let entry = zip.by_index_raw(i).unwrap();
        let at = entry.header_start() as usize;
        let local = &bytes[at..at + 30];
        assert_eq!(&local[18..26], &[0xFF; 8]);
        let name_len = usize::from(u16::from_le_bytes([local[26], local[27]]));
        assert_eq!(u16::from_le_bytes([local[28], local[29]]), 20);
        let extra = &bytes[at + 30 + name_len..at + 30 + name_len + 20];
        assert_eq!(&extra[..4], &[1, 0, 16, 0]);
        let size = entry.size().to_le_bytes();
        assert_eq!((&extra[4..12], &extra[12..20]), (&size[..], &size[..]));
    }
    assert_eq!(read_npz(&path).unwrap(), owned(&arrays));
    let _ = std::fs::remove_dir_all(&dir);
}

/// An in-memory file that keeps only the writes that hold something else than zeros (or
/// overwrite such a write): an archive around gigabytes of zeros, in a few kilobytes.
#[derive(Default)]
struct SparseFile {
    len: u64,
    pos: u64,
    /// Writes in order: (offset, bytes).
    writes: Vec<(u64, Vec<u8>)>,
}

impl SparseFile {
    fn overlaps(&self, start: u64, len: u64) -> bool {
        self.writes
            .iter()
            .any(|(at, bytes)| *at < start + len && start < at + bytes.len() as u64)
    }
}

impl Write for SparseFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let len = buf.len() as u64;
        let zeros = buf
            .chunks(8)
            .all(|c| c.iter().fold(0u8, |acc, &b| acc | b) == 0);
        if !zeros || self.overlaps(self.pos, len) {
            self.writes.push((self.pos, buf.to_vec()));
        }
        self.pos += len;
        self.len = self.len.max(self.pos);
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl Read for SparseFile {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = (self.len.saturating_sub(self.pos)).min(buf.len() as u64) as usize;
        let (start, end) = (self.pos, self.pos + n as u64);
        buf[..n].fill(0);
        for (at, bytes) in &self.writes {
            let (lo, hi) = (start.max(*at), end.min(at + bytes.len() as u64));
            if lo < hi {
                buf[(lo - start) as usize..(hi - start) as usize]
                    .copy_from_slice(&bytes[(lo - at) as usize..(hi - at) as usize]);
            }
        }
        self.pos = end;
        Ok(n)
    }
}

impl Seek for SparseFile {
    fn seek(&mut self, to: SeekFrom) -> std::io::Result<u64> {
        self.pos = match to {
            SeekFrom::Start(p) => p,
            SeekFrom::End(d) => self.len.checked_add_signed(d).unwrap(),
            SeekFrom::Current(d) => self.pos.checked_add_signed(d).unwrap(),
        };
        Ok(self.pos)
    }
}

#[test]
fn entries_and_archives_past_4_gib_get_zip64_records() {
    // 4 GiB of zeros (untouched memory, no pages behind it) and a small array behind them,
    // whose offset needs 64 bits too.
    let big = NpyArray::from_vec(vec![0u8; (4 << 30) + 7]);
    let small = NpyArray::from_vec(vec![7i64, -7]);
    let mut file = SparseFile::default();
    let path = std::path::Path::new("big.npz");
    write_archive(&mut file, &[("big", &big), ("small", &small)], path, false).unwrap();

    // The ZIP64 end record and its locator precede the end record.
    let mut tail = vec![0u8; 22 + 20 + 56];
    file.seek(SeekFrom::End(-(tail.len() as i64))).unwrap();
    file.read_exact(&mut tail).unwrap();
    assert_eq!(&tail[..4], b"PK\x06\x06");
    assert_eq!(&tail[56..60], b"PK\x06\x07");
    assert_eq!(&tail[76..80], b"PK\x05\x06");
    // The directory record of the big entry needs ZIP 4.5 and saturates its sizes, whose values
    // are in its ZIP64 extra field.
    let directory = u64::from_le_bytes(tail[48..56].try_into().unwrap());
    let mut record = vec![0u8; 46];
    file.seek(SeekFrom::Start(directory)).unwrap();
    file.read_exact(&mut record).unwrap();
    assert_eq!(&record[..4], b"PK\x01\x02");
    assert_eq!(u16::from_le_bytes([record[6], record[7]]), 45);
    assert_eq!(&record[20..28], &[0xFF; 8]);

    let mut zip = ZipArchive::new(file).unwrap();
    let big_size = crate::npy::npy_header(&big).len() as u64 + big.len() as u64;
    {
        let mut entry = zip.by_index(0).unwrap();
        assert_eq!((entry.name(), entry.size()), ("big.npy", big_size));
        assert_eq!(entry.compressed_size(), big_size);
        // Reading to the end checks the CRC-32.
        let copied = std::io::copy(&mut entry, &mut std::io::sink()).unwrap();
        assert_eq!(copied, big_size);
    }
    let mut entry = zip.by_index(1).unwrap();
    assert!(entry.header_start() > u64::from(u32::MAX));
    let mut npy = Vec::new();
    entry.read_to_end(&mut npy).unwrap();
    assert_eq!(read_npy_bytes(&npy).unwrap(), small);
}

#[test]
fn reads_deflated_entries() {
    // A deflate-compressed entry, as numpy.savez_compressed writes.
    let array = NpyArray::new(vec![3, 2], vec![1i64, 2, 3, 4, 5, 6]).unwrap();
    let npy = write_npy_bytes(&array).unwrap();
    let mut zip = ZipWriter::new(Cursor::new(Vec::new()));
    let options = FileOptions::default()
        .compression_method(CompressionMethod::Deflated)
        .last_modified_time(DateTime::default());
    zip.start_file("a.npy", options).unwrap();
    zip.write_all(&npy).unwrap();
    let bytes = zip.finish().unwrap().into_inner();
    let dir = temp_dir("npz-deflate");
    let path = dir.join("c.npz");
    std::fs::write(&path, &bytes).unwrap();
    let back = read_npz(&path).unwrap();
    assert_eq!(back, vec![("a".to_string(), array.clone())]);
    let mut npz = NpzReader::open(&path).unwrap();
    assert_eq!(npz.header("a").unwrap().shape, vec![3, 2]);

    // Damaged compressed data is bad deflate data or a CRC-32 mismatch.
    let mut reader = ZipArchive::new(Cursor::new(&bytes)).unwrap();
    let (start, len) = {
        let entry = reader.by_index_raw(0).unwrap();
        (
            entry.data_start() as usize,
            entry.compressed_size() as usize,
        )
    };
    for at in start..start + len {
        let mut bad = bytes.clone();
        bad[at] ^= 0x55;
        std::fs::write(&path, &bad).unwrap();
        match read_npz(&path) {
            Err(err @ IoError::Corrupt { .. }) => {
                assert!(err.to_string().contains("c.npz"), "{err}")
            }
            other => panic!("byte {at}: {other:?}"),
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn other_compression_methods_are_unsupported() {
    let dir = temp_dir("npz-method");
    let path = dir.join("m.npz");
    write_npz(&path, &[("x", &NpyArray::from_vec(vec![1.0f32]))]).unwrap();
    let mut bytes = std::fs::read(&path).unwrap();
    // bzip2 (12), in the local header and in the directory alike: consistent, not corrupt.
    let cd = central_directory_offset(&bytes);
    bytes[8] = 12;
    bytes[cd + 10] = 12;
    std::fs::write(&path, &bytes).unwrap();
    let err = read_npz(&path).unwrap_err();
    assert!(matches!(err, IoError::Unsupported { .. }), "{err}");
    assert!(err.to_string().contains("method 12"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn damaged_central_directory_is_corrupt_never_a_missing_array() {
    let dir = temp_dir("npz-damaged-directory");
    let arrays = stats_arrays();
    let expected = owned(&arrays);
    for force_zip64 in [false, true] {
        let path = dir.join(format!("stats-{force_zip64}.npz"));
        write_npz_impl(&path, &as_refs(&arrays), force_zip64).unwrap();
        let good = std::fs::read(&path).unwrap();
        let directory = central_directory_offset(&good)..good.len();
        assert_damage_is_caught(&path, &good, directory, &expected, "stats_acceleration");
    }
    // The earlier writer's ZIP64 end records, and numpy's directory (behind local headers with
    // ZIP64 size fields).
    for (file, bytes, probe) in [
        ("old-zip64.npz", OLD_WRITER_ZIP64, "i64"),
        ("numpy.npz", NUMPY_SAVEZ, "e"),
    ] {
        let path = dir.join(file);
        std::fs::write(&path, bytes).unwrap();
        let expected = read_npz(&path).unwrap();
        let directory = central_directory_offset(bytes)..bytes.len();
        assert_damage_is_caught(&path, bytes, directory, &expected, probe);
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn damaged_local_headers_and_data_are_corrupt_or_harmless() {
    let dir = temp_dir("npz-damaged-entries");
    let arrays = stats_arrays();
    let expected = owned(&arrays);
    for force_zip64 in [false, true] {
        let path = dir.join(format!("any-{force_zip64}.npz"));
        write_npz_impl(&path, &as_refs(&arrays), force_zip64).unwrap();
        let good = std::fs::read(&path).unwrap();
        let entries = 0..central_directory_offset(&good);
        assert_damage_is_caught(&path, &good, entries, &expected, "stats_acceleration");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
