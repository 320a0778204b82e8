"""Held-out images of a session of flange poses without joints (issue 40): the camera's
calibration judged on images it did not see.

The images, in measurement order, are cut into ``k`` contiguous folds
(:func:`pipeline.refine.holdout.fold_of_blocks`, ``k`` = :data:`~pipeline.refine.holdout.FOLDS`,
more when a fold would leave the refit fewer than
:data:`~pipeline.refine.camera_fit.MIN_IMAGES`); each fold is held out in turn and the
calibration refitted on the others from its own closed-form start
(:func:`~pipeline.refine.hand_eye.fit_hand_eye`, the same options), so every image is
held out once. Per held-out image, as the joint session's held-out images
(:mod:`pipeline.refine.camera_holdout`, whose prediction this reuses):

- ``rms_px``: the RMS length of its points' reprojection errors under the refit;
- ``expected_px``: its prediction, the refit's noise (the stated σ scaled by its χ²/dof)
  and its covariance carried to the image's pixels;
- ``start_rms_px``: the same image under the refit's closed-form start (OpenCV's lens
  when fitted, ``calibrateRobotWorldHandEye``): what the peers' closed forms give.

A held-out RMS well above the in-sample one is a calibration that follows its own images
(an over-fitted lens) or errors an image's points share (the recorded flange pose's own
error): the prediction counts every point's noise as independent and sees neither. On
industrial_calibration's real sets 25-50 % of the residuals' square is such a shift per
image, and the held-out RMS is 1.47-1.61 times its prediction (docs/camera.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.optim.block import Array
from pipeline.refine.camera_fit import MIN_IMAGES, Detections
from pipeline.refine.camera_holdout import per_image, predicted, subset
from pipeline.refine.hand_eye import fit_hand_eye, flange_model, predicted_pixels
from pipeline.refine.holdout import FOLDS, fold_of_blocks
from pipeline.sensor.camera import Intrinsics


@dataclass(frozen=True)
class HandEyeHeldOut:
    """Per image (the fit's order): its ``fold``, ``points``, and under the refit that did
    not see it ``rms_px``, ``expected_px`` and the start's ``start_rms_px`` (px)."""

    fold: np.ndarray
    points: np.ndarray
    rms_px: Array
    expected_px: Array
    start_rms_px: Array

    def overall(self, values: Array) -> float:
        """The RMS over every held-out point of a per-image RMS column."""
        return float(np.sqrt(np.sum(self.points * values**2) / np.sum(self.points)))


def hand_eye_folds(n_images: int, folds: int = FOLDS) -> np.ndarray | None:
    """Each image's fold (n_images,): ``folds`` contiguous blocks, more when a block would
    leave fewer than ``MIN_IMAGES`` to refit; None when even one image held out would."""
    if n_images <= MIN_IMAGES:
        return None
    k = max(folds, -(-n_images // (n_images - MIN_IMAGES)))  # largest block ≤ n − MIN_IMAGES
    return fold_of_blocks(np.zeros(n_images), np.arange(n_images), min(k, n_images))


def hand_eye_holdout(
    det: Detections,
    flange_in_base: Array,
    lens: Intrinsics,
    setup: str,
    fold: np.ndarray,
    **fit_options: object,
) -> HandEyeHeldOut:
    """Every image held out once by its ``fold`` (module docstring); ``fit_options``:
    those of :func:`~pipeline.refine.hand_eye.fit_hand_eye` (intrinsics, prior_sigma,
    loss, f_scale)."""
    n = det.n_images
    rms, expected, start = np.zeros(n), np.zeros(n), np.zeros(n)
    for f in np.unique(fold):
        out = fold == f
        kept, held = subset(det, ~out), subset(det, out)
        refit = fit_hand_eye(kept, flange_in_base[~out], lens, setup, **fit_options)  # type: ignore[arg-type]
        err, e2 = predicted(refit, held, flange_model(flange_in_base[out]))
        s = refit.start
        first = Intrinsics(lens.width_px, lens.height_px, *s.intrinsics)
        uv = predicted_pixels(held, flange_in_base[out], setup, s.fixed_in_base,
                              s.tool_in_flange, first)  # fmt: skip
        h = held.n_images
        rms[out] = per_image(err**2, held.image, h)
        expected[out] = per_image(e2, held.image, h)
        start[out] = per_image(np.sum((uv - held.uv) ** 2, axis=1), held.image, h)
    points = np.bincount(det.image, minlength=n)
    return HandEyeHeldOut(np.asarray(fold), points, rms, expected, start)
