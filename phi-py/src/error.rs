//! The exceptions of `phi_rs` and the errors behind them.
//!
//! Every error of the library crates becomes an exception of one class per area (all subclasses
//! of `phi_rs.PhiError`) whose message is the library's message: the file, the key and what is
//! wrong. A panic inside a call is caught at the boundary and raised as `PhiError`.

use std::any::Any;
use std::panic::{AssertUnwindSafe, catch_unwind};

use pyo3::exceptions::PyException;
use pyo3::{PyErr, Python, create_exception};
use thiserror::Error;

create_exception!(
    phi_rs,
    PhiError,
    PyException,
    "The base class of every error phi_rs raises."
);
create_exception!(
    phi_rs,
    SceneError,
    PhiError,
    "A scene that cannot be read, parsed or built; the message names the file and the key."
);
create_exception!(
    phi_rs,
    SimulationError,
    PhiError,
    "A simulation step that failed: an unstable or non-finite state, a failed pressure solve."
);
create_exception!(
    phi_rs,
    DatasetError,
    PhiError,
    "A dataset that cannot be read, or a split or index it does not have."
);
create_exception!(
    phi_rs,
    ModelError,
    PhiError,
    "A model directory that cannot be loaded, or input that does not fit the model."
);
create_exception!(
    phi_rs,
    TrainingError,
    PhiError,
    "A training run that cannot start or go on: a preset, an output directory, a diverged step."
);
create_exception!(
    phi_rs,
    PointSetError,
    PhiError,
    "Point sets that a distance cannot compare (shapes, counts, non-finite values)."
);

/// Which exception class an argument error raises.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Area {
    /// `PhiError` itself (a backend name, ...).
    General,
    /// `SceneError`.
    Scene,
    /// `SimulationError`.
    Simulation,
    /// `DatasetError`.
    Dataset,
    /// `ModelError`.
    Model,
    /// `PointSetError`.
    PointSet,
    /// `TrainingError`.
    Training,
}

/// What a call of the module can fail with.
#[derive(Debug, Error)]
pub enum Error {
    /// The simulator's errors (scenes and steps).
    #[error(transparent)]
    Flip(#[from] phi_flip::FlipError),
    /// The dataset reader's errors.
    #[error(transparent)]
    Data(#[from] phi_gns::data::DataError),
    /// Dataset generation's errors.
    #[error(transparent)]
    Generate(#[from] phi_dataset::DatasetError),
    /// The GNS model's errors.
    #[error(transparent)]
    Model(#[from] phi_gns::model::ModelError),
    /// The trainer's errors.
    #[error(transparent)]
    Train(#[from] phi_gns::train::TrainError),
    /// The point-set distances' errors.
    #[error(transparent)]
    PointSet(#[from] phi_core::point_sets::PointSetError),
    /// An argument from Python that the call cannot take.
    #[error("{what}: {reason}")]
    Argument {
        /// The exception class.
        area: Area,
        /// The argument, with the function (`emd: a`).
        what: String,
        /// What is wrong with it.
        reason: String,
    },
    /// A panic inside the library, caught at the boundary.
    #[error("internal error in phi: {0}")]
    Panic(String),
    /// An exception from Python while the call ran (`KeyboardInterrupt` from a check of the
    /// signals between steps), raised again as it is.
    #[error("{0}")]
    Python(PyErr),
}

impl Error {
    /// An argument error of `area`.
    pub fn argument(area: Area, what: impl Into<String>, reason: impl Into<String>) -> Self {
        Error::Argument {
            area,
            what: what.into(),
            reason: reason.into(),
        }
    }
}

impl From<Error> for PyErr {
    fn from(error: Error) -> PyErr {
        let message = error.to_string();
        match error {
            Error::Python(error) => error,
            Error::Flip(phi_flip::FlipError::Scene { .. }) => SceneError::new_err(message),
            Error::Flip(_) => SimulationError::new_err(message),
            Error::Data(_) | Error::Generate(_) => DatasetError::new_err(message),
            Error::Model(_) => ModelError::new_err(message),
            Error::Train(phi_gns::train::TrainError::Data(_)) => DatasetError::new_err(message),
            Error::Train(phi_gns::train::TrainError::Model(_)) => ModelError::new_err(message),
            Error::Train(_) => TrainingError::new_err(message),
            Error::PointSet(_) => PointSetError::new_err(message),
            Error::Argument { area, .. } => match area {
                Area::General => PhiError::new_err(message),
                Area::Scene => SceneError::new_err(message),
                Area::Simulation => SimulationError::new_err(message),
                Area::Dataset => DatasetError::new_err(message),
                Area::Model => ModelError::new_err(message),
                Area::PointSet => PointSetError::new_err(message),
                Area::Training => TrainingError::new_err(message),
            },
            Error::Panic(_) => PhiError::new_err(message),
        }
    }
}

/// The text of a panic's payload.
fn panic_message(payload: Box<dyn Any + Send>) -> String {
    if let Some(s) = payload.downcast_ref::<&str>() {
        (*s).to_string()
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s.clone()
    } else {
        "a panic without a message".to_string()
    }
}

/// Runs `f` with the GIL released, a panic turned into [`Error::Panic`] and the error into its
/// exception.
pub fn detached<T, F>(py: Python<'_>, f: F) -> pyo3::PyResult<T>
where
    T: Send,
    F: FnOnce() -> Result<T, Error> + Send,
{
    py.detach(|| {
        catch_unwind(AssertUnwindSafe(f)).unwrap_or_else(|p| Err(Error::Panic(panic_message(p))))
    })
    .map_err(PyErr::from)
}
