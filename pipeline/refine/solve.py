"""The refinement's solve: one kinematic model and one measurement block, jointly.

The parameters are ``x = [θ_kin, x_block]`` (:class:`~pipeline.refine.kinematics.ChainModel`'s,
then the block's). The residuals are the block's whitened residuals at the chain's predicted
positions, and the Jacobian chains the two (:mod:`pipeline.optim.block`)::

    J = [ d_p[rows] · ∂p/∂θ[pos[rows]],  d_x ]

solved by Levenberg-Marquardt on the normal equations (:mod:`pipeline.optim.lm`: a robust
loss in whitened units by reweighting), formed from that structure without the dense ``J``
(:func:`normal_equations`). The covariance is Gauss-Newton at the solution,
``(JᵀWJ)⁻¹ · χ²/dof`` with ``W`` the robust weights and ``χ² = 2 · cost`` (the robust χ²;
the plain Σr² for rows within ``f_scale``).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, replace
from typing import overload

import numpy as np
import numpy.typing as npt
from scipy import sparse

from pipeline.errors import ArmsigError
from pipeline.optim.block import Array, Linearization, MeasurementBlock, dense
from pipeline.optim.lm import LOSSES, Normal, levenberg_marquardt
from pipeline.refine.kinematics import ChainModel
from pipeline.refine.orientation import OrientationRows
from pipeline.refine.points import PointBlock

#: Solver tolerances: at 1e-15 (relative cost, step and gradient) a noiseless session
#: converges to its rounding floor (audit ~1e-12 cm, well inside the 1e-6 cm acceptance);
#: a noisy one stops on the cost test within ~10 iterations.
TOLERANCE = 1e-15
#: Iteration cap (Jacobian evaluations); a session needs ~5-15.
MAX_EVALUATIONS = 200
#: A robust loss's scale is in σ of the stated noise. When the residuals' robust spread
#: (1.4826 · median |r|, whitened) exceeds this, the stated noise is understated at least
#: that much and the loss would down-weight most rows, not the outliers: the fit is redone
#: with ``f_scale`` times that spread (issue 27: the UR10's stated 0.05 mm against a
#: 0.5 mm robot left 40 % of Series C down-weighted, and Series B 0.85 mm instead of
#: 0.82). A session whose noise is stated right has a spread near 1 and is unchanged.
UNDERSTATED_NOISE = 2.0
#: The recorded-sensor χ² re-solves the kinematics only, warm-started at the solution:
#: ~3 iterations; capped so that a poorly recorded sensor cannot double the stage's time.
RECORDED_EVALUATIONS = 10
#: Observations per chunk when the chain is evaluated on many (issue 45): its (k, n, 4, 4)
#: motion stacks and (k, 3, P) Jacobian formed a chunk at a time, never for a million
#: observations at once (the Jacobian alone 0.65-1.1 GB). A session of at most this many
#: observations is evaluated whole, as before. Chunks of 4,096 to 20,000 UR10 poses took
#: 0.12 s of CPU for 100,000 positions, and 0.35 s (4,096) to 0.49 s (20,000) for their
#: Jacobian, against 0.47 and 0.68 s whole (one run each, 2026-11-29).
CHUNK = 4_096
#: A fit of more positions than twice this (a point block's) first solves 1 in every
#: ``⌈K / PREFIT⌉`` of them, and goes on from that solution with all of them (issue 45):
#: the iterations from a far start cost a subsample's evaluations, and the whole data's
#: few more end at the same minimum (the solver's tolerance), not at the subsample's.
PREFIT = 20_000


@dataclass(frozen=True)
class Problem:
    """A kinematic model, its measurement block, and the robust loss (scipy's names).

    ``keep`` (K,) bool selects the block's positions in the fit (rows of the block that
    depend on no position are always kept); ``fixed_block`` holds the block's own
    parameters at their start values (the sensor as recorded); ``held`` (n_params,) bool
    holds those parameters at their start (the ones the data cannot identify:
    :mod:`pipeline.refine.identifiability`); ``orientation``: measured tool orientations,
    three rows each after the block's (:mod:`pipeline.refine.orientation`).
    """

    model: ChainModel
    block: MeasurementBlock
    loss: str = "soft_l1"
    f_scale: float = 3.0
    keep: npt.NDArray[np.bool_] | None = None
    fixed_block: bool = False
    held: npt.NDArray[np.bool_] | None = None
    orientation: OrientationRows | None = None

    @property
    def n_kin(self) -> int:
        return self.model.n_params

    @property
    def n_params(self) -> int:
        return self.model.n_params + len(self.block.x0)


@dataclass(frozen=True)
class Solution:
    """The solver's result and summary (Ceres style: why it stopped is part of it)."""

    x: Array
    covariance: Array  # (P, P), χ²/dof-scaled
    chi2: float
    dof: int
    n_residuals: int
    iterations: int
    status: str
    message: str
    down_weighted: int
    f_scale: float = float("nan")  # the robust loss's scale used (UNDERSTATED_NOISE)

    @property
    def sigma(self) -> Array:
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))

    @property
    def noise_scale(self) -> float:
        return float(np.sqrt(self.chi2 / self.dof)) if self.dof > 0 else float("nan")


def chunks(model: ChainModel, keep: bool = True) -> Sequence[tuple[slice, ChainModel]]:
    """The observations of ``model`` in chunks of at most :data:`CHUNK`: each chunk's
    slice and the model observing it (``model`` itself when one chunk holds them all).
    With ``keep`` the chunks of the last model so asked for are kept (a fit evaluates
    its model again and again; its chunks' regressors are formed once); without, each
    chunk's model is formed when it is reached and is gone when the loop moves on (a
    list of them all held every chunk's regressor and readings' sines at once: ~1 GB at a
    million observations, issue 45)."""
    K = len(model.link)
    if K <= CHUNK:
        return [(slice(0, K), model)]
    if _CHUNKED and _CHUNKED[0][0] is model:
        return _CHUNKED[0][1]
    if not keep:
        return _Chunks(model, K)
    out = [_Chunks(model, K)[k] for k in range(-(-K // CHUNK))]
    _CHUNKED[:] = [(model, out)]
    return out


@dataclass(frozen=True)
class _Chunks(Sequence[tuple[slice, ChainModel]]):
    """:func:`chunks` formed one at a time, as they are reached."""

    model: ChainModel
    K: int

    def __len__(self) -> int:
        return -(-self.K // CHUNK)

    @overload
    def __getitem__(self, k: int) -> tuple[slice, ChainModel]: ...
    @overload
    def __getitem__(self, k: slice) -> Sequence[tuple[slice, ChainModel]]: ...
    def __getitem__(
        self, k: int | slice
    ) -> tuple[slice, ChainModel] | Sequence[tuple[slice, ChainModel]]:
        if isinstance(k, slice):
            return [self[i] for i in range(*k.indices(len(self)))]
        if not -len(self) <= k < len(self):
            raise IndexError(k)
        s = (k % len(self)) * CHUNK
        at = slice(s, min(s + CHUNK, self.K))
        return at, self.model.observing(np.arange(at.start, at.stop))


_CHUNKED: list[tuple[ChainModel, list[tuple[slice, ChainModel]]]] = []


def release_chunks() -> None:
    """Forget the kept chunks (:func:`chunks`): a stage that fitted calls it when done, so
    that its last model's chunks (their regressors: ~1 kB an observation with the
    non-geometric terms) do not stay through the stages after it."""
    _CHUNKED.clear()


def chain_positions(model: ChainModel, kin: Array, keep: bool = True) -> Array:
    """:meth:`ChainModel.positions` (K, 3) at ``kin``, a chunk at a time (:func:`chunks`,
    ``keep`` as there): bit for bit the same (each observation's product is its own)."""
    parts = chunks(model, keep)
    if len(parts) == 1:
        return model.positions(kin)
    out = np.empty((len(model.link), 3))
    for at, sub in parts:
        out[at] = sub.positions(kin)
    return out


def linearize(problem: Problem, x: Array) -> Linearization:
    """The block's linearization at ``x`` (and the measured orientations' rows after it),
    on the rows ``problem.keep`` leaves in the fit."""
    kin, own = x[: problem.n_kin], x[problem.n_kin :]
    pose = getattr(problem.block, "linearize_pose", None)  # a block that sees the tool's pose
    if pose is not None:  # (a camera: pipeline.refine.camera_block)
        lin = pose(problem.model, kin, own)
    else:
        lin = problem.block.linearize(chain_positions(problem.model, kin), own)
    if problem.orientation is not None:
        lin = _with_orientation(lin, problem, x)
    return lin if problem.keep is None else kept_rows(lin, problem.keep)


def _with_orientation(lin: Linearization, problem: Problem, x: Array) -> Linearization:
    """``lin`` and the orientation rows of ``problem`` after it (``d_theta`` of every row)."""
    assert problem.orientation is not None
    n_kin = problem.n_kin
    r_o, d_o = problem.orientation.linearize(problem.model, x[:n_kin])
    m, n_x = len(r_o), lin.d_x.shape[1]
    zeros_x = np.zeros((m, n_x))
    d_x = (
        np.vstack([lin.d_x, zeros_x])
        if isinstance(lin.d_x, np.ndarray)
        else sparse.csr_array(sparse.vstack([lin.d_x, sparse.csr_array(zeros_x)]))
    )
    return Linearization(
        r=np.concatenate([lin.r, r_o]),
        pos=np.concatenate([lin.pos, np.repeat(problem.orientation.index, 3)]),
        d_p=np.vstack([lin.d_p, np.zeros((m, 3))]),
        d_x=d_x,
        d_x_groups=lin.d_x_groups,
        d_theta=np.vstack([np.zeros((len(lin.r), n_kin)), d_o]),
    )


def kept_rows(lin: Linearization, keep: npt.NDArray[np.bool_]) -> Linearization:
    """The rows of ``lin`` on the positions ``keep`` (K,) leaves, and every row of no
    position (the block's own: rods, priors)."""
    rows = np.flatnonzero((lin.pos < 0) | keep[np.maximum(lin.pos, 0)])
    if len(rows) == len(lin.r):
        return lin
    return Linearization(
        r=lin.r[rows],
        pos=lin.pos[rows],
        d_p=lin.d_p[rows],
        d_x=lin.d_x[rows],
        d_theta=None if lin.d_theta is None else lin.d_theta[rows],
    )


def residuals_and_jacobian(problem: Problem, x: Array) -> tuple[Array, Array]:
    """The whitened residuals (R,) and the dense ``∂r/∂x`` (R, n_params) at ``x`` from one
    linearization of the block, per the module docstring."""
    lin = linearize(problem, x)
    dpdx = problem.model.position_jacobian(x[: problem.n_kin])  # (K, 3, n_kin)
    J = np.zeros((len(lin.r), problem.n_params))
    on = lin.pos >= 0
    J[on, : problem.n_kin] = np.einsum("ri,rij->rj", lin.d_p[on], dpdx[lin.pos[on]])
    if lin.d_theta is not None:
        J[:, : problem.n_kin] += lin.d_theta
    J[:, problem.n_kin :] = dense(lin.d_x)
    return lin.r, J


def jacobian_factor(
    problem: Problem, x: Array, columns: Callable[[Array], Array]
) -> tuple[int, Array]:
    """The number of residuals at ``x`` and ``R`` (min(R, P), P) of the QR ``columns(J) =
    Q R`` of the whitened Jacobian ``J`` (:func:`residuals_and_jacobian`), ``columns``
    acting on its rows (a column scaling). Past :data:`CHUNK` observations ``J`` is never
    formed whole: ``R`` is that of the chunks' ``R``s stacked with each next chunk's rows
    (TSQR), equal to the whole ``J``'s up to the rows' signs and rounding."""
    parts = chunks(problem.model)
    if len(parts) == 1:
        r, J = residuals_and_jacobian(problem, x)
        return len(r), np.asarray(np.linalg.qr(columns(J), mode="r"))
    lin = linearize(problem, x)
    n_kin, kin = problem.n_kin, x[: problem.n_kin]
    order = np.argsort(lin.pos, kind="stable")
    bounds = np.searchsorted(lin.pos[order], [0, *(at.stop for at, _ in parts)])

    def rows_of(rows: npt.NDArray[np.int64], kin_part: Array | None) -> Array:
        J = np.zeros((len(rows), problem.n_params))
        if kin_part is not None:
            J[:, :n_kin] = kin_part
        if lin.d_theta is not None:
            J[:, :n_kin] += lin.d_theta[rows]
        J[:, n_kin:] = dense(lin.d_x[rows])
        return columns(J)

    R = rows_of(order[: bounds[0]], None)  # the rows of no position (rods, priors)
    for (at, sub), lo, hi in zip(parts, bounds[:-1], bounds[1:], strict=True):
        rows = order[lo:hi]
        dpdx = sub.position_jacobian(kin)  # (k, 3, n_kin)
        kin_part = np.einsum("ri,rij->rj", lin.d_p[rows], dpdx[lin.pos[rows] - at.start])
        R = r_with_rows(R, rows_of(rows, kin_part))
    return len(lin.r), R


def r_with_rows(R: Array, rows: Array) -> Array:
    """One step of a TSQR: the ``R`` of a QR of the rows ``R`` stands for, with ``rows``
    below them (the same ``R`` up to the rows' signs and rounding)."""
    return np.asarray(np.linalg.qr(np.vstack([R, rows]), mode="r"))


def _block_information(lin: Linearization, w: Array) -> Array:
    """``XᵀWX`` of the block's ``d_x`` (``X``): group by group when the block names its
    rows' column patterns (:class:`~pipeline.optim.block.Linearization`), else one
    product of ``X``, sparse where ``X`` is."""
    sw = np.sqrt(w)
    if isinstance(lin.d_x, np.ndarray):
        Xs = lin.d_x * sw[:, None]
        return np.asarray(Xs.T @ Xs)
    if lin.d_x_groups is None:  # a sparse product: linear in the rows, as the groups are
        Xs = sparse.csr_array(lin.d_x.multiply(sw[:, None]))
        return dense(Xs.T @ Xs)
    data = lin.d_x.data
    n = lin.d_x.shape[1]
    out = np.zeros((n, n))
    for rows, entries, cols in lin.d_x_groups:
        V = data[entries] * sw[rows, None]
        out[np.ix_(cols, cols)] += V.T @ V
    return out


class NormalEquations:
    """``w -> (JᵀWJ, JᵀWr)`` of one linearization (:func:`normal_equations`); :meth:`many`
    forms them for several weight vectors in one pass over the chain's chunks."""

    def __init__(self, problem: Problem, x: Array, lin: Linearization) -> None:
        self.problem, self.x, self.lin = problem, x, lin
        self.n = problem.n_kin if problem.fixed_block else problem.n_params
        self.on = np.flatnonzero(lin.pos >= 0)
        self._Dt: sparse.csr_array | None = None
        self._P: Array | None = None  # ∂p/∂θ (3K, n_kin), kept when one chunk holds it

    def __call__(self, w: Array) -> tuple[Array, Array]:
        return self.many([w])[0]

    def _transposed_rows(self) -> sparse.csr_array:
        """``Dᵀ`` (3K, R): row 3k + i holds ``d_p[:, i]`` of k's rows."""
        if self._Dt is None:
            K, lin, on = len(self.problem.model.link), self.lin, self.on
            rows = (3 * lin.pos[on][:, None] + np.arange(3)).ravel()
            self._Dt = sparse.csr_array(
                (lin.d_p[on].ravel(), (rows, np.repeat(on, 3))), (3 * K, len(lin.r))
            )
        return self._Dt

    def many(self, ws: list[Array]) -> list[tuple[Array, Array]]:
        """:meth:`__call__` of each of ``ws``, ``∂p/∂θ`` formed once for all of them."""
        problem, lin, on, n = self.problem, self.lin, self.on, self.n
        n_kin, K = problem.n_kin, len(problem.model.link)
        key, d_p = lin.pos[on], lin.d_p[on]
        Dt = self._transposed_rows()
        out: list[tuple[Array, Array]] = []
        per_w = []  # per w: H (K, 3, 3), DᵀWr (3K,), DᵀWT, DᵀWX (3K, ·) or None
        for w in ws:
            wk = w[on]
            H = np.empty((K, 3, 3))  # Σ over k's rows of w d_p d_pᵀ
            for i in range(3):
                for j in range(i, 3):
                    H[:, i, j] = H[:, j, i] = np.bincount(key, wk * d_p[:, i] * d_p[:, j], K)
            DtW = sparse.csr_array((Dt.data * w[Dt.indices], Dt.indices, Dt.indptr), Dt.shape)
            DtWT = None if lin.d_theta is None else np.asarray(DtW @ lin.d_theta)
            DtWX = dense(DtW @ lin.d_x) if n > n_kin else None
            per_w.append((H, DtW @ lin.r, DtWT, DtWX))
        sums: list[list[Array | None]] = [[None, None, None, None] for _ in ws]
        for at, P in self._jacobians():
            rows, k = slice(3 * at.start, 3 * at.stop), at.stop - at.start
            for (H, v, DtWT, DtWX), acc in zip(per_w, sums, strict=True):
                terms = (
                    P.T @ (H[at] @ P.reshape(k, 3, n_kin)).reshape(3 * k, n_kin),
                    P.T @ v[rows],
                    None if DtWT is None else P.T @ DtWT[rows],
                    None if DtWX is None else P.T @ DtWX[rows],
                )
                for m, t in enumerate(terms):
                    if t is not None:
                        before = acc[m]
                        acc[m] = t if before is None else before + t
        for w, (Akk, gk, C, Akx) in zip(ws, sums, strict=True):
            A = np.empty((n, n))
            g = np.empty(n)
            A[:n_kin, :n_kin] = Akk
            g[:n_kin] = gk
            if lin.d_theta is not None and C is not None:  # rows of the kinematics directly
                T = lin.d_theta  # (orientations)
                A[:n_kin, :n_kin] += T.T @ (w[:, None] * T)
                g[:n_kin] += T.T @ (w * lin.r)
                # rows of both a position and the kinematics directly (a camera's pixels):
                # the cross terms Pᵀ DᵀW T (zero when no row has both, as for orientations)
                A[:n_kin, :n_kin] += C + C.T
            if n > n_kin:
                A[:n_kin, n_kin:] = Akx
                if lin.d_theta is not None:  # zero while those rows have no block derivative
                    A[:n_kin, n_kin:] += lin.d_theta.T @ dense(
                        sparse.csr_array(lin.d_x).multiply(w[:, None])
                    )
                A[n_kin:, :n_kin] = A[:n_kin, n_kin:].T
                A[n_kin:, n_kin:] = _block_information(lin, w)
                g[n_kin:] = lin.d_x.T @ (w * lin.r)  # sparse where the block's is
            out.append((A, g))
        return out

    def _jacobians(self) -> Iterable[tuple[slice, Array]]:
        """Each chunk's slice of the observations and its ``∂p/∂θ`` (3k, n_kin), the one
        chunk's kept; more chunks are formed anew at each pass (never all at once)."""
        n_kin, kin = self.problem.n_kin, self.x[: self.problem.n_kin]
        parts = chunks(self.problem.model)
        if len(parts) == 1:
            if self._P is None:
                self._P = parts[0][1].position_jacobian(kin).reshape(-1, n_kin)
            return [(parts[0][0], self._P)]
        return ((at, sub.position_jacobian(kin).reshape(-1, n_kin)) for at, sub in parts)


def normal_equations(problem: Problem, x: Array, lin: Linearization) -> NormalEquations:
    """``w -> (JᵀWJ, JᵀWr)`` of ``lin`` (at ``x``) without forming ``J`` (R, P); over the
    kinematic parameters only when ``problem.fixed_block``.

    With ``D`` the rows' ``d_p`` placed at their positions (R, 3K, sparse), ``P`` the
    chain's ``∂p/∂θ`` (3K, n_kin) and ``X`` the block's ``d_x`` (R, n_x)::

        JᵀWJ = [[Pᵀ (DᵀWD) P,  Pᵀ (DᵀWX)],      JᵀWr = [Pᵀ (DᵀWr),
                [   ·ᵀ      ,   XᵀWX    ]]               XᵀWr     ]

    ``DᵀWD`` is block-diagonal (3 × 3 per position, summed by key), so the kinematic part
    costs ~R·9 + 3K·n_kin² instead of R·P² (robot3: 48,115 ranges on 601 positions).
    ``DᵀWX`` is a sparse product when ``X`` is sparse: never the dense R × n_x, whose
    columns (the speed spline's) grow with the session's length, so a dense ``X`` made
    the cost grow as points² (refine 25.7 s at 1,600 points per sweep, 2.9 s at 400).
    ``∂p/∂θ`` and ``D`` are formed at the first call only; past :data:`CHUNK`
    observations ``∂p/∂θ`` is formed a chunk at a time at each call and its products
    summed (issue 45: a million poses' would be 0.6-1 GB), and
    :meth:`NormalEquations.many` forms the products of several weightings (a k-fold's
    folds) in one pass.
    """
    return NormalEquations(problem, x, lin)


def solve(
    problem: Problem,
    x_start: Array,
    max_evaluations: int = MAX_EVALUATIONS,
    f_scale_hint: float | None = None,
) -> Solution:
    """Fit ``problem`` from ``x_start`` (module docstring). ``f_scale_hint``: the robust
    scale a fit of nearly the same problem ended with (:data:`UNDERSTATED_NOISE`): the
    fit starts at it and is redone only when its own residuals' spread asks for a scale
    10 % or more away (a warm refit then skips the first pass at ``problem.f_scale``)."""
    if problem.loss not in LOSSES:
        raise ArmsigError(
            f"unknown loss {problem.loss!r}", expected=", ".join(LOSSES), fix="soft_l1"
        )
    prefit = _subsampled(problem)
    if prefit is not None:  # PREFIT: the iterations from afar on a subsample
        x_start = solve(prefit, x_start, max_evaluations, f_scale_hint).x
    free = np.ones(problem.n_params, bool)
    if problem.fixed_block:
        free[problem.n_kin :] = False
    if problem.held is not None:
        free &= ~problem.held
    x_fixed = np.asarray(x_start, float).copy()

    def full(z: Array) -> Array:
        x = x_fixed.copy()
        x[free] = z
        return x

    n_normal = problem.n_kin if problem.fixed_block else problem.n_params
    on = free[:n_normal]  # the normal equations' parameters that are free

    def fun(z: Array) -> tuple[Array, Normal]:
        x = full(z)
        lin = linearize(problem, x)
        normal = normal_equations(problem, x, lin)
        if on.all():
            return lin.r, normal

        def free_normal(w: Array) -> tuple[Array, Array]:  # over the free parameters
            A, g = normal(w)
            return A[np.ix_(on, on)], g[on]

        return lin.r, free_normal

    start = fun(x_fixed[free])
    r0 = start[0]
    if not np.isfinite(r0).all():
        raise ArmsigError(
            "refinement: the start gives non-finite residuals",
            expected="finite measurements and a finite start",
            got=f"{int((~np.isfinite(r0)).sum())} of {len(r0)} residuals NaN or inf",
            fix="check the positions table; --param refine.enabled=false skips the refinement",
        )
    f_scale = problem.f_scale if f_scale_hint is None else f_scale_hint
    result = levenberg_marquardt(
        fun, x_fixed[free], problem.loss, f_scale, TOLERANCE, max_evaluations, start
    )
    spread = 1.4826 * float(np.median(np.abs(result.r))) if len(result.r) else 0.0
    wanted = problem.f_scale * spread if spread > UNDERSTATED_NOISE else problem.f_scale
    if problem.loss != "linear" and abs(wanted - f_scale) > 0.1 * f_scale:
        f_scale = wanted
        result = levenberg_marquardt(
            fun, result.x, problem.loss, f_scale, TOLERANCE, max_evaluations
        )
    x = full(result.x)
    n_res = len(result.r)
    dof = n_res - int(free.sum())
    chi2 = 2.0 * float(result.cost)
    cov = np.zeros((problem.n_params, problem.n_params))
    scale = chi2 / dof if dof > 0 else np.nan
    cov[np.ix_(free, free)] = np.linalg.pinv(result.information) * scale
    return Solution(
        x=x,
        covariance=cov,
        chi2=chi2,
        dof=dof,
        n_residuals=n_res,
        iterations=result.iterations,
        status="converged" if result.converged else "not converged",
        message=result.message,
        down_weighted=int((np.abs(result.r) > f_scale).sum()),
        f_scale=f_scale,
    )


def _subsampled(problem: Problem) -> Problem | None:
    """``problem`` on 1 in every ``⌈K / PREFIT⌉`` of its positions (:data:`PREFIT`), when
    it has more than twice that many and :func:`on_positions` can take them; else None."""
    K = len(problem.model.link)
    if K <= 2 * PREFIT or not takes_positions(problem):
        return None
    return on_positions(problem, np.arange(0, K, -(-K // PREFIT)))


def takes_positions(problem: Problem) -> bool:
    """Whether ``problem`` is one of positions a subset of which is a problem of its own
    (:func:`on_positions`): a block of positions without parameters of its own (a pose
    set's, a point sensor's), every position kept, no orientation rows."""
    block = problem.block
    simple = problem.keep is None and problem.orientation is None and not len(block.x0)
    return simple and isinstance(block, PointBlock)


def on_positions(problem: Problem, rows: npt.NDArray[np.int64]) -> Problem:
    """``problem`` observing only its positions ``rows`` (indices, in their order; a
    problem :func:`takes_positions` of)."""
    block = problem.block
    assert isinstance(block, PointBlock)  # takes_positions
    sub = PointBlock(block.keys.take(rows), block.measured[rows], block.whiten[rows])
    return replace(problem, model=problem.model.observing(rows), block=sub)


def recorded_chi2(problem: Problem, solution: Solution) -> float:
    """χ² with the block's own parameters held at their start (the sensor as recorded):
    a short second solve of the kinematics only, warm-started at the kinematics that the
    solution's covariance predicts for the recorded sensor (the Gauss-Newton step of the
    fixed-sensor problem from the solution, ``θ̂ + Σ_θb Σ_bb⁻¹ (b₀ − b̂)``; its Schur
    complement form ``−A_θθ⁻¹ A_θb (b₀ − b̂)``): ~3 iterations instead of ~8."""
    if len(problem.block.x0) == 0:
        return solution.chi2
    n = problem.n_kin
    x = solution.x.copy()
    x[n:] = problem.block.x0
    cov = solution.covariance
    if np.isfinite(cov).all():  # not when χ²/dof is undefined (no degree of freedom)
        x[:n] += cov[:n, n:] @ np.linalg.lstsq(cov[n:, n:], x[n:] - solution.x[n:], rcond=None)[0]
    return solve(replace(problem, fixed_block=True), x, RECORDED_EVALUATIONS).chi2


def refit(problem: Problem, keep_mask: npt.NDArray[np.bool_], x_start: Array) -> Solution:
    """The fit without the positions ``~keep_mask`` (K,) of the block, warm-started at
    ``x_start`` (the holdout's folds)."""
    return solve(replace(problem, keep=np.asarray(keep_mask, bool)), x_start)
