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

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};

use phi_core::fields::LatticeKernels;
use phi_flip::{Particles, RecordedFrame, Recording, Scene, TrajectoryArrays};
use serde::Serialize;

use crate::output::target::{OutputSubdir, Outputs, check_dir};
use crate::output::vtk::{VtkFrame, VtkSeries};
use crate::output::{
    ArrayData, FrameStyle, GifWriter, KIND_LIQUID, NpyArray, OutputError, render_frame,
    write_atomic, write_npz, write_png,
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
    let limit = match options.memory_limit {
        Some(limit) => limit as f64,
        None => match crate::memory::memory_limit()? {
            u64::MAX => f64::INFINITY,
            limit => limit as f64,
        },
    };
    let apic = scene.simulation.scheme == phi_flip::Scheme::Apic;
    scene.check_memory(
        &origin,
        steps,
        steps.saturating_add(1),
        recorded_bytes_per_particle(scene.dim(), apic),
        limit,
    )?;
    let out = &options.out;
    prepare_out_dir(out, options.force)?;
    let device = B::default_device();
    let setup = scene.build::<B>(&origin, &device)?;
    let sim = setup.simulation;
    let d = sim.domain().dim();
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let frames_dir = out.join("frames");
    if options.frame_every > 0 {
        std::fs::create_dir_all(&frames_dir)
            .with_context(|| format!("creating {}", frames_dir.display()))?;
    }

    let mut summary = RunSummary {
        backend: B::name().to_string(),
        steps: 0,
        particles: setup.particles.len(),
        simulation_seconds: 0.0,
        steps_per_second: 0.0,
        solver_iterations_mean: 0.0,
        solver_iterations_max: 0,
        solver_residual_max: 0.0,
        max_displacement_cells: 0.0,
        frames: 0,
        trajectory_frames: 0,
        cfl_max: 0.0,
        substeps: 0,
        complete: false,
        failure: None,
    };
    let dt = sim.params().dt;
    write_run_file(out, &origin, scene, dt, d, &summary)?;

    let solid = sim.solid_cells(0.0)?;
    let style = FrameStyle {
        pixels_per_cell: options.pixels_per_cell,
        ..FrameStyle::default()
    };
    let mut gif: Option<GifWriter> = None;
    let mut history = Recording::new(d, dt, apic);
    history.reserve(steps.saturating_add(1));
    let mut particles: Particles<B> = setup.particles;
    history.push(&particles);
    let mut vtk = (options.vtk_every > 0)
        .then(|| VtkSeries::create(out, "simulation", "vtk"))
        .transpose()?;
    if let Some(series) = vtk.as_mut() {
        write_vtk_frame(series, 0, &history.frames()[0], dt, d)?;
    }

    let bar = crate::progress::step_bar(steps, options.progress);

    let mut iterations_total = 0usize;
    let render = |step: usize,
                  host: &[f32],
                  gif: &mut Option<GifWriter>,
                  frames: &mut usize|
     -> Result<()> {
        let time = step as f32 * dt;
        let solid_now = if sim.obstacles().iter().any(|o| o.is_moving()) {
            sim.solid_cells(time)?
        } else {
            solid.clone()
        };
        let kinds = vec![KIND_LIQUID; host.len() / d];
        let view = side_view(host, d, sim.domain(), &solid_now);
        let image = render_frame(
            &view.positions,
            d,
            &kinds,
            &view.lower,
            &view.upper,
            &view.resolution,
            Some(&view.solid),
            &style,
        )?;
        let path = frames_dir.join(format!("frame_{step:05}.png"));
        write_png(&path, &image)?;
        if gif.is_none() {
            *gif = Some(GifWriter::create(
                out.join("simulation.gif"),
                image.width,
                image.height,
                5,
            )?);
        }
        if let Some(g) = gif.as_mut() {
            g.add_frame(&image)?;
        }
        *frames += 1;
        Ok(())
    };

    let mut run = || -> Result<()> {
        if options.frame_every > 0 {
            render(
                0,
                &history.frames()[0].positions,
                &mut gif,
                &mut summary.frames,
            )?;
        }
        for step in 0..steps {
            let started = Instant::now();
            let (next, stats) = sim
                .step(&particles, step)
                .with_context(|| format!("{origin}: the simulation failed"))?;
            summary.simulation_seconds += started.elapsed().as_secs_f64();
            particles = next;
            iterations_total += stats.solve.iterations;
            summary.solver_iterations_max =
                summary.solver_iterations_max.max(stats.solve.iterations);
            summary.solver_residual_max = summary.solver_residual_max.max(stats.solve.residual);
            summary.max_displacement_cells = summary
                .max_displacement_cells
                .max(stats.max_displacement_cells);
            summary.cfl_max = summary.cfl_max.max(stats.cfl);
            summary.substeps += stats.substeps;
            summary.steps = step + 1;
            summary.particles = particles.len();
            history.push(&particles);
            if let Some(series) = vtk.as_mut()
                && (step + 1) % options.vtk_every == 0
            {
                write_vtk_frame(series, step + 1, &history.frames()[step + 1], dt, d)?;
            }
            if options.frame_every > 0 && (step + 1) % options.frame_every == 0 {
                render(
                    step + 1,
                    &history.frames()[step + 1].positions,
                    &mut gif,
                    &mut summary.frames,
                )?;
            }
            if options.checkpoint_every > 0
                && (step + 1) % options.checkpoint_every == 0
                && step + 1 < steps
            {
                write_trajectory(out, &history)?;
                summary.trajectory_frames = history.len();
                write_run_file(out, &origin, scene, dt, d, &summary)?;
            }
            bar.set_message(format!("{} particles", particles.len()));
            bar.inc(1);
        }
        Ok(())
    };
    let outcome = run();
    bar.finish_and_clear();

    summary.solver_iterations_mean = iterations_total as f64 / summary.steps.max(1) as f64;
    summary.steps_per_second = summary.steps as f64 / summary.simulation_seconds.max(1e-12);
    // What exists is written whether or not the run succeeded; on success its errors count.
    let trajectory = write_trajectory(out, &history);
    if trajectory.is_ok() {
        summary.trajectory_frames = history.len();
    }
    let closed = gif.map_or(Ok(()), |g| g.finish().map_err(anyhow::Error::from));
    match outcome {
        Ok(()) => {
            trajectory?;
            closed?;
            summary.complete = true;
            write_run_file(out, &origin, scene, dt, d, &summary)?;
            Ok(summary)
        }
        Err(error) => {
            summary.failure = Some(format!("{error:#}"));
            let kept = [
                trajectory.err(),
                closed.err(),
                write_run_file(out, &origin, scene, dt, d, &summary).err(),
            ];
            for e in kept.into_iter().flatten() {
                tracing::warn!("while keeping what the failed run made: {e:#}");
            }
            Err(error.context(format!(
                "the run stopped after {} of {steps} steps; {} holds its {} frames \
                 (run.json: \"complete\": false)",
                summary.steps,
                out.display(),
                summary.trajectory_frames
            )))
        }
    }
}

/// What `phi simulate` writes in its output directory: the run's files, its PNG frames and its
/// VTK series.
pub const RUN_OUTPUTS: Outputs = Outputs {
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

/// Makes sure `out` can take a run: missing or empty, or, with `force`, a previous run, whose
/// files are removed ([`crate::output::target::check_dir`]).
///
/// # Errors
/// A file where the directory should be; a non-empty directory without `force`; with `force`,
/// one that holds anything `phi simulate` does not write (a dataset, other files).
pub fn prepare_out_dir(out: &Path, force: bool) -> Result<()> {
    check_dir(out, &RUN_OUTPUTS, force)?.remove()
}

fn write_run_file(
    out: &Path,
    origin: &str,
    scene: &Scene,
    dt: f32,
    d: usize,
    summary: &RunSummary,
) -> Result<()> {
    let file = RunFile {
        scene_file: origin.to_string(),
        scene,
        dimension: d,
        dt,
        phi_version: env!("CARGO_PKG_VERSION"),
        summary,
    };
    let text = serde_json::to_string_pretty(&file)?;
    let path = out.join("run.json");
    write_atomic(&path, |w| {
        w.write_all(text.as_bytes())
            .map_err(|e| OutputError::io(&path, "cannot write", e))
    })?;
    Ok(())
}

/// Frame `step` of the run as a VTK file of the series (all particles liquid).
fn write_vtk_frame(
    series: &mut VtkSeries,
    step: usize,
    frame: &RecordedFrame,
    dt: f32,
    d: usize,
) -> Result<()> {
    let types = vec![i32::from(KIND_LIQUID); frame.positions.len() / d];
    series.add(
        step,
        &VtkFrame {
            time: f64::from(step as f32 * dt),
            dim: d,
            positions: &frame.positions,
            velocities: &frame.velocities,
            particle_type: &types,
        },
    )?;
    Ok(())
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
