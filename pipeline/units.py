"""Unit conversions at boundaries: cm and degrees outside, radians inside."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt


def joints_to_internal(q: npt.ArrayLike, prismatic: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Joint values in boundary units (deg / cm) to math units (rad / cm).

    Parameters
    ----------
    q : array_like, shape (..., n)
    prismatic : array_like of bool, shape (n,)
    """
    qq = np.asarray(q, float)
    return np.where(np.asarray(prismatic, bool), qq, np.deg2rad(qq))


def joints_to_boundary(q: npt.ArrayLike, prismatic: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Joint values in math units (rad / cm) to boundary units (deg / cm), shape (..., n)."""
    qq = np.asarray(q, float)
    return np.where(np.asarray(prismatic, bool), qq, np.rad2deg(qq))
