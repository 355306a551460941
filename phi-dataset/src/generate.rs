//! Generating a dataset: the trajectories of its splits simulated in parallel, resumable and
//! shardable, with the progress reported to a callback.
//!
//! Trajectories are independent jobs on a rayon pool ([`GenerateOptions::threads`]); each
//! simulation runs on one thread on the host backend (`phi_core::backend::Host`: ndarray).
//! Trajectory `i` of a split is drawn from [`trajectory_seed`]`(split seed, i)`, so the bytes of
//! every file are the same whatever the thread count, sharding ([`Shard`] `k/n` takes the
//! indices `i ≡ k mod n`) or order of completion. Files are written atomically (temporary
//! file, then rename): a killed run loses only the trajectories in flight, and running the same
//! options again skips every finished file. `generator.json` ([`MANIFEST`]), written before the
//! first trajectory, records the configuration, so a directory holding another configuration's
//! files is refused (unless [`GenerateOptions::resume`]). [`GenerateOptions::force`] replaces a
//! dataset this function wrote ([`GENERATE_OUTPUTS`]): its files are removed and every
//! trajectory made again; [`GenerateOptions::prune`] deletes only the trajectories beyond the
//! count asked for.
//!
//! ```
//! use std::ops::ControlFlow;
//! use phi_dataset::{GenerateEvent, GenerateOptions, Split, generate};
//!
//! let out = std::env::temp_dir().join(format!("phi-dataset-doc-{}", std::process::id()));
//! # let _ = std::fs::remove_dir_all(&out);
//! let mut options = GenerateOptions::new(&out);
//! options.splits = vec![Split::Train];
//! options.trajectories = Some(2);
//! options.params.steps = 3;
//! let mut written = 0;
//! let summary = generate(&options, |event| {
//!     if let GenerateEvent::Written { .. } = event {
//!         written += 1;
//!     }
//!     ControlFlow::Continue(())
//! })?;
//! assert_eq!((summary.written, written), (2, 2));
//! assert!(out.join("train/traj_00001.npz").is_file() && out.join("metadata.json").is_file());
//! // The same options again keep every finished file.
//! let again = generate(&options, |_| ControlFlow::Continue(()))?;
//! assert_eq!((again.written, again.skipped), (0, 2));
//! # std::fs::remove_dir_all(&out).unwrap();
//! # Ok::<(), phi_dataset::DatasetError>(())
//! ```

use std::collections::BTreeMap;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use phi_flip::{RandomSceneParams, SceneVariant};
use phi_gns::data::{
    LIQUID, METADATA_FILE, OBSTACLE, Trajectory, TrajectoryStats, read_trajectory_and_stats,
    trajectory_file_name, trajectory_index_from_file_name, write_trajectory,
};
use phi_io::output_dir::OutputDir;
use rayon::prelude::*;

use crate::manifest::{
    GENERATE_OUTPUTS, GeneratorConfig, MANIFEST, Manifest, Shard, read_generator, read_manifest,
    write_dataset_metadata, write_manifest,
};
use crate::{
    DatasetError, Result, Split, TestScenes, position_scale, simulate_trajectory, trajectory_seed,
};

/// What to generate, and how. [`GenerateOptions::new`] gives the thesis' dataset (table 5.1,
/// every split, seed 0) in a directory; set the fields to change it.
#[derive(Debug, Clone)]
pub struct GenerateOptions {
    /// The dataset directory.
    pub out: PathBuf,
    /// The splits to make.
    pub splits: Vec<Split>,
    /// Trajectories per split (`None`: the thesis' 2000, 20 and 10, or the counts an earlier
    /// run recorded; the test split has at most one per test scene).
    pub trajectories: Option<usize>,
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
    /// The most memory the run's bookkeeping may take, bytes (`None`: no limit): a count of
    /// trajectories too large for it is refused before anything is written.
    pub memory_limit: Option<u64>,
}

impl GenerateOptions {
    /// The thesis' dataset in `out`: every split at the thesis' counts, seed 0, the obstacles
    /// variant, table 5.1, the built-in test scenes, one shard, every core.
    pub fn new(out: impl Into<PathBuf>) -> Self {
        GenerateOptions {
            out: out.into(),
            splits: Split::ALL.to_vec(),
            trajectories: None,
            seed: 0,
            variant: SceneVariant::Obstacles,
            params: RandomSceneParams::default(),
            threads: None,
            shard: Shard::default(),
            resume: false,
            prune: false,
            force: false,
            scenes: TestScenes::builtin(),
            position_scale: None,
            memory_limit: None,
        }
    }
}

/// What a run reports to its progress callback.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GenerateEvent {
    /// Before the first simulation: the trajectories to simulate, the finished ones kept, and
    /// how many of those to simulate replace damaged or foreign files.
    Planned {
        /// Trajectories to simulate.
        trajectories: usize,
        /// Finished files kept.
        kept: usize,
        /// Files to make again.
        remade: usize,
    },
    /// One trajectory simulated and written (from a worker thread, in completion order).
    Written {
        /// Its split.
        split: Split,
        /// Its index in the split.
        index: usize,
        /// Its particles.
        particles: usize,
    },
}

/// What a run did.
#[derive(Debug, Clone, Default, PartialEq)]
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

/// One trajectory to make.
struct Job {
    split: Split,
    index: usize,
    seed: u64,
    path: PathBuf,
}

/// Generates the dataset described by `options`, then writes `metadata.json` (an unsharded
/// run). `progress` hears of the plan and of every trajectory written; returning
/// [`ControlFlow::Break`] stops the run after the trajectories in flight (their files are
/// kept, so the same options continue from them).
///
/// # Errors
/// A directory holding another dataset or files beyond the count asked for, invalid options,
/// a count too large for [`GenerateOptions::memory_limit`], a failing simulation (naming the
/// split, index and seed), a stop asked for by `progress`, I/O errors naming the file.
pub fn generate(
    options: &GenerateOptions,
    progress: impl FnMut(GenerateEvent) -> ControlFlow<()> + Send,
) -> Result<GenerateSummary> {
    let started = Instant::now();
    let out = &options.out;
    OutputDir::check_not_a_file(out, GENERATE_OUTPUTS.flag)?;
    let config = GeneratorConfig::new(
        options.variant,
        options.seed,
        options.params.clone(),
        &options.scenes,
        options.position_scale,
    );
    // With `force` the previous dataset is replaced: checked here, removed once this run has
    // passed its own checks.
    let mut dir = if options.force {
        if options.resume {
            return Err(DatasetError::Options(
                "--force replaces the dataset in --out, --resume continues it: pass one".into(),
            ));
        }
        OutputDir::claim(out, &GENERATE_OUTPUTS, true)?
    } else {
        check_compatible(out, &config, options.shard, options.resume)?;
        OutputDir::adopt(out, &GENERATE_OUTPUTS)
    };
    let counts = split_counts(options, !options.force)?;
    check_bookkeeping_memory(options, &counts)?;
    dir.clear_previous()?;
    let beyond = files_beyond(out, &counts)?;
    if let Some((split, index, count)) = beyond.first()
        && !options.prune
    {
        let last = beyond.iter().map(|b| b.1).max().unwrap_or(*index);
        return Err(DatasetError::Directory {
            path: out.clone(),
            reason: format!(
                "holds {split}/{} beyond the {count} {split} trajectories asked for ({} such \
                 file(s)); pass --trajectories {} or more to keep and extend them, --prune to \
                 delete them, or --force to replace the whole dataset",
                trajectory_file_name(*index),
                beyond.len(),
                last + 1
            ),
        });
    }
    let stale = dir.remove_stale_temp_files()?;
    for path in &stale {
        tracing::info!("removed {}, left by a killed run", path.display());
    }
    remove_beyond(out, &beyond)?;
    for split in &options.splits {
        let path = out.join(split.name());
        std::fs::create_dir_all(&path).map_err(|e| DatasetError::io(&path, "creating", e))?;
    }
    write_manifest(
        out,
        &Manifest {
            config: config.clone(),
            shard: options.shard,
            counts: counts.clone(),
        },
    )?;

    let (jobs, skipped, remade) = plan_jobs(options, &counts);
    let particles = run_jobs(options, &jobs, (skipped, remade), progress)?;
    write_dataset_metadata(out, &config, &counts, options.shard)?;
    Ok(GenerateSummary {
        written: jobs.len(),
        skipped,
        remade,
        stale_removed: stale.len(),
        seconds: started.elapsed().as_secs_f64(),
        particles: (
            particles.iter().copied().min().unwrap_or(0),
            particles.iter().copied().max().unwrap_or(0),
        ),
    })
}

/// Trajectories per split name: the options' splits at their count, and, where `keep_earlier`,
/// the splits an earlier run's manifest asked for that this run does not make.
fn split_counts(options: &GenerateOptions, keep_earlier: bool) -> Result<BTreeMap<String, usize>> {
    let mut counts = BTreeMap::new();
    for &split in &options.splits {
        let mut count = options.trajectories.unwrap_or(split.default_count());
        if split == Split::Test {
            count = count.min(options.scenes.len());
        }
        counts.insert(split.name().to_string(), count);
    }
    if keep_earlier && let Some(manifest) = read_manifest(&options.out)? {
        for (split, count) in manifest.counts {
            counts.entry(split).or_insert(count);
        }
    }
    Ok(counts)
}

/// Refuses counts whose job list alone would not fit [`GenerateOptions::memory_limit`].
fn check_bookkeeping_memory(
    options: &GenerateOptions,
    counts: &BTreeMap<String, usize>,
) -> Result<()> {
    let Some(limit) = options.memory_limit else {
        return Ok(());
    };
    let trajectories: u128 = options
        .splits
        .iter()
        .map(|s| counts[s.name()] as u128 / options.shard.count as u128 + 1)
        .sum();
    let job_bytes = (std::mem::size_of::<Job>() + 64 + options.out.as_os_str().len()) as u128;
    let needed = trajectories * job_bytes;
    if needed > u128::from(limit) {
        return Err(DatasetError::Memory {
            trajectories,
            asked_by: if options.trajectories.is_some() {
                "--trajectories"
            } else {
                "the counts of generator.json"
            },
            needed,
            limit,
        });
    }
    Ok(())
}

/// Deletes the trajectory files `beyond` the counts (`--prune`), `metadata.json` first.
fn remove_beyond(out: &Path, beyond: &[(String, usize, usize)]) -> Result<()> {
    if beyond.is_empty() {
        return Ok(());
    }
    // Without metadata.json the directory is an unfinished dataset until this run ends, so a
    // kill cannot leave metadata that lists files that are gone.
    let metadata = out.join(METADATA_FILE);
    if metadata.exists() {
        std::fs::remove_file(&metadata).map_err(|e| DatasetError::io(&metadata, "removing", e))?;
    }
    for (split, index, _) in beyond {
        let path = out.join(split).join(trajectory_file_name(*index));
        std::fs::remove_file(&path).map_err(|e| DatasetError::io(&path, "removing", e))?;
    }
    Ok(())
}

/// The trajectories of this shard still to make, with the finished files kept and the
/// damaged ones to make again counted.
fn plan_jobs(
    options: &GenerateOptions,
    counts: &BTreeMap<String, usize>,
) -> (Vec<Job>, usize, usize) {
    let steps = options.params.steps;
    let (mut jobs, mut skipped, mut remade) = (Vec::new(), 0, 0);
    for &split in &options.splits {
        let split_seed = split.seed(options.seed);
        for index in (0..counts[split.name()]).filter(|&i| options.shard.holds(i)) {
            let seed = match split {
                Split::Test => 0,
                _ => trajectory_seed(split_seed, index),
            };
            let path = options
                .out
                .join(split.name())
                .join(trajectory_file_name(index));
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
    (jobs, skipped, remade)
}

/// Makes `jobs` on the options' thread pool, telling `progress`; returns each one's particle
/// count.
fn run_jobs(
    options: &GenerateOptions,
    jobs: &[Job],
    (kept, remade): (usize, usize),
    mut progress: impl FnMut(GenerateEvent) -> ControlFlow<()> + Send,
) -> Result<Vec<usize>> {
    let stop = AtomicBool::new(false);
    let planned = GenerateEvent::Planned {
        trajectories: jobs.len(),
        kept,
        remade,
    };
    if progress(planned).is_break() {
        stop.store(true, Ordering::Relaxed);
    }
    let progress = Mutex::new(progress);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(options.threads.unwrap_or(0))
        .build()
        .map_err(|e| DatasetError::Options(format!("starting the worker threads: {e}")))?;
    let (scale, offset) = position_scale(options.params.resolution, options.position_scale);
    let made: Vec<Option<usize>> = pool.install(|| {
        jobs.par_iter()
            .map(|job| {
                if stop.load(Ordering::Relaxed) {
                    return Ok(None);
                }
                let particles = make_trajectory(job, options, scale, offset).map_err(|e| {
                    DatasetError::Trajectory {
                        split: job.split,
                        index: job.index,
                        seed: job.seed,
                        source: Box::new(e),
                    }
                })?;
                let event = GenerateEvent::Written {
                    split: job.split,
                    index: job.index,
                    particles,
                };
                let mut progress = progress.lock().unwrap_or_else(|e| e.into_inner());
                if progress(event).is_break() {
                    stop.store(true, Ordering::Relaxed);
                }
                Ok(Some(particles))
            })
            .collect::<Result<_>>()
    })?;
    let particles: Vec<usize> = made.iter().flatten().copied().collect();
    if particles.len() < jobs.len() {
        return Err(DatasetError::Stopped {
            written: particles.len(),
            planned: jobs.len(),
        });
    }
    Ok(particles)
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
    let refuse = |reason: String| {
        Err(DatasetError::Directory {
            path: out.to_path_buf(),
            reason,
        })
    };
    match stored {
        Some((value, stored_shard)) => {
            let differences = config.differences(&value);
            if !differences.is_empty() && !resume {
                return refuse(format!(
                    "holds a dataset generated with another configuration (differing keys: \
                     {}); {hint}",
                    differences.join(", ")
                ));
            }
            if let Some(s) = stored_shard
                && s != shard
                && !resume
            {
                return refuse(format!("holds shard {s}, not shard {shard}; {hint}"));
            }
        }
        None => {
            if let Some(first) = first_entry(out)?
                && !resume
            {
                return refuse(format!(
                    "is not empty (it holds '{first}') and holds no phi dataset ({MANIFEST} or \
                     metadata.json); choose another --out, or pass --resume to continue in it \
                     anyway"
                ));
            }
        }
    }
    Ok(())
}

/// The first name in `dir` in sorted order; `None` for an empty or missing folder.
fn first_entry(dir: &Path) -> Result<Option<String>> {
    if !dir.is_dir() {
        return Ok(None);
    }
    let mut names = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(|e| DatasetError::io(dir, "reading", e))? {
        let entry = entry.map_err(|e| DatasetError::io(dir, "reading", e))?;
        names.push(entry.file_name().to_string_lossy().into_owned());
    }
    Ok(names.into_iter().min())
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
            let entry = entry.map_err(|e| DatasetError::io(&dir, "listing", e))?;
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::temp_dir;

    fn options(out: &Path, threads: usize) -> GenerateOptions {
        let mut options = GenerateOptions::new(out);
        options.splits = vec![Split::Train, Split::Valid];
        options.trajectories = Some(3);
        options.params.steps = 2;
        options.threads = Some(threads);
        options
    }

    fn continue_always(_: GenerateEvent) -> ControlFlow<()> {
        ControlFlow::Continue(())
    }

    /// Every file of `dir`, by path relative to it, with its bytes.
    fn snapshot(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
        let mut files = Vec::new();
        let mut stack = vec![dir.to_path_buf()];
        while let Some(d) = stack.pop() {
            for entry in std::fs::read_dir(&d).unwrap() {
                let path = entry.unwrap().path();
                if path.is_dir() {
                    stack.push(path);
                } else {
                    let bytes = std::fs::read(&path).unwrap();
                    files.push((path.strip_prefix(dir).unwrap().to_path_buf(), bytes));
                }
            }
        }
        files.sort();
        files
    }

    #[test]
    fn a_stopped_run_continues_to_the_bytes_of_an_uninterrupted_one() {
        let dir = temp_dir("stop-resume");
        let whole = dir.join("whole");
        let summary = generate(&options(&whole, 2), continue_always).unwrap();
        assert_eq!((summary.written, summary.skipped), (6, 0));

        let parts = dir.join("parts");
        let mut events = Vec::new();
        let error = generate(&options(&parts, 1), |event| {
            events.push(event);
            match event {
                GenerateEvent::Written { .. } => ControlFlow::Break(()),
                GenerateEvent::Planned { .. } => ControlFlow::Continue(()),
            }
        })
        .unwrap_err();
        assert!(
            matches!(
                error,
                DatasetError::Stopped {
                    written: 1,
                    planned: 6
                }
            ),
            "{error}"
        );
        assert_eq!(
            events[0],
            GenerateEvent::Planned {
                trajectories: 6,
                kept: 0,
                remade: 0
            }
        );
        assert!(!parts.join(METADATA_FILE).exists());
        let rest = generate(&options(&parts, 3), continue_always).unwrap();
        assert_eq!((rest.written, rest.skipped), (5, 1));
        assert_eq!(snapshot(&parts), snapshot(&whole));
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn refusals_name_the_folder_and_the_way_out() {
        let dir = temp_dir("refusals");
        let mut both = options(&dir.join("a"), 1);
        both.force = true;
        both.resume = true;
        let error = generate(&both, continue_always).unwrap_err().to_string();
        assert!(
            error.contains("--force") && error.contains("--resume"),
            "{error}"
        );

        std::fs::write(dir.join("notes.txt"), "mine").unwrap();
        let error = generate(&options(&dir, 1), continue_always)
            .unwrap_err()
            .to_string();
        assert!(
            error.contains("'notes.txt'") && error.contains("--resume"),
            "{error}"
        );
        let mut forced = options(&dir, 1);
        forced.force = true;
        let error = generate(&forced, continue_always).unwrap_err().to_string();
        assert!(error.contains("does not write"), "{error}");
        assert_eq!(std::fs::read(dir.join("notes.txt")).unwrap(), b"mine");

        let mut huge = options(&dir.join("b"), 1);
        huge.trajectories = Some(1 << 40);
        huge.memory_limit = Some(1 << 20);
        let error = generate(&huge, continue_always).unwrap_err().to_string();
        assert!(
            error.contains("--trajectories") && error.contains("more than the limit of 1.0 MiB"),
            "{error}"
        );
        assert!(!dir.join("b").exists());
        let _ = std::fs::remove_dir_all(dir);
    }
}
