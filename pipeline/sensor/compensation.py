"""Slant range compensation for the speed of sound (Appendix E, ERRATA.md).

Model (B-3): the speed of sound ``β`` is linear in height, hence linear along any
straight line of sight. Speeds are carried as ratios ``f = β / S*`` to the digitizer's
internal speed ``S*``, so a raw range is ``s_raw = S* · t``. The calibration rods (E.1)
give ``f`` at the heights of microphones B and D; ``f`` elsewhere is the line through
those two points. The target's own ``f`` depends on its unknown height, so ranges and
position are refined together by a fixed-point ("Jacobi") iteration.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from pipeline.errors import ArmsigError
from pipeline.sensor.geometry import DigitizerGeometry
from pipeline.sensor.triangulation import Trilateration

Array = npt.NDArray[np.float64]


def _need_last(a: Array, shape: tuple[int, ...], name: str, hint: str) -> None:
    if a.ndim < len(shape) or a.shape[a.ndim - len(shape) :] != shape:
        raise ArmsigError(
            f"{name} has the wrong shape",
            expected=f"shape (..., {', '.join(map(str, shape))})",
            got=f"shape {a.shape}",
            fix=hint,
        )


def rod_ratios(
    s12_b: npt.ArrayLike, s34_d: npt.ArrayLike, rod_length_cm: float
) -> tuple[Array, Array]:
    """Speed-of-sound ratios ``f = c / S*`` at microphones B and D from the rods (E.1).

    Parameters
    ----------
    s12_b : array_like, shape (..., 2)
        Raw ranges sparker 1 → B and sparker 2 → B (cm).
    s34_d : array_like, shape (..., 2)
        Raw ranges sparker 3 → D and sparker 4 → D (cm).
    rod_length_cm : float
        Calibrated sparker spacing ``D_12`` (= ``D_34``).

    Returns
    -------
    f_b, f_d : ndarray, shape (...)
        NaN where an echo is missing.
    """
    a, b = np.asarray(s12_b, float), np.asarray(s34_d, float)
    hint = "pass raw[..., 0:2, 1] and raw[..., 2:4, 3]"
    _need_last(a, (2,), "s12_b", hint)
    _need_last(b, (2,), "s34_d", hint)
    f_b = rod_length_cm / (a[..., 1] - a[..., 0])  # Eq. (E.1)
    f_d = rod_length_cm / (b[..., 1] - b[..., 0])  # Eq. (E.1), lower rod
    return f_b, f_d


def speed_ratio_at_height(
    h: npt.ArrayLike, f_b: npt.ArrayLike, f_d: npt.ArrayLike, h_b: float, h_d: float
) -> Array:
    """Speed ratio at height ``h``, linear through ``(h_b, f_b)`` and ``(h_d, f_d)`` (B-3).

    Parameters
    ----------
    h : array_like, shape (...)
        Heights (cm, same datum as ``h_b``, ``h_d``); extrapolates outside them.
    f_b, f_d : array_like, shape (...)
        Ratios at heights ``h_b`` and ``h_d`` (broadcast against ``h``).
    h_b, h_d : float
        Heights of microphones B and D (distinct).

    Returns
    -------
    f : ndarray, shape (...)
    """
    if not h_b != h_d:  # also rejects NaN heights
        raise ArmsigError(
            "the calibration rods are at the same height",
            expected="distinct heights of microphones B and D",
            got=f"h_B={h_b}, h_D={h_d}",
            fix="check the digitizer geometry in /rig/description",
        )
    w = (np.asarray(h, float) - h_b) / (h_d - h_b)
    fb = np.asarray(f_b, float)
    return np.asarray(fb + w * (np.asarray(f_d, float) - fb), float)


def line_of_sight_length(
    s_raw: npt.ArrayLike, f_mic: npt.ArrayLike, f_target: npt.ArrayLike
) -> Array:
    """True length of a line of sight from its raw range, exact for linear speed (E.2)-(E.4).

    Along the line the speed goes linearly from ``β_t = f_target·S*`` to
    ``β_m = f_mic·S*``, so ``t = L·ln(β_m/β_t)/(β_m − β_t)`` (``L/β`` if equal) and
    ``s_raw = S*·t``. Hence ``L = s_raw·(f_m − f_t)/ln(f_m/f_t)``, evaluated as
    ``s_raw·f_t·d/log1p(d)`` with ``d = (f_m − f_t)/f_t``: ``f_m − f_t`` is exact
    (Sterbenz) and ``log1p`` keeps full precision as ``d → 0``, with ``d = 0`` giving
    ``s_raw·f``.

    Parameters
    ----------
    s_raw : array_like, shape (...)
        Raw ranges (cm).
    f_mic, f_target : array_like, shape (...)
        Speed ratios at the microphone and at the target (broadcast together).

    Returns
    -------
    L : ndarray, shape (...)
        Length of the line of sight (cm).
    """
    fm, ft = np.asarray(f_mic, float), np.asarray(f_target, float)
    d = (fm - ft) / ft
    lg = np.log1p(d)
    ratio = np.divide(d, lg, out=np.ones(np.broadcast(d, lg).shape), where=d != 0.0)
    return np.asarray(np.asarray(s_raw, float) * ft * ratio, float)  # Eq. (E.3) inverted


@dataclass(frozen=True)
class CompensationResult:
    """Compensated ranges and target positions of many digitize cycles.

    Attributes
    ----------
    s_abc_cm : ndarray, shape (..., 3)
        Compensated slant ranges target → A, B, C (NaN where not valid).
    p_cm : ndarray, shape (..., 3)
        Target position in the sensor frame (NaN where not valid).
    f_b, f_d : ndarray, shape (...)
        Rod speed ratios (E.1) (NaN where a rod echo is missing).
    iterations : ndarray of int, shape (...)
        Fixed-point updates performed (0 where not valid).
    converged : ndarray of bool, shape (...)
        The last update moved the position by less than ``tol_cm``.
    valid : ndarray of bool, shape (...)
        All seven needed echoes present and every triangulation succeeded.
    """

    s_abc_cm: Array
    p_cm: Array
    f_b: Array
    f_d: Array
    iterations: npt.NDArray[np.int64]
    converged: npt.NDArray[np.bool_]
    valid: npt.NDArray[np.bool_]


def compensate(
    raw: npt.ArrayLike, geometry: DigitizerGeometry, tol_cm: float = 1e-9, max_iter: int = 50
) -> CompensationResult:
    """Compensate raw slant ranges for the speed of sound and locate the target (App. E).

    Parameters
    ----------
    raw : array_like, shape (..., 5, 4)
        Raw ranges (cm) of sparkers 1-5 (rows) to microphones A-D (columns), NaN = no
        echo. Uses sparkers 1, 2 → B, 3, 4 → D and 5 → A, B, C.
    geometry : DigitizerGeometry
        The digitizer as calibrated; its microphone positions (any layout with Z out
        of the wall, :class:`~pipeline.sensor.triangulation.Trilateration`) and heights
        are used as given, so a calibration error propagates into the positions.
    tol_cm : float
        Stop a cycle when an update moves its position by less than this. The default
        1e-9 cm is about 1e4 ulps of a 250 cm coordinate: above rounding noise, and
        the iteration contracts by ~1e-3 per step, so it is reached in a few steps.
    max_iter : int
        Most updates per cycle.

    Returns
    -------
    CompensationResult
    """
    r = np.asarray(raw, float)
    _need_last(r, (5, 4), "raw", "pass (..., 5, 4) slant ranges, sparkers 1-5 × mics A-D")
    locate = Trilateration.from_microphones(geometry.microphones[:3])  # as recorded
    h_mic = geometry.height(geometry.microphones)  # A, B, C, D
    h_b, h_d = float(h_mic[1]), float(h_mic[3])  # rods are level with B and D (E.1)
    f_b, f_d = rod_ratios(r[..., 0:2, 1], r[..., 2:4, 3], geometry.rod_length_cm)
    f_abc = speed_ratio_at_height(h_mic[:3], f_b[..., None], f_d[..., None], h_b, h_d)
    s_raw = r[..., 4, :3]
    f_avg = (f_b + f_d) / 2.0  # Eq. (E.5), ERRATA form
    s = f_avg[..., None] * s_raw
    p = locate(s)  # Eqs. (6.1)-(6.6): first estimate
    valid = np.array(np.isfinite(p).all(axis=-1) & np.isfinite(s).all(axis=-1))
    iterations = np.zeros(valid.shape, np.int64)
    converged = np.zeros(valid.shape, bool)
    # Flat views of the per-cycle arrays; while every cycle is still iterating the
    # whole arrays are used instead of copies selected by the mask (same numbers).
    pf, sf = p.reshape(-1, 3), s.reshape(-1, 3)
    s_raw_f, f_abc_f = s_raw.reshape(-1, 3), f_abc.reshape(-1, 3)
    f_b_f, f_d_f = np.reshape(f_b, -1), np.reshape(f_d, -1)
    valid_f, converged_f, iterations_f = (a.reshape(-1) for a in (valid, converged, iterations))
    for _ in range(max_iter):
        active = valid_f & ~converged_f
        if not active.any():
            break
        sel = slice(None) if active.all() else active
        f_t = speed_ratio_at_height(geometry.height(pf[sel]), f_b_f[sel], f_d_f[sel], h_b, h_d)
        s_new = line_of_sight_length(s_raw_f[sel], f_abc_f[sel], f_t[:, None])  # Eq. (E.3)
        p_new = locate(s_new)  # Eqs. (6.1)-(6.6)
        step = np.linalg.norm(p_new - pf[sel], axis=-1)
        sf[sel], pf[sel] = s_new, p_new
        iterations_f[sel] += 1
        ok = np.isfinite(step)
        valid_f[sel] = ok
        converged_f[sel] = ok & (step < tol_cm)
    s[~valid] = np.nan
    p[~valid] = np.nan
    iterations[~valid] = 0
    return CompensationResult(s, p, f_b, f_d, iterations, converged, valid)
