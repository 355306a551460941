//! `phi_rs.evaluate` and the evaluation helpers of `Model.evaluate`: `phi eval`'s metrics of
//! phi-gns (`evaluate_trajectory`, `ModelSummary`) from Python.

use std::path::PathBuf;

use phi_gns::data::Trajectory;
use phi_gns::eval::metrics::Container;
use phi_gns::eval::{EmdCost, EvalOptions, ModelSummary, evaluate_trajectory};
use phi_gns::model::{Gns, GnsKernels};
use pyo3::prelude::*;

use crate::error::{Area, Error, detached};
use crate::model::{Loaded, Model, on_model};

/// Evaluates `model` on `trajectory` as `phi eval` does.
pub(crate) fn evaluate_on<B: GnsKernels>(
    model: &Gns<B>,
    trajectory: &Trajectory,
    options: &EvalOptions,
) -> Result<phi_gns::eval::TrajectoryEvaluation, Error> {
    evaluate_trajectory(model, trajectory, options, &B::default_device()).map_err(|e| match e {
        phi_gns::eval::EvalError::Model(e) => Error::Model(e),
        other => Error::argument(Area::Model, "evaluate", other.to_string()),
    })
}

/// The options of `Model.evaluate` and `evaluate` (`function` names the call in errors).
pub(crate) fn eval_options(
    function: &str,
    short_rollout: usize,
    emd_cost: &str,
    sinkhorn_epsilon: f32,
    sinkhorn_every: usize,
    density_radius: f64,
) -> Result<EvalOptions, Error> {
    let argument = |name: &str, reason: String| {
        Error::argument(Area::Model, format!("{function}: {name}"), reason)
    };
    let ground_cost = match emd_cost {
        "sqeuclidean" => EmdCost::SquaredEuclidean,
        "euclidean" => EmdCost::Euclidean,
        other => {
            return Err(argument(
                "emd_cost",
                format!("'{other}' is not a ground cost (use 'sqeuclidean' or 'euclidean')"),
            ));
        }
    };
    if short_rollout == 0 {
        return Err(argument("short_rollout", "must be at least 1".into()));
    }
    if !(density_radius.is_finite() && density_radius > 0.0) {
        return Err(argument(
            "density_radius",
            format!("{density_radius}: must be positive and finite"),
        ));
    }
    let mut options = EvalOptions::new(density_radius);
    options.short_rollout = short_rollout;
    options.ground_cost = ground_cost;
    options.sinkhorn_epsilon = sinkhorn_epsilon;
    options.sinkhorn_every = sinkhorn_every;
    Ok(options)
}

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
/// The GIL is released while it runs; Ctrl-C stops it after the trajectory under way.
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
        let (mut summaries, mut rows) = (serde_json::Map::new(), serde_json::Map::new());
        for (name, model) in &models {
            let model = model.get();
            let mut evaluations = Vec::with_capacity(count);
            for index in 0..count {
                let (trajectory, _) = dataset.read_with_stats(split, index)?;
                evaluations
                    .push(on_model!(&model.inner, m => evaluate_on(m, &trajectory, &options))?);
                // Ctrl-C stops the evaluation between trajectories.
                Python::attach(|py| py.check_signals()).map_err(Error::Python)?;
            }
            let summary = ModelSummary::of(&evaluations, &metadata.acc_std);
            let unwritable = |e: serde_json::Error| {
                Error::argument(Area::Model, "evaluate", format!("cannot be written: {e}"))
            };
            summaries.insert(
                name.clone(),
                serde_json::to_value(&summary).map_err(unwritable)?,
            );
            rows.insert(
                name.clone(),
                serde_json::to_value(&evaluations).map_err(unwritable)?,
            );
        }
        let table = serde_json::json!({ "models": summaries, "trajectories": rows });
        Ok(table.to_string())
    })?;
    py.import("json")?.call_method1("loads", (text,))
}

/// The container of `Model.evaluate`'s plausibility metrics from its `bounds` (`[dim]` pairs
/// `(min, max)`) and `cell_size`: both or neither.
pub(crate) fn evaluation_container(
    bounds: Option<Vec<Vec<f64>>>,
    cell_size: Option<f64>,
    dim: usize,
) -> Result<Option<Container>, Error> {
    let argument = |name: &str, reason: String| {
        Error::argument(Area::Model, format!("evaluate: {name}"), reason)
    };
    let (bounds, cell_size) = match (bounds, cell_size) {
        (None, None) => return Ok(None),
        (Some(bounds), Some(cell_size)) => (bounds, cell_size),
        (Some(_), None) => return Err(argument("cell_size", "must be given with bounds".into())),
        (None, Some(_)) => return Err(argument("bounds", "must be given with cell_size".into())),
    };
    if bounds.len() != dim {
        return Err(argument(
            "bounds",
            format!(
                "{} pairs for a {dim}-dimensional model: one (min, max) per axis",
                bounds.len()
            ),
        ));
    }
    let mut pairs = Vec::with_capacity(dim);
    for (axis, pair) in bounds.iter().enumerate() {
        let &[lo, hi] = pair.as_slice() else {
            return Err(argument(
                "bounds",
                format!("axis {axis} has {} values: expected (min, max)", pair.len()),
            ));
        };
        if !(lo.is_finite() && hi.is_finite() && lo < hi) {
            return Err(argument(
                "bounds",
                format!("axis {axis} is ({lo}, {hi}): must be finite with min < max"),
            ));
        }
        pairs.push([lo, hi]);
    }
    if !(cell_size.is_finite() && cell_size > 0.0) {
        return Err(argument(
            "cell_size",
            format!("{cell_size}: must be positive and finite"),
        ));
    }
    Ok(Some(Container {
        bounds: pairs,
        cell_size,
    }))
}
