//! `phi dataset compare`: two datasets of the same scenes, one read as a rollout of the other.
//!
//! How far apart are two FLIP runs of one scene, sampled with another jitter seed or simulated
//! with another scheme? Each trajectory of `--other` is measured against the one of `--data`
//! with the metrics `phi eval` gives a model's rollout ([`compare_trajectories`]), so a model's
//! table can be read against the spread of the simulator that made its data.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args;
use phi_gns::data::{Dataset, OBSTACLE};
use phi_gns::eval::metrics::Container;
use phi_gns::eval::{EvalOptions, TrajectoryComparison, compare_trajectories};
use rayon::prelude::*;

/// `phi dataset compare`.
#[derive(Debug, Args)]
pub struct CompareArgs {
    /// The dataset read as the truth.
    #[arg(long)]
    pub data: PathBuf,
    /// The dataset compared with it: the same scenes simulated otherwise (another jitter seed,
    /// scheme or resolution of the solver), e.g. `phi dataset generate --split test --scenes
    /// DIR` of the test scenes with other seeds.
    #[arg(long)]
    pub other: PathBuf,
    /// The split to compare.
    #[arg(long, default_value = "test", value_parser = crate::cli::parse_split)]
    pub split: String,
    /// Compare the frames after this one, as `phi eval` compares a model's rollout from its
    /// first input window (`C` = 5 in the thesis: MSE 400 over frames 6–400).
    #[arg(long, default_value_t = 5)]
    pub start: usize,
    /// Compare the first this many trajectories [default: all of the split].
    #[arg(long)]
    pub trajectories: Option<usize>,
    /// The radius of the density's neighbour counts, stored units [default: the dataset's
    /// connectivity radius, as `phi eval`].
    #[arg(long)]
    pub density_radius: Option<f64>,
}

/// Compares the datasets and prints a table, a row a trajectory and their mean.
///
/// # Errors
/// Datasets that cannot be read, of other dimensions or bounds, of other particle counts or
/// types in a trajectory (not the same scenes), a split too short.
pub fn run(args: CompareArgs) -> Result<()> {
    let data =
        Dataset::open(&args.data).with_context(|| format!("--data {}", args.data.display()))?;
    let other =
        Dataset::open(&args.other).with_context(|| format!("--other {}", args.other.display()))?;
    let (m, o) = (data.metadata(), other.metadata());
    if m.dim != o.dim || m.bounds != o.bounds || m.position_scale != o.position_scale {
        bail!(
            "--other {}: its metadata.json has dim {}, bounds {:?} and position_scale {}, {} has \
             {}, {:?} and {}: not the same domain",
            args.other.display(),
            o.dim,
            o.bounds,
            o.position_scale,
            args.data.display(),
            m.dim,
            m.bounds,
            m.position_scale
        );
    }
    let n = crate::cli::split_len(&data, &args.data, &args.split)?;
    let n_other = crate::cli::split_len(&other, &args.other, &args.split)?;
    let count = args.trajectories.unwrap_or(n.min(n_other));
    if count == 0 || count > n.min(n_other) {
        bail!(
            "--trajectories {count}: the split {} holds {n} trajectories in {} and {n_other} in {}",
            args.split,
            args.data.display(),
            args.other.display()
        );
    }
    let radius = args.density_radius.unwrap_or(m.default_connectivity_radius);
    if !(radius.is_finite() && radius > 0.0) {
        bail!("--density-radius {radius}: must be positive and finite");
    }
    let mut options = EvalOptions::new(radius);
    options.sinkhorn_every = 0;
    options.container = Some(Container {
        bounds: m.bounds.clone(),
        cell_size: m.position_scale,
    });
    let mut truths = data
        .split(&args.split)
        .with_context(|| format!("--data {}", args.data.display()))?
        .take(count);
    let mut others = other
        .split(&args.split)
        .with_context(|| format!("--other {}", args.other.display()))?
        .take(count);
    // A few pairs in memory at a time, compared in parallel.
    let chunk = 2 * rayon::current_num_threads();
    let mut rows: Vec<TrajectoryComparison> = Vec::with_capacity(count);
    loop {
        let mut pairs = Vec::with_capacity(chunk);
        for (truth, compared) in truths.by_ref().zip(others.by_ref()).take(chunk) {
            let truth = truth.with_context(|| format!("--data {}", args.data.display()))?;
            let compared = compared.with_context(|| format!("--other {}", args.other.display()))?;
            pairs.push((truth, compared));
        }
        if pairs.is_empty() {
            break;
        }
        let compared: Vec<TrajectoryComparison> = pairs
            .par_iter()
            .map(|(truth, compared)| {
                compare_trajectories(compared, truth, args.start, &[OBSTACLE], &options)
                    .with_context(|| format!("--other {}", args.other.display()))
            })
            .collect::<Result<_>>()?;
        rows.extend(compared);
    }
    print!("{}", table(&rows));
    Ok(())
}

/// The markdown table of the comparisons: EMD and MSE 400 in 10⁻², the plausibility figures.
fn table(rows: &[TrajectoryComparison]) -> String {
    let mut out = String::from(
        "| trajectory | EMD (10⁻²) | MSE 400 (10⁻²) | outside | in obstacles (truth's) | final \
         density | late KE | centre (cells) | plausible |\n|---|---:|---:|---:|---:|---:|---:|---:|---|\n",
    );
    let percent = |x: f64| format!("{:.1} %", 100.0 * x);
    for row in rows {
        let Some(p) = &row.plausibility else { continue };
        out += &format!(
            "| {} | {:.3} | {:.3} | {} | {} ({}) | {:.2} | {:.2} | {:.1} | {} |\n",
            row.index,
            1e2 * row.emd,
            1e2 * row.mse400,
            percent(p.outside),
            percent(p.inside_obstacles),
            percent(p.inside_obstacles_true),
            p.final_density_ratio,
            p.late_kinetic_energy_ratio,
            p.final_centre_distance_cells,
            if p.is_plausible() { "yes" } else { "no" }
        );
    }
    let mean = |f: &dyn Fn(&TrajectoryComparison) -> f64| {
        rows.iter().map(f).sum::<f64>() / rows.len() as f64
    };
    let plausible = rows
        .iter()
        .filter(|r| r.plausibility.as_ref().is_some_and(|p| p.is_plausible()))
        .count();
    let p = |f: fn(&phi_gns::eval::Plausibility) -> f64| {
        move |r: &TrajectoryComparison| r.plausibility.as_ref().map_or(f64::NAN, f)
    };
    out += &format!(
        "| mean | {:.3} | {:.3} | {} | {} ({}) | {:.2} | {:.2} | {:.1} | {plausible} of {} |\n",
        1e2 * mean(&|r| r.emd),
        1e2 * mean(&|r| r.mse400),
        percent(mean(&p(|p| p.outside))),
        percent(mean(&p(|p| p.inside_obstacles))),
        percent(mean(&p(|p| p.inside_obstacles_true))),
        mean(&p(|p| p.final_density_ratio)),
        mean(&p(|p| p.late_kinetic_energy_ratio)),
        mean(&p(|p| p.final_centre_distance_cells)),
        rows.len()
    );
    out
}
