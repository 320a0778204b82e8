"""Compile armsig's cached numba kernels before the test workers start (tests/conftest.py,
with ``ARMSIG_KERNEL_WARMUP=1``; off by default, see its ``pytest_configure``).

On a fresh checkout the kernels' cache folder (:mod:`pipeline.kinematics.kernel_cache`)
is empty, and compiling them costs about 2 CPU minutes. Left to the pytest-xdist
workers, each worker compiles every kernel its tests call: the same minutes twice,
and the slowest tests of the suite wait on it. Here the compile runs once, split in
:data:`GROUPS` that run side by side in their own interpreters (one per core), through
the same public calls the library makes, so the workers load every kernel from the
cache. Nothing here asserts anything: a kernel missed here is compiled by the first
worker that calls it, as without this module.

``python tests/kernel_warmup.py GROUP`` compiles one group; :func:`warm` runs groups
in parallel subprocesses and returns the seconds it took.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _puma_controller():
    """A Controller of the Puma's design model, as if identified without error."""
    import numpy as np

    from pipeline.control.controller import Controller
    from pipeline.kinematics.chain import SerialChain
    from pipeline.rig.plan import default_sensor_from_base
    from pipeline.robots import get_robot
    from pipeline.signature.file import Signature

    robot = get_robot("puma560")
    d = robot.design_chain()
    X, Y = default_sensor_from_base(robot), np.eye(4)
    chain = SerialChain(d.links, d.prismatic, X @ d.base, d.tool @ Y, d.joint_offsets)
    return Controller(Signature(robot, chain, X, Y), robot, X, Y), d


def _targets(chain, robot_limits_deg, n: int, seed: int = 1):
    import numpy as np

    from pipeline.kinematics.chain import forward_kinematics

    lim = np.deg2rad(robot_limits_deg)
    q = np.random.default_rng(seed).uniform(lim[:, 0], lim[:, 1], (n, lim.shape[0]))
    return q, forward_kinematics(chain, q)


def _solve_all_ways(method: str) -> None:
    """Controller.solve by ``method``: one target and a batch, with and without
    ``q_near`` (a full (m, 6) start reaches the kernel as a read-only array), on one
    thread and on several."""
    from pipeline.kinematics import ik_compiled
    from pipeline.robots import puma560

    ctrl, d = _puma_controller()
    q, T = _targets(d, ctrl.robot.limits, 8)
    branch = puma560.BRANCHES[0]
    for threaded_from in (2000, 2):
        ik_compiled.THREADED_MIN_TARGETS = threaded_from
        for near in (None, q):
            ctrl.solve(T, branch=branch, method=method, q_near=near)
            ctrl.solve(T[0], branch=branch, method=method, q_near=None if near is None else q[0])
    ik_compiled.THREADED_MIN_TARGETS = 2000


def puma_newton() -> None:
    """Controller.solve by Newton-Raphson, the real-time solver, and the inline kernels
    that tests call on their own."""
    import numpy as np

    from pipeline.control import puma560_solver as S
    from pipeline.robots import puma560

    _solve_all_ways("nr")
    ctrl, d = _puma_controller()
    q, T = _targets(d, ctrl.robot.limits, 8)
    solver = ctrl.realtime(puma560.BRANCHES[0])
    solver.solve_one(T[0])
    solver.solve_one(T[1], q_near=solver.q)
    S._shift(q, solver._limits)
    flags, margins = np.array([1.0, 1.0, 1.0]), np.array([np.deg2rad(1.0), 1.0])
    q0, Tw = np.empty(6), np.empty((4, 4))
    S._design_start(np.eye(4), np.eye(4), flags, margins, T[0], q[0], q0, Tw)
    S._wrap(7.0)  # tests/test_kernel_cache.py calls it on its own


def puma_jacobi() -> None:
    """Controller.solve by the Jacobi iteration."""
    _solve_all_ways("jacobi")


def plain_newton() -> None:
    """ik.newton_raphson's compiled path on a revolute and a prismatic arm."""
    import numpy as np

    from pipeline.kinematics import ik, ik_compiled
    from pipeline.robots import get_robot

    for name in ("puma560", "stanford", "scara"):
        robot = get_robot(name)
        d = robot.design_chain()
        q, T = _targets(d, robot.limits, 8)
        res = np.full(robot.n_joints, 1e-4)
        ik.newton_raphson(d, T, q + 0.01, res)
        ik_compiled.THREADED_MIN_TARGETS = 2
        ik.newton_raphson(d, T, q + 0.01, res)
        ik_compiled.THREADED_MIN_TARGETS = 2000
    # Two inline kernels that tests/test_ik_compiled.py calls on their own.
    T, J, delta = np.empty((4, 4)), np.empty((6, d.n_joints)), np.empty(6)
    ik_compiled._pose_jacobian(d.base, d.links, d.tool, d.joint_offsets, d.prismatic, q[0], T, J)
    ik_compiled._delta(T, T, delta)


#: Groups of about equal compile time, one interpreter each.
GROUPS = {"puma_newton": puma_newton, "puma_jacobi": puma_jacobi, "plain_newton": plain_newton}


def warm(workers: int) -> float:
    """Run :data:`GROUPS` in up to ``workers`` subprocesses at a time; seconds taken.
    A failing group is reported on stderr and otherwise ignored (see the docstring)."""
    t0 = time.perf_counter()
    path = os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))
    env = os.environ | {"PYTHONPATH": path}

    def run(name: str) -> None:
        argv = [sys.executable, str(Path(__file__)), name]
        out = subprocess.run(argv, env=env, cwd=ROOT, capture_output=True, text=True)
        if out.returncode != 0:
            print(f"kernel warm-up {name} failed:\n{out.stderr}", file=sys.stderr)

    with ThreadPoolExecutor(max(1, workers)) as pool:
        list(pool.map(run, GROUPS))
    return time.perf_counter() - t0


if __name__ == "__main__":
    GROUPS[sys.argv[1]]()
