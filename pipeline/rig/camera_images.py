"""Rendered images of a simulated camera session (``simulate --sensor camera --images``,
issue 40): each image the true lens sees (:func:`pipeline.rig.camera_render.render`, with
its distortion, blur, vignette and grey-level noise), written as a PNG beside the
recording (``images/NNNN.png``, referenced by SHA-256 in ``/camera/images`` as the image
importer does) and detected (:func:`pipeline.sensor.detect.detect_target`, OpenCV's
detectors: no detector was tuned to these images). The ``detections`` stage detects the
same files again (:mod:`pipeline.stages.image_detections`); the recording's
``/camera/detections`` are what the detector found here.

The board is drawn at a resolution that gives each fine sample of the nearest point at
least one board pixel (:func:`board_px_per_cm`).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from pipeline.atomic import atomic_write
from pipeline.rig.camera_render import SUPERSAMPLE, board_image, render
from pipeline.rig.options import SimulationOptions
from pipeline.sensor.camera import Intrinsics
from pipeline.sensor.detect import ImageDetection, detect_target
from pipeline.sensor.target import Target

IMAGES_DIR = "images"  # beside the recording, /rig/description images_dir
MARGIN_PX = 40  # white around the drawn board (camera_render.render's default)


@dataclass(frozen=True)
class RenderedImage:
    """One rendered image: its ``file`` (relative to the session folder's
    :data:`IMAGES_DIR`), the PNG's ``sha256`` and what the detector ``found``."""

    file: str
    sha256: str
    found: ImageDetection


def board_px_per_cm(target: Target, T: np.ndarray, lens: Intrinsics, local: np.ndarray) -> float:
    """Board pixels per cm for the image at pose ``T``: the nearest point's fine samples
    per cm or more, whole pixels per square."""
    z = float(np.min((T[:3, :3] @ local.T)[2] + T[2, 3]))
    per_cm = SUPERSAMPLE * max(lens.fx, lens.fy) / max(z, 1.0)
    n = int(np.ceil(max(per_cm, 10.0) * target.spacing_cm))
    while not _drawable(target, n):
        n += 1
    return n / target.spacing_cm


@lru_cache(maxsize=64)
def _drawable(target: Target, px_per_square: int) -> bool:
    """Whether OpenCV draws the board at ``px_per_square`` (its ``generateImage`` fails
    an assertion at some sizes: the default board at 60 + 70 k px per square)."""
    import cv2

    try:
        board_image(target, px_per_square / target.spacing_cm, MARGIN_PX)
    except cv2.error:
        return False
    return True


def render_images(
    out: Path, opts: SimulationOptions, target: Target, lens: Intrinsics, T: np.ndarray,
    rng: np.random.Generator,
) -> list[RenderedImage]:  # fmt: skip
    """Render, write and detect the images at poses ``T`` (M, 4, 4) (module docstring)."""
    import cv2

    _, local = target.points()
    quiet = opts.noiseless
    folder = out / IMAGES_DIR
    folder.mkdir(parents=True, exist_ok=True)
    images = []
    for k, pose in enumerate(T):
        grey = render(
            target, pose, lens, rng=rng, px_per_cm=board_px_per_cm(target, pose, lens, local),
            margin_px=MARGIN_PX,
            blur_px=0.0 if quiet else opts.blur_px, noise_grey=0.0 if quiet else opts.grey_noise,
            vignette=0.0 if quiet else opts.vignette,
        )  # fmt: skip
        ok, png = cv2.imencode(".png", grey)
        data = png.tobytes()
        name = f"{k:04d}.png"
        with atomic_write(folder / name) as fh:
            fh.write(data)  # type: ignore[arg-type]
        images.append(
            RenderedImage(name, hashlib.sha256(data).hexdigest(), detect_target(grey, target))
        )
    return images
