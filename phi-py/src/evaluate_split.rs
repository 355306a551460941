//! `phi_rs.evaluate`: `phi eval`'s table over a dataset's split (phi-gns's
//! `evaluate_trajectory` and `ModelSummary`) for models loaded in Python.

use std::path::PathBuf;

use phi_gns::eval::ModelSummary;
use phi_gns::eval::metrics::Container;
use pyo3::prelude::*;

use crate::error::{Area, Error, detached};
use crate::evaluate::{eval_options, evaluate_on};
use crate::model::{Loaded, Model, on_model};

/// Evaluates models on every trajectory of a dataset's split, as ``phi eval --data DATA --split
/// SPLIT`` does, against the dataset's container (its bounds and cell size): the table of
/// ``phi eval`` as a dict.
///
/// Args:
///     models: ``{name: Model}`` (``Model.load``, ``Model.init``, ``with_walls``).
///     data: the dataset directory.
///     split: the split to evaluate.
///     trajectories: the first this many trajectories of the split; ``None``: all.
///     short_rollout, emd_cost, sinkhorn_epsilon, sinkhorn_every: as ``Model.evaluate``.
///     density_radius: ``None``: the dataset's ``default_connectivity_radius``.
///
/// Returns:
///     ``{"models": {name: summary}, "trajectories": {name: [evaluation, ...]}}``: each summary
///     is a row of ``phi eval``'s table (``mse_acc1`` in the dataset's ``acc_std``, ``mse20``,
///     ``mse400``, ``emd``, ``sinkhorn``, ``kinetic_energy_error``, ``density_ratio``,
///     ``blown_up``, ``plausibility`` with ``plausible`` the count of plausible rollouts); each
///     evaluation is ``Model.evaluate``'s dict for one trajectory.
///
/// Raises:
///     DatasetError: an unreadable dataset or split.
///     ModelError: a model that does not fit the dataset, bad options.
///
/// The GIL is released while it runs; Ctrl-C stops it after the trajectory under way (each
/// trajectory is read once, for every model).
#[pyfunction]
#[pyo3(signature = (models, data, split = "test", trajectories = None, short_rollout = 20, emd_cost = "sqeuclidean", sinkhorn_epsilon = 1e-4, sinkhorn_every = 0, density_radius = None))]
#[allow(clippy::too_many_arguments)] // Python's keyword arguments
pub fn evaluate<'py>(
    py: Python<'py>,
    models: std::collections::BTreeMap<String, Py<Model>>,
    data: PathBuf,
    split: &str,
    trajectories: Option<usize>,
    short_rollout: usize,
    emd_cost: &str,
    sinkhorn_epsilon: f32,
    sinkhorn_every: usize,
    density_radius: Option<f64>,
) -> PyResult<Bound<'py, PyAny>> {
    let text = detached(py, || {
        let dataset = phi_gns::data::Dataset::open(&data)?;
        let metadata = dataset.metadata();
        let mut options = eval_options(
            "evaluate",
            short_rollout,
            emd_cost,
            sinkhorn_epsilon,
            sinkhorn_every,
            density_radius.unwrap_or(metadata.default_connectivity_radius),
        )?;
        options.container = Some(Container {
            bounds: metadata.bounds.clone(),
            cell_size: metadata.position_scale,
        });
        let count = dataset.split_len(split)?;
        let count = trajectories.map_or(count, |t| t.min(count));
        // Each trajectory is read once and evaluated by every model.
        let mut evaluations: Vec<Vec<_>> =
            models.iter().map(|_| Vec::with_capacity(count)).collect();
        for index in 0..count {
            let (trajectory, _) = dataset.read_with_stats(split, index)?;
            for (model, done) in models.values().zip(&mut evaluations) {
                let model = model.get();
                done.push(on_model!(&model.inner, m => evaluate_on(m, &trajectory, &options))?);
            }
            // Ctrl-C stops the evaluation between trajectories.
            Python::attach(|py| py.check_signals()).map_err(Error::Python)?;
        }
        let unwritable = |e: serde_json::Error| {
            Error::argument(Area::Model, "evaluate", format!("cannot be written: {e}"))
        };
        let (mut summaries, mut rows) = (serde_json::Map::new(), serde_json::Map::new());
        for (name, evaluations) in models.keys().zip(&evaluations) {
            let summary = ModelSummary::of(evaluations, &metadata.acc_std);
            summaries.insert(
                name.clone(),
                serde_json::to_value(&summary).map_err(unwritable)?,
            );
            rows.insert(
                name.clone(),
                serde_json::to_value(evaluations).map_err(unwritable)?,
            );
        }
        let table = serde_json::json!({ "models": summaries, "trajectories": rows });
        Ok(table.to_string())
    })?;
    py.import("json")?.call_method1("loads", (text,))
}
