//! `phi optimize`: the thesis' optimisation experiment (section 4.3) — initial particle positions
//! optimised by gradient descent through the differentiable FLIP simulation so that the simulated
//! liquid matches a target; or, with `--simulator gns --model DIR`, through a trained GNS's
//! rollout over the same scene towards the same (FLIP) target ([`crate::gns::inverse`]).
//!
//! Output directory:
//! - `loss.csv`: `iteration,loss,gradient_norm,rms_distance,chamfer` per iteration (iteration
//!   `k` is the loss of the initial positions after `k` gradient steps);
//! - `loss.png`: the loss curve (labelled axes, logarithmic when every loss is positive; not
//!   drawn when no loss is finite);
//! - `frames/iteration_KKK_initial.png`, `frames/iteration_KKK_final.png`: the initial positions
//!   and the simulated positions of the first, every `frame_every`-th and the last iteration,
//!   the target drawn in orange under the liquid (blue) — initial frames show the target's
//!   initial positions, final frames the target;
//! - `summary.json`: the configuration, the loss and the distances before and after.
//!
//! The output directory must be new or empty; `--force` replaces a previous run (one holding
//! only the files above; [`OPTIMIZE_OUTPUTS`]), whose files are removed first. Anything else is
//! refused, `--force` or not.
//!
//! A run that stops early (non-finite loss or gradient, divergence, a failed step) writes all of
//! the above for the iterations it completed, then returns the error.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use phi_core::AutodiffBackend;
use phi_core::fields::Domain;
use phi_core::fields::LatticeKernels;
use phi_core::point_sets::set_distances;
use phi_flip::optimize::{Forward, IterationRecord, LossSpec};
use phi_flip::{OptimizeConfig, OptimizeOutcome, OptimizeProblem};
use phi_gns::model::GnsKernels;
use phi_io::output_dir::{OutputDir, OutputSubdir, Outputs};
use phi_plot::{LinePlot, Series};
use serde::Serialize;

use crate::gns::inverse::GnsForward;
use crate::output::{FrameStyle, KIND_LIQUID, OutputError, render_frame, write_atomic, write_png};

/// `phi optimize CONFIG.toml --out DIR [--backend burn|tch] [--iterations N] [--loss L]`.
#[derive(Debug, Clone, clap::Args)]
pub struct OptimizeArgs {
    /// The optimisation (TOML; see scenes/optimize/ for examples).
    pub config: PathBuf,
    /// The output directory.
    #[arg(long)]
    pub out: PathBuf,
    /// The backend: one with autodiff [default: burn, else the first with autodiff compiled in,
    /// as for every command that needs gradients].
    #[arg(long)]
    pub backend: Option<crate::backends::BackendKind>,
    /// Run this many iterations instead of the file's.
    #[arg(long)]
    pub iterations: Option<usize>,
    /// Use this loss instead of the file's: l2, sinkhorn or density.
    #[arg(long, value_parser = parse_loss)]
    pub loss: Option<LossSpec>,
    /// Frames of every this many iterations (plus the first and the last). Iterations, not
    /// steps: each draws two PNGs, so the default, 5, keeps a long optimisation's frames/
    /// folder small.
    #[arg(long, default_value_t = 5)]
    pub frame_every: usize,
    /// Pixels per grid cell in the frames.
    #[arg(long, default_value_t = 8)]
    pub pixels_per_cell: u32,
    /// The simulator between the initial positions and the loss: flip, or gns (a trained
    /// model, `--model`). The target is FLIP's either way.
    #[arg(long, value_enum, default_value_t = Simulator::Flip)]
    pub simulator: Simulator,
    /// The model directory of `--simulator gns` (a `phi train` directory's `best/`, say).
    #[arg(long, required_if_eq("simulator", "gns"))]
    pub model: Option<PathBuf>,
    /// Replace a previous run in --out (a folder holding anything else is refused even then).
    #[arg(long)]
    pub force: bool,
}

/// What `phi optimize` writes in its output directory.
pub(crate) const OPTIMIZE_OUTPUTS: Outputs = Outputs {
    command: "phi optimize",
    flag: "--out",
    files: &["loss.csv", "loss.png", "summary.json"],
    subdirs: &[OutputSubdir {
        name: "frames",
        prefix: "iteration_",
        suffix: ".png",
    }],
    marker: None,
};

/// What simulates the optimised liquid.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Simulator {
    /// The differentiable FLIP simulation of the scene.
    Flip,
    /// A trained Graph Network-based Simulator rolled out over the scene.
    Gns,
}

fn parse_loss(name: &str) -> Result<LossSpec, String> {
    match name {
        "l2" => Ok(LossSpec::L2),
        "sinkhorn" => Ok(LossSpec::Sinkhorn),
        "density" => Ok(LossSpec::Density),
        other => Err(format!(
            "unknown loss {other:?}; use l2, sinkhorn or density"
        )),
    }
}

/// Runs `phi optimize` and prints a summary.
///
/// # Errors
/// An unusable backend, configuration or output error, or an early stop.
pub fn run(args: OptimizeArgs) -> Result<()> {
    use crate::backends::BackendKind;
    let config = OptimizeConfig::from_file(&args.config)?;
    let kind = match args.backend {
        Some(kind) => kind,
        None => BackendKind::default_autodiff()
            .context("no backend with autodiff is compiled into this build")?,
    };
    // Refused before the configuration is built; a previous run is removed in `optimize`.
    let _previous = OutputDir::claim(&args.out, &OPTIMIZE_OUTPUTS, args.force)?;
    let options = OptimizeOptions {
        config: args.config.clone(),
        out: args.out.clone(),
        iterations: args.iterations,
        loss: args.loss,
        frame_every: args.frame_every,
        pixels_per_cell: args.pixels_per_cell,
        force: args.force,
        model: match args.simulator {
            Simulator::Flip => {
                if args.model.is_some() {
                    bail!("--model is for --simulator gns");
                }
                None
            }
            Simulator::Gns => args.model.clone(),
        },
    };
    println!(
        "{}: {}",
        args.config.display(),
        config.description.as_deref().unwrap_or("(no description)")
    );
    let summary: Result<OptimizeSummary> = crate::with_autodiff_backend!(
        kind,
        B => optimize::<B>(&config, &options),
        otherwise => {
            let _ = &options;
            Err(anyhow::anyhow!(
                "the {kind} backend has no autodiff; {}",
                BackendKind::autodiff_hint()
            ))
        }
    );
    let summary = summary?;
    println!(
        "{} iterations of {} particles through {} on {} ({} loss, {:.2} s per iteration): loss {} -> {} \
         (within 1% of the lowest from iteration {}); Chamfer distance to the target {:.3} -> \
         {:.3}, earth mover's {:.3} -> {:.3} cells; outputs in {}",
        summary.iterations,
        summary.particles,
        summary.simulator,
        summary.backend,
        summary.loss,
        summary.seconds_per_iteration,
        summary.losses.first().copied().unwrap_or(f32::NAN),
        summary.losses.last().copied().unwrap_or(f32::NAN),
        summary.converged_at,
        summary.chamfer[0],
        summary.chamfer[1],
        summary.wasserstein[0],
        summary.wasserstein[1],
        args.out.display()
    );
    if let Some(check) = &summary.flip_check {
        println!(
            "the initial positions simulated with FLIP: Chamfer distance to the target {:.3} -> \
             {:.3}, earth mover's {:.3} -> {:.3} cells",
            check.chamfer[0], check.chamfer[1], check.wasserstein[0], check.wasserstein[1]
        );
    }
    Ok(())
}

/// The particle kind the target is drawn with (orange in [`FrameStyle::default`]).
const KIND_TARGET: u8 = 2;

/// How to run and what to write.
#[derive(Debug, Clone)]
pub struct OptimizeOptions {
    /// The configuration file (for messages).
    pub config: PathBuf,
    /// The output directory.
    pub out: PathBuf,
    /// Override of `[optimize] iterations`.
    pub iterations: Option<usize>,
    /// Override of `[optimize] loss`.
    pub loss: Option<LossSpec>,
    /// Frames of every this many iterations (plus the first and the last).
    pub frame_every: usize,
    /// Pixels per grid cell in the frames.
    pub pixels_per_cell: u32,
    /// A GNS model directory to simulate with instead of FLIP.
    pub model: Option<PathBuf>,
    /// Replace a previous run in `out` ([`OPTIMIZE_OUTPUTS`]).
    pub force: bool,
}

/// What a run did.
#[derive(Debug, Clone, Serialize)]
pub struct OptimizeSummary {
    /// The backend.
    pub backend: String,
    /// The simulator: `flip`, or `gns <model directory>`.
    pub simulator: String,
    /// The loss (`l2`, `sinkhorn`, `density`).
    pub loss: String,
    /// Particles optimised.
    pub particles: usize,
    /// Iterations completed (loss evaluations).
    pub iterations: usize,
    /// The loss per iteration.
    pub losses: Vec<f32>,
    /// The iteration from which the loss stays within 1% of the lowest, or within round-off of
    /// it (see [`convergence_iteration`]): the convergence point.
    pub converged_at: usize,
    /// Chamfer distance of the simulated liquid to the target, first and last iteration.
    pub chamfer: [f32; 2],
    /// Earth mover's estimate (`√(2 S_ε)`, ε = 0.01) to the target, first and last iteration.
    pub wasserstein: [f32; 2],
    /// RMS distance of particle `i` to target point `i`, first and last iteration.
    pub rms_distance: [f32; 2],
    /// Wall-clock seconds per iteration (forward and backward).
    pub seconds_per_iteration: f64,
    /// Why the run stopped early, if it did.
    pub stopped: Option<String>,
    /// Through a learned simulator: the first and the last iteration's initial positions
    /// simulated with FLIP, measured against the target (does the optimum the model found
    /// solve the physical problem?); `None` for FLIP runs.
    pub flip_check: Option<FlipCheck>,
}

/// The initial positions of a run through a learned simulator, simulated with FLIP.
#[derive(Debug, Clone, Serialize)]
pub struct FlipCheck {
    /// Chamfer distance of FLIP's end state to the target, first and last iteration.
    pub chamfer: [f32; 2],
    /// Earth mover's estimate (`√(2 S_ε)`, ε = 0.01) to the target, first and last iteration.
    pub wasserstein: [f32; 2],
}

/// Runs the optimisation of `config` on backend `B` and writes the outputs.
///
/// # Errors
/// Configuration and output errors; an early stop, after its outputs are written.
pub fn optimize<B: AutodiffBackend + LatticeKernels + GnsKernels>(
    config: &OptimizeConfig,
    options: &OptimizeOptions,
) -> Result<OptimizeSummary> {
    let mut config = config.clone();
    if let Some(n) = options.iterations {
        config.optimize.iterations = n;
    }
    if let Some(loss) = options.loss {
        config.optimize.loss = loss;
    }
    let origin = options.config.display().to_string();
    let problem: OptimizeProblem<B> = config.build(&origin, &B::default_device())?;
    let gns = match &options.model {
        Some(dir) => Some(GnsForward::new(dir, &problem, &origin)?),
        None => None,
    };
    let forward: &dyn Forward<B> = match &gns {
        Some(gns) => gns,
        None => &problem,
    };
    // Checked again here, once the configuration has been built: the previous run goes only
    // when this one is about to write.
    let mut dir = OutputDir::claim(&options.out, &OPTIMIZE_OUTPUTS, options.force)?;
    dir.clear_previous()?;
    let frames = IterationFrames::new(&problem, options)?;
    let started = Instant::now();
    let mut draw_error = None;
    let outcome = problem.run_through(forward, |record: &IterationRecord| {
        if !crate::progress::is_quiet() {
            eprintln!(
                "iteration {:>3}: loss {:>12.4}  |∇| {:>10.4}  chamfer {:.3}",
                record.iteration, record.loss, record.gradient_norm, record.chamfer
            );
        }
        if frames.due(record.iteration)
            && let Err(e) = frames.draw(record)
        {
            draw_error.get_or_insert(e);
        }
    });
    let elapsed = started.elapsed().as_secs_f64();
    if let Some(e) = draw_error {
        return Err(e);
    }
    // Always a frame of the last good state (an early stop may fall between frame iterations).
    if let Some(last) = outcome.records.last() {
        frames.draw(last)?;
    }
    write_loss_files(&dir, &outcome.records)?;
    let summary = summarize(&problem, gns.as_ref(), &outcome, elapsed, &origin)?;
    let json = serde_json::json!({ "config": config, "summary": summary });
    dir.write_bytes("summary.json", &serde_json::to_vec_pretty(&json)?)?;
    if let Some(e) = outcome.stopped {
        bail!(
            "{origin}: {e}; the outputs of the last good iteration ({}) are in {}",
            outcome.records.last().map_or(0, |r| r.iteration),
            dir.path().display()
        );
    }
    Ok(summary)
}

/// `frames/iteration_KKK_{initial,final}.png`: the initial positions over the target's, and
/// the simulated positions over the target, of the first, every `frame_every`-th and the last
/// iteration.
struct IterationFrames {
    frames: PathBuf,
    domain: Domain,
    solid: Vec<bool>,
    style: FrameStyle,
    target: Vec<f32>,
    target_initial: Vec<f32>,
    iterations: usize,
    every: usize,
}

impl IterationFrames {
    fn new<B: LatticeKernels>(
        problem: &OptimizeProblem<B>,
        options: &OptimizeOptions,
    ) -> Result<Self> {
        let frames = options.out.join("frames");
        std::fs::create_dir_all(&frames)
            .with_context(|| format!("creating {}", frames.display()))?;
        let sim = &problem.simulation;
        Ok(IterationFrames {
            frames,
            domain: sim.domain().clone(),
            solid: sim.solid_cells(0.0)?,
            style: FrameStyle {
                pixels_per_cell: options.pixels_per_cell.max(1),
                ..FrameStyle::default()
            },
            target: problem.target.to_vec(),
            target_initial: problem.target_initial.to_vec(),
            iterations: problem.iterations,
            every: options.frame_every.max(1),
        })
    }

    /// Whether iteration `k` is drawn as the run goes.
    fn due(&self, k: usize) -> bool {
        k == 0 || k == self.iterations || k.is_multiple_of(self.every)
    }

    /// Both pictures of `record`.
    fn draw(&self, record: &IterationRecord) -> Result<()> {
        let k = record.iteration;
        let name = |what: &str| self.frames.join(format!("iteration_{k:03}_{what}.png"));
        self.draw_over(
            &record.initial_positions,
            &self.target_initial,
            &name("initial"),
        )?;
        self.draw_over(&record.final_positions, &self.target, &name("final"))
    }

    /// `liquid` (blue) drawn over `under` (the target, orange) into `path`.
    fn draw_over(&self, liquid: &[f32], under: &[f32], path: &Path) -> Result<()> {
        let d = self.domain.dim();
        let mut positions = under.to_vec();
        positions.extend_from_slice(liquid);
        let mut kinds = vec![KIND_TARGET; under.len() / d];
        kinds.extend(std::iter::repeat_n(KIND_LIQUID, liquid.len() / d));
        let image = render_frame(
            &positions,
            d,
            &kinds,
            self.domain.lower(),
            self.domain.upper(),
            self.domain.resolution(),
            Some(&self.solid),
            &self.style,
        )?;
        write_png(path, &image)?;
        Ok(())
    }
}

/// `loss.csv` and `loss.png` (not drawn when no loss is finite).
fn write_loss_files(dir: &OutputDir, records: &[IterationRecord]) -> Result<()> {
    write_loss_csv(&dir.path().join("loss.csv"), records)?;
    let losses: Vec<f32> = records.iter().map(|r| r.loss).collect();
    let loss_png = dir.path().join("loss.png");
    match plot_losses(&losses) {
        Some(plot) => plot
            .write_png(&loss_png)
            .with_context(|| format!("drawing {}", loss_png.display()))?,
        None => tracing::warn!("no finite loss: {} not drawn", loss_png.display()),
    }
    Ok(())
}

/// The summary of a run: losses, convergence, the distances to the target before and after,
/// and, through a learned simulator, the same initial positions simulated with FLIP.
///
/// # Errors
/// A run that stopped before its first iteration, a failing distance or FLIP simulation.
fn summarize<B: AutodiffBackend + LatticeKernels + GnsKernels>(
    problem: &OptimizeProblem<B>,
    gns: Option<&GnsForward<B>>,
    outcome: &OptimizeOutcome,
    elapsed: f64,
    origin: &str,
) -> Result<OptimizeSummary> {
    let records = &outcome.records;
    let (first, last) = match (records.first(), records.last()) {
        (Some(f), Some(l)) => (f, l),
        _ => bail!(
            "{origin}: the optimisation stopped before its first iteration: {}",
            outcome
                .stopped
                .as_ref()
                .map_or("unknown reason".into(), ToString::to_string)
        ),
    };
    let d = problem.simulation.domain().dim();
    let target = problem.target.to_vec();
    let distances = |r: &IterationRecord| set_distances(&r.final_positions, &target, d);
    let (before, after) = (distances(first)?, distances(last)?);
    let losses: Vec<f32> = records.iter().map(|r| r.loss).collect();
    let flip_check = match gns {
        Some(_) => {
            let through_flip = |r: &IterationRecord| -> Result<_> {
                let initial = phi_core::Tensor::<B>::from_vec(
                    r.initial_positions.clone(),
                    &[r.initial_positions.len() / d, d],
                    &B::default_device(),
                )?;
                let end = Forward::run(problem, &initial)
                    .with_context(|| format!("{origin}: simulating the optimum with FLIP"))?;
                Ok(set_distances(&end.to_vec(), &target, d)?)
            };
            let (before, after) = (through_flip(first)?, through_flip(last)?);
            Some(FlipCheck {
                chamfer: [before.chamfer, after.chamfer],
                wasserstein: [before.wasserstein, after.wasserstein],
            })
        }
        None => None,
    };
    Ok(OptimizeSummary {
        backend: B::name().to_string(),
        simulator: gns.map_or_else(|| "flip".into(), |gns| format!("gns {}", gns.name())),
        loss: problem.loss.name().into(),
        particles: problem.initial.len(),
        iterations: records.len(),
        converged_at: convergence_iteration(&losses),
        losses,
        chamfer: [before.chamfer, after.chamfer],
        wasserstein: [before.wasserstein, after.wasserstein],
        rms_distance: [first.rms_distance, last.rms_distance],
        seconds_per_iteration: elapsed / records.len().max(1) as f64,
        stopped: outcome.stopped.as_ref().map(ToString::to_string),
        flip_check,
    })
}

fn write_loss_csv(path: &Path, records: &[IterationRecord]) -> Result<()> {
    write_atomic(path, |w| -> Result<(), OutputError> {
        let io = |e: std::io::Error| OutputError::InvalidInput(e.to_string());
        writeln!(w, "iteration,loss,gradient_norm,rms_distance,chamfer").map_err(io)?;
        for r in records {
            writeln!(
                w,
                "{},{},{},{},{}",
                r.iteration, r.loss, r.gradient_norm, r.rms_distance, r.chamfer
            )
            .map_err(io)?;
        }
        Ok(())
    })?;
    Ok(())
}

/// The loss against the iteration, with axes, labels and a legend: on a logarithmic axis when
/// every finite loss is positive, else a linear one; a non-finite loss leaves a gap. `None`
/// when no loss is finite (nothing to draw).
pub(crate) fn plot_losses(losses: &[f32]) -> Option<LinePlot> {
    let finite: Vec<f32> = losses.iter().copied().filter(|l| l.is_finite()).collect();
    if finite.is_empty() {
        return None;
    }
    let x = (0..losses.len()).map(|i| i as f64).collect();
    let y = losses.iter().map(|&l| f64::from(l)).collect();
    Some(
        LinePlot::new("Optimisation", "iteration", "loss")
            .with_log_y(finite.iter().all(|&l| l > 0.0))
            .with_size(640, 400)
            .with_series(Series::new("loss", x, y)),
    )
}

/// The first iteration from which the loss stays within 1% of the lowest, where "within" also
/// accepts a difference below `1e-6` of the largest loss: a loss that reaches single-precision
/// round-off (an exact match gives values like `1e-11`, then `3e-13`) has converged when it first
/// gets there, not when it hits its smallest round-off value. 0 for no losses.
pub(crate) fn convergence_iteration(losses: &[f32]) -> usize {
    let finite = || losses.iter().copied().filter(|l| l.is_finite());
    let lowest = finite().fold(f32::INFINITY, f32::min);
    let largest = finite().map(f32::abs).fold(0.0, f32::max);
    let tolerance = (0.01 * lowest.abs()).max(1e-6 * largest);
    let close = |l: f32| l <= lowest + tolerance;
    // The last iteration that is not close, plus one: close from there on.
    losses
        .iter()
        .rposition(|&l| !close(l))
        .map_or(0, |i| (i + 1).min(losses.len().saturating_sub(1)))
}

#[cfg(test)]
mod tests {
    use super::convergence_iteration;

    #[test]
    fn convergence_is_where_the_loss_stays_close_to_its_lowest() {
        // A rise, then a fall to round-off zero: converged at the first round-off value.
        let losses = [
            13_810.0, 17_058.0, 7_151.0, 1_323.0, 0.5, 1e-11, 3e-13, 2e-12,
        ];
        assert_eq!(convergence_iteration(&losses), 5);
        // Within 1% of a positive lowest value, and only once it stays there.
        let losses = [10.0, 5.0, 1.005, 3.0, 1.009, 1.0, 1.004];
        assert_eq!(convergence_iteration(&losses), 4);
        // Still falling at the end: the last iteration.
        assert_eq!(convergence_iteration(&[4.0, 3.0, 2.0]), 2);
        assert_eq!(convergence_iteration(&[]), 0);
        assert_eq!(convergence_iteration(&[7.0]), 0);
    }
}
