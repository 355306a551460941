//! `phi_rs.Simulation`: a scene's simulation stepped on demand (phi-flip's `SceneRun`, the run
//! that `run_scene`, and so `phi_rs.simulate`, steps).

use phi_core::Backend;
use phi_core::backend::ndarray::NdArray;
use phi_flip::SceneRun;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::arrays::to_numpy;
use crate::backend::with_backend;
use crate::error::detached;
use crate::simulate::{LIQUID, SceneSource};

/// A run on one backend (boxed: the states differ in size by backend).
enum Run {
    Ndarray(Box<SceneRun<NdArray>>),
    #[cfg(feature = "burn")]
    Burn(Box<SceneRun<phi_core::backend::burn::Burn>>),
}

impl From<SceneRun<NdArray>> for Run {
    fn from(run: SceneRun<NdArray>) -> Self {
        Run::Ndarray(Box::new(run))
    }
}

#[cfg(feature = "burn")]
impl From<SceneRun<phi_core::backend::burn::Burn>> for Run {
    fn from(run: SceneRun<phi_core::backend::burn::Burn>) -> Self {
        Run::Burn(Box::new(run))
    }
}

/// Evaluates `$body` with `$r` bound to the `SceneRun` inside `$run`, whatever its backend.
macro_rules! on_run {
    ($run:expr, $r:ident => $body:expr) => {
        match $run {
            Run::Ndarray($r) => $body,
            #[cfg(feature = "burn")]
            Run::Burn($r) => $body,
        }
    };
}

/// A FLIP scene's simulation that steps on demand: the run ``simulate`` records, one step at a
/// time. Its state after ``k`` steps is ``simulate(scene, steps=k)``'s frame ``k``, bit for
/// bit.
///
/// Args:
///     scene: the path of a scene TOML file (``str`` or ``os.PathLike``), or the TOML text
///         itself (a ``str`` with a line break in it), as ``simulate`` takes it.
///     backend: ``"ndarray"`` (the fast CPU path) or ``"burn"``.
///
/// Raises:
///     SceneError: the scene cannot be read, parsed or built (the message names the file and
///         the key).
///     PhiError: an unknown backend.
#[pyclass(module = "phi_rs")]
pub struct Simulation {
    run: Run,
}

impl Simulation {
    /// The current state's positions (or with `velocities` its velocities) as `[N, d]`.
    fn state<'py>(&self, py: Python<'py>, velocities: bool) -> PyResult<Bound<'py, PyAny>> {
        let (values, d) = on_run!(&self.run, r => {
            let particles = r.particles();
            let tensor = if velocities { &particles.velocities } else { &particles.positions };
            (tensor.to_vec(), r.simulation().domain().dim())
        });
        let n = values.len() / d;
        Ok(to_numpy(py, &[n, d], values)?.into_any())
    }
}

#[pymethods]
impl Simulation {
    /// Builds ``scene`` on ``backend`` at its initial state (step 0).
    #[new]
    #[pyo3(signature = (scene, backend = "ndarray"))]
    fn new(py: Python<'_>, scene: &Bound<'_, PyAny>, backend: &str) -> PyResult<Simulation> {
        let source = SceneSource::from_python(scene)?;
        let backend = backend.to_string();
        let run = detached(py, move || {
            let (scene, origin) = source.read()?;
            with_backend!(backend.as_str(), B => {
                Ok(Run::from(SceneRun::<B>::new(&scene, &origin, &B::default_device())?))
            })
        })?;
        Ok(Simulation { run })
    }

    /// Advances the simulation ``n`` steps (``n = 0`` does nothing).
    ///
    /// The GIL is released during each step, and Python's signals are checked after each: a
    /// Ctrl-C interrupts a long ``step(n)`` with ``KeyboardInterrupt`` and leaves the state at
    /// the last completed step. A failed step (``SimulationError``) leaves it at the step
    /// before.
    ///
    /// Raises:
    ///     TypeError: ``n`` is not an integer.
    ///     ValueError: ``n`` is negative.
    ///     SimulationError: a step failed (an unstable or non-finite state, a failed solve).
    #[pyo3(signature = (n = 1))]
    fn step(&mut self, py: Python<'_>, n: i64) -> PyResult<()> {
        let steps = usize::try_from(n).map_err(|_| {
            PyValueError::new_err(format!(
                "Simulation.step: n is the number of steps to take, at least 0; got {n}"
            ))
        })?;
        for _ in 0..steps {
            let run = &mut self.run;
            detached(py, move || {
                on_run!(run, r => r.step())?;
                Ok(())
            })?;
            py.check_signals()?;
        }
        Ok(())
    }

    /// Positions float32 ``[N, d]`` of the current state, domain units (the particles that
    /// exist now).
    #[getter]
    fn positions<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        self.state(py, false)
    }

    /// Velocities float32 ``[N, d]`` of the current state, domain units per second.
    #[getter]
    fn velocities<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        self.state(py, true)
    }

    /// Particle types int32 ``[N]`` of the current state (1 = liquid, as in ``simulate``).
    #[getter]
    fn particle_type<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let n = on_run!(&self.run, r => r.particles().len());
        Ok(to_numpy(py, &[n], vec![LIQUID; n])?.into_any())
    }

    /// Simulated time of the current state, seconds: ``steps · dt`` (``simulate``'s
    /// ``time[steps]``).
    #[getter]
    fn time(&self) -> f32 {
        on_run!(&self.run, r => r.time())
    }

    /// Steps done so far.
    #[getter]
    fn steps(&self) -> usize {
        on_run!(&self.run, r => r.steps_done())
    }

    /// Step length ``dt``, seconds.
    #[getter]
    fn dt(&self) -> f32 {
        on_run!(&self.run, r => r.simulation().params().dt)
    }

    /// The number of spatial dimensions ``d``.
    #[getter]
    fn dim(&self) -> usize {
        on_run!(&self.run, r => r.simulation().domain().dim())
    }

    /// The backend the simulation runs on.
    #[getter]
    fn backend(&self) -> &'static str {
        match &self.run {
            Run::Ndarray(_) => "ndarray",
            #[cfg(feature = "burn")]
            Run::Burn(_) => "burn",
        }
    }

    fn __repr__(&self) -> String {
        let particles = on_run!(&self.run, r => r.particles().len());
        format!(
            "Simulation(steps={}, time={}, particles={particles}, backend='{}')",
            self.steps(),
            self.time(),
            self.backend()
        )
    }
}
