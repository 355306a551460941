//! `phi model init`: a model directory with seeded random weights for a dataset.
//!
//! The dimension, bounds, velocity and acceleration statistics and particle types come from the
//! dataset's `metadata.json`; the sizes default to the thesis' ([`GnsConfig::thesis`]), the
//! connectivity radius to the dataset's `default_connectivity_radius`, and boundary features
//! are off for a dataset whose walls are particles (variant `walls_as_particles`). The same
//! options and seed give the same bytes.
//!
//! The directory is written when it does not exist or is empty. One that holds nothing but a
//! `model.json` and `model.safetensors` that this command wrote (its `model.json` says
//! `"provenance": {"made_by": "phi model init", ...}`) is replaced only with `--force`; anything
//! else (other files, a trained model, weights without a `model.json`) is refused even then
//! ([`MODEL_OUTPUTS`]).

use std::path::PathBuf;

use anyhow::{Result, bail};
use phi_core::backend::Host;
use phi_gns::data::{METADATA_FILE, Metadata, read_metadata};
use phi_gns::model::{
    ConfigOverrides, Gns, GnsConfig, MODEL_FILE, ModelError, ModelSpec, WEIGHTS_FILE, save_model,
};

use crate::output::target::{Marker, Outputs, check_dir};

/// The value of `provenance.made_by` in the `model.json` this command writes.
pub(crate) const MADE_BY: &str = "phi model init";

/// What `phi model init` writes: a model, recognised by the `provenance.made_by` of its
/// `model.json`.
pub(crate) const MODEL_OUTPUTS: Outputs = Outputs {
    command: "phi model init",
    flag: "--out",
    files: &[MODEL_FILE, WEIGHTS_FILE],
    subdirs: &[],
    marker: Some(Marker::json(MODEL_FILE, "provenance.made_by", MADE_BY)),
};

/// `phi model <command>`.
#[derive(Debug, clap::Subcommand)]
pub enum ModelCommand {
    /// Write a model directory (model.json, model.safetensors) with seeded random weights for
    /// a dataset; sizes default to the thesis' GNS.
    Init(InitArgs),
    /// One-step predictions for a block of liquid in free fall and a pool at rest, as
    /// fractions of gravity, beside the floors: has training learnt gravity and rest?
    Probe(super::probe::ProbeArgs),
    /// Write a model directory whose weights are the mean of several models' of one
    /// configuration (checkpoint averaging over the end of a run).
    Average(super::average::AverageArgs),
}

/// `phi model init --data DATASET --out DIR [options]`.
#[derive(Debug, Clone, clap::Args)]
pub struct InitArgs {
    /// The dataset: its metadata.json gives the dimension, bounds, statistics and particle
    /// types.
    #[arg(long)]
    pub data: PathBuf,
    /// The model directory to write.
    #[arg(long)]
    pub out: PathBuf,
    /// Replace a model that `phi model init` wrote in --out (anything else is refused even
    /// then).
    #[arg(long)]
    pub force: bool,
    /// The seed of the initial weights.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Width of the node and edge latents [default: 128].
    #[arg(long)]
    pub latent: Option<usize>,
    /// Width of the hidden layers of every MLP [default: 128].
    #[arg(long)]
    pub hidden: Option<usize>,
    /// Hidden layers per MLP [default: 2].
    #[arg(long)]
    pub hidden_layers: Option<usize>,
    /// Unshared interaction-network steps M [default: 10].
    #[arg(long)]
    pub message_passing_steps: Option<usize>,
    /// Past velocities C in the node features [default: 5].
    #[arg(long)]
    pub input_velocities: Option<usize>,
    /// Width of the particle-type embedding [default: 16].
    #[arg(long)]
    pub embedding: Option<usize>,
    /// Connectivity radius R in stored units [default: the dataset's
    /// default_connectivity_radius].
    #[arg(long)]
    pub radius: Option<f64>,
    /// No distances to the domain bounds in the node features (the default for a dataset whose
    /// walls are particles).
    #[arg(long, conflicts_with = "boundary_features")]
    pub no_boundary_features: bool,
    /// Distances to the domain bounds in the node features even for a dataset whose walls are
    /// particles.
    #[arg(long)]
    pub boundary_features: bool,
    /// Distance to a wall, in multiples of R, at which the boundary features saturate
    /// [default: 1].
    #[arg(long)]
    pub boundary_horizon: Option<f64>,
    /// Standard deviation σ of the training noise; it widens the normalisation [default: 0].
    #[arg(long)]
    pub noise_std: Option<f64>,
}

/// What `phi model init` wrote.
#[derive(Debug, Clone)]
pub struct InitSummary {
    /// The model's `model.json`.
    pub spec: ModelSpec,
    /// Scalar parameters.
    pub parameters: usize,
    /// Parameter tensors.
    pub tensors: usize,
}

/// The configuration the options ask for, on top of the thesis' sizes and the dataset's facts.
pub(crate) fn config_for(args: &InitArgs, metadata: &Metadata) -> GnsConfig {
    let boundary_features = if args.boundary_features {
        Some(true)
    } else if args.no_boundary_features {
        Some(false)
    } else {
        None
    };
    let overrides = ConfigOverrides {
        latent_size: args.latent,
        hidden_size: args.hidden,
        hidden_layers: args.hidden_layers,
        message_passing_steps: args.message_passing_steps,
        input_velocities: args.input_velocities,
        embedding_size: args.embedding,
        connectivity_radius: args.radius,
        boundary_features,
        boundary_horizon: args.boundary_horizon,
        noise_std: args.noise_std,
    };
    GnsConfig::for_dataset(metadata, &overrides)
}

/// The option of `phi model init` behind a `model.json` key.
fn option_of(key: &str) -> Option<&'static str> {
    Some(match key {
        "config.latent_size" => "--latent",
        "config.hidden_size" => "--hidden",
        "config.hidden_layers" => "--hidden-layers",
        "config.message_passing_steps" => "--message-passing-steps",
        "config.input_velocities" => "--input-velocities",
        "config.embedding_size" => "--embedding",
        "config.connectivity_radius" => "--radius",
        "config.noise_std" => "--noise-std",
        "config.boundary_horizon" => "--boundary-horizon",
        _ => return None,
    })
}

/// Writes the model directory of `args` and returns what it holds.
///
/// # Errors
/// An unreadable dataset, options that do not make a valid model (naming the option), a
/// dataset without usable statistics (naming its metadata key), an output directory this
/// command did not write, one it wrote without `--force`, I/O errors.
pub fn init(args: &InitArgs) -> Result<InitSummary> {
    let metadata = read_metadata(&args.data)?;
    let config = config_for(args, &metadata);
    let mut spec = ModelSpec::for_dataset(&metadata, config, args.seed);
    spec.provenance = serde_json::json!({
        "made_by": MADE_BY,
        "phi_version": env!("CARGO_PKG_VERSION"),
        "dataset": args.data.display().to_string(),
    });
    let metadata_path = args.data.join(METADATA_FILE);
    if let Err(e) = spec.validate(&args.out.join(MODEL_FILE)) {
        match &e {
            ModelError::Config { key, reason, .. } => {
                if let Some(option) = option_of(key) {
                    bail!("{option}: {reason} (model.json key '{key}')");
                }
                if let Some(stat) = key.strip_prefix("normalisation.") {
                    bail!(
                        "'{}': key '{stat}': {reason}; pass --noise-std σ > 0 to widen the \
                         normalisation",
                        metadata_path.display()
                    );
                }
                if key == "bounds" || key == "particle_types" {
                    bail!("'{}': key '{key}': {reason}", metadata_path.display());
                }
                return Err(e.into());
            }
            _ => return Err(e.into()),
        }
    }
    let previous = check_dir(&args.out, &MODEL_OUTPUTS, args.force)?;
    let model = Gns::<Host>::init(spec, &Default::default())?;
    previous.remove()?;
    save_model(&args.out, &model)?;
    Ok(InitSummary {
        spec: model.spec().clone(),
        parameters: model.params().scalar_count(),
        tensors: model.params().len(),
    })
}

/// Runs `phi model <command>` and prints what it wrote.
///
/// # Errors
/// As [`init`].
pub fn run(command: ModelCommand) -> Result<()> {
    match command {
        ModelCommand::Probe(args) => super::probe::run(&args),
        ModelCommand::Average(args) => super::average::run(&args),
        ModelCommand::Init(args) => {
            let summary = init(&args)?;
            let c = &summary.spec.config;
            println!(
                "{}: {}D, bounds {:?}, particle types {:?}",
                args.data.display(),
                c.dim,
                summary.spec.bounds,
                summary.spec.particle_types
            );
            println!(
                "model: {} parameters in {} tensors (latent {}, hidden {} × {} layers, {} \
                 message-passing steps, C = {}, R = {}, embedding {}, boundary features {}, \
                 noise σ = {}, seed {})",
                summary.parameters,
                summary.tensors,
                c.latent_size,
                c.hidden_size,
                c.hidden_layers,
                c.message_passing_steps,
                c.input_velocities,
                c.connectivity_radius,
                if c.uses_embedding() {
                    c.embedding_size.to_string()
                } else {
                    "none".to_string()
                },
                if !c.boundary_features {
                    "off".to_string()
                } else if c.boundary_horizon == 1.0 {
                    "on".to_string()
                } else {
                    format!("on to {} R", c.boundary_horizon)
                },
                c.noise_std,
                summary.spec.seed
            );
            println!(
                "wrote {}/{MODEL_FILE} and {WEIGHTS_FILE}",
                args.out.display()
            );
            Ok(())
        }
    }
}
