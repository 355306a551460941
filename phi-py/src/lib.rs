//! `phi_rs`: phi from Python. The module calls the library crates the `phi` command line is
//! built on (never the command line itself); arrays come and go as NumPy arrays, errors as
//! exceptions under `phi_rs.PhiError`, and long calls release the GIL.
//!
//! - `simulate`: a FLIP scene run as `phi simulate` runs it (phi-flip's `run_scene`);
//! - `Simulation`: a FLIP scene stepped on demand (phi-flip's `SceneRun`);
//! - `emd`: phi-core's exact earth mover's distance;
//! - `Dataset`: phi-gns's dataset reader;
//! - `Model`: a GNS model directory and phi-gns's rollout.

mod arrays;
mod backend;
mod dataset;
mod emd;
mod error;
mod model;
mod simulate;
mod simulation;

use pyo3::prelude::*;

/// phi from Python: FLIP liquid simulation, GNS datasets and models, point-set distances.
#[pymodule]
fn phi_rs(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("BACKENDS", backend::available())?;
    m.add_function(wrap_pyfunction!(simulate::simulate, m)?)?;
    m.add_function(wrap_pyfunction!(emd::emd, m)?)?;
    m.add_class::<simulation::Simulation>()?;
    m.add_class::<dataset::Dataset>()?;
    m.add_class::<model::Model>()?;
    m.add("PhiError", py.get_type::<error::PhiError>())?;
    m.add("SceneError", py.get_type::<error::SceneError>())?;
    m.add("SimulationError", py.get_type::<error::SimulationError>())?;
    m.add("DatasetError", py.get_type::<error::DatasetError>())?;
    m.add("ModelError", py.get_type::<error::ModelError>())?;
    m.add("PointSetError", py.get_type::<error::PointSetError>())?;
    Ok(())
}
