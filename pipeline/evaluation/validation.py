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

from pipeline.kinematics.alignment import register_rigid
from pipeline.kinematics.chain import SerialChain, forward_kinematics
from pipeline.kinematics.nongeometric import NonGeometric
from pipeline.units import joints_to_internal


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


def model_points(
    chain: SerialChain,
    q: np.ndarray,
    prismatic: np.ndarray,
    nongeometric: NonGeometric | None = None,
    payload_kg: np.ndarray | None = None,
) -> np.ndarray:
    """The chain's tool point (m, 3) cm at joint values ``q`` (m, n) deg / cm, the joints
    where the ``nongeometric`` terms put them when the signature has them, under each
    row's ``payload_kg`` (m,) where recorded (NaN or None: the signature's own payload)."""
    qi = joints_sitting(q, prismatic, nongeometric, payload_kg)
    return forward_kinematics(chain, qi)[:, :3, 3]


def joints_sitting(
    q: np.ndarray,
    prismatic: np.ndarray,
    nongeometric: NonGeometric | None = None,
    payload_kg: np.ndarray | None = None,
) -> np.ndarray:
    """The joint values (m, n) rad / cm where the ``nongeometric`` terms put readings ``q``
    (m, n) deg / cm, under each row's ``payload_kg`` (m,) where recorded (NaN or None: the
    signature's own payload); the readings themselves without terms."""
    qi = joints_to_internal(q, prismatic)
    if nongeometric is None:
        return qi
    kg = None
    if payload_kg is not None:
        kg = np.where(np.isfinite(payload_kg), payload_kg, nongeometric.payload_kg)
    return nongeometric.effective(qi, kg)
