//! `phi dataset generate`: simulates the trajectories of a dataset in parallel.
//!
//! Trajectories are independent jobs on a rayon pool (`--threads`); each simulation runs on one
//! thread on the host backend (`phi_core::backend::Host`: ndarray). Trajectory `i` of a split is drawn from
//! [`trajectory_seed`]`(split seed, i)`, so the bytes of every file are the same whatever the
//! thread count, sharding (`--shard k/n` takes the indices `i ≡ k mod n`) or order of
//! completion. Files are written atomically (temporary file, then rename): a killed run loses
//! only the trajectories in flight, and running the same command again skips every finished
//! file. `generator.json`, written before the first trajectory, records the configuration, so
//! a directory holding another configuration's files is refused (unless `--resume`).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressStyle};
use phi_flip::{RandomSceneParams, SceneVariant};
use phi_gns::data::{
    LIQUID, OBSTACLE, Trajectory, TrajectoryStats, read_trajectory, trajectory_file_name,
    write_trajectory,
};
use phi_io::write_atomic;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::{Split, TEST_SCENES, check_dir, position_scale, simulate_trajectory, trajectory_seed};

/// The name of the generation manifest in a dataset directory.
pub const MANIFEST: &str = "generator.json";

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
}

impl GeneratorConfig {
    /// The configuration of a run.
    pub fn new(variant: SceneVariant, seed: u64, params: RandomSceneParams) -> Self {
        Self {
            generator: format!("phi dataset generate {}", env!("CARGO_PKG_VERSION")),
            variant,
            seed,
            split_seeds: Split::ALL
                .iter()
                .map(|s| (s.name().to_string(), s.seed(seed)))
                .collect(),
            params,
            test_scenes: TEST_SCENES.iter().map(|(n, _)| n.to_string()).collect(),
        }
    }

    /// The configuration as JSON, its `f32` values written with their shortest decimals
    /// (`0.05`, not `0.05000000074505806`).
    pub fn to_json(&self) -> serde_json::Value {
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
pub fn read_manifest(dir: &Path) -> Result<Option<Manifest>> {
    let path = dir.join(MANIFEST);
    if !path.exists() {
        return Ok(None);
    }
    let text =
        std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    let manifest =
        serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
    Ok(Some(manifest))
}

fn write_manifest(dir: &Path, manifest: &Manifest) -> Result<()> {
    let text = serde_json::to_string_pretty(manifest)?;
    let path = dir.join(MANIFEST);
    write_atomic::<phi_io::IoError>(&path, |w| phi_io::write_all(w, text.as_bytes(), &path))?;
    Ok(())
}

/// What `phi dataset generate` does.
#[derive(Debug, Clone)]
pub struct GenerateOptions {
    /// The dataset directory.
    pub out: PathBuf,
    /// The splits to make.
    pub splits: Vec<Split>,
    /// Trajectories per split (`None`: the thesis' 2000, 20 and 10; the test split has at most
    /// 10).
    pub count: Option<usize>,
    /// The dataset seed.
    pub seed: u64,
    /// Scene variant.
    pub variant: SceneVariant,
    /// Table 5.1 with `steps` set.
    pub params: RandomSceneParams,
    /// Worker threads (`None`: rayon's default, one per core).
    pub threads: Option<usize>,
    /// This run's shard.
    pub shard: Shard,
    /// Continue in a directory whose manifest differs or is missing.
    pub resume: bool,
    /// Show a progress bar.
    pub progress: bool,
}

/// What a run did.
#[derive(Debug, Clone, Default)]
pub struct GenerateSummary {
    /// Trajectories simulated and written.
    pub written: usize,
    /// Finished files found and kept.
    pub skipped: usize,
    /// Wall time in seconds.
    pub seconds: f64,
    /// Particles per written trajectory, smallest and largest.
    pub particles: (usize, usize),
}

struct Job {
    split: Split,
    index: usize,
    seed: u64,
    path: PathBuf,
}

/// Generates the dataset described by `options`, then writes `metadata.json`.
///
/// # Errors
/// A directory holding another dataset, invalid options, a failing simulation (naming the split,
/// index and seed), I/O errors.
pub fn generate(options: &GenerateOptions) -> Result<GenerateSummary> {
    let started = Instant::now();
    let out = &options.out;
    check_dir(out)?;
    let config = GeneratorConfig::new(options.variant, options.seed, options.params.clone());
    check_compatible(out, &config, options.shard, options.resume)?;

    let mut counts = BTreeMap::new();
    for &split in &options.splits {
        let mut count = options.count.unwrap_or(split.default_count());
        if split == Split::Test {
            count = count.min(TEST_SCENES.len());
        }
        counts.insert(split.name().to_string(), count);
    }
    if let Some(previous) = read_manifest(out)? {
        // Keep what an earlier run asked for in splits this run does not make.
        for (split, count) in previous.counts {
            counts.entry(split).or_insert(count);
        }
    }
    for split in &options.splits {
        let dir = out.join(split.name());
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    write_manifest(
        out,
        &Manifest {
            config: config.clone(),
            shard: options.shard,
            counts: counts.clone(),
        },
    )?;

    let steps = options.params.steps;
    let mut jobs = Vec::new();
    let mut skipped = 0;
    for &split in &options.splits {
        let split_seed = split.seed(options.seed);
        for index in (0..counts[split.name()]).filter(|&i| options.shard.holds(i)) {
            let seed = match split {
                Split::Test => 0,
                _ => trajectory_seed(split_seed, index),
            };
            let path = out.join(split.name()).join(trajectory_file_name(index));
            if is_finished(&path, split, index, seed, steps) {
                skipped += 1;
            } else {
                jobs.push(Job {
                    split,
                    index,
                    seed,
                    path,
                });
            }
        }
    }

    let bar = if options.progress {
        let bar = ProgressBar::new(jobs.len() as u64);
        bar.set_style(
            ProgressStyle::with_template(
                "{elapsed_precise} [{bar:40}] {pos}/{len} trajectories, {per_sec}, ETA {eta}",
            )
            .expect("a valid template")
            .progress_chars("=> "),
        );
        bar
    } else {
        ProgressBar::hidden()
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(options.threads.unwrap_or(0))
        .build()
        .context("starting the worker threads")?;
    let (scale, offset) = position_scale(options.params.resolution);
    let particles: Vec<usize> = pool.install(|| {
        jobs.par_iter()
            .map(|job| {
                let n = make_trajectory(job, options, scale, offset).with_context(|| {
                    format!("{} trajectory {} (seed {})", job.split, job.index, job.seed)
                })?;
                bar.inc(1);
                Ok(n)
            })
            .collect::<Result<Vec<usize>>>()
    })?;
    bar.finish_and_clear();

    super::merge::write_dataset_metadata(out, &config, &counts, options.shard)?;
    Ok(GenerateSummary {
        written: jobs.len(),
        skipped,
        seconds: started.elapsed().as_secs_f64(),
        particles: (
            particles.iter().copied().min().unwrap_or(0),
            particles.iter().copied().max().unwrap_or(0),
        ),
    })
}

/// Refuses a directory that holds files of another configuration (or files without a
/// manifest), unless `resume`.
fn check_compatible(
    out: &Path,
    config: &GeneratorConfig,
    shard: Shard,
    resume: bool,
) -> Result<()> {
    let stored = match read_manifest(out)? {
        Some(m) => Some((m.config.to_json(), Some(m.shard))),
        None => super::merge::read_generator(out)?.map(|value| (value, None)),
    };
    let hint = "choose another --out, or pass --resume to continue in it anyway (finished \
                trajectories whose seed and length match are kept, the others remade)";
    match stored {
        Some((value, stored_shard)) => {
            let differences = config.differences(&value);
            if !differences.is_empty() && !resume {
                bail!(
                    "{} holds a dataset generated with another configuration (differing keys: \
                     {}); {hint}",
                    out.display(),
                    differences.join(", ")
                );
            }
            if let Some(s) = stored_shard
                && s != shard
                && !resume
            {
                bail!(
                    "{} holds shard {s}, not shard {shard}; {hint}",
                    out.display()
                );
            }
        }
        None => {
            let foreign = out.is_dir()
                && std::fs::read_dir(out)
                    .with_context(|| format!("reading {}", out.display()))?
                    .next()
                    .is_some();
            if foreign && !resume {
                bail!(
                    "{} is not empty and holds no phi dataset ({MANIFEST} or metadata.json); \
                     {hint}",
                    out.display()
                );
            }
        }
    }
    Ok(())
}

/// Whether `path` holds the finished trajectory `index` of `split`: a readable file with the
/// right index, seed (random splits) and frame count.
fn is_finished(path: &Path, split: Split, index: usize, seed: u64, steps: usize) -> bool {
    if !path.is_file() {
        return false;
    }
    match read_trajectory(path) {
        Ok(t) => {
            t.index == index && t.frames == steps + 1 && (split == Split::Test || t.seed == seed)
        }
        Err(_) => false,
    }
}

/// Simulates one trajectory, scales it and writes it with its statistics; returns its particle
/// count.
fn make_trajectory(job: &Job, options: &GenerateOptions, scale: f32, offset: f32) -> Result<usize> {
    let raw = simulate_trajectory(
        job.split,
        job.index,
        job.seed,
        &options.params,
        options.variant,
        options.params.steps,
    )?;
    let t = raw.trajectory;
    let position = t.positions.iter().map(|x| x * scale + offset).collect();
    let mut particle_type = vec![LIQUID; t.liquid];
    particle_type.resize(t.particles(), OBSTACLE);
    let trajectory = Trajectory::new(t.dim, position, particle_type, raw.seed, job.index)?;
    let stats = TrajectoryStats::of(&trajectory);
    write_trajectory(&job.path, &trajectory, &stats)?;
    Ok(t.particles())
}
