//! `phi model probe`: the one-step predictions of models for a block of liquid in free fall and
//! a pool at rest ([`phi_gns::eval::probe`]), the cheapest check that training has learnt
//! gravity and rest before any rollout is looked at.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use phi_core::backend::Host;
use phi_gns::data::read_metadata;
use phi_gns::eval::{ProbeResult, probe, probe_scene};
use phi_gns::model::Floor;

use super::eval::resolve_model;

/// `phi model probe --data DATASET --model [NAME=]DIR ... [options]`.
#[derive(Debug, Clone, clap::Args)]
pub struct ProbeArgs {
    /// The dataset the models were trained on: its metadata gives the stored units (position
    /// scale and offset, dt, bounds).
    #[arg(long)]
    pub data: PathBuf,
    /// A model directory or a `phi train` directory (its best/ model), optionally named
    /// `NAME=DIR`; repeat for several models.
    #[arg(long = "model", required = true, value_name = "[NAME=]DIR")]
    pub models: Vec<String>,
    /// Gravity in cells per second², one value per component (the random scenes': 0,-9.81).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true, default_values_t = [0.0, -9.81])]
    pub gravity: Vec<f64>,
    /// Throw the block sideways at this many cells per second (along the first axis across
    /// gravity; negative: the other way): its sideways acceleration, truth 0, is printed as
    /// "along throw" (negative: drag). A test scene's block thrown at 0.25 cells a frame with
    /// dt = 0.05 s is 5 cells/s.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub throw: f64,
    /// Particles per cell (the random scenes': 8).
    #[arg(long, default_value_t = 8)]
    pub particles_per_cell: usize,
    /// Frames the block has fallen from rest before the model's input window starts.
    #[arg(long, default_value_t = 4)]
    pub fallen: usize,
    /// Probe scenes of different jitter, averaged.
    #[arg(long, default_value_t = 4)]
    pub seeds: u64,
    /// Also write the results as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// One model's probe, averaged over the seeds.
#[derive(Debug, Clone, serde::Serialize)]
pub(crate) struct ProbeRow {
    /// The model's name.
    pub label: String,
    /// The model directory, or the floor's pseudo-path.
    pub dir: String,
    /// The mean over the seeds.
    pub result: ProbeResult,
}

/// Probes every model of `args`, and the two floors for reference.
///
/// # Errors
/// Unreadable models or dataset; a model that does not fit the dataset; a scene that does not
/// fit the domain.
pub(crate) fn probe_models(args: &ProbeArgs) -> Result<Vec<ProbeRow>> {
    if args.seeds == 0 {
        bail!("--seeds 0: at least one probe scene is needed");
    }
    if args.particles_per_cell == 0 {
        bail!("--particles-per-cell 0: the scene would be empty");
    }
    let metadata = read_metadata(&args.data)?;
    let device = Default::default();
    let mut rows = Vec::new();
    let mut c = None;
    for arg in &args.models {
        let entry = resolve_model(arg)?;
        entry
            .spec
            .check_dataset(&metadata, &args.data.join(phi_gns::data::METADATA_FILE))
            .with_context(|| format!("--model {arg} does not fit {}", args.data.display()))?;
        let own = entry.spec.config.input_velocities;
        c.get_or_insert(own);
        let model = entry.load::<Host>(&device)?;
        rows.push(ProbeRow {
            label: entry.label.clone(),
            dir: entry.dir.display().to_string(),
            result: mean_probe(args, &metadata, own, |scene| {
                Ok(probe(&model, scene, &device)?)
            })?,
        });
    }
    let c = c.expect("at least one --model");
    for floor in Floor::ALL {
        let model = floor.model::<Host>(&metadata, c, &device)?;
        rows.push(ProbeRow {
            label: floor.name().to_string(),
            dir: format!("floor:{}", floor.name()),
            result: mean_probe(args, &metadata, c, |scene| {
                Ok(probe(&model, scene, &device)?)
            })?,
        });
    }
    Ok(rows)
}

/// The probe of `run` averaged over `args.seeds` scenes for models of `input_velocities`.
fn mean_probe(
    args: &ProbeArgs,
    metadata: &phi_gns::data::Metadata,
    input_velocities: usize,
    mut run: impl FnMut(&phi_gns::eval::ProbeScene) -> Result<ProbeResult>,
) -> Result<ProbeResult> {
    let mut results = Vec::new();
    for seed in 0..args.seeds {
        let scene = probe_scene(
            metadata,
            input_velocities,
            &args.gravity,
            args.throw,
            args.particles_per_cell,
            args.fallen,
            seed,
        )
        .with_context(|| {
            format!(
                "--gravity {:?}, --throw {}, --fallen {}",
                args.gravity, args.throw, args.fallen
            )
        })?;
        results.push(run(&scene)?);
    }
    Ok(ProbeResult::mean(&results))
}

/// Probes the models of `args`, prints a table (fractions of |g|) and writes the JSON.
///
/// # Errors
/// As [`probe_models`]; an unwritable JSON file.
pub fn run(args: &ProbeArgs) -> Result<()> {
    let rows = probe_models(args)?;
    let width = rows.iter().map(|r| r.label.len()).max().unwrap_or(5).max(5);
    let thrown = args.throw != 0.0;
    println!(
        "one-step predictions as fractions of |g| (truth: falling 1 along, 0 across{}; resting 0)",
        if thrown { ", 0 along throw" } else { "" }
    );
    let throw_header = if thrown {
        format!("  {:>13}", "along throw")
    } else {
        String::new()
    };
    println!(
        "{:width$}  {:>15}  {:>16}{throw_header}  {:>12}  {:>11}",
        "model", "falling, along", "falling, across", "resting mean", "resting rms"
    );
    for row in &rows {
        let r = &row.result;
        let g = r.gravity.iter().map(|x| x * x).sum::<f64>().sqrt();
        let throw_column = if thrown {
            format!("  {:>13.3}", r.falling_along_throw)
        } else {
            String::new()
        };
        println!(
            "{:width$}  {:>15.3}  {:>16.3}{throw_column}  {:>12.3}  {:>11.3}",
            row.label,
            r.falling_along_gravity,
            r.falling_across_gravity,
            r.resting_over_gravity,
            r.resting_rms / g
        );
    }
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&rows)? + "\n";
        crate::output::write_atomic(path, |w| {
            std::io::Write::write_all(w, text.as_bytes())
                .map_err(|e| crate::output::OutputError::io(path, "cannot write", e))
        })?;
        println!("wrote {}", path.display());
    }
    Ok(())
}
