//! [`RunTotals`]: what the steps of a run add up to (solver work, the largest CFL number and
//! displacement, the time spent stepping), kept as a run goes, for its summary.
//!
//! ```
//! use phi_core::Backend;
//! use phi_core::backend::ndarray::NdArray;
//! use phi_flip::{RunTotals, Scene, SceneRun};
//!
//! let scene = Scene::from_toml(
//!     r#"
//!     [domain]
//!     resolution = [8, 8]
//!     [simulation]
//!     dt = 0.05
//!     steps = 3
//!     [[liquid]]
//!     geometry = { type = "box", lower = [1, 1], upper = [4, 4] }
//!     "#,
//!     "<string>",
//! )?;
//! let mut run = SceneRun::<NdArray>::new(&scene, "<string>", &NdArray::default_device())?;
//! let mut totals = RunTotals::default();
//! for _ in 0..3 {
//!     run.step_counted(&mut totals)?;
//! }
//! assert_eq!(totals.steps, 3);
//! assert!(totals.substeps >= 3 && totals.cfl_max > 0.0);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use std::time::Instant;

use phi_core::fields::LatticeKernels;

use crate::Result;
use crate::record::SceneRun;
use crate::sim::StepStats;

/// The totals of a run's steps so far.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RunTotals {
    /// Steps completed.
    pub steps: usize,
    /// Wall time of the steps alone (no output), seconds.
    pub seconds: f64,
    /// Iterations of the pressure solves, summed (0 for direct solves).
    pub solver_iterations: usize,
    /// The largest iteration count of one solve.
    pub solver_iterations_max: usize,
    /// The largest absolute residual `‖b − A x‖₂` of the solves.
    pub solver_residual_max: f64,
    /// The largest per-step particle displacement, in cells.
    pub max_displacement_cells: f32,
    /// The largest CFL number of the (sub-)steps.
    pub cfl_max: f32,
    /// Sub-steps over all steps (the step count without `simulation.cfl`).
    pub substeps: usize,
}

impl RunTotals {
    /// Adds one step that took `seconds`.
    pub fn add(&mut self, stats: &StepStats, seconds: f64) {
        self.steps += 1;
        self.seconds += seconds;
        self.solver_iterations += stats.solve.iterations;
        self.solver_iterations_max = self.solver_iterations_max.max(stats.solve.iterations);
        self.solver_residual_max = self.solver_residual_max.max(stats.solve.residual);
        self.max_displacement_cells = self
            .max_displacement_cells
            .max(stats.max_displacement_cells);
        self.cfl_max = self.cfl_max.max(stats.cfl);
        self.substeps += stats.substeps;
    }

    /// The mean iterations of a solve (0 before the first step).
    pub fn solver_iterations_mean(&self) -> f64 {
        self.solver_iterations as f64 / self.steps.max(1) as f64
    }

    /// Steps per second of the steps alone.
    pub fn steps_per_second(&self) -> f64 {
        self.steps as f64 / self.seconds.max(1e-12)
    }
}

impl<B: LatticeKernels> SceneRun<B> {
    /// [`SceneRun::step`], timed and added to `totals`.
    ///
    /// # Errors
    /// The step's errors; `totals` is left as it was.
    pub fn step_counted(&mut self, totals: &mut RunTotals) -> Result<StepStats> {
        let started = Instant::now();
        let stats = self.step()?;
        totals.add(&stats, started.elapsed().as_secs_f64());
        Ok(stats)
    }
}
