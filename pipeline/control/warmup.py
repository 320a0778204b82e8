"""Compile armsig's numerical kernels now, so that the first ``ik`` or ``identify`` answers
as fast as a later one (issue 30, item 4; ``make install`` runs ``pipeline warmup``).

numba compiles a kernel on its first call, for the argument types of that call, and caches
the machine code (:mod:`pipeline.kinematics.kernel_cache`). The cheapest way to compile
exactly what the commands use is to make the calls they make: every built-in robot's
design model solves a few of its own poses through :func:`solve_poses` (Newton-Raphson, a
batch and one pose) and the Puma's real-time solver answers one target. ``everything``
(``pipeline warmup --all``) adds the Jacobi solver and the same with non-geometric terms
(the compiled deflection), which otherwise compile on their first use: 25.7 s of CPU
at install instead of 38.1 s for all (issue 45, measured 2026-11-29 on the shared
machine; docs/scale.md). The answers are checked, so a warm-up that compiles a kernel
which then gives wrong joints fails loudly instead of passing quietly.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from pipeline.control.controller import Controller, solve_poses
from pipeline.errors import ArmsigError
from pipeline.kinematics.nongeometric import NonGeometric, all_terms
from pipeline.robots import builtin_names, get_robot
from pipeline.signature.file import Signature

#: Poses per robot: enough for a batch (the batched kernels) and cheap.
POSES = 4
#: A solve of the design model's own poses is exact; this bound only catches a wrong kernel.
TOLERANCE_CM = 1e-6


@dataclass(frozen=True)
class Warmed:
    """What one robot's warm-up solved: ``calls`` solves, the largest position error."""

    robot: str
    calls: int
    max_error_cm: float
    seconds: float


def design_controller(name: str, nongeometric: bool = False) -> Controller:
    """The controller of a built-in robot's design model (sensor frame = design base);
    with ``nongeometric``, small compliance terms (1e-4 rad per cm of lever)."""
    robot = get_robot(name)
    chain = robot.design_chain()
    ng = None
    if nongeometric:
        terms = all_terms(robot.prismatic, ("compliance",))
        ng = NonGeometric(terms, np.full(terms.size, 1e-4), chain)
    sig = Signature(robot, chain, np.eye(4), np.eye(4), nongeometric=ng)
    return Controller.from_signature(sig)


def _in_limits(c: Controller, seed: int) -> np.ndarray:
    lim = c.robot.limits
    rng = np.random.default_rng(seed)
    return rng.uniform(lim[:, 0] * 0.8 + lim[:, 1] * 0.2, lim[:, 0] * 0.2 + lim[:, 1] * 0.8,
                       (POSES, c.robot.n_joints))  # fmt: skip


def warm_robot(name: str, everything: bool = False) -> Warmed:
    """Solve a few of ``name``'s own design poses the ways the commands do by default
    (Newton-Raphson, a batch and one pose; the Puma's real-time solver); with
    ``everything`` also Jacobi (``--method jacobi``) and with non-geometric terms, which
    otherwise compile on their first use (issue 45; module docstring)."""
    t0 = time.perf_counter()
    worst, calls = 0.0, 0
    for ng in (False, True) if everything else (False,):
        c = design_controller(name, ng)
        p = c.poses(_in_limits(c, 0))
        xyz, rpy = p.xyz_cm, p.rpy_deg
        puma = c.robot.name == "puma560"
        methods = ("nr", "jacobi") if puma and everything else ("nr",)
        for method in methods:
            for rows in (slice(None), slice(0, 1)):  # a batch, and one pose (`ik --pose`)
                _, res = solve_poses(c, xyz[rows], rpy[rows], method=method)
                worst = max(worst, float(np.max(res.position_error_cm, initial=0.0)))
                calls += 1
        if puma:
            solver = c.realtime()
            for T in p.matrix:
                solver.solve_one(T)
                calls += 1
    if not worst <= TOLERANCE_CM:
        raise ArmsigError(
            f"warm-up: {name}'s design model missed its own poses by {worst:.3g} cm",
            expected=f"<= {TOLERANCE_CM:g} cm (an exact solve)",
            fix="report it: the compiled kernels give wrong joints on this machine",
        )
    return Warmed(name, calls, worst, time.perf_counter() - t0)


def warm_all(everything: bool = False) -> list[Warmed]:
    """Every built-in robot, warmed (:func:`warm_robot`)."""
    return [warm_robot(name, everything) for name in builtin_names()]
