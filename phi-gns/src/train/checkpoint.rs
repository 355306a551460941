//! Checkpoints of a training run: everything a resumed run needs to continue bit for bit.
//!
//! A checkpoint is a directory `checkpoints/step-{step:010}/` of the training directory holding
//! a model directory (`model.json`, `model.safetensors`), Adam's moments
//! (`optimizer.safetensors`, tensors `exp_avg.{name}` and `exp_avg_sq.{name}` as PyTorch names
//! them) and `state.json` ([`CheckpointState`]: the step, the seed, the loss accumulated since
//! the last log row, the best screening result, the updates of the weight average) and, when
//! the run averages its weights, the average as a model directory `average/`. Because every random draw of a step is a
//! function of the seed and the step (see [`super::sampler::step_rng`]), that is the whole
//! state of the generators and the sampler.
//!
//! A checkpoint is written into a temporary directory and renamed into place, so a directory
//! named `step-…` is always complete; temporary directories left by a killed process are
//! removed by the next [`prune_checkpoints`]. The best model by the screening metric is kept
//! apart in `best/` (a model directory plus `best.json`), written the same way.

use std::path::{Path, PathBuf};

use phi_core::backend::Host;
use serde::{Deserialize, Serialize};

use super::average::WeightAverage;
use super::config::SelectBy;
use super::{Adam, AdamConfig, TrainError};
use crate::model::files::{tensors_to_bytes, weights_from_bytes};
use crate::model::{Gns, GnsKernels, Parameters, load_model, save_model};

/// The folder of the checkpoints in a training directory.
pub(crate) const CHECKPOINTS_DIR: &str = "checkpoints";
/// The folder of the best model in a training directory.
pub const BEST_DIR: &str = "best";
/// Adam's moments in a checkpoint.
pub(crate) const OPTIMIZER_FILE: &str = "optimizer.safetensors";
/// The state of a checkpoint, written last.
pub(crate) const STATE_FILE: &str = "state.json";
/// What the best model was chosen by, in `best/`.
pub(crate) const BEST_FILE: &str = "best.json";
/// The weight average of a checkpoint, a model directory.
pub(crate) const AVERAGE_DIR: &str = "average";
/// The value of [`CheckpointState::format`].
pub(crate) const CHECKPOINT_FORMAT: &str = "phi-gns-checkpoint";

/// The loss of the steps since the last row of `train.csv`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct LossAccumulator {
    /// The sum of the losses (in f64; JSON keeps it exactly).
    pub sum: f64,
    /// The number of steps summed.
    pub steps: u64,
}

impl LossAccumulator {
    /// Adds one step's loss.
    pub fn add(&mut self, loss: f32) {
        self.sum += f64::from(loss);
        self.steps += 1;
    }

    /// The mean loss, and a fresh accumulator.
    pub(crate) fn take_mean(&mut self) -> f64 {
        let mean = if self.steps == 0 {
            f64::NAN
        } else {
            self.sum / self.steps as f64
        };
        *self = LossAccumulator::default();
        mean
    }
}

/// The best screening result so far.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Best {
    /// The step of the model.
    pub step: u64,
    /// Its value of the selecting metric.
    pub value: f64,
    /// The selecting metric (absent in checkpoints from before it was recorded).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub metric: Option<SelectBy>,
}

/// `state.json` of a checkpoint.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct CheckpointState {
    /// Always [`CHECKPOINT_FORMAT`].
    pub format: String,
    /// Optimisation steps done.
    pub step: u64,
    /// `training.seed`: with `step`, the state of every generator.
    pub seed: u64,
    /// The loss since the last log row.
    pub log: LossAccumulator,
    /// The best screening result so far (none before the first screening).
    pub best: Option<Best>,
    /// The updates of the weight average in `average/` (absent: the run keeps none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub average_updates: Option<u64>,
}

impl CheckpointState {
    /// The state at `step`.
    pub fn new(step: u64, seed: u64, log: LossAccumulator, best: Option<Best>) -> Self {
        CheckpointState {
            format: CHECKPOINT_FORMAT.to_string(),
            step,
            seed,
            log,
            best,
            average_updates: None,
        }
    }
}

/// The directory of the checkpoint at `step` in the training directory `out`.
pub(crate) fn checkpoint_dir(out: &Path, step: u64) -> PathBuf {
    out.join(CHECKPOINTS_DIR).join(format!("step-{step:010}"))
}

fn error(path: &Path, reason: impl std::fmt::Display) -> TrainError {
    TrainError::Checkpoint {
        path: path.to_path_buf(),
        reason: reason.to_string(),
    }
}

/// Writes the checkpoint of `state.step` into `out` (with `average` in `average/`, its updates
/// in `state.json`) and returns its directory. An existing checkpoint of the same step is
/// replaced.
///
/// # Errors
/// [`TrainError::Checkpoint`] or [`TrainError::Io`] naming the file that cannot be written.
pub(crate) fn save_checkpoint<B: GnsKernels>(
    out: &Path,
    model: &Gns<B>,
    adam: &Adam<B>,
    state: &CheckpointState,
    average: Option<&WeightAverage>,
) -> Result<PathBuf, TrainError> {
    let dir = checkpoint_dir(out, state.step);
    let temp = temporary_sibling(&dir);
    let mut state = state.clone();
    state.average_updates = average.map(WeightAverage::updates);
    write_directory(&temp, &dir, |temp| {
        save_model(temp, model)?;
        if let Some(average) = average {
            let averaged = Gns::<Host>::new(model.spec().clone(), average.params().clone())?;
            save_model(&temp.join(AVERAGE_DIR), &averaged)?;
        }
        let path = temp.join(OPTIMIZER_FILE);
        let (first, second) = adam.moments();
        let named = first
            .iter()
            .map(|(n, t)| (format!("exp_avg.{n}"), t))
            .chain(second.iter().map(|(n, t)| (format!("exp_avg_sq.{n}"), t)));
        let bytes = tensors_to_bytes(named, &path)?;
        phi_io::write_atomic(&path, |w| phi_io::write_all(w, &bytes, &path))?;
        write_json(&temp.join(STATE_FILE), &state)
    })?;
    Ok(dir)
}

/// The weight average of the checkpoint in `dir` with decay `decay`, if it holds one.
///
/// # Errors
/// [`TrainError::Checkpoint`] when `state.json` counts updates but `average/` is missing or
/// damaged, or does not fit `model`.
pub(crate) fn load_average<B: GnsKernels>(
    dir: &Path,
    state: &CheckpointState,
    model: &Gns<B>,
    decay: f64,
) -> Result<Option<WeightAverage>, TrainError> {
    let Some(updates) = state.average_updates else {
        return Ok(None);
    };
    let path = dir.join(AVERAGE_DIR);
    let average = load_model::<Host>(&path, &Default::default())
        .map_err(|e| error(&path, format!("the weight average: {e}")))?;
    if average.spec().config != model.spec().config {
        return Err(error(
            &path,
            "the weight average's model.json does not fit the checkpoint's model",
        ));
    }
    Ok(Some(WeightAverage::restore(
        decay,
        average.params().clone(),
        updates,
    )))
}

/// The model, Adam's state (with `adam` as its constants) and the state of the checkpoint in
/// `dir`, on `device`.
///
/// # Errors
/// [`TrainError::Checkpoint`] for a missing or damaged file, [`TrainError::Model`] for weights
/// or moments that do not fit the model.
pub(crate) fn load_checkpoint<B: GnsKernels>(
    dir: &Path,
    adam: AdamConfig,
    device: &B::Device,
) -> Result<(Gns<B>, Adam<B>, CheckpointState), TrainError> {
    let state: CheckpointState = read_json(&dir.join(STATE_FILE))?;
    if state.format != CHECKPOINT_FORMAT {
        return Err(error(
            &dir.join(STATE_FILE),
            format!("format '{}' is not '{CHECKPOINT_FORMAT}'", state.format),
        ));
    }
    let model = load_model::<B>(dir, device)?;
    let path = dir.join(OPTIMIZER_FILE);
    let bytes = std::fs::read(&path).map_err(|e| error(&path, format!("cannot read: {e}")))?;
    let mut tensors = weights_from_bytes::<B>(&bytes, &path, device)?;
    let mut moments = |prefix: &str| -> Result<Parameters<B>, TrainError> {
        let named = model
            .params()
            .iter()
            .map(|(name, _)| {
                let key = format!("{prefix}.{name}");
                tensors
                    .remove(&key)
                    .map(|t| (name.to_string(), t))
                    .ok_or_else(|| error(&path, format!("missing tensor '{key}'")))
            })
            .collect::<Result<_, _>>()?;
        Ok(Parameters::from_tensors(
            &model.spec().config,
            named,
            &path,
        )?)
    };
    let first = moments("exp_avg")?;
    let second = moments("exp_avg_sq")?;
    if let Some(extra) = tensors.keys().next() {
        return Err(error(
            &path,
            format!("tensor '{extra}' is not a moment of the model"),
        ));
    }
    let adam = Adam::restore(adam, state.step, first, second)?;
    Ok((model, adam, state))
}

/// The complete checkpoints of the training directory `out`, oldest first.
///
/// # Errors
/// [`TrainError::Checkpoint`] when the folder cannot be listed.
pub fn checkpoints(out: &Path) -> Result<Vec<(u64, PathBuf)>, TrainError> {
    let folder = out.join(CHECKPOINTS_DIR);
    if !folder.exists() {
        return Ok(Vec::new());
    }
    let mut found = Vec::new();
    for entry in std::fs::read_dir(&folder).map_err(|e| error(&folder, e))? {
        let path = entry.map_err(|e| error(&folder, e))?.path();
        let step = path
            .file_name()
            .and_then(|n| n.to_str())
            .and_then(|n| n.strip_prefix("step-"))
            .and_then(|n| n.parse::<u64>().ok());
        if let Some(step) = step
            && path.join(STATE_FILE).is_file()
        {
            found.push((step, path));
        }
    }
    found.sort();
    Ok(found)
}

/// Removes all but the newest `keep` checkpoints of `out`, and the temporary directories that a
/// killed process left.
///
/// # Errors
/// [`TrainError::Checkpoint`] when a directory cannot be removed.
pub(crate) fn prune_checkpoints(out: &Path, keep: usize) -> Result<(), TrainError> {
    let all = checkpoints(out)?;
    for (_, dir) in all.iter().take(all.len().saturating_sub(keep)) {
        std::fs::remove_dir_all(dir).map_err(|e| error(dir, format!("cannot remove: {e}")))?;
    }
    for folder in [out.join(CHECKPOINTS_DIR), out.to_path_buf()] {
        let Ok(entries) = std::fs::read_dir(&folder) else {
            continue;
        };
        for entry in entries.flatten() {
            let path = entry.path();
            if is_temporary_dir(&path) {
                std::fs::remove_dir_all(&path)
                    .map_err(|e| error(&path, format!("cannot remove: {e}")))?;
            }
        }
    }
    Ok(())
}

/// Writes `model` as the best model of `out` (`best/`, with `best.json` saying the step, the
/// metric and its value), replacing the previous one.
///
/// # Errors
/// [`TrainError::Checkpoint`] or [`TrainError::Io`] naming the file that cannot be written.
pub(crate) fn save_best<B: GnsKernels>(
    out: &Path,
    model: &Gns<B>,
    best: &Best,
    metric: &str,
) -> Result<(), TrainError> {
    let dir = out.join(BEST_DIR);
    let temp = temporary_sibling(&dir);
    write_directory(&temp, &dir, |temp| {
        save_model(temp, model)?;
        write_json(
            &temp.join(BEST_FILE),
            &serde_json::json!({ "step": best.step, "metric": metric, "value": best.value }),
        )
    })
}

/// `.{name}.tmp-{pid}` beside `dir`.
fn temporary_sibling(dir: &Path) -> PathBuf {
    let name = dir.file_name().and_then(|n| n.to_str()).unwrap_or("dir");
    dir.with_file_name(format!(".{name}.tmp-{}", std::process::id()))
}

/// Whether `path` is a directory [`temporary_sibling`] names.
fn is_temporary_dir(path: &Path) -> bool {
    path.is_dir()
        && path
            .file_name()
            .and_then(|n| n.to_str())
            .and_then(|n| n.strip_prefix('.'))
            .and_then(|n| n.rsplit_once(".tmp-").or_else(|| n.rsplit_once(".old-")))
            .is_some_and(|(_, pid)| !pid.is_empty() && pid.bytes().all(|b| b.is_ascii_digit()))
}

/// Fills `temp` with `fill`, then puts it in place of `dir` (the old `dir` is moved aside first
/// and removed last, so that a crash leaves one of the two complete).
fn write_directory(
    temp: &Path,
    dir: &Path,
    fill: impl FnOnce(&Path) -> Result<(), TrainError>,
) -> Result<(), TrainError> {
    if temp.exists() {
        std::fs::remove_dir_all(temp).map_err(|e| error(temp, format!("cannot remove: {e}")))?;
    }
    std::fs::create_dir_all(temp).map_err(|e| error(temp, format!("cannot create: {e}")))?;
    fill(temp)?;
    let name = dir.file_name().and_then(|n| n.to_str()).unwrap_or("dir");
    let old = dir.with_file_name(format!(".{name}.old-{}", std::process::id()));
    if dir.exists() {
        std::fs::rename(dir, &old).map_err(|e| error(dir, format!("cannot move aside: {e}")))?;
    }
    std::fs::rename(temp, dir).map_err(|e| error(dir, format!("cannot rename into place: {e}")))?;
    if old.exists() {
        std::fs::remove_dir_all(&old).map_err(|e| error(&old, format!("cannot remove: {e}")))?;
    }
    Ok(())
}

fn write_json(path: &Path, value: &impl Serialize) -> Result<(), TrainError> {
    Ok(phi_io::write_json(path, value)?)
}

fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T, TrainError> {
    let bytes = std::fs::read(path).map_err(|e| error(path, format!("cannot read: {e}")))?;
    let mut de = serde_json::Deserializer::from_slice(&bytes);
    serde_path_to_error::deserialize(&mut de)
        .map_err(|e| error(path, format!("key '{}': {}", e.path(), e.inner())))
}
