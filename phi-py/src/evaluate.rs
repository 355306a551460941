//! What `Model.evaluate` and `phi_rs.evaluate` share: their options, the container of the
//! plausibility figures and the evaluation of one trajectory (phi-gns's `evaluate_trajectory`).

use phi_gns::data::Trajectory;
use phi_gns::eval::metrics::Container;
use phi_gns::eval::{EmdCost, EvalOptions, evaluate_trajectory};
use phi_gns::model::{Gns, GnsKernels};

use crate::error::{Area, Error};

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
