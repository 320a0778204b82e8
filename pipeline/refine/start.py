"""The start of a pose-set fit: the design model, its base registered to the measurements.

A session that identifies the chain from a pose set (whole-arm configurations, no joint
sweep of every joint) has no circle features to start from. Its start is the design
model placed in the sensor frame:

1. the design's tool point ``t`` (``plan.tool_local_cm``, in the last D-H frame) at every
   measured pose, ``p_k = F_n(q_k) · t`` (design base frame);
2. the base ``B`` that best maps those points onto the measured ones, in closed form
   (:func:`pipeline.kinematics.alignment.register_rigid`: centroids, then the rotation
   by SVD);
3. the tool point given ``B``: ``t = mean_k R_k⁻¹ (B⁻¹ m_k − o_k)`` with ``F_n = (R_k, o_k)``
   (the least-squares point, ``R_k`` orthonormal); 2 and 3 alternate until ``B`` stops
   moving (:data:`START_ROUNDS`), since a design tool point off by a few cm would
   otherwise bias the base.

The refinement (:mod:`pipeline.refine.solve`) then fits every joint axis, the base (as
joint 1's axis line) and the tool point from there. The frames are the design's D-H
frames at ``q̄^s`` moved by ``B``: frame ``i − 1``'s Z is joint ``i``'s axis, so they are
S-Model frames ``S̄_0 … S̄_{n−1}`` (Section 4.3.3) of the design model, ``S̄_n = S̄_{n−1}``,
and the tool the translation to the tool point (thesis convention, gauge 4 of
:mod:`pipeline.refine.kinematics`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.errors import StageError
from pipeline.kinematics.alignment import register_rigid
from pipeline.kinematics.chain import SerialChain, frames_at, link_frames
from pipeline.kinematics.transforms import invert_transform
from pipeline.optim.block import Array

#: Rounds of base registration and tool point at most; each is two closed forms. The
#: alternation stops earlier when the base moves by less than 1e-12 cm (round-off).
START_ROUNDS = 50
_STOP_CM = 1e-12


@dataclass(frozen=True)
class DesignStart:
    """The design model in the sensor frame at ``q̄^s``.

    Attributes
    ----------
    frames : ndarray, shape (n + 1, 4, 4)
        ``S̄_0 … S̄_n`` (``S̄_n = S̄_{n−1}``), sensor frame, cm.
    tool : ndarray, shape (4, 4)
        The tool point in ``S̄_n`` (translation only).
    base : ndarray, shape (4, 4)
        Sensor from the design's world frame (the registration).
    rms_cm : float
        RMS distance of the measured points from the registered design model.
    errors_cm : ndarray, shape (K,)
        Each measured point's distance from it.
    """

    frames: Array
    tool: Array
    base: Array
    rms_cm: float
    errors_cm: Array


def design_start(
    chain: SerialChain,
    q: Array,
    measured: Array,
    tool_local: Array,
    q_signature: Array,
) -> DesignStart:
    """The registered design start (module docstring).

    Parameters
    ----------
    chain : SerialChain
        The design model (its own world frame); its tool is not used.
    q : ndarray, shape (K, n)
        Joint values of the measured tool points (rad / cm).
    measured : ndarray, shape (K, 3)
        Measured tool points, sensor frame (cm).
    tool_local : ndarray, shape (3,)
        The design's tool point in the last D-H frame (cm).
    q_signature : ndarray, shape (n,)
        ``q̄^s``, where the frames are taken (rad / cm).
    """
    n = chain.n_joints
    flange = frames_at(chain, q, n)  # (K, 4, 4): F_n(q_k)
    t = np.asarray(tool_local, float).copy()
    B = np.eye(4)
    for _ in range(START_ROUNDS):
        p = (flange[:, :3, :3] @ t) + flange[:, :3, 3]
        B_new = register_rigid(p, measured)
        if B_new is None:
            raise StageError(
                f"refine: the {len(measured)} measured tool points of the pose set do not fix "
                "the robot's base",
                expected="at least 3 poses whose tool points are not on one line",
                fix="measure more poses, spread over the workspace",
            )
        moved = float(np.max(np.abs(B_new - B)[:3])) * (1.0 + float(np.abs(p).max()))
        B = B_new
        local = invert_transform(B) @ np.c_[measured, np.ones(len(measured))][..., None]
        back = (
            np.swapaxes(flange[:, :3, :3], 1, 2) @ (local[:, :3, 0] - flange[:, :3, 3])[..., None]
        )
        t = back[..., 0].mean(axis=0)
        if moved < _STOP_CM:
            break
    p = (flange[:, :3, :3] @ t) + flange[:, :3, 3]
    errors = np.linalg.norm(p @ B[:3, :3].T + B[:3, 3] - measured, axis=1)
    rms = float(np.sqrt(np.mean(errors**2)))
    F = B @ link_frames(chain, np.asarray(q_signature, float))  # (n + 2, 4, 4)
    frames = np.concatenate([F[:n], F[n - 1 : n]], axis=0)
    tool = np.eye(4)
    tool[:3, 3] = invert_transform(frames[n])[:3] @ np.r_[F[n, :3, :3] @ t + F[n, :3, 3], 1.0]
    return DesignStart(frames=frames, tool=tool, base=B, rms_cm=rms, errors_cm=errors)
