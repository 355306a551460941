//! `phi_rs.simulate`: a scene run as `phi simulate` runs it, its states returned as arrays.

use std::path::PathBuf;

use phi_core::Backend;
use phi_flip::{Recording, Scene, run_scene_checked};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyString};

use crate::arrays::to_numpy;
use crate::backend::with_backend;
use crate::error::{Error, detached};

/// The particle type of liquid in `trajectory.npz` (`phi simulate` writes only liquid).
pub const LIQUID: i32 = 1;

/// Runs a FLIP scene and returns its states: the arrays of the ``trajectory.npz`` that
/// ``phi simulate`` writes, bit for bit.
///
/// Args:
///     scene: the path of a scene TOML file (``str`` or ``os.PathLike``), or the TOML text
///         itself (a ``str`` with a line break in it).
///     steps: the number of steps; ``None`` takes the scene's ``simulation.steps``.
///     backend: ``"ndarray"`` (the fast CPU path) or ``"burn"``.
///
/// Returns:
///     A dict of NumPy arrays: ``positions`` and ``velocities`` float32 ``[T+1, N, d]`` (frame 0
///     is the initial state; with inflows, rows of particles that do not exist yet are NaN),
///     ``particle_type`` int32 ``[N]`` (1 = liquid), ``particle_count`` int32 ``[T+1]``,
///     ``time`` float32 ``[T+1]``, ``steps_completed`` int64 ``[1]``, and for an APIC scene
///     ``affine`` float32 ``[T+1, N, d, d]``.
///
/// Raises:
///     SceneError: the scene cannot be read, parsed or built (the message names the file and
///         the key).
///     SimulationError: a step failed (an unstable or non-finite state, a failed solve).
///     PhiError: an unknown backend.
///
/// The GIL is released while the simulation runs.
#[pyfunction]
#[pyo3(signature = (scene, steps = None, backend = "ndarray"))]
pub fn simulate<'py>(
    py: Python<'py>,
    scene: &Bound<'py, PyAny>,
    steps: Option<usize>,
    backend: &str,
) -> PyResult<Bound<'py, PyDict>> {
    let source = SceneSource::from_python(scene)?;
    let backend = backend.to_string();
    let recording = detached(py, move || {
        let (scene, origin) = source.read()?;
        // Ctrl-C stops the run between steps: Python's signal handlers run only when asked.
        let interrupted = |_| Python::attach(|py| py.check_signals()).map_err(Error::Python);
        with_backend!(backend.as_str(), B => {
            run_scene_checked::<B, Error>(&scene, &origin, steps, &B::default_device(), interrupted)
        })
    })?;
    trajectory_dict(py, &recording)
}

/// Where a scene comes from: a file or TOML text.
pub enum SceneSource {
    File(PathBuf),
    Text(String),
}

impl SceneSource {
    /// A `str` with a line break is TOML text; any other `str` or path-like object a path.
    pub fn from_python(scene: &Bound<'_, PyAny>) -> PyResult<Self> {
        if let Ok(text) = scene.cast::<PyString>() {
            let text = text.to_cow()?;
            if text.contains('\n') {
                return Ok(SceneSource::Text(text.to_string()));
            }
        }
        Ok(SceneSource::File(scene.extract::<PathBuf>()?))
    }

    /// The scene and the name its errors use.
    pub fn read(&self) -> Result<(Scene, String), Error> {
        Ok(match self {
            SceneSource::File(path) => (Scene::from_file(path)?, path.display().to_string()),
            SceneSource::Text(text) => {
                let origin = "<string>".to_string();
                (Scene::from_toml(text, &origin)?, origin)
            }
        })
    }
}

/// The arrays of `trajectory.npz` for `recording`.
fn trajectory_dict<'py>(py: Python<'py>, recording: &Recording) -> PyResult<Bound<'py, PyDict>> {
    let arrays = recording.arrays();
    let (frames, n, d) = (arrays.frames, arrays.particles, arrays.dim);
    let counts: Vec<i32> = arrays.particle_count.iter().map(|&c| c as i32).collect();
    let dict = PyDict::new(py);
    dict.set_item(
        "positions",
        to_numpy(py, &[frames, n, d], arrays.positions)?,
    )?;
    dict.set_item(
        "velocities",
        to_numpy(py, &[frames, n, d], arrays.velocities)?,
    )?;
    dict.set_item("particle_type", to_numpy(py, &[n], vec![LIQUID; n])?)?;
    dict.set_item("particle_count", to_numpy(py, &[frames], counts)?)?;
    dict.set_item("time", to_numpy(py, &[frames], arrays.time)?)?;
    dict.set_item(
        "steps_completed",
        to_numpy(py, &[1], vec![frames as i64 - 1])?,
    )?;
    if let Some(affine) = arrays.affine {
        dict.set_item("affine", to_numpy(py, &[frames, n, d, d], affine)?)?;
    }
    Ok(dict)
}
