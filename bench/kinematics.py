"""Throughput of the batch kinematics (measured, never asserted in tests)."""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from pipeline.kinematics.chain import forward_kinematics
from pipeline.kinematics.jacobian import geometric_jacobian
from pipeline.kinematics.smodel import smodel_from_matrix
from pipeline.robots import get_robot, puma560


def best_of(fn: Callable[[], object], repeats: int = 5) -> float:
    """Best wall time of ``repeats`` calls, in seconds."""
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> None:
    rng = np.random.default_rng(0)
    rob = get_robot("puma560")
    chain = rob.design_chain()
    lim = np.deg2rad(rob.limits)
    n = 100_000
    q = rng.uniform(lim[:, 0], lim[:, 1], (n, 6))
    T = forward_kinematics(chain, q)
    rows = [
        ("forward_kinematics (Puma, batch)", n, best_of(lambda: forward_kinematics(chain, q))),
        ("geometric_jacobian (Puma, batch)", n, best_of(lambda: geometric_jacobian(chain, q))),
        (
            "puma560.inverse_kinematics, 8 branches",
            n,
            best_of(lambda: puma560.inverse_kinematics(T)),
        ),
        ("smodel_from_matrix", n, best_of(lambda: smodel_from_matrix(T))),
    ]
    print(f"{'benchmark':45s} {'items':>8s} {'best s':>9s} {'µs/item':>9s}")
    for name, items, sec in rows:
        print(f"{name:45s} {items:8d} {sec:9.4f} {1e6 * sec / items:9.3f}")
