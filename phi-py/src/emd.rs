//! `phi_rs.emd`: phi-core's exact earth mover's distance between point sets.

use phi_core::point_sets::{GroundCost, earth_movers_distance};
use pyo3::prelude::*;

use crate::arrays::{host_array, shape_text};
use crate::error::{Area, Error, detached};

/// The exact earth mover's distance between two point sets of ``N`` points each: the mean
/// ground cost of the optimal one-to-one assignment, ``(1/N) min_σ Σᵢ C(aᵢ, b_σ(i))``
/// (POT's ``ot.emd2(1/N, 1/N, ot.dist(a, b, metric))``), computed in float64.
///
/// Args:
///     a: points ``[N, d]`` (anything ``numpy.asarray`` takes).
///     b: points ``[N, d]``, the same ``N`` and ``d``.
///     cost: ``"sqeuclidean"`` (``|x − y|²``) or ``"euclidean"`` (``|x − y|``).
///
/// Returns:
///     The distance, in the units of ``cost``.
///
/// Raises:
///     PointSetError: an array that is not ``[N, d]``, sets of different sizes or dimensions,
///         an empty set, a non-finite coordinate, or an unknown ``cost``.
///
/// The GIL is released while the assignment is solved.
#[pyfunction]
#[pyo3(signature = (a, b, cost = "sqeuclidean"))]
pub fn emd(
    py: Python<'_>,
    a: &Bound<'_, PyAny>,
    b: &Bound<'_, PyAny>,
    cost: &str,
) -> PyResult<f64> {
    let cost = match cost {
        "sqeuclidean" => GroundCost::SquaredEuclidean,
        "euclidean" => GroundCost::Euclidean,
        other => {
            return Err(Error::argument(
                Area::PointSet,
                "emd: cost",
                format!("'{other}' is not a ground cost (use 'sqeuclidean' or 'euclidean')"),
            )
            .into());
        }
    };
    let (shape_a, a) = host_array::<f64>(a, "float64", Area::PointSet, "emd: a")?;
    let (shape_b, b) = host_array::<f64>(b, "float64", Area::PointSet, "emd: b")?;
    for (name, shape) in [("a", &shape_a), ("b", &shape_b)] {
        if shape.len() != 2 {
            return Err(Error::argument(
                Area::PointSet,
                format!("emd: {name}"),
                format!("shape {}: expected [N, d]", shape_text(shape)),
            )
            .into());
        }
    }
    if shape_a != shape_b {
        return Err(Error::argument(
            Area::PointSet,
            "emd",
            format!(
                "a has shape {} and b {}: the exact EMD pairs sets of the same shape [N, d]",
                shape_text(&shape_a),
                shape_text(&shape_b)
            ),
        )
        .into());
    }
    let d = shape_a[1];
    detached(py, move || Ok(earth_movers_distance(&a, &b, d, cost)?))
}
