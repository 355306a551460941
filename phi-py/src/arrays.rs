//! NumPy arrays in and out.

use numpy::ndarray::{ArrayD, IxDyn};
use numpy::{Element, IntoPyArray, PyArrayDyn, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::error::{Area, Error};

/// `obj` as a C-contiguous NumPy array of `dtype` (anything `numpy.asarray` takes), copied out:
/// its shape and values. `what` names the argument in errors of `area`.
pub fn host_array<T: Element + Copy>(
    obj: &Bound<'_, PyAny>,
    dtype: &str,
    area: Area,
    what: &str,
) -> PyResult<(Vec<usize>, Vec<T>)> {
    let py = obj.py();
    let kwargs = PyDict::new(py);
    kwargs.set_item("dtype", dtype)?;
    let converted = py
        .import("numpy")?
        .call_method("ascontiguousarray", (obj,), Some(&kwargs))
        .map_err(|e| {
            Error::argument(
                area,
                what,
                format!("not an array of {dtype}: {}", e.value(py)),
            )
        })?;
    let array = converted
        .cast_into::<PyArrayDyn<T>>()
        .map_err(|e| Error::argument(area, what, format!("not an array of {dtype}: {e}")))?;
    let readonly = array.readonly();
    let shape = readonly.shape().to_vec();
    let values = readonly
        .as_slice()
        .map_err(|e| Error::argument(area, what, e.to_string()))?
        .to_vec();
    Ok((shape, values))
}

/// A NumPy array of `shape` holding `values` (row-major).
pub fn to_numpy<'py, T: Element>(
    py: Python<'py>,
    shape: &[usize],
    values: Vec<T>,
) -> PyResult<Bound<'py, PyArrayDyn<T>>> {
    let array = ArrayD::from_shape_vec(IxDyn(shape), values).map_err(|e| {
        Error::Panic(format!(
            "an array of shape {shape:?} does not fit its values: {e}"
        ))
    })?;
    Ok(array.into_pyarray(py))
}

/// `shape` as Python writes it: `(3, 2)`.
pub fn shape_text(shape: &[usize]) -> String {
    match shape {
        [one] => format!("({one},)"),
        _ => format!(
            "({})",
            shape
                .iter()
                .map(usize::to_string)
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}
