"""What a session's measurements can identify: rank, conditioning, and the parameters held.

A pose set (random whole-arm configurations) need not see every parameter of the chain:
a tool point on the last joint's axis cannot show that axis's direction, a joint that
never moves cannot show its axis at all, and a few poses cannot fix 27 parameters. Such
parameters must not be fitted to noise. They are found from the whitened Jacobian
``J`` (residuals in σ of the stated noise) with its columns scaled by a design tolerance
(:data:`TOLERANCE_RAD`, :data:`TOLERANCE_CM`): column ``j`` of ``J_s = J · diag(tol)`` is
how many σ the residuals move when parameter ``j`` is off by a tolerance.

QR with column pivoting of ``J_s`` (LAPACK ``geqp3``, :func:`scipy.linalg.qr`) orders the
parameters from the best seen to the worst; ``|R_kk|`` is what parameter ``k`` adds that
the ones before it cannot explain, in σ. A parameter is **held** at its start (the
design value) when

- ``|R_kk| < RANK_RTOL · |R_00|``: structurally invisible, a rank deficiency of the
  model on these configurations (round-off level); or
- ``|R_kk| < MIN_SIGMAS``: a tolerance-sized error in it moves the residuals by less
  than one σ once the others have done what they can: the data cannot tell it from
  noise (only when the block states its noise; at the solution σ is the larger of the
  stated noise and the scatter the fit shows, ``sqrt(χ²/dof)``).

The analysis runs at the start (the design) and again at the solution
(:func:`fit_identifiable`): what either finds invisible is held, and the summary is the
solution's.

This is the base-parameter selection of the calibration literature (figaroh's QR with
pivoting; Khalil & Dombre, *Modeling, identification and control of robots*, 11.4),
with a noise floor added. The condition number and Borm & Menq's observability index
``O_1 = (Π σ_i)^{1/m} / √N`` are those of ``J_s`` on the identified parameters (its
singular values ``σ_i``, ``N`` the measured points).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import numpy.typing as npt

from pipeline.errors import StageError
from pipeline.optim.block import Array
from pipeline.refine.solve import Problem, Solution, jacobian_factor, solve

#: Design tolerances the columns are scaled by: the basin a design model is expected in
#: (issue 26: off by up to 1 cm and 1° in every parameter).
TOLERANCE_RAD = np.radians(1.0)
TOLERANCE_CM = 1.0
#: A compliance coefficient's (rad per cm of lever, issue 27): 1° of deflection at a 1 m
#: lever, ten times a UR10's largest.
TOLERANCE_RAD_PER_CM = TOLERANCE_RAD / 100.0
#: Relative pivot below which a parameter is structurally invisible: the QR of an exactly
#: rank-deficient Jacobian leaves pivots at round-off, ~1e-15 of the first (measured on
#: a Puma tool point on joint 6's axis: 6e-15); a seen parameter is above 1e-6.
RANK_RTOL = 1e-10
#: A parameter whose tolerance-sized error moves the residuals by less than this many σ
#: (after the others) is below the noise.
MIN_SIGMAS = 1.0
#: Correlations of identified parameters listed in the report.
CORRELATION_LIMIT = 0.95
#: Coordinates per identified parameter a pose set must hold at least: with fewer the
#: residual degrees of freedom are too few to estimate the noise and the fit follows it.
COORDINATES_PER_PARAMETER = 2


@dataclass(frozen=True)
class Identifiability:
    """The analysis of one Jacobian (module docstring).

    Attributes
    ----------
    held : ndarray of bool, shape (P,)
        Parameters held at their start.
    why : tuple of str
        Per held parameter, in index order: ``structural`` or ``below noise``.
    sigmas : ndarray, shape (P,)
        ``|R_kk|`` of each parameter (σ per tolerance), in parameter order.
    condition : float
        Condition number of ``J_s`` on the identified parameters.
    observability : float
        ``O_1`` of ``J_s`` on the identified parameters.
    """

    held: npt.NDArray[np.bool_]
    why: tuple[str, ...]
    sigmas: Array
    condition: float
    observability: float
    correlated: tuple[tuple[int, int, float], ...] = field(default=())

    @property
    def rank(self) -> int:
        return int((~self.held).sum())


def tolerance_scale(units: tuple[str, ...]) -> Array:
    """The tolerance of each parameter by its internal unit (rad, rad/cm, cm; others 1)."""
    by_unit = {"rad": TOLERANCE_RAD, "rad/cm": TOLERANCE_RAD_PER_CM}
    return np.array([by_unit.get(u, TOLERANCE_CM) for u in units])


def analyse(
    J: Array,
    units: tuple[str, ...],
    noise_stated: bool,
    n_points: int,
    held_before: npt.NDArray[np.bool_] | None = None,
    tolerance: Array | None = None,
) -> Identifiability:
    """The identifiability of the parameters of the whitened Jacobian ``J`` (R, P) with
    internal ``units`` (P,); ``noise_stated``: whether the whitening is the recorded
    noise (else only structural deficiencies are held); ``n_points``: measured points;
    ``held_before``: parameters held already (at the start: they stay held);
    ``tolerance`` (P,): each parameter's, where its start is not a design value
    (default :func:`tolerance_scale` of ``units``)."""
    Js = scaled_columns(J, units, held_before, tolerance)
    # J_s = Q₀ R₀ (blocked Householder, fast), then R₀ P = Q₁ R: the pivots and R of J_s
    # itself (Q₀ Q₁ orthonormal), at the cost of a (P, P) pivoted QR (geqp3 on the tall
    # J_s took 0.14 s of a 2,000-pose fit).
    R0 = np.asarray(np.linalg.qr(Js, mode="r"))
    return analyse_factor(R0, noise_stated, n_points, held_before)


def scaled_columns(
    J: Array, units: tuple[str, ...], held_before: npt.NDArray[np.bool_] | None = None,
    tolerance: Array | None = None,
) -> Array:  # fmt: skip
    """``J_s``: the columns of ``J`` scaled by their tolerances, those ``held_before``
    zero (:func:`analyse`)."""
    Js = J * (tolerance_scale(units) if tolerance is None else tolerance)
    if held_before is not None:  # held already: out of the QR, so that the exact partner
        # of a held parameter (two lumped masses on one joint's axis) is not held too
        Js = np.where(held_before, 0.0, Js)
    return Js


def analyse_factor(
    R0: Array, noise_stated: bool, n_points: int,
    held_before: npt.NDArray[np.bool_] | None = None,
) -> Identifiability:  # fmt: skip
    """:func:`analyse` from ``R₀`` (min(R, P), P) of the QR ``J_s = Q₀ R₀`` of the scaled
    Jacobian (:func:`scaled_columns`), which may be formed a chunk of rows at a time
    (:func:`pipeline.refine.solve.jacobian_factor`)."""
    from scipy.linalg import qr

    R, piv = qr(R0, mode="r", pivoting=True)
    R = R[: min(R0.shape)]
    d = np.abs(np.diag(R)) if R.size else np.zeros(0)
    d = np.concatenate([d, np.zeros(R0.shape[1] - len(d))])  # fewer rows than parameters
    sigmas = np.zeros(R0.shape[1])
    sigmas[piv] = d
    top = d[0] if len(d) and d[0] > 0 else 1.0
    held = sigmas < RANK_RTOL * top
    why = np.where(held, "structural", "")
    if noise_stated:
        low = ~held & (sigmas < MIN_SIGMAS)
        why = np.where(low, "below noise", why)
        held = held | low
    if held_before is not None:  # their columns are zero here: "structural" says nothing
        why = np.where(held_before, "at the start", why)
        held = held | held_before
    # Pivoted QR is greedy: a later pivot may have fallen below a threshold only because
    # an earlier one took its share; the held set is what the greedy order leaves, the
    # usual base-parameter choice, and the rest is refitted jointly.
    # The singular values of J_s's identified columns are R's (J_s P = Q R, Q orthonormal).
    free = ~held[piv]
    s = np.linalg.svd(R[:, free], compute_uv=False) if free.any() else np.ones(1)
    condition = float(s[0] / s[-1]) if s[-1] > 0 else float("inf")
    observability = float(
        np.exp(np.mean(np.log(np.maximum(s, 1e-300)))) / np.sqrt(max(n_points, 1))
    )
    return Identifiability(
        held=held,
        why=tuple(str(w) for w in why[held]),
        sigmas=sigmas,
        condition=condition,
        observability=observability,
    )


def correlated_pairs(
    covariance: Array, limit: float = CORRELATION_LIMIT
) -> tuple[tuple[int, int, float], ...]:
    """Pairs (i, j, ρ) of parameters whose correlation exceeds ``limit`` in magnitude,
    strongest first; parameters with zero variance (held) are skipped."""
    v = np.diag(covariance)
    on = np.flatnonzero(v > 0)
    if len(on) < 2:
        return ()
    s = np.sqrt(v[on])
    rho = covariance[np.ix_(on, on)] / np.outer(s, s)
    i, j = np.triu_indices(len(on), 1)
    big = np.abs(rho[i, j]) > limit
    pairs = sorted(
        ((int(on[a]), int(on[b]), float(rho[a, b])) for a, b in zip(i[big], j[big], strict=True)),
        key=lambda t: -abs(t[2]),
    )
    return tuple(pairs)


def summary(
    ident: Identifiability, names: tuple[str, ...], n_poses: int, n_points: int
) -> dict[str, Any]:
    """The analysis as the refine summary records it (JSON): held parameters with why,
    rank, condition, observability, correlations above :data:`CORRELATION_LIMIT`, and how
    many poses the data had against how many the identified parameters need."""
    held = [
        {"name": names[k], "why": w, "sigmas_per_tolerance": float(ident.sigmas[k])}
        for k, w in zip(np.flatnonzero(ident.held), ident.why, strict=True)
    ]
    return {
        "n_params": len(names),
        "rank": ident.rank,
        "held": held,
        "condition": ident.condition,
        "observability_index": ident.observability,
        "correlated": [
            {"a": names[i], "b": names[j], "rho": rho} for i, j, rho in ident.correlated
        ],
        "n_poses": n_poses,
        "n_points": n_points,
        "poses_needed": poses_needed(ident.rank),
        "tolerance": {
            "deg": float(np.degrees(TOLERANCE_RAD)),
            "cm": TOLERANCE_CM,
            **(
                {"deg/cm": float(np.degrees(TOLERANCE_RAD_PER_CM))}
                if any(n.startswith("compliance.") for n in names)
                else {}
            ),
        },
    }


def poses_needed(n_params: int, coordinates_per_pose: int = 3) -> int:
    """Poses of one point each that ``n_params`` identified parameters need at least
    (:data:`COORDINATES_PER_PARAMETER` coordinates each)."""
    return int(np.ceil(COORDINATES_PER_PARAMETER * n_params / coordinates_per_pose))


def fit_identifiable(
    problem: Problem,
    x0: Array,
    units: tuple[str, ...],
    noise_stated: bool,
    n_points: int,
    x_warm: Array | None = None,
    f_scale_hint: float | None = None,
    tolerance: Array | None = None,
) -> tuple[Solution, Identifiability]:
    """Solve ``problem`` from ``x0`` (or from ``x_warm``, a nearer start, with the robust
    scale ``f_scale_hint`` of the fit it came from: :func:`pipeline.refine.solve.solve`)
    with the parameters the data cannot identify held at ``x0`` (module docstring); a
    problem with fewer residuals than :data:`COORDINATES_PER_PARAMETER` per identifiable
    parameter is refused. ``tolerance``: as :func:`analyse`'s."""
    begin = x0 if x_warm is None else np.asarray(x_warm, float)
    tol = tolerance_scale(units) if tolerance is None else tolerance
    n_res, R0 = jacobian_factor(problem, begin, lambda J: J * tol)
    n = R0.shape[1]
    need = COORDINATES_PER_PARAMETER * n
    if n_res < need:  # before the analysis: with so few rows every rank is the data's
        raise StageError(
            f"refine: {n_points} measured points ({n_res} coordinates) cannot identify the "
            f"{n} parameters of the chain",
            expected=f"at least {need} coordinates ({COORDINATES_PER_PARAMETER} per parameter): "
            f"{poses_needed(n)} poses of one target",
            got=f"{n_res}",
            fix="measure more poses, spread over the joint ranges",
        )
    start = analyse_factor(R0, noise_stated, n_points)
    begin = begin.copy()
    begin[start.held] = x0[start.held]
    solution = solve(replace(problem, held=start.held), begin, f_scale_hint=f_scale_hint)
    # The noise the data show, when above the stated one: a σ stated for the sensor alone
    # (a tracker's 0.008 mm) leaves out what the chain cannot model (a robot's 0.5 mm),
    # and a parameter below that scatter is fitted to it (UR10 Series C: joint 6's
    # direction fitted to 6.3° ± 5.7° at the stated σ).
    scale = solution.noise_scale if np.isfinite(solution.noise_scale) else 1.0
    _, R0 = jacobian_factor(
        problem, solution.x, lambda J: np.where(start.held, 0.0, (J / max(scale, 1.0)) * tol)
    )
    final = analyse_factor(R0, noise_stated, n_points, start.held)
    if (final.held & ~start.held).any():  # seen at the design, not at the solution
        warm = solution.x.copy()  # the rest from where the first fit left them
        warm[final.held] = x0[final.held]
        solution = solve(replace(problem, held=final.held), warm, f_scale_hint=solution.f_scale)
    # A parameter held at the start keeps the start's reason and pivot (its column is out
    # of the solution's analysis).
    why_start = dict(zip(np.flatnonzero(start.held), start.why, strict=True))
    why_final = dict(zip(np.flatnonzero(final.held), final.why, strict=True))
    why = tuple(why_start.get(k, why_final[k]) for k in np.flatnonzero(final.held))
    sigmas = np.where(start.held, start.sigmas, final.sigmas)
    return solution, replace(
        final, why=why, sigmas=sigmas, correlated=correlated_pairs(solution.covariance)
    )
