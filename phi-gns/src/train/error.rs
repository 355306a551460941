//! Errors of training: each names the file, the key or the step.

use std::path::PathBuf;

use crate::data::DataError;
use crate::model::ModelError;

/// What stops a training run.
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    /// A preset that cannot be read, or a value in it that is not allowed.
    #[error("{path}: {key}: {reason}")]
    Config {
        /// The preset file.
        path: String,
        /// The dotted key (`training.steps`) or the place the parser stopped.
        key: String,
        /// What is wrong.
        reason: String,
    },
    /// The model: its files, a dataset it does not fit, its inputs.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// The dataset: a missing or damaged trajectory, its metadata.
    #[error(transparent)]
    Data(#[from] DataError),
    /// Writing a file failed (the error names it).
    #[error(transparent)]
    Io(#[from] phi_io::IoError),
    /// A training directory that holds something other than a run (the rule of every writer
    /// of phi, [`phi_io::output_dir`]; the error names the entry in the way).
    #[error(transparent)]
    Output(Box<phi_io::output_dir::OutputDirError>),
    /// A checkpoint or training directory that cannot be used.
    #[error("'{path}': {reason}", path = path.display())]
    Checkpoint {
        /// The file or directory.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// A non-finite loss or gradient: training stops; the checkpoint of the step before is
    /// kept.
    #[error("training diverged at step {step}: {reason}")]
    Diverged {
        /// The step that failed (counted from 1).
        step: u64,
        /// The loss or gradient at fault.
        reason: String,
    },
}

impl From<phi_io::output_dir::OutputDirError> for TrainError {
    fn from(e: phi_io::output_dir::OutputDirError) -> Self {
        TrainError::Output(Box::new(e))
    }
}

impl From<phi_io::TomlError> for TrainError {
    fn from(e: phi_io::TomlError) -> Self {
        TrainError::Config {
            path: e.path,
            key: e.key,
            reason: e.reason,
        }
    }
}
