"""The worst image of a camera session in its report (issue 40): the image itself, when
the recording references it (rendered or imported; its SHA-256 checked), cropped to the
board, with its detected corners and their residual vectors (predicted − detected)
magnified so that the largest is a fifteenth of the board's extent."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pipeline.report.figures import panel_figure, save_png

FIGURE = "camera_worst_image.png"


def worst_image_section(sdir: Path, residuals: Any, image: int, out_dir: Path) -> str | None:
    """The report's section of image ``image`` (a step of sweep ``poses``): the figure and
    its caption; None when the recording references no image file for it."""
    import cv2

    from pipeline.stages.image_inputs import image_refs
    from pipeline.stages.recording import read_recording

    refs = image_refs(read_recording(sdir / "recording.mcap"))
    at = [k for k, s in enumerate(refs.step) if int(s) == image and refs.recorded[k]]
    if refs.folder is None or not at or refs.current[at[0]] != refs.recorded[at[0]]:
        return None
    grey = cv2.imread(str(refs.folder / refs.file[at[0]]), cv2.IMREAD_GRAYSCALE)
    if grey is None:
        return None
    m = residuals.column("image").to_numpy() == image
    u, v = residuals.column("u_px").to_numpy()[m], residuals.column("v_px").to_numpy()[m]
    du, dv = residuals.column("du_px").to_numpy()[m], residuals.column("dv_px").to_numpy()[m]
    largest = float(np.max(np.hypot(du, dv))) if len(du) else 0.0
    # the board's part of the image, a tenth of its size around it
    span = max(float(np.ptp(u)), float(np.ptp(v)), 20.0) if len(u) else float(grey.shape[1])
    pad = 0.1 * span + 10.0
    gain = span / 15.0 / largest if largest > 0 else 1.0
    fig, (ax,) = panel_figure(1)
    ax.imshow(grey, cmap="gray", vmin=0, vmax=255, extent=(-0.5, grey.shape[1] - 0.5,
                                                            grey.shape[0] - 0.5, -0.5))  # fmt: skip
    ax.plot(u, v, "o", ms=3, mfc="none", mec="tab:green")
    ax.quiver(u, v, du * gain, dv * gain, angles="xy", scale_units="xy", scale=1.0,
              color="tab:red", width=0.003)  # fmt: skip
    if len(u):
        ax.set_xlim(u.min() - pad, u.max() + pad)
        ax.set_ylim(v.max() + pad, v.min() - pad)  # v down, as in the image
    ax.set_title(f"image {image} ({refs.file[at[0]]}): residuals x {gain:.3g}")
    ax.set_xlabel("u (px)")
    ax.set_ylabel("v (px)")
    png = save_png(fig, out_dir / FIGURE)
    rms = float(np.sqrt(np.mean(du**2 + dv**2))) if len(du) else 0.0
    return (f"## The worst image\n\nImage {image} (`{refs.file[at[0]]}`), {len(du)} points, "
            f"{rms:.3f} px rms: its detected corners (green) and residuals (predicted − "
            f"detected, red) magnified {gain:.3g}×.\n\n![]({png.name})")  # fmt: skip
