"""The design alignment: base ``X`` and tool ``Y`` that carry the design model onto a
signature chain (Section 5.3: design and signature models share one physical base frame).

Uses only the two models (random configurations within the joint limits, fixed seed): no
ground truth. Written into every signature file; the verdict, the convergence tables and
the fleet report compare chains with it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from pipeline.kinematics.alignment import fit_alignment
from pipeline.kinematics.chain import forward_kinematics
from pipeline.kinematics.transforms import pose_error

if TYPE_CHECKING:
    from pipeline.kinematics.chain import SerialChain
    from pipeline.robots.description import RobotDescription

#: Random configurations the alignment is fitted over.
ALIGNMENT_SAMPLES = 500
#: The world frames a signature's poses and exports are given in: the sensor's (where the
#: points were measured), or the design base placed there by the design alignment ``X``.
FRAMES = ("sensor", "design-base")


def design_alignment(
    signature_chain: SerialChain, robot: RobotDescription, samples: int = ALIGNMENT_SAMPLES
) -> tuple[np.ndarray, np.ndarray, float]:
    """Base ``X`` and tool ``Y`` with ``F_s(q) ≈ X · F_d(q) · Y``, and the RMS misfit (cm).

    Uses only the signature and the design model (random configurations within
    the joint limits, fixed seed): no ground truth.
    """
    return chain_alignment(signature_chain, robot.design_chain(), robot, samples)


def chain_alignment(
    chain_a: SerialChain,
    chain_b: SerialChain,
    robot: RobotDescription,
    samples: int = ALIGNMENT_SAMPLES,
) -> tuple[np.ndarray, np.ndarray, float]:
    """Base ``X`` and tool ``Y`` with ``F_a(q) ≈ X · F_b(q) · Y`` over random configurations
    of ``robot`` (fixed seed), and the RMS position misfit (cm) that remains."""
    q = robot.random_configurations(samples, 0)  # fixed: the same signature, the same file
    T_a = forward_kinematics(chain_a, q)
    T_b = forward_kinematics(chain_b, q)
    X, Y = fit_alignment(T_a, T_b)
    dp, _ = pose_error(T_a, X @ T_b @ Y)
    return X, Y, float(np.sqrt(np.mean(dp**2)))
