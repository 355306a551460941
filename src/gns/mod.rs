//! `phi model ...`: model directories of Graph Network-based Simulators.
//!
//! - [`init`]: `phi model init`, a model directory (`model.json`, `model.safetensors`) with
//!   seeded random weights for a dataset.
//!
//! The files are those of [`phi_gns::model`]. A command here overwrites only files it wrote,
//! which it recognises by a key of the JSON file it writes (see [`init::check_model_dir`]).

pub mod init;

use std::ffi::OsStr;

/// Whether `name` is the temporary file of an atomic write of one of `files`
/// (`.{file}.tmp-{pid}`): what a process killed mid-write leaves beside its outputs.
pub(crate) fn is_temporary_of(name: &OsStr, files: &[&str]) -> bool {
    let Some(name) = name.to_str() else {
        return false;
    };
    files.iter().any(|file| {
        name.strip_prefix('.')
            .and_then(|rest| rest.strip_prefix(file))
            .and_then(|rest| rest.strip_prefix(".tmp-"))
            .is_some_and(|pid| !pid.is_empty() && pid.bytes().all(|b| b.is_ascii_digit()))
    })
}
