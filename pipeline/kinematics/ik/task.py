"""Task axes: the components of δ = [dx, dy, dz, rx, ry, rz] a solve controls
(:mod:`pipeline.kinematics.ik`, "Task axes"), their masks, and
:func:`controllable_axes`, which derives them from a chain."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from pipeline.errors import KinematicsError
from pipeline.kinematics.chain import SerialChain
from pipeline.kinematics.ik.steps import _unit_weights
from pipeline.kinematics.jacobian import geometric_jacobian
from pipeline.kinematics.transforms import Array, ArrayLike

ALL_AXES = (0, 1, 2, 3, 4, 5)


def _task_mask(task_axes: Sequence[int] | None) -> tuple[tuple[int, ...], Array | None]:
    """Validated task axes and the 0/1 mask of δ's components (None: all six)."""
    if task_axes is None:
        return ALL_AXES, None
    axes = tuple(sorted({int(a) for a in task_axes}))
    if not axes or axes[0] < 0 or axes[-1] > 5 or len(axes) != len(tuple(task_axes)):
        raise KinematicsError(
            "bad task axes",
            expected="distinct indices 0-5 into δ = [dx, dy, dz, rx, ry, rz]",
            got=repr(task_axes),
        )
    if axes == ALL_AXES:
        return ALL_AXES, None
    mask = np.zeros(6)
    mask[list(axes)] = 1.0
    return axes, mask


def _masked(delta: Array, mask: Array | None) -> Array:
    """δ (..., 6) with the unselected components set to 0 (unchanged without a mask)."""
    return delta if mask is None else delta * mask


def _masked_rows(J: Array, mask: Array | None) -> Array:
    """Jacobians (..., 6, n) with the unselected rows set to 0."""
    return J if mask is None else J * mask[:, None]


#: A row of the unit-scaled Jacobian counts as identically zero below this fraction
#: of the largest entry over the samples: exact design geometry (α = 0° or 180°)
#: leaves ~1e-16 of round-off in the rows it cannot move, a real coupling (an axis
#: tilted by even 1e-6 rad) is orders of magnitude above 1e-9.
DEAD_ROW_FRACTION = 1e-9


def controllable_axes(chain: SerialChain, q: ArrayLike) -> tuple[int, ...]:
    """Components of δ = [dx, dy, dz, rx, ry, rz] a chain can move (task axes).

    A row of the geometric Jacobian (world frame, position rows divided by
    the length scale) that vanishes at every sample configuration is a pose
    component no joint motion changes: for a SCARA-like arm whose revolute
    axes are parallel to the world Z, ``rx`` and ``ry``. The remaining
    components are the task axes, e.g. ``(0, 1, 2, 5)``. Where more
    components move than the chain has joints (a 5-joint arm moves all six),
    no component is free of the others and only the position is controlled,
    ``(0, 1, 2)``. Evaluate on the *design* model: identified models have
    slightly tilted axes, which move every component a little.

    Parameters
    ----------
    chain : SerialChain
        Unbatched chain.
    q : array_like, shape (k, n)
        Sample configurations (rad / cm), generic (not all singular).

    Returns
    -------
    axes : tuple of int
        Sorted indices into δ; all six for an arm that moves all six with six
        or more joints.

    Raises
    ------
    KinematicsError
        When even the moving position components outnumber the joints (a
        two-joint arm that moves x, y and z): choose ``task_axes`` by hand.
    """
    J = geometric_jacobian(chain, np.atleast_2d(np.asarray(q, float)))
    w = _unit_weights(chain.length_scale)
    size = np.abs(J * w[:, None]).max(axis=(0, 2))  # (6,): largest entry of each row
    live = tuple(int(i) for i in np.flatnonzero(size > DEAD_ROW_FRACTION * size.max()))
    n = chain.n_joints
    if len(live) <= n:
        return live
    position = tuple(i for i in live if i < 3)
    if len(position) > n:
        raise KinematicsError(
            f"cannot choose task axes for a {n}-joint chain",
            expected=f"at most {n} independent pose components",
            got=f"{len(position)} position components move",
            fix="pass task_axes explicitly",
        )
    return position
