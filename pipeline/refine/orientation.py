"""Measured tool orientations: three residuals per 6-D measurement (issue 26).

A 6-D sensor (a laser tracker's T-Mac, a camera) measures the tool's frame, ``R_m``, with
its position. The chain predicts the tool frame ``R = (Π_k A_k) · S_n · R_c``
(:meth:`~pipeline.refine.kinematics.ChainModel.tool_rotations`, ``R_c = Exp(r)`` the tool
in ``S_n``), and the residual is the rotation between them in the tool frame, in σ:

    ``e = Log(Rᵀ R_m) / σ``,   ``∂e/∂x ≈ −Rᵀ Ω / σ``

with ``Ω`` (3, P) the tool frame's ``ω`` per parameter (``δR = [ω]× R``,
:meth:`~pipeline.refine.kinematics.ChainModel.tool_orientation_jacobian`); the derivative
drops the right Jacobian of ``Log`` at ``e``, exact at ``e = 0`` (where noiseless data and
the solution's expansion are), so Gauss-Newton still ends at the exact fit. ``σ`` is
the recorded ``orientation_sigma_deg`` of each measurement, per rotation-vector component.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from pipeline.kinematics.so3 import vector_from_rotation
from pipeline.optim.block import Array
from pipeline.refine.kinematics import ChainModel


@dataclass(frozen=True)
class OrientationRows:
    """Measured tool orientations.

    Attributes
    ----------
    index : ndarray of int, shape (K_o,)
        The model observation (block position) of the tool point each was measured with.
    measured : ndarray, shape (K_o, 3, 3)
        ``R_m``, sensor frame.
    sigma_rad : ndarray, shape (K_o,)
        σ of each rotation-vector component (rad).
    """

    index: npt.NDArray[np.int64]
    measured: Array
    sigma_rad: Array

    def linearize(self, model: ChainModel, x: Array) -> tuple[Array, Array]:
        """Residuals (3 K_o,) and ``∂r/∂x`` (3 K_o, P) at ``x`` (module docstring)."""
        R = model.tool_rotations(x)[self.index]
        e = vector_from_rotation(np.swapaxes(R, 1, 2) @ self.measured)
        W = model.tool_orientation_jacobian(x)[self.index]  # (K_o, 3, P)
        d = -(np.swapaxes(R, 1, 2) @ W) / self.sigma_rad[:, None, None]
        r = e / self.sigma_rad[:, None]
        return r.reshape(-1), d.reshape(-1, d.shape[-1])


def start_rotation(model: ChainModel, x: Array, rows: OrientationRows) -> Array:
    """The start of the tool's rotation vector: ``Log`` of the chordal mean of
    ``R_Fᵀ R_m`` over the measurements (``R_F`` the start chain's frame without ``R_c``),
    projected onto SO(3) by SVD (the closest rotation in Frobenius norm)."""
    x = np.asarray(x, float).copy()
    x[model.rotation_slice] = 0.0
    R_F = model.tool_rotations(x)[rows.index]
    U, _, Vt = np.linalg.svd(np.sum(np.swapaxes(R_F, 1, 2) @ rows.measured, axis=0))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    return vector_from_rotation(U @ D @ Vt)
