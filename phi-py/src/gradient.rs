//! `phi_rs.FlipGradient`: a scene's FLIP run as a differentiable function of its initial state
//! (phi-flip's `FlipGradient` on the Burn autodiff backend), the operation behind
//! `phi_rs.torch`.

use phi_core::Backend;
use phi_core::backend::burn::Burn;
use phi_flip::HostState;
use pyo3::prelude::*;

use crate::arrays::{host_array, shape_text, to_numpy};
use crate::error::{Area, Error, detached};
use crate::simulate::SceneSource;

/// The autodiff backend of the gradients: Burn on the CPU.
type Autodiff = Burn;

/// Two NumPy arrays `[N, d]`: positions and velocities (or their gradients).
type ArrayPair<'py> = (Bound<'py, PyAny>, Bound<'py, PyAny>);

/// A FLIP scene's run of ``steps`` steps as a differentiable function of the initial particle
/// positions and velocities, on the Burn (autodiff) backend: ``run`` is the forward map
/// ``(x₀, v₀) ↦ (x_T, v_T)`` and ``vjp`` its vector-Jacobian product, the backward pass that
/// ``phi_rs.torch`` hands to PyTorch.
///
/// The run takes the scene's steps (gravity, obstacles, inflows, solver) from step 0; only the
/// initial state is replaced. Gradients are exact for the run's smooth piece: which cells hold
/// liquid, which faces are valid and which cells each particle interpolates from are held
/// constant, as in ``phi optimize``.
///
/// Args:
///     scene: the path of a scene TOML file (``str`` or ``os.PathLike``), or the TOML text
///         itself (a ``str`` with a line break in it), as ``simulate`` takes it.
///     steps: steps per run; ``None`` takes the scene's ``simulation.steps``.
///
/// Raises:
///     SceneError: the scene cannot be read, parsed or built (the message names the file and
///         the key).
#[pyclass(frozen, module = "phi_rs")]
pub struct FlipGradient {
    inner: phi_flip::FlipGradient<Autodiff>,
    initial: HostState,
}

/// `array` from Python as float32 `[N, d]`: its shape and values; `what` names the call and
/// `name` the argument in errors.
fn host_matrix(
    array: &Bound<'_, PyAny>,
    d: usize,
    what: &str,
    name: &str,
) -> PyResult<(Vec<usize>, Vec<f32>)> {
    let what = format!("{what}: {name}");
    let (shape, values) = host_array::<f32>(array, "float32", Area::Simulation, &what)?;
    if shape.len() != 2 || shape[1] != d {
        return Err(Error::argument(
            Area::Simulation,
            what,
            format!("shape {}: expected [N, {d}]", shape_text(&shape)),
        )
        .into());
    }
    Ok((shape, values))
}

/// `positions` and `velocities` from Python as one state `[N, d]`; `what` names the call and
/// `names` the two arguments in errors.
fn host_state(
    positions: &Bound<'_, PyAny>,
    velocities: &Bound<'_, PyAny>,
    d: usize,
    what: &str,
    names: [&str; 2],
) -> PyResult<HostState> {
    let (position_shape, positions) = host_matrix(positions, d, what, names[0])?;
    let (velocity_shape, velocities) = host_matrix(velocities, d, what, names[1])?;
    if position_shape != velocity_shape {
        return Err(Error::argument(
            Area::Simulation,
            what,
            format!(
                "{} has shape {} and {} {}: they must have the same shape [N, {d}]",
                names[0],
                shape_text(&position_shape),
                names[1],
                shape_text(&velocity_shape)
            ),
        )
        .into());
    }
    Ok(HostState {
        positions,
        velocities,
        dim: d,
    })
}

/// `state` as two NumPy arrays `[N, d]`.
fn to_arrays<'py>(py: Python<'py>, state: HostState) -> PyResult<ArrayPair<'py>> {
    let shape = [state.particles(), state.dim];
    Ok((
        to_numpy(py, &shape, state.positions)?.into_any(),
        to_numpy(py, &shape, state.velocities)?.into_any(),
    ))
}

#[pymethods]
impl FlipGradient {
    /// Builds ``scene``'s simulation for runs of ``steps`` steps.
    #[new]
    #[pyo3(signature = (scene, steps = None))]
    fn new(py: Python<'_>, scene: &Bound<'_, PyAny>, steps: Option<usize>) -> PyResult<Self> {
        let source = SceneSource::from_python(scene)?;
        let (inner, initial) = detached(py, move || {
            let (scene, origin) = source.read()?;
            Ok(phi_flip::FlipGradient::<Autodiff>::from_scene(
                &scene,
                &origin,
                steps,
                &Autodiff::default_device(),
            )?)
        })?;
        Ok(FlipGradient { inner, initial })
    }

    /// The scene's seeded initial positions, float32 ``[N, d]`` (``simulate``'s frame 0).
    #[getter]
    fn positions<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        Ok(to_arrays(py, self.initial.clone())?.0)
    }

    /// The scene's initial velocities, float32 ``[N, d]``.
    #[getter]
    fn velocities<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        Ok(to_arrays(py, self.initial.clone())?.1)
    }

    /// Steps per run.
    #[getter]
    fn steps(&self) -> usize {
        self.inner.steps()
    }

    /// Step length ``dt``, seconds.
    #[getter]
    fn dt(&self) -> f32 {
        self.inner.simulation().params().dt
    }

    /// The number of spatial dimensions ``d``.
    #[getter]
    fn dim(&self) -> usize {
        self.inner.simulation().domain().dim()
    }

    /// Runs the steps from ``positions`` and ``velocities`` (float32 ``[N, d]``, domain units
    /// and units per second) and returns the final ``(positions, velocities)``, float32
    /// ``[N_T, d]`` (``N_T = N`` unless inflows emit).
    ///
    /// Raises:
    ///     SimulationError: arrays that are not both ``[N, d]``, or a failed step.
    ///
    /// The GIL is released while the steps run.
    fn run<'py>(
        &self,
        py: Python<'py>,
        positions: &Bound<'py, PyAny>,
        velocities: &Bound<'py, PyAny>,
    ) -> PyResult<ArrayPair<'py>> {
        let initial = host_state(
            positions,
            velocities,
            self.dim(),
            "FlipGradient.run",
            ["positions", "velocities"],
        )?;
        let end = detached(py, || Ok(self.inner.run_host(&initial)?))?;
        to_arrays(py, end)
    }

    /// The vector-Jacobian product of the run at ``(positions, velocities)``: the gradients
    /// with respect to the initial positions and velocities of ``Σ grad_positions ⊙ x_T +
    /// Σ grad_velocities ⊙ v_T``, where ``grad_*`` are upstream gradients of the final state
    /// (float32 ``[N_T, d]``; ``None`` for zeros). Runs the steps again, recording them, and
    /// differentiates backwards through them.
    ///
    /// Returns:
    ///     ``(grad_initial_positions, grad_initial_velocities)``, float32 ``[N, d]``.
    ///
    /// Raises:
    ///     SimulationError: arrays of the wrong shape (the message names which), or a failed
    ///         step.
    ///
    /// The GIL is released while the steps run.
    #[pyo3(signature = (positions, velocities, grad_positions, grad_velocities = None))]
    fn vjp<'py>(
        &self,
        py: Python<'py>,
        positions: &Bound<'py, PyAny>,
        velocities: &Bound<'py, PyAny>,
        grad_positions: &Bound<'py, PyAny>,
        grad_velocities: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<ArrayPair<'py>> {
        let d = self.dim();
        let what = "FlipGradient.vjp";
        let initial = host_state(positions, velocities, d, what, ["positions", "velocities"])?;
        let upstream = match grad_velocities {
            Some(gv) => host_state(
                grad_positions,
                gv,
                d,
                what,
                ["grad_positions", "grad_velocities"],
            )?,
            None => {
                let (_, positions) = host_matrix(grad_positions, d, what, "grad_positions")?;
                HostState {
                    velocities: vec![0.0; positions.len()],
                    positions,
                    dim: d,
                }
            }
        };
        let gradient = detached(py, || Ok(self.inner.vjp_host(&initial, &upstream)?))?;
        to_arrays(py, gradient)
    }

    fn __repr__(&self) -> String {
        format!(
            "FlipGradient(steps={}, particles={}, dim={})",
            self.steps(),
            self.initial.particles(),
            self.dim()
        )
    }
}
