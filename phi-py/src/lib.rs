//! `phi_rs`: phi from Python. The module calls the library crates the `phi` command line is
//! built on (never the command line itself); arrays come and go as NumPy arrays, errors as
//! exceptions under `phi_rs.PhiError`, and long calls release the GIL.
//!
//! - `simulate`: a FLIP scene run as `phi simulate` runs it (phi-flip's `run_scene`);
//! - `Simulation`: a FLIP scene stepped on demand (phi-flip's `SceneRun`);
//! - `emd`: phi-core's exact earth mover's distance; `sinkhorn` and `position_mse`, the
//!   metrics of `phi eval`;
//! - `Dataset`: phi-gns's dataset reader;
//! - `Model`: a GNS model (loaded or initialised), phi-gns's one step and rollout;
//! - `train`: phi-gns's `TrainingRun`, as `phi train` runs it;
//! - `FlipGradient`: a FLIP run as a differentiable function of its initial state (phi-flip's
//!   `FlipGradient` on Burn), which the Python module `phi_rs.torch` wraps for PyTorch.
//!
//! The compiled module is `phi_rs._phi_rs`; the package `phi_rs` (phi-py/python/phi_rs)
//! re-exports its names and adds the Python-side modules.

mod arrays;
mod backend;
mod dataset;
mod emd;
mod error;
mod evaluate;
mod evaluate_split;
mod generate;
#[cfg(feature = "burn")]
mod gradient;
mod metrics;
mod model;
mod simulate;
mod simulation;
#[cfg(feature = "burn")]
mod train;

use pyo3::prelude::*;

/// phi from Python: FLIP liquid simulation, GNS datasets and models, point-set distances.
#[pymodule]
fn _phi_rs(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("BACKENDS", backend::available())?;
    m.add_function(wrap_pyfunction!(simulate::simulate, m)?)?;
    m.add_function(wrap_pyfunction!(generate::generate_dataset, m)?)?;
    m.add_function(wrap_pyfunction!(generate::merge_dataset, m)?)?;
    m.add_function(wrap_pyfunction!(evaluate_split::evaluate, m)?)?;
    m.add_function(wrap_pyfunction!(emd::emd, m)?)?;
    m.add_function(wrap_pyfunction!(metrics::sinkhorn, m)?)?;
    m.add_function(wrap_pyfunction!(metrics::position_mse, m)?)?;
    m.add_class::<simulation::Simulation>()?;
    m.add_class::<dataset::Dataset>()?;
    m.add_class::<dataset::Windows>()?;
    m.add_class::<model::Model>()?;
    #[cfg(feature = "burn")]
    m.add_class::<gradient::FlipGradient>()?;
    #[cfg(feature = "burn")]
    m.add_function(wrap_pyfunction!(train::train, m)?)?;
    m.add("PhiError", py.get_type::<error::PhiError>())?;
    m.add("SceneError", py.get_type::<error::SceneError>())?;
    m.add("SimulationError", py.get_type::<error::SimulationError>())?;
    m.add("DatasetError", py.get_type::<error::DatasetError>())?;
    m.add("ModelError", py.get_type::<error::ModelError>())?;
    m.add("PointSetError", py.get_type::<error::PointSetError>())?;
    m.add("TrainingError", py.get_type::<error::TrainingError>())?;
    Ok(())
}
