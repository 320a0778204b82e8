"""Do targets fixed in the world move beyond their noise? The test that decides whether
import registers a pose set by them (``fixed_correction = "auto"``, docs/import.md, Fixed
targets).

Each reading ``m`` of fixed target ``f`` at pose ``r`` is its place ``b_f`` seen through
the tracker's placement at that pose; the drift is a rigid motion, tiny (µm over a
metre), so to first order ``m − ref_f = β_f + t_B + ω_B × (ref_f − c) + e`` with ``ref``
the targets' reference places, ``c`` their centroid, ``β_f`` each target's offset and
``(t_B, ω_B)`` the motion of block ``B``: the poses in file order in blocks of ``k`` (the
correction's ``fixed_block``, the scale at which it estimates the motion). Against no
motion (every reading its target's mean plus noise), the least-squares fit of the block
motions explains ``RSS0 − RSS1`` of the readings' sum of squares with ``d1 = Σ rank − 6``
more parameters (a motion common to all blocks is each target's offset); what it leaves,
``RSS1``, has ``d2`` degrees of freedom (three per reading, less the parameters). For
independent isotropic Gaussian noise of any σ, ``(RSS0 − RSS1)/d1 / (RSS1/d2)`` follows
F(d1, d2) when nothing moves: the readings' σ is estimated from their own scatter about
the fit (a map's σ is often the arm points', and need not be stated), and the
false-alarm level is exact to the linearisation (:data:`FALSE_ALARM`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.kinematics.so3 import skew

#: The probability that readings which hold still are taken for drift.
FALSE_ALARM = 0.01


@dataclass(frozen=True)
class MotionTest:
    """The F test of the fixed readings' block motions against none (module docstring)."""

    f: float  # the statistic
    d1: int  # the motions' degrees of freedom
    d2: int  # the residual's
    threshold: float  # F(d1, d2)'s quantile at 1 − FALSE_ALARM
    sigma_cm: float  # the readings' σ from their scatter about the fit
    block: int  # poses per block

    @property
    def moved(self) -> bool:
        """The readings move beyond their noise."""
        return self.f > self.threshold

    def words(self) -> str:
        """The statistic and its threshold, for the user's line."""
        return (
            f"F = {self.f:.3g} {'>' if self.moved else '<='} {self.threshold:.3g}, the "
            f"{FALSE_ALARM:.0%} false-alarm level of F({self.d1}, {self.d2}): the motion of "
            f"blocks of {self.block} poses against none, their σ {self.sigma_cm:.3g} cm from "
            "their scatter"
        )


def motion_test(fixed: np.ndarray, ref: np.ndarray, block: int) -> MotionTest | None:
    """The test (module docstring) of readings ``fixed`` (R, F, 3) (cm, NaN: not read)
    of targets whose reference places are ``ref`` (F, 3), in blocks of ``block`` poses;
    None when the readings leave no degree of freedom to test with."""
    from scipy.special import fdtri

    seen = np.isfinite(fixed).all(axis=2)
    r_i, f_i = np.nonzero(seen)
    F = len(ref)
    z = fixed[r_i, f_i] - ref[f_i]
    H = np.zeros((len(r_i), 3, 6))
    H[:, :, :3] = np.eye(3)
    H[:, :, 3:] = -skew((ref - ref.mean(axis=0))[f_i])  # ω × L = −[L]× ω
    b = r_i // block
    nb = int(b.max()) + 1
    A = np.zeros((nb, 6, 6))
    np.add.at(A, b, np.einsum("nij,nik->njk", H, H))
    g = np.zeros((nb, 6))
    np.add.at(g, b, np.einsum("nij,ni->nj", H, z))
    c4 = np.zeros((nb, F, 6, 3))  # the blocks' coupling to the targets' offsets
    np.add.at(c4, (b, f_i), np.swapaxes(H, 1, 2))
    C = np.swapaxes(c4, 1, 2).reshape(nb, 6, 3 * F)
    count = np.bincount(f_i, minlength=F).astype(float)
    h = np.zeros((F, 3))
    np.add.at(h, f_i, z)
    # the normal equations with each block's motion eliminated (its Schur complement)
    A_inv = np.linalg.pinv(A)
    S = np.diag(np.repeat(count, 3)) - np.einsum("bji,bjk,bkl->il", C, A_inv, C)
    rhs = h.ravel() - np.einsum("bji,bjk,bk->i", C, A_inv, g)
    beta = np.linalg.lstsq(S, rhs, rcond=None)[0]
    theta = np.einsum("bij,bj->bi", A_inv, g - C @ beta)
    res = z - beta.reshape(F, 3)[f_i] - np.einsum("nij,nj->ni", H, theta[b])
    rss1 = float(np.sum(res**2))
    rss0 = float(np.sum((z - (h / np.maximum(count, 1.0)[:, None])[f_i]) ** 2))
    rank = np.linalg.matrix_rank(A)
    d1 = int(rank.sum()) - 6
    d2 = 3 * len(r_i) - 3 * F - d1
    if rank.max() < 6 or d1 < 1 or d2 < 1 or not rss1 > 0.0:
        return None
    return MotionTest(
        f=(rss0 - rss1) / d1 / (rss1 / d2),
        d1=d1,
        d2=d2,
        threshold=float(fdtri(d1, d2, 1.0 - FALSE_ALARM)),
        sigma_cm=float(np.sqrt(rss1 / d2)),
        block=block,
    )
