//! `phi dataset generate`: parses the arguments into [`GenerateOptions`], calls
//! [`phi_dataset::generate`] with a progress bar on its callback, and reports what it did.
//! The library's documentation says how trajectories are drawn, sharded, resumed and replaced.

use std::ops::ControlFlow;
use std::path::PathBuf;

use anyhow::{Result, bail};
use clap::Args;
use indicatif::ProgressBar;
use phi_flip::{RandomSceneParams, SceneVariant};

use super::manifest::Shard;
use super::{GenerateEvent, GenerateOptions, Split, TestScenes};

/// `phi dataset generate --split`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum SplitChoice {
    /// Random scenes for training.
    Train,
    /// Random scenes from another seed.
    Valid,
    /// The hand-made test scenes.
    Test,
    /// Train, valid and test.
    All,
}

/// `phi dataset generate`.
#[derive(Debug, Args)]
pub struct GenerateArgs {
    /// The dataset directory.
    #[arg(long)]
    pub out: PathBuf,
    /// The split to make.
    #[arg(long, value_enum, default_value_t = SplitChoice::All)]
    pub split: SplitChoice,
    /// Trajectories per split (default: train 2000, valid 20, test 10; test has at most 10;
    /// --count before, deprecated).
    #[arg(long, alias = "count")]
    pub trajectories: Option<usize>,
    /// The dataset seed; each split and trajectory derives its own from it.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// `obstacles`, or `walls` (walls as a ring of obstacle particles).
    #[arg(long, default_value = "obstacles")]
    pub variant: SceneVariant,
    /// Table 5.1 as TOML (every key optional; unknown keys are errors).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Steps per trajectory (overrides the configuration; table: 400).
    #[arg(long)]
    pub steps: Option<usize>,
    /// Worker threads (default: one per core).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Make only the trajectories `i` with `i mod n = k` (0 <= k < n).
    #[arg(long, default_value = "0/1", value_name = "K/N")]
    pub shard: Shard,
    /// Continue in a directory whose generator.json differs or is missing.
    #[arg(long)]
    pub resume: bool,
    /// Delete trajectory files beyond --trajectories instead of refusing to run.
    #[arg(long)]
    pub prune: bool,
    /// Replace a dataset this command wrote in --out: its files are removed and every
    /// trajectory made again (a folder holding anything else is refused even then). Before,
    /// --force deleted only the trajectories beyond --trajectories: that is --prune now.
    #[arg(long, conflicts_with = "resume")]
    pub force: bool,
    /// Make the test split from the scene files (*.toml) of this folder, in name order, instead
    /// of the ten built-in ones; they share one domain size and time step, which become the
    /// dataset's. Only with --split test.
    #[arg(long, value_name = "DIR")]
    pub scenes: Option<PathBuf>,
    /// Stored units per cell [default: 0.8 / the longest side, which maps the domain onto
    /// [0.1, 0.9]]; 0.025 keeps the thesis' scale (x / 40 + 0.1) on larger domains.
    #[arg(long, value_name = "S")]
    pub position_scale: Option<f64>,
}

/// Runs `phi dataset generate` and prints a summary.
///
/// # Errors
/// Invalid arguments (a configuration or scene folder naming the file and key), and whatever
/// [`phi_dataset::generate`] reports.
pub fn run(args: GenerateArgs) -> Result<()> {
    let options = options(&args)?;
    let show = std::io::IsTerminal::is_terminal(&std::io::stderr());
    let mut bar: Option<ProgressBar> = None;
    let outcome = phi_dataset::generate(&options, |event| {
        match event {
            GenerateEvent::Planned { trajectories, .. } => {
                bar = Some(crate::progress::count_bar(
                    trajectories,
                    "trajectories",
                    show,
                ));
            }
            GenerateEvent::Written { .. } => {
                if let Some(bar) = &bar {
                    bar.inc(1);
                }
            }
        }
        ControlFlow::Continue(())
    });
    if let Some(bar) = bar {
        bar.finish_and_clear();
    }
    let summary = outcome?;
    let mut repaired = String::new();
    if summary.remade > 0 {
        repaired.push_str(&format!(
            ", remade {} damaged or foreign file(s)",
            summary.remade
        ));
    }
    if summary.stale_removed > 0 {
        repaired.push_str(&format!(
            ", removed {} stale temporary file(s)",
            summary.stale_removed
        ));
    }
    let shard = if options.shard.count > 1 {
        format!(
            " (shard {}; run `phi dataset merge` when all shards are done)",
            options.shard
        )
    } else {
        String::new()
    };
    println!(
        "{}: wrote {} ({}..{} particles), kept {} finished{repaired}, in {:.1} s{shard}",
        options.out.display(),
        trajectories(summary.written),
        summary.particles.0,
        summary.particles.1,
        summary.skipped,
        summary.seconds,
    );
    Ok(())
}

/// The library's options from the arguments: table 5.1 from `--config` with `--steps` applied,
/// the test scenes of `--scenes` (whose domain size and time step become the dataset's), the
/// memory limit of the environment.
///
/// # Errors
/// A configuration that cannot be read or is invalid, `--scenes` without `--split test`, a
/// configuration whose resolution or step disagrees with the scenes, a bad `--position-scale`.
pub fn options(args: &GenerateArgs) -> Result<GenerateOptions> {
    let splits = match args.split {
        SplitChoice::All => Split::ALL.to_vec(),
        SplitChoice::Train => vec![Split::Train],
        SplitChoice::Valid => vec![Split::Valid],
        SplitChoice::Test => vec![Split::Test],
    };
    let mut params = match &args.config {
        Some(path) => RandomSceneParams::from_file(path)?,
        None => RandomSceneParams::default(),
    };
    if let Some(steps) = args.steps {
        params.steps = steps;
        params.validate("--steps")?;
    }
    let scenes = match &args.scenes {
        None => TestScenes::builtin(),
        Some(dir) => {
            if splits != [Split::Test] {
                bail!(
                    "--scenes {} makes the test split; pass --split test",
                    dir.display()
                );
            }
            let scenes = TestScenes::from_dir(dir)?;
            let (resolution, dt) = scenes.domain()?;
            if let Some(path) = &args.config
                && (params.resolution != resolution || params.dt != dt)
            {
                bail!(
                    "{}: resolution {:?} and dt {} differ from the scenes of {} ({resolution:?}, \
                     {dt}); leave them out of the configuration",
                    path.display(),
                    params.resolution,
                    params.dt,
                    dir.display()
                );
            }
            params.resolution = resolution;
            params.dt = dt;
            scenes
        }
    };
    if let Some(scale) = args.position_scale
        && !(scale.is_finite() && scale > 0.0)
    {
        bail!("--position-scale {scale}: the stored units per cell must be a positive number");
    }
    let memory_limit = Some(crate::memory::memory_limit()?).filter(|&limit| limit != u64::MAX);
    Ok(GenerateOptions {
        out: args.out.clone(),
        splits,
        trajectories: args.trajectories,
        seed: args.seed,
        variant: args.variant,
        params,
        threads: args.threads,
        shard: args.shard,
        resume: args.resume,
        prune: args.prune,
        force: args.force,
        scenes,
        position_scale: args.position_scale,
        memory_limit,
    })
}

/// "1 trajectory", "2 trajectories".
pub fn trajectories(count: usize) -> String {
    if count == 1 {
        "1 trajectory".to_string()
    } else {
        format!("{count} trajectories")
    }
}
