//! One test trajectory evaluated: the thesis's four metrics and the extra ones, with their
//! curves over the frames of the full rollout.

use phi_core::point_sets::{EmdSolver, GroundCost, SinkhornOptions, sinkhorn_divergence_host};
use serde::{Deserialize, Serialize};

use super::EvalError;
use super::metrics::{
    Container, centre_of_mass, kinetic_energy, liquid_positions, mean_neighbour_count,
};
use crate::data::Trajectory;
use crate::model::{Gns, GnsKernels, GraphBatch, ModelError, Normalisation};
use crate::rollout::{RolloutRange, input_window, position_mse, rollout};
use crate::train::loss::{counted_particles, squared_error};
use crate::train::non_kinematic_mask;

/// What an evaluation computes beyond the model and the data.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EvalOptions {
    /// The length of the short rollouts of MSE 20 (the thesis: 20).
    pub short_rollout: usize,
    /// The ground cost of the EMD.
    pub ground_cost: EmdCost,
    /// The Sinkhorn divergence's `ε` (stored units², for the cost `½|x − y|²`).
    pub sinkhorn_epsilon: f32,
    /// The Sinkhorn divergence of every this many predicted frames (the last one always), 0 for
    /// none: it costs far more than the EMD.
    pub sinkhorn_every: usize,
    /// The radius of the neighbour counts of the density (stored units).
    pub density_radius: f64,
    /// The container of the plausibility metrics (liquid outside the domain or inside an
    /// obstacle); `null`: not measured.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub container: Option<Container>,
}

impl EvalOptions {
    /// The thesis's MSE 20, the squared-Euclidean EMD, the Sinkhorn divergence at `ε = 10⁻⁴`
    /// every 100 frames, and neighbour counts within `density_radius` (the model's
    /// connectivity radius is the natural choice).
    pub fn new(density_radius: f64) -> Self {
        EvalOptions {
            short_rollout: 20,
            ground_cost: EmdCost::SquaredEuclidean,
            sinkhorn_epsilon: 1e-4,
            sinkhorn_every: 100,
            density_radius,
            container: None,
        }
    }
}

/// The EMD's ground cost, as the evaluation files name it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EmdCost {
    /// `|x − y|²` (POT's `ot.dist` default; what the thesis's EMD used).
    SquaredEuclidean,
    /// `|x − y|`.
    Euclidean,
}

impl From<EmdCost> for GroundCost {
    fn from(cost: EmdCost) -> Self {
        match cost {
            EmdCost::SquaredEuclidean => GroundCost::SquaredEuclidean,
            EmdCost::Euclidean => GroundCost::Euclidean,
        }
    }
}

/// The per-frame curves of the full rollout, one value per predicted frame (frames
/// `start + 1 ..`), up to the frame before a blow-up.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Curves {
    /// The dataset frame of each entry.
    pub frame: Vec<usize>,
    /// Position MSE over the liquid particles and dimensions (stored units²).
    pub mse: Vec<f64>,
    /// The EMD between the predicted and the true liquid particles (ground-cost units).
    pub emd: Vec<f64>,
    /// The Sinkhorn divergence where computed (stored units²), else `null`.
    pub sinkhorn: Vec<Option<f64>>,
    /// Kinetic energy per liquid particle of the prediction and of the truth
    /// ([`kinetic_energy`], stored units² per frame²).
    pub kinetic_energy_predicted: Vec<f64>,
    /// See `kinetic_energy_predicted`.
    pub kinetic_energy_true: Vec<f64>,
    /// Mean neighbour count of a liquid particle, prediction and truth.
    pub density_predicted: Vec<f64>,
    /// Liquid particles of the prediction outside the container's bounds (with
    /// [`EvalOptions::container`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub outside: Vec<usize>,
    /// Liquid particles of the prediction inside an obstacle cell (with
    /// [`EvalOptions::container`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub inside_obstacles: Vec<usize>,
    /// The same of the ground truth: the FLIP liquid in the cells of the obstacle particles
    /// (cells only partly covered by a rotated obstacle hold liquid in the truth too).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub inside_obstacles_true: Vec<usize>,
    /// See `density_predicted`.
    pub density_true: Vec<f64>,
}

impl Curves {
    /// The largest share of the `liquid_particles` inside an obstacle cell in any one frame,
    /// of the prediction and of the truth (zeros without the plausibility curves).
    pub fn peak_inside_obstacles(&self, liquid_particles: usize) -> (f64, f64) {
        let peak = |counts: &[usize]| {
            counts.iter().copied().max().unwrap_or(0) as f64 / liquid_particles.max(1) as f64
        };
        (
            peak(&self.inside_obstacles),
            peak(&self.inside_obstacles_true),
        )
    }
}

/// What a physicist checks of a rollout first, each against the ground truth's.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Plausibility {
    /// The fraction of the liquid's particle-frames outside the domain.
    pub outside: f64,
    /// The fraction of the liquid's particle-frames inside an obstacle.
    pub inside_obstacles: f64,
    /// The same fraction of the ground truth's.
    pub inside_obstacles_true: f64,
    /// The largest share of the liquid inside obstacle cells in any one frame
    /// ([`Curves::peak_inside_obstacles`]): a block that passes through a thin obstacle in a few
    /// frames is inside it for a small fraction of the particle-frames, and for a large share of
    /// the liquid in those frames. Not part of [`Plausibility::is_plausible`], whose bounds are
    /// the particle-frame fractions. A cache entry written before it was recorded is filled in
    /// from its curves when read.
    #[serde(default)]
    pub peak_inside_obstacles: f64,
    /// The same of the ground truth's.
    #[serde(default)]
    pub peak_inside_obstacles_true: f64,
    /// Mean neighbour count of the prediction over the truth's at the last frame.
    pub final_density_ratio: f64,
    /// Kinetic energy of the prediction over the truth's, summed over the last
    /// `LATE_FRAMES` frames.
    pub late_kinetic_energy_ratio: f64,
    /// The distance between the predicted and the true liquid's centres of mass at the last
    /// frame, in cells.
    pub final_centre_distance_cells: f64,
}

/// The frames at the end of a rollout whose kinetic energy [`Plausibility`] compares.
pub(crate) const LATE_FRAMES: usize = 50;

impl Plausibility {
    /// Whether every figure is within the bounds of a usable simulator: at most 1 % of the
    /// liquid's particle-frames outside the domain or inside an obstacle, the final density
    /// within 0.8–1.25 of the truth's, the late kinetic energy within a factor 2 and the
    /// centre of mass within 2 cells at the end.
    pub fn is_plausible(&self) -> bool {
        self.outside + self.inside_obstacles <= 0.01
            && (0.8..=1.25).contains(&self.final_density_ratio)
            && (0.5..=2.0).contains(&self.late_kinetic_energy_ratio)
            && self.final_centre_distance_cells <= 2.0
    }
}

/// One trajectory's evaluation. A metric over a rollout that blew up (a non-finite predicted
/// position) is `null`: it is infinite, and JSON has no infinity.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrajectoryEvaluation {
    /// The trajectory's index in its split.
    pub index: usize,
    /// The trajectory's generator seed (checked against the dataset when reused).
    pub seed: u64,
    /// Particles, of which liquid (the metrics' particles).
    pub particles: usize,
    /// See `particles`.
    pub liquid_particles: usize,
    /// The last ground-truth frame of the full rollout's input window (`C`).
    pub start: usize,
    /// MSE-acc 1 in the model's own normalisation: eq. 5.1 averaged over every one-step window
    /// (normalised acceleration units², per dimension; the units of its training loss, which
    /// differ between models trained with and without noise: see [`OneStepErrors`]).
    pub mse_acc1: f64,
    /// The one-step acceleration error per dimension in stored units (position units per
    /// frame², squared), mean over the liquid particles and the windows: MSE-acc 1 in any
    /// normalisation ([`mse_acc1_in`]). Empty in a cache entry written before it was recorded.
    #[serde(default)]
    pub acc_error: Vec<f64>,
    /// The one-step windows: latest input frames `C ..= F − 2`.
    pub acc_windows: usize,
    /// MSE 20: the mean over the short rollouts of their position MSE.
    pub mse20: Option<f64>,
    /// The short rollouts: from frames `C, C + 20, …` while 20 frames follow.
    pub short_windows: usize,
    /// MSE 400: the position MSE of the full rollout, mean over its frames.
    pub mse400: Option<f64>,
    /// The mean of the EMD curve.
    pub emd: Option<f64>,
    /// The mean of the computed Sinkhorn divergences (`null` when none was asked for).
    pub sinkhorn: Option<f64>,
    /// `Σ_t |KE_pred − KE_true| / Σ_t KE_true` over the full rollout (a fraction).
    pub kinetic_energy_error: Option<f64>,
    /// `mean_t density_pred / mean_t density_true`: above 1, the model compresses the liquid.
    pub density_ratio: Option<f64>,
    /// The step at which the full rollout blew up (`null` when it did not).
    pub failed_step: Option<usize>,
    /// Whether the rollout is physically plausible (`null` without a container or after a
    /// blow-up): see [`Plausibility`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plausibility: Option<Plausibility>,
    /// The per-frame curves.
    pub curves: Curves,
}

/// Evaluates `model` on `trajectory`: every one-step window (MSE-acc 1), the short rollouts
/// (MSE 20) and the full rollout from frame `C` with its per-frame curves (MSE 400, EMD,
/// Sinkhorn divergence, kinetic energy, density).
///
/// The first short rollout is the first `short_rollout` steps of the full rollout, which the
/// model computes identically, so it is taken from there.
///
/// # Errors
/// [`ModelError::Input`] (as [`EvalError::Model`]) for a trajectory too short for a window and
/// a target; [`EvalError::Input`] for one without liquid particles; model errors other than a
/// blow-up; metric errors.
pub fn evaluate_trajectory<B: GnsKernels>(
    model: &Gns<B>,
    trajectory: &Trajectory,
    options: &EvalOptions,
    device: &B::Device,
) -> Result<TrajectoryEvaluation, EvalError> {
    evaluate_trajectory_with(model, trajectory, options, device, |_, _| {})
}

/// [`evaluate_trajectory`], handing each frame of the full rollout to `on_frame(frame,
/// positions)` (`frame` the trajectory frame, `positions` `[N, dim]`) as it is predicted, so
/// that a caller that also draws the rollout does not run it twice.
///
/// # Errors
/// As [`evaluate_trajectory`].
pub fn evaluate_trajectory_with<B: GnsKernels>(
    model: &Gns<B>,
    trajectory: &Trajectory,
    options: &EvalOptions,
    device: &B::Device,
    on_frame: impl FnMut(usize, &[f32]),
) -> Result<TrajectoryEvaluation, EvalError> {
    let spec = model.spec();
    let c = spec.config.input_velocities;
    let frames = trajectory.frames;
    let liquid: Vec<bool> = spec
        .kinematic(&trajectory.particle_type)
        .into_iter()
        .map(|k| !k)
        .collect();
    let liquid_particles = liquid.iter().filter(|l| **l).count();
    if liquid_particles == 0 {
        return Err(EvalError::Input {
            what: "trajectory",
            reason: format!("trajectory {} has no liquid particles", trajectory.index),
        });
    }
    if options.short_rollout == 0 {
        return Err(EvalError::Input {
            what: "short_rollout",
            reason: "the short rollouts of MSE 20 need at least one step".into(),
        });
    }

    let one_step = one_step_errors(model, trajectory, 1, device)?;
    let full = full_rollout(model, trajectory, &liquid, options, device, on_frame)?;
    let steps = frames - 1 - c;
    let failed = full.failed_step;

    // Short rollouts from C, C + S, ... while S frames follow; the first is the full rollout's.
    let s = options.short_rollout;
    let starts: Vec<usize> = (c..)
        .step_by(s)
        .take_while(|start| start + s < frames)
        .collect();
    let mut short_sum = Some(0.0f64);
    for (k, &start) in starts.iter().enumerate() {
        let mse = if k == 0 {
            (full.curves.mse.len() >= s)
                .then(|| full.curves.mse[..s].iter().sum::<f64>() / s as f64)
        } else {
            rollout_mse(
                model,
                trajectory,
                &liquid,
                RolloutRange { start, steps: s },
                device,
            )?
        };
        short_sum = short_sum.zip(mse).map(|(a, b)| a + b);
    }
    let mse20 = (!starts.is_empty())
        .then_some(short_sum)
        .flatten()
        .map(|sum| sum / starts.len() as f64);

    let curves = full.curves;
    let complete = failed.is_none() && curves.mse.len() == steps;
    let plausibility = match (&options.container, complete, &full.final_centres) {
        (Some(container), true, Some((predicted, truth))) => Some(plausibility(
            &curves,
            liquid_particles,
            container.cell_size,
            predicted,
            truth,
        )),
        _ => None,
    };
    let sinkhorns: Vec<f64> = curves.sinkhorn.iter().flatten().copied().collect();
    let (ke_error, density_ratio) = if complete {
        energy_and_density(&curves)
    } else {
        (None, None)
    };
    Ok(TrajectoryEvaluation {
        index: trajectory.index,
        seed: trajectory.seed,
        particles: trajectory.particles,
        liquid_particles,
        start: c,
        mse_acc1: one_step.mse_acc1,
        acc_error: one_step.acc_error,
        acc_windows: one_step.windows,
        mse20,
        short_windows: starts.len(),
        mse400: complete.then(|| mean(&curves.mse)),
        emd: complete.then(|| mean(&curves.emd)),
        sinkhorn: (complete && !sinkhorns.is_empty()).then(|| mean(&sinkhorns)),
        kinetic_energy_error: ke_error,
        density_ratio,
        failed_step: failed,
        plausibility,
        curves,
    })
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

/// The relative kinetic-energy error `Σ_t |KE_pred − KE_true| / Σ_t KE_true` and the mean
/// density ratio of complete curves (`None` where the truth's is zero).
fn energy_and_density(curves: &Curves) -> (Option<f64>, Option<f64>) {
    let diff: f64 = curves
        .kinetic_energy_predicted
        .iter()
        .zip(&curves.kinetic_energy_true)
        .map(|(p, t)| (p - t).abs())
        .sum();
    let truth: f64 = curves.kinetic_energy_true.iter().sum();
    let density_true = mean(&curves.density_true);
    (
        (truth > 0.0).then(|| diff / truth),
        (density_true > 0.0).then(|| mean(&curves.density_predicted) / density_true),
    )
}

/// Two trajectories of one scene compared frame by frame as a model's rollout is against the
/// truth ([`compare_trajectories`]): the metrics of [`TrajectoryEvaluation`] that need no model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrajectoryComparison {
    /// The trajectory's index in its split.
    pub index: usize,
    /// Liquid particles (the metrics' particles).
    pub liquid_particles: usize,
    /// The frame after which the comparison starts (a model's `C`).
    pub start: usize,
    /// The position MSE over the compared frames (MSE 400 for a 401-frame trajectory from 5).
    pub mse400: f64,
    /// The mean of the EMD curve.
    pub emd: f64,
    /// The mean of the computed Sinkhorn divergences (`null` when none was asked for).
    pub sinkhorn: Option<f64>,
    /// As [`TrajectoryEvaluation::kinetic_energy_error`].
    pub kinetic_energy_error: Option<f64>,
    /// As [`TrajectoryEvaluation::density_ratio`].
    pub density_ratio: Option<f64>,
    /// With [`EvalOptions::container`]: the plausibility figures.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plausibility: Option<Plausibility>,
    /// The per-frame curves.
    pub curves: Curves,
}

/// Compares `other` with `truth`, two trajectories of one scene (another simulator, another
/// sampling of the initial liquid), over frames `start + 1 ..` as [`evaluate_trajectory`]
/// compares a model's full rollout from `start = C`: the position MSE, the EMD, the Sinkhorn
/// divergence, the kinetic-energy and density ratios and the plausibility figures, over the
/// particles whose type is not in `kinematic_types`. Particle `i` of one is compared with
/// particle `i` of the other in the MSE; the EMD pairs them as it likes.
///
/// # Errors
/// [`EvalError::Input`] for trajectories of different particle counts, types, dimensions or
/// lengths, one without liquid or too short for a frame after `start`; metric errors.
pub fn compare_trajectories(
    other: &Trajectory,
    truth: &Trajectory,
    start: usize,
    kinematic_types: &[i64],
    options: &EvalOptions,
) -> Result<TrajectoryComparison, EvalError> {
    let refuse = |reason: String| EvalError::Input {
        what: "comparison",
        reason,
    };
    let index = truth.index;
    if (other.particles, other.dim, other.frames) != (truth.particles, truth.dim, truth.frames) {
        return Err(refuse(format!(
            "trajectory {index}: {} particles in {}D over {} frames against {} in {}D over {}",
            other.particles, other.dim, other.frames, truth.particles, truth.dim, truth.frames
        )));
    }
    if other.particle_type != truth.particle_type {
        return Err(refuse(format!(
            "trajectory {index}: the particle types differ (not the same scene)"
        )));
    }
    if start + 1 >= truth.frames {
        return Err(refuse(format!(
            "trajectory {index}: {} frames leave none after frame {start}",
            truth.frames
        )));
    }
    let liquid: Vec<bool> = truth
        .particle_type
        .iter()
        .map(|t| !kinematic_types.contains(t))
        .collect();
    let liquid_particles = liquid.iter().filter(|l| **l).count();
    if liquid_particles == 0 {
        return Err(refuse(format!(
            "trajectory {index} has no liquid particles"
        )));
    }
    let range = RolloutRange {
        start,
        steps: truth.frames - 1 - start,
    };
    let mut metrics = FrameMetrics::new(truth, &liquid, options, range, other.frame(start));
    for step in 1..=range.steps {
        metrics.push(start + step, step, other.frame(start + step))?;
    }
    let (curves, centres) = (metrics.curves, metrics.final_centres);
    let plausibility = match (&options.container, &centres) {
        (Some(container), Some((predicted, truth))) => Some(plausibility(
            &curves,
            liquid_particles,
            container.cell_size,
            predicted,
            truth,
        )),
        _ => None,
    };
    let sinkhorns: Vec<f64> = curves.sinkhorn.iter().flatten().copied().collect();
    let (kinetic_energy_error, density_ratio) = energy_and_density(&curves);
    Ok(TrajectoryComparison {
        index,
        liquid_particles,
        start,
        mse400: mean(&curves.mse),
        emd: mean(&curves.emd),
        sinkhorn: (!sinkhorns.is_empty()).then(|| mean(&sinkhorns)),
        kinetic_energy_error,
        density_ratio,
        plausibility,
        curves,
    })
}

/// The plausibility figures of a complete rollout's curves and its final centres of mass.
fn plausibility(
    curves: &Curves,
    liquid_particles: usize,
    cell_size: f64,
    predicted_centre: &[f64],
    true_centre: &[f64],
) -> Plausibility {
    let frames = curves.mse.len();
    let particle_frames = (liquid_particles * frames).max(1) as f64;
    let late = frames.saturating_sub(LATE_FRAMES);
    let sum = |v: &[f64]| v[late..].iter().sum::<f64>();
    let last = |v: &[f64]| v.last().copied().unwrap_or(0.0);
    let (peak_inside_obstacles, peak_inside_obstacles_true) =
        curves.peak_inside_obstacles(liquid_particles);
    let distance = predicted_centre
        .iter()
        .zip(true_centre)
        .map(|(a, b)| (a - b) * (a - b))
        .sum::<f64>()
        .sqrt();
    Plausibility {
        outside: curves.outside.iter().sum::<usize>() as f64 / particle_frames,
        inside_obstacles: curves.inside_obstacles.iter().sum::<usize>() as f64 / particle_frames,
        inside_obstacles_true: curves.inside_obstacles_true.iter().sum::<usize>() as f64
            / particle_frames,
        peak_inside_obstacles,
        peak_inside_obstacles_true,
        final_density_ratio: last(&curves.density_predicted) / last(&curves.density_true),
        late_kinetic_energy_ratio: sum(&curves.kinetic_energy_predicted)
            / sum(&curves.kinetic_energy_true),
        final_centre_distance_cells: distance / cell_size,
    }
}

/// The one-step errors of a model on a trajectory.
///
/// A model's normalised accelerations are divided by `sqrt(acc_std² + σ²)`, DeepMind's scale
/// widened by the model's training noise `σ`, so a model trained with noise (1sn, 1snb) measures
/// its errors in larger units than one without (1s, 2ss, 2si): on the thesis's data the widened
/// scale is ~1.8 times the plain one, and the same error reads ~3.2 times smaller. `acc_error`
/// holds the error in stored units, so that models can be compared in one normalisation.
#[derive(Debug, Clone, PartialEq)]
pub struct OneStepErrors {
    /// Eq. 5.1 (no noise) divided by the dimension, in the model's own normalisation, mean over
    /// the windows.
    pub mse_acc1: f64,
    /// Per dimension: the squared acceleration error in stored units, mean over the
    /// non-kinematic particles and the windows.
    pub acc_error: Vec<f64>,
    /// The windows.
    pub windows: usize,
}

/// MSE-acc 1 of `model` on `trajectory`: eq. 5.1 (no noise) per window, divided by the
/// dimension, averaged over the windows whose latest input frame is `C, C + stride, …, F − 2`,
/// in the model's own normalisation. Returns the mean and the number of windows.
///
/// # Errors
/// As [`one_step_errors`].
pub fn mse_acc1<B: GnsKernels>(
    model: &Gns<B>,
    trajectory: &Trajectory,
    stride: usize,
    device: &B::Device,
) -> Result<(f64, usize), ModelError> {
    one_step_errors(model, trajectory, stride, device).map(|e| (e.mse_acc1, e.windows))
}

/// MSE-acc 1 from the per-dimension stored-unit errors `acc_error` in the normalisation of
/// `acc_std` (a dataset's, the same for every model measured): `Σ_a acc_error_a / acc_std_a² / d`.
pub fn mse_acc1_in(acc_error: &[f64], acc_std: &[f64]) -> f64 {
    let d = acc_error.len().max(1) as f64;
    acc_error
        .iter()
        .zip(acc_std)
        .map(|(e, s)| e / (s * s))
        .sum::<f64>()
        / d
}

/// The one-step errors of `model` on the windows of `trajectory` whose latest input frame is
/// `C, C + stride, …, F − 2` ([`OneStepErrors`]).
///
/// # Errors
/// Model errors; [`ModelError::Input`] for a trajectory without a window and a target, or
/// without a non-kinematic particle.
pub fn one_step_errors<B: GnsKernels>(
    model: &Gns<B>,
    trajectory: &Trajectory,
    stride: usize,
    device: &B::Device,
) -> Result<OneStepErrors, ModelError> {
    let spec = model.spec();
    let c = spec.config.input_velocities;
    let frames = trajectory.frames;
    if frames < c + 2 {
        return Err(ModelError::Input {
            what: "trajectory",
            reason: format!(
                "a trajectory of {frames} frames has no window of {} frames and a target",
                c + 1
            ),
        });
    }
    let dim = spec.config.dim;
    let mask = non_kinematic_mask::<B>(&trajectory.particle_type, &spec.kinematic_types, device)?;
    let counted = mask.to_vec();
    let scale = Normalisation::scale(&spec.normalisation.acc_std, spec.config.noise_std);
    let (mut normalised, mut stored) = (0.0f64, vec![0.0f64; dim]);
    let mut windows = 0usize;
    for t in (c..frames - 1).step_by(stride.max(1)) {
        let window = input_window(trajectory, t, c);
        let batch = GraphBatch::from_host(&window, &trajectory.particle_type, spec, device)?;
        let next = phi_core::Tensor::from_slice(
            trajectory.frame(t + 1),
            &[trajectory.particles, trajectory.dim],
            device,
        )?;
        // Eq. 5.1 as the training loss computes it, and its errors per dimension.
        let count = counted_particles(&batch, &mask)?;
        let predicted = model.normalised_acceleration(&batch)?;
        let target = model.target_acceleration(&batch, &next)?;
        let loss = squared_error(&predicted, &target, &mask, count)?.to_scalar()?;
        normalised += f64::from(loss) / dim as f64;
        let (predicted, target) = (predicted.to_vec(), target.to_vec());
        let mut per_dim = vec![0.0f64; dim];
        for (i, _) in counted.iter().enumerate().filter(|(_, m)| **m > 0.0) {
            for (a, sum) in per_dim.iter_mut().enumerate() {
                let e = f64::from(predicted[i * dim + a]) - f64::from(target[i * dim + a]);
                *sum += e * e;
            }
        }
        for ((s, e), k) in stored.iter_mut().zip(&per_dim).zip(&scale) {
            *s += e * k * k / f64::from(count);
        }
        windows += 1;
    }
    Ok(OneStepErrors {
        mse_acc1: normalised / windows as f64,
        acc_error: stored.iter().map(|s| s / windows as f64).collect(),
        windows,
    })
}

/// The position MSE of a rollout over `range`, mean over its frames; `None` when it blows up.
fn rollout_mse<B: GnsKernels>(
    model: &Gns<B>,
    trajectory: &Trajectory,
    liquid: &[bool],
    range: RolloutRange,
    device: &B::Device,
) -> Result<Option<f64>, EvalError> {
    let kinematic: Vec<bool> = liquid.iter().map(|l| !l).collect();
    let mut sum = 0.0;
    let ran = rollout(model, trajectory, range, device, |step, positions| {
        let truth = trajectory.frame(range.start + step);
        sum += position_mse(positions, truth, &kinematic, trajectory.dim);
        Ok(())
    });
    match ran {
        Ok(()) => Ok(Some(sum / range.steps as f64)),
        Err(ModelError::NonFinitePrediction { .. }) => Ok(None),
        Err(e) => Err(e.into()),
    }
}

/// The full rollout's curves, and the step at which it blew up.
struct FullRollout {
    curves: Curves,
    failed_step: Option<usize>,
    /// The predicted and true liquid's centres of mass at the last frame reached.
    final_centres: Option<(Vec<f64>, Vec<f64>)>,
}

/// The per-frame metrics of a predicted trajectory against the truth, a frame at a time: the
/// curves of [`Curves`] and the last frame's centres of mass.
struct FrameMetrics<'a> {
    truth: &'a Trajectory,
    liquid: &'a [bool],
    kinematic: Vec<bool>,
    options: &'a EvalOptions,
    /// The last step of the range (the Sinkhorn divergence is always computed there).
    last_step: usize,
    // Consecutive frames differ little: each EMD starts from the previous frame's solution.
    emd: EmdSolver,
    sinkhorn: SinkhornOptions,
    /// The predicted frame before the one pushed next (for its kinetic energy).
    previous: Vec<f32>,
    obstacles: Option<std::collections::HashSet<Vec<i64>>>,
    curves: Curves,
    final_centres: Option<(Vec<f64>, Vec<f64>)>,
}

impl<'a> FrameMetrics<'a> {
    /// Metrics of the frames after `range.start`, whose predicted positions are `first`.
    fn new(
        truth: &'a Trajectory,
        liquid: &'a [bool],
        options: &'a EvalOptions,
        range: RolloutRange,
        first: &[f32],
    ) -> Self {
        let obstacles = options
            .container
            .as_ref()
            .map(|box_| box_.obstacle_cells(truth.frame(range.start), liquid, truth.dim));
        FrameMetrics {
            truth,
            liquid,
            kinematic: liquid.iter().map(|l| !l).collect(),
            options,
            last_step: range.steps,
            emd: EmdSolver::new(),
            sinkhorn: SinkhornOptions::new(options.sinkhorn_epsilon),
            previous: first.to_vec(),
            obstacles,
            curves: Curves::default(),
            final_centres: None,
        }
    }

    /// Adds predicted frame `frame` (`step` steps after the start) with positions `positions`.
    fn push(&mut self, frame: usize, step: usize, positions: &[f32]) -> Result<(), EvalError> {
        let (liquid, dim, options) = (self.liquid, self.truth.dim, self.options);
        let truth = self.truth.frame(frame);
        let curves = &mut self.curves;
        let predicted_liquid = liquid_positions(positions, liquid, dim);
        let true_liquid = liquid_positions(truth, liquid, dim);
        curves.frame.push(frame);
        curves
            .mse
            .push(position_mse(positions, truth, &self.kinematic, dim));
        curves.emd.push(self.emd.solve(
            &predicted_liquid,
            &true_liquid,
            dim,
            options.ground_cost.into(),
        )?);
        let every = options.sinkhorn_every;
        curves.sinkhorn.push(
            if every > 0 && (step.is_multiple_of(every) || step == self.last_step) {
                Some(sinkhorn_divergence_host(
                    &predicted_liquid,
                    &true_liquid,
                    dim,
                    &self.sinkhorn,
                )?)
            } else {
                None
            },
        );
        curves.kinetic_energy_predicted.push(kinetic_energy(
            &self.previous,
            positions,
            liquid,
            dim,
        ));
        curves.kinetic_energy_true.push(kinetic_energy(
            self.truth.frame(frame - 1),
            truth,
            liquid,
            dim,
        ));
        curves.density_predicted.push(mean_neighbour_count(
            positions,
            liquid,
            dim,
            options.density_radius,
        )?);
        curves.density_true.push(mean_neighbour_count(
            truth,
            liquid,
            dim,
            options.density_radius,
        )?);
        if let (Some(container), Some(obstacles)) = (&options.container, &self.obstacles) {
            let (outside, inside) = container.misplaced(positions, liquid, dim, obstacles);
            curves.outside.push(outside);
            curves.inside_obstacles.push(inside);
            let (_, inside_true) = container.misplaced(truth, liquid, dim, obstacles);
            curves.inside_obstacles_true.push(inside_true);
        }
        self.final_centres = Some((
            centre_of_mass(positions, liquid, dim),
            centre_of_mass(truth, liquid, dim),
        ));
        self.previous.copy_from_slice(positions);
        Ok(())
    }
}

/// Rolls out from frame `C` to the last frame, computing the per-frame metrics as frames come.
fn full_rollout<B: GnsKernels>(
    model: &Gns<B>,
    trajectory: &Trajectory,
    liquid: &[bool],
    options: &EvalOptions,
    device: &B::Device,
    mut on_frame: impl FnMut(usize, &[f32]),
) -> Result<FullRollout, EvalError> {
    let c = model.spec().config.input_velocities;
    let range = RolloutRange::full(c, trajectory.frames);
    let mut metrics = FrameMetrics::new(trajectory, liquid, options, range, trajectory.frame(c));
    let mut metric_error: Option<EvalError> = None;
    let ran = rollout(model, trajectory, range, device, |step, positions| {
        let frame = c + step;
        on_frame(frame, positions);
        metrics.push(frame, step, positions).map_err(|e| {
            metric_error = Some(e);
            ModelError::Input {
                what: "evaluation",
                reason: "a metric failed".into(),
            }
        })
    });
    if let Some(e) = metric_error {
        return Err(e);
    }
    let failed_step = match ran {
        Ok(()) => None,
        Err(ModelError::NonFinitePrediction { step, .. }) => Some(step),
        Err(e) => return Err(e.into()),
    };
    Ok(FullRollout {
        curves: metrics.curves,
        failed_step,
        final_centres: metrics.final_centres,
    })
}
