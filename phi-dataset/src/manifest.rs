//! What a dataset directory records about how it was made: `generator.json` (the manifest that
//! [`generate`](crate::generate()) writes before its first trajectory, so that a resumed or
//! sharded run can be checked against it) and the `generator` entry of `metadata.json`, which
//! generation and merging both write.

use std::collections::BTreeMap;
use std::path::Path;

use phi_flip::{RandomSceneParams, SceneVariant};
use phi_gns::data::{
    DataError, METADATA_FILE, Metadata, TrajectoryStats, Variant, read_trajectory_stats,
    trajectory_file_name, write_metadata,
};
use phi_io::output_dir::{Marker, OutputSubdir, Outputs};
use phi_io::write_atomic;
use serde::{Deserialize, Serialize};

use crate::{DatasetError, Result, Split, TestScenes};

/// The name of the generation manifest in a dataset directory.
pub const MANIFEST: &str = "generator.json";

/// The split folders of a dataset `phi dataset generate` and `phi dataset merge` write, with
/// their trajectory files (`traj_NNNNN.npz`).
const SPLIT_DIRS: &[OutputSubdir] = &[
    OutputSubdir {
        name: "train",
        prefix: "traj_",
        suffix: ".npz",
    },
    OutputSubdir {
        name: "valid",
        prefix: "traj_",
        suffix: ".npz",
    },
    OutputSubdir {
        name: "test",
        prefix: "traj_",
        suffix: ".npz",
    },
];

/// What `phi dataset generate` writes: a dataset (or a shard of one) with its [`MANIFEST`].
pub const GENERATE_OUTPUTS: Outputs = Outputs {
    command: "phi dataset generate",
    flag: "--out",
    files: &[MANIFEST, METADATA_FILE],
    subdirs: SPLIT_DIRS,
    marker: Some(Marker::file(MANIFEST)),
};

/// What `phi dataset merge` writes: the same files as [`GENERATE_OUTPUTS`].
pub const MERGE_OUTPUTS: Outputs = Outputs {
    command: "phi dataset merge",
    flag: "OUT",
    ..GENERATE_OUTPUTS
};

/// `--shard k/n`: this run makes the trajectories whose index is `k` modulo `n`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Shard {
    /// `k`, from 0.
    pub index: usize,
    /// `n`, at least 1.
    pub count: usize,
}

impl Default for Shard {
    fn default() -> Self {
        Self { index: 0, count: 1 }
    }
}

impl Shard {
    /// Whether trajectory `i` belongs to this shard.
    pub fn holds(&self, i: usize) -> bool {
        i % self.count == self.index
    }
}

impl std::str::FromStr for Shard {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Self, String> {
        let bad = || format!("a shard is `k/n` with 0 <= k < n, e.g. 0/4; got {s:?}");
        let (k, n) = s.split_once('/').ok_or_else(bad)?;
        let (index, count) = (
            k.trim().parse().map_err(|_| bad())?,
            n.trim().parse().map_err(|_| bad())?,
        );
        if count == 0 || index >= count {
            return Err(bad());
        }
        Ok(Shard { index, count })
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

/// Everything that decides the bytes of a trajectory file; two runs with equal configurations
/// write the same files, so they may share a directory.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GeneratorConfig {
    /// The tool that wrote the dataset and its version.
    pub generator: String,
    /// `obstacles` or `walls`.
    pub variant: SceneVariant,
    /// The dataset seed (`--seed`).
    pub seed: u64,
    /// The seed of each split's stream of trajectory seeds.
    pub split_seeds: BTreeMap<String, u64>,
    /// Table 5.1 (steps included).
    pub params: RandomSceneParams,
    /// The test scenes, by file name.
    pub test_scenes: Vec<String>,
    /// The CRC-32 of the test scenes' names and texts when they come from a folder
    /// (`--scenes`); absent for the built-in ones.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub test_scenes_crc32: Option<u32>,
    /// Stored units per cell (`--position-scale`); absent: 0.8 / the longest side.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub position_scale: Option<f64>,
}

impl GeneratorConfig {
    /// The configuration of a run.
    pub fn new(
        variant: SceneVariant,
        seed: u64,
        params: RandomSceneParams,
        scenes: &TestScenes,
        position_scale: Option<f64>,
    ) -> Self {
        Self {
            generator: format!("phi dataset generate {}", env!("CARGO_PKG_VERSION")),
            variant,
            seed,
            split_seeds: Split::ALL
                .iter()
                .map(|s| (s.name().to_string(), s.seed(seed)))
                .collect(),
            params,
            test_scenes: scenes.names(),
            test_scenes_crc32: (!scenes.builtin).then(|| scenes.crc32()),
            position_scale,
        }
    }

    /// The configuration as JSON, its `f32` values written with their shortest decimals
    /// (`0.05`, not `0.05000000074505806`).
    pub(crate) fn to_json(&self) -> serde_json::Value {
        let text = serde_json::to_string(self).expect("a configuration serialises");
        serde_json::from_str(&text).expect("serde_json reads what it writes")
    }

    /// The keys whose values differ from `other`'s, for error messages.
    pub fn differences(&self, other: &serde_json::Value) -> Vec<String> {
        let mine = self.to_json();
        let (Some(a), Some(b)) = (mine.as_object(), other.as_object()) else {
            return vec!["(not a generator configuration)".into()];
        };
        let mut keys: Vec<String> = a
            .keys()
            .chain(b.keys())
            .filter(|k| a.get(*k) != b.get(*k))
            .cloned()
            .collect();
        keys.sort();
        keys.dedup();
        keys
    }
}

/// `generator.json`: the configuration, the shard and the trajectories asked for.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// What decides the files.
    pub config: GeneratorConfig,
    /// This directory's shard.
    pub shard: Shard,
    /// Trajectories per split asked for (all shards together).
    pub counts: BTreeMap<String, usize>,
}

/// Reads `DIR/generator.json`, if there is one.
///
/// # Errors
/// A file that cannot be read or parsed.
pub(crate) fn read_manifest(dir: &Path) -> Result<Option<Manifest>> {
    let path = dir.join(MANIFEST);
    if !path.exists() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(&path).map_err(|e| DatasetError::io(&path, "reading", e))?;
    let manifest =
        serde_json::from_str(&text).map_err(|source| DataError::Json { path, source })?;
    Ok(Some(manifest))
}

/// Writes `DIR/generator.json`, atomically.
///
/// # Errors
/// I/O errors, naming the file.
pub(crate) fn write_manifest(dir: &Path, manifest: &Manifest) -> Result<()> {
    let text = serde_json::to_string_pretty(manifest).expect("a manifest serialises");
    let path = dir.join(MANIFEST);
    write_atomic::<phi_io::IoError>(&path, |w| phi_io::write_all(w, text.as_bytes(), &path))?;
    Ok(())
}

/// The `generator` value of `DIR/metadata.json`, if the file exists.
///
/// # Errors
/// A file that cannot be read or parsed as JSON.
pub(crate) fn read_generator(dir: &Path) -> Result<Option<serde_json::Value>> {
    let path = dir.join(METADATA_FILE);
    if !path.exists() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(&path).map_err(|e| DatasetError::io(&path, "reading", e))?;
    let value: serde_json::Value =
        serde_json::from_str(&text).map_err(|source| DataError::Json { path, source })?;
    Ok(Some(value.get("generator").cloned().unwrap_or_default()))
}

/// Writes `DIR/metadata.json` for the trajectories of `counts` (an unsharded directory holds all
/// of them). The statistics are those of the train split when it has trajectories, else of every
/// split, merged from the files in index order. A shard (`n > 1`) writes none: its directory is
/// not a dataset until merged.
///
/// # Errors
/// A missing or unreadable trajectory file, I/O errors.
pub(crate) fn write_dataset_metadata(
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
    // In f64 from the shortest decimals of the f32 (0.05, not 0.05000000074505806).
    metadata.dt = params
        .dt
        .to_string()
        .parse()
        .unwrap_or(f64::from(params.dt));
    // In f64 from the same decimals as `position_scale` (0.8 / 32 = 0.025, offset 0.1).
    let longest = params.resolution[0].max(params.resolution[1]) as f64;
    let (scale, offset) = (config.position_scale.unwrap_or(0.8 / longest), 0.1);
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
            stats.merge(&one).map_err(|e| DatasetError::Invalid {
                path: path.display().to_string(),
                reason: format!("merging its statistics: {e}"),
            })?;
        }
    }
    if stats.velocity.count() > 0 {
        metadata.set_statistics(&stats)?;
    }
    write_metadata(dir, &metadata)?;
    Ok(())
}
