//! `phi dataset generate`: parses the arguments into [`GenerateOptions`], calls
//! [`phi_dataset::generate`] with a progress bar on its callback, and reports what it did.
//! The library's documentation says how trajectories are drawn, sharded, resumed and replaced.

use std::ops::ControlFlow;

use anyhow::{Result, bail};
use indicatif::ProgressBar;
use phi_flip::RandomSceneParams;

use super::cli::{GenerateArgs, SplitChoice, trajectories};
use super::{GenerateEvent, GenerateOptions, Split, TestScenes};

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
