"""The sonic digitizer at the level of its raw slant ranges: a measurement block.

:class:`RangeBlock` implements :class:`pipeline.optim.block.MeasurementBlock` for a
sonic session (its ``ranges`` table and recorded geometry). Its rows, each whitened by
the range noise of :mod:`pipeline.sensor.noise` ((7.9) and the 0.01 cm rounding,
evaluated at the measured range):

- speed ratio to the digitizer's internal speed ``S*`` (B-3), linear in height,
  drifting in time: ``f(h, t) = a(t) + g·(h − h_ref)``, ``a`` a cubic B-spline in
  time (:mod:`pipeline.sensor.speed_spline`), ``h = position · up``;
- target sparker → microphone ``m`` (all four, D too)::

      s = L · ln(f_m / f_t) / (f_m − f_t) + b_m          # Eqs. (E.2)-(E.4)

  ``L = |p − mic_m|``, ``f_m = f(h_m, t)``, ``f_t = f(h_t, t)``; evaluated as
  ``L · φ(d) / f_t`` with ``d = (f_m − f_t)/f_t`` and ``φ(d) = log1p(d)/d``, as
  :func:`pipeline.sensor.compensation.line_of_sight_length` inverts it;
- rod sparker ``k`` → its microphone (1, 2 → B; 3, 4 → D), on a level line::

      s = d_k / f(h_mic, t) + b_mic                        # Eq. (E.1)

  ``d_k`` the recorded distance from sparker ``k`` to its microphone (the rod is
  rigid with the microphone; the calibrated rod length fixes the scale);
- priors (``pos = −1``): microphone coordinates about the recorded ones, biases
  about 0, ``g`` about the rods' value, ``a(t)`` about the rods' values (weak).

Parameters ``x`` (names in :attr:`RangeBlock.param_names`), in the *gauge frame*
of the recorded microphones (the (6.1) frame of
:class:`~pipeline.sensor.triangulation.Trilateration`: origin C, Y toward B, X in
the A-B-C plane on A's side, Z out of the wall):
``mic_A_x_cm, mic_A_y_cm, mic_B_y_cm, mic_D_x_cm, mic_D_y_cm, mic_D_z_cm``,
``bias_A_cm … bias_D_cm``, ``speed_knot_00 …`` (``a``'s coefficients) and
``speed_gradient_per_cm`` (``g``).

Gauge freedoms and how they are fixed:

- *Rigid motion of the sensor frame* (6): moving microphones and targets together
  changes no range; the refinement's base pose would absorb it. Fixed by holding C
  at the recorded C (3), B on the recorded C→B line (2) and A in the recorded
  A-B-C plane (1). Free: ``|CB|``, A in-plane, D.
- *Scale* (1): scaling all lengths and ``f`` together changes no time of flight.
  Fixed by the rods: their recorded lengths ``d_k`` (two per microphone, at
  different distances) give ``f`` and the bias at B and D.
- *Vertical*: ``up`` is the recorded geometry's (in-plane, perpendicular to C→A),
  held fixed; it only defines where ``g`` acts.
- *Reference height*: ``a(t)`` is ``f`` at ``h_ref``, the midpoint of the recorded
  heights of B and D (where the rods measure their mean, (E.5)); a choice of
  coordinates, not a freedom.

Left to the data (and bounded by the priors): the biases of A and C, which no rod
measures, against the speed and the microphone positions.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
import pyarrow as pa
from scipy import sparse

from pipeline.errors import ArmsigError
from pipeline.optim.block import Group, Linearization, MeasurementBlock
from pipeline.sensor.geometry import MICROPHONES, DigitizerGeometry
from pipeline.sensor.noise import range_sigma_cm
from pipeline.sensor.range_rows import RangeRows, check_cycle_order, range_rows, unique_rows
from pipeline.sensor.speed_spline import TimeSpline
from pipeline.sensor.triangulation import Trilateration

Array = npt.NDArray[np.float64]

#: (microphone, gauge-frame axis) of the six free microphone coordinates.
MIC_COORDS = ((0, 0), (0, 1), (1, 1), (3, 0), (3, 1), (3, 2))
N_GEO, N_BIAS = len(MIC_COORDS), len(MICROPHONES)
#: The target id of a sonic session's single target, as the positions table names it
#: (:data:`pipeline.stages.positions.SONIC_TARGET`; a stage module, which the sensor floor
#: does not import).
SONIC_TARGET = "sparker"
#: Below this |d| the derivative of φ(d) = log1p(d)/d comes from its series: the
#: closed form loses ~eps/|d| to cancellation (≤ 2e-14 relative above 1e-2); the
#: series' first omitted term, 13/14·d¹², is below 1e-24 there (≪ eps). Speeds in a lab
#: give |d| ≲ 3e-3 (a 2 °F difference along a line of sight).
_SERIES_D = 1e-2
_SERIES_TERMS = 12


@dataclass(frozen=True)
class RangeModelOptions:
    """Options of the range-level sensor model.

    Attributes
    ----------
    knot_spacing_s : float or None
        Time between the knots of ``a(t)`` (at most); None: chosen from the rods' speed
        ratios (:meth:`~pipeline.sensor.speed_spline.TimeSpline.chosen`: 120 s, halved
        down to 15 s while the rods ask for it: a drift of 8 min and more is followed
        exactly in a noiseless session, and a noisy session's slow drift keeps 120 s).
    mic_prior_sigma_cm : float
        Prior σ of each free microphone coordinate about the recorded one.
    bias_prior_sigma_cm : float
        Prior σ of each microphone's range bias about 0.
    gradient_prior_sigma_per_cm : float
        Prior σ of ``g`` about the rods' value: 1e-5 per cm is a 1.8 °F difference
        over 150 cm (the (B-4) bound), weak next to the rods' ~1e-7.
    speed_prior_sigma : float
        Prior σ of each coefficient of ``a(t)`` about the rods' fit: 0.01 spans the
        whole 65-75 °F of (B-5); it only keeps a knot no range reaches defined.
    """

    knot_spacing_s: float | None = None
    mic_prior_sigma_cm: float = 1.0
    bias_prior_sigma_cm: float = 1.0
    gradient_prior_sigma_per_cm: float = 1e-5
    speed_prior_sigma: float = 0.01

    def __post_init__(self) -> None:
        vals = {k: float(v) for k, v in self.__dict__.items() if v is not None}
        bad = {k: v for k, v in vals.items() if not (np.isfinite(v) and v > 0.0)}
        if bad:
            raise ArmsigError(
                "range model options must be positive",
                expected="knot_spacing_s (or None) and every prior σ > 0 and finite",
                got=", ".join(f"{k}={v}" for k, v in bad.items()),
                fix="pass positive values",
            )


def phi(d: Array) -> tuple[Array, Array]:
    """``φ(d) = log1p(d)/d`` (1 at 0) and its derivative, shape of ``d``."""
    lg = np.log1p(d)
    f = np.divide(lg, d, out=np.ones_like(d), where=d != 0.0)
    small = np.abs(d) < _SERIES_D
    dd = np.where(small, 1.0, d)
    df = (dd / (1.0 + dd) - np.log1p(dd)) / dd**2
    k = np.arange(_SERIES_TERMS, 0, -1, dtype=float)
    series = np.zeros_like(d)
    for kk in k:  # Σ_{k≥1} (−1)^k k d^(k−1) / (k+1), Horner
        series = series * d + (-1.0) ** kk * kk / (kk + 1.0)
    return f, np.where(small, series, df)


@dataclass(eq=False)  # not frozen: MeasurementBlock declares settable attributes
class RangeBlock:
    """Residuals of every raw slant range of a sonic session (see the module docstring).

    Attributes
    ----------
    keys : pyarrow.Table
        ``sweep`` (int32), ``step`` (int32), ``target`` (``"sparker"``), sorted.
    param_names, param_units : tuple of str
    x0 : ndarray, shape (n_params,)
        Recorded geometry, zero biases, ``a(t)`` and ``g`` from the rods.
    x_prior, sigma_prior : ndarray, shape (n_params,)
        Prior means and σ (every parameter has one).
    row_kind : ndarray of str, shape (R,)
        ``target``, ``rod`` or ``prior`` for each row of :meth:`linearize`.
    geometry : DigitizerGeometry
        As recorded.
    spline : TimeSpline
        The basis of ``a(t)``.
    h_ref_cm : float
        Height of ``a(t)``.
    """

    keys: pa.Table
    param_names: tuple[str, ...]
    param_units: tuple[str, ...]
    x0: Array
    x_prior: Array
    sigma_prior: Array
    row_kind: npt.NDArray[np.str_]
    geometry: DigitizerGeometry
    spline: TimeSpline
    h_ref_cm: float
    rows: RangeRows = field(repr=False)
    gauge_origin: Array = field(repr=False)
    gauge_axes: Array = field(repr=False)
    d_mic_d_geo: Array = field(repr=False)  # (4, 3, N_GEO) ∂mic/∂x_geo, sensor frame
    up: Array = field(repr=False)  # (3,) the recorded vertical
    t_spline: tuple[npt.NDArray[np.int64], Array] = field(repr=False)  # basis of target rows
    r_spline: tuple[npt.NDArray[np.int64], Array] = field(repr=False)  # basis of rod rows
    t_d_mic: Array = field(repr=False)  # (Rt, 3, N_GEO) ∂mic/∂x_geo of each target row
    t_w: Array = field(repr=False)  # 1/σ of target rows
    r_w: Array = field(repr=False)  # 1/σ of rod rows
    rod_d_cm: Array = field(repr=False)  # (Rr,) recorded d_k

    @property
    def n_params(self) -> int:
        return len(self.param_names)

    @property
    def slices(self) -> dict[str, slice]:
        """Parameter groups: ``mic``, ``bias``, ``speed``, ``gradient``."""
        n = self.spline.n_coef
        b = N_GEO + N_BIAS
        return {
            "mic": slice(0, N_GEO),
            "bias": slice(N_GEO, b),
            "speed": slice(b, b + n),
            "gradient": slice(b + n, b + n + 1),
        }

    def microphones(self, x: npt.ArrayLike) -> Array:
        """Microphones A-D (4, 3) in the sensor frame for parameters ``x``."""
        return np.asarray(self.gauge_origin + self.d_mic_d_geo @ np.asarray(x)[:N_GEO], float)

    def speed_ratio(self, h_cm: npt.ArrayLike, t_s: npt.ArrayLike, x: npt.ArrayLike) -> Array:
        """``f(h, t)`` at heights ``h_cm`` and times ``t_s`` (broadcast, 1-D) for ``x``."""
        sl, xx = self.slices, np.asarray(x, float)
        a = self.spline.design(np.atleast_1d(t_s)) @ xx[sl["speed"]]
        return np.asarray(a + xx[sl["gradient"]][0] * (np.asarray(h_cm, float) - self.h_ref_cm))

    def linearize(self, p: Array, x: Array) -> Linearization:
        """Whitened residuals and analytic derivatives at positions ``p`` (K, 3) and ``x``."""
        p, x = np.asarray(p, float), np.asarray(x, float)
        if p.shape != (self.keys.num_rows, 3) or x.shape != (self.n_params,):
            raise ArmsigError(
                "RangeBlock.linearize got arrays of the wrong shape",
                expected=f"p ({self.keys.num_rows}, 3) in keys order, x ({self.n_params},)",
                got=f"p {p.shape}, x {x.shape}",
                fix="pass one position per key and the block's parameter vector",
            )
        sl, rows, up = self.slices, self.rows, self.up
        coef = x[sl["speed"]]
        g = float(x[sl["gradient"]][0])
        mics = self.microphones(x)
        dh_mic = mics @ up - self.h_ref_cm  # (4,)
        bias = x[sl["bias"]]
        n, nt, nr = self.n_params, len(rows.t_pos), len(rows.r_mic)

        # Target rows, Eqs. (E.2)-(E.4).
        mi, w = rows.t_mic, self.t_w
        t_idx, t_val = self.t_spline
        a = np.einsum("ij,ij->i", t_val, coef[t_idx])
        dh_t = (p @ up - self.h_ref_cm)[rows.t_pos]
        f_t = a + g * dh_t
        d = g * (dh_mic[mi] - dh_t) / f_t  # (f_m − f_t) / f_t
        ph, dph = phi(d)
        # Lines of sight once per (position, microphone), not per echo (~20 repeats each).
        diff = (p[:, None, :] - mics[None]).reshape(-1, 3)
        line = np.sqrt(np.einsum("ij,ij->i", diff, diff))
        pair = rows.t_pos * len(mics) + mi
        length, u = line[pair], (diff / line[:, None])[pair]
        psi = ph / f_t  # s = L ψ(f_m, f_t) + b
        psi_m = dph / f_t**2  # ∂ψ/∂f_m
        psi_t = -(ph + (1.0 + d) * dph) / f_t**2  # ∂ψ/∂f_t
        r_t = w * (length * psi + bias[mi] - rows.t_s_cm)
        d_p = w[:, None] * (psi[:, None] * u + (length * psi_t * g)[:, None] * up)
        d_mic = w[:, None] * (-psi[:, None] * u + (length * psi_m * g)[:, None] * up)
        d_f = w * length  # times ∂ψ/∂f, ∂f/∂a_j = B_j(t)
        t_vals = np.concatenate(  # columns of _row_columns: mic, bias, speed, gradient
            [
                np.einsum("ij,ijk->ik", d_mic, self.t_d_mic),
                w[:, None],
                (d_f * (psi_m + psi_t))[:, None] * t_val,
                (d_f * (psi_m * dh_mic[mi] + psi_t * dh_t))[:, None],
            ],
            axis=1,
        )

        # Rod rows, Eq. (E.1).
        mr, wr = rows.r_mic, self.r_w
        r_idx, r_val = self.r_spline
        f_r = np.einsum("ij,ij->i", r_val, coef[r_idx]) + g * dh_mic[mr]
        r_r = wr * (self.rod_d_cm / f_r + bias[mr] - rows.r_s_cm)
        ds_df = -wr * self.rod_d_cm / f_r**2
        r_vals = np.concatenate(
            [
                (ds_df * g)[:, None] * (up @ self.d_mic_d_geo)[mr],
                wr[:, None],
                ds_df[:, None] * r_val,
                (ds_df * dh_mic[mr])[:, None],
            ],
            axis=1,
        )

        # Priors.
        r_p = (x - self.x_prior) / self.sigma_prior
        data = np.concatenate([t_vals.ravel(), r_vals.ravel(), 1.0 / self.sigma_prior])
        cols, indptr = self.d_x_pattern
        d_x = sparse.csr_array((data, cols, indptr), shape=(nt + nr + n, n))

        r = np.concatenate([r_t, r_r, r_p])
        pos = np.concatenate([rows.t_pos, np.full(nr + n, -1, np.int64)])
        d_p_all = np.zeros((len(r), 3))
        d_p_all[:nt] = d_p
        return Linearization(r=r, pos=pos, d_p=d_p_all, d_x=d_x, d_x_groups=self.d_x_groups)

    @cached_property
    def d_x_pattern(self) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
        """CSR column indices and row pointers of ``d_x`` (:meth:`linearize`): a target or
        rod row touches the six microphone coordinates, its microphone's bias, the
        ``DEGREE + 1`` speed coefficients not zero at its time and the gradient; a prior
        row its own parameter. Sorted, no repeats."""
        sl = self.slices
        mic = np.arange(N_GEO)

        def columns(m: npt.NDArray[np.int64], idx: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:
            k = len(m)
            return np.concatenate(
                [
                    np.broadcast_to(mic, (k, N_GEO)),
                    (N_GEO + m)[:, None],
                    sl["speed"].start + idx,
                    np.full((k, 1), sl["gradient"].start),
                ],
                axis=1,
            )

        t = columns(self.rows.t_mic, self.t_spline[0])
        r = columns(self.rows.r_mic, self.r_spline[0])
        cols = np.concatenate([t.ravel(), r.ravel(), np.arange(self.n_params)]).astype(np.int64)
        per_row = np.concatenate(
            [np.full(len(t) + len(r), t.shape[1]), np.ones(self.n_params, np.int64)]
        )
        return cols, np.concatenate([[0], np.cumsum(per_row)]).astype(np.int64)

    @cached_property
    def d_x_groups(self) -> tuple[Group, ...]:
        """``d_x``'s rows grouped by their columns (:class:`~pipeline.optim.block.
        Linearization`): ~6 per speed coefficient (a microphone's target rows, a rod's
        microphone), one per prior."""
        cols, indptr = self.d_x_pattern
        nnz = np.diff(indptr)
        out: list[Group] = []
        for m in np.unique(nnz):
            rows = np.flatnonzero(nnz == m)
            entries = indptr[rows][:, None] + np.arange(m)
            patterns, inverse = unique_rows(cols[entries])
            order = np.argsort(inverse, kind="stable")
            bounds = np.searchsorted(inverse[order], np.arange(len(patterns) + 1))
            for k, pattern in enumerate(patterns):
                sel = order[bounds[k] : bounds[k + 1]]
                out.append((rows[sel], entries[sel], pattern))
        return tuple(out)


if TYPE_CHECKING:  # mypy proves that a RangeBlock is a MeasurementBlock

    def _is_measurement_block(block: RangeBlock) -> MeasurementBlock:
        return block


def _gauge(mics: Array) -> tuple[Array, Array, Array]:
    """Origin (C), axes (3, 3) (columns X, Y, Z of the gauge frame) and the free
    coordinates' start values (N_GEO,) of the recorded microphones."""
    tri = Trilateration.from_microphones(mics[:3])
    axes = np.eye(3) if tri.axes is None else tri.axes
    local = (mics - tri.origin) @ axes  # (4, 3) gauge-frame coordinates
    return tri.origin, axes, np.array([local[m, k] for m, k in MIC_COORDS])


def range_block(
    ranges: pa.Table,
    geometry: DigitizerGeometry,
    order: list[int | str],
    options: RangeModelOptions | None = None,
) -> RangeBlock:
    """The :class:`RangeBlock` of a sonic session's ``ranges`` table, its digitizer's
    recorded ``geometry`` and its plan's measurement ``order`` (sweeps as recorded). The
    session's tables are read by :func:`pipeline.stages.refine_problem.session_range_block`.

    Raises
    ------
    ArmsigError
        A bad geometry or ranges table, cycle times out of the measurement order, no rod
        ranges at B or D, or a microphone that never heard the target.
    """
    opts = options or RangeModelOptions()
    check_cycle_order(ranges, order)
    rows = range_rows(ranges, geometry)
    origin, axes, geo0 = _gauge(geometry.microphones)
    d_mic = np.zeros((4, 3, N_GEO))
    for j, (m, k) in enumerate(MIC_COORDS):
        d_mic[m, :, j] = axes[:, k]
    origin_all = geometry.microphones - d_mic @ geo0  # C for every microphone but D/A/B's free part
    h = geometry.height(geometry.microphones)
    h_ref = float(h[1] + h[3]) / 2.0
    ok = np.isfinite(rows.f_b) & np.isfinite(rows.f_d)
    if not ok.any():
        raise ArmsigError(
            "no digitize cycle has all four calibration-rod ranges",
            expected="sparkers 1, 2 → B and 3, 4 → D heard in one cycle at least (E.1)",
            got=f"{len(ok)} cycles, none complete",
            fix="check the rods' sparkers, then re-record",
        )
    g_cycles = (rows.f_b[ok] - rows.f_d[ok]) / (h[1] - h[3])
    g0 = float(np.median(g_cycles))  # robust to a spurious rod echo
    # a(t) through the rods' f at h_ref: with h_ref midway, their mean (E.5).
    t_all = np.concatenate([rows.t_time_s, rows.r_time_s])
    t_min, t_max = float(t_all.min()), float(t_all.max())
    f_mid = (rows.f_b[ok] + rows.f_d[ok]) / 2.0  # Eq. (E.5)
    if opts.knot_spacing_s is None:
        spline = TimeSpline.chosen(t_min, t_max, rows.cycle_t_s[ok], f_mid)
    else:
        spline = TimeSpline.over(t_min, t_max, opts.knot_spacing_s)
    a0 = spline.fit(rows.cycle_t_s[ok], f_mid)
    x0 = np.concatenate([geo0, np.zeros(N_BIAS), a0, [g0]])
    sigma = np.concatenate(
        [
            np.full(N_GEO, opts.mic_prior_sigma_cm),
            np.full(N_BIAS, opts.bias_prior_sigma_cm),
            np.full(spline.n_coef, opts.speed_prior_sigma),
            [opts.gradient_prior_sigma_per_cm],
        ]
    )
    axis = "xyz"
    names = (
        *(f"mic_{MICROPHONES[m]}_{axis[k]}_cm" for m, k in MIC_COORDS),
        *(f"bias_{m}_cm" for m in MICROPHONES),
        *(f"speed_knot_{j:02d}" for j in range(spline.n_coef)),
        "speed_gradient_per_cm",
    )
    units = ("cm",) * (N_GEO + N_BIAS) + ("1",) * spline.n_coef + ("1/cm",)
    rod_d = np.linalg.norm(
        geometry.rod_sparkers[rows.r_sparker - 1] - geometry.microphones[rows.r_mic], axis=1
    )
    res = geometry.resolution_cm
    keys = pa.table(
        {
            "sweep": pa.array(rows.key_sweep, pa.int32()),
            "step": pa.array(rows.key_step, pa.int32()),
            "target": pa.array([SONIC_TARGET] * len(rows.key_sweep), pa.string()),
        }
    )
    kind = np.concatenate(
        [
            np.full(len(rows.t_pos), "target"),
            np.full(len(rows.r_mic), "rod"),
            np.full(len(x0), "prior"),
        ]
    )
    return RangeBlock(
        keys=keys,
        param_names=tuple(names),
        param_units=units,
        x0=x0,
        x_prior=x0.copy(),
        sigma_prior=sigma,
        row_kind=kind,
        geometry=geometry,
        spline=spline,
        h_ref_cm=h_ref,
        rows=rows,
        gauge_origin=origin_all,
        gauge_axes=axes,
        d_mic_d_geo=d_mic,
        up=geometry.up,
        t_spline=spline.basis(rows.t_time_s),
        r_spline=spline.basis(rows.r_time_s),
        t_d_mic=d_mic[rows.t_mic],
        t_w=1.0 / range_sigma_cm(rows.t_s_cm, res),
        r_w=1.0 / range_sigma_cm(rows.r_s_cm, res),
        rod_d_cm=rod_d,
    )
