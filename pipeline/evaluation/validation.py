"""The model's position error on measured points: as is and after registering the base.

A measured target point is compared with the signature's prediction: the S-Model
chain's forward kinematics (with its tool) at the recorded joint values, in the
sensor frame. "After registering the base" removes a rigid motion of the whole
measurement: the rotation and translation that best map the predicted points onto
the measured ones in the least-squares sense (centroids matched, rotation by SVD,
scipy's ``Rotation.align_vectors``; no scale). That is the error a user sees when
the data and the model disagree only in where the robot's base stands, e.g. a
second file measured from another tracker station.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from pipeline.kinematics.chain import SerialChain, forward_kinematics
from pipeline.units import joints_to_internal

#: A registration needs points spread in at least two directions: the second singular
#: value of the centred points above this fraction of the first (else the rotation
#: about their line is free and the fit would invent it).
MIN_SPREAD = 1e-6


@dataclass(frozen=True)
class PositionErrors:
    """Distances |measured - model| (cm) of ``n`` points, as is and base-registered."""

    n: int
    mean_cm: float
    rms_cm: float
    max_cm: float
    registered_mean_cm: float | None
    registered_rms_cm: float | None
    registered_max_cm: float | None

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def register_rigid(model: np.ndarray, measured: np.ndarray) -> np.ndarray | None:
    """The rigid transform (4, 4) best mapping ``model`` (m, 3) onto ``measured`` (m, 3),
    least squares; None when the points do not fix a rotation (fewer than 3, collinear)."""
    if len(model) < 3:
        return None
    cm, cp = model.mean(axis=0), measured.mean(axis=0)
    s = np.linalg.svd(model - cm, compute_uv=False)
    if not s[1] > MIN_SPREAD * max(s[0], 1e-300):
        return None
    from scipy.spatial.transform import Rotation  # lazy: ~0.3 s of import (warm runs)

    rot, _ = Rotation.align_vectors(measured - cp, model - cm)
    T = np.eye(4)
    T[:3, :3] = rot.as_matrix()
    T[:3, 3] = cp - T[:3, :3] @ cm
    return T


def error_distances(
    model: np.ndarray, measured: np.ndarray
) -> tuple[np.ndarray, np.ndarray | None]:
    """Per-point distances (m,), as is and after :func:`register_rigid` (None if it cannot)."""
    raw = np.linalg.norm(measured - model, axis=1)
    T = register_rigid(model, measured)
    if T is None:
        return raw, None
    moved = model @ T[:3, :3].T + T[:3, 3]
    return raw, np.linalg.norm(measured - moved, axis=1)


def position_errors(raw: np.ndarray, registered: np.ndarray | None) -> PositionErrors:
    """Mean, RMS and max of the distances of :func:`error_distances`."""

    def stats(d: np.ndarray) -> tuple[float, float, float]:
        return float(d.mean()), float(np.sqrt(np.mean(d**2))), float(d.max())

    reg = (None, None, None) if registered is None else stats(registered)
    return PositionErrors(len(raw), *stats(raw), *reg)


def model_points(chain: SerialChain, q: np.ndarray, prismatic: np.ndarray) -> np.ndarray:
    """The chain's tool point (m, 3) cm at joint values ``q`` (m, n) deg / cm."""
    return forward_kinematics(chain, joints_to_internal(q, prismatic))[:, :3, 3]
