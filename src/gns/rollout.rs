//! `phi rollout`: a GNS rolled out on trajectories of a dataset, its predictions beside the
//! ground truth (thesis fig. 5.8).
//!
//! For each trajectory `I` of the split, the directory `OUT/<split>_<I>/` holds:
//! - `rollout.npz`: `predicted_position` and `true_position` `[steps, N, dim]` float32 (the
//!   predicted and the dataset's positions of frames `start + 1 ..= start + steps`, stored
//!   units), `particle_type [N]` int64, `start [1]` int64, `frame [steps]` int64 (the frame index
//!   of each row). Written atomically, first after `checkpoint_every` steps and then every
//!   `checkpoint_every` steps, and at the end, so that a killed run keeps its frames.
//! - `rollout.json` ([`RolloutRecord`]): what was rolled out, the steps done, whether the
//!   rollout is complete (and why not), the per-frame position MSE over the non-kinematic
//!   particles and its mean, the wall time. Written first (`"complete": false`), at every
//!   checkpoint, and last.
//! - `rollout.gif`: the truth (left) and the prediction (right) of the start frame and of every
//!   `frame_every`-th step, drawn as `phi render` draws a dataset (2D datasets only).
//! - with `--vtk-every N`: `rollout.pvd` and `truth.pvd`, VTK series of the prediction and the
//!   truth (the start frame and every `N`-th step; frames in `vtk/`), for ParaView.
//!
//! A trajectory's folder must be new or empty, or hold an earlier rollout (recognised by its
//! `rollout.json`), which only `--force` replaces; a folder holding anything else is refused even
//! then ([`ROLLOUT_OUTPUTS`]). Other folders in `OUT` are left alone.
//!
//! A prediction with a NaN or infinite position stops the trajectory's rollout: the frames
//! before it are written, `rollout.json` says `"complete": false` with the reason (step, frame
//! and particle) and `failed_step`, the GIF is closed, and the command exits non-zero once the
//! other trajectories are done.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use indicatif::ProgressBar;
use phi_gns::data::{Dataset, METADATA_FILE, Trajectory};
use phi_gns::model::{Gns, GnsKernels, ModelError, Obstacles, Walls, load_model, read_spec};
use phi_gns::rollout::{RolloutRange, TrajectoryRollout, position_mse};
use serde::{Deserialize, Serialize};

use super::{BoundsFrom, ObstaclesArg, WallsArg, bounds_for};
use crate::backends::BackendKind;
use crate::dataset::render::DatasetRenderer;
use crate::output::sink::{Every, FrameSink, FrameView};
use crate::output::target::{
    Marker, OutputSubdir, Outputs, Previous, check_not_a_file, previous_output,
};
use crate::output::vtk::{VtkFrame, VtkSeries};
use crate::output::{ArrayData, FrameStyle, GifWriter, NpyArray, side_by_side, write_npz};

/// The value of [`RolloutRecord::format`].
pub(crate) const ROLLOUT_FORMAT: &str = "phi-rollout";
/// The value of [`RolloutRecord::format_version`].
pub(crate) const ROLLOUT_FORMAT_VERSION: u32 = 1;
/// The record of a rollout directory.
pub(crate) const RECORD_FILE: &str = "rollout.json";
/// The positions of a rollout directory.
pub(crate) const POSITIONS_FILE: &str = "rollout.npz";
/// The animation of a rollout directory.
pub(crate) const GIF_FILE: &str = "rollout.gif";
/// [`RolloutRecord::reason`] while the rollout runs (what a killed run leaves).
pub(crate) const RUNNING: &str = "not finished: the rollout is running or was interrupted";

/// The VTK series of the prediction, of the truth, and their folder.
pub(crate) const VTK_FILES: [&str; 3] = ["rollout.pvd", "truth.pvd", "vtk"];

/// What `phi rollout` writes in each trajectory's folder, recognised by its [`RECORD_FILE`]
/// of [`ROLLOUT_FORMAT`].
pub(crate) const ROLLOUT_OUTPUTS: Outputs = Outputs {
    command: "phi rollout",
    flag: "--out",
    files: &[
        RECORD_FILE,
        POSITIONS_FILE,
        GIF_FILE,
        VTK_FILES[0],
        VTK_FILES[1],
    ],
    subdirs: &[OutputSubdir {
        name: VTK_FILES[2],
        prefix: "",
        suffix: ".vtu",
    }],
    marker: Some(Marker::json(RECORD_FILE, "format", ROLLOUT_FORMAT)),
};

/// Columns of background between the truth and the prediction in the GIF.
const GIF_GAP: u32 = 6;

/// `phi rollout --model DIR --data DATASET --out DIR [options]`.
#[derive(Debug, Clone, clap::Args)]
pub struct RolloutArgs {
    /// The model directory (model.json, model.safetensors).
    #[arg(long)]
    pub model: PathBuf,
    /// The dataset directory.
    #[arg(long)]
    pub data: PathBuf,
    /// The split of the trajectories: train, valid, test, or another its metadata.json lists.
    #[arg(long, default_value = "test", value_name = "SPLIT", value_parser = crate::cli::parse_split)]
    pub split: String,
    /// The trajectory's index in the split [default: 0] (--index before, deprecated).
    #[arg(long, alias = "index", value_name = "I", conflicts_with = "all")]
    pub trajectory: Option<usize>,
    /// Roll out every trajectory of the split.
    #[arg(long)]
    pub all: bool,
    /// The last ground-truth frame of the input window [default: C, the model's input
    /// velocities].
    #[arg(long)]
    pub start: Option<usize>,
    /// Predicted frames [default: up to the trajectory's last frame].
    #[arg(long)]
    pub steps: Option<usize>,
    /// The backend [default: ndarray, as for every command without gradients].
    #[arg(long)]
    pub backend: Option<BackendKind>,
    /// The device the model runs on: `cpu`, or `cuda` / `cuda:N` on the tch backend of a
    /// `--features tch,cuda` build.
    #[arg(long, default_value = "cpu")]
    pub device: String,
    /// The output directory: one folder `<split>_<index>` per trajectory.
    #[arg(long)]
    pub out: PathBuf,
    /// Replace the earlier rollouts of these trajectories in --out (only files `phi rollout`
    /// writes; anything else is refused even then).
    #[arg(long)]
    pub force: bool,
    /// Rewrite rollout.npz and rollout.json every this many steps (0: only at the end).
    #[arg(long, default_value_t = 25)]
    pub checkpoint_every: usize,
    /// A GIF picture every this many steps (0: no GIF). The default, 1, shows every predicted
    /// step, where the prediction starts to leave the truth; `phi render` and `phi eval` draw
    /// every 2nd frame to keep their GIFs small.
    #[arg(long, default_value_t = 1)]
    pub frame_every: usize,
    /// Pixels per grid cell in the GIF.
    #[arg(long, default_value_t = 6)]
    pub pixels_per_cell: u32,
    /// Print the MSE of every step (default: the first, quartile and last steps).
    #[arg(long)]
    pub mse_every_step: bool,
    /// Write the prediction and the truth as VTK frames every this many steps, for ParaView:
    /// `rollout.pvd` and `truth.pvd`, frames in `vtk/` (0: none).
    #[arg(long, default_value_t = 0)]
    pub vtk_every: usize,
    /// For a dataset whose domain is not the model's: the walls its boundary features measure,
    /// the dataset's (`data`) or the training domain's (`model`) [default: refuse such a
    /// dataset].
    #[arg(long, value_enum)]
    pub bounds: Option<BoundsFrom>,
    /// What the rollout does at the domain's walls: `open` (predictions as they are) or `clamp`
    /// (into the domain's box, as FLIP clamps its particles) [default: the model's `walls`,
    /// open when model.json has none].
    #[arg(long, value_enum)]
    pub walls: Option<WallsArg>,
    /// What the rollout does with liquid predicted inside an obstacle: `open` (predictions as
    /// they are) or `push` (out of the obstacle particles' cells, those of the dataset's
    /// `position_scale`, as FLIP pushes its particles out of obstacles) [default: the model's
    /// `obstacles`, open when model.json has none].
    #[arg(long, value_enum)]
    pub obstacles: Option<ObstaclesArg>,
}

/// `rollout.json`: one trajectory's rollout.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct RolloutRecord {
    /// Always [`ROLLOUT_FORMAT`]; marks the directory as written by `phi rollout`.
    pub format: String,
    /// Always [`ROLLOUT_FORMAT_VERSION`].
    pub format_version: u32,
    /// `phi rollout` and its version.
    pub made_by: String,
    /// The model directory, as given.
    pub model: String,
    /// What the rollout did at the domain's walls (absent: open).
    #[serde(default, skip_serializing_if = "Walls::is_open")]
    pub walls: Walls,
    /// What the rollout did with liquid predicted inside obstacles (absent: open).
    #[serde(default, skip_serializing_if = "Obstacles::is_open")]
    pub obstacles: Obstacles,
    /// The dataset directory, as given.
    pub dataset: String,
    /// The split.
    pub split: String,
    /// The trajectory's index in the split.
    pub index: usize,
    /// The trajectory's generator seed.
    pub trajectory_seed: u64,
    /// The backend's name.
    pub backend: String,
    /// Particles of the trajectory.
    pub particles: usize,
    /// Of which kinematic (their positions follow the truth, and the MSE leaves them out).
    pub kinematic_particles: usize,
    /// `C`, the model's input velocities.
    pub input_velocities: usize,
    /// The last ground-truth frame of the input window.
    pub start: usize,
    /// The ground-truth frames the model reads first: `[start − C, start]`.
    pub window: [usize; 2],
    /// The steps asked for.
    pub steps_requested: usize,
    /// The steps done: predicted frames `start + 1 ..= start + steps`.
    pub steps: usize,
    /// Whether every requested step was predicted and written.
    pub complete: bool,
    /// Why not (`null` when complete).
    pub reason: Option<String>,
    /// The step that failed (`null` when none did).
    pub failed_step: Option<usize>,
    /// The position MSE of each predicted frame (stored units², over the non-kinematic
    /// particles and the dimensions).
    pub mse: Vec<f64>,
    /// The mean of `mse` (`null` without frames).
    pub mse_mean: Option<f64>,
    /// The GIF's file name (`null` without one).
    pub gif: Option<String>,
    /// Pictures in the GIF.
    pub gif_pictures: usize,
    /// Seconds from the first step to the last write.
    pub wall_seconds: f64,
    /// Of which in the model (graph, network, integration), not writing files.
    pub model_seconds: f64,
}

/// The folder of trajectory `index` of `split` in the output directory: `<split>_<index>`.
pub(crate) fn rollout_dir_name(split: &str, index: usize) -> String {
    format!("{split}_{index}")
}

/// What was checked before any rollout: the dataset, the trajectories, the
/// range and the output folders.
#[derive(Debug)]
pub(crate) struct Plan {
    dataset: Dataset,
    indices: Vec<usize>,
    range: RolloutRange,
    dirs: Vec<PathBuf>,
    /// The earlier rollouts in `dirs` that --force replaces.
    previous: Vec<Previous>,
    /// The dataset's bounds for the model's boundary features (`--bounds data`).
    bounds: Option<Vec<[f64; 2]>>,
}

/// Checks everything a rollout needs before anything is written: the model's `model.json`, the
/// dataset and that the model fits it ([`ModelSpec::check_dataset`](phi_gns::model::ModelSpec::check_dataset): dimension, bounds,
/// particle types), the split and index, the start and steps, and the output folders
/// ([`ROLLOUT_OUTPUTS`]: new or empty, or an earlier rollout and `--force`).
///
/// # Errors
/// Naming the file, key or option and what is wrong.
pub(crate) fn plan(args: &RolloutArgs) -> Result<Plan> {
    let spec = read_spec(&args.model)?;
    let dataset = Dataset::open(&args.data)?;
    let bounds = bounds_for(
        &spec,
        dataset.metadata(),
        &args.data.join(METADATA_FILE),
        args.bounds,
    )?;
    let count = crate::cli::split_len(&dataset, &args.data, &args.split)?;
    let indices: Vec<usize> = if args.all {
        if count == 0 {
            bail!(
                "{}: split '{}' has no trajectories",
                args.data.display(),
                args.split
            );
        }
        (0..count).collect()
    } else {
        let index = args.trajectory.unwrap_or(0);
        if index >= count {
            bail!(
                "{}: --trajectory {index}: split '{}' has {count} trajectories{}",
                args.data.display(),
                args.split,
                match count {
                    0 => String::new(),
                    1 => " (index 0)".to_string(),
                    n => format!(" (indices 0..={})", n - 1),
                }
            );
        }
        vec![index]
    };
    let frames = dataset.metadata().frames();
    let c = spec.config.input_velocities;
    let start = args.start.unwrap_or(c);
    if start < c {
        bail!(
            "--start {start}: the model reads the {c} frames before the start, so a rollout \
             starts at frame {c} or later"
        );
    }
    if start + 1 >= frames {
        bail!(
            "--start {start}: the trajectories of '{}' have {frames} frames (0..={}), so a \
             rollout starts at frame {} at the latest",
            args.split,
            frames - 1,
            frames.saturating_sub(2)
        );
    }
    let steps = args.steps.unwrap_or(frames - 1 - start);
    if steps == 0 {
        bail!("--steps 0: nothing to predict");
    }
    let range = RolloutRange { start, steps };
    range.check(c, frames).with_context(|| {
        format!(
            "--steps {steps}: the trajectories of '{}' end at frame {}",
            args.split,
            frames - 1
        )
    })?;
    check_not_a_file(&args.out, "--out")?;
    let dirs: Vec<PathBuf> = indices
        .iter()
        .map(|&i| args.out.join(rollout_dir_name(&args.split, i)))
        .collect();
    // Files of others in any folder first: they are refused even with --force.
    let previous = dirs
        .iter()
        .map(|dir| previous_output(dir, &ROLLOUT_OUTPUTS, args.force))
        .collect::<Result<Vec<_>>>()?
        .into_iter()
        .map(|previous| previous.require_force(args.force))
        .collect::<Result<_>>()?;
    Ok(Plan {
        dataset,
        indices,
        range,
        dirs,
        previous,
        bounds,
    })
}

/// Runs `phi rollout` and prints each trajectory's MSE.
///
/// # Errors
/// As [`plan`]; a model that does not load; I/O errors; and, after every trajectory was
/// rolled out, an error naming each one that stopped early and its step.
pub fn run(args: RolloutArgs) -> Result<()> {
    let mut plan = plan(&args)?;
    let previous = std::mem::take(&mut plan.previous);
    let kind = args.backend.unwrap_or_else(BackendKind::default_forward);
    let records = crate::with_backend!(kind, B => roll_all::<B>(&plan, previous, &args))?;
    let failed: Vec<String> = records
        .iter()
        .zip(&plan.dirs)
        .filter(|(r, _)| !r.complete)
        .map(|(r, dir)| {
            format!(
                "{}: {} (the {} frames before it are in {POSITIONS_FILE})",
                dir.display(),
                r.reason.as_deref().unwrap_or("stopped"),
                r.steps
            )
        })
        .collect();
    if !failed.is_empty() {
        bail!(
            "{} of {} rollouts stopped early:\n  {}",
            failed.len(),
            records.len(),
            failed.join("\n  ")
        );
    }
    Ok(())
}

/// Loads the model on backend `B`, removes the `previous` rollouts and rolls the model out on
/// each planned trajectory, printing each one's summary.
fn roll_all<B: GnsKernels>(
    plan: &Plan,
    previous: Vec<Previous>,
    args: &RolloutArgs,
) -> Result<Vec<RolloutRecord>> {
    let Some(device) = B::device_by_name(&args.device) else {
        bail!(
            "--device {}: not available on the {} backend of this build ({})",
            args.device,
            B::name(),
            super::train::devices_hint(B::name())
        );
    };
    let mut model = load_model::<B>(&args.model, &device)?;
    if let Some(bounds) = &plan.bounds {
        model = model.with_bounds(bounds.clone())?;
    }
    if let Some(walls) = args.walls {
        model = model.with_walls(walls.into());
    }
    if let Some(obstacles) = args.obstacles {
        model =
            model.with_obstacles(obstacles.for_cells(plan.dataset.metadata().position_scale))?;
    }
    for previous in previous {
        previous.remove()?;
    }
    let mut records = Vec::with_capacity(plan.indices.len());
    for (&index, dir) in plan.indices.iter().zip(&plan.dirs) {
        let record = roll_one::<B>(&model, plan, args, index, dir, &device)?;
        print!("{}", format_record(&record, dir, args.mse_every_step));
        std::io::stdout().flush().ok();
        records.push(record);
    }
    Ok(records)
}

/// One trajectory's rollout into `dir` (see the module docs). A failed prediction is recorded
/// in the returned record, not returned as an error.
fn roll_one<B: GnsKernels>(
    model: &Gns<B>,
    plan: &Plan,
    args: &RolloutArgs,
    index: usize,
    dir: &Path,
    device: &B::Device,
) -> Result<RolloutRecord> {
    let (trajectory, _) = plan.dataset.read_with_stats(&args.split, index)?;
    let spec = model.spec();
    let (n, dim) = (trajectory.particles, trajectory.dim);
    let range = plan.range;
    let kinematic = spec.kinematic(&trajectory.particle_type);
    let c = spec.config.input_velocities;
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut record = RolloutRecord::start::<B>(args, index, &trajectory, &kinematic, c, range);
    record.walls = spec.config.walls;
    record.obstacles = spec.config.obstacles;
    // The record first: it marks the folder as ours.
    write_record(dir, &record)?;
    let mut sinks = open_sinks(dir, plan, args, &trajectory, &mut record)?;

    let bar = progress_bar(range.steps, &rollout_dir_name(&args.split, index));
    let mut predicted: Vec<f32> = Vec::with_capacity(range.steps * n * dim);
    let started = Instant::now();
    let mut output_seconds = 0.0;
    let written = (|| -> Result<()> {
        for frame in TrajectoryRollout::new(model, &trajectory, range, device)? {
            let frame = match frame {
                Ok(frame) => frame,
                Err(e) => {
                    record.fail(e, range.start);
                    return Ok(());
                }
            };
            let output = Instant::now();
            let (step, positions) = (frame.step, &frame.positions[..]);
            let truth = trajectory.frame(frame.frame);
            let before = match step {
                1 => trajectory.frame(range.start),
                _ => &predicted[(step - 2) * n * dim..(step - 1) * n * dim],
            };
            let view = FrameView {
                frame: frame.frame,
                step,
                positions,
                before,
                truth: Some((truth, trajectory.frame(frame.frame - 1))),
            };
            for sink in &mut sinks {
                sink.add(&view)?;
            }
            predicted.extend_from_slice(positions);
            record
                .mse
                .push(position_mse(positions, truth, &kinematic, dim));
            record.steps = step;
            if args.checkpoint_every > 0 && step % args.checkpoint_every == 0 && step < range.steps
            {
                record.wall_seconds = started.elapsed().as_secs_f64();
                write_positions(dir, &trajectory, range.start, &predicted)?;
                write_record(dir, &record)?;
            }
            bar.inc(1);
            output_seconds += output.elapsed().as_secs_f64();
        }
        record.complete = true;
        record.reason = None;
        Ok(())
    })();
    bar.finish_and_clear();
    // The pictures of the start frame and of every `frame_every`-th step reached.
    if record.gif.is_some() {
        record.gif_pictures = 1 + record.steps / args.frame_every;
    }
    if let Err(e) = written {
        // The first error stands; the outputs are closed as far as they can be.
        for sink in sinks {
            let _ = sink.finish();
        }
        return Err(e);
    }
    record.mse_mean =
        (!record.mse.is_empty()).then(|| record.mse.iter().sum::<f64>() / record.mse.len() as f64);
    write_positions(dir, &trajectory, range.start, &predicted)?;
    for sink in sinks {
        sink.finish()?;
    }
    let elapsed = started.elapsed().as_secs_f64();
    record.model_seconds = (elapsed - output_seconds).max(0.0);
    record.wall_seconds = elapsed;
    write_record(dir, &record)?;
    Ok(record)
}

/// The frame writers `args` asks for in `dir` (VTK frames, the GIF, which `record` then
/// names), each given the start frame.
fn open_sinks(
    dir: &Path,
    plan: &Plan,
    args: &RolloutArgs,
    trajectory: &Trajectory,
    record: &mut RolloutRecord,
) -> Result<Vec<Box<dyn FrameSink>>> {
    let mut sinks: Vec<Box<dyn FrameSink>> = Vec::new();
    if args.vtk_every > 0 {
        let vtk = RolloutVtk::create(dir, plan.dataset.metadata().dt, trajectory)?;
        sinks.push(Box::new(Every::new(args.vtk_every, vtk)));
    }
    if args.frame_every > 0 && trajectory.dim == 2 {
        let renderer = DatasetRenderer::new(plan.dataset.metadata(), args.pixels_per_cell)?;
        let gif = RolloutGif::create(&dir.join(GIF_FILE), renderer, trajectory)?;
        sinks.push(Box::new(Every::new(args.frame_every, gif)));
        record.gif = Some(GIF_FILE.to_string());
    }
    let first = trajectory.frame(plan.range.start);
    let start_view = FrameView {
        frame: plan.range.start,
        step: 0,
        positions: first,
        before: first,
        truth: Some((first, first)),
    };
    for sink in &mut sinks {
        sink.add(&start_view)?;
    }
    Ok(sinks)
}

impl RolloutRecord {
    /// Records that the prediction after the last step reached failed with `e`; `start` is the
    /// frame the rollout started from.
    fn fail(&mut self, e: ModelError, start: usize) {
        let step = self.steps + 1;
        self.failed_step = Some(step);
        self.reason = Some(match e {
            ModelError::NonFinitePrediction { .. } => e.to_string(),
            other => format!("rollout step {step} (frame {}): {other}", start + step),
        });
    }

    /// The record of a rollout that is starting: nothing predicted yet, `"complete": false`.
    fn start<B: GnsKernels>(
        args: &RolloutArgs,
        index: usize,
        trajectory: &Trajectory,
        kinematic: &[bool],
        c: usize,
        range: RolloutRange,
    ) -> Self {
        let n = trajectory.particles;
        RolloutRecord {
            format: ROLLOUT_FORMAT.to_string(),
            format_version: ROLLOUT_FORMAT_VERSION,
            made_by: format!("phi rollout {}", env!("CARGO_PKG_VERSION")),
            model: args.model.display().to_string(),
            walls: Walls::Open,
            obstacles: Obstacles::Open,
            dataset: args.data.display().to_string(),
            split: args.split.clone(),
            index,
            trajectory_seed: trajectory.seed,
            backend: B::name().to_string(),
            particles: n,
            kinematic_particles: kinematic.iter().filter(|k| **k).count(),
            input_velocities: c,
            start: range.start,
            window: [range.start - c, range.start],
            steps_requested: range.steps,
            steps: 0,
            complete: false,
            reason: Some(RUNNING.to_string()),
            failed_step: None,
            mse: Vec::with_capacity(range.steps),
            mse_mean: None,
            gif: None,
            gif_pictures: 0,
            wall_seconds: 0.0,
            model_seconds: 0.0,
        }
    }
}

/// The truth (left) and the prediction (right) of each frame it is given, side by side, as
/// `rollout.gif`.
struct RolloutGif {
    renderer: DatasetRenderer,
    kinds: Vec<u8>,
    writer: Option<GifWriter>,
    path: PathBuf,
}

impl RolloutGif {
    fn create(path: &Path, renderer: DatasetRenderer, trajectory: &Trajectory) -> Result<Self> {
        Ok(RolloutGif {
            renderer,
            kinds: DatasetRenderer::kinds(&trajectory.particle_type),
            writer: None,
            path: path.to_path_buf(),
        })
    }
}

impl FrameSink for RolloutGif {
    fn add(&mut self, frame: &FrameView<'_>) -> Result<()> {
        let truth = frame.truth.map_or(frame.positions, |(truth, _)| truth);
        let left = self.renderer.render(truth, &self.kinds)?;
        let right = self.renderer.render(frame.positions, &self.kinds)?;
        let image = side_by_side(&[&left, &right], GIF_GAP, FrameStyle::default().background)?;
        let writer = match &mut self.writer {
            Some(writer) => writer,
            None => {
                self.writer
                    .insert(GifWriter::create(&self.path, image.width, image.height, 5)?)
            }
        };
        writer.add_frame(&image)?;
        Ok(())
    }

    fn finish(self: Box<Self>) -> Result<()> {
        if let Some(writer) = self.writer {
            writer.finish()?;
        }
        Ok(())
    }
}

/// The VTK series of a rollout: the prediction (`rollout.pvd`) and the truth (`truth.pvd`),
/// frames `vtk/predicted_NNNNN.vtu` and `vtk/truth_NNNNN.vtu` (`NNNNN` the dataset frame),
/// positions in stored units, velocity the backward difference over `dt` (stored units per
/// second), `particle_type` the dataset's (0 obstacle, 1 liquid).
struct RolloutVtk {
    predicted: VtkSeries,
    truth: VtkSeries,
    dt: f64,
    dim: usize,
    types: Vec<i32>,
}

impl RolloutVtk {
    fn create(dir: &Path, dt: f64, trajectory: &Trajectory) -> Result<Self> {
        Ok(RolloutVtk {
            predicted: VtkSeries::create(dir, "rollout", "vtk")?.with_prefix("predicted"),
            truth: VtkSeries::create(dir, "truth", "vtk")?.with_prefix("truth"),
            dt,
            dim: trajectory.dim,
            types: trajectory
                .particle_type
                .iter()
                .map(|&t| i32::try_from(t).unwrap_or(i32::MAX))
                .collect(),
        })
    }

    /// Frame `frame`: the predicted and true positions and those of the frame before.
    fn add_frame(
        &mut self,
        frame: usize,
        predicted: &[f32],
        predicted_before: &[f32],
        truth: &[f32],
        truth_before: &[f32],
    ) -> Result<()> {
        let time = frame as f64 * self.dt;
        let dt = self.dt as f32;
        let velocity = |now: &[f32], before: &[f32]| -> Vec<f32> {
            now.iter().zip(before).map(|(a, b)| (a - b) / dt).collect()
        };
        for (series, now, before) in [
            (&mut self.predicted, predicted, predicted_before),
            (&mut self.truth, truth, truth_before),
        ] {
            series.add(
                frame,
                &VtkFrame {
                    time,
                    dim: self.dim,
                    positions: now,
                    velocities: &velocity(now, before),
                    particle_type: &self.types,
                },
            )?;
        }
        Ok(())
    }
}

impl FrameSink for RolloutVtk {
    fn add(&mut self, frame: &FrameView<'_>) -> Result<()> {
        let (truth, truth_before) = frame.truth.unwrap_or((frame.positions, frame.before));
        self.add_frame(
            frame.frame,
            frame.positions,
            frame.before,
            truth,
            truth_before,
        )
    }

    fn finish(self: Box<Self>) -> Result<()> {
        Ok(())
    }
}

/// A progress bar of `steps` steps on stderr when it is a terminal, else a hidden one.
fn progress_bar(steps: usize, name: &str) -> ProgressBar {
    let bar =
        crate::progress::step_bar(steps, std::io::IsTerminal::is_terminal(&std::io::stderr()));
    bar.set_message(name.to_string());
    bar
}

/// `rollout.npz` of the frames predicted so far (see the module docs).
fn write_positions(
    dir: &Path,
    trajectory: &Trajectory,
    start: usize,
    predicted: &[f32],
) -> Result<()> {
    let (n, dim) = (trajectory.particles, trajectory.dim);
    let per_frame = n * dim;
    let steps = predicted.len() / per_frame;
    let truth = &trajectory.position[(start + 1) * per_frame..(start + 1 + steps) * per_frame];
    let frames: Vec<i64> = (start + 1..=start + steps).map(|f| f as i64).collect();
    let arrays = [
        (
            "predicted_position",
            NpyArray::new(vec![steps, n, dim], ArrayData::F32(predicted.to_vec()))?,
        ),
        (
            "true_position",
            NpyArray::new(vec![steps, n, dim], ArrayData::F32(truth.to_vec()))?,
        ),
        (
            "particle_type",
            NpyArray::from_vec(trajectory.particle_type.clone()),
        ),
        ("start", NpyArray::from_vec(vec![start as i64])),
        ("frame", NpyArray::from_vec(frames)),
    ];
    let refs: Vec<(&str, &NpyArray)> = arrays.iter().map(|(k, a)| (*k, a)).collect();
    write_npz(dir.join(POSITIONS_FILE), &refs)?;
    Ok(())
}

/// `rollout.json`, atomically.
fn write_record(dir: &Path, record: &RolloutRecord) -> Result<()> {
    Ok(phi_io::write_json(&dir.join(RECORD_FILE), record)?)
}

/// The steps whose MSE the summary prints: every step with `every_step` or at most 6 steps, else
/// the first, the quartiles and the last.
pub(crate) fn printed_steps(steps: usize, every_step: bool) -> Vec<usize> {
    if every_step || steps <= 6 {
        return (1..=steps).collect();
    }
    let mut shown = vec![1, steps / 4, steps / 2, 3 * steps / 4, steps];
    shown.dedup();
    shown
}

/// The summary `phi rollout` prints for one trajectory: what ran, the MSE table, what it wrote.
pub(crate) fn format_record(record: &RolloutRecord, dir: &Path, every_step: bool) -> String {
    let mut text = format!(
        "{}: {} of {} steps from frame {} (window {}..={}) on {}, {} particles ({} kinematic), \
         {:.2} s ({:.2} ms/step in the model)\n",
        rollout_dir_name(&record.split, record.index),
        record.steps,
        record.steps_requested,
        record.start,
        record.window[0],
        record.window[1],
        record.backend,
        record.particles,
        record.kinematic_particles,
        record.wall_seconds,
        1e3 * record.model_seconds / record.steps.max(1) as f64,
    );
    if !record.mse.is_empty() {
        text.push_str("   step  frame  position MSE (stored units², non-kinematic particles)\n");
        for step in printed_steps(record.mse.len(), every_step) {
            text.push_str(&format!(
                "  {step:>5}  {:>5}  {:.6e}\n",
                record.start + step,
                record.mse[step - 1]
            ));
        }
        if let Some(mean) = record.mse_mean {
            text.push_str(&format!("   mean         {mean:.6e}\n"));
        }
    }
    if let Some(reason) = &record.reason {
        text.push_str(&format!("  stopped: {reason}\n"));
    }
    let gif = match &record.gif {
        Some(name) => format!(
            ", {name} ({} pictures: truth left, prediction right)",
            record.gif_pictures
        ),
        None => String::new(),
    };
    text.push_str(&format!(
        "wrote {}: {POSITIONS_FILE}, {RECORD_FILE}{gif}\n",
        dir.display()
    ));
    text
}
