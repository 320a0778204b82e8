"""The refinement's normal equations from the problem's structure (issue 15's cost): equal
to the dense ``JᵀWJ`` and ``JᵀWr``, and a recorded-sensor χ² warm-started at the solution's
prediction that needs few evaluations and finds the same χ²."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from recording_data import small_session

from pipeline.identify import identify
from pipeline.refine import solve as solve_module
from pipeline.refine.solve import (
    normal_equations,
    recorded_chi2,
    residuals_and_jacobian,
    solve,
)
from pipeline.stages.refine import STAGE
from pipeline.stages.refine_problem import session_problem
from pipeline.stages.runner import stage_path
from pipeline.stages.tables import read_table


@pytest.fixture(scope="module")
def sonic_problem(tmp_path_factory):
    d = small_session(tmp_path_factory, seed=5, points=8)
    if not (d / "signature.json").is_file():
        identify(d, report=False)
    inputs = {name: read_table(stage_path(d, name)) for name in STAGE.inputs}
    return session_problem(inputs, level="ranges")


@pytest.mark.parametrize("variant", ["all", "keep", "fixed_block"])
def test_normal_equations_equal_the_dense_products(sonic_problem, variant: str) -> None:
    problem, x = sonic_problem.problem, sonic_problem.x0.copy()
    rng = np.random.default_rng(4)
    x[: problem.n_kin] += rng.normal(0.0, 1e-3, problem.n_kin)
    if variant == "keep":
        keep = rng.random(problem.block.keys.num_rows) < 0.7
        problem = dataclasses.replace(problem, keep=keep)
    if variant == "fixed_block":
        problem = dataclasses.replace(problem, fixed_block=True)
    r, J = residuals_and_jacobian(problem, x)
    if variant == "fixed_block":
        J = J[:, : problem.n_kin]
    w = rng.uniform(0.2, 1.0, len(r))
    lin = solve_module.linearize(problem, x)
    A, g = normal_equations(problem, x, lin)(w)
    A_ref, g_ref = J.T @ (J * w[:, None]), J.T @ (w * r)
    d = np.sqrt(np.diag(A_ref))
    scale = np.outer(np.where(d > 0, d, 1.0), np.where(d > 0, d, 1.0))
    np.testing.assert_allclose(A / scale, A_ref / scale, rtol=0, atol=1e-12)
    np.testing.assert_allclose(g, g_ref, rtol=1e-10, atol=1e-10 * np.abs(g_ref).max())


def test_recorded_chi2_is_warm_started(sonic_problem, monkeypatch) -> None:
    """The recorded-sensor solve starts at the solution's Gauss-Newton prediction: fewer
    evaluations than from the solution's kinematics (robot3: 5 against 9; this session:
    8 against 10), the same χ² to rounding."""
    problem = sonic_problem.problem
    sol = solve(problem, sonic_problem.x0)
    calls: list[int] = []
    linearize = solve_module.linearize
    monkeypatch.setattr(solve_module, "linearize", lambda p, z: calls.append(1) or linearize(p, z))
    x = sol.x.copy()
    x[problem.n_kin :] = problem.block.x0
    cold = solve(dataclasses.replace(problem, fixed_block=True), x).chi2
    n_cold, calls[:] = len(calls), []
    warm = recorded_chi2(problem, sol)
    assert warm == pytest.approx(cold, rel=1e-12)
    assert len(calls) < n_cold
