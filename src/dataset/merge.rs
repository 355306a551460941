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
use phi_gns::data::{
    METADATA_FILE, Metadata, TrajectoryStats, Variant, read_trajectory_stats, trajectory_file_name,
    write_metadata,
};

use super::generate::{GeneratorConfig, MANIFEST, Manifest, Shard, read_manifest};
use super::{Split, check_dir};
use phi_flip::SceneVariant;

/// The `generator` value of `DIR/metadata.json`, if the file exists.
///
/// # Errors
/// A file that cannot be read or parsed as JSON.
pub fn read_generator(dir: &Path) -> Result<Option<serde_json::Value>> {
    let path = dir.join(METADATA_FILE);
    if !path.exists() {
        return Ok(None);
    }
    let text =
        std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    let value: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
    Ok(Some(value.get("generator").cloned().unwrap_or_default()))
}

/// Writes `DIR/metadata.json` for the trajectories of `counts` (an unsharded directory holds all
/// of them). The statistics are those of the train split when it has trajectories, else of every
/// split, merged from the files in index order. A shard (`n > 1`) writes none: its directory is
/// not a dataset until merged.
///
/// # Errors
/// A missing or unreadable trajectory file, I/O errors.
pub fn write_dataset_metadata(
    dir: &Path,
    config: &GeneratorConfig,
    counts: &BTreeMap<String, usize>,
    shard: Shard,
) -> Result<()> {
    if shard.count > 1 {
        return Ok(());
    }
    let params = &config.params;
    let mut metadata = Metadata::new(2);
    metadata.sequence_length = params.steps;
    metadata.dt = params.dt.to_string().parse()?;
    // In f64 from the same decimals as `position_scale` (0.8 / 32 = 0.025, offset 0.1).
    let longest = params.resolution[0].max(params.resolution[1]) as f64;
    let (scale, offset) = (0.8 / longest, 0.1);
    metadata.position_scale = scale;
    metadata.position_offset = offset;
    metadata.bounds = params
        .resolution
        .iter()
        .map(|&n| [offset, n as f64 * scale + offset])
        .collect();
    metadata.variant = match config.variant {
        SceneVariant::Obstacles => Variant::Obstacles,
        SceneVariant::Walls => Variant::WallsAsParticles,
    };
    metadata.generator = config.to_json();
    metadata.splits = counts.clone();
    metadata.seeds = counts
        .keys()
        .filter(|s| *s != Split::Test.name())
        .filter_map(|s| Some((s.clone(), *config.split_seeds.get(s)?)))
        .collect();
    let train = counts.get(Split::Train.name()).copied().unwrap_or(0);
    let mut stats = TrajectoryStats::new(2);
    for (split, &count) in counts {
        if train > 0 && split != Split::Train.name() {
            continue;
        }
        for index in 0..count {
            let path = dir.join(split).join(trajectory_file_name(index));
            let one = read_trajectory_stats(&path)?;
            stats
                .merge(&one)
                .with_context(|| format!("merging the statistics of {}", path.display()))?;
        }
    }
    if stats.velocity.count() > 0 {
        metadata.set_statistics(&stats)?;
    }
    write_metadata(dir, &metadata)?;
    Ok(())
}

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

    let mut summary = MergeSummary {
        counts: counts.clone(),
        files: 0,
    };
    for (split, &count) in &counts {
        let dir = out.join(split);
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        for index in 0..count {
            let name = trajectory_file_name(index);
            let target = dir.join(&name);
            let source = shards
                .iter()
                .map(|s| s.join(split).join(&name))
                .find(|p| p.is_file())
                .with_context(|| {
                    format!(
                        "no shard holds {split}/{name}: run the missing shard (or resume it) first"
                    )
                })?;
            link_or_copy(&source, &target)?;
            summary.files += 1;
        }
    }
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
