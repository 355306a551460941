//! Merging: joins the shard directories of a sharded run ([`Shard`]) into one dataset, and
//! writes its `metadata.json`.
//!
//! Trajectory files are hard-linked (copied where the file system cannot link) into the output
//! directory; the statistics come from the statistics stored in each file, merged in split and
//! index order, so a merged dataset has the same bytes as an unsharded run of the same
//! configuration.
//!
//! `out` must be new or empty; `force` replaces a dataset that [`generate`](crate::generate())
//! or [`merge`] wrote there (its files are removed once every source is found). A folder
//! holding anything else, or one of the shards itself, is refused.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use phi_gns::data::trajectory_file_name;
use phi_io::output_dir::OutputDir;

use crate::manifest::{
    MANIFEST, MERGE_OUTPUTS, Manifest, Shard, read_manifest, write_dataset_metadata, write_manifest,
};
use crate::{DatasetError, Result};

/// What a merge did.
#[derive(Debug, Clone, Default)]
pub struct MergeSummary {
    /// Trajectories per split.
    pub counts: BTreeMap<String, usize>,
    /// Files linked (or copied).
    pub files: usize,
}

/// Joins the shard directories `shards` (made by [`generate`](crate::generate()) with one
/// configuration and shards `k/n`) into the dataset `out`, replacing a dataset there only with `force`
/// ([`MERGE_OUTPUTS`]).
///
/// # Errors
/// Shards of different configurations, a trajectory that no shard holds, an output directory
/// that is one of the shards, holds anything but a dataset, or a dataset without `force`; I/O
/// errors.
pub fn merge(out: &Path, shards: &[PathBuf], force: bool) -> Result<MergeSummary> {
    if shards.is_empty() {
        return Err(DatasetError::Options(
            "give at least one shard directory".into(),
        ));
    }
    if let Ok(target) = out.canonicalize()
        && let Some(shard) = shards
            .iter()
            .find(|s| s.canonicalize().is_ok_and(|s| s == target))
    {
        return Err(DatasetError::Directory {
            path: out.to_path_buf(),
            reason: format!(
                "is the shard {}; merge into a new directory",
                shard.display()
            ),
        });
    }
    let mut previous = OutputDir::claim(out, &MERGE_OUTPUTS, force)?;
    let mut manifests = Vec::new();
    for dir in shards {
        let manifest = read_manifest(dir)?.ok_or_else(|| DatasetError::Directory {
            path: dir.clone(),
            reason: format!(
                "has no {MANIFEST}: it is not a directory written by `phi dataset generate`"
            ),
        })?;
        manifests.push(manifest);
    }
    let config = manifests[0].config.clone();
    let reference = config.to_json();
    for (dir, m) in shards.iter().zip(&manifests).skip(1) {
        let differences = m.config.differences(&reference);
        if !differences.is_empty() {
            return Err(DatasetError::Directory {
                path: dir.clone(),
                reason: format!(
                    "was generated with another configuration than {} (differing keys: {})",
                    shards[0].display(),
                    differences.join(", ")
                ),
            });
        }
    }
    let mut counts: BTreeMap<String, usize> = BTreeMap::new();
    for m in &manifests {
        for (split, &count) in &m.counts {
            let entry = counts.entry(split.clone()).or_insert(count);
            *entry = (*entry).max(count);
        }
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
                .ok_or_else(|| {
                    DatasetError::Options(format!(
                        "no shard holds {split}/{name}: run the missing shard (or resume it) first"
                    ))
                })?;
            pairs.push((source, out.join(split).join(&name)));
        }
    }
    previous.clear_previous()?;
    for split in counts.keys() {
        let dir = out.join(split);
        std::fs::create_dir_all(&dir).map_err(|e| DatasetError::io(&dir, "creating", e))?;
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
    write_manifest(out, &manifest)?;
    write_dataset_metadata(out, &config, &counts, Shard::default())?;
    Ok(summary)
}

/// Hard-links `source` to the new file `target`, or copies through a temporary file
/// (`.{name}.tmp-{pid}`) and a rename where linking is not possible.
fn link_or_copy(source: &Path, target: &Path) -> Result<()> {
    if std::fs::hard_link(source, target).is_ok() {
        return Ok(());
    }
    let mut name = std::ffi::OsString::from(".");
    name.push(target.file_name().unwrap_or_default());
    name.push(format!(".tmp-{}", std::process::id()));
    let temp = target.with_file_name(name);
    std::fs::copy(source, &temp).map_err(|e| DatasetError::io(source, "copying", e))?;
    std::fs::rename(&temp, target).map_err(|e| DatasetError::io(&temp, "renaming", e))?;
    Ok(())
}
