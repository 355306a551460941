"""Fixtures of the phi_rs tests: the `phi` command line (built once if missing), a tiny
dataset that `phi dataset generate` wrote and a small model that `phi model init` made."""

import os
import pathlib
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]


def _phi_binary() -> pathlib.Path:
    """`PHI_BIN`, else `target/release/phi` (CARGO_TARGET_DIR respected), built if missing."""
    if "PHI_BIN" in os.environ:
        return pathlib.Path(os.environ["PHI_BIN"])
    target = pathlib.Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target"))
    binary = target / "release" / "phi"
    if not binary.exists():
        subprocess.run(
            ["cargo", "build", "--release", "--bin", "phi"], cwd=ROOT, check=True
        )
    return binary


@pytest.fixture(scope="session")
def phi():
    """Runs `phi ARGS...` quietly and fails the test on a non-zero exit."""
    binary = _phi_binary()

    def run(*args):
        result = subprocess.run(
            [str(binary), "--quiet", *map(str, args)],
            cwd=ROOT,
            capture_output=True,
            text=True,
        )
        assert result.returncode == 0, f"phi {' '.join(map(str, args))}:\n{result.stderr}"
        return result

    return run


@pytest.fixture(scope="session")
def dataset_dir(phi, tmp_path_factory):
    """Two training trajectories of 12 steps each."""
    out = tmp_path_factory.mktemp("data") / "ds"
    phi("dataset", "generate", "--out", out, "--split", "train",
        "--trajectories", 2, "--steps", 12, "--threads", 1)
    return out


@pytest.fixture(scope="session")
def model_dir(phi, dataset_dir, tmp_path_factory):
    """A small freshly initialised model of the dataset."""
    out = tmp_path_factory.mktemp("model") / "m"
    phi("model", "init", "--data", dataset_dir, "--out", out, "--latent", 16,
        "--hidden", 16, "--hidden-layers", 1, "--message-passing-steps", 2,
        "--input-velocities", 2, "--seed", 3)
    return out
