//! `phi_rs.Model`: a GNS model directory, rolled out by phi-gns's rollout stepper.

use std::path::{Path, PathBuf};

use phi_core::Tensor;
use phi_gns::data::{Trajectory, read_metadata};
use phi_gns::model::{
    ConfigOverrides, Gns, GnsConfig, GnsKernels, GraphBatch, MODEL_FILE, ModelSpec, Obstacles,
    WEIGHTS_FILE, Walls, load_model, save_model,
};
use phi_gns::rollout::{Rollout, RolloutRange, TrajectoryRollout, input_window};
use pyo3::prelude::*;

use crate::arrays::{host_array, shape_text, to_numpy};
use crate::backend::with_backend;
use crate::error::{Area, Error, detached};
use crate::evaluate::{eval_options, evaluate_on, evaluation_container};

/// A model loaded on one backend (boxed: the models differ in size by backend).
pub(crate) enum Loaded {
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
    pub(crate) inner: Loaded,
    /// The directory it was loaded from; `None` for a model made by `Model.init`.
    dir: Option<PathBuf>,
}

/// Evaluates `$body` with `$m` bound to the `Gns` inside `$loaded`, whatever its backend.
macro_rules! on_model {
    ($loaded:expr, $m:ident => $body:expr) => {
        match $loaded {
            Loaded::Ndarray($m) => $body,
            #[cfg(feature = "burn")]
            Loaded::Burn($m) => $body,
        }
    };
}
pub(crate) use on_model;

/// Loads `dir` on backend `B`.
fn load_on<B: GnsKernels>(dir: &Path) -> Result<Gns<B>, Error> {
    Ok(load_model::<B>(dir, &B::default_device())?)
}

/// Rolls `model` out on `trajectory` over `range`: `[steps * N * dim]`. Python's signals are
/// checked after every step, so Ctrl-C stops it with `KeyboardInterrupt`.
fn rollout_on<B: GnsKernels>(
    model: &Gns<B>,
    trajectory: &Trajectory,
    range: RolloutRange,
) -> Result<Vec<f32>, Error> {
    let mut frames = Vec::with_capacity(range.steps * trajectory.particles * trajectory.dim);
    for frame in TrajectoryRollout::new(model, trajectory, range, &B::default_device())? {
        frames.extend_from_slice(&frame?.positions);
        Python::attach(|py| py.check_signals()).map_err(Error::Python)?;
    }
    Ok(frames)
}

/// One step of `model` from `window` (`[N, C + 1, dim]`, the model's layout): the next
/// positions `[N, dim]`, kinematic particles at `kinematic` (`[N, dim]`).
fn predict_on<B: GnsKernels>(
    model: &Gns<B>,
    window: &[f32],
    types: &[i64],
    kinematic: &[f32],
) -> Result<Vec<f32>, Error> {
    let device = B::default_device();
    let spec = model.spec();
    let batch = GraphBatch::from_host(window, types, spec, &device)?;
    let kinematic = Tensor::from_slice(kinematic, &[types.len(), spec.config.dim], &device)
        .map_err(phi_gns::model::ModelError::from)?;
    let mut stepper = Rollout::new(model, batch)?;
    stepper.step(&kinematic)?;
    Ok(stepper.read().to_vec())
}

/// The argument of `Model.init` behind a `model.json` key.
fn init_argument(key: &str) -> Option<&'static str> {
    Some(match key {
        "config.latent_size" => "latent",
        "config.hidden_size" => "hidden",
        "config.hidden_layers" => "hidden_layers",
        "config.message_passing_steps" => "message_passing_steps",
        "config.input_velocities" => "input_velocities",
        "config.embedding_size" => "embedding",
        "config.connectivity_radius" => "radius",
        "config.noise_std" => "noise_std",
        "config.boundary_horizon" => "boundary_horizon",
        _ => return None,
    })
}

/// A fresh model of `spec` on backend `B`.
fn init_on<B: GnsKernels>(spec: ModelSpec) -> Result<Gns<B>, Error> {
    Ok(Gns::<B>::init(spec, &B::default_device())?)
}

impl Model {
    /// The spec of the loaded model.
    fn spec(&self) -> &phi_gns::model::ModelSpec {
        on_model!(&self.inner, m => m.spec())
    }
}

/// The walls a Python caller names: `"open"` or `"clamp"`.
fn parse_walls(name: &str, what: &str) -> Result<Walls, Error> {
    match name {
        "open" => Ok(Walls::Open),
        "clamp" => Ok(Walls::Clamp),
        other => Err(Error::argument(
            Area::Model,
            what,
            format!("'{other}' is not a kind of walls (use 'open' or 'clamp')"),
        )),
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
        Ok(Model {
            inner,
            dir: Some(dir),
        })
    }

    /// A new model for the dataset at ``data`` with seeded random weights, as ``phi model init
    /// --data DATA`` makes it (the same options and seed give the same weights, bit for bit).
    /// Sizes default to the thesis' GNS, ``radius`` to the dataset's
    /// ``default_connectivity_radius``, ``boundary_features`` to on unless the dataset's walls
    /// are particles, ``boundary_horizon`` (where the boundary features saturate, in multiples
    /// of the radius) to 1. The model lives in memory; ``save(dir)`` writes it.
    ///
    /// Raises:
    ///     DatasetError: ``data`` has no valid ``metadata.json``.
    ///     ModelError: options that do not make a valid model (naming the argument), a dataset
    ///         without usable statistics (naming its metadata key).
    #[staticmethod]
    #[pyo3(signature = (data, seed = 0, latent = None, hidden = None, hidden_layers = None, message_passing_steps = None, input_velocities = None, embedding = None, radius = None, boundary_features = None, boundary_horizon = None, noise_std = None, backend = "ndarray"))]
    #[allow(clippy::too_many_arguments)]
    fn init(
        py: Python<'_>,
        data: PathBuf,
        seed: u64,
        latent: Option<usize>,
        hidden: Option<usize>,
        hidden_layers: Option<usize>,
        message_passing_steps: Option<usize>,
        input_velocities: Option<usize>,
        embedding: Option<usize>,
        radius: Option<f64>,
        boundary_features: Option<bool>,
        boundary_horizon: Option<f64>,
        noise_std: Option<f64>,
        backend: &str,
    ) -> PyResult<Model> {
        let backend = backend.to_string();
        let inner = detached(py, move || {
            let metadata = read_metadata(&data)?;
            let overrides = ConfigOverrides {
                latent_size: latent,
                hidden_size: hidden,
                hidden_layers,
                message_passing_steps,
                input_velocities,
                embedding_size: embedding,
                connectivity_radius: radius,
                boundary_features,
                boundary_horizon,
                noise_std,
            };
            let config = GnsConfig::for_dataset(&metadata, &overrides);
            let mut spec = ModelSpec::for_dataset(&metadata, config, seed);
            spec.provenance = serde_json::json!({
                "made_by": "phi_rs.Model.init",
                "phi_version": env!("CARGO_PKG_VERSION"),
                "dataset": data.display().to_string(),
            });
            if let Err(error) = spec.validate(std::path::Path::new("Model.init")) {
                if let phi_gns::model::ModelError::Config { key, reason, .. } = &error {
                    if let Some(argument) = init_argument(key) {
                        return Err(Error::argument(
                            Area::Model,
                            format!("Model.init: {argument}"),
                            reason.clone(),
                        ));
                    }
                    let metadata_path = data.join(phi_gns::data::METADATA_FILE);
                    return Err(Error::argument(
                        Area::Model,
                        format!("Model.init: '{}': key '{key}'", metadata_path.display()),
                        reason.clone(),
                    ));
                }
                return Err(error.into());
            }
            with_backend!(backend.as_str(), B => init_on::<B>(spec).map(Into::into))
        })?;
        Ok(Model { inner, dir: None })
    }

    /// Writes ``model.json`` and ``model.safetensors`` into ``dir`` (created if missing), the
    /// files ``Model.load`` reads and ``phi rollout --model`` takes. A directory that already
    /// holds either file is refused unless ``overwrite``.
    ///
    /// Raises:
    ///     ModelError: the files exist (without ``overwrite``), or cannot be written.
    #[pyo3(signature = (dir, overwrite = false))]
    fn save(&self, py: Python<'_>, dir: PathBuf, overwrite: bool) -> PyResult<()> {
        detached(py, || {
            for file in [MODEL_FILE, WEIGHTS_FILE] {
                let path = dir.join(file);
                if !overwrite && path.exists() {
                    return Err(Error::argument(
                        Area::Model,
                        "Model.save",
                        format!(
                            "'{}' exists; pass overwrite=True to replace it",
                            path.display()
                        ),
                    ));
                }
            }
            std::fs::create_dir_all(&dir).map_err(|e| {
                Error::argument(
                    Area::Model,
                    "Model.save",
                    format!("cannot create '{}': {e}", dir.display()),
                )
            })?;
            on_model!(&self.inner, m => save_model(&dir, m))?;
            Ok(())
        })
    }

    /// The model's directory (``None`` for a model from ``Model.init`` not loaded from disk).
    #[getter]
    fn dir(&self) -> Option<PathBuf> {
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

    /// What the model's rollouts do at the domain's walls: ``"open"`` (predictions taken as
    /// they are) or ``"clamp"`` (each prediction clamped into the box of the model's bounds,
    /// as FLIP keeps its particles inside the domain).
    #[getter]
    fn walls(&self) -> &'static str {
        match self.spec().config.walls {
            Walls::Open => "open",
            Walls::Clamp => "clamp",
        }
    }

    /// The same model (the same weights, on the same backend) whose rollouts have the walls
    /// ``walls`` (``"open"`` or ``"clamp"``). The network is unchanged: with ``"clamp"``,
    /// ``predict`` is the open model's prediction clamped into the box.
    ///
    /// Raises:
    ///     ModelError: an unknown kind of walls.
    fn with_walls(&self, walls: &str) -> PyResult<Model> {
        let walls = parse_walls(walls, "with_walls")?;
        let inner = match &self.inner {
            Loaded::Ndarray(m) => Loaded::Ndarray(Box::new(m.with_walls(walls))),
            #[cfg(feature = "burn")]
            Loaded::Burn(m) => Loaded::Burn(Box::new(m.with_walls(walls))),
        };
        Ok(Model {
            inner,
            dir: self.dir.clone(),
        })
    }

    /// What the model's rollouts do with liquid predicted inside an obstacle: ``"open"``
    /// (predictions taken as they are) or ``"push"`` (pushed out of the obstacle particles'
    /// cells, as FLIP pushes its particles out of obstacles).
    #[getter]
    fn obstacles(&self) -> &'static str {
        match self.spec().config.obstacles {
            Obstacles::Open => "open",
            Obstacles::Push { .. } => "push",
        }
    }

    /// The same model (the same weights, on the same backend) whose rollouts treat liquid
    /// predicted inside an obstacle as ``obstacles`` says: ``"open"`` or ``"push"``, the
    /// latter out of the squares (cubes) of side ``cell_size`` around the obstacle particles,
    /// the dataset's ``position_scale``. The network is unchanged.
    ///
    /// Raises:
    ///     ModelError: an unknown kind, ``"push"`` without a positive ``cell_size``.
    #[pyo3(signature = (obstacles, cell_size = None))]
    fn with_obstacles(&self, obstacles: &str, cell_size: Option<f64>) -> PyResult<Model> {
        let obstacles = match (obstacles, cell_size) {
            ("open", _) => Obstacles::Open,
            ("push", Some(cell_size)) => Obstacles::Push { cell_size },
            ("push", None) => {
                return Err(Error::argument(
                    Area::Model,
                    "with_obstacles",
                    "'push' needs the cell_size of the dataset's obstacle particles",
                )
                .into());
            }
            (other, _) => {
                return Err(Error::argument(
                    Area::Model,
                    "with_obstacles",
                    format!("'{other}' is not a kind of obstacles (use 'open' or 'push')"),
                )
                .into());
            }
        };
        let inner = match &self.inner {
            Loaded::Ndarray(m) => {
                Loaded::Ndarray(Box::new(m.with_obstacles(obstacles).map_err(Error::from)?))
            }
            #[cfg(feature = "burn")]
            Loaded::Burn(m) => {
                Loaded::Burn(Box::new(m.with_obstacles(obstacles).map_err(Error::from)?))
            }
        };
        Ok(Model {
            inner,
            dir: self.dir.clone(),
        })
    }

    /// The content of ``model.json`` as a dict.
    #[getter]
    fn spec_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let text = serde_json::to_string(self.spec()).map_err(|e| {
            Error::argument(Area::Model, "model.json", format!("cannot be written: {e}"))
        })?;
        py.import("json")?.call_method1("loads", (text,))
    }

    /// One step of the model: the positions after the window's last frame, as a rollout's
    /// step computes them (``rollout``'s first frame is ``predict`` of its input window with
    /// ``kinematic`` the ground truth's next frame).
    ///
    /// Args:
    ///     window: float32 ``[C + 1, N, d]``, the particles' last ``C + 1`` positions, oldest
    ///         first (``positions[t - C : t + 1]`` of a dataset trajectory), stored units.
    ///     particle_type: int64 ``[N]`` (0 = obstacle, 1 = liquid).
    ///     kinematic: float32 ``[N, d]``, where kinematic particles (obstacles) are at the next
    ///         frame; ``None`` leaves them at the window's last positions.
    ///
    /// Returns:
    ///     float32 ``[N, d]``: the next positions of every particle.
    ///
    /// Raises:
    ///     ModelError: arrays of the wrong shape, a type the model does not know.
    ///
    /// The GIL is released while the model runs.
    #[pyo3(signature = (window, particle_type, kinematic = None))]
    fn predict<'py>(
        &self,
        py: Python<'py>,
        window: &Bound<'py, PyAny>,
        particle_type: &Bound<'py, PyAny>,
        kinematic: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let c = self.input_velocities();
        let dim = self.dim();
        let (shape, values) = host_array::<f32>(window, "float32", Area::Model, "predict: window")?;
        if shape.len() != 3 || shape[0] != c + 1 || shape[2] != dim {
            return Err(Error::argument(
                Area::Model,
                "predict: window",
                format!(
                    "shape {}: the model reads [{}, N, {dim}] (C + 1 frames, oldest first)",
                    shape_text(&shape),
                    c + 1
                ),
            )
            .into());
        }
        let n = shape[1];
        let (type_shape, types) = host_array::<i64>(
            particle_type,
            "int64",
            Area::Model,
            "predict: particle_type",
        )?;
        if type_shape != [n] {
            return Err(Error::argument(
                Area::Model,
                "predict: particle_type",
                format!(
                    "shape {}: expected ({n},), one type per particle of the window",
                    shape_text(&type_shape)
                ),
            )
            .into());
        }
        let kinematic = match kinematic {
            Some(k) => {
                let (k_shape, k_values) =
                    host_array::<f32>(k, "float32", Area::Model, "predict: kinematic")?;
                if k_shape != [n, dim] {
                    return Err(Error::argument(
                        Area::Model,
                        "predict: kinematic",
                        format!("shape {}: expected ({n}, {dim})", shape_text(&k_shape)),
                    )
                    .into());
                }
                k_values
            }
            None => values[c * n * dim..].to_vec(),
        };
        let next = detached(py, || {
            let trajectory = Trajectory::new(dim, values, types.clone(), 0, 0)
                .map_err(|e| Error::argument(Area::Model, "predict: window", e.to_string()))?;
            let window = input_window(&trajectory, c, c);
            on_model!(&self.inner, m => predict_on(m, &window, &types, &kinematic))
        })?;
        Ok(to_numpy(py, &[n, dim], next)?.into_any())
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
    ///     kinematic: float32 ``[S, N, d]``, where the kinematic particles are at the ``S``
    ///         frames after ``positions`` (only their rows are read): a rollout of a window
    ///         (``positions`` of ``C + 1`` frames) with no ground truth after it. Obstacles
    ///         that stay put: ``np.repeat(window[-1:], S, axis=0)``.
    ///
    /// Returns:
    ///     float32 ``[steps, N, d]``: the predicted frames ``start + 1 ..= start + steps``.
    ///
    /// Raises:
    ///     ModelError: arrays of the wrong shape or dimension, a range past the trajectory's
    ///         end, a non-finite prediction (naming the step and the particle).
    ///
    /// The GIL is released while the model runs; Ctrl-C stops it between steps.
    #[pyo3(signature = (positions, particle_type, steps = None, start = None, kinematic = None))]
    fn rollout<'py>(
        &self,
        py: Python<'py>,
        positions: &Bound<'py, PyAny>,
        particle_type: &Bound<'py, PyAny>,
        steps: Option<usize>,
        start: Option<usize>,
        kinematic: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (mut frames, n, d, mut values, types) =
            trajectory_arrays(positions, particle_type, "rollout")?;
        if let Some(kinematic) = kinematic {
            let (shape, after) =
                host_array::<f32>(kinematic, "float32", Area::Model, "rollout: kinematic")?;
            let more = match shape[..] {
                [more, kn, kd] if (kn, kd) == (n, d) => more,
                _ => {
                    return Err(Error::argument(
                        Area::Model,
                        "rollout: kinematic",
                        format!("shape {}: expected [S, {n}, {d}]", shape_text(&shape)),
                    )
                    .into());
                }
            };
            frames += more;
            values.extend_from_slice(&after);
        }
        let c = self.input_velocities();
        let start = start.unwrap_or(c);
        let steps = steps.unwrap_or_else(|| frames.saturating_sub(start + 1));
        let range = RolloutRange { start, steps };
        let predicted = detached(py, || {
            let trajectory = Trajectory::new(d, values, types, 0, 0)
                .map_err(|e| Error::argument(Area::Model, "rollout: trajectory", e.to_string()))?;
            on_model!(&self.inner, m => rollout_on(m, &trajectory, range))
        })?;
        Ok(to_numpy(py, &[steps, n, d], predicted)?.into_any())
    }

    /// Evaluates the model on one ground-truth trajectory as ``phi eval`` does (thesis section
    /// 5.4), over its liquid particles, and returns the evaluation as a dict: ``mse_acc1``
    /// (every one-step window, in the model's normalisation), ``mse20`` (rollouts of
    /// ``short_rollout`` steps from frames ``C, C + 20, …``), ``mse400`` (the full rollout from
    /// frame ``C``), ``emd``, ``sinkhorn``, ``kinetic_energy_error``, ``density_ratio``,
    /// ``failed_step`` and the per-frame ``curves``; a metric of a rollout that blew up is
    /// ``None``. With ``bounds`` and ``cell_size`` (the container: a dataset's
    /// ``metadata["bounds"]`` and ``metadata["position_scale"]``) it adds ``plausibility``
    /// (the fractions of the liquid's particle-frames ``outside`` the domain and
    /// ``inside_obstacles``, ``final_density_ratio``, ``late_kinetic_energy_ratio``,
    /// ``final_centre_distance_cells``) and ``plausible``, the verdict of ``phi eval``.
    ///
    /// Args:
    ///     positions: float32 ``[T, N, d]`` in stored units (a dataset trajectory).
    ///     particle_type: int64 ``[N]``.
    ///     short_rollout: the length of MSE 20's rollouts.
    ///     emd_cost: ``"sqeuclidean"`` or ``"euclidean"``.
    ///     sinkhorn_epsilon, sinkhorn_every: the Sinkhorn divergence's ``ε`` and frame stride
    ///         (0: none).
    ///     density_radius: the radius of the density's neighbour counts; ``None`` is the
    ///         model's connectivity radius.
    ///     bounds: ``(min, max)`` per axis, stored units: the domain the liquid must stay in.
    ///     cell_size: the side of a grid cell, stored units (obstacle particles sit one at the
    ///         centre of each obstacle cell).
    ///
    /// Raises:
    ///     ModelError: arrays that do not fit the model, a trajectory too short for a window,
    ///         one without liquid, a container that is not one.
    ///
    /// The GIL is released while it runs.
    #[pyo3(signature = (positions, particle_type, short_rollout = 20, emd_cost = "sqeuclidean", sinkhorn_epsilon = 1e-4, sinkhorn_every = 100, density_radius = None, bounds = None, cell_size = None))]
    #[allow(clippy::too_many_arguments)] // Python's keyword arguments
    fn evaluate<'py>(
        &self,
        py: Python<'py>,
        positions: &Bound<'py, PyAny>,
        particle_type: &Bound<'py, PyAny>,
        short_rollout: usize,
        emd_cost: &str,
        sinkhorn_epsilon: f32,
        sinkhorn_every: usize,
        density_radius: Option<f64>,
        bounds: Option<Vec<Vec<f64>>>,
        cell_size: Option<f64>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (_, _, d, values, types) = trajectory_arrays(positions, particle_type, "evaluate")?;
        let mut options = eval_options(
            "evaluate",
            short_rollout,
            emd_cost,
            sinkhorn_epsilon,
            sinkhorn_every,
            density_radius.unwrap_or(self.spec().config.connectivity_radius),
        )?;
        options.container = evaluation_container(bounds, cell_size, self.dim())?;
        let text = detached(py, || {
            let trajectory = Trajectory::new(d, values, types, 0, 0)
                .map_err(|e| Error::argument(Area::Model, "evaluate: trajectory", e.to_string()))?;
            let evaluation = on_model!(&self.inner, m => evaluate_on(m, &trajectory, &options))?;
            let unwritable = |e: serde_json::Error| {
                Error::argument(Area::Model, "evaluate", format!("cannot be written: {e}"))
            };
            let mut value = serde_json::to_value(&evaluation).map_err(unwritable)?;
            if options.container.is_some() {
                value["plausible"] = serde_json::Value::from(
                    evaluation.plausibility.as_ref().map(|p| p.is_plausible()),
                );
            }
            serde_json::to_string(&value).map_err(unwritable)
        })?;
        py.import("json")?.call_method1("loads", (text,))
    }

    fn __repr__(&self) -> String {
        let dir = match &self.dir {
            Some(dir) => format!("'{}'", dir.display()),
            None => "None".to_string(),
        };
        format!(
            "Model({dir}, backend='{}', dim={}, input_velocities={})",
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

/// A trajectory from Python: positions float32 `[T, N, d]` and particle types int64 `[N]`, as
/// `(T, N, d, positions, types)`; `function` names the call in the errors.
#[allow(clippy::type_complexity)]
fn trajectory_arrays(
    positions: &Bound<'_, PyAny>,
    particle_type: &Bound<'_, PyAny>,
    function: &str,
) -> PyResult<(usize, usize, usize, Vec<f32>, Vec<i64>)> {
    let what = |name: &str| format!("{function}: {name}");
    let (shape, values) = host_array::<f32>(positions, "float32", Area::Model, &what("positions"))?;
    let (type_shape, types) =
        host_array::<i64>(particle_type, "int64", Area::Model, &what("particle_type"))?;
    let [frames, n, d] = shape[..] else {
        return Err(Error::argument(
            Area::Model,
            what("positions"),
            format!("shape {}: expected [T, N, d]", shape_text(&shape)),
        )
        .into());
    };
    if type_shape != [n] {
        return Err(Error::argument(
            Area::Model,
            what("particle_type"),
            format!(
                "shape {}: expected ({n},), one type per particle of positions",
                shape_text(&type_shape)
            ),
        )
        .into());
    }
    Ok((frames, n, d, values, types))
}
