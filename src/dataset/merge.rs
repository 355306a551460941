//! `phi dataset merge`: joins shard directories into one dataset, and writes `metadata.json`
//! (also for unsharded runs of `phi dataset generate`).
//!
//! Trajectory files are hard-linked (copied where the file system cannot link) into the output
//! directory; the statistics come from the statistics stored in each file, merged in split and
//! index order, so a merged dataset has the same bytes as an unsharded run of the same
//! configuration.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use phi_gns::data::trajectory_file_name;

use super::check_dir;
use super::manifest::{MANIFEST, Manifest, Shard, read_manifest, write_dataset_metadata};

/// What a merge did.
#[derive(Debug, Clone, Default)]
pub struct MergeSummary {
    /// Trajectories per split.
    pub counts: BTreeMap<String, usize>,
    /// Files linked (or copied).
    pub files: usize,
}

/// Joins the shard directories `shards` (made by `phi dataset generate --shard k/n` with one
/// configuration) into the dataset `out`.
///
/// # Errors
/// Shards of different configurations, a trajectory that no shard holds, an output directory
/// holding another dataset, I/O errors.
pub fn merge(out: &Path, shards: &[PathBuf]) -> Result<MergeSummary> {
    if shards.is_empty() {
        bail!("give at least one shard directory");
    }
    check_dir(out)?;
    let mut manifests = Vec::new();
    for dir in shards {
        let manifest = read_manifest(dir)?.with_context(|| {
            format!(
                "{} has no {MANIFEST}: it is not a directory written by `phi dataset generate`",
                dir.display()
            )
        })?;
        manifests.push(manifest);
    }
    let config = manifests[0].config.clone();
    let reference = config.to_json();
    for (dir, m) in shards.iter().zip(&manifests).skip(1) {
        let differences = m.config.differences(&reference);
        if !differences.is_empty() {
            bail!(
                "{} was generated with another configuration than {} (differing keys: {})",
                dir.display(),
                shards[0].display(),
                differences.join(", ")
            );
        }
    }
    let mut counts: BTreeMap<String, usize> = BTreeMap::new();
    for m in &manifests {
        for (split, &count) in &m.counts {
            let entry = counts.entry(split.clone()).or_insert(count);
            *entry = (*entry).max(count);
        }
    }
    if let Some(existing) = read_manifest(out)? {
        let differences = config.differences(&existing.config.to_json());
        if !differences.is_empty() {
            bail!(
                "{} holds a dataset of another configuration (differing keys: {})",
                out.display(),
                differences.join(", ")
            );
        }
    } else if out.is_dir() && std::fs::read_dir(out)?.next().is_some() {
        bail!("{} is not empty and holds no phi dataset", out.display());
    }

    // Every source is found before anything is written, so a merge that cannot finish (a shard
    // not run yet) leaves `out` as it was.
    let mut pairs = Vec::new();
    for (split, &count) in &counts {
        for index in 0..count {
            let name = trajectory_file_name(index);
            let source = shards
                .iter()
                .map(|s| s.join(split).join(&name))
                .find(|p| p.is_file())
                .with_context(|| {
                    format!(
                        "no shard holds {split}/{name}: run the missing shard (or resume it) first"
                    )
                })?;
            pairs.push((source, out.join(split).join(&name)));
        }
    }
    for split in counts.keys() {
        let dir = out.join(split);
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    for (source, target) in &pairs {
        link_or_copy(source, target)?;
    }
    let summary = MergeSummary {
        counts: counts.clone(),
        files: pairs.len(),
    };
    let manifest = Manifest {
        config: config.clone(),
        shard: Shard::default(),
        counts: counts.clone(),
    };
    let text = serde_json::to_string_pretty(&manifest)?;
    let path = out.join(MANIFEST);
    phi_io::write_atomic::<phi_io::IoError>(&path, |w| {
        phi_io::write_all(w, text.as_bytes(), &path)
    })?;
    write_dataset_metadata(out, &config, &counts, Shard::default())?;
    Ok(summary)
}

/// Hard-links `source` to `target` (replacing it), or copies through a temporary file and a
/// rename where linking is not possible.
fn link_or_copy(source: &Path, target: &Path) -> Result<()> {
    if target.exists() {
        if same_file(source, target) {
            return Ok(());
        }
        std::fs::remove_file(target).with_context(|| format!("replacing {}", target.display()))?;
    }
    if std::fs::hard_link(source, target).is_ok() {
        return Ok(());
    }
    let temp = target.with_extension(format!("tmp-{}", std::process::id()));
    std::fs::copy(source, &temp)
        .with_context(|| format!("copying {} to {}", source.display(), temp.display()))?;
    std::fs::rename(&temp, target).with_context(|| format!("renaming {}", temp.display()))?;
    Ok(())
}

#[cfg(unix)]
fn same_file(a: &Path, b: &Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    match (std::fs::metadata(a), std::fs::metadata(b)) {
        (Ok(a), Ok(b)) => a.dev() == b.dev() && a.ino() == b.ino(),
        _ => false,
    }
}

#[cfg(not(unix))]
fn same_file(_: &Path, _: &Path) -> bool {
    false
}
