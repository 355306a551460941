"""phi from Python: FLIP liquid simulation, GNS datasets and models, point-set distances."""

import os
from typing import Any, Callable, Dict, Iterator, List, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str
#: The backends of this build, the default first: ``["ndarray", "burn"]``.
BACKENDS: List[str]

class PhiError(Exception):
    """The base class of every error phi_rs raises."""

class SceneError(PhiError):
    """A scene that cannot be read, parsed or built; the message names the file and the key."""

class SimulationError(PhiError):
    """A simulation step that failed: an unstable or non-finite state, a failed solve."""

class DatasetError(PhiError):
    """A dataset that cannot be read, or a split or index it does not have."""

class ModelError(PhiError):
    """A model directory that cannot be loaded, or input that does not fit the model."""

class TrainingError(PhiError):
    """A training run that cannot start or go on: a preset, an output directory, a diverged
    step."""

class PointSetError(PhiError):
    """Point sets that a distance cannot compare."""

def generate_dataset(
    out: Union[str, os.PathLike[str]],
    split: str = "all",
    trajectories: Optional[int] = None,
    seed: int = 0,
    variant: str = "obstacles",
    steps: Optional[int] = None,
    threads: Optional[int] = None,
    shard: Tuple[int, int] = (0, 1),
    resume: bool = False,
    prune: bool = False,
    force: bool = False,
    progress: Optional[Callable[[int, int], object]] = None,
) -> Dict[str, float]:
    """Simulates a dataset of random FLIP scenes (table 5.1) into ``out`` as ``phi dataset
    generate`` does, byte for byte; ``progress(done, total)`` after each trajectory (an
    exception in it stops the run, keeping the finished files). Returns ``written``,
    ``skipped``, ``remade`` and ``seconds``. Raises ``DatasetError``."""

def evaluate(
    models: Dict[str, "Model"],
    data: Union[str, os.PathLike[str]],
    split: str = "test",
    trajectories: Optional[int] = None,
    short_rollout: int = 20,
    emd_cost: str = "sqeuclidean",
    sinkhorn_epsilon: float = 1e-4,
    sinkhorn_every: int = 0,
    density_radius: Optional[float] = None,
) -> Dict[str, Any]:
    """Evaluates ``{name: Model}`` on the first ``trajectories`` (all) trajectories of a
    dataset's split as ``phi eval`` does, against the dataset's container: ``{"models": {name:
    summary}, "trajectories": {name: [evaluation, ...]}}``, each summary a row of ``phi eval``'s
    table (``plausibility.plausible`` counts plausible rollouts), each evaluation
    ``Model.evaluate``'s dict. Raises ``DatasetError`` and ``ModelError``."""

def merge_dataset(
    out: Union[str, os.PathLike[str]],
    shards: Sequence[Union[str, os.PathLike[str]]],
    force: bool = False,
) -> Dict[str, Any]:
    """Joins the shard directories of ``generate_dataset(shard=(k, n))`` into the dataset
    ``out`` as ``phi dataset merge`` does (files hard-linked; the dataset of an unsharded run,
    byte for byte). Returns ``counts`` (trajectories per split) and ``files``. Raises
    ``DatasetError``."""

def simulate(
    scene: Union[str, "os.PathLike[str]"],
    steps: Optional[int] = None,
    backend: str = "ndarray",
) -> Dict[str, np.ndarray]:
    """Runs a FLIP scene (a TOML file, or TOML text with a line break) and returns the arrays of
    ``phi simulate``'s ``trajectory.npz``: ``positions``, ``velocities`` float32 ``[T+1, N, d]``,
    ``particle_type`` int32 ``[N]``, ``particle_count`` int32 ``[T+1]``, ``time`` float32
    ``[T+1]``, ``steps_completed`` int64 ``[1]`` (and ``affine`` for APIC scenes)."""

class Simulation:
    """A FLIP scene's simulation that steps on demand: the run ``simulate`` records, one step at
    a time. After ``k`` steps its state is ``simulate(scene, steps=k)``'s frame ``k``, bit for
    bit. Raises ``SceneError`` for a scene that cannot be read, parsed or built (the message
    names the file and the key), ``PhiError`` for an unknown backend."""

    def __init__(
        self, scene: Union[str, "os.PathLike[str]"], backend: str = "ndarray"
    ) -> None:
        """Builds ``scene`` (a TOML file, or TOML text with a line break, as ``simulate`` takes
        it) on ``backend`` at its initial state (step 0)."""
    def step(self, n: int = 1) -> None:
        """Advances ``n`` steps (``0`` does nothing), the GIL released during each. Python's
        signals are checked after every step: Ctrl-C raises ``KeyboardInterrupt`` and leaves the
        state at the last completed step; a failed step raises ``SimulationError`` and leaves it
        at the step before. ``TypeError`` for a non-integer ``n``, ``ValueError`` for a negative
        one."""
    @property
    def positions(self) -> npt.NDArray[np.float32]:
        """Positions ``[N, d]`` of the current state (the particles that exist now)."""
    @property
    def velocities(self) -> npt.NDArray[np.float32]:
        """Velocities ``[N, d]`` of the current state, domain units per second."""
    @property
    def particle_type(self) -> npt.NDArray[np.int32]:
        """Particle types ``[N]`` of the current state (1 = liquid)."""
    @property
    def time(self) -> float:
        """Simulated seconds, ``steps · dt`` (``simulate``'s ``time[steps]``)."""
    @property
    def steps(self) -> int:
        """Steps done so far."""
    @property
    def dt(self) -> float:
        """Step length, seconds."""
    @property
    def dim(self) -> int: ...
    @property
    def backend(self) -> str: ...

def emd(a: npt.ArrayLike, b: npt.ArrayLike, cost: str = "sqeuclidean") -> float:
    """The exact earth mover's distance between two ``[N, d]`` point sets: the mean ground cost
    (``"sqeuclidean"`` or ``"euclidean"``) of the optimal one-to-one assignment."""

def sinkhorn(
    a: npt.ArrayLike,
    b: npt.ArrayLike,
    epsilon: float = 1e-4,
    scaling: float = 0.7,
    tolerance: Optional[float] = None,
    max_iterations: int = 1000,
) -> float:
    """The debiased Sinkhorn divergence between the uniform measures on ``a`` ``[N, d]`` and
    ``b`` ``[M, d]``, cost ``½|x − y|²`` (``phi eval``'s): ``S ≥ 0``, ``S(a, a) = 0``, and
    ``S → ½ emd(a, b)`` as ``epsilon → 0``. Log-domain iterations in float64 with ε-scaling;
    ``tolerance`` defaults to ``1e-6 · epsilon``. ``PointSetError`` for arrays that are not
    ``[N, d]``, different ``d``, non-finite values, an ``epsilon`` or ``scaling`` out of
    range."""

def position_mse(
    predicted: npt.ArrayLike,
    truth: npt.ArrayLike,
    particle_type: Optional[npt.ArrayLike] = None,
    per_frame: bool = False,
) -> Union[float, npt.NDArray[np.float64]]:
    """``phi eval``'s position MSE: per frame of ``[T, N, d]`` (or one ``[N, d]``) arrays, the
    mean squared difference over the non-kinematic particles (type 0 is kinematic) and the
    components, in float64; their mean, or with ``per_frame`` the ``[T]`` curve."""

class Dataset:
    """A GNS dataset directory written by ``phi dataset generate``."""

    def __init__(self, path: Union[str, "os.PathLike[str]"]) -> None: ...
    @property
    def path(self) -> str: ...
    @property
    def metadata(self) -> Dict[str, Any]:
        """The content of ``metadata.json``."""
    @property
    def splits(self) -> List[str]: ...
    def len(self, split: str = "train") -> int:
        """The number of trajectories in ``split``."""
    def __len__(self) -> int:
        """``len(ds)``: the number of trajectories in all splits together."""
    def windows(
        self,
        split: str = "train",
        input_velocities: int = 5,
        seed: Optional[int] = None,
        batch_size: int = 2,
        start_step: int = 0,
        steps: Optional[int] = None,
    ) -> "Windows":
        """The training windows of ``split`` as ``phi train`` cuts them: items
        ``((window [C+1, N, d] float32, particle_type [N] int64), target [N, d] float32)``,
        the target being the frame after the window's last. ``seed=None``: every valid window
        once, in (trajectory, frame) order. A ``seed``: the trainer's draws with that seed,
        ``batch_size`` per step from ``start_step``, for ``steps`` steps or without end.
        ``DatasetError`` for an unknown split or trajectories shorter than a window."""
    def __getitem__(
        self, key: Tuple[str, int]
    ) -> Tuple[npt.NDArray[np.float32], npt.NDArray[np.int64]]:
        """``ds[split, i]``: positions float32 ``[frames, N, d]`` and particle types int64
        ``[N]``."""

class Windows(Iterator[Tuple[Tuple[npt.NDArray[np.float32], npt.NDArray[np.int64]], npt.NDArray[np.float32]]]):
    """An iterator over training windows (``Dataset.windows``); ``len()`` is the number still
    to come (``TypeError`` for an endless one)."""

    def __iter__(self) -> "Windows": ...
    def __next__(
        self,
    ) -> Tuple[Tuple[npt.NDArray[np.float32], npt.NDArray[np.int64]], npt.NDArray[np.float32]]: ...
    def __len__(self) -> int: ...

class Model:
    """A GNS model directory (``model.json`` + ``model.safetensors``)."""

    @staticmethod
    def load(dir: Union[str, "os.PathLike[str]"], backend: str = "ndarray") -> "Model": ...
    @staticmethod
    def init(
        data: Union[str, "os.PathLike[str]"],
        seed: int = 0,
        latent: Optional[int] = None,
        hidden: Optional[int] = None,
        hidden_layers: Optional[int] = None,
        message_passing_steps: Optional[int] = None,
        input_velocities: Optional[int] = None,
        embedding: Optional[int] = None,
        radius: Optional[float] = None,
        boundary_features: Optional[bool] = None,
        boundary_horizon: Optional[float] = None,
        noise_std: Optional[float] = None,
        backend: str = "ndarray",
    ) -> "Model":
        """A new model for the dataset at ``data`` with seeded random weights, as ``phi model
        init`` makes it with the same options (bit for bit). In memory; ``save`` writes it.
        ``DatasetError`` for a dataset without a valid ``metadata.json``, ``ModelError`` for
        options that do not make a valid model (naming the argument)."""
    def save(self, dir: Union[str, "os.PathLike[str]"], overwrite: bool = False) -> None:
        """Writes ``model.json`` and ``model.safetensors`` into ``dir``; existing files are
        refused (``ModelError``) unless ``overwrite``."""
    @property
    def dir(self) -> Optional[str]:
        """The directory the model was loaded from (``None`` after ``Model.init``)."""
    @property
    def backend(self) -> str: ...
    @property
    def dim(self) -> int: ...
    @property
    def input_velocities(self) -> int: ...
    @property
    def walls(self) -> str:
        """``"open"`` or ``"clamp"``: what the model's rollouts do at the domain's walls."""
    def with_walls(self, walls: str) -> "Model":
        """The same model whose rollouts have the walls ``walls`` (``"open"``: predictions
        taken as they are; ``"clamp"``: each clamped into the box of the model's bounds, as
        FLIP keeps its particles in the domain). The network is unchanged: with ``"clamp"``,
        ``predict`` is the open model's prediction clamped into the box."""
    @property
    def obstacles(self) -> str:
        """``"open"`` or ``"push"``: what the model's rollouts do with liquid predicted inside
        an obstacle."""
    def with_obstacles(self, obstacles: str, cell_size: Optional[float] = None) -> "Model":
        """The same model whose rollouts push liquid predicted inside an obstacle particle's
        cell (a square or cube of side ``cell_size``, the dataset's ``position_scale``) out to
        the nearest free cell (``"push"``), or take it as it is (``"open"``)."""
    @property
    def spec_dict(self) -> Dict[str, Any]:
        """The content of ``model.json``."""
    def predict(
        self,
        window: npt.ArrayLike,
        particle_type: npt.ArrayLike,
        kinematic: Optional[npt.ArrayLike] = None,
    ) -> npt.NDArray[np.float32]:
        """One step: the positions ``[N, d]`` after a window ``[C+1, N, d]`` (oldest first),
        as a rollout's step computes them; kinematic particles go to ``kinematic`` ``[N, d]``
        (default: they stay at the window's last positions)."""
    def rollout(
        self,
        positions: npt.ArrayLike,
        particle_type: npt.ArrayLike,
        steps: Optional[int] = None,
        start: Optional[int] = None,
        kinematic: Optional[npt.ArrayLike] = None,
    ) -> npt.NDArray[np.float32]:
        """Rolls the model out from frame ``start`` (default ``C``) of a ground-truth trajectory
        ``[T, N, d]``; returns the predicted frames ``[steps, N, d]``. ``kinematic``
        ``[S, N, d]`` appends the kinematic particles' next frames: a window of ``C + 1``
        frames rolled out with no ground truth after it."""
    def evaluate(
        self,
        positions: npt.ArrayLike,
        particle_type: npt.ArrayLike,
        short_rollout: int = 20,
        emd_cost: str = "sqeuclidean",
        sinkhorn_epsilon: float = 1e-4,
        sinkhorn_every: int = 100,
        density_radius: Optional[float] = None,
        bounds: Optional[Sequence[Tuple[float, float]]] = None,
        cell_size: Optional[float] = None,
    ) -> Dict[str, Any]:
        """Evaluates the model on one trajectory ``[T, N, d]`` as ``phi eval`` does: a dict with
        ``mse_acc1``, ``mse20``, ``mse400``, ``emd``, ``sinkhorn``, ``kinetic_energy_error``,
        ``density_ratio``, ``failed_step`` and the per-frame ``curves`` (``None`` for a metric
        of a rollout that blew up). ``density_radius`` defaults to the connectivity radius.
        With ``bounds`` and ``cell_size`` (a dataset's ``metadata["bounds"]`` and
        ``metadata["position_scale"]``) it adds ``plausibility`` (``outside``,
        ``inside_obstacles``, ``final_density_ratio``, ``late_kinetic_energy_ratio``,
        ``final_centre_distance_cells``) and ``plausible``, ``phi eval``'s verdict."""

def train(
    out: Union[str, "os.PathLike[str]"],
    data: Optional[Union[str, "os.PathLike[str]"]] = None,
    config: Optional[Union[str, "os.PathLike[str]"]] = None,
    steps: Optional[int] = None,
    resume: bool = False,
    init_from: Optional[Union[str, "os.PathLike[str]"]] = None,
    batch_size: Optional[int] = None,
    seed: Optional[int] = None,
    noise_std: Optional[float] = None,
    extra_steps: Optional[int] = None,
    log_every: Optional[int] = None,
    checkpoint_every: Optional[int] = None,
    screen_every: Optional[int] = None,
    emd_every: Optional[int] = None,
    select_by: Optional[str] = None,
    ema_decay: Optional[float] = None,
    progress: Optional[Callable[[int, int, float, float], Any]] = None,
) -> Dict[str, Any]:
    """Trains a GNS as ``phi train --backend burn`` does (the same curve and weights), into the
    training directory ``out``; ``resume`` continues from its newest checkpoint. The options
    override the preset's as ``phi train``'s do. ``progress(step, total, loss, learning_rate)``
    is called after every step; an exception from it (or Ctrl-C) stops the run after a
    checkpoint. Returns ``{"step", "loss", "best", "out"}``. ``TrainingError`` for a preset,
    directory or resume that does not work (naming the key), ``DatasetError``/``ModelError``
    for data or models that do not load or fit. Releases the GIL during each step."""

class FlipGradient:
    """A FLIP scene's run of ``steps`` steps as a differentiable function of the initial
    particle positions and velocities, on the Burn (autodiff) backend: ``run`` is the forward
    map ``(x0, v0) -> (x_T, v_T)``, ``vjp`` its vector-Jacobian product. ``phi_rs.torch`` wraps
    it as a ``torch.autograd.Function``. ``SceneError`` for a scene that does not build."""

    def __init__(
        self, scene: Union[str, "os.PathLike[str]"], steps: Optional[int] = None
    ) -> None:
        """Builds ``scene`` (a TOML file, or TOML text with a line break) for runs of ``steps``
        steps (default: the scene's ``simulation.steps``)."""
    @property
    def positions(self) -> npt.NDArray[np.float32]:
        """The scene's seeded initial positions ``[N, d]`` (``simulate``'s frame 0)."""
    @property
    def velocities(self) -> npt.NDArray[np.float32]:
        """The scene's initial velocities ``[N, d]``."""
    @property
    def steps(self) -> int: ...
    @property
    def dt(self) -> float: ...
    @property
    def dim(self) -> int: ...
    def run(
        self, positions: npt.ArrayLike, velocities: npt.ArrayLike
    ) -> Tuple[npt.NDArray[np.float32], npt.NDArray[np.float32]]:
        """The final ``(positions, velocities)`` ``[N_T, d]`` after the steps from the initial
        state ``[N, d]``. ``SimulationError`` for arrays that are not ``[N, d]`` or a failed
        step. Releases the GIL."""
    def vjp(
        self,
        positions: npt.ArrayLike,
        velocities: npt.ArrayLike,
        grad_positions: npt.ArrayLike,
        grad_velocities: Optional[npt.ArrayLike] = None,
    ) -> Tuple[npt.NDArray[np.float32], npt.NDArray[np.float32]]:
        """The gradients ``[N, d]`` with respect to the initial positions and velocities of
        ``sum(grad_positions * x_T) + sum(grad_velocities * v_T)`` (upstream gradients
        ``[N_T, d]``; ``None`` for zeros). Runs the steps again, recording them. Releases the
        GIL."""
