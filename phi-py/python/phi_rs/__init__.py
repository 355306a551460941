"""phi from Python: FLIP liquid simulation, GNS datasets and models, point-set distances.

The compiled part is ``phi_rs._phi_rs``; everything is re-exported here. ``phi_rs.torch`` (FLIP
as a PyTorch operation) is imported on first use and needs PyTorch.
"""

import importlib

from . import _phi_rs
from ._phi_rs import (
    BACKENDS,
    Dataset,
    DatasetError,
    Model,
    ModelError,
    PhiError,
    PointSetError,
    SceneError,
    Simulation,
    SimulationError,
    TrainingError,
    Windows,
    __version__,
    emd,
    evaluate,
    generate_dataset,
    merge_dataset,
    position_mse,
    simulate,
    sinkhorn,
)

__all__ = [
    "BACKENDS",
    "Dataset",
    "DatasetError",
    "Model",
    "ModelError",
    "PhiError",
    "PointSetError",
    "SceneError",
    "Simulation",
    "SimulationError",
    "TrainingError",
    "Windows",
    "emd",
    "evaluate",
    "generate_dataset",
    "merge_dataset",
    "position_mse",
    "simulate",
    "sinkhorn",
]

# A build without the Burn backend has no autodiff: no FlipGradient, no train.
if hasattr(_phi_rs, "FlipGradient"):
    FlipGradient = _phi_rs.FlipGradient
    train = _phi_rs.train
    __all__ += ["FlipGradient", "train"]


def __getattr__(name):
    # `phi_rs.torch` imports PyTorch, which takes seconds: only when asked for.
    if name == "torch":
        return importlib.import_module(".torch", __name__)
    raise AttributeError(f"module 'phi_rs' has no attribute '{name}'")
