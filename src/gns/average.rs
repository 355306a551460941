//! `phi model average`: a model directory whose weights are the mean of several models'
//! ([`average_models`]): checkpoint averaging over the end of a run.
//!
//! The output directory is handled as `phi model init`'s: written when it does not exist or is
//! empty, replaced with `--force` only when this command wrote it.

use std::path::PathBuf;

use anyhow::{Context, Result};
use phi_core::backend::Host;
use phi_gns::model::{Gns, MODEL_FILE, WEIGHTS_FILE, average_models, load_model, save_model};

use crate::output::target::{Marker, Outputs, check_dir};

/// The value of `provenance.made_by` in the `model.json` this command writes.
const MADE_BY: &str = "phi model average";

/// What `phi model average` writes: a model, recognised by its `model.json`'s
/// `provenance.made_by`.
const AVERAGE_OUTPUTS: Outputs = Outputs {
    command: "phi model average",
    flag: "--out",
    files: &[MODEL_FILE, WEIGHTS_FILE],
    subdirs: &[],
    marker: Some(Marker::json(MODEL_FILE, "provenance.made_by", MADE_BY)),
};

/// `phi model average --out DIR MODEL MODEL...`.
#[derive(Debug, Clone, clap::Args)]
pub struct AverageArgs {
    /// The model directories (model.json, model.safetensors) to average: two or more of one
    /// configuration and normalisation, such as checkpoints of one run.
    #[arg(required = true, num_args = 2..)]
    pub models: Vec<PathBuf>,
    /// The model directory to write: the first model's model.json, the mean weights.
    #[arg(long)]
    pub out: PathBuf,
    /// Replace a model that `phi model average` wrote in --out (anything else is refused even
    /// then).
    #[arg(long)]
    pub force: bool,
}

/// Writes the mean of `args.models` to `args.out`; returns its parameter count.
///
/// # Errors
/// A model that cannot be read (naming its file), models of different configurations or
/// normalisations (naming the key), an output directory this command did not write, one it
/// wrote without `--force`, I/O errors.
pub fn average(args: &AverageArgs) -> Result<usize> {
    let device = Default::default();
    let models = args
        .models
        .iter()
        .map(|dir| {
            load_model::<Host>(dir, &device)
                .with_context(|| format!("reading the model in '{}'", dir.display()))
        })
        .collect::<Result<Vec<_>>>()?;
    let refs: Vec<_> = models.iter().collect();
    let mean = average_models(&refs)?;
    let mut spec = mean.spec().clone();
    spec.provenance = serde_json::json!({
        "made_by": MADE_BY,
        "phi_version": env!("CARGO_PKG_VERSION"),
        "averaged": args.models.iter().map(|m| m.display().to_string()).collect::<Vec<_>>(),
        "first": models[0].spec().provenance,
    });
    let mean = Gns::new(spec, mean.params().clone())?;
    let previous = check_dir(&args.out, &AVERAGE_OUTPUTS, args.force)?;
    previous.remove()?;
    save_model(&args.out, &mean)?;
    Ok(mean.params().scalar_count())
}

/// Runs `phi model average` and prints what it wrote.
///
/// # Errors
/// As [`average`].
pub fn run(args: &AverageArgs) -> Result<()> {
    let parameters = average(args)?;
    println!(
        "wrote {}/{MODEL_FILE} and {WEIGHTS_FILE}: the mean of {} models' weights ({parameters} \
         parameters each)",
        args.out.display(),
        args.models.len()
    );
    Ok(())
}
