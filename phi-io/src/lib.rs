//! Files for phi: NumPy `.npy` arrays ([`npy`]), `.npz` archives of them ([`npz`]), object arrays
//! of numeric arrays as numpy pickles them ([`pickle`]), the atomic
//! writing they share ([`write_atomic`]), the rule every writer applies to its target folder
//! ([`output_dir::OutputDir`]), and TOML files read with errors that name the key
//! ([`parse_toml`]).
//!
//! Every fallible function returns [`IoError`]; errors about a file name it, and a file that is
//! damaged or cut short is reported as [`IoError::Corrupt`] ("corrupt or truncated"). Files that
//! are written in one go ([`npz::write_npz`], [`npy::write_npy`], and anything written through
//! [`write_atomic`]) are written atomically: into a temporary file `.{filename}.tmp-{pid}` in the
//! same directory, which is flushed to disk and then renamed over the destination, so that readers
//! never see a half-written file.
//!
//! The crate knows nothing of tensors or of the rest of phi: arrays are plain vectors with a
//! shape ([`npy::NpyArray`]), so any layer may use it.

mod atomic;
mod error;
pub mod npy;
pub mod npz;
pub mod output_dir;
pub mod pickle;
mod toml_file;

pub use atomic::{
    publish_dir, remove_stale_temp_files, staging_dir, temp_file_pid, write_all, write_atomic,
    write_json,
};
pub use error::IoError;
pub use toml_file::{TomlError, parse_toml, read_toml_text};

#[cfg(test)]
pub(crate) mod test_util {
    use std::path::PathBuf;

    use crate::npy::NpyArray;

    /// A fresh, empty directory under the system's temporary directory for one test.
    pub fn temp_dir(test: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("phi-io-test-{}-{test}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("create test directory");
        dir
    }

    /// One array of every dtype, including extreme values, a scalar and an empty array.
    pub fn sample_arrays() -> Vec<(&'static str, NpyArray)> {
        vec![
            (
                "positions",
                NpyArray::new(
                    vec![2, 3],
                    vec![0.5f32, -1.25, 3.0, f32::MAX, f32::MIN_POSITIVE, -0.0],
                )
                .unwrap(),
            ),
            (
                "f64",
                NpyArray::new(vec![3], vec![std::f64::consts::PI, -1e300, 1e-300]).unwrap(),
            ),
            (
                "i32",
                NpyArray::new(vec![2, 2], vec![i32::MIN, -1, 0, i32::MAX]).unwrap(),
            ),
            (
                "i64",
                NpyArray::new(vec![1, 2, 2], vec![i64::MIN, -7, 7, i64::MAX]).unwrap(),
            ),
            (
                "kinds",
                NpyArray::new(vec![5], vec![0u8, 1, 2, 254, 255]).unwrap(),
            ),
            ("scalar", NpyArray::new(vec![], vec![42.0f64]).unwrap()),
            (
                "empty",
                NpyArray::new(vec![0, 3], Vec::<f32>::new()).unwrap(),
            ),
        ]
    }

    /// `(name, &array)` pairs, as [`crate::npz::write_npz`] takes them.
    pub(crate) fn as_refs<'a>(
        arrays: &'a [(&'static str, NpyArray)],
    ) -> Vec<(&'static str, &'a NpyArray)> {
        arrays.iter().map(|(n, a)| (*n, a)).collect()
    }
}
