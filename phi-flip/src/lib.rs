//! The FLIP liquid simulator (thesis algorithm 1), written once against
//! `phi_core::backend::Backend`: 2D and 3D, obstacles (any geometry, rotated, moving), inflows,
//! FLIP, PIC, a blend or APIC, and scenes read from TOML files.

mod error;
pub mod gradient;
pub mod loss;
pub mod memory;
pub mod optimize;
mod random;
pub mod record;
mod scene;
mod seed;
mod sim;
mod toml_file;
pub mod totals;

pub use error::{FlipError, Result};
pub use gradient::{FlipGradient, HostState};
pub use loss::Loss;
pub use memory::MemoryEstimate;
pub use optimize::{OptimizeConfig, OptimizeError, OptimizeOutcome, OptimizeProblem};
pub use random::{
    BlockDraw, OBSTACLE_ATTEMPTS, ObstacleDraw, ParticleTrajectory, RandomScene, RandomSceneParams,
    SceneVariant, cell_centres, generate_random_scene, record_trajectory,
};
pub use record::{
    RecordedFrame, Recording, SceneRun, TrajectoryArrays, run_scene, run_scene_checked,
};
pub use scene::{
    DomainSpec, InflowSpec, LiquidSpec, PlacementSpec, RunSpec, Scene, SceneSetup, Scheme,
    SimulationSpec, SolverSpec, TransferSpec,
};
pub use seed::{Placement, seed_particles};
pub use sim::{
    DEFAULT_MAX_CFL, DEFAULT_MAX_SUBSTEPS, FlipParams, FlipSimulation, Inflow, Particles,
    SceneParameters, StepStats,
};
pub use totals::RunTotals;
