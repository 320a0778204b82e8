"""The batch a solver works on: validated targets and starts, a batched chain's
rows, and the pose errors of δ (lengths in cm, angles in radians)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from pipeline.errors import KinematicsError
from pipeline.kinematics.chain import SerialChain
from pipeline.kinematics.transforms import Array, ArrayLike

BoolArray = npt.NDArray[np.bool_]
IntArray = npt.NDArray[np.int64]


def _prepare(
    chain: SerialChain, T_target: ArrayLike, q0: ArrayLike, resolution: ArrayLike
) -> tuple[Array, Array, Array]:
    """Validate and broadcast the inputs to (m, 4, 4), (m, n), (n,)."""
    T = np.asarray(T_target, float)
    if T.ndim == 2:
        T = T[None]
    if T.ndim != 3 or T.shape[-2:] != (4, 4):
        raise KinematicsError(
            "bad target poses", expected="shape (m, 4, 4) or (4, 4)", got=f"shape {T.shape}"
        )
    m, n = T.shape[0], chain.n_joints
    q_start = np.asarray(q0, float)
    if q_start.shape not in ((n,), (m, n)):
        raise KinematicsError(
            "bad start configurations",
            expected=f"shape ({m}, {n}) or ({n},)",
            got=f"{q_start.shape}",
        )
    q = np.empty((m, n))
    q[...] = q_start
    if np.count_nonzero(np.isfinite(T)) < T.size or np.count_nonzero(np.isfinite(q)) < q.size:
        raise KinematicsError(
            "non-finite target pose or start configuration",
            fix="replace NaN rows (e.g. where the design inverse is unreachable) "
            "by a finite guess such as the home configuration",
        )
    res = np.asarray(resolution, float)
    if res.shape != (n,):
        res = np.broadcast_to(res, (n,))
    if np.count_nonzero(res > 0) < n:
        raise KinematicsError("encoder resolution must be positive", got=repr(res))
    parts = (("links", chain.links, 3), ("base", chain.base, 2), ("tool", chain.tool, 2))
    for name, arr, core in parts:
        if arr.ndim > core + 1 or (arr.ndim == core + 1 and arr.shape[0] not in (1, m)):
            raise KinematicsError(
                f"chain {name} batch does not match the targets",
                expected=f"no batch or a batch of 1 or {m}",
                got=f"shape {arr.shape}",
            )
    return T, q, res


def _take(chain: SerialChain, rows: IntArray, m: int) -> SerialChain:
    """The chain restricted to target ``rows`` (a no-op for an unbatched chain)."""
    links, base, tool = chain.links, chain.base, chain.tool
    if links.ndim == 3 and base.ndim == 2 and tool.ndim == 2:
        return chain

    def pick(a: Array, core: int) -> Array:
        if a.ndim == core:
            return a
        return np.broadcast_to(a, (m, *a.shape[1:]))[rows]

    return SerialChain(
        links=pick(links, 3),
        prismatic=chain.prismatic,
        base=pick(base, 2),
        tool=pick(tool, 2),
        joint_offsets=chain.joint_offsets,
    )


def _errors(delta: Array) -> Array:
    """Radial position error (cm) and rotation angle (rad) of δ vectors (..., 6), as (..., 2)."""
    out: Array = np.sqrt((delta * delta) @ _HALVES)  # a product: numpy sums short axes slowly
    return out


#: Sums of δ's position and rotation components: ``δ² @ _HALVES``.
_HALVES = np.repeat(np.eye(2), 3, axis=0)


def _scaled_error(errors: Array, length: float) -> Array:
    """Scalar pose error ``|dp| / length + |rotation|`` from :func:`_errors` (..., 2)."""
    out: Array = errors @ np.array((1.0 / length, 1.0))
    return out
