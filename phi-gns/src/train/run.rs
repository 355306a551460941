//! A training run: the loop of thesis section 5.3 with its files, checkpoints and screening.
//!
//! A run lives in a training directory:
//!
//! - `train.json`: what made it (`"made_by": "phi train"`), the dataset, the preset it came
//!   from and the backend;
//! - `config.toml`: the configuration as run (the preset with the command line's overrides);
//! - `train.csv`: a row every `training.log_every` steps — `step`, the mean `loss` since the
//!   previous row, the `learning_rate` of the row's step, `steps_per_second` (of the training
//!   steps since the previous row, screening left out) — and, on
//!   screening rows, `valid_mse_acc1`, `valid_rollout_mse` and `valid_emd` (empty unless
//!   `screening.emd_every ≥ 1`);
//! - `checkpoints/step-…/`: the newest `checkpoints.keep` checkpoints (`checkpoint.rs`);
//! - `best/`: the model with the best screening metric so far (the metric may change on
//!   `--resume`; the next screening then replaces it).
//! - `train.lock` (`LOCK_FILE`): the process id of the run while it is open, so that a
//!   second run on the directory is refused; a killed run's lock is taken over.
//!
//! With `training.ema_decay`, the run keeps a moving average of its weights
//! (`WeightAverage`): screening reads the average, `best/` holds it, and each
//! checkpoint holds it as `average/` beside the weights training continues from.
//!
//! Each step `s` draws its windows, its noise and its pushforward unroll from generators that
//! depend only on `(training.seed, s)`, so a run resumed from the checkpoint at step `s`
//! ([`TrainingRun::open`] with `resume`) computes exactly the losses an uninterrupted run
//! computes from `s` on, on the same backend and thread count; `train.csv` is cut back to the
//! checkpoint's step first, so the curve it holds is that of one uninterrupted run.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use phi_core::AutodiffBackend;
use phi_core::backend::Host;
use phi_io::output_dir::{Marker, OutputDir, OutputSubdir, Outputs};
use serde::{Deserialize, Serialize};

use super::average::WeightAverage;
use super::checkpoint::{
    BEST_DIR, Best, CHECKPOINTS_DIR, CheckpointState, LossAccumulator, checkpoints, load_average,
    load_checkpoint, prune_checkpoints, save_best, save_checkpoint,
};
use super::config::{SelectBy, TrainConfig};
use super::impacts::ImpactCriterion;
use super::screening::{Screening, ScreeningPlan, screen};
use super::step::take_step;
use super::stream::{BatchSource, BatchStream};
use super::{Adam, TrainError};
use crate::data::{Dataset, METADATA_FILE, Trajectory};
use crate::model::{Gns, GnsKernels, ModelError, load_model};

/// The value of `made_by` in `train.json`.
pub const MADE_BY: &str = "phi train";
/// The run's description file.
pub(crate) const TRAIN_FILE: &str = "train.json";
/// The configuration as run.
pub(crate) const CONFIG_FILE: &str = "config.toml";
/// The loss and screening log.
pub(crate) const LOG_FILE: &str = "train.csv";
/// The header of [`LOG_FILE`].
pub(crate) const LOG_HEADER: &str =
    "step,loss,learning_rate,steps_per_second,valid_mse_acc1,valid_rollout_mse,valid_emd";
/// The header of logs written before the screening measured EMD; a resumed run upgrades it.
const LOG_HEADER_BEFORE_EMD: &str =
    "step,loss,learning_rate,steps_per_second,valid_mse_acc1,valid_rollout_mse";

/// `train.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct TrainRecord {
    /// Always [`MADE_BY`].
    pub made_by: String,
    /// The dataset directory.
    pub dataset: PathBuf,
    /// The preset the configuration came from.
    pub preset: String,
    /// The backend that trains (a resumed run must use the same for a bit-exact curve).
    pub backend: String,
    /// The model directory the weights started from (`--init-from`), if any.
    pub init_from: Option<PathBuf>,
}

/// What a run is asked to do.
#[derive(Debug, Clone)]
pub struct RunOptions {
    /// The training directory.
    pub out: PathBuf,
    /// The dataset directory.
    pub data: PathBuf,
    /// The configuration, with the command line's overrides applied.
    pub config: TrainConfig,
    /// The preset's path or name, for `train.json` and errors.
    pub preset: String,
    /// Start from the weights of this model directory (2si starts from a 1s model).
    pub init_from: Option<PathBuf>,
    /// Continue the run in `out` from its newest checkpoint.
    pub resume: bool,
}

/// What one optimisation step did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepReport {
    /// Steps done after it (counted from 1).
    pub step: u64,
    /// Its loss (before the update).
    pub loss: f32,
    /// Its learning rate.
    pub learning_rate: f64,
    /// The pushforward unrolls of its batch.
    pub unrolls: usize,
}

/// A training run on backend `B`: the model, Adam, the batch stream and the files.
pub struct TrainingRun<B: AutodiffBackend + GnsKernels> {
    out: PathBuf,
    config: TrainConfig,
    model: Gns<B>,
    adam: Adam<B>,
    average: Option<WeightAverage>,
    state: CheckpointState,
    stream: BatchStream,
    valid: Vec<Trajectory>,
    device: B::Device,
    log_started: Instant,
    log_steps: u64,
    /// Held while the run is open; dropping the run frees the directory.
    _lock: RunLock,
}

impl<B: AutodiffBackend + GnsKernels> TrainingRun<B> {
    /// Opens a run: a fresh one in an empty or missing `options.out`, or, with
    /// `options.resume`, the run there continued from its newest checkpoint.
    ///
    /// # Errors
    /// [`TrainError::Checkpoint`] for an output directory that holds something else (a fresh
    /// run never overwrites), a resumed run without a checkpoint or with another
    /// configuration; [`TrainError::Config`] / [`TrainError::Model`] for a configuration that
    /// does not fit the dataset; [`TrainError::Data`] for an unreadable dataset.
    pub fn open(options: &RunOptions, device: &B::Device) -> Result<Self, TrainError> {
        let out = &options.out;
        let config = &options.config;
        let dataset = Dataset::open(&options.data)?;
        let metadata_path = options.data.join(METADATA_FILE);
        let mut spec = config.model_spec(dataset.metadata(), &metadata_path, &options.preset)?;
        spec.provenance = serde_json::json!({
            "made_by": MADE_BY,
            "phi_version": env!("CARGO_PKG_VERSION"),
            "dataset": options.data.display().to_string(),
            "preset": options.preset,
            "init_from": options.init_from.as_ref().map(|p| p.display().to_string()),
        });
        // One process at a time in a run's directory: a resumed run takes the lock before it
        // touches anything, a new one as soon as its files exist.
        let mut lock = None;
        if options.resume {
            check_resumable(out, options, config, B::name())?;
            lock = Some(RunLock::acquire(out)?);
        } else {
            check_fresh(out)?;
        }
        let (model, adam, state, average) = if options.resume {
            let (step, dir) = checkpoints(out)?
                .pop()
                .ok_or_else(|| TrainError::Checkpoint {
                    path: out.join(super::checkpoint::CHECKPOINTS_DIR),
                    reason: "no checkpoint to resume from".into(),
                })?;
            let (model, adam, mut state) = load_checkpoint::<B>(&dir, config.optimizer, device)?;
            reconcile_best(out, &mut state, config.screening.select_by);
            if model.spec().config != spec.config {
                return Err(TrainError::Checkpoint {
                    path: dir,
                    reason: "its model.json does not fit the configuration".into(),
                });
            }
            tracing::info!(step, checkpoint = %dir.display(), "resuming");
            let average = match config.training.ema_decay {
                Some(decay) => Some(match load_average(&dir, &state, &model, decay)? {
                    Some(average) => average,
                    None => {
                        tracing::info!(step, "the weight average starts from this checkpoint");
                        WeightAverage::new(decay, model.params())
                    }
                }),
                None => None,
            };
            truncate_log(&out.join(LOG_FILE), state.step)?;
            (model, adam, state, average)
        } else {
            let model = match &options.init_from {
                Some(dir) => start_from(dir, spec, device)?,
                None => Gns::<B>::init(spec, device)?,
            };
            let adam = Adam::new(config.optimizer, model.params());
            let state =
                CheckpointState::new(0, config.training.seed, LossAccumulator::default(), None);
            let average = config
                .training
                .ema_decay
                .map(|decay| WeightAverage::new(decay, model.params()));
            (model, adam, state, average)
        };
        let mut source = BatchSource::new(&dataset, &config.data.split, &config.batches())?;
        if let Some(sampling) = config.training.impact_sampling {
            let spec = model.spec();
            let criterion = ImpactCriterion {
                kinematic_types: spec.kinematic_types.clone(),
                radius: spec.config.connectivity_radius,
                acc_mean: dataset.metadata().acc_mean.clone(),
                acc_std: dataset.metadata().acc_std.clone(),
                threshold: sampling.threshold,
            };
            let started = Instant::now();
            let (with, windows, impacts) = source.with_impacts(&criterion, sampling.share)?;
            source = with;
            tracing::info!(
                windows,
                impacts,
                seconds = started.elapsed().as_secs_f64(),
                "impact sampling: {:.0} % of the draws from the windows with obstacle impacts",
                100.0 * sampling.share
            );
        }
        let stream = BatchStream::new(source, state.step, config.data.read_ahead)?;
        let valid = if config.screening.every > 0 {
            read_split(
                &dataset,
                &config.screening.split,
                config.screening.trajectories,
            )?
        } else {
            Vec::new()
        };
        if !options.resume {
            // Only now that the dataset, both splits and the model are known to work.
            write_run_files(out, options, B::name())?;
            lock = Some(RunLock::acquire(out)?);
        }
        let mut run = TrainingRun {
            out: out.clone(),
            config: config.clone(),
            model,
            adam,
            average,
            state,
            stream,
            valid,
            device: device.clone(),
            log_started: Instant::now(),
            log_steps: 0,
            _lock: lock.expect("both branches take the lock"),
        };
        if !options.resume {
            // A run killed before its first periodic checkpoint can still be resumed.
            run.checkpoint()?;
        }
        Ok(run)
    }

    /// Optimisation steps done.
    pub fn step(&self) -> u64 {
        self.state.step
    }

    /// The model of the moment.
    pub fn model(&self) -> &Gns<B> {
        &self.model
    }

    /// The configuration.
    pub fn config(&self) -> &TrainConfig {
        &self.config
    }

    /// The best screening result so far.
    pub fn best(&self) -> Option<Best> {
        self.state.best
    }

    /// One optimisation step on the next batch, then the log row, the screening and the
    /// checkpoint that fall due at the step.
    ///
    /// # Errors
    /// [`TrainError::Diverged`] for a non-finite loss or gradient (the model and Adam stay as
    /// they were before the step, and a checkpoint of that state is written); data, model and
    /// file errors.
    pub fn train_step(&mut self) -> Result<StepReport, TrainError> {
        let batch = self.stream.next()?;
        let step = self.state.step;
        debug_assert_eq!(batch.step, step, "the stream runs in step with the run");
        let learning_rate = self.config.optimizer.learning_rate.at(step);
        let result = take_step(
            &self.model,
            &mut self.adam,
            &self.config,
            &batch,
            &self.device,
        );
        let (model, loss, unrolls) = match result {
            Ok(done) => done,
            Err(ModelError::NonFinite { what, reason }) => {
                let kept = self.checkpoint()?;
                return Err(TrainError::Diverged {
                    step: step + 1,
                    reason: format!(
                        "{what}: {reason}; the state before it is in {}",
                        kept.display()
                    ),
                });
            }
            Err(e) => return Err(e.into()),
        };
        self.model = model;
        if let Some(average) = &mut self.average {
            average.update(self.model.params());
        }
        self.state.step = step + 1;
        self.state.log.add(loss);
        self.log_steps += 1;
        let done = self.state.step;
        if done.is_multiple_of(self.config.training.log_every) {
            let seconds = self.log_started.elapsed().as_secs_f64();
            let rate = self.log_steps as f64 / seconds.max(1e-9);
            let screening = (self.config.screening.every > 0
                && done.is_multiple_of(self.config.screening.every))
            .then(|| self.screen())
            .transpose()?;
            self.write_log_row(learning_rate, rate, screening)?;
        }
        if done.is_multiple_of(self.config.checkpoints.every) || done == self.config.training.steps
        {
            self.checkpoint()?;
        }
        Ok(StepReport {
            step: done,
            loss,
            learning_rate,
            unrolls,
        })
    }

    /// Screens the model of the moment (the weight average, if the run keeps one) on the
    /// validation trajectories (on the host backend) and keeps it as `best/` when it beats the
    /// best so far.
    ///
    /// # Errors
    /// As `screen`; file errors writing `best/`.
    pub fn screen(&mut self) -> Result<Screening, TrainError> {
        let weights = match &self.average {
            Some(average) => average.params().clone(),
            None => self.model.params().to_backend::<Host>(&Default::default()),
        };
        let host = Gns::<Host>::new(self.model.spec().clone(), weights)?;
        let s = &self.config.screening;
        let plan = ScreeningPlan {
            window_stride: s.window_stride,
            rollout_steps: s.rollout_steps,
            emd_every: s.emd_every,
        };
        let result = screen(&host, &self.valid, plan, &Default::default())?;
        let value = match s.select_by {
            SelectBy::MseAcc1 => result.mse_acc1,
            SelectBy::RolloutMse => result.rollout_mse,
            // The configuration's check makes sure the EMD was measured.
            SelectBy::Emd => result.emd.unwrap_or(f64::INFINITY),
        };
        let metric = s.select_by.column();
        tracing::info!(
            step = self.state.step,
            mse_acc1 = result.mse_acc1,
            rollout_mse = result.rollout_mse,
            emd = result.emd,
            "screening"
        );
        if value.is_finite() && self.state.best.is_none_or(|b| value < b.value) {
            let best = Best {
                step: self.state.step,
                value,
                metric: Some(s.select_by),
            };
            save_best(&self.out, &host, &best, metric)?;
            self.state.best = Some(best);
        }
        Ok(result)
    }

    /// Writes the checkpoint of the current step and prunes the old ones; returns its
    /// directory.
    ///
    /// # Errors
    /// File errors.
    pub fn checkpoint(&mut self) -> Result<PathBuf, TrainError> {
        let dir = save_checkpoint(
            &self.out,
            &self.model,
            &self.adam,
            &self.state,
            self.average.as_ref(),
        )?;
        prune_checkpoints(&self.out, self.config.checkpoints.keep)?;
        tracing::debug!(step = self.state.step, dir = %dir.display(), "checkpoint");
        Ok(dir)
    }

    fn write_log_row(
        &mut self,
        learning_rate: f64,
        rate: f64,
        screening: Option<Screening>,
    ) -> Result<(), TrainError> {
        self.log_started = Instant::now();
        self.log_steps = 0;
        let loss = self.state.log.take_mean();
        let (acc, rollout, emd) =
            screening.map_or((String::new(), String::new(), String::new()), |s| {
                let emd = s.emd.map(|e| e.to_string()).unwrap_or_default();
                (s.mse_acc1.to_string(), s.rollout_mse.to_string(), emd)
            });
        let row = format!(
            "{},{loss},{learning_rate},{rate:.4},{acc},{rollout},{emd}\n",
            self.state.step
        );
        append_log(&self.out.join(LOG_FILE), &row)
    }
}

/// Forgets the best screening result of a resumed run when it was chosen by another metric
/// than `select_by` (the screening may change on `--resume`): the next screening starts the
/// best afresh. A checkpoint from before the state named its metric takes `best/best.json`'s.
fn reconcile_best(out: &Path, state: &mut CheckpointState, select_by: SelectBy) {
    let Some(best) = &mut state.best else {
        return;
    };
    if best.metric.is_none() {
        best.metric = best_file_metric(out);
    }
    if best.metric != Some(select_by) {
        tracing::info!(
            step = best.step,
            was = best.metric.map_or("an unknown metric", SelectBy::column),
            now = select_by.column(),
            "best/ was chosen by another metric: the next screening replaces it"
        );
        state.best = None;
    }
}

/// The metric `best/best.json` of the run in `out` names, if it reads.
fn best_file_metric(out: &Path) -> Option<SelectBy> {
    let path = out.join(super::BEST_DIR).join(super::checkpoint::BEST_FILE);
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(path).ok()?).ok()?;
    let name = json.get("metric")?.as_str()?;
    SelectBy::ALL.into_iter().find(|m| m.column() == name)
}

/// The model of `dir` as the start of a run with `spec`: its weights, `spec`'s facts.
fn start_from<B: GnsKernels>(
    dir: &Path,
    spec: crate::model::ModelSpec,
    device: &B::Device,
) -> Result<Gns<B>, TrainError> {
    let init = load_model::<B>(dir, device)?;
    let (a, b) = (&init.spec().config, &spec.config);
    let differs = [
        ("input_velocities", a.input_velocities != b.input_velocities),
        ("latent_size", a.latent_size != b.latent_size),
        ("hidden_size", a.hidden_size != b.hidden_size),
        ("hidden_layers", a.hidden_layers != b.hidden_layers),
        (
            "message_passing_steps",
            a.message_passing_steps != b.message_passing_steps,
        ),
        ("embedding_size", a.embedding_size != b.embedding_size),
        (
            "boundary_features",
            a.boundary_features != b.boundary_features,
        ),
        ("particle_types", a.particle_types != b.particle_types),
        ("dim", a.dim != b.dim),
    ];
    if let Some((key, _)) = differs.iter().find(|(_, d)| *d) {
        return Err(TrainError::Checkpoint {
            path: dir.join(crate::model::MODEL_FILE),
            reason: format!(
                "config.{key} differs from the configuration's model.{key}: --init-from needs a \
                 model of the same sizes"
            ),
        });
    }
    Ok(Gns::new(spec, init.params().clone())?)
}

/// The first `limit` trajectories of `split` (all for 0).
fn read_split(dataset: &Dataset, split: &str, limit: usize) -> Result<Vec<Trajectory>, TrainError> {
    let reader = dataset.split(split)?;
    let count = if limit == 0 { reader.len() } else { limit };
    Ok(reader.take(count).collect::<Result<_, _>>()?)
}

fn checkpoint_error(path: &Path, reason: impl std::fmt::Display) -> TrainError {
    TrainError::Checkpoint {
        path: path.to_path_buf(),
        reason: reason.to_string(),
    }
}

/// The lock file of a training directory: the process id of the run that holds it.
pub(crate) const LOCK_FILE: &str = "train.lock";

/// A training directory held by this process ([`LOCK_FILE`]), freed when dropped. A lock left by
/// a process that no longer runs (a run that was killed) is taken over.
#[derive(Debug)]
struct RunLock {
    path: PathBuf,
}

impl RunLock {
    fn acquire(out: &Path) -> Result<Self, TrainError> {
        let path = out.join(LOCK_FILE);
        let me = std::process::id();
        // Twice at most: once to find a stale lock, once to take its place.
        for _ in 0..2 {
            match std::fs::OpenOptions::new()
                .write(true)
                .create_new(true)
                .open(&path)
            {
                Ok(mut file) => {
                    writeln!(file, "{me}").map_err(|e| checkpoint_error(&path, e))?;
                    return Ok(RunLock { path });
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                    let holder = std::fs::read_to_string(&path)
                        .ok()
                        .and_then(|text| text.trim().parse::<u32>().ok());
                    if let Some(pid) = holder.filter(|&pid| pid != me && process_runs(pid)) {
                        return Err(checkpoint_error(
                            out,
                            format!(
                                "is in use by another `phi train` (process {pid}); wait for it \
                                 to end, or delete {LOCK_FILE} if no such process runs"
                            ),
                        ));
                    }
                    match std::fs::remove_file(&path) {
                        Ok(()) => {}
                        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                        Err(e) => return Err(checkpoint_error(&path, e)),
                    }
                }
                Err(e) => return Err(checkpoint_error(&path, e)),
            }
        }
        Err(checkpoint_error(
            &path,
            "another process keeps taking the lock; is a second `phi train` starting here?",
        ))
    }
}

impl Drop for RunLock {
    fn drop(&mut self) {
        // Best effort: a lock that stays behind is taken over by the next run.
        let _ = std::fs::remove_file(&self.path);
    }
}

/// Whether process `pid` runs (on Linux, from `/proc`; elsewhere every holder is taken to run,
/// and the message says how to free the directory).
fn process_runs(pid: u32) -> bool {
    if cfg!(target_os = "linux") {
        Path::new(&format!("/proc/{pid}")).exists()
    } else {
        true
    }
}

/// A fresh run needs `out` missing or empty; one that holds a run is refused with a pointer
/// to `--resume`, one that holds anything else naming the entry in the way.
fn check_fresh(out: &Path) -> Result<(), TrainError> {
    if OutputDir::inspect(out, &RUN_OUTPUTS, false)?.holds_nothing() {
        return Ok(());
    }
    Err(checkpoint_error(
        out,
        "holds a training run already: pass --resume to continue it, or choose another --out",
    ))
}

/// What a run writes into its directory, by the rule of every writer of phi
/// ([`phi_io::output_dir`]): a run is recognised by its `train.json`, and a directory holding
/// anything else is refused, naming the entry in the way.
const RUN_OUTPUTS: Outputs = Outputs {
    command: "phi train",
    flag: "--out",
    files: &[TRAIN_FILE, CONFIG_FILE, LOG_FILE, LOCK_FILE],
    subdirs: &[
        OutputSubdir {
            name: CHECKPOINTS_DIR,
            prefix: "step-",
            suffix: "",
        },
        OutputSubdir {
            name: BEST_DIR,
            prefix: "",
            suffix: "",
        },
    ],
    marker: Some(Marker::json(TRAIN_FILE, "made_by", MADE_BY)),
};

/// A resumed run needs `out` to hold a run of `phi train` with the same configuration (the
/// total step count aside), dataset and backend.
fn check_resumable(
    out: &Path,
    options: &RunOptions,
    config: &TrainConfig,
    backend: &str,
) -> Result<(), TrainError> {
    let path = out.join(TRAIN_FILE);
    let record = TrainRecord::read(out)?;
    if record.made_by != MADE_BY {
        return Err(checkpoint_error(
            &path,
            format!("made_by is '{}', not '{MADE_BY}'", record.made_by),
        ));
    }
    let stored_path = out.join(CONFIG_FILE);
    let stored = TrainConfig::from_file(&stored_path)?;
    let mut same_steps = config.clone();
    same_steps.training.steps = stored.training.steps;
    same_steps.training.ema_decay = stored.training.ema_decay;
    // The screening reads the weights and never changes them.
    same_steps.screening = stored.screening.clone();
    if same_steps != stored {
        return Err(checkpoint_error(
            &stored_path,
            "the run was made with another configuration (only training.steps, \
             training.ema_decay and [screening] may change on --resume)",
        ));
    }
    if record.backend != backend {
        tracing::warn!(
            stored = %record.backend,
            given = backend,
            "resuming on another backend: the loss curve will not match an uninterrupted run's bit for bit"
        );
    }
    if record.dataset != options.data {
        tracing::warn!(
            stored = %record.dataset.display(),
            given = %options.data.display(),
            "resuming on a dataset path other than the run's"
        );
    }
    if *config != stored {
        let text = config.to_toml();
        phi_io::write_atomic(&stored_path, |w| {
            phi_io::write_all(w, text.as_bytes(), &stored_path)
        })?;
    }
    Ok(())
}

impl TrainRecord {
    /// The `train.json` of the training directory `out`.
    ///
    /// # Errors
    /// [`TrainError::Checkpoint`] naming the file when it is missing or not such a record.
    pub fn read(out: &Path) -> Result<Self, TrainError> {
        let path = out.join(TRAIN_FILE);
        let bytes = std::fs::read(&path).map_err(|e| {
            checkpoint_error(&path, format!("cannot read ({e}): not a training run"))
        })?;
        serde_json::from_slice(&bytes).map_err(|e| checkpoint_error(&path, e))
    }
}

/// `train.json`, `config.toml` and the header of `train.csv` of a fresh run.
fn write_run_files(out: &Path, options: &RunOptions, backend: &str) -> Result<(), TrainError> {
    std::fs::create_dir_all(out)
        .map_err(|e| checkpoint_error(out, format!("cannot create: {e}")))?;
    let record = TrainRecord {
        made_by: MADE_BY.to_string(),
        dataset: options.data.clone(),
        preset: options.preset.clone(),
        backend: backend.to_string(),
        init_from: options.init_from.clone(),
    };
    let path = out.join(TRAIN_FILE);
    let json = serde_json::to_vec_pretty(&record).map_err(|e| checkpoint_error(&path, e))?;
    phi_io::write_atomic(&path, |w| phi_io::write_all(w, &json, &path))?;
    let path = out.join(CONFIG_FILE);
    let text = options.config.to_toml();
    phi_io::write_atomic(&path, |w| phi_io::write_all(w, text.as_bytes(), &path))?;
    let path = out.join(LOG_FILE);
    let header = format!("{LOG_HEADER}\n");
    phi_io::write_atomic(&path, |w| phi_io::write_all(w, header.as_bytes(), &path))?;
    Ok(())
}

/// Appends `row` to the log and flushes it.
fn append_log(path: &Path, row: &str) -> Result<(), TrainError> {
    let mut file = std::fs::OpenOptions::new()
        .append(true)
        .open(path)
        .map_err(|e| checkpoint_error(path, format!("cannot open: {e}")))?;
    file.write_all(row.as_bytes())
        .and_then(|()| file.flush())
        .map_err(|e| checkpoint_error(path, format!("cannot write: {e}")))
}

/// Cuts the log back to the rows of steps `≤ step` (and drops a row cut short by a kill). A
/// log from before the EMD column gets the column, empty in its rows.
fn truncate_log(path: &Path, step: u64) -> Result<(), TrainError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| checkpoint_error(path, format!("cannot read: {e}")))?;
    let mut kept = String::with_capacity(text.len());
    let mut upgrade = false;
    for (i, line) in text.split_inclusive('\n').enumerate() {
        if i == 0 {
            match line.trim_end() {
                LOG_HEADER => {}
                LOG_HEADER_BEFORE_EMD => upgrade = true,
                _ => {
                    return Err(checkpoint_error(
                        path,
                        "not the log of phi train (another header)",
                    ));
                }
            }
            kept.push_str(LOG_HEADER);
            kept.push('\n');
            continue;
        }
        let complete = line.ends_with('\n');
        let row_step = line.split(',').next().and_then(|s| s.parse::<u64>().ok());
        match row_step {
            Some(s) if complete && s <= step => {
                if upgrade {
                    kept.push_str(line.trim_end_matches('\n'));
                    kept.push_str(",\n");
                } else {
                    kept.push_str(line);
                }
            }
            _ => {}
        }
    }
    phi_io::write_atomic(path, |w| phi_io::write_all(w, kept.as_bytes(), path))?;
    Ok(())
}
