//! `phi_rs.Dataset`: a dataset that `phi dataset generate` wrote, read by phi-gns's reader.

use std::path::PathBuf;

use pyo3::prelude::*;

use crate::arrays::to_numpy;
use crate::error::{Area, Error, detached};

/// A GNS dataset directory (``metadata.json`` and one ``.npz`` per trajectory), read with the
/// checks of ``phi``'s own reader (CRC-32 of every member, index and seed of every file).
///
/// ``ds[split, i]`` is trajectory ``i`` of ``split``: ``(positions, particle_type)``, float32
/// ``[frames, N, d]`` in stored units and int64 ``[N]`` (0 = obstacle, 1 = liquid). A negative
/// ``i`` counts from the end.
///
/// Raises:
///     DatasetError: a directory without a valid ``metadata.json``, an unknown split, an index
///         out of range or a damaged file (the message names the file).
#[pyclass(frozen, module = "phi_rs")]
pub struct Dataset {
    inner: phi_gns::data::Dataset,
}

#[pymethods]
impl Dataset {
    /// Opens the dataset at ``path`` and checks its ``metadata.json``.
    #[new]
    fn new(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        let inner = detached(py, move || Ok(phi_gns::data::Dataset::open(&path)?))?;
        Ok(Dataset { inner })
    }

    /// The dataset's directory.
    #[getter]
    fn path(&self) -> PathBuf {
        self.inner.dir().to_path_buf()
    }

    /// The content of ``metadata.json`` as a dict.
    #[getter]
    fn metadata<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let text = serde_json::to_string(self.inner.metadata()).map_err(|e| {
            Error::argument(Area::Dataset, "metadata", format!("cannot be written: {e}"))
        })?;
        py.import("json")?.call_method1("loads", (text,))
    }

    /// The names of the splits, in the order of ``metadata.json``.
    #[getter]
    fn splits(&self) -> Vec<String> {
        self.inner.metadata().splits.keys().cloned().collect()
    }

    /// The number of trajectories in ``split``.
    #[pyo3(signature = (split = "train"))]
    fn len(&self, split: &str) -> PyResult<usize> {
        Ok(self.inner.split_len(split).map_err(Error::from)?)
    }

    /// Trajectory ``i`` of ``split`` as ``(positions, particle_type)``.
    fn __getitem__<'py>(
        &self,
        py: Python<'py>,
        key: (String, i64),
    ) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
        let (split, index) = key;
        let count = self.inner.split_len(&split).map_err(Error::from)?;
        let resolved = if index < 0 {
            (count as i64).checked_add(index)
        } else {
            Some(index)
        };
        let index = match resolved {
            Some(i) if i >= 0 && (i as u64) < count as u64 => i as usize,
            _ => {
                return Err(Error::argument(
                    Area::Dataset,
                    format!("{}: split '{split}'", self.inner.dir().display()),
                    format!("index {index} is out of range for its {count} trajectories"),
                )
                .into());
            }
        };
        let dataset = &self.inner;
        let (trajectory, _) = detached(py, || Ok(dataset.read_with_stats(&split, index)?))?;
        let shape = [trajectory.frames, trajectory.particles, trajectory.dim];
        let positions = to_numpy(py, &shape, trajectory.position)?.into_any();
        let n = trajectory.particle_type.len();
        let types = to_numpy(py, &[n], trajectory.particle_type)?.into_any();
        Ok((positions, types))
    }

    fn __repr__(&self) -> String {
        let splits: Vec<String> = self
            .inner
            .metadata()
            .splits
            .iter()
            .map(|(name, count)| format!("{name}={count}"))
            .collect();
        format!(
            "Dataset('{}', {})",
            self.inner.dir().display(),
            splits.join(", ")
        )
    }
}
