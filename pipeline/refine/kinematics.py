"""The refinement's kinematic model: every measured point from the joint axes as lines.

The signature chain ``T(q) = S̄_0 Π M_i(q_i − q̄_i^s) B_i · tool`` with
``B_i = S̄_{i−1}⁻¹ S̄_i`` (:mod:`pipeline.kinematics.signature`) is, written at the
signature configuration ``q̄^s`` (product of exponentials), a point fixed on link ``ℓ``
at

    ``p(q) = A_1(θ_1) ⋯ A_ℓ(θ_ℓ) · p0``,  ``A_k(θ) = S_k M_k(θ) S_k⁻¹``,  ``θ = q − q̄^s``,

with ``S_k = S̄_{k−1}`` and ``p0`` the point at ``q̄^s`` (sensor frame). Only the
*axis lines* of the ``S_k`` and the points ``p0`` enter, so these are the parameters:

- joint ``k``'s axis line as a move of its start frame (the thesis's ``S̄_{k−1}``):
  ``S_k(δ) = S_k⁰ · Trans(t_x, t_y, 0) · Rot_x(r_x) · Rot_y(r_y)``, ``δ = (r_x, r_y, t_x, t_y)``
  for a revolute joint, ``(r_x, r_y)`` for a prismatic one (its origin does not matter).
  It has no singularity near the start, unlike D-H's ``α`` on nearly parallel axes
  (Hayati's problem): it is the thesis frame moved;
- each target point's ``p0`` (cm): one per (sweep, target) of the joint sweeps, one
  ``tool`` point shared by every measurement of the tool (tool sweep, check sweep, the
  pose set's tool target and an import's ``plan.tool_target`` rows), and one per other
  target on the last link (``tool/<target>``: the pose set's other reflectors, an
  import's ``plan.tool_targets``), shared by every sweep that measures it.

Gauge freedoms and how they are fixed:

1. the sensor frame is the world: ``S̄_0`` is joint 1's axis in the sensor frame, no
   separate base;
2. the origin of ``S_k`` along its axis and its rotation about it do not change ``T(q)``
   (``M_k`` commutes with both), so they are not parameters: the refined frame is
   ``S_k(δ)``, whose origin is where the refined axis meets the thesis frame's X-Y plane
   and whose X is the thesis X made normal to the refined axis;
3. encoder offsets are absorbed by ``q̄^s``, the zero of ``θ`` (the signature
   configuration defines the readings' reference, Section 4.3.3);
4. the tool's orientation is not observable from points: it is ``S_n``'s (thesis
   convention, ``S̄_n = S̄_{n−1}``), the tool a translation. When a 6-D sensor measured
   the tool's orientation (``tool_rotation``), the tool is turned in ``S_n`` by
   ``R_c = Exp(r)``, its rotation vector ``r`` three more parameters (``tool_rot.*``,
   after the points).

Parameter vector: ``x = [δ_1 … δ_n, p0_0 … p0_{m−1}, r, β]``. ``x`` with every ``δ = 0``
and the points from :func:`start_points` reproduces the thesis chain.

Non-geometric terms (issue 27, :mod:`pipeline.kinematics.nongeometric`): the joints sit at
``θ + Φ β`` instead of ``θ``, ``Φ`` (K, n, m) each observation's regressor at its readings
(a function of the readings alone), ``β`` their coefficients, the last parameters.
``∂p/∂β = Σ_j ∂p/∂θ_j Φ_j``, ``∂p/∂θ_j = (Π_{i<j} A_i) Ĝ_j (Π_{i≥j} A_i p0)`` with
``Ĝ_j = S_j G_z S_j⁻¹`` the joint's own generator.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np
import numpy.typing as npt

from pipeline.errors import StageError
from pipeline.kinematics.chain import SerialChain
from pipeline.kinematics.nongeometric import Terms, regressor
from pipeline.kinematics.so3 import right_jacobian, rotation_from_vector
from pipeline.kinematics.transforms import invert_transform, rot_x, rot_y, trans
from pipeline.refine.motions import (
    by_observation,
    joint_motions,
    moved_by_twists,
    prefixes,
    rotate,
    rotate_constant,
    trig_basis,
    twists,
)
from pipeline.sweeps import WHOLE_ARM_SWEEPS

Array = npt.NDArray[np.float64]

#: Names of a revolute joint's axis parameters (a prismatic joint has the first two).
AXIS_PARAMS = ("rx", "ry", "tx", "ty")
#: Name of the tool's rotation parameters (``tool_rot.rx, .ry, .rz``), fitted when a 6-D
#: sensor measured the tool's orientation (issue 26).
TOOL_ROTATION = "tool_rot"
_AXIS_UNITS = ("rad", "rad", "cm", "cm")
TOOL_POINT = "tool"

# Generators: d/da Rot_x(a) = Rot_x(a) · _GX, d/da Rot_y(a) = Rot_y(a) · _GY.
_GX = np.zeros((4, 4))
_GX[1, 2], _GX[2, 1] = -1.0, 1.0
_GY = np.zeros((4, 4))
_GY[0, 2], _GY[2, 0] = 1.0, -1.0


@dataclass(frozen=True, eq=False)
class ChainModel:
    """Positions of measured points as functions of the axis lines and the points.

    Attributes
    ----------
    frames0 : ndarray, shape (n, 4, 4)
        Start frames ``S̄_0 … S̄_{n−1}`` at ``q̄^s`` (sensor frame, cm).
    prismatic : ndarray of bool, shape (n,)
    link : ndarray of int, shape (K,)
        Link 1..n that each observation's point is fixed on.
    theta : ndarray, shape (K, n)
        Joint readings minus ``q̄^s`` (rad / cm) of each observation.
    point : ndarray of int, shape (K,)
        Index of the point ``p0`` each observation sees.
    point_names : tuple of str
        One name per point (``tool`` or ``sweep<j>/<target>``).
    terms : Terms
        The non-geometric terms fitted (empty: none); their regressor ``Φ`` (module
        docstring) is the design chain's ``design`` at the readings ``θ + q̄^s``,
        ``reading_zero`` = ``q̄^s``, under each observation's ``payload_kg`` (K,)
        (:attr:`regressor`).
    """

    frames0: Array
    prismatic: npt.NDArray[np.bool_]
    link: npt.NDArray[np.int64]
    theta: Array
    point: npt.NDArray[np.int64]
    point_names: tuple[str, ...]
    tool_rotation: bool = False
    terms: Terms = Terms()
    design: SerialChain | None = None
    reading_zero: Array | None = None
    payload_kg: Array | None = None

    @cached_property
    def regressor(self) -> Array:
        """``Φ`` (K, n, terms.size) at every observation's readings."""
        if not self.terms:
            return np.zeros((*self.theta.shape, 0))
        if self.design is None or self.reading_zero is None:
            raise ValueError("non-geometric terms need the design chain and q̄^s")
        payload = 0.0 if self.payload_kg is None else self.payload_kg
        return regressor(self.terms, self.design, self.theta + self.reading_zero, payload)

    @property
    def n_joints(self) -> int:
        return len(self.prismatic)

    @property
    def n_points(self) -> int:
        return len(self.point_names)

    def observing(self, rows: npt.ArrayLike) -> ChainModel:
        """This model observing only its observations ``rows`` (a boolean mask or indices,
        in their order)."""
        r = np.asarray(rows)
        payload = None if self.payload_kg is None else self.payload_kg[r]
        return replace(self, link=self.link[r], theta=self.theta[r], point=self.point[r],
                       payload_kg=payload)  # fmt: skip

    @cached_property
    def axis_offsets(self) -> Array:
        """Start of each joint's ``δ`` in ``x``, shape (n + 1,) (last = axis parameters)."""
        sizes = np.where(self.prismatic, 2, 4)
        return np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)

    @property
    def n_axis_params(self) -> int:
        return int(self.axis_offsets[-1])

    @property
    def n_params(self) -> int:
        return self.beta_slice.stop

    @property
    def beta_slice(self) -> slice:
        """Where the non-geometric coefficients ``β`` sit in ``x`` (the last parameters)."""
        start = self.n_axis_params + 3 * self.n_points + (3 if self.tool_rotation else 0)
        return slice(start, start + self.terms.size)

    def joint_values(self, x: npt.ArrayLike) -> Array:
        """``θ + Φ β`` (K, n): where the joints sit (``θ`` without non-geometric terms)."""
        if not self.terms:
            return self.theta
        beta = np.asarray(x, float)[self.beta_slice]
        return np.asarray(self.theta + self.regressor @ beta, float)

    @property
    def rotation_slice(self) -> slice:
        """Where the tool's rotation vector sits in ``x`` (empty without ``tool_rotation``)."""
        start = self.n_axis_params + 3 * self.n_points
        return slice(start, start + (3 if self.tool_rotation else 0))

    def tool_rotation_matrix(self, x: npt.ArrayLike) -> Array:
        """``R_c = Exp(r)`` (3, 3) of the tool in ``S_n`` (identity without ``tool_rotation``:
        gauge 4, the tool has ``S_n``'s orientation)."""
        r = np.asarray(x, float)[self.rotation_slice]
        return rotation_from_vector(r) if self.tool_rotation else np.eye(3)

    @cached_property
    def param_names(self) -> tuple[str, ...]:
        names = [
            f"joint{k + 1}.{AXIS_PARAMS[m]}"
            for k in range(self.n_joints)
            for m in range(2 if self.prismatic[k] else 4)
        ]
        names += [f"{p}.{c}" for p in self.point_names for c in "xyz"]
        names += [f"{TOOL_ROTATION}.{c}" for c in ("rx", "ry", "rz")] if self.tool_rotation else []
        return (*names, *self.terms.names)

    @cached_property
    def param_units(self) -> tuple[str, ...]:
        sizes = [2 if p else 4 for p in self.prismatic]
        units = [_AXIS_UNITS[m] for size in sizes for m in range(size)]
        units += ["cm"] * (3 * self.n_points) + ["rad"] * (3 * self.tool_rotation)
        return (*units, *self.terms.units)

    def point_slice(self, j: int) -> slice:
        """Where point ``j``'s ``p0`` sits in ``x``."""
        start = self.n_axis_params + 3 * j
        return slice(start, start + 3)

    def _deltas(self, x: Array) -> Array:
        """``δ`` of every joint as (n, 4): zeros for a prismatic joint's translations."""
        d = np.zeros((self.n_joints, 4))
        for k in range(self.n_joints):
            a, b = self.axis_offsets[k], self.axis_offsets[k + 1]
            d[k, : b - a] = x[a:b]
        return d

    def frames(self, x: npt.ArrayLike) -> Array:
        """Refined ``S_1 … S_n`` (= ``S̄_0 … S̄_{n−1}``), shape (n, 4, 4)."""
        d = self._deltas(np.asarray(x, float))
        move = trans(d[:, 2], d[:, 3], 0.0) @ rot_x(d[:, 0]) @ rot_y(d[:, 1])
        return np.asarray(self.frames0 @ move, float)

    def _frame_generators(self, x: Array) -> tuple[Array, Array]:
        """Frames ``S`` (n, 4, 4) and ``G_m = ∂S/∂δ_m · S⁻¹`` (n, 4, 4, 4) (m = rx, ry, tx, ty)."""
        d = self._deltas(x)
        T, Rx, Ry = trans(d[:, 2], d[:, 3], 0.0), rot_x(d[:, 0]), rot_y(d[:, 1])
        S = self.frames0 @ T @ Rx @ Ry
        E = np.zeros((2, 4, 4))
        E[0, 0, 3] = E[1, 1, 3] = 1.0  # d Trans(tx, ty, 0) / d(tx, ty)
        dS = np.stack(
            [
                self.frames0 @ T @ Rx @ _GX @ Ry,
                self.frames0 @ T @ Rx @ Ry @ _GY,
                self.frames0 @ E[0] @ Rx @ Ry,
                self.frames0 @ E[1] @ Rx @ Ry,
            ],
            axis=1,
        )
        return S, dS @ invert_transform(S)[:, None]

    def _moving(self, theta: Array) -> Array:
        """``theta`` (K, n) as (n, K), 0 on joints past each observation's link."""
        theta_T = theta.T
        if (self.link != self.n_joints).any():  # pose sets: every point on link n
            moving = np.arange(1, self.n_joints + 1)[:, None] <= self.link[None, :]
            theta_T = np.where(moving, theta_T, 0.0)
        return np.ascontiguousarray(theta_T)

    @cached_property
    def _reading_motions(self) -> tuple[Array, Array]:
        """The readings ``θ`` (n, K) as :meth:`_moving` and their sines and cosines
        (:func:`~pipeline.refine.motions.trig_basis`), formed once: without non-geometric
        terms every evaluation of the fit moves the joints by the same ``θ``."""
        theta = self._moving(self.theta)
        return theta, trig_basis(theta)

    def _motions(self, S: Array, theta: Array) -> tuple[Array, Array]:
        """``A_k(θ_k)`` of every joint and observation at joint values ``theta`` (K, n), in
        closed form (:func:`~pipeline.refine.motions.joint_motions`: columns (n, 3, 3, K),
        translations (n, 3, K)); exactly I on joints past the observation's link (θ = 0)."""
        if theta is self.theta:
            return joint_motions(S, self.prismatic, *self._reading_motions)
        return joint_motions(S, self.prismatic, self._moving(theta))

    def _motion(self, S: Array, theta: Array) -> Callable[[int], tuple[Array, Array]]:
        """``k -> A_k(θ_k)`` (columns (3, 3, K), translation (3, K)): one joint's motions of
        :meth:`_motions`, formed when asked, in one buffer (valid until the next call)."""
        reading = theta is self.theta
        theta_T, basis = self._reading_motions if reading else (self._moving(theta), None)
        buffer = np.empty((1, 12, theta_T.shape[1]))

        def motion(k: int) -> tuple[Array, Array]:
            b = None if basis is None else basis[k : k + 1]
            one = slice(k, k + 1)
            Q, t = joint_motions(S[one], self.prismatic[one], theta_T[one], b, buffer)
            return Q[0], t[0]

        return motion

    def _points(self, x: Array) -> Array:
        """``p0`` of every observation, shape (3, K)."""
        p0 = x[self.n_axis_params : self.n_axis_params + 3 * self.n_points]
        return np.ascontiguousarray(p0.reshape(self.n_points, 3)[self.point].T)

    def positions(self, x: npt.ArrayLike) -> Array:
        """Sensor-frame position of every observation, shape (K, 3)."""
        x = np.asarray(x, float)
        motion = self._motion(self.frames(x), self.joint_values(x))
        v = self._points(x)
        for k in range(self.n_joints - 1, -1, -1):  # A_1 (A_2 ( … A_n p0))
            Q, t = motion(k)
            v = rotate(Q, v) + t
        return np.ascontiguousarray(v.T)

    def joint_differences(self, x: npt.ArrayLike, h: float) -> Array:
        """``(p(θ + h e_k) − p(θ − h e_k)) / 2h`` (K, n, 3) of every observation and joint k,
        each :meth:`positions` with joint k moved, bit for bit, with the other joints'
        motions formed once (a twelfth of the work on six joints, issue 45). For joint
        values that are ``θ`` itself (no non-geometric terms, or ``β = 0``)."""
        x = np.asarray(x, float)
        theta = self.joint_values(x)
        S = self.frames(x)
        Q, t = self._motions(S, theta)
        v = self._points(x)
        K, n = theta.shape
        out = np.zeros((K, n, 3))
        for k in range(n - 1, -1, -1):  # v: Π_{i>k} A_i p0, as positions() forms it
            ends = []
            for step in (h, -h):
                th = np.where(k + 1 > self.link, 0.0, theta[:, k] + step)[None]  # as _motions
                Qk, tk = joint_motions(S[k : k + 1], self.prismatic[k : k + 1], th)
                w = rotate(Qk[0], v) + tk[0]
                for i in range(k - 1, -1, -1):
                    w = rotate(Q[i], w) + t[i]
                ends.append(w)
            out[:, k] = ((ends[0] - ends[1]) / (2.0 * h)).T
            v = rotate(Q[k], v) + t[k]
        return out

    def _chain(self, x: Array, S: Array) -> tuple[Array, Array, Array]:
        """The prefixes ``Π_{i<k} A_i`` (k = 0..n: columns (n + 1, 3, 3, K), translations
        (n + 1, 3, K)) and every observation's position (3, K) at ``x``."""
        QP, tP = prefixes(self._motion(S, self.joint_values(x)), self.n_joints)
        return QP, tP, rotate(QP[-1], self._points(x)) + tP[-1]

    def _joint_twists(self, S: Array) -> tuple[Array, Array]:
        """``(w, v)`` (n, 3) of every joint's own generator ``Ĝ_j = S_j G S_j⁻¹``: the
        rotation about its axis line (``w`` its direction, ``v = c × w``) or the
        translation along it (``w = 0``, ``v`` its direction)."""
        axis, c = S[:, :3, 2], S[:, :3, 3]
        w = np.where(self.prismatic[:, None], 0.0, axis)
        v = np.where(self.prismatic[:, None], axis, np.cross(c, axis))
        return w, v

    def _joint_tangents(self, S: Array, QP: Array, tP: Array, p: Array) -> Array:
        """``∂p/∂θ_j`` (K, 3, n) of every observation: ``(Π_{i<j} A_i) Ĝ_j (Π_{i≥j} A_i
        p0)``, the point moved by joint j's twist after its prefix; zero for joints past
        the observation's link."""
        w, v = self._joint_twists(S)
        n = self.n_joints
        t = np.empty((n, 3, p.shape[-1]))
        for j in range(n):
            t[j] = moved_by_twists(QP[j], tP[j], p, w[j : j + 1], v[j : j + 1])[0]
        out = t.transpose(2, 1, 0).copy()
        past = np.arange(1, n + 1)[None, :] > self.link[:, None]  # (K, n)
        out[np.broadcast_to(past[:, None, :], out.shape)] = 0.0
        return out

    def position_jacobian(self, x: npt.ArrayLike) -> Array:
        """``∂p/∂x`` of every observation, shape (K, 3, n_params) (exact, analytic).

        ``∂A_k/∂δ_m = G_m A_k − A_k G_m`` with ``G_m = ∂S_k/∂δ_m · S_k⁻¹`` a twist, so
        ``∂p/∂δ_m = (Π_{i<k} A_i) G_m (Π_{i≥k} A_i p0) − (Π_{i≤k} A_i) G_m (Π_{i>k} A_i p0)``:
        the point ``p`` moved by ``G_m`` after the prefix ``Π_{i<k}`` less moved by it after
        ``Π_{i≤k}`` (:func:`~pipeline.refine.motions.moved_by_twists`); ``∂p/∂p0`` is the
        rotation of the whole product.
        """
        x = np.asarray(x, float)
        S, G = self._frame_generators(x)
        QP, tP, p = self._chain(x, S)
        K = len(self.link)
        J = np.zeros((K, 3, self.n_params))
        if self.terms:
            J[:, :, self.beta_slice] = self._joint_tangents(S, QP, tP, p) @ self.regressor
        w, v = twists(G)  # (n, 4, 3) each
        for k in range(self.n_joints):
            a, b = self.axis_offsets[k], self.axis_offsets[k + 1]
            wk, vk = w[k, : b - a], v[k, : b - a]
            dp = moved_by_twists(QP[k], tP[k], p, wk, vk)
            dp -= moved_by_twists(QP[k + 1], tP[k + 1], p, wk, vk)
            J[:, :, a:b] = dp.transpose(2, 1, 0)
        R = by_observation(QP[-1])
        if self.n_points == 1:
            J[:, :, self.point_slice(0)] = R
        else:
            for j in range(self.n_points):
                sel = self.point == j
                J[sel, :, self.point_slice(j)] = R[sel]
        return J

    def tool_rotations(self, x: npt.ArrayLike) -> Array:
        """Rotation (K, 3, 3) of the tool frame ``(Π_k A_k) · S_n · R_c`` at every
        observation (sensor frame)."""
        x = np.asarray(x, float)
        F = self.frames(x)
        QP, _ = prefixes(self._motion(F, self.joint_values(x)), self.n_joints)
        return np.asarray(by_observation(QP[-1]) @ (F[-1, :3, :3] @ self.tool_rotation_matrix(x)))

    def tool_orientation_jacobian(self, x: npt.ArrayLike) -> Array:
        """``ω`` with ``δR = [ω]× R`` of the tool frame per parameter, shape (K, 3, n_params).

        The tool frame is ``(Π_k A_k) · S_n · R_c`` (thesis convention: ``S̄_n = S̄_{n−1}``,
        ``R_c`` = I without ``tool_rotation``); rows of observations not on link n are
        zero. A joint's ``δ`` (twist ``G``, rotation part ``w``) enters through
        ``Ξ = ∂A_k A_k⁻¹ = G − A_k G A_k⁻¹`` carried by the prefix:
        ``R_{<k} w − R_{≤k} w``, and ``δ_n`` also through ``S_n`` itself (``+ R_Π w``); the
        tool's rotation vector ``r`` (``R_c = Exp(r)``) through ``ω = R_tool · J_r(r)``
        (right Jacobian of SO(3)).
        """
        x = np.asarray(x, float)
        S, G = self._frame_generators(x)
        QP, _ = prefixes(self._motion(S, self.joint_values(x)), self.n_joints)
        K, n = len(self.link), self.n_joints
        W = np.zeros((K, 3, self.n_params))
        w, _ = twists(G)
        for k in range(n):
            a, b = self.axis_offsets[k], self.axis_offsets[k + 1]
            wk = w[k, : b - a]
            turn = rotate_constant(QP[k], wk)
            if k < n - 1:  # δ_n: − R_Π w + R_Π w
                turn -= rotate_constant(QP[k + 1], wk)
            W[:, :, a:b] = turn.transpose(2, 1, 0)
        if self.tool_rotation:
            r = x[self.rotation_slice]
            W[:, :, self.rotation_slice] = self.tool_rotations(x) @ right_jacobian(r)
        if self.terms:  # joint j turns the tool about its axis: ω = R_{<j} · S_j's z
            axis, _ = self._joint_twists(S)
            w_q = np.stack([rotate_constant(QP[j], axis[j : j + 1])[0] for j in range(n)])
            W[:, :, self.beta_slice] = w_q.transpose(2, 1, 0) @ self.regressor
        W[self.link != n] = 0.0
        return W

    def signature_frames(self, x: npt.ArrayLike, tool_point: int) -> Array:
        """``S̄_0 … S̄_n`` and the tool (n + 2, 4, 4), the rows of the ``frames`` table.

        ``S̄_n = S̄_{n−1}``; the tool is the translation of point ``tool_point`` at
        ``q̄^s`` in ``S̄_n``, with ``S̄_n``'s orientation (gauge 4 of the module docstring),
        or turned by the fitted ``R_c`` when the tool's orientation was measured.
        """
        x = np.asarray(x, float)
        F = self.frames(x)
        tool = np.eye(4)
        tool[:3, :3] = self.tool_rotation_matrix(x)
        R, o = F[-1, :3, :3], F[-1, :3, 3]
        tool[:3, 3] = R.T @ (x[self.point_slice(tool_point)] - o)
        return np.concatenate([F, F[-1:], tool[None]], axis=0)


def point_name(sweep: int, target: str, tool: str | None, sweep_tool_targets: Sequence[str]) -> str:
    """The point a measurement of ``target`` in ``sweep`` sees (module docstring).

    ``tool``: the tool point's target id (``plan.tool_target``; None: every target of the
    tool, check and pose sweeps is the tool, the single target of a session without a
    nest on the last link). ``sweep_tool_targets``: the ids the joint sweeps measure on
    the last link (``plan.tool_targets``, else ``plan.tool_target``, when
    ``plan.sweeps_measure_tool``: imports), each one point in every sweep; empty
    otherwise: a tracker's joint sweeps may reuse the tool's ids for their own nests. A
    target on the last link other than the tool is a point of its own there,
    ``tool/<target>``; any other target of a joint sweep is one of that sweep's link,
    ``sweep<j>/<target>``.
    """
    if sweep in WHOLE_ARM_SWEEPS or target in sweep_tool_targets:
        return TOOL_POINT if tool is None or target == tool else f"{TOOL_POINT}/{target}"
    return f"sweep{sweep}/{target}"


def chain_model(
    sweep: npt.NDArray[np.int64],
    target: Sequence[str],
    theta: Array,
    frames0: Array,
    prismatic: npt.NDArray[np.bool_],
    tool: str | None = None,
    sweep_tool_targets: Sequence[str] = (),
    tool_rotation: bool = False,
) -> ChainModel:
    """The model of the observations (``sweep``, ``target``) (K,), started at the thesis
    frames ``frames0`` (n, 4, 4) of the joints ``prismatic`` (n,).

    ``theta`` (K, n): each observation's joint readings minus ``q̄^s`` (rad / cm);
    ``tool``, ``sweep_tool_targets``: as in :func:`point_name`; ``tool_rotation``: the
    tool's orientation is a parameter (a 6-D sensor measured it). The stage tables are
    read by :func:`pipeline.stages.refine_problem.model_for_keys`.
    """
    n = len(prismatic)
    names = [
        point_name(int(s), str(t), tool, sweep_tool_targets)
        for s, t in zip(sweep, target, strict=True)
    ]
    point_names = tuple(dict.fromkeys(names))
    index = {p: j for j, p in enumerate(point_names)}
    on_last = np.isin(sweep, WHOLE_ARM_SWEEPS) | np.isin(np.array(target), sweep_tool_targets)
    link = np.where(on_last, n, sweep)
    if ((link < 1) | (link > n)).any():
        bad = int(sweep[(link < 1) | (link > n)][0])
        raise StageError(
            f"refine: sweep {bad} is not a joint of the {n}-joint robot",
            expected=f"joint sweeps 1..{n}, the tool and check sweeps and the pose set",
            fix="re-record the session",
        )
    return ChainModel(
        frames0=frames0,
        prismatic=prismatic,
        link=link.astype(np.int64),
        theta=theta,
        point=np.array([index[p] for p in names], np.int64),
        point_names=point_names,
        tool_rotation=tool_rotation,
    )


def start_points(model: ChainModel, p_measured: npt.ArrayLike) -> Array:
    """Start ``p0`` of every point (n_points, 3): the mean over its observations of the
    measured position carried back to ``q̄^s`` by the start chain (``δ = 0``).

    Rows of ``p_measured`` (K, 3) with a NaN are skipped; a point with no usable
    observation is a one-line :class:`StageError`.
    """
    p = np.asarray(p_measured, float)
    x0 = np.zeros(model.n_params)
    QP, tP = prefixes(model._motion(model.frames(x0), model.theta), model.n_joints)
    back = (QP[-1] * (p.T - tP[-1])[None]).sum(axis=1).T  # Rᵀ (p − t): columns · (p − t)
    ok = np.isfinite(back).all(axis=1)
    out = np.zeros((model.n_points, 3))
    for j, name in enumerate(model.point_names):
        sel = ok & (model.point == j)
        if not sel.any():
            raise StageError(
                f"refine: point {name} has no usable measurement",
                expected="at least one finite position of every target point",
                fix="re-record that sweep, or run with --param refine.enabled=false",
            )
        out[j] = back[sel].mean(axis=0)
    return out
