"""The contract between the refinement's kinematic model and a sensor's measurements.

The refinement (:mod:`pipeline.refine`) fits one kinematic chain to every
measurement of a session. The chain predicts the sensor-frame position ``p`` of
each measured target at each configuration, one row per (sweep, step, target)
key; a *measurement block* turns those positions and its own parameters (sensor
self-calibration: microphone positions, range biases, the speed of sound) into
whitened residuals and their derivatives. Point sensors give three residuals per
position; the sonic digitizer gives one per slant range, and rows of its own
(calibration rods, priors) that depend on no position.

The solver chains the two: ``J = [d_p[rows] · dp/dθ[pos[rows]], d_x]``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np
import numpy.typing as npt
from scipy import sparse

if TYPE_CHECKING:  # a block's keys are an Arrow table; the optimiser never reads them
    import pyarrow as pa

Array = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
#: Rows of a CSR ``d_x`` that hold the same columns: (rows, entries, columns).
Group = tuple[IntArray, IntArray, IntArray]


@dataclass(frozen=True)
class Linearization:
    """A block's residuals and their first derivatives at one point.

    Attributes
    ----------
    r : ndarray, shape (R,)
        Whitened residuals, (model − measured) / σ: unit variance under the block's
        noise model.
    pos : ndarray of int, shape (R,)
        Index into the block's ``keys`` of the one target position row ``k``
        depends on; −1 where it depends on none (rods, priors).
    d_p : ndarray, shape (R, 3)
        ``∂r/∂p`` for that position (sensor frame, per cm); zero where ``pos`` is −1.
    d_x : ndarray or scipy.sparse array, shape (R, n_params)
        ``∂r/∂x`` for the block's own parameters (sparse where few of them touch a
        row: the solver never densifies it, :func:`dense` does).
    d_x_groups : tuple of (rows, entries, columns), optional
        For a CSR ``d_x``: rows that hold the same columns in the same order; ``rows``
        (n_g,), ``entries`` (n_g, m) their entries' positions in ``d_x.data``, ``columns``
        (m,). With it the solver forms ``XᵀWX`` group by group (m² per row, not P²).
    d_theta : ndarray, shape (R, n_kin), optional
        ``∂r/∂θ`` of rows that depend on the kinematic parameters other than through a
        position (a measured tool orientation, :mod:`pipeline.refine.orientation`); zero
        on the other rows. Their ``pos`` is the position they were measured with (so a
        fold that holds the position out holds them out), their ``d_p`` zero.
    """

    r: Array
    pos: npt.NDArray[np.int64]
    d_p: Array
    d_x: Array | sparse.csr_array
    d_x_groups: tuple[Group, ...] | None = None
    d_theta: Array | None = None


def dense(m: Array | sparse.sparray) -> Array:
    """``m`` (ndarray or scipy.sparse array) as a dense float ndarray."""
    if isinstance(m, np.ndarray):
        return np.asarray(m, float)
    return np.asarray(m.toarray(), float)


class MeasurementBlock(Protocol):
    """What the refinement needs from a sensor's measurements.

    Attributes
    ----------
    keys : pyarrow.Table
        Columns ``sweep`` (int32), ``step`` (int32), ``target`` (string): the
        target positions the block observes, unique rows; ``p`` passed to
        :meth:`linearize` follows this order.
    param_names, param_units : tuple of str
        One per parameter of the block (may be empty).
    x0 : ndarray, shape (n_params,)
        Start values.
    """

    keys: pa.Table
    param_names: tuple[str, ...]
    param_units: tuple[str, ...]
    x0: Array

    def linearize(self, p: Array, x: Array) -> Linearization:
        """Residuals and derivatives at positions ``p`` (K, 3) and parameters ``x``."""
        ...
