"""The non-geometric terms compiled for the real-time solver: readings from where the
joints must sit, one target, nothing allocated (issue 27).

The same arithmetic as :meth:`pipeline.kinematics.nongeometric.NonGeometric.readings_for`
(the fixed point of ``q = q* − Φ(q)β``) with ``Φ`` from the design chain's frames in
scalars; :class:`CompiledDeflection` packs the arrays once. Agreement with the numpy
model is a test (``tests/test_nongeometric.py``).
"""

from __future__ import annotations

import numpy as np

from pipeline.kinematics.ik_compiled import Buf, jit
from pipeline.kinematics.nongeometric import GRAVITY, READINGS_TOLERANCE, NonGeometric

#: Fixed-point iterations at most (a deflection of 1e-3 rad converges in ~5).
MAX_ITER = 50
#: Stop when a step moves no reading by more than this (relative to max(1, |q|)).
TOLERANCE = READINGS_TOLERANCE


@jit
def _deflection_into(
    q: Buf, base: Buf, links: Buf, offsets: Buf, prismatic: Buf, comp: Buf, harm: Buf,
    beta: Buf, gravity: Buf, F: Buf, W: Buf, out: Buf,
) -> None:  # fmt: skip
    """``Φ(q)β`` (n,) into ``out``; ``F`` (n + 1, 4, 4) scratch for the design frames
    (``F[i]`` has joint ``i+1``'s axis, ``F[k]`` link ``k``'s lumped mass at its origin),
    ``W`` (4, 4) scratch."""
    n = q.shape[0]
    F[0] = base
    for i in range(n):
        a = q[i] - offsets[i]
        c, s = np.cos(a), np.sin(a)
        for r in range(4):  # W = F_i · M_i(a)
            x0, x1, x2, x3 = F[i, r, 0], F[i, r, 1], F[i, r, 2], F[i, r, 3]
            if prismatic[i]:
                W[r, 0], W[r, 1], W[r, 2], W[r, 3] = x0, x1, x2, x3 + a * x2
            else:
                W[r, 0], W[r, 1], W[r, 2], W[r, 3] = c * x0 + s * x1, c * x1 - s * x0, x2, x3
        for r in range(4):  # F_{i+1} = W · K̄_i
            for col in range(4):
                acc = 0.0
                for k in range(4):
                    acc += W[r, k] * links[i, k, col]
                F[i + 1, r, col] = acc
    out[:] = 0.0
    for m in range(comp.shape[0]):
        j, k = comp[m, 0] - 1, comp[m, 1]
        ax, ay, az = F[k, 0, 3] - F[j, 0, 3], F[k, 1, 3] - F[j, 1, 3], F[k, 2, 3] - F[j, 2, 3]
        mx = ay * gravity[2] - az * gravity[1]
        my = az * gravity[0] - ax * gravity[2]
        mz = ax * gravity[1] - ay * gravity[0]
        out[j] += beta[m] * (mx * F[j, 0, 2] + my * F[j, 1, 2] + mz * F[j, 2, 2])
    base_m = comp.shape[0]
    for i in range(harm.shape[0]):
        j = harm[i, 0] - 1
        value = np.cos(q[j]) if harm[i, 1] == 1 else np.sin(q[j])
        out[j] += beta[base_m + i] * value


@jit
def _readings_rows(q: Buf, consts: Buf, ints: Buf, outside: Buf, scratch: Buf) -> None:
    """Each row of ``q`` (m, n), where the joints must sit, replaced in place by the
    readings that put them there, ``outside[r]`` whether a reading of row ``r`` left the
    limits. ``consts``, ``ints``, ``scratch``: :class:`CompiledDeflection`'s packed arrays
    (few arguments: a numba call unboxes each, ~0.25 µs apiece)."""
    n, nc, nh = ints[0], ints[1], ints[2]
    prismatic = ints[3 : 3 + n] != 0
    comp = ints[3 + n : 3 + n + 2 * nc].reshape(nc, 2)
    harm = ints[3 + n + 2 * nc : 3 + n + 2 * nc + 2 * nh].reshape(nh, 2)
    base = consts[0:16].reshape(4, 4)
    links = consts[16 : 16 + 16 * n].reshape(n, 4, 4)
    at = 16 + 16 * n
    offsets, lower, upper = (
        consts[at : at + n],
        consts[at + n : at + 2 * n],
        consts[at + 2 * n : at + 3 * n],
    )
    gravity = consts[at + 3 * n : at + 3 * n + 3]
    beta = consts[at + 3 * n + 3 :]
    F = scratch[0 : 16 * (n + 1)].reshape(n + 1, 4, 4)
    W = scratch[16 * (n + 1) : 16 * (n + 2)].reshape(4, 4)
    d = scratch[16 * (n + 2) : 16 * (n + 2) + n]
    target = scratch[16 * (n + 2) + n : 16 * (n + 2) + 2 * n]
    for r in range(q.shape[0]):
        row = q[r]
        big = 1.0
        for i in range(n):
            target[i] = row[i]
            big = max(big, abs(row[i]))
        scale = TOLERANCE * big
        for _ in range(MAX_ITER):
            _deflection_into(
                row, base, links, offsets, prismatic, comp, harm, beta, gravity, F, W, d
            )
            step = 0.0
            for i in range(n):
                nxt = target[i] - d[i]
                step = max(step, abs(nxt - row[i]))
                row[i] = nxt
            if step <= scale:
                break
        outside[r] = False
        for i in range(n):
            if row[i] < lower[i] or row[i] > upper[i]:
                outside[r] = True


class CompiledDeflection:
    """A :class:`NonGeometric` packed for :func:`_readings_rows` (arrays made once), with
    the joint limits ``lower``, ``upper`` (n,) its readings are checked against."""

    def __init__(self, model: NonGeometric, lower: Buf, upper: Buf) -> None:
        d, t = model.design, model.terms
        n = d.n_joints
        # A payload term is the flange's lever (link n) times the payload: a compliance
        # pair (j, n) of coefficient γ_j · payload_kg, in the coefficients' order.
        pairs = [*t.compliance, *((j, n) for j in t.payload)]
        comp = np.array(pairs, np.int64).reshape(-1)
        harm = np.array([(j, f == "cos") for j, f in t.harmonic], np.int64).reshape(-1)
        self._ints = np.concatenate(
            [[n, len(comp) // 2, len(harm) // 2], d.prismatic.astype(np.int64), comp, harm]
        ).astype(np.int64)
        beta = model.coefficients.copy()
        beta[len(t.compliance) : len(t.compliance) + len(t.payload)] *= model.payload_kg
        parts = (d.base, d.links, d.joint_offsets, lower, upper, GRAVITY, beta)
        self._consts = np.concatenate([np.asarray(a, float).ravel() for a in parts])
        self._scratch = np.empty(16 * (n + 2) + 2 * n)

    def readings_into(self, q: Buf, outside: Buf) -> None:
        """``q`` (m, n), where the joints must sit (rad / cm), replaced in place by the
        readings that put them there (C-contiguous float; one target: a (1, n) view), and
        ``outside`` (m,) bool: whether a row's readings left the limits."""
        _readings_rows(q, self._consts, self._ints, outside, self._scratch)
