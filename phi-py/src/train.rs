//! `phi_rs.train`: a GNS trained as `phi train` trains it (phi-gns's `TrainingRun`), with its
//! files, checkpoints and resume, on the Burn (autodiff) backend.

use std::path::PathBuf;

use phi_core::Backend;
use phi_core::backend::burn::Burn;
use phi_gns::train::config::SelectBy;
use phi_gns::train::options::{Overrides, RunSource};
use phi_gns::train::run::{RunOptions, TrainingRun};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::error::{Area, Error, detached};

/// The backend that trains: Burn on the CPU, the one of this build with autodiff.
type Autodiff = Burn;

/// Trains a GNS as ``phi train`` does, into the training directory ``out`` (``train.json``,
/// ``config.toml``, ``train.csv``, ``checkpoints/``, ``best/``), on the Burn backend. The same
/// preset, options and seed give the same loss curve and weights as ``phi train --backend burn``
/// (same thread count), and a run resumed from a checkpoint continues as an uninterrupted one.
///
/// Args:
///     out: the training directory (new or empty; with ``resume`` the run's own).
///     data: the dataset (with ``resume``: the run's, by default).
///     config: the preset TOML (``configs/gns/*.toml``; with ``resume``: the run's
///         ``config.toml``, by default).
///     steps: the total number of steps (overrides ``training.steps``).
///     resume: continue from the newest checkpoint in ``out``.
///     init_from: a model directory whose weights the run starts from.
///     batch_size, seed, noise_std, extra_steps, log_every, checkpoint_every, screen_every,
///         emd_every, select_by, ema_decay: override the preset's values, as ``phi train``'s
///         options do (``select_by``: ``"mse_acc1"``, ``"rollout_mse"`` or ``"emd"``).
///     progress: called after every step as ``progress(step, total, loss, learning_rate)``;
///         an exception it raises stops the run after a checkpoint and is raised again.
///
/// Returns:
///     A dict: ``step`` (the steps done), ``loss`` (the last step's), ``best`` (``{"value",
///     "step"}`` of the best screening, or ``None``) and ``out``.
///
/// Raises:
///     TrainingError: a preset or override that is not valid (naming the key), an output
///         directory that holds something else, a resume without a checkpoint, a diverged run.
///     DatasetError, ModelError: a dataset or model that does not load or fit.
///     KeyboardInterrupt: Ctrl-C, after the checkpoint of the last completed step.
///
/// The GIL is released during each step.
#[pyfunction]
#[pyo3(signature = (out, data = None, config = None, steps = None, resume = false, init_from = None, batch_size = None, seed = None, noise_std = None, extra_steps = None, log_every = None, checkpoint_every = None, screen_every = None, emd_every = None, select_by = None, ema_decay = None, progress = None))]
#[allow(clippy::too_many_arguments)] // Python's keyword arguments
pub fn train<'py>(
    py: Python<'py>,
    out: PathBuf,
    data: Option<PathBuf>,
    config: Option<PathBuf>,
    steps: Option<u64>,
    resume: bool,
    init_from: Option<PathBuf>,
    batch_size: Option<usize>,
    seed: Option<u64>,
    noise_std: Option<f64>,
    extra_steps: Option<usize>,
    log_every: Option<u64>,
    checkpoint_every: Option<u64>,
    screen_every: Option<u64>,
    emd_every: Option<usize>,
    select_by: Option<String>,
    ema_decay: Option<f64>,
    progress: Option<Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let source = run_source(resume, config, data, init_from)?;
    let select_by = select_by
        .map(|name| name.parse::<SelectBy>())
        .transpose()
        .map_err(|reason| Error::argument(Area::Training, "train: select_by", &reason))?;
    let overrides = Overrides {
        steps,
        batch_size,
        seed,
        noise_std,
        extra_steps,
        log_every,
        checkpoint_every,
        screen_every,
        emd_every,
        select_by,
        ema_decay,
    };
    let target = out.clone();
    let mut run = detached(py, move || {
        let options = RunOptions::resolve(target, source, &overrides)?;
        Ok(TrainingRun::<Autodiff>::open(
            &options,
            &Autodiff::default_device(),
        )?)
    })?;
    let total = run.config().training.steps;
    let mut loss = None;
    while run.step() < total {
        let report = detached(py, || Ok(run.train_step()?))?;
        loss = Some(report.loss);
        let stopped = match &progress {
            Some(callback) => callback
                .call1((report.step, total, report.loss, report.learning_rate))
                .err(),
            None => None,
        };
        if let Some(error) = stopped.or_else(|| py.check_signals().err()) {
            detached(py, || Ok(run.checkpoint()?))?;
            return Err(error);
        }
    }
    summary(py, &run, loss, out)
}

/// Where a run comes from: the run in `out` resumed (with its own preset and dataset unless
/// given), or a new one from a preset and a dataset.
fn run_source(
    resume: bool,
    config: Option<PathBuf>,
    data: Option<PathBuf>,
    init_from: Option<PathBuf>,
) -> PyResult<RunSource> {
    if resume {
        if init_from.is_some() {
            return Err(Error::argument(
                Area::Training,
                "train: init_from",
                "a resumed run continues from its checkpoint; init_from is for a new run",
            )
            .into());
        }
        return Ok(RunSource::Resume {
            preset: config,
            data,
        });
    }
    let Some(preset) = config else {
        return Err(Error::argument(
            Area::Training,
            "train: config",
            "a preset is needed for a new run (e.g. configs/gns/cpu/1sn.toml)",
        )
        .into());
    };
    let Some(data) = data else {
        return Err(Error::argument(
            Area::Training,
            "train: data",
            "a dataset is needed for a new run",
        )
        .into());
    };
    Ok(RunSource::New {
        preset,
        data,
        init_from,
    })
}

/// The dictionary `train` returns: the step reached, the last loss, the best screening and
/// the run's folder.
fn summary<'py>(
    py: Python<'py>,
    run: &TrainingRun<Autodiff>,
    loss: Option<f32>,
    out: PathBuf,
) -> PyResult<Bound<'py, PyDict>> {
    let result = PyDict::new(py);
    result.set_item("step", run.step())?;
    result.set_item("loss", loss)?;
    match run.best() {
        Some(best) => {
            let b = PyDict::new(py);
            b.set_item("value", best.value)?;
            b.set_item("step", best.step)?;
            result.set_item("best", b)?;
        }
        None => result.set_item("best", py.None())?,
    }
    result.set_item("out", out)?;
    Ok(result)
}
