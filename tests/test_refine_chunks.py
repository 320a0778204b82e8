"""The refinement on many observations (issue 45): the chain evaluated a chunk at a time
(``solve.CHUNK``), the normal equations and the identifiability's triangular factor summed
over chunks, the folds' normal equations in one pass, and a large fit started on a
subsample (``solve.PREFIT``): each the same as the whole computation, to rounding."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from recording_data import small_session

from pipeline.identify import identify
from pipeline.refine import solve as solve_module
from pipeline.refine.holdout import StepRefit, fold_of_blocks
from pipeline.refine.identifiability import analyse, analyse_factor, scaled_columns
from pipeline.refine.solve import (
    chain_positions,
    jacobian_factor,
    linearize,
    normal_equations,
    residuals_and_jacobian,
    solve,
)
from pipeline.rig.simulate import SimulationOptions, simulate_session
from pipeline.stages.refine import STAGE
from pipeline.stages.refine_problem import session_problem
from pipeline.stages.runner import stage_path
from pipeline.stages.tables import read_table


def _inputs(d, ranges=False):
    if not (d / "signature.json").is_file():
        identify(d, report=False)
    names = [n for n in STAGE.inputs if ranges or n != "ranges"]
    return {name: read_table(stage_path(d, name)) for name in names}


@pytest.fixture(scope="module")
def sonic_problem(tmp_path_factory):
    """Raw ranges: rows of no position (rods) and a block with parameters of its own."""
    d = small_session(tmp_path_factory, seed=5, points=8)
    return session_problem(_inputs(d, ranges=True), level="ranges")


@pytest.fixture(scope="module")
def pose_problem(tmp_path_factory):
    """A tracker pose set of 300 poses (one target each)."""
    d = tmp_path_factory.mktemp("poses")
    simulate_session(d, SimulationOptions(sensor="tracker", poses=300, sweeps=False, seed=3))
    return session_problem(_inputs(d))


def _perturbed(problem, x0, seed=4):
    x = x0.copy()
    x[: problem.n_kin] += np.random.default_rng(seed).normal(0.0, 1e-3, problem.n_kin)
    return x


@pytest.mark.parametrize("variant", ["all", "keep", "fixed_block"])
def test_chunked_normal_equations_equal_the_whole(sonic_problem, monkeypatch, variant) -> None:
    problem = sonic_problem.problem
    x = _perturbed(problem, sonic_problem.x0)
    rng = np.random.default_rng(5)
    if variant == "keep":
        problem = dataclasses.replace(problem, keep=rng.random(len(problem.model.link)) < 0.7)
    if variant == "fixed_block":
        problem = dataclasses.replace(problem, fixed_block=True)
    lin = linearize(problem, x)
    w = rng.uniform(0.2, 1.0, len(lin.r))
    A, g = normal_equations(problem, x, lin)(w)
    monkeypatch.setattr(solve_module, "CHUNK", 7)
    assert len(solve_module.chunks(problem.model)) > 1
    A_c, g_c = normal_equations(problem, x, lin)(w)
    d = np.sqrt(np.diag(A))
    d = np.outer(np.where(d > 0, d, 1.0), np.where(d > 0, d, 1.0))
    np.testing.assert_allclose(A_c / d, A / d, rtol=0, atol=1e-12)
    np.testing.assert_allclose(g_c, g, rtol=0, atol=1e-12 * np.abs(g).max())


def test_many_weightings_equal_one_at_a_time(sonic_problem, monkeypatch) -> None:
    monkeypatch.setattr(solve_module, "CHUNK", 9)
    problem = sonic_problem.problem
    x = _perturbed(problem, sonic_problem.x0)
    lin = linearize(problem, x)
    normal = normal_equations(problem, x, lin)
    ws = [np.random.default_rng(s).uniform(0.0, 1.0, len(lin.r)) for s in range(3)]
    for (A, g), w in zip(normal.many(ws), ws, strict=True):
        A1, g1 = normal(w)
        np.testing.assert_array_equal(A, A1)
        np.testing.assert_array_equal(g, g1)


def test_chunked_positions_are_the_same_bits(pose_problem, monkeypatch) -> None:
    model, kin = pose_problem.problem.model, pose_problem.x0[: pose_problem.problem.n_kin]
    whole = model.positions(kin)
    monkeypatch.setattr(solve_module, "CHUNK", 17)
    np.testing.assert_array_equal(chain_positions(model, kin), whole)
    np.testing.assert_array_equal(chain_positions(model, kin, keep=False), whole)


@pytest.mark.parametrize("fixture", ["sonic_problem", "pose_problem"])
def test_chunked_factor_gives_the_same_analysis(request, monkeypatch, fixture) -> None:
    """``RᵀR`` of the chunks' TSQR is the scaled ``JᵀJ``; the analysis (pivots, held
    parameters) is the whole Jacobian's."""
    sp = request.getfixturevalue(fixture)
    problem, x = sp.problem, _perturbed(sp.problem, sp.x0)
    r, J = residuals_and_jacobian(problem, x)
    whole = analyse(J, sp.units, True, len(problem.model.link))
    monkeypatch.setattr(solve_module, "CHUNK", 11)
    n, R = jacobian_factor(problem, x, lambda Jc: scaled_columns(Jc, sp.units))
    assert n == len(r)
    Js = scaled_columns(J, sp.units)
    ref = Js.T @ Js
    d = np.sqrt(np.diag(ref))
    np.testing.assert_allclose((R.T @ R) / np.outer(d, d), ref / np.outer(d, d), atol=1e-12)
    chunked = analyse_factor(R, True, len(problem.model.link))
    np.testing.assert_array_equal(chunked.held, whole.held)
    np.testing.assert_allclose(chunked.sigmas, whole.sigmas, rtol=1e-9)
    assert chunked.condition == pytest.approx(whole.condition, rel=1e-9)


def test_a_large_fit_started_on_a_subsample_ends_at_the_same_minimum(
    pose_problem, monkeypatch
) -> None:
    problem = pose_problem.problem
    x0 = _perturbed(problem, pose_problem.x0, seed=7)
    whole = solve(problem, x0)
    calls: list[int] = []
    inner = solve_module.solve

    def counted(p, *a, **k):
        calls.append(len(p.model.link))
        return inner(p, *a, **k)

    monkeypatch.setattr(solve_module, "PREFIT", 40)
    monkeypatch.setattr(solve_module, "solve", counted)
    started = solve_module.solve(problem, x0)
    assert calls[0] == 300 and max(calls[1:]) <= 40  # the subsample's fit ran first
    # the same minimum to the solver's tolerance: every parameter within 1e-5 of its σ
    # (the least determined, joint 6's ty, 1.3e-9 cm apart on these noisy 300 poses), the
    # measured points' predictions within 1e-9 cm
    sigma = np.sqrt(np.diag(whole.covariance))
    np.testing.assert_array_less(np.abs(started.x - whole.x), 1e-5 * sigma)
    model = problem.model
    np.testing.assert_allclose(
        model.positions(started.x[: model.n_params]),
        model.positions(whole.x[: model.n_params]),
        rtol=0,
        atol=1e-9,
    )
    assert started.chi2 == pytest.approx(whole.chi2, rel=1e-11)  # 1.3e-12 apart


def test_fold_steps_prepared_in_one_pass_equal_one_at_a_time(pose_problem, monkeypatch) -> None:
    problem = pose_problem.problem
    sol = solve(problem, pose_problem.x0)
    keys = problem.block.keys
    fold = fold_of_blocks(keys.column("sweep").to_numpy(), keys.column("step").to_numpy(), 5)
    keeps = [fold != f for f in range(5)]
    one = StepRefit(problem, sol.x, 1.0)
    steps = [one.step(k) for k in keeps]
    monkeypatch.setattr(solve_module, "CHUNK", 23)
    prepared = StepRefit(problem, sol.x, 1.0)
    prepared.prepare(keeps)
    for keep, (x, N) in zip(keeps, steps, strict=True):
        x_p, N_p = prepared.step(keep)
        np.testing.assert_allclose(x_p, x, rtol=0, atol=1e-12)
        np.testing.assert_allclose(N_p, N, rtol=1e-8, atol=1e-14)
