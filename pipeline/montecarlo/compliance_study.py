"""The ``compliance`` study (issue 27): a rigid fit against a fit with joint compliance.

Each robot is a ``refine`` study robot (:mod:`.refine_study`: Puma 560, ``pipeline
simulate`` + ``pipeline identify``, default plan, (7.9) at k = 1, audited over 1,000
configurations) whose true joints may deflect under gravity
(:func:`pipeline.rig.true_robot.draw_nongeometric`). Its one recording is identified twice:
``refine.nongeometric=none`` (the rigid signature) and ``=compliance`` (with the terms of
:mod:`pipeline.kinematics.nongeometric`), each audited, the terms included, against a truth
that has them (:func:`pipeline.rig.audit.table_errors`).

A study of its own, not a setting of ``refine``: the refine study sweeps the range noise
k and compares two models of one fit (S-Model, refined), with a table and figures along
k; here the two fits of one recording are the comparison, and the swept parameter is the
truth's compliance, the RMS flange displacement over the joint ranges: 0 (a rigid robot:
what the terms cost where there is nothing to fit) and 0.3 mm (a UR10's, issue 27). A
compliant k would be a point on the refine study's k axis with other indices and another
truth. What both share is the refine study's: its sessions, seeds, runner and accuracy.

The session is the refine study's, joint sweeps alone: they see the compliance. The study
names both fits rather than ``refine.nongeometric=auto``, whose choice between them is
docs/nongeometric.md's. A sweep moves the links beyond its joint, so the gravity torques
on the joints change along it and bend its circle: noiseless, the fit with the terms is exact
(tests/test_montecarlo_compliance.py; sonic and tracker sweeps); at the default noise
the 9 independent terms lowered χ² by 158 on one robot (seed 5), and the audited RMS
3.3× (median) on 10 (docs/montecarlo.md). The coefficients one by one are not identified
(σ ~10× their values at this noise); the deflections are. No pose set is needed.

Common random numbers: the robots and deviates are the same at every setting (the
compliance draws from its own stream of the simulate seed), so the sessions of a robot
differ by the deflections alone.

Cost: two sessions per robot, each simulated once and identified twice (the second fit
reruns ``refine`` and the stages after it, ~1.2 s of CPU): ~6 s of CPU per robot,
measured 2026-11-27 (docs/montecarlo.md, "Cost").
"""

from __future__ import annotations

import math
from functools import partial
from pathlib import Path

import numpy as np

from pipeline.kinematics.transforms import Array
from pipeline.montecarlo.refine_study import (
    VERDICT_CODES,
    SessionAccuracy,
    each_session,
    run_session,
    session_accuracy,
)
from pipeline.rig.simulate import SimulationOptions

#: True compliance, RMS flange displacement (mm): a rigid robot and a UR10's (issue 27).
COMPLIANCE_MM = (0.0, 0.3)
#: The two fits of each recording, ``refine.nongeometric``: rigid, then with the terms.
FITS = ("none", "compliance")
#: One robot (its settings) per task, as the refine study.
BATCH = 1
INDEX_NAMES = (
    "rigid_rms_cm", "rigid_max_cm", "terms_rms_cm", "terms_max_cm", "ratio",
    "rigid_predicted_rms_cm", "terms_predicted_rms_cm", "rigid_chi2_per_dof",
    "terms_chi2_per_dof", "rigid_verdict", "terms_verdict", "simulate_seed",
)  # fmt: skip
INDEX_UNITS = ("cm", "cm", "cm", "cm", "", "cm", "cm", "", "", "", "", "")
INDEX_SIGNED = (False,) * len(INDEX_NAMES)


def indices(rigid: SessionAccuracy, terms: SessionAccuracy, sim_seed: int) -> Array:
    """The study's indices (K,) of one session's two fits, in the order of
    :data:`INDEX_NAMES` (``ratio``: rigid RMS / RMS with the terms)."""
    rg, tm = rigid.refined, terms.refined
    return np.array(
        [
            rg.rms_position_cm, rg.max_position_cm, tm.rms_position_cm, tm.max_position_cm,
            rg.rms_position_cm / tm.rms_position_cm, rigid.predicted_rms_cm,
            terms.predicted_rms_cm, rigid.chi2_per_dof, terms.chi2_per_dof,
            VERDICT_CODES.get(rigid.verdict, math.nan),
            VERDICT_CODES.get(terms.verdict, math.nan), sim_seed,
        ],
        float,
    )  # fmt: skip


def _both_fits(folder: Path, sim_seed: int) -> Array:
    """Identify the session in ``folder`` with each of :data:`FITS` (the second run redoes
    ``refine`` and the stages after it) and audit each."""
    from pipeline.identify import identify

    acc = []
    for fit in FITS:
        identify(folder, report=False, overrides={"refine": {"nongeometric": fit}})
        acc.append(session_accuracy(folder))
    rigid, terms = acc
    return indices(rigid, terms, sim_seed)


def compliance_all(
    values: tuple[float, ...],
    seeds: list[np.random.SeedSequence],
    points: int = 100,
    repeats: int = 10,
) -> Array:
    """Indices (settings, robots, K) of a batch of robots at every compliance ``values``
    (mm). ``points`` and ``repeats``: the plan's N_i and N_avg (the defaults of ``pipeline
    simulate``; tests bind smaller ones with :func:`functools.partial`)."""

    def session(folder: Path, sim_seed: int, mm: float) -> Array:
        opts = SimulationOptions(seed=sim_seed, points=points, repeats=repeats, compliance_mm=mm)
        identify = "pipeline identify sessions/NAME --param refine.nongeometric=compliance"
        measure = partial(_both_fits, sim_seed=sim_seed)
        return run_session(folder, opts, measure, "compliance", identify)

    return each_session(values, seeds, session, len(INDEX_NAMES))


def compliance_setting(value: float, seeds: list[np.random.SeedSequence]) -> Array:
    """Indices (robots, K) at one compliance (the engine's per-setting form)."""
    return compliance_all((value,), seeds)[0]
