"""Stage ``flange_poses`` of a session without joint readings (issue 40): the flange's pose
at each image as recorded on ``/robot/flange_pose`` (``schemas/arrow/flange_poses.json``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.errors import StageError
from pipeline.schemas import arrow_table
from pipeline.stages.base import RECORDING, NoParams, Stage
from pipeline.sweeps import POSES_SWEEP


def compute(inputs: Mapping[str, Any], params: NoParams) -> pa.Table:
    from scipy.spatial.transform import Rotation

    rec = inputs[RECORDING]
    T = rec.flange_in_base_cm
    if not len(T):
        raise StageError(
            f"{rec.path}: no /robot/flange_pose",
            expected="a recording of flange poses (an image set without joint readings)",
            fix="run `pipeline identify`; it picks the stages of the recording",
        )
    xyzw = Rotation.from_matrix(T[:, :3, :3]).as_quat()
    xyzw *= np.where(xyzw[:, 3:] < 0, -1.0, 1.0)  # w ≥ 0: one quaternion per rotation
    columns = {
        "sweep": rec.flange_sweep, "image": rec.flange_step,
        "x_cm": T[:, 0, 3], "y_cm": T[:, 1, 3], "z_cm": T[:, 2, 3],
        "qw": xyzw[:, 3], "qx": xyzw[:, 0], "qy": xyzw[:, 1], "qz": xyzw[:, 2],
    }  # fmt: skip
    return arrow_table("flange_poses", columns)


STAGE = Stage(
    "flange_poses",
    1,
    (RECORDING,),
    NoParams(),
    compute,
    "the flange's pose at each image, as the robot reported it (camera, no joints)",
)


def flange_matrices(table: pa.Table, images: np.ndarray) -> np.ndarray:
    """The flange in the base (m, 4, 4, cm) at ``images`` (steps) of a ``flange_poses``
    table."""
    from scipy.spatial.transform import Rotation

    use = table.column("sweep").to_numpy() == POSES_SWEEP  # the fit's images
    at = np.searchsorted(table.column("image").to_numpy()[use], images)  # sorted, unique
    c = {n: table.column(n).to_numpy()[use][at]
         for n in ("x_cm", "y_cm", "z_cm", "qw", "qx", "qy", "qz")}  # fmt: skip
    T = np.tile(np.eye(4), (len(at), 1, 1))
    T[:, :3, :3] = Rotation.from_quat(np.stack([c["qx"], c["qy"], c["qz"], c["qw"]], 1)).as_matrix()
    T[:, :3, 3] = np.stack([c["x_cm"], c["y_cm"], c["z_cm"]], 1)
    return T
