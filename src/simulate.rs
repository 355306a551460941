//! `phi simulate`: runs a scene file and writes the trajectory, frames and a GIF.
//!
//! Output directory:
//! - `trajectory.npz`: `positions` and `velocities` `[T+1, N, d]` float32 (frame 0 is the initial
//!   state; with inflows, `N` is the final particle count and rows of particles that do not exist
//!   yet are NaN), `particle_type [N]` int32 (1 = liquid), `particle_count [T+1]` int32, `time
//!   [T+1]` float32, `steps_completed [1]` int64. It is rewritten (atomically) every
//!   `checkpoint_every` steps, so a killed run leaves the steps done so far. An APIC scene adds
//!   `affine` `[T+1, N, d, d]` float32, each particle's affine velocity matrix (`[.., a, j]` =
//!   `∂v_a/∂x_j`, per second; zero in frame 0).
//! - `run.json`: the scene, the backend, and run facts; `"complete": false` until the last step
//!   is written. Rewritten with the trajectory at every checkpoint.
//! - `frames/frame_NNNNN.png` and `simulation.gif` (written frame by frame).
//! - with `vtk_every > 0`: `vtk/frame_NNNNN.vtu` every `vtk_every` steps and `simulation.pvd`,
//!   the series with its times, for ParaView (positions in cells, velocity in cells per second,
//!   `particle_type` 1 = liquid).
//!
//! # When a run fails
//! A step that fails (an unstable run: a CFL number above `simulation.max_cfl`, a non-finite
//! state, a failed pressure solve) or an output error ends the run with an error, after the
//! trajectory of the steps done so far is written, the GIF is closed and `run.json` records the
//! steps and frames that exist, `"complete": false` and the reason (`"failure"`).
//!
//! # The output directory
//! It must be missing or empty. `--force` replaces a previous run (a directory holding only what
//! `phi simulate` writes: its files are removed first, so old and new frames never mix); a
//! directory with anything else in it, a dataset above all, is refused even then.
//!
//! # Memory
//! Before anything is allocated, the scene's needs are estimated ([`phi_flip::memory`], plus the
//! recorded frames) and a run that needs more than the limit (`--memory-limit`, else
//! `PHI_MEMORY_LIMIT`, else the machine's memory) is refused, naming the key.

use std::cell::Cell;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use phi_core::fields::LatticeKernels;
use phi_flip::{
    FlipSimulation, RecordedFrame, Recording, RunTotals, Scene, SceneRun, TrajectoryArrays,
};
use phi_io::output_dir::{OutputDir, OutputSubdir, Outputs};
use serde::Serialize;

use crate::output::sink::{Every, FrameSink, FrameView};
use crate::output::vtk::{VtkFrame, VtkSeries};
use crate::output::{
    ArrayData, FrameStyle, GifWriter, KIND_LIQUID, NpyArray, render_frame, write_npz, write_png,
};

/// How to run and what to write.
#[derive(Debug, Clone)]
pub struct SimulateOptions {
    /// The scene file.
    pub scene: PathBuf,
    /// The output directory (created if missing).
    pub out: PathBuf,
    /// Render a frame every this many steps (0: no frames, no GIF).
    pub frame_every: usize,
    /// Rewrite the trajectory file every this many steps.
    pub checkpoint_every: usize,
    /// Pixels per cell of the frames.
    pub pixels_per_cell: u32,
    /// Override of the scene's step count.
    pub steps: Option<usize>,
    /// Write a VTK frame every this many steps (0: none): `vtk/frame_NNNNN.vtu` and
    /// `simulation.pvd` ([`crate::output::vtk`]).
    pub vtk_every: usize,
    /// Show a progress bar.
    pub progress: bool,
    /// Replace a previous run in `out`.
    pub force: bool,
    /// The most memory the run may need, bytes (`None`: the machine's memory).
    pub memory_limit: Option<u64>,
}

/// What a run did.
#[derive(Debug, Clone, Serialize)]
pub struct RunSummary {
    /// The backend's name.
    pub backend: String,
    /// Steps run.
    pub steps: usize,
    /// Particles at the end.
    pub particles: usize,
    /// Wall time of the steps alone (no output), seconds.
    pub simulation_seconds: f64,
    /// Steps per second of the steps alone.
    pub steps_per_second: f64,
    /// Mean and largest iterations of the pressure solves (0 for direct solves).
    pub solver_iterations_mean: f64,
    /// Largest iteration count.
    pub solver_iterations_max: usize,
    /// The largest absolute residual `‖b − A x‖₂` of the pressure solves.
    pub solver_residual_max: f64,
    /// The largest per-step particle displacement, in cells.
    pub max_displacement_cells: f32,
    /// Frames rendered.
    pub frames: usize,
    /// Frames in `trajectory.npz` (the initial state and one per step done).
    pub trajectory_frames: usize,
    /// The largest CFL number of the run's (sub-)steps.
    pub cfl_max: f32,
    /// Sub-steps over all steps (equal to `steps` without `simulation.cfl`).
    pub substeps: usize,
    /// Whether every step completed.
    pub complete: bool,
    /// Why the run stopped early (only when it did).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub failure: Option<String>,
}

#[derive(Serialize)]
struct RunFile<'a> {
    scene_file: String,
    scene: &'a Scene,
    dimension: usize,
    dt: f32,
    phi_version: &'static str,
    #[serde(flatten)]
    summary: &'a RunSummary,
}

/// Bytes `phi simulate` holds per particle and recorded frame: positions and velocities (and
/// APIC's matrices) in the history, again in the arrays of `trajectory.npz` and in its encoding.
fn recorded_bytes_per_particle(d: usize, apic: bool) -> f64 {
    let floats = 2 * d + if apic { d * d } else { 0 };
    3.0 * 4.0 * floats as f64
}

/// Runs `scene` on backend `B` and writes everything to `options.out`.
///
/// # Errors
/// Scene errors (a scene that needs more memory than the limit among them), an output directory
/// that is not empty (see the module docs), a failing step (an unstable or non-finite state,
/// a solver failure) and I/O errors, with the path. After a failing step, what the run made is
/// written (see the module docs).
pub fn simulate<B: LatticeKernels>(scene: &Scene, options: &SimulateOptions) -> Result<RunSummary> {
    let origin = options.scene.display().to_string();
    let steps = options.steps.unwrap_or(scene.simulation.steps);
    check_memory(scene, &origin, steps, options.memory_limit)?;
    let dir = prepare_out_dir(&options.out, options.force)?;
    let run = SceneRun::<B>::new(scene, &origin, &B::default_device())?;
    let frames = Cell::new(0);
    let sinks = frame_sinks(&run, options, dir.path(), &frames)?;
    let mut trajectory = TrajectorySink {
        out: dir.path().to_path_buf(),
        history: run.recording(),
        checkpoint_every: options.checkpoint_every,
        steps,
        written: 0,
    };
    trajectory.history.reserve(steps.saturating_add(1));
    let record = RunRecord {
        dim: run.simulation().domain().dim(),
        dt: run.simulation().params().dt,
        dir,
        origin,
        scene,
        backend: B::name(),
    };
    let mut state = RunState {
        run,
        steps,
        totals: RunTotals::default(),
        record,
        trajectory,
        sinks,
        frames: &frames,
    };
    state.record.write(&state.summary(false))?;
    let bar = crate::progress::step_bar(steps, options.progress);
    let outcome = state.step_all(&bar);
    bar.finish_and_clear();
    state.finish(outcome)
}

/// Refuses a scene whose run would need more memory than `limit` (`None`: the limit of
/// [`crate::memory::memory_limit`]), naming the key.
fn check_memory(scene: &Scene, origin: &str, steps: usize, limit: Option<u64>) -> Result<()> {
    let limit = match limit {
        Some(limit) => limit as f64,
        None => match crate::memory::memory_limit()? {
            u64::MAX => f64::INFINITY,
            limit => limit as f64,
        },
    };
    let apic = scene.simulation.scheme == phi_flip::Scheme::Apic;
    scene.check_memory(
        origin,
        steps,
        steps.saturating_add(1),
        recorded_bytes_per_particle(scene.dim(), apic),
        limit,
    )?;
    Ok(())
}

/// A run of `phi simulate` under way: the simulation, its totals, and where its frames go.
struct RunState<'a, B: LatticeKernels> {
    run: SceneRun<B>,
    steps: usize,
    totals: RunTotals,
    record: RunRecord<'a>,
    trajectory: TrajectorySink,
    sinks: Vec<Box<dyn FrameSink + 'a>>,
    /// Pictures rendered so far.
    frames: &'a Cell<usize>,
}

impl<B: LatticeKernels> RunState<'_, B> {
    /// The summary so far; `rates`: with the mean solver iterations and the steps per second
    /// (at the end of a run).
    fn summary(&self, rates: bool) -> RunSummary {
        let t = &self.totals;
        RunSummary {
            backend: self.record.backend.to_string(),
            steps: t.steps,
            particles: self.run.particles().len(),
            simulation_seconds: t.seconds,
            steps_per_second: if rates { t.steps_per_second() } else { 0.0 },
            solver_iterations_mean: if rates {
                t.solver_iterations_mean()
            } else {
                0.0
            },
            solver_iterations_max: t.solver_iterations_max,
            solver_residual_max: t.solver_residual_max,
            max_displacement_cells: t.max_displacement_cells,
            frames: self.frames.get(),
            trajectory_frames: self.trajectory.written,
            cfl_max: t.cfl_max,
            substeps: t.substeps,
            complete: false,
            failure: None,
        }
    }

    /// Hands the start frame and the state after every step to the sinks.
    fn step_all(&mut self, bar: &indicatif::ProgressBar) -> Result<()> {
        self.deliver(0)?;
        for step in 1..=self.steps {
            self.run
                .step_counted(&mut self.totals)
                .with_context(|| format!("{}: the simulation failed", self.record.origin))?;
            self.deliver(step)?;
            bar.set_message(format!("{} particles", self.run.particles().len()));
            bar.inc(1);
        }
        Ok(())
    }

    /// The current state, after `step` steps, to every sink; `run.json` follows a checkpoint
    /// of the trajectory.
    fn deliver(&mut self, step: usize) -> Result<()> {
        let state = self.run.frame();
        let before = self
            .trajectory
            .history
            .frames()
            .last()
            .map_or_else(|| state.positions.clone(), |f| f.positions.clone());
        let view = FrameView {
            frame: step,
            step,
            positions: &state.positions,
            before: &before,
            truth: None,
        };
        for sink in &mut self.sinks {
            sink.add_state(&view, &state)?;
        }
        let written = self.trajectory.written;
        self.trajectory.add_state(&view, &state)?;
        if self.trajectory.written != written {
            self.record.write(&self.summary(false))?;
        }
        Ok(())
    }

    /// Closes the outputs and writes `run.json` whether or not the run succeeded; on success
    /// their errors count, after a failure they are logged and the failure is returned.
    fn finish(self, outcome: Result<()>) -> Result<RunSummary> {
        let mut summary = self.summary(true);
        let recorded = self.trajectory.history.len();
        let trajectory = Box::new(self.trajectory).finish();
        if trajectory.is_ok() {
            summary.trajectory_frames = recorded;
        }
        let mut closed = Ok(());
        for sink in self.sinks {
            let result = sink.finish();
            if closed.is_ok() {
                closed = result;
            }
        }
        let record = self.record;
        match outcome {
            Ok(()) => {
                trajectory?;
                closed?;
                summary.complete = true;
                record.write(&summary)?;
                Ok(summary)
            }
            Err(error) => {
                summary.failure = Some(format!("{error:#}"));
                let kept = [trajectory.err(), closed.err(), record.write(&summary).err()];
                for e in kept.into_iter().flatten() {
                    tracing::warn!("while keeping what the failed run made: {e:#}");
                }
                Err(error.context(format!(
                    "the run stopped after {} of {} steps; {} holds its {} frames \
                     (run.json: \"complete\": false)",
                    summary.steps,
                    self.steps,
                    record.dir.path().display(),
                    summary.trajectory_frames
                )))
            }
        }
    }
}

/// What `phi simulate` writes in its output directory: the run's files, its PNG frames and its
/// VTK series.
pub(crate) const RUN_OUTPUTS: Outputs = Outputs {
    command: "phi simulate",
    flag: "--out",
    files: &[
        "run.json",
        "trajectory.npz",
        "simulation.gif",
        "simulation.pvd",
    ],
    subdirs: &[
        OutputSubdir {
            name: "frames",
            prefix: "frame_",
            suffix: ".png",
        },
        OutputSubdir {
            name: "vtk",
            prefix: "frame_",
            suffix: ".vtu",
        },
    ],
    marker: None,
};

/// Claims `out` for a run ([`OutputDir::claim`]): missing or empty, or, with `force`, a
/// previous run, whose files are removed; then creates it.
///
/// # Errors
/// A file where the directory should be; a non-empty directory without `force`; with `force`,
/// one that holds anything `phi simulate` does not write (a dataset, other files).
pub(crate) fn prepare_out_dir(out: &Path, force: bool) -> Result<OutputDir> {
    let mut dir = OutputDir::claim(out, &RUN_OUTPUTS, force)?;
    dir.clear_previous()?;
    dir.create()?;
    Ok(dir)
}

/// `run.json`: the scene, the backend and the run's summary, rewritten at every checkpoint.
struct RunRecord<'a> {
    dir: OutputDir,
    origin: String,
    scene: &'a Scene,
    backend: &'static str,
    dt: f32,
    dim: usize,
}

impl RunRecord<'_> {
    fn write(&self, summary: &RunSummary) -> Result<()> {
        let file = RunFile {
            scene_file: self.origin.clone(),
            scene: self.scene,
            dimension: self.dim,
            dt: self.dt,
            phi_version: env!("CARGO_PKG_VERSION"),
            summary,
        };
        let text = serde_json::to_string_pretty(&file)?;
        self.dir.write_bytes("run.json", text.as_bytes())?;
        Ok(())
    }
}

/// The sinks of `options` besides the trajectory: the VTK series (every `vtk_every` steps)
/// and the pictures with the GIF (every `frame_every` steps), counting pictures in `frames`.
fn frame_sinks<'a, B: LatticeKernels>(
    run: &SceneRun<B>,
    options: &SimulateOptions,
    out: &Path,
    frames: &'a Cell<usize>,
) -> Result<Vec<Box<dyn FrameSink + 'a>>> {
    let simulation = run.simulation();
    let dt = simulation.params().dt;
    let mut sinks: Vec<Box<dyn FrameSink + 'a>> = Vec::new();
    if options.vtk_every > 0 {
        let series = VtkSeries::create(out, "simulation", "vtk")?;
        let vtk = VtkSink {
            series,
            dt,
            dim: simulation.domain().dim(),
        };
        sinks.push(Box::new(Every::new(options.vtk_every, vtk)));
    }
    if options.frame_every > 0 {
        let frames_dir = out.join("frames");
        std::fs::create_dir_all(&frames_dir)
            .with_context(|| format!("creating {}", frames_dir.display()))?;
        let pictures = Pictures {
            solid: simulation.solid_cells(0.0)?,
            simulation: simulation.clone(),
            style: FrameStyle {
                pixels_per_cell: options.pixels_per_cell,
                ..FrameStyle::default()
            },
            frames_dir,
            gif_path: out.join("simulation.gif"),
            gif: None,
            count: frames,
        };
        sinks.push(Box::new(Every::new(options.frame_every, pictures)));
    }
    Ok(sinks)
}

/// `frames/frame_NNNNN.png` and `simulation.gif`: the liquid over the solid cells at the
/// frame's time, seen from the side in 3D.
struct Pictures<'a, B: LatticeKernels> {
    simulation: FlipSimulation<B>,
    /// The solid cells at time 0 (all times, when no obstacle moves).
    solid: Vec<bool>,
    style: FrameStyle,
    frames_dir: PathBuf,
    gif_path: PathBuf,
    gif: Option<GifWriter>,
    count: &'a Cell<usize>,
}

impl<B: LatticeKernels> FrameSink for Pictures<'_, B> {
    fn add(&mut self, frame: &FrameView<'_>) -> Result<()> {
        let sim = &self.simulation;
        let d = sim.domain().dim();
        let time = frame.step as f32 * sim.params().dt;
        let solid_now = if sim.obstacles().iter().any(|o| o.is_moving()) {
            sim.solid_cells(time)?
        } else {
            self.solid.clone()
        };
        let kinds = vec![KIND_LIQUID; frame.positions.len() / d];
        let view = side_view(frame.positions, d, sim.domain(), &solid_now);
        let image = render_frame(
            &view.positions,
            d,
            &kinds,
            &view.lower,
            &view.upper,
            &view.resolution,
            Some(&view.solid),
            &self.style,
        )?;
        let path = self.frames_dir.join(format!("frame_{:05}.png", frame.step));
        write_png(&path, &image)?;
        let gif = match &mut self.gif {
            Some(gif) => gif,
            None => self.gif.insert(GifWriter::create(
                &self.gif_path,
                image.width,
                image.height,
                5,
            )?),
        };
        gif.add_frame(&image)?;
        self.count.set(self.count.get() + 1);
        Ok(())
    }

    fn finish(self: Box<Self>) -> Result<()> {
        if let Some(gif) = self.gif {
            gif.finish()?;
        }
        Ok(())
    }
}

/// `vtk/frame_NNNNN.vtu` and `simulation.pvd`: positions and velocities (all particles
/// liquid); from positions alone the velocity is the backward difference over the frames.
struct VtkSink {
    series: VtkSeries,
    dt: f32,
    dim: usize,
}

impl FrameSink for VtkSink {
    fn add(&mut self, frame: &FrameView<'_>) -> Result<()> {
        self.add_state(frame, &state_from_positions(frame, self.dt))
    }

    fn add_state(&mut self, frame: &FrameView<'_>, state: &RecordedFrame) -> Result<()> {
        let types = vec![i32::from(KIND_LIQUID); state.positions.len() / self.dim];
        self.series.add(
            frame.step,
            &VtkFrame {
                time: f64::from(frame.step as f32 * self.dt),
                dim: self.dim,
                positions: &state.positions,
                velocities: &state.velocities,
                particle_type: &types,
            },
        )?;
        Ok(())
    }

    fn finish(self: Box<Self>) -> Result<()> {
        Ok(())
    }
}

/// A state from positions alone: the velocity is the backward difference over one step `dt`
/// (zero for the start frame, whose `before` is itself), no APIC matrices.
fn state_from_positions(frame: &FrameView<'_>, dt: f32) -> RecordedFrame {
    RecordedFrame {
        positions: frame.positions.to_vec(),
        velocities: frame
            .positions
            .iter()
            .zip(frame.before)
            .map(|(now, before)| (now - before) / dt)
            .collect(),
        affine: None,
    }
}

/// `trajectory.npz`: every state, rewritten every `checkpoint_every` steps and at the end.
struct TrajectorySink {
    out: PathBuf,
    history: Recording,
    checkpoint_every: usize,
    steps: usize,
    /// Frames in the file on disk.
    written: usize,
}

impl FrameSink for TrajectorySink {
    fn add(&mut self, frame: &FrameView<'_>) -> Result<()> {
        let state = state_from_positions(frame, self.history.dt());
        self.add_state(frame, &state)
    }

    fn add_state(&mut self, frame: &FrameView<'_>, state: &RecordedFrame) -> Result<()> {
        self.history.push_frame(state.clone());
        let step = frame.step;
        if self.checkpoint_every > 0
            && step > 0
            && step.is_multiple_of(self.checkpoint_every)
            && step < self.steps
        {
            write_trajectory(&self.out, &self.history)?;
            self.written = self.history.len();
        }
        Ok(())
    }

    fn finish(self: Box<Self>) -> Result<()> {
        write_trajectory(&self.out, &self.history)
    }
}

/// The trajectory so far as `trajectory.npz` (see the module docs).
fn write_trajectory(out: &Path, history: &Recording) -> Result<()> {
    let TrajectoryArrays {
        frames,
        particles: n,
        dim: d,
        positions,
        velocities,
        affine,
        particle_count,
        time,
    } = history.arrays();
    let counts: Vec<i32> = particle_count.iter().map(|&c| c as i32).collect();
    let mut arrays = vec![
        (
            "positions",
            NpyArray::new(vec![frames, n, d], ArrayData::F32(positions))?,
        ),
        (
            "velocities",
            NpyArray::new(vec![frames, n, d], ArrayData::F32(velocities))?,
        ),
        (
            "particle_type",
            NpyArray::new(vec![n], ArrayData::I32(vec![i32::from(KIND_LIQUID); n]))?,
        ),
        (
            "particle_count",
            NpyArray::new(vec![frames], ArrayData::I32(counts))?,
        ),
        ("time", NpyArray::new(vec![frames], ArrayData::F32(time))?),
        (
            "steps_completed",
            NpyArray::new(vec![1], ArrayData::I64(vec![frames as i64 - 1]))?,
        ),
    ];
    if let Some(affine) = affine {
        arrays.push((
            "affine",
            NpyArray::new(vec![frames, n, d, d], ArrayData::F32(affine))?,
        ));
    }
    let refs: Vec<(&str, &NpyArray)> = arrays.iter().map(|(k, a)| (*k, a)).collect();
    write_npz(out.join("trajectory.npz"), &refs)?;
    Ok(())
}

/// Particles and grid as the renderer sees them: positions, lower and upper bounds, resolution
/// and solid cells.
struct View {
    positions: Vec<f32>,
    lower: Vec<f32>,
    upper: Vec<f32>,
    resolution: Vec<usize>,
    solid: Vec<bool>,
}

/// What the frames show: 2D as it is; 3D seen from the side (horizontal axis x, vertical axis
/// z, the last axis, along which gravity pulls by default), depth y. Returns positions, bounds,
/// resolution and solid cells in the order the renderer takes (its axes 0 and 1 on screen).
fn side_view(
    positions: &[f32],
    d: usize,
    domain: &phi_core::fields::Domain,
    solid: &[bool],
) -> View {
    let (lower, upper, res) = (domain.lower(), domain.upper(), domain.resolution());
    if d != 3 {
        return View {
            positions: positions.to_vec(),
            lower: lower.to_vec(),
            upper: upper.to_vec(),
            resolution: res.to_vec(),
            solid: solid.to_vec(),
        };
    }
    let order = [0usize, 2, 1];
    let view = positions
        .chunks(3)
        .flat_map(|p| order.map(|a| p[a]))
        .collect();
    let permute_f = |v: &[f32]| order.iter().map(|&a| v[a]).collect::<Vec<f32>>();
    let new_res: Vec<usize> = order.iter().map(|&a| res[a]).collect();
    let mut mask = vec![false; solid.len()];
    for i in 0..res[0] {
        for j in 0..res[1] {
            for k in 0..res[2] {
                mask[(i * res[2] + k) * res[1] + j] = solid[(i * res[1] + j) * res[2] + k];
            }
        }
    }
    View {
        positions: view,
        lower: permute_f(lower),
        upper: permute_f(upper),
        resolution: new_res,
        solid: mask,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::output::read_npz;
    use crate::output::test_util::temp_dir;

    #[test]
    fn positions_alone_give_backward_difference_velocities_in_the_trajectory() {
        let dir = temp_dir("simulate-trajectory-sink");
        let mut sink = TrajectorySink {
            out: dir.clone(),
            history: Recording::new(1, 0.5, false),
            checkpoint_every: 2,
            steps: 3,
            written: 0,
        };
        let frames = [[1.0f32, 2.0], [1.5, 2.0], [2.5, 1.0], [2.5, 0.0]];
        for (step, positions) in frames.iter().enumerate() {
            let before = &frames[step.saturating_sub(1)];
            let view = FrameView {
                frame: step,
                step,
                positions,
                before,
                truth: None,
            };
            sink.add(&view).unwrap();
            // A checkpoint after step 2 (of 3): the three frames so far on disk.
            assert_eq!(sink.written, if step >= 2 { 3 } else { 0 }, "step {step}");
        }
        Box::new(sink).finish().unwrap();
        let arrays = read_npz(dir.join("trajectory.npz")).unwrap();
        let (_, velocities) = arrays
            .iter()
            .find(|(name, _)| name == "velocities")
            .unwrap();
        let expected = [0.0f32, 0.0, 1.0, 0.0, 2.0, -2.0, 0.0, -2.0];
        assert_eq!(velocities.shape, vec![4, 2, 1]);
        assert_eq!(velocities.data, ArrayData::F32(expected.to_vec()));
        let _ = std::fs::remove_dir_all(dir);
    }
}
