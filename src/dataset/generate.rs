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
//! `--force` replaces a dataset this command wrote ([`GENERATE_OUTPUTS`]): its files are removed
//! and every trajectory made again; `--prune` deletes only the trajectories beyond
//! `--trajectories`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use phi_flip::{RandomSceneParams, SceneVariant};
use phi_gns::data::{
    LIQUID, OBSTACLE, Trajectory, TrajectoryStats, read_trajectory_and_stats, trajectory_file_name,
    trajectory_index_from_file_name, write_trajectory,
};
use rayon::prelude::*;

use super::manifest::{
    GENERATE_OUTPUTS, GeneratorConfig, MANIFEST, Manifest, Shard, read_generator, read_manifest,
    write_dataset_metadata, write_manifest,
};
use super::{Split, TestScenes, position_scale, simulate_trajectory, trajectory_seed};
use crate::memory::check_memory;
use crate::output::target::{check_dir as check_outputs, check_not_a_file};

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
    /// Delete trajectory files beyond this run's count instead of refusing to.
    pub prune: bool,
    /// Replace the dataset in `out` ([`GENERATE_OUTPUTS`]) instead of continuing it.
    pub force: bool,
    /// The test split's scenes.
    pub scenes: TestScenes,
    /// Stored units per cell (`None`: 0.8 / the longest side).
    pub position_scale: Option<f64>,
    /// Show a progress bar (never with `phi -q`).
    pub progress: bool,
}

/// What a run did.
#[derive(Debug, Clone, Default)]
pub struct GenerateSummary {
    /// Trajectories simulated and written.
    pub written: usize,
    /// Finished files found and kept.
    pub skipped: usize,
    /// Files found damaged, unreadable or of another trajectory, and made again.
    pub remade: usize,
    /// Temporary files that killed runs left behind, removed.
    pub stale_removed: usize,
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
    check_not_a_file(out, "--out")?;
    let config = GeneratorConfig::new(
        options.variant,
        options.seed,
        options.params.clone(),
        &options.scenes,
        options.position_scale,
    );
    // With --force the previous dataset is replaced: checked here, removed once this run has
    // passed its own checks.
    let previous = if options.force {
        if options.resume {
            bail!("--force replaces the dataset in --out, --resume continues it: pass one");
        }
        Some(check_outputs(out, &GENERATE_OUTPUTS, true)?)
    } else {
        check_compatible(out, &config, options.shard, options.resume)?;
        None
    };

    let mut counts = BTreeMap::new();
    for &split in &options.splits {
        let mut count = options.count.unwrap_or(split.default_count());
        if split == Split::Test {
            count = count.min(options.scenes.len());
        }
        counts.insert(split.name().to_string(), count);
    }
    if previous.is_none()
        && let Some(manifest) = read_manifest(out)?
    {
        // Keep what an earlier run asked for in splits this run does not make.
        for (split, count) in manifest.counts {
            counts.entry(split).or_insert(count);
        }
    }
    let jobs_asked: u128 = options
        .splits
        .iter()
        .map(|s| counts[s.name()] as u128 / options.shard.count as u128 + 1)
        .sum();
    let job_bytes = (std::mem::size_of::<Job>() + 64 + out.as_os_str().len()) as u128;
    check_memory(
        &format!(
            "{} trajectories ({})",
            jobs_asked,
            if options.count.is_some() {
                "--trajectories"
            } else {
                "the counts of generator.json"
            }
        ),
        jobs_asked * job_bytes,
    )?;
    if let Some(previous) = previous {
        previous.remove()?;
    }
    let beyond = files_beyond(out, &counts)?;
    if let Some((split, index, count)) = beyond.first()
        && !options.prune
    {
        let last = beyond.iter().map(|b| b.1).max().unwrap_or(*index);
        bail!(
            "{} holds {split}/{} beyond the {count} {split} trajectories asked for ({} such \
             file(s)); pass --trajectories {} or more to keep and extend them, --prune to \
             delete them, or --force to replace the whole dataset",
            out.display(),
            trajectory_file_name(*index),
            beyond.len(),
            last + 1
        );
    }
    let mut stale_removed = 0;
    for dir in std::iter::once(out.clone()).chain(Split::ALL.iter().map(|s| out.join(s.name()))) {
        for path in phi_io::remove_stale_temp_files(&dir)? {
            tracing::info!("removed {}, left by a killed run", path.display());
            stale_removed += 1;
        }
    }
    if !beyond.is_empty() {
        // Without metadata.json the directory is an unfinished dataset until this run ends, so
        // a kill cannot leave metadata that lists files that are gone.
        let metadata = out.join(phi_gns::data::METADATA_FILE);
        if metadata.exists() {
            std::fs::remove_file(&metadata)
                .with_context(|| format!("removing {}", metadata.display()))?;
        }
        for (split, index, _) in &beyond {
            let path = out.join(split).join(trajectory_file_name(*index));
            std::fs::remove_file(&path).with_context(|| format!("removing {}", path.display()))?;
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
    let mut remade = 0;
    for &split in &options.splits {
        let split_seed = split.seed(options.seed);
        for index in (0..counts[split.name()]).filter(|&i| options.shard.holds(i)) {
            let seed = match split {
                Split::Test => 0,
                _ => trajectory_seed(split_seed, index),
            };
            let path = out.join(split.name()).join(trajectory_file_name(index));
            match check_finished(&path, index, (split != Split::Test).then_some(seed), steps) {
                Ok(true) => {
                    skipped += 1;
                    continue;
                }
                Ok(false) => {}
                Err(why) => {
                    tracing::warn!("{}: {why}; making it again", path.display());
                    remade += 1;
                }
            }
            jobs.push(Job {
                split,
                index,
                seed,
                path,
            });
        }
    }

    let bar = crate::progress::count_bar(jobs.len(), "trajectories", options.progress);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(options.threads.unwrap_or(0))
        .build()
        .context("starting the worker threads")?;
    let (scale, offset) = position_scale(options.params.resolution, options.position_scale);
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

    write_dataset_metadata(out, &config, &counts, options.shard)?;
    Ok(GenerateSummary {
        written: jobs.len(),
        skipped,
        remade,
        stale_removed,
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
        None => read_generator(out)?.map(|value| (value, None)),
    };
    let hint = "choose another --out, pass --force to replace it, or --resume to continue in it \
                anyway (finished trajectories whose seed and length match are kept, the others \
                remade)";
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
            let first = if out.is_dir() {
                let mut names = std::fs::read_dir(out)
                    .with_context(|| format!("reading {}", out.display()))?
                    .map(|e| e.map(|e| e.file_name().to_string_lossy().into_owned()))
                    .collect::<std::io::Result<Vec<_>>>()
                    .with_context(|| format!("reading {}", out.display()))?;
                names.sort();
                names.into_iter().next()
            } else {
                None
            };
            if let Some(first) = first
                && !resume
            {
                bail!(
                    "{} is not empty (it holds '{first}') and holds no phi dataset ({MANIFEST} or \
                     metadata.json); choose another --out, or pass --resume to continue in it \
                     anyway",
                    out.display()
                );
            }
        }
    }
    Ok(())
}

/// Whether `path` holds the finished trajectory `index`: `Ok(false)` when there is no file,
/// `Ok(true)` for a whole file (every member read and its CRC-32 checked, the statistics
/// included) with the right index, seed (random splits) and frame count, and an error saying
/// what is wrong otherwise (damaged, truncated, another trajectory's file).
fn check_finished(
    path: &Path,
    index: usize,
    seed: Option<u64>,
    steps: usize,
) -> std::result::Result<bool, String> {
    if !path.exists() {
        return Ok(false);
    }
    let (t, _) = read_trajectory_and_stats(path).map_err(|e| e.to_string())?;
    if t.index != index {
        return Err(format!("it stores index {} instead of {index}", t.index));
    }
    if let Some(seed) = seed
        && t.seed != seed
    {
        return Err(format!("it stores seed {} instead of {seed}", t.seed));
    }
    if t.frames != steps + 1 {
        return Err(format!(
            "it has {} frames, this run makes {}",
            t.frames,
            steps + 1
        ));
    }
    Ok(true)
}

/// The trajectory files of the split folders of `out` whose index is at or past the split's
/// count in `counts` (or in a split `counts` does not list): `(split, index, count)`, sorted.
fn files_beyond(
    out: &Path,
    counts: &BTreeMap<String, usize>,
) -> Result<Vec<(String, usize, usize)>> {
    let mut beyond = Vec::new();
    for split in Split::ALL {
        let dir = out.join(split.name());
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        let count = counts.get(split.name()).copied().unwrap_or(0);
        for entry in entries {
            let entry = entry.with_context(|| format!("listing {}", dir.display()))?;
            if let Some(index) = entry
                .file_name()
                .to_str()
                .and_then(trajectory_index_from_file_name)
                && index >= count
            {
                beyond.push((split.name().to_string(), index, count));
            }
        }
    }
    beyond.sort();
    Ok(beyond)
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
        &options.scenes,
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
