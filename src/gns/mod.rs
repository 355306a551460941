//! `phi model ...`, `phi rollout`, `phi train` and `phi eval`: model directories of Graph
//! Network-based Simulators, their rollouts on the trajectories of a dataset, their training and
//! their evaluation (thesis sections 5.3–5.4).
//!
//! - [`init`]: `phi model init`, a model directory (`model.json`, `model.safetensors`) with
//!   seeded random weights for a dataset;
//! - [`rollout`]: `phi rollout`, a model run forward from ground-truth frames, with the
//!   predictions, the truth, the per-frame position error and a GIF of both side by side;
//! - [`train`]: `phi train`, a model trained on a dataset with a preset of `configs/gns/`;
//! - [`eval`]: `phi eval`, models evaluated on a split with the thesis's metrics: tables,
//!   plots and a GIF of their rollouts side by side;
//! - [`inverse`]: `phi optimize --simulator gns`, the optimisation of initial positions through
//!   a trained model's rollout instead of FLIP.
//!
//! The files are those of [`phi_gns::model`] and [`phi_gns::data`]; `docs/gns.md` describes
//! them and the commands. Neither command overwrites files it did not write: each recognises
//! its own outputs by a key of the JSON file it writes first (see [`init::check_model_dir`] and
//! [`rollout::check_rollout_dir`]).

pub mod eval;
pub mod init;
pub mod inverse;
pub mod rollout;
pub mod train;

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
