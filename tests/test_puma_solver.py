"""The compiled Puma design start (pipeline.control.puma560_start) against the numpy
design inverse it stands in for: every branch, clamped poses, the wrist singularity."""

import numpy as np
import pytest

from pipeline.control import puma560_start as S
from pipeline.control.puma560_inverse import puma_design_inverse
from pipeline.kinematics.chain import forward_kinematics
from pipeline.kinematics.transforms import invert_transform, transform_from_xyz_rpy
from pipeline.robots import puma560 as P
from tests.test_ik import LIM


@pytest.mark.parametrize("branch", P.BRANCHES, ids=lambda b: b.label)
def test_compiled_design_start_matches_numpy(rng, branch) -> None:
    base = transform_from_xyz_rpy(np.array([10.0, -5.0, 3.0]), np.array([0.1, -0.2, 0.3]))
    tool = transform_from_xyz_rpy(np.array([1.0, 2.0, 8.0]), np.array([0.05, 0.0, -0.1]))
    design = P.simulator_chain()
    q = rng.uniform(LIM[:, 0], LIM[:, 1], (300, 6))
    q[:20, 4] = 0.0  # exactly at the wrist singularity
    q[20:40, 2] = -np.arctan2(P.DESIGN_A_CM[2], P.DESIGN_D_CM[3]) + 1e-3  # elbow stretched
    T = base @ forward_kinematics(design, q) @ tool
    T[40:60, :3, 3] *= 1.5  # out of reach: clamped onto the workspace
    near = rng.uniform(-8.0, 8.0, (300, 6))  # 2π classes and θ4 at the singularity
    ref = puma_design_inverse(branch, tool=tool, base=base)(T, near)
    margins = np.array([np.deg2rad(1.0), 1.0])
    flags = np.array([branch.shoulder, branch.elbow, branch.wrist], float)
    pre, post = invert_transform(base), invert_transform(tool)
    q0, Tw = np.empty(6), np.empty((4, 4))
    for k in range(len(T)):
        assert S._design_start(pre, post, flags, margins, T[k], near[k], q0, Tw)
        # The same closed form, another order of operations: round-off apart
        # (amplified near the stretched elbow, ~1e-12 rad).
        np.testing.assert_allclose(q0, ref[k], rtol=0, atol=1e-9)
