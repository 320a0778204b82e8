"""Predicted tool accuracy: the refinement's parameter covariance carried to the tool.

A parameter error ``δθ ~ N(0, Σ)`` (``Σ``: the refinement's covariance of the
:class:`~pipeline.refine.kinematics.ChainModel` parameters) moves the tool at a
configuration ``i`` by ``δp_i = J_i δθ`` and turns it by ``ω_i = W_i δθ``
(``δR = [ω]× R``). Its predicted error is the RMS length of that 3-D error:

    ``σ_i = sqrt(trace(J_i Σ J_iᵀ))``                                   (raw)

**Aligned.** The audit (:mod:`pipeline.rig.audit`) compares a model with the truth after
the best-fit constant base ``X`` and tool ``Y`` (:func:`~pipeline.kinematics.alignment.
fit_alignment`), so part of ``δθ`` never shows there. To first order ``X = I + [ω_b, v_b]``
and ``Y = I + [ω_t, v_t]`` add to the tool pose

    ``δp_i += v_b + ω_b × p_i + R_i v_t``,   ``ω_i += ω_b + R_i ω_t``

with ``p_i, R_i`` the tool pose: twelve directions ``G_i`` (6 × 12) per configuration.
The audit's residual weighs a rotation error on a lever of ``L`` =
:data:`~pipeline.kinematics.alignment.LEVER_CM` per rotation-matrix entry, and
``‖[ω]× R‖_F = √2 |ω|``, so it fits in the metric ``e_i = [δp_i; √2 L ω_i]``. Stacked over
the m configurations, ``e = A δθ`` and the fit removes its projection on the span of
``G``: the aligned error is ``P A δθ`` with ``P = I − Q Qᵀ`` (``Q``: orthonormal basis of
``G``'s columns, dropping the directions the audit also treats as symmetries,
:data:`~pipeline.kinematics.alignment.GAUGE_RCOND`), and with ``B = P A``

    ``σ_i^aligned = sqrt(trace(B_i Σ B_iᵀ))`` (position rows of ``B_i``).

Summaries over the m configurations: RMS, 95th percentile and max of ``σ_i``, and
``max95``: the 95th percentile, over draws of ``δθ``, of the largest aligned position
error among the configurations (the bound the audit's max error should stay under).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from pipeline.kinematics.alignment import GAUGE_RCOND, LEVER_CM
from pipeline.refine.kinematics import TOOL_POINT, ChainModel

Array = npt.NDArray[np.float64]

#: Draws of ``δθ`` for :attr:`Prediction.max95_cm`: the 95th percentile of 400 draws
#: is within ~2 % (its binomial standard error ~ sqrt(.95 · .05 / 400) = 1 % in rank).
MAX_DRAWS = 400
#: Weight of a rotation in the alignment metric: √2 · lever (module docstring).
_ROT_WEIGHT = np.sqrt(2.0) * LEVER_CM


@dataclass(frozen=True)
class Prediction:
    """Predicted 1σ RMS tool errors per configuration (cm, deg), raw and aligned."""

    position_cm: Array
    position_aligned_cm: Array
    orientation_deg: Array
    orientation_aligned_deg: Array
    max95_cm: float

    def summary(self) -> dict[str, float]:
        """RMS, 95th percentile and max of each error, and ``max95_cm``."""
        out = {"max95_cm": self.max95_cm}
        for f in dataclasses.fields(self):
            if f.name != "max95_cm":
                v = getattr(self, f.name)
                unit = f.name.rsplit("_", 1)[1]
                stem = f.name.removesuffix("_" + unit)
                out[f"{stem}_rms_{unit}"] = float(np.sqrt(np.mean(v**2)))
                out[f"{stem}_p95_{unit}"] = float(np.percentile(v, 95))
                out[f"{stem}_max_{unit}"] = float(v.max())
        return out


def _skew(v: Array) -> Array:
    """[v]× of every row of (m, 3), shape (m, 3, 3)."""
    S = np.zeros((*v.shape[:-1], 3, 3))
    S[..., 0, 1], S[..., 0, 2], S[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    return S - np.swapaxes(S, -1, -2)


def alignment_directions(p: Array, R: Array) -> Array:
    """The base and tool re-alignment ``G`` (m, 6, 12) in the metric ``[δp; √2 L ω]``.

    Columns: base translation ``v_b``, base rotation ``ω_b``, tool translation ``v_t``
    (in the tool frame), tool rotation ``ω_t`` (tool frame); module docstring.
    """
    m = len(p)
    G = np.zeros((m, 6, 12))
    G[:, :3, 0:3] = np.eye(3)
    G[:, :3, 3:6] = -_skew(p)  # ω_b × p
    G[:, :3, 6:9] = R
    G[:, 3:, 3:6] = _ROT_WEIGHT * np.eye(3)
    G[:, 3:, 9:12] = _ROT_WEIGHT * R
    return G


def project_out_alignment(A: Array, G: Array) -> Array:
    """``(I − Q Qᵀ) A`` for stacked errors ``A`` (m, 6, P) and directions ``G`` (m, 6, 12)."""
    Gs = G.reshape(-1, G.shape[-1])
    U, s, _ = np.linalg.svd(Gs, full_matrices=False)
    Q = U[:, s > GAUGE_RCOND * s[0]]
    As = A.reshape(-1, A.shape[-1])
    return (As - Q @ (Q.T @ As)).reshape(A.shape)


def _sqrt_psd(Sigma: Array) -> Array:
    """``F`` with ``F Fᵀ = Σ`` (symmetric part; tiny negative eigenvalues of round-off as 0)."""
    w, V = np.linalg.eigh(0.5 * (Sigma + Sigma.T))
    out: Array = V * np.sqrt(np.clip(w, 0.0, None))
    return out


def error_maps(J_pos: Array, J_rot: Array, p: Array, R: Array) -> tuple[Array, Array]:
    """Tool error per unit of each parameter, raw ``A`` and aligned ``B = P A`` (m, 6, P).

    Rows ``[δp; √2 L ω]`` (module docstring) from ``J_pos, J_rot`` (m, 3, P): ``∂p/∂θ``
    (cm per unit) and ``ω`` per unit (rad); ``p, R`` (m, 3), (m, 3, 3): the tool poses.
    """
    A = np.concatenate([J_pos, _ROT_WEIGHT * J_rot], axis=1)
    return A, project_out_alignment(A, alignment_directions(p, R))


def predict(A: Array, B: Array, Sigma: Array, seed: int = 0) -> Prediction:
    """Predicted errors from the :func:`error_maps` and the covariance ``Sigma`` (P, P) of
    θ; ``seed``: of the draws of :attr:`Prediction.max95_cm`."""
    F = _sqrt_psd(np.asarray(Sigma, float))
    AF, BF = A @ F, B @ F

    def rms(M: Array) -> Array:  # sqrt(trace(M Mᵀ)) per configuration
        return np.sqrt(np.einsum("mij,mij->m", M, M))

    z = np.random.default_rng(seed).standard_normal((F.shape[1], MAX_DRAWS))
    worst = np.linalg.norm(BF[:, :3] @ z, axis=1).max(axis=0)  # (draws,)
    return Prediction(
        position_cm=rms(AF[:, :3]),
        position_aligned_cm=rms(BF[:, :3]),
        orientation_deg=np.degrees(rms(AF[:, 3:]) / _ROT_WEIGHT),
        orientation_aligned_deg=np.degrees(rms(BF[:, 3:]) / _ROT_WEIGHT),
        max95_cm=float(np.percentile(worst, 95)),
    )


def tool_model(model: ChainModel, theta: Array) -> ChainModel:
    """``model`` observing only its tool point, at configurations ``theta`` (m, n) (no
    payload on the flange, when the model has non-geometric terms)."""
    j = model.point_names.index(TOOL_POINT)
    return dataclasses.replace(
        model,
        link=np.full(len(theta), model.n_joints, np.int64),
        theta=np.asarray(theta, float),
        point=np.full(len(theta), j, np.int64),
        payload_kg=None,
    )


def tool_poses(model: ChainModel, x: Array) -> tuple[Array, Array]:
    """Tool position (m, 3) and orientation (m, 3, 3) of a :func:`tool_model` at ``x``:
    the tool point and ``(Π A_k) · S_n``'s rotation (gauge 4 of the model)."""
    from pipeline.kinematics.chain import forward_kinematics
    from pipeline.kinematics.signature import signature_chain

    F = model.signature_frames(x, model.point_names.index(TOOL_POINT))
    n = model.n_joints
    chain = signature_chain(F[: n + 1], np.zeros(n), model.prismatic, F[n + 1])
    T = forward_kinematics(chain, model.joint_values(x))  # deflected by the terms, if any
    return T[:, :3, 3], T[:, :3, :3]


def model_error_maps(model: ChainModel, x: Array) -> tuple[Array, Array]:
    """:func:`error_maps` of a :func:`tool_model` at ``x``."""
    p, R = tool_poses(model, x)
    return error_maps(model.position_jacobian(x), model.tool_orientation_jacobian(x), p, R)


def predict_model(model: ChainModel, x: Array, Sigma: Array, seed: int = 0) -> Prediction:
    """:func:`predict` for a :func:`tool_model` at ``x`` with covariance ``Sigma`` of ``x``."""
    return predict(*model_error_maps(model, x), Sigma, seed)
