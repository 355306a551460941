//! The command-line form of `phi dataset ...` and `phi render` (parsed by clap in `main.rs`).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::{Args, Subcommand};
use phi_gns::data::METADATA_FILE;

use super::export::{EXPORT_OUTPUTS, ExportFormat, ExportOptions, export};
use super::generate::{GenerateArgs, trajectories};
use super::merge;
use super::render::render_trajectory;
use super::stats::{StatsOptions, dataset_stats, format_report};
use crate::output::target::{Marker, OutputSubdir, Outputs, check_dir};

/// `phi dataset <command>`.
#[derive(Debug, Subcommand)]
pub enum DatasetCommand {
    /// Simulate the trajectories of a dataset (thesis section 5.2, table 5.1).
    Generate(GenerateArgs),
    /// Join shard directories into one dataset and write its metadata.json.
    Merge {
        /// The dataset directory to write.
        #[arg(long)]
        out: Option<PathBuf>,
        /// The shard directories (`phi dataset generate --shard k/n`). Without --out, the first
        /// is the dataset to write (`merge OUT SHARDS...`, deprecated: pass --out).
        #[arg(required = true, value_name = "SHARDS")]
        shards: Vec<PathBuf>,
        /// Replace a dataset in --out (a folder holding anything else is refused even then).
        #[arg(long)]
        force: bool,
    },
    /// Measure the trajectories of another dataset of the same scenes (another jitter seed,
    /// scheme or solver) against this one's, with the metrics of `phi eval`: how far apart two
    /// simulations of one scene are.
    Compare(super::compare::CompareArgs),
    /// Particle counts and the neighbour-count distribution over time (thesis fig. 5.4).
    Stats {
        /// The dataset directory (a positional DATA, the form before --data, is deprecated).
        #[arg(long, required_unless_present = "data_positional")]
        data: Option<PathBuf>,
        /// Deprecated: the dataset directory; pass --data.
        #[arg(hide = true, value_name = "DATA")]
        data_positional: Option<PathBuf>,
        /// The split: train, valid, test, or another its metadata.json lists [default: train
        /// if present, else the first listed].
        #[arg(long, value_name = "SPLIT", value_parser = crate::cli::parse_split)]
        split: Option<String>,
        /// Connectivity radius in stored units.
        #[arg(long, default_value_t = 0.03)]
        radius: f32,
        /// Measure the first this many trajectories (--limit before, deprecated).
        #[arg(long, alias = "limit", default_value_t = 50)]
        trajectories: usize,
        /// Draw the distribution over time into this PNG, and as a heat map into
        /// {stem}_heatmap.png beside it.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Replace existing PNGs --out and its heat map (any other file is refused even then).
        #[arg(long)]
        force: bool,
        /// Print every this many frames.
        #[arg(long, default_value_t = 25)]
        print_every: usize,
    },
    /// Write a dataset in another format: `npz` (one archive per split, for numpy),
    /// `tfrecord` (DeepMind learning_to_simulate), `gns` (geoelements/gns) or `lagrangebench`
    /// (LagrangeBench's HDF5, written through Python's h5py). docs/datasets.md describes each.
    Export {
        /// The dataset directory (a positional DATA, the form before --data, is deprecated).
        #[arg(long, required_unless_present = "data_positional")]
        data: Option<PathBuf>,
        /// Deprecated: the dataset directory; pass --data.
        #[arg(hide = true, value_name = "DATA")]
        data_positional: Option<PathBuf>,
        /// The format to write.
        #[arg(long)]
        format: ExportFormat,
        /// The directory to write into: absent or empty, or an earlier export (its export.json)
        /// with --force.
        #[arg(long)]
        out: PathBuf,
        /// Replace an earlier export in --out, once the new one is complete (anything else is
        /// refused even then).
        #[arg(long)]
        force: bool,
        /// The Python interpreter, with numpy and h5py, for `--format lagrangebench`.
        #[arg(long, default_value = "python3")]
        python: PathBuf,
    },
    /// Read DeepMind learning_to_simulate's TFRecord files (`{split}.tfrecord` and
    /// metadata.json) into a phi dataset directory.
    Import {
        /// The directory holding the TFRecord files and metadata.json (a positional DATA, the
        /// form before --data, is deprecated).
        #[arg(long, required_unless_present = "data_positional")]
        data: Option<PathBuf>,
        /// Deprecated: the TFRecord directory; pass --data.
        #[arg(hide = true, value_name = "DATA")]
        data_positional: Option<PathBuf>,
        /// The dataset directory to write: absent or empty, or an earlier import (its
        /// import.json) with --force.
        #[arg(long)]
        out: PathBuf,
        /// Replace an earlier import in --out, once the new one is complete (anything else is
        /// refused even then).
        #[arg(long)]
        force: bool,
    },
}

/// `phi render`.
#[derive(Debug, Args)]
pub struct RenderArgs {
    /// The dataset directory (a positional DATA, the form before --data, is deprecated).
    #[arg(long, required_unless_present = "data_positional")]
    pub data: Option<PathBuf>,
    /// Deprecated: the dataset directory; pass --data.
    #[arg(hide = true, value_name = "DATA")]
    pub data_positional: Option<PathBuf>,
    /// The split: train, valid, test, or another its metadata.json lists.
    #[arg(long, default_value = "test", value_name = "SPLIT", value_parser = crate::cli::parse_split)]
    pub split: String,
    /// The trajectory's index in the split (--index before, deprecated).
    #[arg(long, alias = "index", value_name = "I", default_value_t = 0)]
    pub trajectory: usize,
    /// The GIF to write.
    #[arg(long)]
    pub out: PathBuf,
    /// Pixels per grid cell.
    #[arg(long, default_value_t = 8)]
    pub pixels_per_cell: u32,
    /// Draw every this many frames of the trajectory. The default, 2, keeps the GIF of a
    /// 400-frame trajectory to 200 pictures (a few MB); 1 draws every frame.
    #[arg(long, default_value_t = 2)]
    pub frame_every: usize,
    /// Replace an existing GIF --out (any other file is refused even then).
    #[arg(long)]
    pub force: bool,
}

/// Runs a `phi dataset` command.
///
/// # Errors
/// Whatever the command reports.
pub fn run(command: DatasetCommand) -> Result<()> {
    match command {
        DatasetCommand::Generate(args) => super::generate::run(args),
        DatasetCommand::Merge { out, shards, force } => run_merge(out, shards, force),
        DatasetCommand::Compare(args) => super::compare::run(args),
        DatasetCommand::Stats {
            data,
            data_positional,
            split,
            radius,
            trajectories,
            out,
            force,
            print_every,
        } => run_stats(
            data,
            data_positional,
            split,
            radius,
            trajectories,
            out,
            force,
            print_every,
        ),
        DatasetCommand::Export {
            data,
            data_positional,
            format,
            out,
            force,
            python,
        } => run_export(data, data_positional, format, out, force, python),
        DatasetCommand::Import {
            data,
            data_positional,
            out,
            force,
        } => run_import(data, data_positional, out, force),
    }
}

/// `phi dataset merge`: joins the shards and prints the counts.
fn run_merge(out: Option<PathBuf>, shards: Vec<PathBuf>, force: bool) -> Result<()> {
    let (out, shards) = merge_paths(out, shards)?;
    let summary = merge(&out, &shards, force)?;
    println!(
        "merged {} shard(s) into {}: {}",
        shards.len(),
        out.display(),
        summary
            .counts
            .iter()
            .map(|(s, n)| format!("{s} {n}"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    Ok(())
}

/// `phi dataset stats`: measures the dataset, prints the report, draws the figures.
#[allow(clippy::too_many_arguments)]
fn run_stats(
    data: Option<PathBuf>,
    data_positional: Option<PathBuf>,
    split: Option<String>,
    radius: f32,
    trajectories: usize,
    out: Option<PathBuf>,
    force: bool,
    print_every: usize,
) -> Result<()> {
    let dir = crate::cli::dataset_dir("phi dataset stats", data, data_positional)?;
    let report = dataset_stats(&StatsOptions {
        dir: dir.clone(),
        split,
        radius,
        limit: trajectories,
        out: out.clone(),
        force,
        progress: std::io::IsTerminal::is_terminal(&std::io::stderr()),
    })?;
    print!("{}", format_report(&report, &dir, radius, print_every));
    if let Some(out) = out {
        println!(
            "wrote {} and {}",
            out.display(),
            super::stats::heatmap_path(&out).display()
        );
    }
    Ok(())
}

/// `phi dataset export`: writes the dataset in another format, published whole.
fn run_export(
    data: Option<PathBuf>,
    data_positional: Option<PathBuf>,
    format: ExportFormat,
    out: PathBuf,
    force: bool,
    python: PathBuf,
) -> Result<()> {
    let dir = crate::cli::dataset_dir("phi dataset export", data, data_positional)?;
    if let (Ok(data), Ok(target)) = (dir.canonicalize(), out.canonicalize())
        && data.starts_with(&target)
    {
        anyhow::bail!(
            "--out {} holds the dataset being exported; choose another directory",
            out.display()
        );
    }
    let staging = prepare_output(&out, &EXPORT_OUTPUTS, force)?;
    let written = export(&ExportOptions {
        dir,
        format,
        out: staging.clone(),
        python,
        progress: std::io::IsTerminal::is_terminal(&std::io::stderr()),
    })
    .and_then(|counts| {
        phi_io::publish_dir(&staging, &out)?;
        Ok(counts)
    });
    let counts = discard_on_error(written, &staging)?;
    for (split, count) in counts {
        let file = match format {
            ExportFormat::Npz | ExportFormat::Gns => format!("{split}.npz"),
            ExportFormat::Tfrecord => format!("{split}.tfrecord"),
            ExportFormat::Lagrangebench => format!("{split}.h5"),
        };
        println!(
            "{split}: {} -> {}",
            trajectories(count),
            out.join(file).display()
        );
    }
    if format != ExportFormat::Npz {
        println!("wrote {}", out.join("metadata.json").display());
    }
    Ok(())
}

/// `phi dataset import`: reads TFRecord files into a dataset, published whole.
fn run_import(
    data: Option<PathBuf>,
    data_positional: Option<PathBuf>,
    out: PathBuf,
    force: bool,
) -> Result<()> {
    let input = crate::cli::dataset_dir("phi dataset import", data, data_positional)?;
    let staging = prepare_output(&out, &IMPORT_OUTPUTS, force)?;
    let imported = (|| -> Result<()> {
        let bar = crate::progress::counter(
            "trajectories imported",
            std::io::IsTerminal::is_terminal(&std::io::stderr()),
        );
        phi_gns::data::tfrecord::import_tfrecord_with(&input, &staging, &|| bar.inc(1))?;
        bar.finish_and_clear();
        write_import_marker(&staging, &input)?;
        phi_io::publish_dir(&staging, &out)?;
        Ok(())
    })();
    discard_on_error(imported, &staging)?;
    let dataset = phi_gns::data::Dataset::open(&out)?;
    let counts: Vec<String> = dataset
        .metadata()
        .splits
        .iter()
        .map(|(s, n)| format!("{s} {n}"))
        .collect();
    println!(
        "imported {} into {}: {}",
        input.display(),
        out.display(),
        counts.join(", ")
    );
    Ok(())
}

/// The dataset to write and the shards of `phi dataset merge`: `--out` and every positional
/// path, or, without `--out`, the first positional path and the others (the form before `--out`,
/// deprecated). With `--out`, every positional path is a shard, so that `--out A A B` is refused
/// as a merge into shard A, not taken for the two forms at once.
fn merge_paths(out: Option<PathBuf>, mut shards: Vec<PathBuf>) -> Result<(PathBuf, Vec<PathBuf>)> {
    if let Some(out) = out {
        return Ok((out, shards));
    }
    if shards.len() < 2 {
        bail!(
            "no dataset to write: pass --out DIR and the shard directories \
             (`phi dataset merge --out DIR SHARDS...`)"
        );
    }
    let out = shards.remove(0);
    tracing::warn!(
        "`phi dataset merge OUT SHARDS...` is deprecated and goes in the next release: pass \
         --out {}",
        out.display()
    );
    Ok((out, shards))
}

/// The file that marks a dataset as written by `phi dataset import`, and where from.
pub(crate) const IMPORT_MARKER: &str = "import.json";

/// The `made_by` of [`IMPORT_MARKER`].
pub(crate) const IMPORT_MADE_BY: &str = "phi dataset import";

/// What `phi dataset import` writes: a dataset (metadata.json and a folder of trajectories per
/// split) and [`IMPORT_MARKER`].
pub(crate) const IMPORT_OUTPUTS: Outputs = Outputs {
    command: "phi dataset import",
    flag: "--out",
    files: &[IMPORT_MARKER, METADATA_FILE],
    subdirs: &[OutputSubdir {
        name: "*",
        prefix: "traj_",
        suffix: ".npz",
    }],
    marker: Some(Marker::json(IMPORT_MARKER, "made_by", IMPORT_MADE_BY)),
};

/// Writes [`IMPORT_MARKER`] into the imported dataset `dir`.
fn write_import_marker(dir: &Path, input: &Path) -> Result<()> {
    let marker = serde_json::json!({
        "made_by": IMPORT_MADE_BY,
        "phi_version": env!("CARGO_PKG_VERSION"),
        "source": input.display().to_string(),
    });
    let path = dir.join(IMPORT_MARKER);
    std::fs::write(&path, serde_json::to_vec_pretty(&marker)?)
        .with_context(|| format!("cannot write {}", path.display()))
}

/// Applies the rule of `outputs` to the directory `out` of a command that writes a whole
/// directory (absent, empty, or its own earlier output and `force`), and makes the staging
/// directory the command fills: `out` is only replaced, whole, once everything is written
/// ([`phi_io::publish_dir`]).
fn prepare_output(out: &Path, outputs: &Outputs, force: bool) -> Result<PathBuf> {
    // Nothing is removed now: publishing the staging directory replaces `out` whole.
    let _replaced = check_dir(out, outputs, force)?;
    if let Some(parent) = out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent)
            .with_context(|| format!("creating {}", parent.display()))?;
    }
    Ok(phi_io::staging_dir(out)?)
}

/// `result`, after removing the staging directory if it is an error.
fn discard_on_error<T>(result: Result<T>, staging: &Path) -> Result<T> {
    if result.is_err() {
        let _ = std::fs::remove_dir_all(staging);
    }
    result
}

/// Runs `phi render`.
///
/// # Errors
/// A missing dataset or trajectory, I/O errors.
pub fn render(args: RenderArgs) -> Result<()> {
    let data = crate::cli::dataset_dir("phi render", args.data, args.data_positional)?;
    let pictures = render_trajectory(
        &data,
        &args.split,
        args.trajectory,
        &args.out,
        args.pixels_per_cell,
        args.frame_every,
        args.force,
    )?;
    println!("wrote {} ({pictures} pictures)", args.out.display());
    Ok(())
}
