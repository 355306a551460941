//! `phi train`: a GNS trained on a dataset with a preset of `configs/gns/` (thesis section 5.3).
//!
//! The run lives in `--out` (see [`phi_gns::train::run`] for its files). `--steps N` is the
//! total step count, so a run resumed with the same `N` ends where an uninterrupted one would.
//! SIGINT and SIGTERM end the current step, write a checkpoint and stop; `--resume` continues
//! from the newest checkpoint, with the same loss curve as an uninterrupted run (same backend,
//! same thread count).

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use phi_core::AutodiffBackend;
use phi_gns::model::GnsKernels;
use phi_gns::train::config::SelectBy;
use phi_gns::train::options::{Overrides, RunSource};
use phi_gns::train::run::{RunOptions, TrainingRun};

use crate::backends::BackendKind;

/// `phi train --data DATASET --config PRESET --out DIR [options]`.
#[derive(Debug, Clone, clap::Args)]
pub struct TrainArgs {
    /// The dataset directory (with --resume: the run's, by default).
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// The preset (configs/gns/*.toml; with --resume: the run's config.toml, by default).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// The training directory.
    #[arg(long)]
    pub out: PathBuf,
    /// The backend: one with autodiff [default: burn, else the first with autodiff compiled in,
    /// as for every command that needs gradients].
    #[arg(long)]
    pub backend: Option<BackendKind>,
    /// The device: cpu, or cuda / cuda:N on the tch backend of a `--features tch,cuda` build.
    #[arg(long, default_value = "cpu")]
    pub device: String,
    /// The total number of steps (overrides training.steps).
    #[arg(long)]
    pub steps: Option<u64>,
    /// Continue the run in --out from its newest checkpoint.
    #[arg(long)]
    pub resume: bool,
    /// Start from the weights of this model directory (2si starts from a 1s model).
    #[arg(long, conflicts_with = "resume")]
    pub init_from: Option<PathBuf>,
    /// Graphs per batch (overrides training.batch_size).
    #[arg(long)]
    pub batch_size: Option<usize>,
    /// The seed of the data and noise draws (overrides training.seed).
    #[arg(long)]
    pub seed: Option<u64>,
    /// σ of the training noise (overrides model.noise_std).
    #[arg(long)]
    pub noise_std: Option<f64>,
    /// Extra steps n of the multi-step loss (overrides training.extra_steps).
    #[arg(long)]
    pub extra_steps: Option<usize>,
    /// A row of train.csv every this many steps (overrides training.log_every).
    #[arg(long)]
    pub log_every: Option<u64>,
    /// A checkpoint every this many steps (overrides checkpoints.every).
    #[arg(long)]
    pub checkpoint_every: Option<u64>,
    /// Screen the validation split every this many steps, 0 for never (overrides
    /// screening.every).
    #[arg(long)]
    pub screen_every: Option<u64>,
    /// The EMD of every this many predicted frames of the screening rollouts, 0 for none
    /// (overrides screening.emd_every; may change on --resume).
    #[arg(long)]
    pub emd_every: Option<usize>,
    /// The screening metric that picks best/: mse_acc1, rollout_mse or emd (overrides
    /// screening.select_by; may change on --resume, and the next screening then starts the
    /// best afresh).
    #[arg(long)]
    pub select_by: Option<SelectBy>,
    /// Keep a moving average of the weights with this decay, e.g. 0.999, screened and kept
    /// in best/ and each checkpoint's average/ (overrides training.ema_decay; may be switched
    /// on with --resume, starting from the checkpoint's weights).
    #[arg(long)]
    pub ema_decay: Option<f64>,
}

/// The run `args` ask for: the preset and dataset (of a new run, or the resumed run's own
/// unless given) with the command line's overrides.
fn resolve(args: &TrainArgs) -> Result<RunOptions> {
    let source = if args.resume {
        RunSource::Resume {
            preset: args.config.clone(),
            data: args.data.clone(),
        }
    } else {
        let Some(preset) = args.config.clone() else {
            bail!("--config PRESET is needed for a new run (e.g. configs/gns/cpu/1sn.toml)");
        };
        let Some(data) = args.data.clone() else {
            bail!("--data DATASET is needed for a new run");
        };
        RunSource::New {
            preset,
            data,
            init_from: args.init_from.clone(),
        }
    };
    let overrides = Overrides {
        steps: args.steps,
        batch_size: args.batch_size,
        seed: args.seed,
        noise_std: args.noise_std,
        extra_steps: args.extra_steps,
        log_every: args.log_every,
        checkpoint_every: args.checkpoint_every,
        screen_every: args.screen_every,
        emd_every: args.emd_every,
        select_by: args.select_by,
        ema_decay: args.ema_decay,
    };
    let options = RunOptions::resolve(args.out.clone(), source, &overrides);
    if args.resume {
        options.context("--resume")
    } else {
        Ok(options?)
    }
}

/// Runs `phi train`.
///
/// # Errors
/// Bad options or presets (naming the key), datasets the configuration does not fit, output
/// directories that hold something else, a diverged run (naming the step), an interrupted run
/// (after its checkpoint is written), I/O errors.
pub fn run(args: TrainArgs) -> Result<()> {
    let options = resolve(&args)?;
    let stop = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&stop);
    ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst))
        .context("cannot install the SIGINT/SIGTERM handler")?;
    let kind = match args.backend {
        Some(kind) => kind,
        None => BackendKind::default_autodiff()
            .context("no backend with autodiff is compiled into this build")?,
    };
    crate::with_autodiff_backend!(kind, B => train::<B>(&options, &args.device, &stop),
        otherwise => bail!("the {kind} backend has no autodiff and cannot train; {}", BackendKind::autodiff_hint()))
}

/// The devices `--device` takes on a backend of this build, for the message that refuses another.
/// A build without the `cuda` feature leaves libtorch's CUDA library unlinked (see build.rs), so
/// its tch backend sees no CUDA device even on a GPU machine.
pub(crate) fn devices_hint(backend: &str) -> &'static str {
    match backend {
        "tch" if cfg!(feature = "cuda") => {
            "cpu, or cuda / cuda:N where libtorch sees that CUDA device"
        }
        "tch" => {
            "cpu only: this build links libtorch without CUDA; build with `--features tch,cuda`"
        }
        _ => "cpu",
    }
}

fn train<B: AutodiffBackend + GnsKernels>(
    options: &RunOptions,
    device: &str,
    stop: &AtomicBool,
) -> Result<()> {
    let Some(device) = B::device_by_name(device) else {
        bail!(
            "--device {device}: not available on the {} backend of this build ({})",
            B::name(),
            devices_hint(B::name())
        );
    };
    let mut run = TrainingRun::<B>::open(options, &device)?;
    let total = run.config().training.steps;
    let first = run.step();
    if first >= total {
        println!(
            "{}: at step {first}, the total of {total} steps is reached: nothing to train",
            options.out.display()
        );
        return Ok(());
    }
    println!(
        "{}: training {} on {} ({}), steps {first} → {total}, into {}",
        options.preset,
        run.config().description,
        options.data.display(),
        B::name(),
        options.out.display()
    );
    let bar = crate::progress::step_bar(
        usize::try_from(total).unwrap_or(usize::MAX),
        std::io::IsTerminal::is_terminal(&std::io::stderr()),
    );
    bar.set_position(first);
    let started = Instant::now();
    while run.step() < total {
        if stop.load(Ordering::SeqCst) {
            let dir = run.checkpoint()?;
            bar.abandon();
            bail!(
                "interrupted at step {}: checkpoint {}; continue with `phi train --resume --out {}`",
                run.step(),
                dir.display(),
                options.out.display()
            );
        }
        let report = run.train_step()?;
        bar.set_position(report.step);
        bar.set_message(format!(
            "loss {:.4e}, lr {:.2e}",
            report.loss, report.learning_rate
        ));
    }
    bar.finish_and_clear();
    let seconds = started.elapsed().as_secs_f64();
    let steps = total - first;
    println!(
        "{steps} steps in {seconds:.1} s ({:.2} steps/s); best screening: {}",
        steps as f64 / seconds.max(1e-9),
        run.best().map_or("none".to_string(), |b| format!(
            "{:.4e} at step {} ({}/best)",
            b.value,
            b.step,
            options.out.display()
        ))
    );
    println!(
        "wrote {}/train.csv and checkpoints/step-{total:010}",
        options.out.display()
    );
    Ok(())
}
