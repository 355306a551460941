//! Writing simulation output: NumPy arrays and pictures.
//!
//! - NumPy `.npy` arrays and `.npz` archives, so that trajectories can be exchanged with Python
//!   tooling: [`phi_io::npz`], whose reader ([`read_npz`], [`NpyArray`]) is re-exported here;
//! - [`render`]: drawing particle frames ([`render_frame`]) and saving them as PNG pictures
//!   ([`write_png`]) or streamed animated GIFs ([`GifWriter`]);
//! - [`vtk`]: particle frames as VTK `.vtu` files and a `.pvd` series for ParaView
//!   ([`vtk::VtkSeries`]);
//! - [`sink`]: where a run's frames go as they are made ([`sink::FrameSink`]);
//! - [`target`]: the rule every writing command applies to its target (new or empty, or its
//!   own previous output, replaced only with `--force`).
//!
//! Every fallible function returns [`OutputError`]; errors about a file name it.
//! Files that are written in one go (`.npz` archives and PNG pictures) are written
//! atomically ([`phi_io::write_atomic`]): into a temporary file `.{filename}.tmp-{pid}` in
//! the same directory, which is flushed to disk and then renamed over the destination, so that
//! readers never see a half-written file.

pub mod render;
pub(crate) mod sink;
pub mod target;
pub mod vtk;

use std::path::{Path, PathBuf};

pub(crate) use phi_io::IoError;
pub(crate) use phi_io::npz::{ArrayData, write_npz};
pub use phi_io::npz::{NpyArray, read_npz};
pub(crate) use phi_io::write_atomic;
pub(crate) use render::{
    FrameStyle, GifWriter, KIND_LIQUID, KIND_OBSTACLE, MAX_PIXELS, RgbImage, render_frame,
    side_by_side, write_png,
};

/// Errors of the output module.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// A file operation failed: an operating-system error, or a NumPy file that is damaged or
    /// unsupported ([`phi_io`]); the error names the file.
    #[error(transparent)]
    File(#[from] IoError),
    /// The arguments of a function are inconsistent (wrong lengths, empty domain, ...).
    #[error("invalid input: {0}")]
    InvalidInput(String),
    /// Encoding a PNG picture failed.
    #[error("cannot encode PNG '{path}': {source}", path = path.display())]
    Png {
        /// The destination.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: png::EncodingError,
    },
    /// Encoding a GIF animation failed.
    #[error("cannot encode GIF '{path}': {source}", path = path.display())]
    Gif {
        /// The destination.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: gif::EncodingError,
    },
}

impl OutputError {
    /// Wraps an I/O error with the path and the action that failed.
    pub(crate) fn io(path: &Path, action: &'static str, source: std::io::Error) -> Self {
        OutputError::File(IoError::io(path, action, source))
    }
}

#[cfg(test)]
pub(crate) mod test_util {
    use std::path::PathBuf;

    /// A fresh, empty directory under the system's temporary directory for one test.
    pub fn temp_dir(test: &str) -> PathBuf {
        let dir =
            std::env::temp_dir().join(format!("phi-output-test-{}-{test}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("create test directory");
        dir
    }
}
