"""Held-out validation without ground truth: predict positions the fit did not see.

k-fold over the configurations of each joint sweep and of the pose set: fold ``f`` holds
out the steps ``≡ f (mod k)`` of every sweep (so each sweep's target point keeps most of
its observations), the refinement is refit without them, warm-started at the full fit, and
the refit chain predicts the held-out positions. A session with validation (``check``)
configurations uses those instead: the full fit never saw them, so no refit.

The held-out error of one position is ``e = m − p̂`` (measured minus predicted); its
expected size combines the measurement noise and the fit's uncertainty there,

    ``E|e|² = trace(C_m) + trace(J Σ Jᵀ)``

with ``C_m`` the position's covariance and ``Σ`` the (refit's) kinematic covariance,
``J = ∂p/∂θ``. The ratio of the RMS held-out error to the RMS expected one is ≈ 1 when
the noise model and the covariance are honest.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from pipeline.refine.kinematics import TOOL_POINT, ChainModel
from pipeline.sweeps import POSES_SWEEP

Array = npt.NDArray[np.float64]
#: A refit: positions kept (K,) bool -> kinematic parameters (P,) and their covariance.
Refit = Callable[[npt.NDArray[np.bool_]], tuple[Array, Array]]

#: Folds (issue 15): 5, so each refit keeps 80 % of every sweep.
FOLDS = 5


@dataclass(frozen=True)
class HeldOut:
    """Per held-out position: its fold (−1: a check configuration), the error (cm) and
    its expected 1σ RMS size (cm), and the measurement's part of that."""

    index: npt.NDArray[np.int64]
    fold: npt.NDArray[np.int64]
    error_cm: Array
    expected_cm: Array
    measurement_cm: Array

    @property
    def ratio(self) -> float:
        """RMS error over RMS expected error (nan without held-out positions)."""
        if len(self.error_cm) == 0:
            return float("nan")
        return float(np.sqrt(np.mean(self.error_cm**2) / np.mean(self.expected_cm**2)))


def fold_of_steps(steps: npt.ArrayLike, k: int = FOLDS) -> npt.NDArray[np.int64]:
    """Fold of each step: ``step mod k`` (module docstring)."""
    return np.asarray(steps, np.int64) % k


def _score(
    model: ChainModel, x: Array, cov: Array, sel: npt.NDArray[np.bool_],
    measured: Array, cov_m: Array,
) -> tuple[Array, Array, Array]:  # fmt: skip
    """Errors, expected errors and the measurement parts of the rows ``sel``."""
    payload = None if model.payload_kg is None else model.payload_kg[sel]
    sub = dataclasses.replace(
        model, link=model.link[sel], theta=model.theta[sel], point=model.point[sel],
        payload_kg=payload,
    )  # fmt: skip
    J = sub.position_jacobian(x)
    fit_var = np.einsum("kip,pq,kiq->k", J, cov, J)
    meas_var = np.trace(cov_m[sel], axis1=1, axis2=2)
    err = np.linalg.norm(measured[sel] - sub.positions(x), axis=1)
    return err, np.sqrt(fit_var + meas_var), np.sqrt(meas_var)


def kfold(
    model: ChainModel, sweep: npt.ArrayLike, step: npt.ArrayLike,
    measured: Array, cov_m: Array, refit: Refit, k: int = FOLDS,
) -> HeldOut:  # fmt: skip
    """Held-out errors of the joint sweeps' and the pose set's positions, k-fold (the
    targets of one pose share its fold: a pose is held out whole).

    ``model`` observes the block's K positions (``measured`` (K, 3), NaN rows not
    scored; their covariances ``cov_m`` (K, 3, 3)); ``refit(keep)`` fits without the
    positions ``~keep``.
    """
    fold = fold_of_steps(step, k)
    sweep = np.asarray(sweep)
    joint = ((sweep >= 1) | (sweep == POSES_SWEEP)) & np.isfinite(measured).all(axis=1)
    out: list[tuple[np.ndarray, ...]] = []
    for f in range(k):
        held = joint & (fold == f)
        if not held.any():
            continue
        x, cov = refit(~held)
        idx = np.flatnonzero(held)
        out.append((idx, np.full(len(idx), f), *_score(model, x, cov, held, measured, cov_m)))
    return _held_out(out)


def check_configurations(
    model: ChainModel, theta: Array, measured: Array, cov_m: Array, x: Array, cov: Array,
    payload_kg: Array | None = None,
) -> HeldOut:  # fmt: skip
    """Held-out errors of the check configurations: the tool point of ``model`` at the
    joint offsets ``theta`` (m, n) from ``q̄^s`` (under ``payload_kg`` (m,), kg, when the
    model has non-geometric terms) against ``measured`` (m, 3)."""
    j = model.point_names.index(TOOL_POINT)
    m = len(theta)
    tool = dataclasses.replace(
        model, link=np.full(m, model.n_joints, np.int64), theta=np.asarray(theta, float),
        point=np.full(m, j, np.int64), payload_kg=payload_kg,
    )  # fmt: skip
    sel = np.ones(m, bool)
    return _held_out([(np.arange(m), np.full(m, -1), *_score(tool, x, cov, sel, measured, cov_m))])


def _held_out(parts: list[tuple[np.ndarray, ...]]) -> HeldOut:
    if not parts:
        e = np.zeros(0)
        return HeldOut(np.zeros(0, np.int64), np.zeros(0, np.int64), e, e, e)
    cols = [np.concatenate(c) for c in zip(*parts, strict=True)]
    return HeldOut(cols[0].astype(np.int64), cols[1].astype(np.int64), *cols[2:])
