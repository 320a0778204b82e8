"""The refinement's kinematic model: joint axis lines and target points (issue 15).

STAND-IN written by helper ``refinecore`` against the API of /work/notes/common15.md so the
solver and stages can be built and tested before the integrator's module lands; the
integrator's ``pipeline/refine/kinematics.py`` replaces this file on merge.

Product of exponentials at the signature configuration q̄^s: a point fixed on link ℓ is at
``p(q) = A_1(θ_1) ⋯ A_ℓ(θ_ℓ) · p0``, ``A_k(θ) = S_k M_k(θ) S_k⁻¹``, ``θ = q − q̄^s``,
``S_k = S̄_{k−1}``; ``S_k(δ) = S_k⁰ · Trans(tx, ty, 0) · Rot_x(rx) · Rot_y(ry)``.
Point ids: ``tool`` is point 0 (see :func:`model_for_keys`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pyarrow as pa

from pipeline.kinematics.transforms import invert_transform, rot_x, rot_y, rot_z, trans, trans_z

Array = npt.NDArray[np.float64]
TOOL_POINT = "tool"


def _hat(w: Array) -> Array:
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def _local(delta: Array, prismatic: bool) -> tuple[Array, Array]:
    """``E(δ)`` (4, 4) and the generators ``E⁻¹ ∂E/∂δ_i`` (len(δ), 4, 4)."""
    rx, ry = delta[0], delta[1]
    tx, ty = (0.0, 0.0) if prismatic else (delta[2], delta[3])
    E = trans(tx, ty, 0.0) @ rot_x(rx) @ rot_y(ry)
    R = E[:3, :3]
    Ry = rot_y(ry)[:3, :3]
    G = np.zeros((len(delta), 4, 4))
    G[0, :3, :3] = _hat(Ry.T @ np.array([1.0, 0.0, 0.0]))
    G[1, :3, :3] = _hat(np.array([0.0, 1.0, 0.0]))
    if not prismatic:
        G[2, :3, 3] = R.T @ np.array([1.0, 0.0, 0.0])
        G[3, :3, 3] = R.T @ np.array([0.0, 1.0, 0.0])
    return E, G


@dataclass(frozen=True)
class ChainModel:
    """Axis lines of the joints and target points; see the module docstring."""

    frames0: Array
    prismatic: npt.NDArray[np.bool_]
    link: npt.NDArray[np.int64]
    theta: Array
    point: npt.NDArray[np.int64]
    n_points: int

    @property
    def n_axis_params(self) -> int:
        return int(sum(2 if p else 4 for p in self.prismatic))

    @property
    def n_params(self) -> int:
        return self.n_axis_params + 3 * self.n_points

    @property
    def axis_params(self) -> slice:
        return slice(0, self.n_axis_params)

    def point_params(self, j: int) -> slice:
        a = self.n_axis_params + 3 * j
        return slice(a, a + 3)

    def _axis_slices(self) -> list[slice]:
        out, a = [], 0
        for p in self.prismatic:
            out.append(slice(a, a + (2 if p else 4)))
            a += 2 if p else 4
        return out

    @property
    def param_names(self) -> tuple[str, ...]:
        names = []
        for k, p in enumerate(self.prismatic, start=1):
            names += [f"joint{k}.{c}" for c in (("rx", "ry") if p else ("rx", "ry", "tx", "ty"))]
        names += [f"point{j}.{c}" for j in range(self.n_points) for c in "xyz"]
        return tuple(names)

    @property
    def param_units(self) -> tuple[str, ...]:
        units = []
        for p in self.prismatic:
            units += ["rad", "rad"] + ([] if p else ["cm", "cm"])
        units += ["cm"] * (3 * self.n_points)
        return tuple(units)

    def frames(self, x: Array) -> Array:
        """``S_k(δ_k)``, (n, 4, 4)."""
        return np.stack(
            [
                self.frames0[k] @ _local(x[s], bool(self.prismatic[k]))[0]
                for k, s in enumerate(self._axis_slices())
            ]
        )

    def _motions(self, S: Array) -> Array:
        """``M_k(θ)`` (K, n, 4, 4)."""
        th = self.theta
        M = np.empty((*th.shape, 4, 4))
        for k, p in enumerate(self.prismatic):
            M[:, k] = trans_z(th[:, k]) if p else rot_z(th[:, k])
        return M

    def _prefix(self, x: Array) -> tuple[Array, Array, Array, Array]:
        S = self.frames(x)
        Sinv = invert_transform(S)
        M = self._motions(S)
        K, n = self.theta.shape
        F = np.tile(np.eye(4), (K, n + 1, 1, 1))
        for k in range(n):
            A = S[k] @ M[:, k] @ Sinv[k]
            # keys on earlier links stop moving: F_k = F_{k-1} beyond their link
            on = (self.link > k)[:, None, None]
            F[:, k + 1] = np.where(on, F[:, k] @ A, F[:, k])
        return S, Sinv, M, F

    def _p0(self, x: Array) -> Array:
        a = self.n_axis_params
        return x[a:].reshape(self.n_points, 3)

    def positions(self, x: Array) -> Array:
        """Predicted target positions (K, 3), sensor frame (cm)."""
        F = self._prefix(x)[3][:, -1]
        p0 = self._p0(x)[self.point]
        return np.einsum("kij,kj->ki", F[:, :3, :3], p0) + F[:, :3, 3]

    def _derivatives(self, x: Array, orientation: bool = False) -> tuple[Array, Array]:
        """``∂p/∂x`` (K, 3, P) and the tool's ``ω`` per parameter (K, 3, P)."""
        S, Sinv, M, F = self._prefix(x)
        K, n = self.theta.shape
        p = self.positions(x)
        ph = np.concatenate([p, np.ones((K, 1))], axis=1)
        J = np.zeros((K, 3, self.n_params))
        W = np.zeros((K, 3, self.n_params))
        for k, s in enumerate(self._axis_slices()):
            on = self.link > k
            _, G = _local(x[s], bool(self.prismatic[k]))
            Fk_inv = invert_transform(F[:, k + 1])
            u = np.einsum("ij,kjl,kl->ki", Sinv[k], Fk_inv, ph)  # S⁻¹ F_k⁻¹ p
            L = F[:, k] @ S[k]  # F_{k-1} S_k
            for i in range(G.shape[0]):
                C = G[i] @ M[:, k] - M[:, k] @ G[i]  # [G_i, M_k]
                dp = np.einsum("kij,kjl,kl->ki", L, C, u)[:, :3]
                J[:, :, s.start + i] = np.where(on[:, None], dp, 0.0)
                if not orientation:
                    continue
                D = L @ C @ Sinv[k] @ Fk_inv  # dF_n F_n⁻¹
                w = np.stack([D[:, 2, 1], D[:, 0, 2], D[:, 1, 0]], axis=1)
                W[:, :, s.start + i] = np.where((self.link == n)[:, None], w, 0.0)
        R = F[:, -1, :3, :3]
        for j in range(self.n_points):
            at = self.point == j
            J[at, :, self.point_params(j)] = R[at]
        return J, W

    def position_jacobian(self, x: Array) -> Array:
        """``∂p/∂x`` (K, 3, n_params)."""
        return self._derivatives(x)[0]

    def tool_orientation_jacobian(self, x: Array) -> Array:
        """``ω`` with ``δR = [ω]× R`` per parameter (K, 3, n_params); zero off link n."""
        return self._derivatives(x, orientation=True)[1]


def model_for_keys(
    keys: pa.Table, session: pa.Table, joints: pa.Table, frames_table: pa.Table
) -> tuple[ChainModel, list[str]]:
    """The model of the positions ``keys`` (sweep, step, target); point ids, ``tool`` first."""
    from pipeline.stages.frames import matrices_from_columns, readings_at
    from pipeline.stages.session import session_plan, session_robot
    from pipeline.units import joints_to_internal

    robot = session_robot(session)
    plan = session_plan(session)
    n, pris = robot.n_joints, robot.prismatic
    deg = frames_table.column("q_signature_deg").to_numpy(zero_copy_only=False)[1 : n + 1]
    cm = frames_table.column("q_signature_cm").to_numpy(zero_copy_only=False)[1 : n + 1]
    qs = joints_to_internal(np.where(pris, cm, deg).astype(float), pris)
    sweep = keys.column("sweep").to_numpy().astype(np.int64)
    step = keys.column("step").to_numpy().astype(np.int64)
    target = keys.column("target").to_pylist()
    tool_target = plan.get("tool_target")
    on_tool = plan.get("sweeps_measure_tool", False)
    ids = [TOOL_POINT]
    point = np.zeros(len(sweep), np.int64)
    link = np.full(len(sweep), n, np.int64)
    for r, (s, t) in enumerate(zip(sweep, target, strict=True)):
        if s <= 0 or (on_tool and t == tool_target):
            continue
        pid = f"sweep{s}/{t}"
        if pid not in ids:
            ids.append(pid)
        point[r], link[r] = ids.index(pid), s
    theta = np.zeros((len(sweep), n))
    for s in np.unique(sweep):
        at = sweep == s
        q = readings_at(joints, int(s), step[at], n, pris)
        theta[at] = joints_to_internal(q, pris) - qs
    F = matrices_from_columns(frames_table)[:n]
    return ChainModel(F, pris, link, theta, point, len(ids)), ids


def start_points(model: ChainModel, p_measured: Array) -> Array:
    """``p0`` (n_points, 3) from measured positions (NaN rows skipped) with δ = 0."""
    x = np.zeros(model.n_params)
    F = model._prefix(x)[3][:, -1]
    local = np.einsum("kji,kj->ki", F[:, :3, :3], p_measured - F[:, :3, 3])
    out = np.full((model.n_points, 3), np.nan)
    ok = np.isfinite(local).all(axis=1)
    for j in range(model.n_points):
        at = ok & (model.point == j)
        if at.any():
            out[j] = local[at].mean(axis=0)
    return out


def refined_frames_table(model: ChainModel, x: Array, frames_table: pa.Table) -> pa.Table:
    """The frames schema from a fit: gauge (2) of common15.md; tool = point 0."""
    from pipeline.stages.frames import matrices_from_columns, matrices_to_columns

    T0 = matrices_from_columns(frames_table)
    n = len(model.prismatic)
    S = model.frames(x)
    out = T0.copy()
    for k in range(n):
        z = S[k, :3, 2]
        o = T0[k, :3, 3]
        if not model.prismatic[k]:
            c = S[k, :3, 3]
            o = c + np.dot(o - c, z) * z  # foot of the thesis origin on the refined axis
        xa = T0[k, :3, 0] - np.dot(T0[k, :3, 0], z) * z
        xa /= np.linalg.norm(xa)
        out[k, :3, :3] = np.stack([xa, np.cross(z, xa), z], axis=1)
        out[k, :3, 3] = o
    out[n] = out[n - 1]
    tool = np.eye(4)
    p_tool = x[model.point_params(0)]
    tool[:3, 3] = out[n, :3, :3].T @ (p_tool - out[n, :3, 3])
    out[n + 1] = tool
    cols = matrices_to_columns(out)
    return pa.table(
        {
            "frame": frames_table.column("frame"),
            "kind": frames_table.column("kind"),
            "from_joint": frames_table.column("from_joint"),
            **{k: pa.array(v) for k, v in cols.items()},
            "q_signature_deg": frames_table.column("q_signature_deg"),
            "q_signature_cm": frames_table.column("q_signature_cm"),
        }
    )
