//! The `phi` command-line tool.

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};
use phi::backends::BackendKind;
use phi::demo::{self, DemoReport};
use phi::{with_autodiff_backend, with_backend};

#[derive(Parser)]
#[command(
    name = "phi",
    version,
    about = "Differentiable liquid simulation and learned simulators"
)]
struct Cli {
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
}

fn main() -> Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "info".into()),
        )
        .with_writer(std::io::stderr)
        .init();
    match Cli::parse().command {
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
    }
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
