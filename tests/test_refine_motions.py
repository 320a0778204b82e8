"""The chain model's closed forms (:mod:`pipeline.refine.motions`) against the 4 × 4 matrix
products they replaced (issue 45): positions, both Jacobians, the tool rotations and the
joint differences, on random chains with prismatic joints, a point on every link,
non-geometric terms and the tool's rotation."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt
import pytest

from pipeline.kinematics.nongeometric import Terms
from pipeline.kinematics.so3 import right_jacobian
from pipeline.kinematics.transforms import invert_transform, rot_z, trans_z
from pipeline.refine.kinematics import ChainModel
from pipeline.refine.motions import vee as _vee
from tests.test_refine_kinematics import _model

Array = np.ndarray
_GZ = np.zeros((4, 4))
_GZ[0, 1], _GZ[1, 0] = -1.0, 1.0
_GT = np.zeros((4, 4))
_GT[2, 3] = 1.0


@dataclass(frozen=True, eq=False)
class Products(ChainModel):
    """The model as it was formed before issue 45: (K, n, 4, 4) stacks of
    ``S_k M_k(θ) S_k⁻¹`` and their matrix products (the reference)."""

    def _points_h(self, x: Array) -> Array:
        p0 = x[self.n_axis_params : self.n_axis_params + 3 * self.n_points]
        p0 = p0.reshape(self.n_points, 3)[self.point]
        return np.concatenate([p0, np.ones((len(p0), 1))], axis=1)

    def _motions4(self, S: Array, theta: Array) -> Array:
        n, K = self.n_joints, len(self.link)
        M = np.where(
            self.prismatic[None, :, None, None], trans_z(theta), rot_z(theta)
        )  # (K, n, 4, 4)
        A = S @ M @ invert_transform(S)
        moving = np.arange(1, n + 1)[None, :] <= self.link[:, None]
        A[~moving] = np.eye(4)
        return A.reshape(K, n, 4, 4)

    def _points_h(self, x: Array) -> Array:
        p0 = x[self.n_axis_params : self.n_axis_params + 3 * self.n_points]
        p0 = p0.reshape(self.n_points, 3)
        p0 = p0[self.point]
        return np.concatenate([p0, np.ones((len(p0), 1))], axis=1)

    def positions(self, x: npt.ArrayLike) -> Array:
        x = np.asarray(x, float)
        A = self._motions4(self.frames(x), self.joint_values(x))
        v = self._points_h(x)
        for k in range(self.n_joints - 1, -1, -1):
            v = (A[:, k] @ v[..., None])[..., 0]
        return v[:, :3]

    def joint_differences(self, x: npt.ArrayLike, h: float) -> Array:
        x = np.asarray(x, float)
        theta = self.joint_values(x)
        S = self.frames(x)
        A = self._motions4(S, theta)
        S_inv = invert_transform(S)
        v = self._points_h(x)
        K, n = theta.shape
        out = np.zeros((K, n, 3))
        for k in range(n - 1, -1, -1):  # v: Π_{i>k} A_i p0, as positions() forms it
            still = np.arange(K)[k + 1 > self.link]
            ends = []
            for t in (theta[:, k] + h, theta[:, k] - h):
                Ak = S[k] @ (trans_z(t) if self.prismatic[k] else rot_z(t)) @ S_inv[k]
                Ak[still] = np.eye(4)
                w = (Ak @ v[..., None])[..., 0]
                for i in range(k - 1, -1, -1):
                    w = (A[:, i] @ w[..., None])[..., 0]
                ends.append(w[:, :3])
            out[:, k] = (ends[0] - ends[1]) / (2.0 * h)
            v = (A[:, k] @ v[..., None])[..., 0]
        return out

    def _prefix_suffix(self, A: Array, v0: Array) -> tuple[Array, Array]:
        K, n = A.shape[:2]
        pre = np.empty((K, n + 1, 4, 4))
        pre[:, 0] = np.eye(4)
        for k in range(n):
            pre[:, k + 1] = pre[:, k] @ A[:, k]
        suf = np.empty((K, n, 4))
        v = v0
        for k in range(n - 1, -1, -1):
            suf[:, k] = v
            v = (A[:, k] @ v[..., None])[..., 0]
        return pre, suf

    def _joint_generators(self, S: Array) -> Array:
        G = np.where(self.prismatic[:, None, None], _GT, _GZ)
        return np.asarray(S @ G @ invert_transform(S), float)

    def _joint_tangents(self, S: Array, A: Array, pre: Array, suf: Array) -> Array:
        Gh = self._joint_generators(S)
        moved = np.einsum("knij,knj->kni", A, suf)  # Π_{i≥j} A_i p0, (K, n, 4)
        t = np.einsum("nij,knj->kni", Gh[:, :3], moved)  # (K, n, 3)
        t = np.einsum("knij,knj->kni", pre[:, :-1, :3, :3], t)
        t[np.arange(1, self.n_joints + 1)[None, :] > self.link[:, None]] = 0.0
        return np.swapaxes(t, 1, 2)

    def position_jacobian(self, x: npt.ArrayLike) -> Array:
        x = np.asarray(x, float)
        S, G = self._frame_generators(x)
        A = self._motions4(S, self.joint_values(x))
        pre, suf = self._prefix_suffix(A, self._points_h(x))
        K = len(self.link)
        J = np.zeros((K, 3, self.n_params))
        if self.terms:
            J[:, :, self.beta_slice] = self._joint_tangents(S, A, pre, suf) @ self.regressor
        for k in range(self.n_joints):
            a, b = self.axis_offsets[k], self.axis_offsets[k + 1]
            Gk = G[k, : b - a, :3]  # (m, 3, 4): only the rows that reach p's 3 coordinates
            moved = np.einsum("kij,kj->ki", A[:, k], suf[:, k])  # Π_{i≥k} A_i p0
            # (K, 3, m); G's last row is 0, so the prefixes' rotations suffice. Two products
            # of two operands each: one three-operand einsum looped in C over all K·3·m·3·4
            # terms and took a third of a 2,000-pose fit.
            Gm = moved @ Gk.reshape(-1, 4).T  # (K, m·3): G_m (Π_{i≥k} A_i p0)
            Gs = suf[:, k] @ Gk.reshape(-1, 4).T  # (K, m·3): G_m (Π_{i>k} A_i p0)
            m = b - a
            dp = pre[:, k, :3, :3] @ Gm.reshape(-1, m, 3).transpose(0, 2, 1) - pre[
                :, k + 1, :3, :3
            ] @ Gs.reshape(-1, m, 3).transpose(0, 2, 1)
            J[:, :, a:b] = dp
        R = pre[:, -1, :3, :3]
        for j in range(self.n_points):
            sel = self.point == j
            J[sel, :, self.point_slice(j)] = R[sel]
        return J

    def tool_rotations(self, x: npt.ArrayLike) -> Array:
        x = np.asarray(x, float)
        F = self.frames(x)
        A = self._motions4(F, self.joint_values(x))
        R = np.broadcast_to(np.eye(3), (len(self.link), 3, 3)).copy()
        for k in range(self.n_joints):
            R = R @ A[:, k, :3, :3]
        return np.asarray(R @ F[-1, :3, :3] @ self.tool_rotation_matrix(x))

    def tool_orientation_jacobian(self, x: npt.ArrayLike) -> Array:
        x = np.asarray(x, float)
        S, G = self._frame_generators(x)
        A = self._motions4(S, self.joint_values(x))
        pre, _ = self._prefix_suffix(A, self._points_h(x))
        K, n = len(self.link), self.n_joints
        W = np.zeros((K, 3, self.n_params))
        A_inv = invert_transform(A)
        for k in range(n):
            a, b = self.axis_offsets[k], self.axis_offsets[k + 1]
            Gk = G[k, : b - a]
            Xi = Gk[None] - A[:, k, None] @ Gk[None] @ A_inv[:, k, None]  # (K, m, 4, 4)
            w = (pre[:, k, None, :3, :3] @ _vee(Xi[..., :3, :3])[..., None])[..., 0]  # (K, m, 3)
            W[:, :, a:b] = np.swapaxes(w, 1, 2)
        a, b = self.axis_offsets[n - 1], self.axis_offsets[n]
        w_n = (pre[:, -1, None, :3, :3] @ _vee(G[n - 1, : b - a, :3, :3])[None, ..., None])[..., 0]
        W[:, :, a:b] += np.swapaxes(w_n, 1, 2)
        if self.tool_rotation:
            r = x[self.rotation_slice]
            W[:, :, self.rotation_slice] = self.tool_rotations(x) @ right_jacobian(r)
        if self.terms:  # joint j turns the tool about its axis: ω = R_{<j} · S_j's z
            axis = np.where(self.prismatic[:, None], 0.0, S[:, :3, 2])  # (n, 3)
            w_q = np.einsum("knij,nj->kin", pre[:, :-1, :3, :3], axis)  # (K, 3, n)
            W[:, :, self.beta_slice] = w_q @ self.regressor
        W[self.link != n] = 0.0
        return W


CASES = [[False] * 6, [False, False, True, False], [True, False, False]]


def _models(prismatic: list[bool], seed: int) -> tuple[ChainModel, ChainModel, np.ndarray]:
    """A random model with terms and the tool's rotation, its reference, and an ``x``."""
    rng = np.random.default_rng(seed)
    rigid = _model(rng, prismatic)
    n = rigid.n_joints
    terms = Terms(compliance=((1, 2), (2, 2)), harmonic=((1, "cos"), (n, "sin")))
    m = replace(rigid, terms=terms, tool_rotation=True)
    m.__dict__["regressor"] = rng.normal(0.0, 0.05, (len(rigid.link), n, terms.size))
    ref = Products(**{f: getattr(m, f) for f in m.__dataclass_fields__})
    ref.__dict__["regressor"] = m.regressor
    x = rng.normal(0.0, 0.05, m.n_params)
    x[m.n_axis_params : m.rotation_slice.start] = rng.uniform(-80.0, 80.0, 3 * m.n_points)
    x[m.rotation_slice] = rng.normal(0.0, 0.5, 3)
    return m, ref, x


@pytest.mark.parametrize("prismatic", CASES)
def test_closed_forms_equal_the_matrix_products(prismatic: list[bool]) -> None:
    m, ref, x = _models(prismatic, 7)
    assert (m.link < m.n_joints).any() and (m.link == m.n_joints).any()
    for f, tol in (
        ("positions", 1e-12),
        ("position_jacobian", 1e-12),
        ("tool_rotations", 1e-14),
        ("tool_orientation_jacobian", 1e-13),
    ):
        new, old = getattr(m, f)(x), getattr(ref, f)(x)
        assert new.shape == old.shape
        scale = max(1.0, float(np.abs(old).max()))
        np.testing.assert_allclose(new, old, rtol=0, atol=tol * scale, err_msg=f)


@pytest.mark.parametrize("prismatic", CASES)
def test_joint_differences_equal_the_matrix_products_and_the_moved_positions(
    prismatic: list[bool],
) -> None:
    """Without terms (the method's domain): equal to the old form to its rounding
    (differences of positions over 2h), and each is exactly the difference of
    :meth:`positions` with one joint moved."""
    m, ref, x = _models(prismatic, 8)
    rigid = replace(m, terms=Terms(), tool_rotation=False)
    old = replace(ref, terms=Terms(), tool_rotation=False)
    xr = x[: rigid.n_params]
    h = 1e-6
    new = rigid.joint_differences(xr, h)
    np.testing.assert_allclose(new, old.joint_differences(xr, h), rtol=0, atol=1e-7)
    for k in range(rigid.n_joints):
        step = np.zeros_like(rigid.theta)
        step[:, k] = h
        up = replace(rigid, theta=rigid.theta + step).positions(xr)
        down = replace(rigid, theta=rigid.theta - step).positions(xr)
        np.testing.assert_array_equal(new[:, k], (up - down) / (2.0 * h))


def test_a_pose_set_on_the_last_link_and_a_chunk_of_rows() -> None:
    """Every observation on link n (no masking), and ``observing`` a chunk of rows: the
    chunk's positions and Jacobian are the whole model's rows."""
    m, ref, x = _models([False] * 6, 9)
    m, ref = replace(m, terms=Terms()), replace(ref, terms=Terms())  # Φ from the design
    x = x[: m.n_params]
    n = m.n_joints
    last, ref_last = m.observing(m.link == n), ref.observing(ref.link == n)
    scale = float(np.abs(ref_last.position_jacobian(x)).max())
    np.testing.assert_allclose(
        last.position_jacobian(x), ref_last.position_jacobian(x), rtol=0, atol=1e-12 * scale
    )
    rows = np.arange(5, 30)
    np.testing.assert_array_equal(m.observing(rows).positions(x), m.positions(x)[rows])
    np.testing.assert_allclose(
        m.observing(rows).position_jacobian(x), m.position_jacobian(x)[rows], rtol=0, atol=1e-13
    )
