"""Signature model from frames (4.49)-(4.51) and its pseudo D-H form (4.59)-(4.73)."""

import numpy as np

from pipeline.kinematics.chain import SerialChain, forward_kinematics, link_frames
from pipeline.kinematics.signature import (
    chain_from_pseudo_dh,
    frame_from_features,
    pseudo_dh_from_chain,
    signature_chain,
)
from pipeline.kinematics.transforms import pose_error
from pipeline.robots import puma560
from tests.conftest import random_rigid


def _true_frames(chain: SerialChain, qs: np.ndarray) -> np.ndarray:
    """Exact S̄_0..S̄_n of a chain: joint i+1's axis frames at q^s (S̄_n = S̄_{n-1})."""
    F = link_frames(chain, qs)[: chain.n_joints]
    return np.concatenate([F, F[-1:]], axis=0)


def test_signature_from_exact_frames_reproduces_robot(rng) -> None:
    eps = rng.normal(0, 0.05, 39)
    true = puma560.simulator_chain(eps)
    qs = rng.uniform(-1, 1, 6)
    frames = _true_frames(true, qs)
    # Re-express each frame with an arbitrary X axis (4.50 only fixes it up to the first point).
    for i in range(7):
        ang = rng.uniform(-np.pi, np.pi)
        c, s = np.cos(ang), np.sin(ang)
        frames[i, :3, :2] = frames[i, :3, :2] @ np.array([[c, -s], [s, c]])
    tool = np.linalg.inv(frames[-1]) @ link_frames(true, qs)[-1]  # flange in S_n
    sig = signature_chain(frames, qs, np.zeros(6, bool), tool)
    q = rng.uniform(-np.pi, np.pi, (500, 6))
    dp, dth = pose_error(forward_kinematics(true, q), forward_kinematics(sig, q))
    assert dp.max() < 1e-10 and dth.max() < 1e-12


def test_frame_from_features() -> None:
    S = frame_from_features([0, 0, 2.0], [1.0, 2.0, 3.0], [5.0, 2.0, 9.0])
    np.testing.assert_allclose(S[:3, :3], np.eye(3), atol=1e-15)
    np.testing.assert_allclose(S[:3, 3], [1, 2, 3])


def test_pseudo_dh_reproduces_signature(rng) -> None:
    for prismatic in ([False] * 6, [False, False, True, False, False, False]):
        chain = SerialChain(
            links=random_rigid(rng, 6, 30.0),
            prismatic=np.array(prismatic),
            base=random_rigid(rng, 1)[0],
            tool=random_rigid(rng, 1, 10.0)[0],
            joint_offsets=rng.normal(0, 1, 6),
        )
        p = pseudo_dh_from_chain(chain)
        q = rng.normal(0, 1, (300, 6))
        dp, dth = pose_error(
            forward_kinematics(chain, q), forward_kinematics(chain_from_pseudo_dh(p, prismatic), q)
        )
        assert dp.max() < 1e-9 and dth.max() < 1e-12
