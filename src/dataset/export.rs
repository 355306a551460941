//! `phi dataset export`: a dataset in the formats of numpy, DeepMind's `learning_to_simulate`,
//! geoelements/gns and LagrangeBench.
//!
//! The LagrangeBench export writes HDF5 through Python's `h5py` (no HDF5 library is linked into
//! phi): the arrays of each split go into a temporary `.npz` in LagrangeBench's layout
//! ([`phi_gns::data::export::export_lagrangebench_arrays`]), and the script
//! `lagrangebench_h5.py`, built into the binary, turns it into `{split}.h5`.
//!
//! Beside the files of the format, `export.json` says what was exported from where; it marks the
//! folder as this command's output, which a later export replaces only with `--force`
//! ([`EXPORT_OUTPUTS`]).

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Context, Result, bail};
use indicatif::ProgressBar;
use phi_gns::data::export::{
    export_gns, export_lagrangebench_arrays, write_lagrangebench_metadata,
};
use phi_gns::data::{Dataset, METADATA_FILE};

use crate::output::target::{Marker, Outputs};

/// The file that marks a folder as an export of phi: who wrote it, from which dataset, in
/// which format.
pub(crate) const EXPORT_MARKER: &str = "export.json";

/// The `made_by` of [`EXPORT_MARKER`].
pub(crate) const EXPORT_MADE_BY: &str = "phi dataset export";

/// What `phi dataset export` writes, in every format: the files of each split, the format's
/// metadata.json and [`EXPORT_MARKER`].
pub(crate) const EXPORT_OUTPUTS: Outputs = Outputs {
    command: "phi dataset export",
    flag: "--out",
    files: &[EXPORT_MARKER, METADATA_FILE, "*.npz", "*.tfrecord", "*.h5"],
    subdirs: &[],
    marker: Some(Marker::json(EXPORT_MARKER, "made_by", EXPORT_MADE_BY)),
};

/// The script that writes LagrangeBench's HDF5 files.
pub(crate) const LAGRANGEBENCH_SCRIPT: &str = include_str!("lagrangebench_h5.py");

/// Formats of `phi dataset export`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ExportFormat {
    /// One `{split}.npz` per split with `trajectory_{i}_position` and
    /// `trajectory_{i}_particle_type` (phi's types: 0 obstacle, 1 liquid).
    Npz,
    /// DeepMind learning_to_simulate's `{split}.tfrecord` and metadata.json.
    Tfrecord,
    /// geoelements/gns: `{split}.npz` of (positions, particle_type) items, type 3 kinematic,
    /// 5 water, and its metadata.json.
    Gns,
    /// LagrangeBench: `{split}.h5` (groups 00000, ... with position and particle_type; FLUID 0,
    /// SOLID_WALL 1) and its metadata.json. Needs a Python with numpy and h5py (`--python`).
    Lagrangebench,
}

/// What `phi dataset export` writes and how.
#[derive(Debug, Clone)]
pub struct ExportOptions {
    /// The dataset directory.
    pub dir: PathBuf,
    /// The format.
    pub format: ExportFormat,
    /// The directory to write into.
    pub out: PathBuf,
    /// The Python interpreter for the LagrangeBench export.
    pub python: PathBuf,
    /// Show a progress bar.
    pub progress: bool,
}

/// Exports a dataset; returns the trajectories written per split.
///
/// # Errors
/// A dataset that does not open, I/O errors, and for LagrangeBench a Python that cannot be run
/// or lacks numpy or h5py (the error says which).
pub fn export(options: &ExportOptions) -> Result<Vec<(String, usize)>> {
    let dataset = Dataset::open(&options.dir)?;
    let out = &options.out;
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let marker = serde_json::json!({
        "made_by": EXPORT_MADE_BY,
        "phi_version": env!("CARGO_PKG_VERSION"),
        "format": format!("{:?}", options.format).to_lowercase(),
        "dataset": options.dir.display().to_string(),
    });
    let path = out.join(EXPORT_MARKER);
    std::fs::write(&path, serde_json::to_vec_pretty(&marker)?)
        .with_context(|| format!("cannot write {}", path.display()))?;
    let total: usize = dataset.metadata().splits.values().sum();
    let bar = crate::progress::count_bar(total, "trajectories", options.progress);
    let mut tick = || bar.inc(1);
    let splits: Vec<String> = dataset.metadata().splits.keys().cloned().collect();
    let mut counts = Vec::new();
    match options.format {
        ExportFormat::Npz => {
            for split in &splits {
                let file = out.join(format!("{split}.npz"));
                let count = phi_gns::data::export_npz(&dataset, split, &file)?;
                bar.inc(count as u64);
                counts.push((split.clone(), count));
            }
        }
        ExportFormat::Tfrecord => {
            phi_gns::data::tfrecord::export_tfrecord(&dataset, out)?;
            for split in &splits {
                let count = dataset.split_len(split)?;
                bar.inc(count as u64);
                counts.push((split.clone(), count));
            }
        }
        ExportFormat::Gns => counts = export_gns(&dataset, out, &mut tick)?,
        ExportFormat::Lagrangebench => {
            let script = out.join(format!(".lagrangebench_h5-{}.py", std::process::id()));
            std::fs::write(&script, LAGRANGEBENCH_SCRIPT)
                .with_context(|| format!("cannot write {}", script.display()))?;
            let result =
                export_lagrangebench(&dataset, &splits, out, &options.python, &script, &bar);
            let _ = std::fs::remove_file(&script);
            counts = result?;
            write_lagrangebench_metadata(&dataset, out)?;
        }
    }
    bar.finish_and_clear();
    Ok(counts)
}

fn export_lagrangebench(
    dataset: &Dataset,
    splits: &[String],
    out: &Path,
    python: &Path,
    script: &Path,
    bar: &ProgressBar,
) -> Result<Vec<(String, usize)>> {
    let mut counts = Vec::new();
    for split in splits {
        let arrays = out.join(format!(".{split}.lagrangebench-{}.npz", std::process::id()));
        let h5 = out.join(format!("{split}.h5"));
        let written = export_lagrangebench_arrays(dataset, split, &arrays, &mut || bar.inc(1));
        let result = written.map_err(anyhow::Error::from).and_then(|count| {
            run_python(python, script, &arrays, &h5)?;
            Ok(count)
        });
        let _ = std::fs::remove_file(&arrays);
        counts.push((split.clone(), result?));
    }
    Ok(counts)
}

fn run_python(python: &Path, script: &Path, arrays: &Path, h5: &Path) -> Result<()> {
    let output = Command::new(python)
        .arg(script)
        .arg(arrays)
        .arg(h5)
        .output()
        .with_context(|| {
            format!(
                "cannot run '{}' to write {} (the LagrangeBench export needs a Python with \
                 numpy and h5py; name it with --python)",
                python.display(),
                h5.display()
            )
        })?;
    if !output.status.success() {
        let stderr = String::from_utf8_lossy(&output.stderr);
        let hint = if stderr.contains("No module named") {
            " (the LagrangeBench export needs numpy and h5py: pip install numpy h5py)"
        } else {
            ""
        };
        bail!(
            "'{}' failed to write {}{hint}:\n{}",
            python.display(),
            h5.display(),
            stderr.trim_end()
        );
    }
    Ok(())
}
