"""The camera's held-out images: the fit's error on images it did not see (issue 39).

The last ``fraction`` of the images in measurement order (at least
:data:`MIN_HELD_IMAGES`, leaving the fit :data:`~pipeline.refine.camera_fit.MIN_IMAGES`)
are held out; the whole fit is redone on the others (:func:`fit_camera`, its own
closed-form start) and predicts the held-out images' pixels from their joint readings.
Per held-out image: the RMS length of its points' reprojection errors, px, and its
expected value, the stated noise and the refit's parameter covariance carried to the
pixels (``J Σ Jᵀ``) and the image's own readings' rounding (``G Σ_q Gᵀ``,
:mod:`pipeline.refine.camera_readings`), scaled by the refit's χ²/dof as its covariance is:

    ``e_i² = mean over the image's points of σ² (s² (2 + tr(G_d Σ_q G_dᵀ)) + tr(J_d Σ J_dᵀ))``

with ``J_d`` (2, P) the whitened pixels' derivatives (:func:`residuals_and_jacobian`).
Beside each, the *design model*'s error on the same image (the measured gain, issue 41):
the peers' hand-eye problem on the same kept images, the chain held at its design and the
fixed body's pose and the lens fitted (``fit_camera(..., chain="design")``), which is what
a user without armsig's chain would have.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import pyarrow as pa

from pipeline.errors import StageError
from pipeline.kinematics.chain import SerialChain
from pipeline.optim.block import Array
from pipeline.refine.camera_block import CameraBlock
from pipeline.refine.camera_fit import MIN_IMAGES, CameraFit, Detections, fit_camera, observing
from pipeline.refine.camera_readings import reading_jacobian
from pipeline.refine.kinematics import ChainModel
from pipeline.refine.solve import Problem, residuals_and_jacobian
from pipeline.sensor.camera import Intrinsics
from pipeline.sweeps import POSES_SWEEP

#: Fewest held-out images: a held-out RMS of one image is one draw of its 6-D pose error.
MIN_HELD_IMAGES = 2


@dataclass(frozen=True)
class HeldOutImages:
    """Per held-out image (rows of the fit's image order): ``image`` (h,) its index,
    ``points`` (h,), ``rms_px``, ``expected_px`` and ``design_rms_px`` (h,)."""

    image: np.ndarray
    points: np.ndarray
    rms_px: Array
    expected_px: Array
    design_rms_px: Array


def held_out(n_images: int, fraction: float) -> np.ndarray:
    """Which images (n_images,) bool are held out: the last ``fraction`` (module docstring)."""
    h = max(MIN_HELD_IMAGES, int(round(fraction * n_images)))
    if n_images - h < MIN_IMAGES:
        raise StageError(
            f"camera holdout: {n_images} images leave {n_images - h} to fit after holding out {h}",
            expected=f"at least {MIN_IMAGES + MIN_HELD_IMAGES} images",
            fix="record more images, or --param camera_holdout.fraction=0.1",
        )
    out = np.zeros(n_images, bool)
    out[n_images - h :] = True
    return out


def subset(det: Detections, images: np.ndarray) -> Detections:
    """The detections of ``images`` (n_images,) bool, renumbered in the same order."""
    new = np.cumsum(images) - 1
    rows = images[det.image]
    return dataclasses.replace(det, image=new[det.image[rows]], local=det.local[rows],
                               uv=det.uv[rows], sigma_px=det.sigma_px[rows],
                               q=det.q[images])  # fmt: skip


def predicted(
    fit: CameraFit, det: Detections, model: ChainModel, reading_sigma: Array | None = None
) -> tuple[Array, Array]:
    """Per detection of ``det`` (images the fit did not see): its reprojection error under
    ``fit`` (D,) px, and its expected square (D,) px² (module docstring), with the share
    of the joint readings' σ ``reading_sigma`` (n,) when given; ``model``: the fit's model
    observing ``det``'s images (the chain at their readings, :func:`observing`, or their
    flange poses, :func:`pipeline.refine.hand_eye.flange_model`)."""
    n = det.n_images
    keys = pa.table(
        {
            "sweep": pa.array(np.full(n, POSES_SWEEP), pa.int32()),
            "step": pa.array(np.arange(n), pa.int32()),
            "target": ["tool"] * n,
        }
    )
    b = fit.block
    block = CameraBlock(keys, det.image, det.local, det.uv, det.sigma_px, b.setup, b.x0,
                        fixed_start=b.fixed_start)  # fmt: skip
    r, J = residuals_and_jacobian(Problem(model, block, "linear"), fit.solution.x)
    s = fit.solution
    var = np.einsum("rp,pq,rq->r", J, s.covariance, J)  # whitened, per coordinate
    if reading_sigma is not None:  # the image's own readings' rounding, scaled as the rest
        G = reading_jacobian(block, model, s.x)
        var += s.noise_scale**2 * (G**2 @ np.asarray(reading_sigma, float) ** 2)
    sig2 = np.repeat(det.sigma_px**2, 2)
    err = np.hypot(*(r.reshape(-1, 2) * det.sigma_px[:, None]).T)
    own = sig2 * s.noise_scale**2  # the image's own error per coordinate: the fit's scatter,
    if fit.shared_px2 > 0:  # or its independent and shared parts (camera_readings.py)
        own = np.full(len(sig2), fit.independent_px2 + 3.0 * fit.shared_px2)
    expected = (own + sig2 * var).reshape(-1, 2).sum(axis=1)
    return err, expected


def per_image(values: Array, image: np.ndarray, n: int) -> Array:
    """RMS per image of per-detection lengths (or square root of the mean of squares)."""
    count = np.bincount(image, minlength=n)
    return np.sqrt(np.bincount(image, values, n) / np.maximum(count, 1))


def camera_holdout(
    det: Detections,
    design: SerialChain,
    lens: Intrinsics,
    setup: str,
    fraction: float,
    **fit_options: object,
) -> HeldOutImages:
    """The held-out images of ``det`` (module docstring); ``fit_options``: those of
    :func:`fit_camera` (intrinsics, prior_sigma, loss, f_scale, reading_sigma)."""
    out = held_out(det.n_images, fraction)
    kept, held = subset(det, ~out), subset(det, out)
    refit = fit_camera(kept, design, lens, setup, **fit_options)  # type: ignore[arg-type]
    seen = observing(refit.model, held.q, held.q_signature)
    err, expected = predicted(refit, held, seen, fit_options.get("reading_sigma"))  # type: ignore[arg-type]
    peers = fit_camera(kept, design, lens, setup, chain="design", **fit_options)  # type: ignore[arg-type]
    design_err, _ = predicted(peers, held, observing(peers.model, held.q, held.q_signature))
    h = held.n_images
    return HeldOutImages(np.flatnonzero(out), np.bincount(held.image, minlength=h),
                         per_image(err**2, held.image, h), per_image(expected, held.image, h),
                         per_image(design_err**2, held.image, h))  # fmt: skip
