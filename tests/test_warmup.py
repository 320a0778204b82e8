"""`pipeline warmup` (issue 30, item 4): the kernels compiled ahead by the calls the commands
make, with answers checked; a wrong answer is refused, not cached quietly."""

from __future__ import annotations

import json

import numpy as np
from typer.testing import CliRunner

from pipeline.cli import app
from pipeline.control import warmup
from pipeline.robots import builtin_names

runner = CliRunner()


def test_warmup_solves_every_builtin_robot_exactly() -> None:
    """By default what the commands use by default (issue 45): Newton, batch and one
    pose, and the Puma's real-time solver; ``--all`` adds Jacobi (Puma) and the same
    with non-geometric terms."""
    for args, models, methods in ((["warmup"], 1, 1), (["warmup", "--all"], 2, 2)):
        r = runner.invoke(app, [*args, "--json"])
        assert r.exit_code == 0, r.output
        doc = json.loads(r.output)
        assert [w["robot"] for w in doc["robots"]] == builtin_names()
        for w in doc["robots"]:
            assert w["max_error_cm"] <= 1e-9
            per_model = (methods * 2 + warmup.POSES) if w["robot"] == "puma560" else 2
            assert w["calls"] == models * per_model, (args, w)


def test_the_design_controller_with_terms_moves_the_tool() -> None:
    rigid, bent = (warmup.design_controller("puma560", ng) for ng in (False, True))
    q = np.array([[10.0, -40.0, 170.0, 20.0, 30.0, 40.0]])
    moved = np.linalg.norm(rigid.poses(q).xyz_cm - bent.poses(q).xyz_cm)
    assert moved > 1e-3  # the compiled deflection is exercised, not a rigid copy


def test_a_kernel_that_misses_its_own_poses_is_refused(monkeypatch) -> None:
    real = warmup.solve_poses

    def off(*args, **kwargs):
        q, res = real(*args, **kwargs)
        res.position_error_cm[...] = 0.5
        return q, res

    monkeypatch.setattr(warmup, "solve_poses", off)
    r = runner.invoke(app, ["warmup"])
    assert r.exit_code == 1
    assert r.output.count("\n") == 1 and "missed its own poses by 0.5 cm" in r.output
