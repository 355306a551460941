//! [`FlipError`], the error type of the simulator.

use phi_core::TensorError;
use phi_core::point_sets::PointSetError;
use phi_core::solve::SolveError;
use phi_geom::GeomError;
use thiserror::Error;

/// What can go wrong when setting up or running a simulation.
#[derive(Debug, Error)]
pub enum FlipError {
    /// A scene file that cannot be read or parsed, or a value in it that is not allowed.
    #[error("{path}: {key}: {reason}")]
    Scene {
        /// The file (or `<string>` for a scene given as text).
        path: String,
        /// The key, as a dotted path (`domain.resolution`, `liquid[1].geometry`), or the place in
        /// the file where the parser stopped.
        key: String,
        /// What is wrong with it.
        reason: String,
    },
    /// A parameter of the simulation outside its range (built in code rather than read from a
    /// file).
    #[error("invalid simulation parameter {name}: {reason}")]
    InvalidParameter {
        /// The parameter.
        name: &'static str,
        /// Why it is invalid.
        reason: String,
    },
    /// The state became NaN or infinite: the run is stopped rather than carried on with garbage.
    #[error(
        "step {step}: non-finite values in {what}; the simulation is unstable (try a smaller dt)"
    )]
    NonFinite {
        /// The step that produced them (0-based).
        step: usize,
        /// Which quantity.
        what: &'static str,
    },
    /// The step went unstable: its CFL number (the most cells the fastest particle or grid
    /// velocity crosses in one (sub-)step) exceeds the limit, or keeping it below the adaptive
    /// target would take more sub-steps than allowed.
    #[error(
        "step {step}: the simulation is unstable: CFL number {cfl:.4} at dt = {dt} s {why}; use a \
         smaller dt, or set simulation.cfl (e.g. 1.0) to sub-step adaptively"
    )]
    Unstable {
        /// The step (0-based).
        step: usize,
        /// The CFL number `Δt · maxₐ maxᵢ |uₐ,ᵢ| / Δxₐ` over the particle and grid velocities.
        cfl: f32,
        /// The (sub-)step length it was measured or estimated for.
        dt: f32,
        /// What limit it broke, in words.
        why: String,
    },
    /// The pressure solve failed (did not converge, non-finite input, ...).
    #[error("step {step}: pressure solve: {source}")]
    Solve {
        /// The step (0-based).
        step: usize,
        /// The solver's error.
        source: SolveError,
    },
    /// A geometry operation failed.
    #[error(transparent)]
    Geometry(#[from] GeomError),
    /// A tensor operation failed.
    #[error(transparent)]
    Tensor(#[from] TensorError),
    /// A simulator other than FLIP, driven through [`crate::optimize::Forward`] (a learned
    /// one), failed.
    #[error("{simulator}: {source}")]
    Simulator {
        /// The simulator, as named to the user.
        simulator: String,
        /// Its error.
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
}

/// The result type of the simulator.
pub type Result<T, E = FlipError> = std::result::Result<T, E>;

/// The simulator compares point sets only with a loss's target, so a point set that cannot be
/// compared is an invalid `target`; tensor errors stay tensor errors.
impl From<PointSetError> for FlipError {
    fn from(error: PointSetError) -> Self {
        match error {
            PointSetError::Tensor(source) => FlipError::Tensor(source),
            invalid @ PointSetError::Invalid { .. } => FlipError::InvalidParameter {
                name: "target",
                reason: invalid.to_string(),
            },
        }
    }
}
