"""Reads phi's exports the way the target tools read them, and prints what they see.

    python scripts/check_exports.py gns DIR            # phi dataset export --format gns
    python scripts/check_exports.py lagrangebench DIR  # phi dataset export --format lagrangebench
    python scripts/check_exports.py vtk FILE.pvd       # phi simulate/rollout --vtk-every N

Needs numpy; `lagrangebench` also h5py, `vtk` also meshio. Prints one JSON line per split (or
one per series) and exits non-zero, with the reason, when the files are not what the tool
expects. The reading code follows each tool's public source:

- gns: `gns/data_loader.py` (`load_npz_data`, `SamplesDataset`, `TrajectoriesDataset`) and
  `gns/reading_utils.py` (`read_metadata`), geoelements/gns; the torch parts are left out (they
  only wrap the numpy arrays).
- LagrangeBench: `lagrangebench/data/data.py` (`H5Dataset.__init__`, `get_window`,
  `get_trajectory`) and the metadata keys read by `case_setup/case.py`, `runner.py` and
  `evaluate/metrics.py`, tumaer/lagrangebench.
- VTK: the `.pvd` is parsed as ParaView's collection reader does (`DataSet` elements with
  `timestep` and `file`), each `.vtu` is read with meshio.
"""

import json
import os
import sys

import numpy as np

GNS_KINEMATIC_PARTICLE_ID = 3
GNS_INPUT_SEQUENCE_LENGTH = 6
GNS_METADATA_KEYS = [
    "bounds", "sequence_length", "default_connectivity_radius", "dim", "dt",
    "vel_mean", "vel_std", "acc_mean", "acc_std",
]
LB_FLUID, LB_SOLID_WALL = 0, 1
LB_METADATA_KEYS = [
    "bounds", "dim", "dt", "write_every", "dx", "default_connectivity_radius",
    "periodic_boundary_conditions", "num_particles_max",
    "vel_mean", "vel_std", "acc_mean", "acc_std",
]


def fail(message):
    sys.exit(f"check_exports: {message}")


# --------------------------------------------------------------------------------------------
# geoelements/gns


def gns_load_npz_data(path):
    # As gns.data_loader.load_npz_data.
    with np.load(path, allow_pickle=True) as data_file:
        if "gns_data" in data_file:
            data = data_file["gns_data"]
        else:
            data = [item for _, item in data_file.items()]
    return data


def gns_read_metadata(data_path, purpose):
    # As gns.reading_utils.read_metadata.
    try:
        with open(os.path.join(data_path, "metadata.json"), "rt") as fp:
            metadata = json.loads(fp.read())[purpose]
    except Exception:
        with open(os.path.join(data_path, "metadata.json"), "rt") as fp:
            metadata = json.loads(fp.read())
    return metadata


def check_gns(directory):
    metadata = gns_read_metadata(directory, "train")
    missing = [k for k in GNS_METADATA_KEYS if k not in metadata]
    if missing:
        fail(f"{directory}/metadata.json lacks {missing}")
    dim = metadata["dim"]
    for key in ["vel_mean", "vel_std", "acc_mean", "acc_std", "bounds"]:
        if len(metadata[key]) != dim:
            fail(f"metadata key {key} has {len(metadata[key])} entries for dim {dim}")
    # train.py: nnode_in = 37 if dim == 3 else 30; nedge_in = dim + 1 (when not in metadata).
    splits = sorted(f[:-4] for f in os.listdir(directory) if f.endswith(".npz"))
    if not splits:
        fail(f"{directory}: no {{split}}.npz")
    for split in splits:
        path = os.path.join(directory, f"{split}.npz")
        data = gns_load_npz_data(path)
        # SamplesDataset.__init__
        dimension = data[0][0].shape[-1]
        material_property_as_feature = len(data[0]) >= 3
        if material_property_as_feature:
            fail(f"{path}: items have {len(data[0])} parts, expected (positions, particle_type)")
        data_lengths = [x.shape[0] - GNS_INPUT_SEQUENCE_LENGTH for x, _, in data]
        samples = sum(data_lengths)
        if dimension != dim:
            fail(f"{path}: positions have {dimension} components, metadata dim {dim}")
        # SamplesDataset.__getitem__ of the last sample of the first trajectory, and
        # TrajectoriesDataset.__getitem__ of every trajectory.
        positions = data[0][0][data_lengths[0] - 1 : data_lengths[0] - 1 + GNS_INPUT_SEQUENCE_LENGTH]
        positions = np.transpose(positions, (1, 0, 2))
        particle_type = np.full(positions.shape[0], data[0][1], dtype=int)
        label = data[0][0][data_lengths[0] - 1 + GNS_INPUT_SEQUENCE_LENGTH]
        if label.shape != (positions.shape[0], dim):
            fail(f"{path}: label shape {label.shape}")
        trajectories = []
        for x, types in data:
            n = x.shape[1]
            t = np.full(n, types, dtype=int)
            if x.dtype != np.float32 or x.ndim != 3 or t.shape != (n,):
                fail(f"{path}: positions {x.dtype} {x.shape}, particle_type {t.shape}")
            kinematic = t == GNS_KINEMATIC_PARTICLE_ID
            if not np.array_equal(x[:, kinematic], np.broadcast_to(x[:1, kinematic], x[:, kinematic].shape)):
                fail(f"{path}: a kinematic particle (type 3) moves")
            if metadata["sequence_length"] - GNS_INPUT_SEQUENCE_LENGTH > x.shape[0] - GNS_INPUT_SEQUENCE_LENGTH:
                fail(f"{path}: sequence_length {metadata['sequence_length']} > {x.shape[0]} frames")
            trajectories.append({
                "frames": int(x.shape[0]),
                "particles": int(n),
                "kinematic": int(kinematic.sum()),
                "position_sum": float(x.astype(np.float64).sum()),
                "types": sorted(int(v) for v in set(t.tolist())),
            })
        print(json.dumps({
            "format": "gns", "split": split, "trajectories": len(data), "samples": int(samples),
            "dim": int(dimension), "sample_particle_type": particle_type.tolist()[:1],
            "items": trajectories,
        }))


# --------------------------------------------------------------------------------------------
# LagrangeBench


def check_lagrangebench(directory):
    import h5py

    with open(os.path.join(directory, "metadata.json"), "r") as f:
        metadata = json.loads(f.read())
    missing = [k for k in LB_METADATA_KEYS if k not in metadata]
    if missing:
        fail(f"{directory}/metadata.json lacks {missing}")
    dim = metadata["dim"]
    if len(metadata["periodic_boundary_conditions"]) != dim or len(metadata["bounds"]) != dim:
        fail("periodic_boundary_conditions or bounds do not have dim entries")
    splits = [s for s in ["train", "valid", "test"] if os.path.exists(os.path.join(directory, f"{s}.h5"))]
    if not splits:
        fail(f"{directory}: no {{split}}.h5")
    for split in splits:
        file_path = os.path.join(directory, split + ".h5")
        # H5Dataset.__init__
        with h5py.File(file_path, "r") as f:
            traj_keys = list(f.keys())
            sequence_length = f["00000/position"].shape[0]
        input_seq_length = 6
        if split == "train":
            subseq_length = input_seq_length + 1
            samples_per_traj = sequence_length - subseq_length + 1
            num_samples = samples_per_traj * len(traj_keys)
        else:
            subseq_length = input_seq_length + 1
            num_samples = (sequence_length // subseq_length) * len(traj_keys)
        items = []
        with h5py.File(file_path, "r") as db:
            for key in traj_keys:
                # get_window / get_trajectory
                traj = db[key]
                pos = traj["position"]
                window = pos[0:subseq_length].transpose((1, 0, 2))
                particle_type = traj["particle_type"][:]
                if window.shape[0] != particle_type.shape[0] or window.shape[2] != dim:
                    fail(f"{file_path} {key}: position {pos.shape}, particle_type {particle_type.shape}")
                if particle_type.shape[0] > metadata["num_particles_max"]:
                    fail(f"{file_path} {key}: more particles than num_particles_max")
                if not set(np.unique(particle_type).tolist()) <= {LB_FLUID, LB_SOLID_WALL}:
                    fail(f"{file_path} {key}: types {np.unique(particle_type)}")
                full = pos[:]
                walls = particle_type == LB_SOLID_WALL
                if not np.array_equal(full[:, walls], np.broadcast_to(full[:1, walls], full[:, walls].shape)):
                    fail(f"{file_path} {key}: a SOLID_WALL particle moves")
                items.append({
                    "key": key,
                    "frames": int(full.shape[0]),
                    "particles": int(full.shape[1]),
                    "walls": int(walls.sum()),
                    "position_sum": float(full.astype(np.float64).sum()),
                    "dtype": str(full.dtype),
                })
        print(json.dumps({
            "format": "lagrangebench", "split": split, "trajectories": len(traj_keys),
            "samples": int(num_samples), "items": items,
        }))


# --------------------------------------------------------------------------------------------
# VTK


def check_vtk(pvd):
    import xml.etree.ElementTree as ET

    import meshio

    root = ET.parse(pvd).getroot()
    if root.get("type") != "Collection":
        fail(f"{pvd}: VTKFile type {root.get('type')}, expected Collection")
    base = os.path.dirname(os.path.abspath(pvd))
    frames = []
    for dataset in root.iter("DataSet"):
        mesh = meshio.read(os.path.join(base, dataset.get("file")))
        n = mesh.points.shape[0]
        velocity = mesh.point_data["velocity"]
        speed = mesh.point_data["speed"]
        types = mesh.point_data["particle_type"]
        if velocity.shape != (n, 3) or speed.shape != (n,) or types.shape != (n,):
            fail(f"{dataset.get('file')}: point data shapes {velocity.shape} {speed.shape} {types.shape}")
        if not np.allclose(np.linalg.norm(velocity, axis=1), speed, rtol=1e-5, atol=1e-6):
            fail(f"{dataset.get('file')}: speed is not |velocity|")
        vertices = sum(len(block.data) for block in mesh.cells if block.type == "vertex")
        frames.append({
            "time": float(dataset.get("timestep")),
            "points": int(n),
            "vertices": int(vertices),
            "position_sum": float(mesh.points.astype(np.float64).sum()),
            "velocity_sum": float(velocity.astype(np.float64).sum()),
            "types": sorted(int(v) for v in set(types.tolist())),
        })
    print(json.dumps({"format": "vtk", "frames": frames}))


if __name__ == "__main__":
    if len(sys.argv) != 3 or sys.argv[1] not in ("gns", "lagrangebench", "vtk"):
        sys.exit(__doc__)
    {"gns": check_gns, "lagrangebench": check_lagrangebench, "vtk": check_vtk}[sys.argv[1]](sys.argv[2])
