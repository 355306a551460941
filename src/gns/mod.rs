//! `phi model ...`, `phi rollout`, `phi train` and `phi eval`: model directories of Graph
//! Network-based Simulators, their rollouts on the trajectories of a dataset, their training and
//! their evaluation (thesis sections 5.3–5.4).
//!
//! - [`init`]: `phi model init`, a model directory (`model.json`, `model.safetensors`) with
//!   seeded random weights for a dataset;
//! - [`probe`]: `phi model probe`, one-step predictions for free fall and rest beside the
//!   floors;
//! - [`rollout`]: `phi rollout`, a model run forward from ground-truth frames, with the
//!   predictions, the truth, the per-frame position error and a GIF of both side by side;
//! - [`train`]: `phi train`, a model trained on a dataset with a preset of `configs/gns/`;
//! - [`eval`]: `phi eval`, models evaluated on a split with the thesis's metrics: tables,
//!   plots and a GIF of their rollouts side by side;
//! - [`inverse`]: `phi optimize --simulator gns`, the optimisation of initial positions through
//!   a trained model's rollout instead of FLIP.
//!
//! The files are those of [`phi_gns::model`] and [`phi_gns::data`]; `docs/gns.md` describes
//! them and the commands. No command overwrites files it did not write, and `model init`,
//! `rollout` and `eval` replace their own earlier output only with `--force`: each recognises
//! its outputs by a key of the JSON file it writes first ([`init::MODEL_OUTPUTS`],
//! [`rollout::ROLLOUT_OUTPUTS`], [`eval::EVAL_OUTPUTS`]; the rule is
//! [`crate::output::target`]'s).

pub mod average;
pub mod eval;
pub mod init;
pub mod inverse;
pub mod probe;
pub mod rollout;
pub mod train;

/// `--bounds`: the walls a model with boundary features measures against when the dataset's
/// domain is not the one it was trained on (domain generalisation, thesis fig. 5.9).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum BoundsFrom {
    /// The dataset's walls: the features see the domain as it is.
    Data,
    /// The training domain's walls, wherever the dataset's are.
    Model,
}

/// `--walls`: what a rollout does at the domain's walls ([`phi_gns::model::Walls`]), instead of
/// what the model's `model.json` says.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum WallsArg {
    /// Predicted positions are taken as they are, wherever they lie.
    Open,
    /// Predicted positions are clamped into the domain's closed box, as FLIP clamps its
    /// particles.
    Clamp,
}

impl From<WallsArg> for phi_gns::model::Walls {
    fn from(arg: WallsArg) -> Self {
        match arg {
            WallsArg::Open => phi_gns::model::Walls::Open,
            WallsArg::Clamp => phi_gns::model::Walls::Clamp,
        }
    }
}

/// `--obstacles`: what a rollout does with liquid predicted inside an obstacle
/// ([`phi_gns::model::Obstacles`]), instead of what the model's `model.json` says.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ObstaclesArg {
    /// Predicted positions are taken as they are.
    Open,
    /// Liquid predicted inside the cell of an obstacle particle is pushed out to the nearest
    /// free cell, as FLIP pushes its particles out of obstacles.
    Push,
}

impl ObstaclesArg {
    /// The rollout option for a dataset whose grid cells (and obstacle-particle spacing) are
    /// `cell_size` stored units wide.
    pub(crate) fn for_cells(self, cell_size: f64) -> phi_gns::model::Obstacles {
        match self {
            ObstaclesArg::Open => phi_gns::model::Obstacles::Open,
            ObstaclesArg::Push => phi_gns::model::Obstacles::Push { cell_size },
        }
    }
}

/// Checks that `metadata` (read from `path`) fits the model of `spec` and returns the bounds the
/// model should run with: `None` to keep its own. Without `choice`, a model with boundary
/// features refuses other bounds, with a hint at `--bounds`.
///
/// # Errors
/// A dataset of another dimension or other particle types; other bounds without `choice`.
pub(crate) fn bounds_for(
    spec: &phi_gns::model::ModelSpec,
    metadata: &phi_gns::data::Metadata,
    path: &std::path::Path,
    choice: Option<BoundsFrom>,
) -> anyhow::Result<Option<Vec<[f64; 2]>>> {
    use anyhow::Context;
    let Some(choice) = choice else {
        let other_bounds = spec.config.boundary_features && metadata.bounds != spec.bounds;
        spec.check_dataset(metadata, path).with_context(|| {
            if other_bounds {
                "the dataset's domain is not the model's; pass --bounds data (the features \
                 measure the dataset's walls) or --bounds model (the training domain's) to \
                 roll out on it anyway"
                    .to_string()
            } else {
                format!("the model does not fit {}", path.display())
            }
        })?;
        return Ok(None);
    };
    let mut same_domain = spec.clone();
    same_domain.bounds = metadata.bounds.clone();
    same_domain.check_dataset(metadata, path)?;
    Ok(match choice {
        BoundsFrom::Data if metadata.bounds != spec.bounds => Some(metadata.bounds.clone()),
        BoundsFrom::Data | BoundsFrom::Model => None,
    })
}
