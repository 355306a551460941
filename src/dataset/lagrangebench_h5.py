"""Turns the arrays of one split, written by `phi dataset export --format lagrangebench` as an
.npz archive with entries "{group}/position" and "{group}/particle_type", into LagrangeBench's
{split}.h5: one HDF5 group per trajectory ("00000", ...) holding the datasets `position`
(float32 [T, N, D], gzip) and `particle_type` (int64 [N]), as LagrangeBench's own converters
write them.

Usage: python lagrangebench_h5.py ARRAYS.npz OUT.h5   (needs numpy and h5py)

OUT.h5 is written to a temporary file next to it and renamed when complete.
"""

import os
import sys

import h5py
import numpy as np


def main(arrays_path, out_path):
    tmp_path = os.path.join(
        os.path.dirname(os.path.abspath(out_path)),
        f".{os.path.basename(out_path)}.tmp-{os.getpid()}",
    )
    try:
        with np.load(arrays_path) as arrays, h5py.File(tmp_path, "w") as h5:
            groups = sorted({name.split("/")[0] for name in arrays.files})
            for group in groups:
                position = arrays[f"{group}/position"]
                particle_type = arrays[f"{group}/particle_type"]
                h5.create_dataset(f"{group}/particle_type", data=particle_type)
                h5.create_dataset(
                    f"{group}/position",
                    data=position,
                    dtype=np.float32,
                    compression="gzip",
                )
        os.replace(tmp_path, out_path)
    except BaseException:
        if os.path.exists(tmp_path):
            os.remove(tmp_path)
        raise
    print(len(groups))


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit("usage: lagrangebench_h5.py ARRAYS.npz OUT.h5")
    main(sys.argv[1], sys.argv[2])
