//! `phi_rs.sinkhorn` and `phi_rs.position_mse`: the point-set and rollout metrics of `phi eval`
//! (phi-core's Sinkhorn divergence, phi-gns's position MSE) on NumPy arrays.

use phi_core::point_sets::{PointSetError, SinkhornOptions, sinkhorn_divergence_host};
use phi_gns::rollout::position_mse as frame_mse;
use pyo3::prelude::*;

use crate::arrays::{host_array, shape_text, to_numpy};
use crate::error::{Area, Error, detached};

/// A point set `[N, d]` from Python as float32: its shape and values.
fn point_set(array: &Bound<'_, PyAny>, what: &str) -> PyResult<(Vec<usize>, Vec<f32>)> {
    let (shape, values) = host_array::<f32>(array, "float32", Area::PointSet, what)?;
    if shape.len() != 2 {
        return Err(Error::argument(
            Area::PointSet,
            what,
            format!("shape {}: expected [N, d]", shape_text(&shape)),
        )
        .into());
    }
    Ok((shape, values))
}

/// The debiased Sinkhorn divergence ``S_ε(a, b) = OT_ε(a, b) − ½ OT_ε(a, a) − ½ OT_ε(b, b)``
/// between the uniform measures on two point sets, with ground cost ``½|x − y|²`` (Feydy et
/// al. 2019; what ``phi eval`` reports, and LagrangeBench). ``S ≥ 0``, ``S(a, a) = 0``, and for
/// ``ε → 0`` it tends to ``½ W₂²``, half the squared-Euclidean ``emd`` of equal-size sets.
/// Log-domain iterations in float64 with ε-scaling (from the sets' diameter² down by
/// ``scaling`` per iteration), then at ``epsilon`` until no potential moves by more than
/// ``tolerance`` or ``max_iterations``.
///
/// Args:
///     a: points ``[N, d]``.
///     b: points ``[M, d]`` (any ``M``, the same ``d``).
///     epsilon: the entropic regularisation ``ε`` in the units² of the points (``phi eval``'s
///         default, ``1e-4``, is meant for its unit-box datasets).
///     scaling: the ε-scaling factor, in (0, 1).
///     tolerance: the convergence threshold on the potentials; ``None`` is ``1e-6 · ε``.
///     max_iterations: iterations at the final ``ε``.
///
/// Returns:
///     The divergence, in the units² of the points.
///
/// Raises:
///     PointSetError: arrays that are not ``[N, d]``, different ``d``, an empty set, a
///         non-finite coordinate, an ``ε`` or ``scaling`` out of range.
///
/// The GIL is released while it iterates.
#[pyfunction]
#[pyo3(signature = (a, b, epsilon = 1e-4, scaling = 0.7, tolerance = None, max_iterations = 1000))]
pub fn sinkhorn(
    py: Python<'_>,
    a: &Bound<'_, PyAny>,
    b: &Bound<'_, PyAny>,
    epsilon: f32,
    scaling: f64,
    tolerance: Option<f64>,
    max_iterations: usize,
) -> PyResult<f64> {
    let (shape_a, a) = point_set(a, "sinkhorn: a")?;
    let (shape_b, b) = point_set(b, "sinkhorn: b")?;
    if shape_a[1] != shape_b[1] {
        return Err(Error::argument(
            Area::PointSet,
            "sinkhorn",
            format!(
                "a has shape {} and b {}: the points must have the same dimension",
                shape_text(&shape_a),
                shape_text(&shape_b)
            ),
        )
        .into());
    }
    if !(scaling > 0.0 && scaling < 1.0) {
        return Err(Error::argument(
            Area::PointSet,
            "sinkhorn: scaling",
            format!("must lie in (0, 1), got {scaling}"),
        )
        .into());
    }
    let mut options = SinkhornOptions::new(epsilon);
    options.scaling = scaling;
    options.max_iterations = max_iterations;
    if let Some(tolerance) = tolerance {
        options.tolerance = tolerance;
    }
    let d = shape_a[1];
    detached(py, move || {
        sinkhorn_divergence_host(&a, &b, d, &options).map_err(Error::from)
    })
}

/// The position MSE of a rollout as ``phi eval`` computes it: per frame, the mean of
/// ``(predicted − truth)²`` over the particles that are not kinematic (type 0, obstacles) and
/// the ``d`` components, in float64; then the mean over the frames. On a full rollout
/// (``Model.rollout(...)`` against the frames it predicts) it is the thesis's MSE 400.
///
/// Args:
///     predicted: float32 ``[T, N, d]`` (or one frame ``[N, d]``).
///     truth: the same shape.
///     particle_type: int64 ``[N]``; ``None`` counts every particle.
///     per_frame: return the ``T`` per-frame values (the MSE curve) instead of their mean.
///
/// Raises:
///     PointSetError: shapes that differ or are not ``[T, N, d]`` / ``[N, d]``, types that do
///         not fit ``N``.
#[pyfunction]
#[pyo3(signature = (predicted, truth, particle_type = None, per_frame = false))]
pub fn position_mse<'py>(
    py: Python<'py>,
    predicted: &Bound<'py, PyAny>,
    truth: &Bound<'py, PyAny>,
    particle_type: Option<&Bound<'py, PyAny>>,
    per_frame: bool,
) -> PyResult<Bound<'py, PyAny>> {
    let what = "position_mse";
    let (shape, predicted) = host_array::<f32>(
        predicted,
        "float32",
        Area::PointSet,
        "position_mse: predicted",
    )?;
    let (truth_shape, truth) =
        host_array::<f32>(truth, "float32", Area::PointSet, "position_mse: truth")?;
    if shape != truth_shape || !(shape.len() == 2 || shape.len() == 3) {
        return Err(Error::argument(
            Area::PointSet,
            what,
            format!(
                "predicted has shape {} and truth {}: expected the same [T, N, d] or [N, d]",
                shape_text(&shape),
                shape_text(&truth_shape)
            ),
        )
        .into());
    }
    let (n, d) = (shape[shape.len() - 2], shape[shape.len() - 1]);
    let kinematic = match particle_type {
        None => vec![false; n],
        Some(types) => {
            let (type_shape, types) = host_array::<i64>(
                types,
                "int64",
                Area::PointSet,
                "position_mse: particle_type",
            )?;
            if type_shape != [n] {
                return Err(Error::argument(
                    Area::PointSet,
                    "position_mse: particle_type",
                    format!("shape {}: expected ({n},)", shape_text(&type_shape)),
                )
                .into());
            }
            types
                .iter()
                .map(|&t| t == phi_gns::data::OBSTACLE)
                .collect()
        }
    };
    let per_frame_mse: Vec<f64> = if n * d == 0 {
        Vec::new()
    } else {
        predicted
            .chunks_exact(n * d)
            .zip(truth.chunks_exact(n * d))
            .map(|(p, t)| frame_mse(p, t, &kinematic, d))
            .collect()
    };
    if per_frame {
        let frames = per_frame_mse.len();
        return Ok(to_numpy(py, &[frames], per_frame_mse)?.into_any());
    }
    if per_frame_mse.is_empty() {
        return Err(Error::from(PointSetError::Invalid {
            what: "position_mse",
            reason: "no frame or no particle to compare".into(),
        })
        .into());
    }
    let mean = per_frame_mse.iter().sum::<f64>() / per_frame_mse.len() as f64;
    Ok(mean.into_pyobject(py)?.into_any())
}
