"""Held-out validation without ground truth: predict positions the fit did not see.

k-fold over the configurations of each joint sweep and of the pose set: fold ``f`` holds
out the steps ``≡ f (mod k)`` of every sweep (so each sweep's target point keeps most of
its observations), the refinement is refit without them, warm-started at the full fit, and
the refit chain predicts the held-out positions. A session with validation (``check``)
configurations uses those instead: the full fit never saw them, so no refit. The
non-geometric model's cross-validation (:mod:`pipeline.refine.model_choice`) holds out
contiguous blocks of each sweep's steps instead (:func:`fold_of_blocks`), each fold
refit by one Gauss-Newton step (:class:`StepRefit`).

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
from functools import cached_property

import numpy as np
import numpy.typing as npt
from scipy import sparse

from pipeline.optim.block import Linearization
from pipeline.optim.lm import rho
from pipeline.refine.kinematics import TOOL_POINT, ChainModel
from pipeline.refine.solve import Problem, chain_positions, chunks, linearize, normal_equations
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


def fold_of_blocks(
    sweep: npt.ArrayLike, step: npt.ArrayLike, k: int = FOLDS
) -> npt.NDArray[np.int64]:
    """Fold of each (sweep, step): each sweep's distinct steps in step order (the order
    they were measured in) cut into ``k`` contiguous blocks of nearly equal size, fold
    ``f`` the ``f``-th block of every sweep (a pose set is one sweep). A slow drift then
    cannot leak from a held-out block into the fit of its neighbours, as it does when
    the folds interleave (:func:`fold_of_steps`). The targets of one step share its
    fold."""
    rank, count = step_ranks(sweep, step)
    return rank * k // count  # rank r of n in block ⌊r k / n⌋


def step_ranks(
    sweep: npt.ArrayLike, step: npt.ArrayLike
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Per row (sweep, step): the rank of its step among its sweep's distinct steps in
    step order (the order they were measured in), and how many distinct steps that sweep
    has."""
    sweep, step = np.asarray(sweep), np.asarray(step, np.int64)
    rank = np.zeros(len(step), np.int64)
    count = np.ones(len(step), np.int64)
    for s in np.unique(sweep):
        on = sweep == s
        steps, rank[on] = np.unique(step[on], return_inverse=True)
        count[on] = len(steps)
    return rank, count


def _score(
    model: ChainModel, x: Array, cov: Array, sel: npt.NDArray[np.bool_],
    measured: Array, cov_m: Array, expected: bool = True,
) -> tuple[Array, Array, Array]:  # fmt: skip
    """Errors, expected errors and the measurement parts of the rows ``sel``; without
    ``expected`` the fit's part of the expected errors is left out (zero), and the chain's
    Jacobian is not formed. The chain is evaluated a chunk at a time
    (:func:`pipeline.refine.solve.chunks`)."""
    sub = model.observing(sel)
    fit_var = np.zeros(len(sub.link))
    if expected:
        for at, part in chunks(sub, keep=False):
            J = part.position_jacobian(x)
            fit_var[at] = np.einsum("kip,pq,kiq->k", J, cov, J)
    meas_var = np.trace(cov_m[sel], axis1=1, axis2=2)
    err = np.linalg.norm(measured[sel] - chain_positions(sub, x, keep=False), axis=1)
    return err, np.sqrt(fit_var + meas_var), np.sqrt(meas_var)


def kfold(
    model: ChainModel, sweep: npt.ArrayLike, step: npt.ArrayLike,
    measured: Array, cov_m: Array, refit: Refit, k: int = FOLDS,
    fold: npt.NDArray[np.int64] | None = None,
    measured_by: Callable[[npt.NDArray[np.bool_]], Array] | None = None,
    expected: bool = True,
) -> HeldOut:  # fmt: skip
    """Held-out errors of the joint sweeps' and the pose set's positions, k-fold (the
    targets of one pose share its fold: a pose is held out whole).

    ``model`` observes the block's K positions (``measured`` (K, 3), NaN rows not
    scored; their covariances ``cov_m`` (K, 3, 3)); ``refit(keep)`` fits without the
    positions ``~keep``; ``fold`` (K,): each position's fold in ``0..k−1``, by default
    :func:`fold_of_steps`; ``measured_by(keep)``: the positions measured by the refit's
    own block parameters, when the block calibrates its sensor (else ``measured``);
    ``expected``: whether the expected errors count the refit's covariance (else only the
    measurements', :func:`_score`). A ``refit`` with a ``prepare(keeps)`` (a
    :class:`StepRefit`) is handed every fold's kept positions first.
    """
    fold = fold_of_steps(step, k) if fold is None else np.asarray(fold, np.int64)
    sweep = np.asarray(sweep)
    joint = ((sweep >= 1) | (sweep == POSES_SWEEP)) & np.isfinite(measured).all(axis=1)
    helds = [(f, joint & (fold == f)) for f in range(k)]
    helds = [(f, held) for f, held in helds if held.any()]
    prepare = getattr(refit, "prepare", None)
    if prepare is not None:
        prepare([~held for _, held in helds])
    out: list[tuple[np.ndarray, ...]] = []
    for f, held in helds:
        x, cov = refit(~held)
        m = measured if measured_by is None else measured_by(~held)
        idx = np.flatnonzero(held)
        scored = _score(model, x, cov, held, m, cov_m, expected)
        out.append((idx, np.full(len(idx), f), *scored))
    return _held_out(out)


def fold_mse(held: HeldOut, k: int = FOLDS) -> Array:
    """Per fold ``0..k−1``, the mean squared held-out error (cm²); NaN for a fold with no
    held-out position."""
    n = np.bincount(held.fold, minlength=k)[:k]
    sse = np.bincount(held.fold, held.error_cm**2, minlength=k)[:k]
    return np.where(n > 0, sse / np.maximum(n, 1), np.nan)


def measured_positions(lin: Linearization, predicted: Array, w: Array | None = None) -> Array:
    """The position (K, 3) each key's rows measure: one Gauss-Newton step of the position
    alone from ``predicted`` (where the model puts it, at which ``lin`` linearizes the
    block), ``p − (Σ w d_p d_pᵀ)⁻¹ Σ w d_p r`` over its rows (robust weights ``w``).
    The rows of a measured position are linear in it (``r = L⁻¹ (p − m)``): the step
    gives ``m`` itself. Raw ranges give the position the block's sensor parameters
    triangulate, to second order in the residuals. NaN where the rows do not fix a point
    (fewer than three independent ranges, or none)."""
    H, fixed = position_information(lin, len(predicted), w)
    on = lin.pos >= 0
    key, d_p, r = lin.pos[on], lin.d_p[on], lin.r[on]
    wk = np.ones(len(r)) if w is None else w[on]
    g = np.stack([np.bincount(key, wk * d_p[:, i] * r, len(predicted)) for i in range(3)], 1)
    out = np.full((len(predicted), 3), np.nan)
    out[fixed] = predicted[fixed] - np.linalg.solve(H[fixed], g[fixed][..., None])[..., 0]
    return out


def position_information(
    lin: Linearization, K: int, w: Array | None = None
) -> tuple[Array, npt.NDArray[np.bool_]]:
    """Each of the ``K`` keys' information about its position (K, 3, 3), ``Σ w d_p d_pᵀ``
    over its (whitened) rows, and whether the rows fix the point (K,): the inverse is the
    covariance of :func:`measured_positions`' position, in the rows' noise units."""
    on = lin.pos >= 0
    key, d_p = lin.pos[on], lin.d_p[on]
    wk = np.ones(len(key)) if w is None else w[on]
    H = np.zeros((K, 3, 3))
    for i in range(3):
        for j in range(i, 3):
            H[:, i, j] = H[:, j, i] = np.bincount(key, wk * d_p[:, i] * d_p[:, j], K)
    lam = np.linalg.eigvalsh(H)
    # 1e-10: a rank-deficient H (two ranges, or none) leaves its smallest eigenvalue at
    # round-off of the largest; three microphones' ranges are 1e-3 to 1 of it
    return H, lam[:, 0] > 1e-10 * np.maximum(lam[:, -1], 1e-300)


@dataclass(frozen=True)
class StepRefit:
    """A :data:`Refit` of ``problem``: one Gauss-Newton step from its fit ``x_hat`` on the
    rows of the positions kept, robust weights at ``x_hat`` (at ``problem.f_scale``): the
    kinematic part of the step and its covariance ``(Jᵀ W J)⁺ · noise_var`` (as the solver
    scales its covariance). The block is linearized once, at ``x_hat``; each fold's normal
    equations are the solver's structured products
    (:func:`pipeline.refine.solve.normal_equations`) of that linearization with the held-out
    rows at weight zero, formed once (``∂p/∂θ`` and the rows' pattern): the dense ``J``
    (rows × parameters, whose speed-spline columns grow with the session's length) took
    13 s at 1,600 points per sweep. On a default Puma session its held-out RMS equals
    the full refit's to 0.1 % (0.02319 vs 0.02317 cm), at ~0.05 s a fold instead of
    ~2.7 s. Parameters ``problem.held`` stay where the fit held them."""

    problem: Problem
    x_hat: Array
    noise_var: float

    def __post_init__(self) -> None:
        full = dataclasses.replace(self.problem, keep=None)
        lin = linearize(full, self.x_hat)
        w = rho(full.loss, (lin.r / full.f_scale) ** 2)[1]  # the solver's robust weights
        normal = normal_equations(full, self.x_hat, lin)
        object.__setattr__(self, "_at_x_hat", (full, lin, w, normal))
        # each fold's step, by its kept positions: the holdout stage asks for a fold's step
        # for its chain, its expected error and its measured positions
        object.__setattr__(self, "_steps", {})

    def prepare(self, keeps: list[npt.NDArray[np.bool_]]) -> None:
        """The steps of every fold's kept positions ``keeps``, their normal equations
        formed in one pass (:meth:`pipeline.refine.solve.NormalEquations.many`: past
        :data:`~pipeline.refine.solve.CHUNK` positions the chain's Jacobian is formed
        anew at each pass)."""
        steps = self._steps  # type: ignore[attr-defined]
        todo = {self._key(keep): keep for keep in keeps if self._key(keep) not in steps}
        _, _, _, normal = self._at_x_hat  # type: ignore[attr-defined]
        products = normal.many([self._weights(keep) for keep in todo.values()])
        for key, (A, g) in zip(todo, products, strict=True):
            steps[key] = self._solved(A, g)

    @staticmethod
    def _key(keep: npt.NDArray[np.bool_]) -> bytes:
        return np.packbits(keep).tobytes() + len(keep).to_bytes(8, "little")

    def _weights(self, keep: npt.NDArray[np.bool_]) -> Array:
        """The robust weights at ``x_hat``, zero on the rows of the positions ``~keep`` (a
        row of weight zero is out of the fit)."""
        _, lin, w, _ = self._at_x_hat  # type: ignore[attr-defined]
        kept = (lin.pos < 0) | keep[np.maximum(lin.pos, 0)]  # as kept_rows keeps them
        return np.where(kept, w, 0.0)

    def step(self, keep: npt.NDArray[np.bool_]) -> tuple[Array, Array]:
        """The whole step's ``x`` (kinematics and block) without the positions ``~keep``,
        and ``(Jᵀ W J)⁺`` (unscaled)."""
        key = self._key(keep)
        steps = self._steps  # type: ignore[attr-defined]
        if key not in steps:
            normal = self._at_x_hat[3]  # type: ignore[attr-defined]
            steps[key] = self._solved(*normal(self._weights(keep)))
        return steps[key]  # type: ignore[no-any-return]

    def _solved(self, A: Array, g: Array) -> tuple[Array, Array]:
        """The step and ``(Jᵀ W J)⁺`` of the normal equations ``A``, ``g``."""
        full = self._at_x_hat[0]  # type: ignore[attr-defined]
        free = np.ones(len(g), bool) if full.held is None else ~full.held[: len(g)]
        N = np.zeros_like(A)  # held parameters (not identifiable) stay where the fit held them
        N[np.ix_(free, free)] = np.linalg.pinv(A[np.ix_(free, free)])
        x = self.x_hat.copy()
        x[: len(g)] -= N @ g
        return x, N

    def __call__(self, keep: npt.NDArray[np.bool_]) -> tuple[Array, Array]:
        x, N = self.step(keep)
        n = self.problem.model.n_params
        return x[:n], (N * self.noise_var)[:n, :n]

    @cached_property
    def _predicted(self) -> Array:
        """The chain's positions (K, 3) at ``x_hat``."""
        full = self._at_x_hat[0]  # type: ignore[attr-defined]
        return chain_positions(full.model, self.x_hat[: full.n_kin])

    @cached_property
    def measured(self) -> Array:
        """The positions (K, 3) the block measures with its own parameters at ``x_hat``
        (:func:`measured_positions`): for a block of positions, its measured positions;
        for raw ranges, the positions the fitted sensor's ranges put there."""
        _, lin, w, _ = self._at_x_hat  # type: ignore[attr-defined]
        return measured_positions(lin, self._predicted, w)

    @property
    def measured_covariance(self) -> Array:
        """The covariances (K, 3, 3) of :attr:`measured` (and of :meth:`measured_without`,
        whose rows keep their derivatives), ``(Σ w d_p d_pᵀ)⁻¹ · noise_var``; NaN where the
        rows do not fix the point."""
        full, lin, w, _ = self._at_x_hat  # type: ignore[attr-defined]
        H, fixed = position_information(lin, len(full.model.link), w)
        out = np.full(H.shape, np.nan)
        out[fixed] = np.linalg.inv(H[fixed]) * self.noise_var
        return out

    def difference_variance(self, keep: npt.NDArray[np.bool_]) -> Array:
        """Per position (K,), the variance (cm²) of :meth:`measured_without` ``(keep)``
        minus the step's chain there, from the step's parameters alone (chain and
        sensor together, ``A N Aᵀ · noise_var`` with ``A = [−∂p/∂θ, ∂m/∂b]``): a sensor
        frame the fold fits moves its chain and its measured positions alike, which the
        chain's covariance alone counts as error."""
        A = self._difference_jacobian
        _, N = self.step(keep)
        return np.einsum("kip,pq,kiq->k", A, N[: A.shape[2], : A.shape[2]], A) * self.noise_var

    @cached_property
    def _difference_jacobian(self) -> Array:
        """``A = [−∂p/∂θ, ∂m/∂b]`` (K, 3, n + B) at ``x_hat``, the same for every fold:
        ``∂m/∂b = −H⁻¹ Σ w d_p d_xᵀ`` per key (:func:`measured_positions`' step, ``H``
        :func:`position_information`)."""
        full, lin, w, _ = self._at_x_hat  # type: ignore[attr-defined]
        n, K = full.n_kin, len(full.model.link)
        H, fixed = position_information(lin, K, w)
        on = lin.pos >= 0
        rows = sparse.csr_array((w[on], (lin.pos[on], np.flatnonzero(on))), (K, len(lin.r)))
        d_x = sparse.csr_array(lin.d_x)
        S = np.stack([np.asarray((rows @ d_x.multiply(lin.d_p[:, [i]])).todense()) for i in
                      range(3)], 1)  # (K, 3, B): Σ w d_p d_xᵀ per key  # fmt: skip
        dm = np.zeros_like(S)
        dm[fixed] = -np.linalg.solve(H[fixed], S[fixed])
        return np.concatenate([-full.model.position_jacobian(self.x_hat[:n]), dm], axis=2)

    def measured_without(self, keep: npt.NDArray[np.bool_]) -> Array:
        """:attr:`measured` with the block's own parameters of the step without the
        positions ``~keep``: the chain and the sensor it is fitted with (its frame, its
        speed of sound) move together when a fold is left out, so the fold's chain is
        judged by the fold's sensor. The residuals move by ``d_x δb`` (linear); for a block
        of positions (no parameters of its own) the same as :attr:`measured`."""
        full, lin, w, _ = self._at_x_hat  # type: ignore[attr-defined]
        n = full.n_kin
        if n == full.n_params:  # no parameters of its own: the residuals do not move
            return self.measured
        x, _ = self.step(keep)
        moved = dataclasses.replace(lin, r=lin.r + lin.d_x @ (x[n:] - self.x_hat[n:]))
        return measured_positions(moved, self._predicted, w)


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
