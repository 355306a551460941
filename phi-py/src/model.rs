//! `phi_rs.Model`: a GNS model directory, rolled out by phi-gns's rollout stepper.

use std::path::{Path, PathBuf};

use phi_gns::data::Trajectory;
use phi_gns::model::{Gns, GnsKernels, load_model};
use phi_gns::rollout::{RolloutRange, rollout_positions};
use pyo3::prelude::*;

use crate::arrays::{host_array, shape_text, to_numpy};
use crate::backend::with_backend;
use crate::error::{Area, Error, detached};

/// A model loaded on one backend (boxed: the models differ in size by backend).
enum Loaded {
    Ndarray(Box<Gns<phi_core::backend::ndarray::NdArray>>),
    #[cfg(feature = "burn")]
    Burn(Box<Gns<phi_core::backend::burn::Burn>>),
}

/// A trained (or freshly initialised) GNS: ``model.json`` and ``model.safetensors`` in one
/// directory, as ``phi model init`` and ``phi train`` write them.
///
/// Raises:
///     ModelError: a directory that does not hold a valid model, or input that does not fit it.
#[pyclass(frozen, module = "phi_rs")]
pub struct Model {
    inner: Loaded,
    dir: PathBuf,
}

/// Loads `dir` on backend `B`.
fn load_on<B: GnsKernels>(dir: &Path) -> Result<Gns<B>, Error> {
    Ok(load_model::<B>(dir, &B::default_device())?)
}

/// Rolls `model` out on `trajectory` over `range`: `[steps * N * dim]`.
fn rollout_on<B: GnsKernels>(
    model: &Gns<B>,
    trajectory: &Trajectory,
    range: RolloutRange,
) -> Result<Vec<f32>, Error> {
    Ok(rollout_positions(
        model,
        trajectory,
        range,
        &B::default_device(),
    )?)
}

impl Model {
    /// The spec of the loaded model.
    fn spec(&self) -> &phi_gns::model::ModelSpec {
        match &self.inner {
            Loaded::Ndarray(m) => m.spec(),
            #[cfg(feature = "burn")]
            Loaded::Burn(m) => m.spec(),
        }
    }
}

#[pymethods]
impl Model {
    /// Loads the model in directory ``dir`` on ``backend`` (``"ndarray"`` or ``"burn"``).
    #[staticmethod]
    #[pyo3(signature = (dir, backend = "ndarray"))]
    fn load(py: Python<'_>, dir: PathBuf, backend: &str) -> PyResult<Model> {
        let backend = backend.to_string();
        let path = dir.clone();
        let inner = detached(
            py,
            move || with_backend!(backend.as_str(), B => load_on::<B>(&path).map(Into::into)),
        )?;
        Ok(Model { inner, dir })
    }

    /// The model's directory.
    #[getter]
    fn dir(&self) -> PathBuf {
        self.dir.clone()
    }

    /// The backend the model runs on.
    #[getter]
    fn backend(&self) -> &'static str {
        match &self.inner {
            Loaded::Ndarray(_) => "ndarray",
            #[cfg(feature = "burn")]
            Loaded::Burn(_) => "burn",
        }
    }

    /// The number of spatial dimensions.
    #[getter]
    fn dim(&self) -> usize {
        self.spec().config.dim
    }

    /// ``C``: the model reads ``C + 1`` frames (``C`` velocities) per step.
    #[getter]
    fn input_velocities(&self) -> usize {
        self.spec().config.input_velocities
    }

    /// The content of ``model.json`` as a dict.
    #[getter]
    fn spec_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let text = serde_json::to_string(self.spec()).map_err(|e| {
            Error::argument(Area::Model, "model.json", format!("cannot be written: {e}"))
        })?;
        py.import("json")?.call_method1("loads", (text,))
    }

    /// Rolls the model out from frame ``start`` of a ground-truth trajectory, as ``phi
    /// rollout`` does: the ``C + 1`` frames ending at ``start`` are the input window, each step
    /// feeds the prediction back, and kinematic particles (obstacles) follow the trajectory.
    ///
    /// Args:
    ///     positions: float32 ``[T, N, d]`` in stored units (a dataset trajectory).
    ///     particle_type: int64 ``[N]`` (0 = obstacle, 1 = liquid).
    ///     steps: predicted frames; ``None`` runs to the trajectory's last frame.
    ///     start: the last frame of the input window; ``None`` is ``C``, the first possible.
    ///
    /// Returns:
    ///     float32 ``[steps, N, d]``: the predicted frames ``start + 1 ..= start + steps``.
    ///
    /// Raises:
    ///     ModelError: arrays of the wrong shape or dimension, a range past the trajectory's
    ///         end, a non-finite prediction (naming the step and the particle).
    ///
    /// The GIL is released while the model runs.
    #[pyo3(signature = (positions, particle_type, steps = None, start = None))]
    fn rollout<'py>(
        &self,
        py: Python<'py>,
        positions: &Bound<'py, PyAny>,
        particle_type: &Bound<'py, PyAny>,
        steps: Option<usize>,
        start: Option<usize>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (shape, values) =
            host_array::<f32>(positions, "float32", Area::Model, "rollout: positions")?;
        let (type_shape, types) = host_array::<i64>(
            particle_type,
            "int64",
            Area::Model,
            "rollout: particle_type",
        )?;
        let [frames, n, d] = shape[..] else {
            return Err(Error::argument(
                Area::Model,
                "rollout: positions",
                format!("shape {}: expected [T, N, d]", shape_text(&shape)),
            )
            .into());
        };
        if type_shape != [n] {
            return Err(Error::argument(
                Area::Model,
                "rollout: particle_type",
                format!(
                    "shape {}: expected ({n},), one type per particle of positions",
                    shape_text(&type_shape)
                ),
            )
            .into());
        }
        let c = self.input_velocities();
        let start = start.unwrap_or(c);
        let steps = steps.unwrap_or_else(|| frames.saturating_sub(start + 1));
        let range = RolloutRange { start, steps };
        let predicted = detached(py, || {
            let trajectory = Trajectory::new(d, values, types, 0, 0)
                .map_err(|e| Error::argument(Area::Model, "rollout: trajectory", e.to_string()))?;
            match &self.inner {
                Loaded::Ndarray(m) => rollout_on(m, &trajectory, range),
                #[cfg(feature = "burn")]
                Loaded::Burn(m) => rollout_on(m, &trajectory, range),
            }
        })?;
        Ok(to_numpy(py, &[steps, n, d], predicted)?.into_any())
    }

    fn __repr__(&self) -> String {
        format!(
            "Model('{}', backend='{}', dim={}, input_velocities={})",
            self.dir.display(),
            self.backend(),
            self.dim(),
            self.input_velocities()
        )
    }
}

impl From<Gns<phi_core::backend::ndarray::NdArray>> for Loaded {
    fn from(model: Gns<phi_core::backend::ndarray::NdArray>) -> Self {
        Loaded::Ndarray(Box::new(model))
    }
}

#[cfg(feature = "burn")]
impl From<Gns<phi_core::backend::burn::Burn>> for Loaded {
    fn from(model: Gns<phi_core::backend::burn::Burn>) -> Self {
        Loaded::Burn(Box::new(model))
    }
}
