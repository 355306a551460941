//! The `phi` command-line tool.

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};
use phi::backends::BackendKind;
use std::path::PathBuf;
use std::process::ExitCode;

use phi::demo::{self, DemoReport};
use phi::memory::shorten;
use phi::phi_flip::Scene;
use phi::simulate::{SimulateOptions, simulate};
use phi::{with_autodiff_backend, with_backend};

#[derive(Parser)]
#[command(
    name = "phi",
    version,
    about = "Differentiable liquid simulation and learned simulators",
    long_about = "Differentiable liquid simulation and learned simulators.\n\n\
                  Default backend: a command runs on ndarray, the first backend compiled in, \
                  unless --backend names another; the commands that need gradients (train, \
                  optimize) run on burn, the first compiled in with autodiff; simulate takes a \
                  scene's [run] backend before either, and demo runs on all. `phi backends` \
                  lists the backends of this build in that order. Devices: every command runs \
                  on the CPU, except train and rollout with --device cuda on tch in a build with \
                  CUDA, and the burn-wgpu backend, which runs on wgpu's default device (a GPU).",
    after_help = "Logging goes to stderr at level info; set RUST_LOG to change it, e.g. \
                  RUST_LOG=warn (quieter), RUST_LOG=debug, or RUST_LOG=phi_gns=debug (one crate). \
                  Progress bars are drawn only when stderr is a terminal, and not with -q."
)]
struct Cli {
    /// On an error, also print where in the program it arose (a backtrace).
    #[arg(short, long, global = true)]
    verbose: bool,
    /// Print results and errors only: no progress bars, and log warnings only (unless RUST_LOG
    /// is set).
    #[arg(short, long, global = true)]
    quiet: bool,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// List the backends compiled into this build.
    Backends,
    /// Run the same small tasks on every backend and check that they agree.
    Demo {
        /// Run on these backends only (default: all compiled in).
        #[arg(long, value_delimiter = ',')]
        backend: Vec<BackendKind>,
    },
    /// Simulate a scene file: trajectory (.npz), frames (PNG), an animated GIF and a summary.
    Simulate {
        /// The scene (TOML; see scenes/ for examples).
        scene: PathBuf,
        /// The output directory.
        #[arg(long)]
        out: PathBuf,
        /// The backend [default: the scene's `[run] backend`, else ndarray, as for every command
        /// without gradients].
        #[arg(long)]
        backend: Option<BackendKind>,
        /// The device; the CPU backends have only `cpu`.
        #[arg(long)]
        device: Option<String>,
        /// Run this many steps instead of the scene's.
        #[arg(long)]
        steps: Option<usize>,
        /// Render a frame (a PNG and a picture of the GIF) every this many steps (0: no
        /// frames). The default, 1, draws every step of a scene, whose runs are short; `phi
        /// render` draws a dataset's long trajectories every 2nd frame.
        #[arg(long, default_value_t = 1)]
        frame_every: usize,
        /// Pixels per grid cell in the frames.
        #[arg(long, default_value_t = 6)]
        pixels_per_cell: u32,
        /// Rewrite the trajectory file every this many steps, so a killed run keeps them.
        #[arg(long, default_value_t = 25)]
        checkpoint_every: usize,
        /// Write a VTK frame (vtk/frame_NNNNN.vtu, listed in simulation.pvd) every this many
        /// steps, for ParaView (0: none).
        #[arg(long, default_value_t = 0)]
        vtk_every: usize,
        /// Replace a previous run in --out (never anything else).
        #[arg(long)]
        force: bool,
        /// Refuse scenes estimated to need more memory than this (e.g. 8GiB; default: the
        /// machine's memory).
        #[arg(long, value_parser = phi::memory::parse_bytes)]
        memory_limit: Option<u64>,
    },
    /// Generate, merge and inspect FLIP datasets (thesis section 5.2).
    Dataset {
        #[command(subcommand)]
        command: phi::dataset::cli::DatasetCommand,
    },
    /// Render one trajectory of a dataset as an animated GIF.
    Render(phi::dataset::cli::RenderArgs),
    /// Optimise initial particle positions through the simulation to match a target (thesis 4.3).
    Optimize(phi::optimize::OptimizeArgs),
    /// Make Graph Network-based Simulator model directories.
    Model {
        #[command(subcommand)]
        command: phi::gns::init::ModelCommand,
    },
    /// Roll a GNS out on trajectories of a dataset: predictions, truth, per-frame MSE and a GIF
    /// of both side by side.
    Rollout(phi::gns::rollout::RolloutArgs),
    /// Train a GNS on a dataset with a preset of configs/gns/ (1s, 1sn, 1snb, 2ss, 2si):
    /// checkpoints, screening on the validation split, exact resume.
    Train(phi::gns::train::TrainArgs),
    /// Evaluate GNS models on a split as the thesis does (MSE-acc 1, MSE 20, MSE 400, EMD, and
    /// more): tables, plots and a GIF of their rollouts side by side.
    Eval(phi::gns::eval::EvalArgs),
}

#[global_allocator]
static ALLOCATOR: phi::allocator::Allocator = phi::allocator::Allocator;

fn main() -> ExitCode {
    phi::allocator::configure();
    die_quietly_on_broken_pipe();
    let cli = Cli::parse();
    if cli.verbose {
        // SAFETY: nothing else runs yet (no thread has been started), so no other code reads the
        // environment while it changes.
        unsafe { std::env::set_var("RUST_LIB_BACKTRACE", "1") };
    }
    phi::progress::set_quiet(cli.quiet);
    let level = if cli.quiet { "warn" } else { "info" };
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| level.into()),
        )
        .with_writer(std::io::stderr)
        .init();
    match run(cli.command) {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprint!("{}", error_report(&err, cli.verbose));
            ExitCode::FAILURE
        }
    }
}

/// Lets a closed standard output (`phi dataset stats --data D | head -1`) end the process as it
/// ends `cat` or `grep`: killed by SIGPIPE, status 141 in the shell, with nothing on stderr.
/// Rust ignores SIGPIPE, so that `println!` would meet the error EPIPE and panic instead. Every
/// file is written atomically (a temporary file renamed into place), so a process killed at a
/// `println!` leaves no half-written output; at worst a temporary file that the next run
/// removes or replaces.
fn die_quietly_on_broken_pipe() {
    #[cfg(unix)]
    // SAFETY: nothing else runs yet (no thread has been started), so no other code installs a
    // signal handler meanwhile; SIG_DFL is a valid disposition of SIGPIPE.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

/// The longest message of an error chain printed whole; longer ones (a value echoed from a
/// damaged file) are cut.
const MESSAGE_LIMIT: usize = 4096;

/// What a user sees of an error: the message and its causes, one a line, each cut at
/// [`MESSAGE_LIMIT`] bytes; with `-v` also the backtrace, where one was captured. A bad input is
/// not a bug in the program, so its backtrace is noise unless asked for (`RUST_BACKTRACE` in the
/// environment alone does not print it; panics, which are bugs, print theirs as usual).
fn error_report(err: &anyhow::Error, verbose: bool) -> String {
    let mut report = String::new();
    let mut causes = err.chain();
    if let Some(top) = causes.next() {
        report.push_str(&format!(
            "Error: {}\n",
            shorten(&top.to_string(), MESSAGE_LIMIT)
        ));
    }
    let causes: Vec<String> = causes
        .map(|c| shorten(&c.to_string(), MESSAGE_LIMIT))
        .collect();
    if !causes.is_empty() {
        report.push_str("\nCaused by:\n");
        for (i, cause) in causes.iter().enumerate() {
            report.push_str(&format!("    {i}: {cause}\n"));
        }
    }
    if verbose {
        let backtrace = err.backtrace();
        if backtrace.status() == std::backtrace::BacktraceStatus::Captured {
            report.push_str(&format!("\nBacktrace:\n{backtrace}\n"));
        }
    }
    report
}

fn run(command: Command) -> Result<()> {
    match command {
        Command::Backends => {
            for kind in BackendKind::available() {
                let autodiff = if kind.has_autodiff() {
                    "autodiff"
                } else {
                    "forward only"
                };
                println!("{kind:<10} {autodiff}");
            }
            Ok(())
        }
        Command::Demo { backend } => run_demo(if backend.is_empty() {
            BackendKind::available()
        } else {
            backend
        }),
        Command::Simulate {
            scene,
            out,
            backend,
            device,
            steps,
            frame_every,
            pixels_per_cell,
            checkpoint_every,
            vtk_every,
            force,
            memory_limit,
        } => run_simulate(
            SimulateOptions {
                scene,
                out,
                frame_every,
                checkpoint_every,
                pixels_per_cell,
                steps,
                vtk_every,
                progress: std::io::IsTerminal::is_terminal(&std::io::stderr()),
                force,
                memory_limit,
            },
            backend,
            device,
        ),
        Command::Dataset { command } => phi::dataset::cli::run(command),
        Command::Render(args) => phi::dataset::cli::render(args),
        Command::Optimize(args) => phi::optimize::run(args),
        Command::Model { command } => phi::gns::init::run(command),
        Command::Rollout(args) => phi::gns::rollout::run(args),
        Command::Train(args) => phi::gns::train::run(args),
        Command::Eval(args) => phi::gns::eval::run(args),
    }
}

fn run_simulate(
    options: SimulateOptions,
    backend: Option<BackendKind>,
    device: Option<String>,
) -> Result<()> {
    let scene = Scene::from_file(&options.scene)?;
    let kind = match (backend, &scene.run.backend) {
        (Some(kind), _) => kind,
        (None, Some(name)) => name
            .parse()
            .with_context(|| format!("{}: run.backend", options.scene.display()))?,
        (None, None) => BackendKind::default_forward(),
    };
    if let Some(device) = device.as_deref().or(scene.run.device.as_deref())
        && device != "cpu"
    {
        let runs_on = if kind.name() == "burn-wgpu" {
            "wgpu's default adapter"
        } else {
            "the CPU"
        };
        bail!(
            "device `{device}` is not available: `phi simulate` runs the {kind} backend on \
             {runs_on}, whatever the device; pass --device cpu or leave it out"
        );
    }
    println!(
        "{}: {}",
        options.scene.display(),
        scene.description.as_deref().unwrap_or("(no description)")
    );
    let summary = with_backend!(kind, B => simulate::<B>(&scene, &options))?;
    println!(
        "{} steps of {} particles on {} in {:.2} s: {:.1} steps/s ({:.3} ms/step); pressure solve: \
         {:.1} iterations on average, {} at most; largest step {:.2} cells, CFL number {:.2} at \
         most ({} sub-steps)",
        summary.steps,
        summary.particles,
        summary.backend,
        summary.simulation_seconds,
        summary.steps_per_second,
        1e3 / summary.steps_per_second,
        summary.solver_iterations_mean,
        summary.solver_iterations_max,
        summary.max_displacement_cells,
        summary.cfl_max,
        summary.substeps,
    );
    println!(
        "wrote {}/trajectory.npz, run.json{}{}",
        options.out.display(),
        if summary.frames > 0 {
            format!(", {} frames and simulation.gif", summary.frames)
        } else {
            String::new()
        },
        if options.vtk_every > 0 {
            ", simulation.pvd and vtk/"
        } else {
            ""
        }
    );
    Ok(())
}

fn run_demo(kinds: Vec<BackendKind>) -> Result<()> {
    println!(
        "Binning {} particles into a {g}×{g} grid (scatter-add), and inverting a 20-step ballistic \
         integration by gradient descent (autodiff backends).\n",
        demo::PARTICLES,
        g = demo::GRID
    );
    let mut reports: Vec<DemoReport> = Vec::new();
    for kind in kinds {
        let report = with_autodiff_backend!(kind, B => demo::run_autodiff::<B>(),
            otherwise => with_backend!(kind, B => demo::run_forward::<B>()))
        .with_context(|| format!("the demo failed on backend {kind}"))?;
        reports.push(report);
    }
    let reference = &reports[0];
    println!(
        "{:<10} {:>12} {:>10} {:>24} {:>24} {:>6} {:>10}",
        "backend", "binning", "agrees", "launch velocity found", "exact", "iters", "descent"
    );
    let mut disagreements = 0;
    for report in &reports {
        let agrees = report.cell_counts == reference.cell_counts;
        disagreements += usize::from(!agrees);
        let total: f32 = report.cell_counts.iter().sum();
        if total != demo::PARTICLES as f32 {
            bail!(
                "{}: binned {total} particles instead of {}",
                report.backend,
                demo::PARTICLES
            );
        }
        let (found, exact, iterations, seconds) = match &report.ballistics {
            Some(b) => (
                format!("({:.4}, {:.4})", b.found[0], b.found[1]),
                format!("({:.4}, {:.4})", b.exact[0], b.exact[1]),
                b.iterations.to_string(),
                format!("{:.1} ms", b.seconds * 1e3),
            ),
            None => (
                "(no autodiff)".into(),
                String::new(),
                String::new(),
                String::new(),
            ),
        };
        println!(
            "{:<10} {:>9.1} ms {:>10} {found:>24} {exact:>24} {iterations:>6} {seconds:>10}",
            report.backend,
            report.binning_seconds * 1e3,
            if agrees { "yes" } else { "NO" },
        );
    }
    if disagreements > 0 {
        bail!(
            "{disagreements} backend(s) binned particles differently from {}",
            reference.backend
        );
    }
    println!("\nAll {} backends agree on every cell.", reports.len());
    Ok(())
}
