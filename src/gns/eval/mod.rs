//! `phi eval`: trained GNS models evaluated on a split of a dataset as the thesis does
//! (section 5.4, table B.1, figs. 5.5–5.8), several models side by side.
//!
//! The metrics are those of [`phi_gns::eval`]. The output directory holds:
//! - `eval.json`: the dataset, the split, the options and, per model, its directory, its
//!   weights digest, its summary ([`ModelSummary`]) and the per-frame bands of MSE and EMD.
//!   Written first (`"complete": false`), so that the directory is recognisably ours, and last;
//! - `table.md` (the units of table B.1) and `table.csv` (raw values): one row per model;
//! - `error_over_time.png` (fig. 5.7: MSE and EMD per frame, mean over the trajectories with
//!   the min–max range), `metrics.png` (fig. 5.6) and, for models that come from a `phi train`
//!   directory, `screening.png` (fig. 5.5: the validation curves of its `train.csv`);
//! - `rollouts.gif` (fig. 5.8): one trajectory, the ground truth first and then every model, side
//!   by side, each panel captioned with its model and the truth's with the frame (2D datasets);
//! - `cache/<model>/<split>_<index>.json`: each trajectory's evaluation, written as soon as it
//!   is done and reused by a later run with the same model weights, dataset trajectory and
//!   options, so that a killed evaluation resumes where it stopped. A cache entry of another
//!   model, trajectory or options is an error naming both, never silently overwritten (with
//!   `--force` it is recomputed).
//!
//! The output directory must be new or empty, or hold an evaluation of `phi eval` (recognised
//! by its `eval.json`, [`EVAL_OUTPUTS`]); anything else is refused even with `--force`. An
//! unfinished evaluation (`"complete": false`: a killed run) is resumed as it is: run the same
//! command again. A finished one is replaced only with `--force`, which removes its record,
//! tables, figures and GIF but keeps the cache, so that adding a model to an evaluation or
//! re-running it recomputes only what is not cached.
//!
//! Trajectories are evaluated in parallel (rayon) on the forward backend.

mod plots;

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use anyhow::{Context, Result, bail};
use phi_gns::data::{Dataset, METADATA_FILE, Metadata};
use phi_gns::eval::metrics::Container;
use phi_gns::eval::{
    Band, EmdCost, EvalOptions, ModelSummary, TrajectoryEvaluation, evaluate_trajectory,
    evaluate_trajectory_with, one_step_errors,
};
use phi_gns::model::{
    Floor, Gns, GnsKernels, MODEL_FILE, ModelError, ModelSpec, Obstacles, WEIGHTS_FILE, Walls,
    load_model, read_spec,
};
use phi_gns::rollout::{RolloutRange, rollout};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::{BoundsFrom, bounds_for};
use crate::backends::BackendKind;
use crate::dataset::render::DatasetRenderer;
use crate::output::target::{Marker, OutputSubdir, Outputs, Previous, previous_output};
use crate::output::{FrameStyle, GifWriter, OutputError, RgbImage, side_by_side, write_atomic};

/// The value of [`EvalRecord::format`].
pub(crate) const EVAL_FORMAT: &str = "phi-eval";
/// The value of [`CacheEntry::format`].
pub(crate) const CACHE_FORMAT: &str = "phi-eval-trajectory";
/// The record of an evaluation directory.
pub(crate) const RECORD_FILE: &str = "eval.json";
/// The table in the units of table B.1.
pub(crate) const TABLE_MD: &str = "table.md";
/// The table in raw values.
pub(crate) const TABLE_CSV: &str = "table.csv";
/// The per-trajectory results.
pub(crate) const CACHE_DIR: &str = "cache";
/// Fig. 5.7: MSE and EMD per frame.
pub(crate) const ERROR_PLOT: &str = "error_over_time.png";
/// Fig. 5.6: the metrics of table B.1 as bars.
pub(crate) const METRICS_PLOT: &str = "metrics.png";
/// Fig. 5.5: the screening curves of the training logs.
pub(crate) const SCREENING_PLOT: &str = "screening.png";
/// The rollouts of every model on one trajectory, beside the truth.
pub(crate) const GIF_FILE: &str = "rollouts.gif";

/// What `phi eval` writes, recognised by the `format` of its [`RECORD_FILE`]. The entries of
/// [`CACHE_DIR`] are checked one by one when read ([`EVAL_FORMAT`]'s cache entries).
pub(crate) const EVAL_OUTPUTS: Outputs = Outputs {
    command: "phi eval",
    flag: "--out",
    files: &[
        RECORD_FILE,
        TABLE_MD,
        TABLE_CSV,
        ERROR_PLOT,
        METRICS_PLOT,
        SCREENING_PLOT,
        GIF_FILE,
    ],
    subdirs: &[OutputSubdir {
        name: CACHE_DIR,
        prefix: "",
        suffix: "",
    }],
    marker: Some(Marker::json(RECORD_FILE, "format", EVAL_FORMAT)),
};

/// Columns of background between the panels of the GIF.
const GIF_GAP: u32 = 6;

/// The ground cost of the EMD on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum CostArg {
    /// `|x − y|²` (POT's `ot.dist` default, what the thesis's EMD used).
    Sqeuclidean,
    /// `|x − y|`.
    Euclidean,
}

/// `phi eval --model [NAME=]DIR ... --data DATASET --out DIR [options]`.
#[derive(Debug, Clone, clap::Args)]
pub struct EvalArgs {
    /// A model directory (model.json, model.safetensors) or a `phi train` directory (its best/
    /// model and its train.csv), optionally named `NAME=DIR`; repeat for several models.
    #[arg(long = "model", required = true, value_name = "[NAME=]DIR")]
    pub models: Vec<String>,
    /// The dataset directory.
    #[arg(long)]
    pub data: PathBuf,
    /// `NAME=DATASET`: evaluate the model named NAME on another dataset of the same scenes (a
    /// walls-variant model such as 1snb on the walls variant of `--data`), so that it joins the
    /// same table; its split must come from the same seed, with the same trajectory count, frames
    /// and bounds. Repeat for several models.
    #[arg(long = "model-data", value_name = "NAME=DATASET")]
    pub model_data: Vec<String>,
    /// `NAME=WALLS`: roll the model named NAME out with `open` or `clamp` walls instead of its
    /// model.json's (see `phi rollout --walls`), so that one model can join the table both
    /// ways under two names; NAME may be a floor of `--floors`. Repeat for several models.
    #[arg(long = "model-walls", value_name = "NAME=WALLS")]
    pub model_walls: Vec<String>,
    /// `NAME=OBSTACLES`: roll the model named NAME out with `open` or `push` obstacles instead
    /// of its model.json's (see `phi rollout --obstacles`; the cells pushed out of are those of
    /// its dataset's `position_scale`); NAME may be a floor of `--floors`. Repeat for several
    /// models.
    #[arg(long = "model-obstacles", value_name = "NAME=OBSTACLES")]
    pub model_obstacles: Vec<String>,
    /// `NAME=RUN`: the training run whose `train.csv` `screening.png` draws for the model named
    /// NAME (its loss, and its screenings where it has them), for a model copied out of its run
    /// (a model in `RUN/best/` or `RUN/checkpoints/step-…/` is found without it) or trained
    /// elsewhere with a log of the same columns. Repeat for several models.
    #[arg(long = "model-run", value_name = "NAME=RUN")]
    pub model_run: Vec<String>,
    /// The split to evaluate on: train, valid, test, or another its metadata.json lists.
    #[arg(long, default_value = "test", value_name = "SPLIT", value_parser = crate::cli::parse_split)]
    pub split: String,
    /// Evaluate only the first N trajectories of the split [default: all].
    #[arg(long)]
    pub trajectories: Option<usize>,
    /// The output directory.
    #[arg(long)]
    pub out: PathBuf,
    /// Replace a finished evaluation in --out, reusing its cached trajectory evaluations where
    /// they fit and recomputing the others (an unfinished one resumes without it; anything
    /// `phi eval` does not write is refused even with it).
    #[arg(long)]
    pub force: bool,
    /// The backend [default: ndarray, as for every command without gradients].
    #[arg(long)]
    pub backend: Option<BackendKind>,
    /// Steps of the short rollouts of MSE 20.
    #[arg(long, default_value_t = 20)]
    pub short_rollout: usize,
    /// The EMD's ground cost.
    #[arg(long, value_enum, default_value_t = CostArg::Sqeuclidean)]
    pub emd_cost: CostArg,
    /// The Sinkhorn divergence's ε (stored units², cost ½|x − y|²).
    #[arg(long, default_value_t = 1e-4)]
    pub sinkhorn_epsilon: f32,
    /// The Sinkhorn divergence every this many frames (0: none).
    #[arg(long, default_value_t = 100)]
    pub sinkhorn_every: usize,
    /// The radius of the density's neighbour counts [default: the dataset's
    /// default_connectivity_radius].
    #[arg(long)]
    pub density_radius: Option<f64>,
    /// The trajectory of rollouts.gif, an index into the split (--gif-index before,
    /// deprecated).
    #[arg(long, alias = "gif-index", value_name = "I", default_value_t = 0)]
    pub gif_trajectory: usize,
    /// A picture of rollouts.gif every this many frames (0: no GIF; --gif-every before,
    /// deprecated). The default, 2, as `phi render`'s: a panel per model beside the truth makes
    /// each picture several times wider than `phi rollout`'s.
    #[arg(long, alias = "gif-every", default_value_t = 2)]
    pub frame_every: usize,
    /// Pixels per grid cell in the GIF.
    #[arg(long, default_value_t = 4)]
    pub pixels_per_cell: u32,
    /// For a dataset whose domain is not the models': the walls their boundary features
    /// measure, the dataset's (`data`) or the training domain's (`model`) [default: refuse such
    /// a dataset].
    #[arg(long, value_enum)]
    pub bounds: Option<BoundsFrom>,
    /// Also evaluate the floors every model is read against: `constant-velocity` (zero
    /// acceleration) and `mean-acceleration` (the dataset's mean acceleration for every
    /// particle), as rows of the table and panels of the GIF.
    #[arg(long)]
    pub floors: bool,
}

/// A model as the command line named it, resolved.
#[derive(Debug, Clone)]
pub(crate) struct ModelEntry {
    /// Its name in tables and plots.
    pub label: String,
    /// The model directory (model.json, model.safetensors).
    pub dir: PathBuf,
    /// The `phi train` directory it comes from, if any (for its train.csv).
    pub run: Option<PathBuf>,
    /// Its model.json.
    pub spec: ModelSpec,
    /// A digest of model.json and model.safetensors: which weights a cache entry belongs to
    /// (with the bounds of `--bounds data` appended when they replace the model's).
    pub digest: String,
    /// The dataset's bounds for the boundary features (`--bounds data`), or `None`.
    pub bounds: Option<Vec<[f64; 2]>>,
    /// The walls of its rollouts when `--model-walls` replaces the model's.
    pub walls: Option<Walls>,
    /// The obstacles of its rollouts when `--model-obstacles` replaces the model's.
    pub obstacles: Option<Obstacles>,
    /// Which of [`Plan`]'s datasets it is evaluated on: 0 for `--data`, k for the k-th
    /// `--model-data`.
    pub data: usize,
    /// For a floor (`--floors`): which, and the metadata of the dataset whose statistics it
    /// predicts from; the model is then built, not read from `dir`.
    pub floor: Option<(Floor, Box<Metadata>)>,
}

impl ModelEntry {
    /// The model on `device`, with [`ModelEntry::bounds`] applied.
    ///
    /// # Errors
    /// Unreadable or invalid model files.
    pub fn load<B: GnsKernels>(&self, device: &B::Device) -> Result<Gns<B>> {
        if let Some((floor, metadata)) = &self.floor {
            let c = self.spec.config.input_velocities;
            let mut gns = floor.model::<B>(metadata, c, device)?;
            if let Some(walls) = self.walls {
                gns = gns.with_walls(walls);
            }
            if let Some(obstacles) = self.obstacles {
                gns = gns.with_obstacles(obstacles)?;
            }
            return Ok(gns);
        }
        let mut gns = load_model::<B>(&self.dir, device)?;
        if let Some(bounds) = &self.bounds {
            gns = gns.with_bounds(bounds.clone())?;
        }
        if let Some(walls) = self.walls {
            gns = gns.with_walls(walls);
        }
        if let Some(obstacles) = self.obstacles {
            gns = gns.with_obstacles(obstacles)?;
        }
        Ok(gns)
    }
}

/// One model's part of `eval.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct ModelRecord {
    /// The model's name.
    pub label: String,
    /// The model directory.
    pub dir: String,
    /// The dataset it was evaluated on when not the evaluation's (`--model-data`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dataset: Option<String>,
    /// The weights digest.
    pub digest: String,
    /// The metrics over the evaluated trajectories (`null` until done).
    pub summary: Option<ModelSummary>,
    /// Position MSE per frame over the trajectories.
    pub mse_band: Option<Band>,
    /// EMD per frame over the trajectories.
    pub emd_band: Option<Band>,
}

/// `eval.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct EvalRecord {
    /// Always [`EVAL_FORMAT`].
    pub format: String,
    /// `phi eval` and its version.
    pub made_by: String,
    /// The dataset directory, as given.
    pub dataset: String,
    /// The split.
    pub split: String,
    /// The indices evaluated.
    pub trajectories: Vec<usize>,
    /// The metric options.
    pub options: EvalOptions,
    /// Whether every model was evaluated on every trajectory.
    pub complete: bool,
    /// The models, in command-line order.
    pub models: Vec<ModelRecord>,
    /// The trajectory of the GIF and its panels from left to right (`null` without a GIF).
    pub gif: Option<GifRecord>,
}

/// What `rollouts.gif` shows.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct GifRecord {
    /// The trajectory's index in the split.
    pub index: usize,
    /// The panels from left to right: `ground truth`, then the models' names.
    pub panels: Vec<String>,
    /// The dataset frames shown.
    pub frames: Vec<usize>,
}

/// `cache/<model>/<split>_<index>.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct CacheEntry {
    /// Always [`CACHE_FORMAT`].
    pub format: String,
    /// The model directory it was computed for.
    pub model: String,
    /// That model's weights digest.
    pub digest: String,
    /// The split.
    pub split: String,
    /// The options it was computed with.
    pub options: EvalOptions,
    /// The result.
    pub evaluation: TrajectoryEvaluation,
}

/// What was checked before any evaluation.
#[derive(Debug)]
pub(crate) struct Plan {
    /// `--data`, then each `--model-data` dataset.
    datasets: Vec<Dataset>,
    models: Vec<ModelEntry>,
    indices: Vec<usize>,
    options: EvalOptions,
    /// The earlier evaluation in `--out`, to be resumed or replaced.
    previous: Option<Previous>,
}

/// Resolves `[NAME=]DIR`: a model directory, or a `phi train` directory whose `best/` model
/// is taken. The default name is the directory's (the training directory's for `best/` and
/// `checkpoints/step-N/`, with `@step-N` for the latter).
///
/// # Errors
/// A directory that is neither, or a model.json that does not read.
pub(crate) fn resolve_model(arg: &str) -> Result<ModelEntry> {
    let (name, path) = match arg.split_once('=') {
        Some((name, path)) if !name.is_empty() && !Path::new(arg).exists() => {
            (Some(name.to_string()), PathBuf::from(path))
        }
        _ => (None, PathBuf::from(arg)),
    };
    let file_name = |p: &Path| {
        p.file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| p.display().to_string())
    };
    let (dir, run) = if path.join(MODEL_FILE).is_file() {
        let base = file_name(&path);
        let run = if base == phi_gns::train::BEST_DIR {
            path.parent().map(Path::to_path_buf)
        } else if base.starts_with("step-") {
            path.parent().and_then(Path::parent).map(Path::to_path_buf)
        } else {
            None
        };
        (path.clone(), run.filter(|r| r.join("train.csv").is_file()))
    } else if path.join("train.json").is_file() {
        let best = path.join(phi_gns::train::BEST_DIR);
        if !best.join(MODEL_FILE).is_file() {
            bail!(
                "--model {arg}: the training directory {} has no {}/ model yet (it is written \
                 at the first screening); name a checkpoint instead: {}/checkpoints/step-…",
                path.display(),
                phi_gns::train::BEST_DIR,
                path.display()
            );
        }
        (best, Some(path.clone()))
    } else {
        bail!(
            "--model {arg}: {} holds neither a model ({MODEL_FILE}) nor a `phi train` directory \
             (train.json)",
            path.display()
        );
    };
    let label = name.unwrap_or_else(|| match &run {
        Some(run) if dir != *run => {
            let base = file_name(&dir);
            if base == phi_gns::train::BEST_DIR {
                file_name(run)
            } else {
                format!("{}@{base}", file_name(run))
            }
        }
        _ => file_name(&dir),
    });
    let spec = read_spec(&dir)?;
    let digest = model_digest(&dir)?;
    Ok(ModelEntry {
        label,
        dir,
        run,
        spec,
        digest,
        bounds: None,
        walls: None,
        obstacles: None,
        data: 0,
        floor: None,
    })
}

/// The entry of `floor` on `metadata`'s dataset, for models of `input_velocities` past
/// velocities. Its directory is the pseudo-path `floor:NAME`; its digest holds the
/// acceleration it predicts, so that a cache entry follows the dataset's statistics.
///
/// # Errors
/// A dataset whose statistics make no valid model.
fn floor_entry(floor: Floor, metadata: &Metadata, input_velocities: usize) -> Result<ModelEntry> {
    let model =
        floor.model::<phi_core::backend::Host>(metadata, input_velocities, &Default::default())?;
    Ok(ModelEntry {
        label: floor.name().to_string(),
        dir: PathBuf::from(format!("floor:{}", floor.name())),
        run: None,
        spec: model.spec().clone(),
        digest: format!("floor:{}:{:?}", floor.name(), floor.acceleration(metadata)),
        bounds: None,
        walls: None,
        obstacles: None,
        data: 0,
        floor: Some((floor, Box::new(metadata.clone()))),
    })
}

/// A digest of a model directory's two files: CRC-32 of each and their lengths, in hex.
fn model_digest(dir: &Path) -> Result<String> {
    let mut parts = Vec::new();
    for name in [MODEL_FILE, WEIGHTS_FILE] {
        let path = dir.join(name);
        let bytes = std::fs::read(&path).with_context(|| format!("reading {}", path.display()))?;
        parts.push(format!("{:08x}-{}", crc32fast::hash(&bytes), bytes.len()));
    }
    Ok(parts.join(":"))
}

/// Checks everything before anything is written: each model's files and that it fits the
/// dataset, distinct names, the split and the trajectory count, the options, and that the
/// output directory is empty or one of ours.
///
/// # Errors
/// Naming the option, file or key and what is wrong.
pub(crate) fn plan(args: &EvalArgs) -> Result<Plan> {
    let dataset = Dataset::open(&args.data)?;
    let (mut datasets, model_data) = (vec![dataset], other_datasets(args)?);
    let models = resolve_models(args, &mut datasets, &model_data)?;
    let dataset = &datasets[0];
    let count = crate::cli::split_len(dataset, &args.data, &args.split)?;
    for (name, dir, other) in &model_data {
        same_scenes(dataset, other, &args.split)
            .with_context(|| format!("--model-data {name}={}", dir.display()))?;
    }
    if count == 0 {
        bail!(
            "{}: split '{}' has no trajectories",
            args.data.display(),
            args.split
        );
    }
    let used = match args.trajectories {
        Some(0) => bail!("--trajectories 0: nothing to evaluate"),
        Some(n) if n > count => bail!(
            "--trajectories {n}: split '{}' of {} has {count}",
            args.split,
            args.data.display()
        ),
        Some(n) => n,
        None => count,
    };
    if args.frame_every > 0 && args.gif_trajectory >= used {
        bail!(
            "--gif-trajectory {}: only trajectories 0..{used} are evaluated",
            args.gif_trajectory
        );
    }
    if args.short_rollout == 0 {
        bail!("--short-rollout 0: the short rollouts need at least one step");
    }
    if !(args.sinkhorn_epsilon.is_finite() && args.sinkhorn_epsilon > 0.0) {
        bail!(
            "--sinkhorn-epsilon {}: must be positive and finite",
            args.sinkhorn_epsilon
        );
    }
    let radius = args
        .density_radius
        .unwrap_or(dataset.metadata().default_connectivity_radius);
    if !(radius.is_finite() && radius > 0.0) {
        bail!("--density-radius {radius}: must be positive and finite");
    }
    let previous = check_out(&args.out, args.force)?;
    let options = EvalOptions {
        short_rollout: args.short_rollout,
        ground_cost: match args.emd_cost {
            CostArg::Sqeuclidean => EmdCost::SquaredEuclidean,
            CostArg::Euclidean => EmdCost::Euclidean,
        },
        sinkhorn_epsilon: args.sinkhorn_epsilon,
        sinkhorn_every: args.sinkhorn_every,
        density_radius: radius,
        container: Some(Container {
            bounds: dataset.metadata().bounds.clone(),
            cell_size: dataset.metadata().position_scale,
        }),
    };
    Ok(Plan {
        datasets,
        models,
        indices: (0..used).collect(),
        options,
        previous: Some(previous),
    })
}

/// The `--model`s resolved, each with its dataset (`--model-data`, appended to `datasets`),
/// bounds and walls, then the floors (`--floors`); names are checked to be distinct and usable
/// as folder names, and every `--model-data` and `--model-walls` name to be a model's.
fn resolve_models(
    args: &EvalArgs,
    datasets: &mut Vec<Dataset>,
    model_data: &[(String, PathBuf, Dataset)],
) -> Result<Vec<ModelEntry>> {
    let overrides = ModelOverrides::parse(args)?;
    let mut models: Vec<ModelEntry> = Vec::with_capacity(args.models.len());
    for arg in &args.models {
        let mut entry = resolve_model(arg)?;
        if let Some((_, dir, other)) = model_data.iter().find(|(name, ..)| *name == entry.label) {
            entry.data = datasets.len();
            entry.digest.push_str(&format!(":data{}", dir.display()));
            datasets.push(other.clone());
        }
        let data = &datasets[entry.data];
        let metadata_path = data.dir().join(METADATA_FILE);
        entry.bounds = bounds_for(&entry.spec, data.metadata(), &metadata_path, args.bounds)
            .with_context(|| {
                format!(
                    "--model {arg} ({}) does not fit the dataset {}",
                    entry.dir.display(),
                    data.dir().display()
                )
            })?;
        if let Some(bounds) = &entry.bounds {
            entry.digest.push_str(&format!(":bounds{bounds:?}"));
        }
        overrides.apply(&mut entry, data.metadata());
        overrides.apply_run(&mut entry)?;
        if let Some(other) = models.iter().find(|m| m.label == entry.label) {
            bail!(
                "--model {arg}: the name '{}' is taken by {}; name them: --model NAME=DIR",
                entry.label,
                other.dir.display()
            );
        }
        if entry.label.contains(['/', '\\']) || entry.label.starts_with('.') {
            bail!(
                "--model {arg}: the name '{}' cannot be a folder name; name it: --model NAME=DIR",
                entry.label
            );
        }
        models.push(entry);
    }
    if args.floors {
        let c = models[0].spec.config.input_velocities;
        for floor in Floor::ALL {
            if let Some(taken) = models.iter().find(|m| m.label == floor.name()) {
                bail!(
                    "--floors: the name '{}' is taken by {}; name it otherwise: --model NAME=DIR",
                    floor.name(),
                    taken.dir.display()
                );
            }
            let mut entry = floor_entry(floor, datasets[0].metadata(), c)?;
            overrides.apply(&mut entry, datasets[0].metadata());
            models.push(entry);
        }
    }
    if let Some((name, ..)) = model_data
        .iter()
        .find(|(name, ..)| !models.iter().any(|m| m.label == *name))
    {
        bail!("--model-data {name}=…: no --model is named '{name}'");
    }
    overrides.check_names(&models)?;
    Ok(models)
}

/// The per-model overrides of `phi eval`: `--model-walls`, `--model-obstacles` and
/// `--model-run`, each a list of `NAME=VALUE`.
struct ModelOverrides {
    walls: Vec<(String, Walls)>,
    /// `true` for `push`.
    obstacles: Vec<(String, bool)>,
    runs: Vec<(String, PathBuf)>,
}

impl ModelOverrides {
    fn parse(args: &EvalArgs) -> Result<Self> {
        Ok(ModelOverrides {
            walls: named_overrides("--model-walls", &args.model_walls, |w| match w {
                "open" => Some(Walls::Open),
                "clamp" => Some(Walls::Clamp),
                _ => None,
            })?,
            obstacles: named_overrides("--model-obstacles", &args.model_obstacles, |o| {
                ["open", "push"].contains(&o).then_some(o == "push")
            })?,
            runs: named_overrides("--model-run", &args.model_run, |run| {
                Some(PathBuf::from(run))
            })?,
        })
    }

    /// The walls and obstacles named for `entry`, evaluated on a dataset of `metadata`.
    fn apply(&self, entry: &mut ModelEntry, metadata: &Metadata) {
        if let Some((_, walls)) = self.walls.iter().find(|(name, _)| *name == entry.label) {
            entry.walls = Some(*walls);
            entry.digest.push_str(&format!(":walls-{walls:?}"));
        }
        override_obstacles(entry, &self.obstacles, metadata);
    }

    /// The training run named for `entry` (`--model-run`), which must hold a `train.csv`.
    fn apply_run(&self, entry: &mut ModelEntry) -> Result<()> {
        if let Some((_, run)) = self.runs.iter().find(|(name, _)| *name == entry.label) {
            if !run.join("train.csv").is_file() {
                bail!(
                    "--model-run {}={}: no train.csv there (a phi train directory has one)",
                    entry.label,
                    run.display()
                );
            }
            entry.run = Some(run.clone());
        }
        Ok(())
    }

    /// Every name an override gives is a model's.
    fn check_names(&self, models: &[ModelEntry]) -> Result<()> {
        let given: [(&str, Vec<&String>); 3] = [
            ("--model-walls", self.walls.iter().map(|(n, _)| n).collect()),
            (
                "--model-obstacles",
                self.obstacles.iter().map(|(n, _)| n).collect(),
            ),
            ("--model-run", self.runs.iter().map(|(n, _)| n).collect()),
        ];
        for (flag, names) in given {
            if let Some(name) = names
                .iter()
                .find(|name| !models.iter().any(|m| m.label == ***name))
            {
                bail!("{flag} {name}=…: no --model is named '{name}'");
            }
        }
        Ok(())
    }
}

/// `--model-obstacles` applied to `entry`: `push` pushes out of the cells of `metadata`'s
/// `position_scale`, the spacing of the obstacle particles of the dataset it is evaluated on.
fn override_obstacles(entry: &mut ModelEntry, overrides: &[(String, bool)], metadata: &Metadata) {
    if let Some((_, push)) = overrides.iter().find(|(name, _)| *name == entry.label) {
        let obstacles = if *push {
            Obstacles::Push {
                cell_size: metadata.position_scale,
            }
        } else {
            Obstacles::Open
        };
        entry.obstacles = Some(obstacles);
        entry.digest.push_str(&format!(":obstacles-{obstacles:?}"));
    }
}

/// The `FLAG NAME=VALUE` pairs of a per-model override, each NAME once, VALUE parsed by `parse`
/// (`None`: not a value of FLAG).
fn named_overrides<T>(
    flag: &str,
    args: &[String],
    parse: impl Fn(&str) -> Option<T>,
) -> Result<Vec<(String, T)>> {
    let mut out: Vec<(String, T)> = Vec::with_capacity(args.len());
    for arg in args {
        let Some((name, value)) = arg.split_once('=') else {
            bail!("{flag} {arg}: expected NAME=VALUE, NAME a --model's name");
        };
        let Some(value) = parse(value) else {
            bail!("{flag} {arg}: '{value}' is not one of its values (see phi eval --help)");
        };
        if out.iter().any(|(n, _)| n == name) {
            bail!("{flag} {arg}: the model '{name}' is named twice");
        }
        out.push((name.to_string(), value));
    }
    Ok(out)
}

/// The `--model-data NAME=DATASET` pairs, opened.
fn other_datasets(args: &EvalArgs) -> Result<Vec<(String, PathBuf, Dataset)>> {
    let mut out: Vec<(String, PathBuf, Dataset)> = Vec::with_capacity(args.model_data.len());
    for arg in &args.model_data {
        let Some((name, dir)) = arg
            .split_once('=')
            .filter(|(n, d)| !n.is_empty() && !d.is_empty())
        else {
            bail!("--model-data {arg}: expected NAME=DATASET, NAME a --model's name");
        };
        if out.iter().any(|(n, ..)| n == name) {
            bail!("--model-data {arg}: the model '{name}' has a dataset already");
        }
        let dataset = Dataset::open(dir).with_context(|| format!("--model-data {arg}"))?;
        out.push((name.to_string(), PathBuf::from(dir), dataset));
    }
    Ok(out)
}

/// Checks that `other` holds the scenes of `dataset`'s `split`: the same generator seed, the
/// same number of trajectories, frames, dimension and bounds (the walls variant of a dataset
/// differs in its wall particles alone).
fn same_scenes(dataset: &Dataset, other: &Dataset, split: &str) -> Result<()> {
    let (a, b) = (dataset.metadata(), other.metadata());
    let what = |key: &str, x: String, y: String| {
        anyhow::anyhow!(
            "{}: {key} is {y}, where {} has {x}: not the same scenes",
            other.dir().join(METADATA_FILE).display(),
            dataset.dir().display()
        )
    };
    if a.seeds.get(split) != b.seeds.get(split) {
        let show = |m: &phi_gns::data::Metadata| {
            m.seeds
                .get(split)
                .map_or("none".to_string(), u64::to_string)
        };
        return Err(what(&format!("seeds.{split}"), show(a), show(b)));
    }
    let (n, m) = (dataset.split_len(split)?, other.split_len(split)?);
    if n != m {
        return Err(what(
            &format!("splits.{split}"),
            n.to_string(),
            m.to_string(),
        ));
    }
    if a.sequence_length != b.sequence_length {
        let (x, y) = (a.sequence_length.to_string(), b.sequence_length.to_string());
        return Err(what("sequence_length", x, y));
    }
    if a.dim != b.dim || a.bounds != b.bounds {
        let (x, y) = (format!("{:?}", a.bounds), format!("{:?}", b.bounds));
        return Err(what("bounds", x, y));
    }
    Ok(())
}

/// The rule of [`EVAL_OUTPUTS`] for `out`, with one exception: an unfinished evaluation (its
/// `eval.json` says `"complete": false`) is resumed without `force`.
///
/// # Errors
/// `out` holds anything `phi eval` does not write, or a finished evaluation and no `force`.
fn check_out(out: &Path, force: bool) -> Result<Previous> {
    let previous = previous_output(out, &EVAL_OUTPUTS, force)?;
    let unfinished = std::fs::read(out.join(RECORD_FILE))
        .ok()
        .and_then(|bytes| serde_json::from_slice::<serde_json::Value>(&bytes).ok())
        .is_some_and(|record| record.get("complete") == Some(&serde_json::Value::Bool(false)));
    if unfinished {
        return Ok(previous);
    }
    previous.require_force(force)
}

/// Runs `phi eval`: evaluates every model on every trajectory (reusing cached results), then
/// writes the record, the tables, the plots and the GIF, and prints the table.
///
/// # Errors
/// As [`plan`]; a model that does not load; a cache entry of another model or options; I/O.
pub fn run(args: EvalArgs) -> Result<()> {
    let mut plan = plan(&args)?;
    if let Some(previous) = plan.previous.take() {
        // The record is rewritten at once; the cache is reused where it fits.
        previous.keep(CACHE_DIR).keep(RECORD_FILE).remove()?;
    }
    let kind = args.backend.unwrap_or_else(BackendKind::default_forward);
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let mut record = EvalRecord {
        format: EVAL_FORMAT.to_string(),
        made_by: format!("phi eval {}", env!("CARGO_PKG_VERSION")),
        dataset: args.data.display().to_string(),
        split: args.split.clone(),
        trajectories: plan.indices.clone(),
        options: plan.options.clone(),
        complete: false,
        gif: None,
        models: plan
            .models
            .iter()
            .map(|m| ModelRecord {
                label: m.label.clone(),
                dir: m.dir.display().to_string(),
                dataset: (m.data > 0).then(|| plan.datasets[m.data].dir().display().to_string()),
                digest: m.digest.clone(),
                summary: None,
                mse_band: None,
                emd_band: None,
            })
            .collect(),
    };
    write_json(&args.out.join(RECORD_FILE), &record)?;
    let (evaluations, kept) = crate::with_backend!(kind, B => evaluate_all::<B>(&plan, &args))?;
    for (model, evals) in record.models.iter_mut().zip(&evaluations) {
        // MSE-acc 1 in one normalisation for every model: the (first) dataset's.
        model.summary = Some(ModelSummary::of(
            evals,
            &plan.datasets[0].metadata().acc_std,
        ));
        model.mse_band = Some(Band::of(evals, |e| &e.curves.mse));
        model.emd_band = Some(Band::of(evals, |e| &e.curves.emd));
    }
    if args.frame_every > 0 && plan.datasets[0].metadata().dim == 2 {
        record.gif = Some(crate::with_backend!(kind, B => write_gif::<B>(&plan, &args, kept))?);
    }
    let mut figures = Vec::new();
    let any_band = record
        .models
        .iter()
        .filter_map(|m| m.mse_band.as_ref())
        .any(|b| b.mean.iter().any(|v| v.is_finite() && *v > 0.0));
    if any_band {
        plots::error_over_time(&record, &args.out.join(ERROR_PLOT))?;
        figures.push(ERROR_PLOT);
    }
    plots::metric_bars(&record, &args.out.join(METRICS_PLOT))?;
    figures.push(METRICS_PLOT);
    if plots::screening(&plan.models, &args.out.join(SCREENING_PLOT))? {
        figures.push(SCREENING_PLOT);
    }
    record.complete = true;
    let table = markdown_table(&record);
    write_text(&args.out.join(TABLE_MD), &table)?;
    write_text(&args.out.join(TABLE_CSV), &csv_table(&record))?;
    write_json(&args.out.join(RECORD_FILE), &record)?;
    print!("{table}");
    let gif = match &record.gif {
        Some(gif) => format!(
            ", {GIF_FILE} (trajectory {}: {})",
            gif.index,
            gif.panels.join(" | ")
        ),
        None => String::new(),
    };
    println!(
        "wrote {}: {RECORD_FILE}, {TABLE_MD}, {TABLE_CSV}, {}{gif}, {CACHE_DIR}/",
        args.out.display(),
        figures.join(", ")
    );
    std::io::stdout().flush().ok();
    Ok(())
}

/// Evaluates every (model, trajectory) pair not in the cache, in parallel, writing each result
/// to the cache as it is done; returns each model's evaluations in index order.
fn evaluate_all<B: GnsKernels>(
    plan: &Plan,
    args: &EvalArgs,
) -> Result<(Vec<Vec<TrajectoryEvaluation>>, KeptRollouts)> {
    let mut results: Vec<Vec<Option<TrajectoryEvaluation>>> =
        vec![vec![None; plan.indices.len()]; plan.models.len()];
    let mut todo = Vec::new();
    for (m, model) in plan.models.iter().enumerate() {
        let dir = args.out.join(CACHE_DIR).join(&model.label);
        for (k, &index) in plan.indices.iter().enumerate() {
            let path = dir.join(cache_file_name(&args.split, index));
            match read_cache(&path, model, &args.split, &plan.options, args.force)? {
                // An entry from before the stored-unit one-step errors were recorded: only they
                // are computed.
                Some(entry) if entry.evaluation.acc_error.is_empty() => {
                    todo.push((m, k, index, path, Some(entry)));
                }
                Some(entry) => results[m][k] = Some(entry.evaluation),
                None => todo.push((m, k, index, path, None)),
            }
        }
    }
    let cached = plan.models.len() * plan.indices.len() - todo.len();
    if cached > 0 {
        tracing::info!(cached, "reusing cached trajectory evaluations");
    }
    let completed = todo.iter().filter(|t| t.4.is_some()).count();
    if completed > 0 {
        tracing::info!(
            completed,
            "adding the one-step errors in stored units to cached evaluations"
        );
    }
    // One item per model and trajectory.
    let bar = crate::progress::count_bar(
        todo.len(),
        "trajectory evaluations",
        std::io::IsTerminal::is_terminal(&std::io::stderr()),
    );
    let done = Mutex::new(Vec::with_capacity(todo.len()));
    // The jobs of each model in one lane per thread, each lane reading the weights once (a
    // model on the device is not shared between threads).
    let threads = rayon::current_num_threads().max(1);
    let mut lanes: Vec<(usize, Vec<&EvalJob>)> = Vec::new();
    for (m, _) in plan.models.iter().enumerate() {
        let jobs: Vec<&EvalJob> = todo.iter().filter(|job| job.0 == m).collect();
        for lane in 0..threads.min(jobs.len()) {
            let share = jobs.iter().skip(lane).step_by(threads).copied().collect();
            lanes.push((m, share));
        }
    }
    // The GIF's trajectory keeps its frames as it is evaluated, so that the GIF does not roll
    // the model out a second time.
    let gif = args.frame_every > 0 && plan.datasets[0].metadata().dim == 2;
    let kept: Vec<Mutex<Option<KeptRollout>>> =
        plan.models.iter().map(|_| Mutex::new(None)).collect();
    lanes
        .par_iter()
        .map(|(m, jobs)| -> Result<()> {
            let device = B::default_device();
            let gns = plan.models[*m].load::<B>(&device)?;
            for job in jobs {
                evaluate_job(plan, args, &gns, job, &device, gif, &kept[*m], &done)?;
                bar.inc(1);
            }
            Ok(())
        })
        .collect::<Result<Vec<()>>>()?;
    bar.finish_and_clear();
    for (m, k, evaluation) in done.into_inner().expect("no thread panicked") {
        results[m][k] = Some(evaluation);
    }
    let evaluations = results
        .into_iter()
        .map(|evals| evals.into_iter().flatten().collect())
        .collect();
    let kept = kept
        .into_iter()
        .map(|k| k.into_inner().expect("no thread panicked"))
        .collect();
    Ok((evaluations, kept))
}

/// One (model, trajectory) evaluation to do: the model, its position among the trajectories,
/// the trajectory, the cache file, and a cached entry that lacks only the stored-unit one-step
/// errors.
type EvalJob = (usize, usize, usize, PathBuf, Option<CacheEntry>);

/// Evaluates one job with the loaded model `gns`, writes its cache entry and pushes the result
/// to `done`; on the GIF's trajectory (`gif`), keeps the rollout's frames in `kept`.
#[allow(clippy::too_many_arguments)]
fn evaluate_job<B: GnsKernels>(
    plan: &Plan,
    args: &EvalArgs,
    gns: &Gns<B>,
    (m, k, index, path, earlier): &EvalJob,
    device: &B::Device,
    gif: bool,
    kept: &Mutex<Option<KeptRollout>>,
    done: &Mutex<Vec<(usize, usize, TrajectoryEvaluation)>>,
) -> Result<()> {
    let model = &plan.models[*m];
    let dataset = &plan.datasets[model.data];
    let (trajectory, _) = dataset.read_with_stats(&args.split, *index)?;
    let context = || {
        format!(
            "evaluating {} on trajectory {index} of '{}'",
            model.label, args.split
        )
    };
    let entry = match earlier {
        Some(earlier) => {
            let mut entry = earlier.clone();
            let errors = one_step_errors(gns, &trajectory, 1, device).with_context(context)?;
            // The same weights and data give the same value up to the order of sums.
            let before = entry.evaluation.mse_acc1;
            if (errors.mse_acc1 - before).abs() > 1e-4 * before.abs().max(1e-30) {
                bail!(
                    "{}: its MSE-acc 1 ({}) is not what the model computes now ({}): \
                             delete the entry to recompute it",
                    path.display(),
                    entry.evaluation.mse_acc1,
                    errors.mse_acc1
                );
            }
            entry.evaluation.acc_error = errors.acc_error;
            entry
        }
        None => CacheEntry {
            format: CACHE_FORMAT.to_string(),
            model: model.dir.display().to_string(),
            digest: model.digest.clone(),
            split: args.split.clone(),
            options: plan.options.clone(),
            evaluation: if gif && *index == args.gif_trajectory {
                let c = gns.spec().config.input_velocities;
                let mut frames = vec![trajectory.frame(c).to_vec()];
                let evaluation = evaluate_trajectory_with(
                    gns,
                    &trajectory,
                    &plan.options,
                    device,
                    |_, positions| frames.push(positions.to_vec()),
                )
                .with_context(context)?;
                *kept
                    .lock()
                    .expect("no thread panics while holding the lock") = Some((c, frames));
                evaluation
            } else {
                evaluate_trajectory(gns, &trajectory, &plan.options, device)
                    .with_context(context)?
            },
        },
    };
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent)
            .with_context(|| format!("creating {}", parent.display()))?;
    }
    write_json(path, &entry)?;
    done.lock()
        .expect("no thread panics while holding the lock")
        .push((*m, *k, entry.evaluation));
    Ok(())
}

/// A model's rollout on the GIF's trajectory: its start frame `C` and the frames from there
/// (the truth at `C`, then each prediction, up to the last finite one).
type KeptRollout = (usize, Vec<Vec<f32>>);

/// Each model's [`KeptRollout`], where its evaluation kept one.
type KeptRollouts = Vec<Option<KeptRollout>>;

/// Writes `rollouts.gif` of trajectory `--gif-trajectory`: the truth, then each model, side by
/// side, every `--frame-every` frames from the start frame `C`. A model's frames are those kept
/// while it was evaluated (`kept`); one whose evaluation came from the cache is rolled out here.
/// A model whose rollout blew up keeps its last finite frame, captioned "(blown up)"; one that
/// reads more history frames than another shows the truth until its own start, captioned
/// "(history)".
fn write_gif<B: GnsKernels>(
    plan: &Plan,
    args: &EvalArgs,
    kept: Vec<Option<KeptRollout>>,
) -> Result<GifRecord> {
    // The trajectory of every dataset: a `--model-data` model rolls out on its own and is drawn
    // with its own particles (the walls of the walls variant).
    let trajectories: Vec<_> = plan
        .datasets
        .iter()
        .map(|d| Ok(d.read_with_stats(&args.split, args.gif_trajectory)?.0))
        .collect::<Result<_>>()?;
    let trajectory = &trajectories[0];
    let device = B::default_device();
    let rollouts: Vec<KeptRollout> =
        plan.models
            .par_iter()
            .zip(kept)
            .map(|(model, kept)| -> Result<KeptRollout> {
                if let Some(kept) = kept {
                    return Ok(kept);
                }
                let own = &trajectories[model.data];
                let gns = model.load::<B>(&device)?;
                let c = model.spec.config.input_velocities;
                let mut frames = vec![own.frame(c).to_vec()];
                let range = RolloutRange::full(c, own.frames);
                let ran = rollout(&gns, own, range, &device, |_, positions| {
                    frames.push(positions.to_vec());
                    Ok(())
                });
                match ran {
                    Ok(()) | Err(ModelError::NonFinitePrediction { .. }) => Ok((c, frames)),
                    Err(e) => Err(e)
                        .with_context(|| format!("rolling {} out for {GIF_FILE}", model.label)),
                }
            })
            .collect::<Result<_>>()?;
    // From the earliest start; a model that reads more frames shows the truth until its own.
    let start = rollouts.iter().map(|(c, _)| *c).min().unwrap_or(0);
    let renderer = DatasetRenderer::new(plan.datasets[0].metadata(), args.pixels_per_cell)?;
    let kinds: Vec<_> = trajectories
        .iter()
        .map(|t| DatasetRenderer::kinds(&t.particle_type))
        .collect();
    let background = FrameStyle::default().background;
    let mut writer: Option<GifWriter> = None;
    let mut shown = Vec::new();
    for frame in (start..trajectory.frames).step_by(args.frame_every) {
        let truth = trajectory.frame(frame);
        let mut pictures = vec![plots::captioned(
            &renderer.render(truth, &kinds[0])?,
            &format!("ground truth, frame {frame}"),
            background,
        )?];
        for ((c, frames), model) in rollouts.iter().zip(&plan.models) {
            let (shown, caption) = match frame.checked_sub(*c) {
                Some(k) if k < frames.len() => (&frames[k][..], model.label.clone()),
                Some(_) => (
                    &frames[frames.len() - 1][..],
                    format!("{} (blown up)", model.label),
                ),
                None => (
                    trajectories[model.data].frame(frame),
                    format!("{} (history)", model.label),
                ),
            };
            pictures.push(plots::captioned(
                &renderer.render(shown, &kinds[model.data])?,
                &caption,
                background,
            )?);
        }
        let refs: Vec<&RgbImage> = pictures.iter().collect();
        let image = side_by_side(&refs, GIF_GAP, background)?;
        if writer.is_none() {
            writer = Some(GifWriter::create(
                args.out.join(GIF_FILE),
                image.width,
                image.height,
                5,
            )?);
        }
        if let Some(writer) = writer.as_mut() {
            writer.add_frame(&image)?;
        }
        shown.push(frame);
    }
    if let Some(writer) = writer {
        writer.finish()?;
    }
    let mut panels = vec!["ground truth".to_string()];
    panels.extend(plan.models.iter().map(|m| m.label.clone()));
    Ok(GifRecord {
        index: args.gif_trajectory,
        panels,
        frames: shown,
    })
}

/// `<split>_<index>.json`.
pub(crate) fn cache_file_name(split: &str, index: usize) -> String {
    format!("{split}_{index}.json")
}

/// A cache entry that fits `model`, `split` and `options`, `None` when there is none, or,
/// with `replace` (`--force`), when it belongs to other weights, a split or options: it is
/// then recomputed and overwritten.
///
/// # Errors
/// An entry that does not read; without `replace`, one that belongs to another model, split,
/// options or trajectory: the message names the entry and both sides.
fn read_cache(
    path: &Path,
    model: &ModelEntry,
    split: &str,
    options: &EvalOptions,
    replace: bool,
) -> Result<Option<CacheEntry>> {
    let bytes = match std::fs::read(path) {
        Ok(bytes) => bytes,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(e).with_context(|| format!("reading {}", path.display())),
    };
    let entry: CacheEntry = serde_json::from_slice(&bytes).with_context(|| {
        format!(
            "{}: not a cached evaluation of `phi eval` (delete it to recompute it)",
            path.display()
        )
    })?;
    if entry.format != CACHE_FORMAT {
        bail!(
            "{}: format '{}', expected '{CACHE_FORMAT}'",
            path.display(),
            entry.format
        );
    }
    let mut older = entry.options.clone();
    older.container.clone_from(&options.container);
    let (stale, hint) = if entry.digest != model.digest {
        let stale = format!(
            "computed for the model {} (weights digest {}), but '{}' is now {} (digest {})",
            entry.model,
            entry.digest,
            model.label,
            model.dir.display(),
            model.digest
        );
        (stale, "another name (--model NAME=DIR)")
    } else if entry.split != split {
        let stale = format!("computed on split '{}', not '{split}'", entry.split);
        (stale, "another --split")
    } else if entry.options.container.is_none() && options.container.is_some() && older == *options
    {
        // Written before the plausibility figures: the same evaluation, recomputed with them.
        tracing::info!(
            "{}: an evaluation without the plausibility figures, recomputed",
            path.display()
        );
        return Ok(None);
    } else if entry.options != *options {
        let stale = format!(
            "computed with other options ({:?}) than this run's ({:?})",
            entry.options, options
        );
        (stale, "the same options")
    } else {
        return Ok(Some(fill_peaks(entry)));
    };
    if replace {
        tracing::info!("{}: recomputed (--force): {stale}", path.display());
        return Ok(None);
    }
    bail!(
        "{}: {stale}: use another --out, {hint}, or --force to recompute it",
        path.display()
    )
}

/// `entry` with its peak shares inside obstacles taken from its curves, which a cache entry
/// written before those figures holds too.
fn fill_peaks(mut entry: CacheEntry) -> CacheEntry {
    let evaluation = &mut entry.evaluation;
    if let Some(p) = &mut evaluation.plausibility {
        (p.peak_inside_obstacles, p.peak_inside_obstacles_true) = evaluation
            .curves
            .peak_inside_obstacles(evaluation.liquid_particles);
    }
    entry
}

/// Writes `value` as pretty JSON, atomically.
fn write_json(path: &Path, value: &impl Serialize) -> Result<()> {
    Ok(phi_io::write_json(path, value)?)
}

/// Writes `text`, atomically.
fn write_text(path: &Path, text: &str) -> Result<()> {
    write_bytes(path, text.as_bytes())
}

fn write_bytes(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic(path, |w| {
        w.write_all(bytes)
            .map_err(|e| OutputError::io(path, "cannot write", e))
    })?;
    Ok(())
}

/// The columns of the tables: the markdown header (with table B.1's units), the scale of the
/// markdown values, the CSV header, and the value.
type Column = (
    &'static str,
    f64,
    &'static str,
    fn(&ModelSummary) -> Option<f64>,
);

const COLUMNS: [Column; 12] = [
    ("EMD (10⁻²)", 1e-2, "emd", |s| s.emd),
    ("MSE-acc 1 (10⁻¹)", 1e-1, "mse_acc1", |s| {
        Some(s.mse_acc1)
    }),
    ("MSE 20 (10⁻⁵)", 1e-5, "mse20", |s| s.mse20),
    ("MSE 400 (10⁻²)", 1e-2, "mse400", |s| s.mse400),
    ("Sinkhorn (10⁻³)", 1e-3, "sinkhorn", |s| s.sinkhorn),
    ("KE error (%)", 1e-2, "kinetic_energy_error", |s| {
        s.kinetic_energy_error
    }),
    ("density ratio", 1.0, "density_ratio", |s| s.density_ratio),
    ("misplaced (%)", 1e-2, "misplaced", |s| {
        s.plausibility.as_ref().map(|p| p.misplaced)
    }),
    (
        "peak in obstacles (%)",
        1e-2,
        "peak_inside_obstacles",
        |s| s.plausibility.as_ref().map(|p| p.peak_inside_obstacles),
    ),
    ("final density", 1.0, "final_density_ratio", |s| {
        s.plausibility.as_ref().map(|p| p.final_density_ratio)
    }),
    ("late KE ratio", 1.0, "late_kinetic_energy_ratio", |s| {
        s.plausibility.as_ref().map(|p| p.late_kinetic_energy_ratio)
    }),
    ("centre (cells)", 1.0, "final_centre_distance_cells", |s| {
        s.plausibility
            .as_ref()
            .map(|p| p.final_centre_distance_cells)
    }),
];

/// Whether the column `name` was switched off (the Sinkhorn divergence with
/// `--sinkhorn-every 0`), so that a missing value means "not measured", not a blown-up rollout.
fn not_measured(record: &EvalRecord, name: &str) -> bool {
    name == "sinkhorn" && record.options.sinkhorn_every == 0
}

/// The markdown table: one row per model, the thesis's four metrics in table B.1's units,
/// then the extra ones; a rollout that blew up makes its metrics `inf`, a metric switched off
/// reads `–` (empty in the CSV).
pub(crate) fn markdown_table(record: &EvalRecord) -> String {
    let mut text = String::from("| model |");
    for (header, ..) in COLUMNS {
        text.push_str(&format!(" {header} |"));
    }
    text.push_str(" blown up | plausible |\n|---|");
    text.push_str(&"---:|".repeat(COLUMNS.len() + 2));
    text.push('\n');
    for model in &record.models {
        let Some(summary) = &model.summary else {
            continue;
        };
        text.push_str(&format!("| {} |", model.label));
        for (_, scale, name, value) in COLUMNS {
            match value(summary) {
                Some(v) => text.push_str(&format!(" {:.4} |", v / scale)),
                None if not_measured(record, name) => text.push_str(" – |"),
                None => text.push_str(" inf |"),
            }
        }
        let plausible = summary
            .plausibility
            .as_ref()
            .map_or("–".to_string(), |p| p.plausible.to_string());
        text.push_str(&format!(
            " {} of {} | {plausible} |\n",
            summary.blown_up, summary.trajectories
        ));
    }
    for model in &record.models {
        if let Some(dataset) = &model.dataset {
            text.push_str(&format!(
                "\n{}: on {dataset} (the same scenes as {}).\n",
                model.label, record.dataset
            ));
        }
    }
    text
}

/// The CSV table: raw values (stored units², normalised units², fractions), `inf` for a blown-up
/// rollout, empty for a metric switched off.
pub(crate) fn csv_table(record: &EvalRecord) -> String {
    let mut text = String::from("model");
    for (_, _, name, _) in COLUMNS {
        text.push(',');
        text.push_str(name);
    }
    text.push_str(",blown_up,trajectories,plausible\n");
    for model in &record.models {
        let Some(summary) = &model.summary else {
            continue;
        };
        text.push_str(&csv_field(&model.label));
        for (_, _, name, value) in COLUMNS {
            match value(summary) {
                Some(v) => text.push_str(&format!(",{v:e}")),
                None if not_measured(record, name) => text.push(','),
                None => text.push_str(",inf"),
            }
        }
        let plausible = summary
            .plausibility
            .as_ref()
            .map_or(String::new(), |p| p.plausible.to_string());
        text.push_str(&format!(
            ",{},{},{plausible}\n",
            summary.blown_up, summary.trajectories
        ));
    }
    text
}

/// A CSV field, quoted where it holds a comma, a quote or a line break.
fn csv_field(value: &str) -> String {
    if value.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", value.replace('"', "\"\""))
    } else {
        value.to_string()
    }
}
