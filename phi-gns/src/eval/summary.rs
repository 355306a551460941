//! A model's evaluations over a split summed up: the row of table B.1 and the bands of fig. 5.7.

use serde::{Deserialize, Serialize};

use super::trajectory::{Plausibility, TrajectoryEvaluation, mse_acc1_in};

/// A model's metrics averaged over the evaluated trajectories. A rollout metric is `null`
/// (infinite) when any trajectory's rollout blew up; `blown_up` counts them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelSummary {
    /// Trajectories evaluated.
    pub trajectories: usize,
    /// Of which whose full rollout blew up.
    pub blown_up: usize,
    /// MSE-acc 1 in the normalisation of the `acc_std` given to [`ModelSummary::of`] (the
    /// evaluated dataset's: one unit for every model of a table).
    pub mse_acc1: f64,
    /// MSE-acc 1 in the model's own normalisation (widened by its training noise), the units of
    /// its training loss and screening.
    #[serde(default)]
    pub mse_acc1_own: f64,
    /// MSE 20 (stored units²).
    pub mse20: Option<f64>,
    /// MSE 400 (stored units²).
    pub mse400: Option<f64>,
    /// EMD (ground-cost units).
    pub emd: Option<f64>,
    /// Sinkhorn divergence (stored units²).
    pub sinkhorn: Option<f64>,
    /// Relative kinetic-energy error (a fraction).
    pub kinetic_energy_error: Option<f64>,
    /// Predicted over true mean neighbour count.
    pub density_ratio: Option<f64>,
    /// The mean over the trajectories of the [`Plausibility`] figures (`null` without a
    /// container or when a rollout blew up); `misplaced` is outside plus inside obstacles.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plausibility: Option<PlausibilitySummary>,
}

/// [`Plausibility`] over a model's trajectories.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlausibilitySummary {
    /// The mean fraction of the liquid's particle-frames outside the domain or inside an
    /// obstacle.
    pub misplaced: f64,
    /// The same fraction of the ground truth's (liquid in partly covered obstacle cells).
    pub misplaced_true: f64,
    /// The mean over the trajectories of the largest share of the liquid inside obstacle
    /// cells in one frame ([`Plausibility::peak_inside_obstacles`]).
    pub peak_inside_obstacles: f64,
    /// The same of the ground truth's.
    pub peak_inside_obstacles_true: f64,
    /// The mean final density ratio.
    pub final_density_ratio: f64,
    /// The mean late kinetic-energy ratio.
    pub late_kinetic_energy_ratio: f64,
    /// The mean final distance of the centres of mass, cells.
    pub final_centre_distance_cells: f64,
    /// The trajectories whose rollout passes [`Plausibility::is_plausible`].
    pub plausible: usize,
}

/// The mean of `values` when every one is present, `None` otherwise (or without values).
fn mean_of_all(values: impl Iterator<Item = Option<f64>>) -> Option<f64> {
    let mut sum = 0.0;
    let mut count = 0usize;
    for v in values {
        sum += v?;
        count += 1;
    }
    (count > 0).then(|| sum / count as f64)
}

impl ModelSummary {
    /// The summary of `evaluations` (at least one), MSE-acc 1 in the normalisation of
    /// `acc_std` (per dimension; an evaluation without `acc_error` counts its own
    /// normalisation's value).
    pub fn of(evaluations: &[TrajectoryEvaluation], acc_std: &[f64]) -> Self {
        let n = evaluations.len();
        let of =
            |f: fn(&TrajectoryEvaluation) -> Option<f64>| mean_of_all(evaluations.iter().map(f));
        ModelSummary {
            trajectories: n,
            blown_up: evaluations
                .iter()
                .filter(|e| e.failed_step.is_some())
                .count(),
            mse_acc1: evaluations
                .iter()
                .map(|e| {
                    if e.acc_error.is_empty() {
                        e.mse_acc1
                    } else {
                        mse_acc1_in(&e.acc_error, acc_std)
                    }
                })
                .sum::<f64>()
                / n.max(1) as f64,
            mse_acc1_own: evaluations.iter().map(|e| e.mse_acc1).sum::<f64>() / n.max(1) as f64,
            mse20: of(|e| e.mse20),
            mse400: of(|e| e.mse400),
            emd: of(|e| e.emd),
            sinkhorn: of(|e| e.sinkhorn),
            kinetic_energy_error: of(|e| e.kinetic_energy_error),
            density_ratio: of(|e| e.density_ratio),
            plausibility: PlausibilitySummary::of(evaluations),
        }
    }
}

impl PlausibilitySummary {
    /// The summary when every evaluation has its plausibility figures.
    fn of(evaluations: &[TrajectoryEvaluation]) -> Option<Self> {
        let all: Option<Vec<&Plausibility>> = evaluations
            .iter()
            .map(|e| e.plausibility.as_ref())
            .collect();
        let all = all.filter(|a| !a.is_empty())?;
        let mean =
            |f: fn(&Plausibility) -> f64| all.iter().map(|p| f(p)).sum::<f64>() / all.len() as f64;
        Some(PlausibilitySummary {
            misplaced: mean(|p| p.outside + p.inside_obstacles),
            misplaced_true: mean(|p| p.inside_obstacles_true),
            peak_inside_obstacles: mean(|p| p.peak_inside_obstacles),
            peak_inside_obstacles_true: mean(|p| p.peak_inside_obstacles_true),
            final_density_ratio: mean(|p| p.final_density_ratio),
            late_kinetic_energy_ratio: mean(|p| p.late_kinetic_energy_ratio),
            final_centre_distance_cells: mean(|p| p.final_centre_distance_cells),
            plausible: all.iter().filter(|p| p.is_plausible()).count(),
        })
    }
}

/// A per-frame curve over the trajectories: at each frame the mean, minimum and maximum over
/// the trajectories that reached it (fig. 5.7's line and shaded range).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Band {
    /// The dataset frame.
    pub frame: Vec<usize>,
    /// The mean over the trajectories.
    pub mean: Vec<f64>,
    /// The minimum.
    pub min: Vec<f64>,
    /// The maximum.
    pub max: Vec<f64>,
    /// How many trajectories reached the frame (fewer where a rollout blew up earlier).
    pub count: Vec<usize>,
}

impl Band {
    /// The band of the curve `curve(e)` (aligned with `e.curves.frame`) over `evaluations`.
    pub fn of(
        evaluations: &[TrajectoryEvaluation],
        curve: fn(&TrajectoryEvaluation) -> &[f64],
    ) -> Self {
        let longest = evaluations
            .iter()
            .max_by_key(|e| e.curves.frame.len())
            .map(|e| e.curves.frame.clone())
            .unwrap_or_default();
        let mut band = Band::default();
        for (i, &frame) in longest.iter().enumerate() {
            let values: Vec<f64> = evaluations
                .iter()
                .filter_map(|e| curve(e).get(i).copied())
                .collect();
            band.frame.push(frame);
            band.mean
                .push(values.iter().sum::<f64>() / values.len() as f64);
            band.min
                .push(values.iter().copied().fold(f64::INFINITY, f64::min));
            band.max
                .push(values.iter().copied().fold(f64::NEG_INFINITY, f64::max));
            band.count.push(values.len());
        }
        band
    }
}
