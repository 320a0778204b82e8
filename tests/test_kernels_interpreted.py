"""The numba kernels made on first use and run as Python (pipeline.kinematics.kernels):
``ik --pose`` answers as the compiled kernels do, without loading numba."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from pipeline.control.controller import Controller
from pipeline.control.puma560_newton import _solve_packed
from pipeline.control.session import session_controller
from pipeline.kinematics.chain import forward_kinematics
from pipeline.kinematics.kernels import interpreted
from pipeline.kinematics.transforms import invert_transform
from pipeline.robots import puma560

ROOT = Path(__file__).resolve().parent.parent
FIELDS = ("q", "converged", "iterations", "position_error_cm", "orientation_error_rad", "status")


@pytest.fixture(scope="module")
def robot3(robot3_identified: Path) -> Controller:
    return session_controller(robot3_identified)


def _targets(c: Controller, n: int) -> np.ndarray:
    """Poses (n, 4, 4) in the design base frame: some beyond the joint limits, some next
    to the wrist singularity, some out of reach."""
    rng = np.random.default_rng(45)
    lim = np.deg2rad(c.robot.limits)
    q = rng.uniform(1.2 * lim[:, 0], 1.2 * lim[:, 1], (n, 6))
    q[: n // 10, 4] = rng.normal(0.0, 0.01, n // 10)
    T = invert_transform(c.sensor_from_base) @ forward_kinematics(c.signature.chain, q)
    T[n // 10 : n // 7, :3, 3] *= 1.6
    return T


def _one_by_one(c: Controller, T: np.ndarray) -> list:
    return [c.solve(T[k], branch=puma560.BRANCHES[k % 8]) for k in range(len(T))]


@pytest.mark.parametrize("terms", [False, True], ids=["rigid", "nongeometric"])
def test_interpreted_kernels_answer_as_compiled(robot3: Controller, terms: bool) -> None:
    """Every branch, one target a call (the ``ik --pose`` path): the converged answers
    bit for bit; the others (out of limits, unreachable: Levenberg-Marquardt's long
    searches) to round-off."""
    c = robot3
    if terms:
        from pipeline.rig.true_robot import draw_nongeometric

        ng = draw_nongeometric(c.robot, 0.3, 0.01, seed=27)
        c = Controller.from_signature(replace(c.signature, nongeometric=ng))
    T = _targets(c, 400)
    compiled = _one_by_one(c, T)
    python = interpreted(_one_by_one, c, T)
    assert sum(bool(r.converged[0]) for r in compiled) >= 150
    for a, b in zip(compiled, python, strict=True):
        assert a.status[0] == b.status[0]
        assert a.branch_changed is not None and b.branch_changed is not None
        assert a.branch_changed[0] == b.branch_changed[0]
        if a.converged[0]:
            for name in FIELDS:
                np.testing.assert_array_equal(getattr(a, name), getattr(b, name), name)
        else:
            np.testing.assert_allclose(a.q, b.q, rtol=0, atol=1e-12)
    assert _solve_packed.run is _solve_packed.dispatcher  # compiled again after


def test_an_arithmetic_error_in_python_runs_compiled() -> None:
    """Where Python refuses what the machine code computes through (here a division by
    zero), the call runs again with the kernels compiled."""
    calls = []

    def solve() -> str:
        calls.append(_solve_packed.run is _solve_packed.dispatcher)
        if not calls[-1]:
            raise ZeroDivisionError("float division by zero")
        return "compiled"

    assert interpreted(solve) == "compiled"
    assert calls == [False, True]


_IK_POSE = """
import sys
from pipeline.console import main
sys.argv = ["pipeline", "ik", sys.argv[1], "--pose", "40", "20", "60", "180", "0", "90", "--json"]
try:
    main()
finally:
    print(sorted(m for m in ("numba", "scipy", "llvmlite") if m in sys.modules))
"""


def test_ik_pose_loads_no_numba(robot3: Controller, robot3_identified: Path) -> None:
    """The README's ``ik --pose`` (Newton-Raphson) imports neither numba nor scipy and
    prints the compiled answer at full precision."""

    def run() -> tuple[dict, str]:
        argv = [sys.executable, "-c", _IK_POSE, str(robot3_identified)]
        env = dict(os.environ, PYTHONPATH=str(ROOT))
        out = subprocess.run(argv, capture_output=True, text=True, env=env, cwd=ROOT, timeout=300)
        assert out.returncode == 0, out.stderr
        *answer, loaded = out.stdout.strip().splitlines()
        return json.loads("\n".join(answer)), loaded

    answer, loaded = run()
    assert loaded == "[]"
    from pipeline.control.poses import solve_pose

    assert answer["q"] == list(solve_pose(robot3_identified, [40, 20, 60, 180, 0, 90]).q)
