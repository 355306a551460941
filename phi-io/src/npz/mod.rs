//! NumPy `.npz` archives: ZIP files holding one `name.npy` entry per array, as written by
//! `numpy.savez` and read by `numpy.load`.
//!
//! - [`write_npz`] writes arrays in one go, [`write_npz_streamed`] one at a time
//!   ([`NpzWriter`]), both atomically;
//! - [`read_npz`] reads every array; [`NpzReader`] reads one array at a time, or only its
//!   header.
//!
//! The ZIP container is the `zip` crate's. Entries are written STORED (not compressed) with
//! their CRC-32 and the date 1980-01-01 00:00, so the same arrays always give the same bytes and
//! an array's bytes lie in the file as they are, to be read without inflating. Entries of 4 GiB
//! and more carry the ZIP64 size fields, and archives past 4 GiB or 65,535 entries the ZIP64
//! end records; numpy (Python's `zipfile`) reads them. The reader reads stored and
//! deflate-compressed entries (`numpy.savez_compressed`) and checks every entry's CRC-32; since
//! the zip crate takes the central directory on trust, the reader first checks it against the
//! end records and the local headers (`integrity`), so that a damaged directory is reported as a
//! corrupt file rather than as a missing or renamed array.
//!
//! The `.npy` items ([`NpyArray`], [`ArrayData`], ...) live in [`crate::npy`] and are re-exported
//! here, so that users of archives need one import.

mod integrity;
mod reader;
mod writer;

#[cfg(test)]
mod tests;

pub use crate::npy::{
    ArrayData, NpyArray, NpyHeader, read_npy, read_npy_bytes, write_npy, write_npy_bytes,
};
pub use reader::{NpzReader, read_npz};
pub use writer::{NpzWriter, write_npz, write_npz_streamed};
