"""Figures of the evaluation report: the mylar (2-D grid), 3-D error vectors, 1-D line errors.

matplotlib is imported inside the functions (object-oriented API only), as in
:mod:`pipeline.report.figures`, whose ``save_png`` writes the files.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from pipeline.report.figures import save_png

CONTROLLERS = ("design", "signature")


def mylar(desired: np.ndarray, marks: Mapping[str, np.ndarray], magnify: float, path: Path) -> Path:
    """The 2-D grid as drawn on the mylar, design and signature side by side.

    ``desired`` (nx, ny, 2) and ``marks[controller]`` (nx, ny, 2) in cm; each
    mark is drawn at ``desired + magnify · (mark − desired)``.
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11.0, 3.6))
    fig.subplots_adjust(left=0.06, right=0.98, bottom=0.16, top=0.84, wspace=0.15)
    axes = fig.subplots(1, 2, sharey=True)
    for ax, c in zip(axes, CONTROLLERS, strict=True):
        shown = desired + magnify * (marks[c] - desired)
        for i in range(desired.shape[1]):
            ax.plot(desired[:, i, 0], desired[:, i, 1], color="0.8", lw=0.8)
            ax.plot(shown[:, i, 0], shown[:, i, 1], color="C0", lw=0.8)
        for j in range(desired.shape[0]):
            ax.plot(desired[j, :, 0], desired[j, :, 1], color="0.8", lw=0.8)
            ax.plot(shown[j, :, 0], shown[j, :, 1], color="C0", lw=0.8)
        ax.plot(shown[..., 0].ravel(), shown[..., 1].ravel(), ".", color="C3", ms=4)
        ax.set_title(f"{c} model control")
        ax.set_xlabel("X (cm)")
        ax.set_aspect("equal")
        ax.grid(alpha=0.2)
    axes[0].set_ylabel("Y (cm)")
    fig.suptitle(f"Pen marks on the mylar, errors magnified {magnify:g}x (grey: desired grid)")
    return save_png(fig, path)


def error_vectors(
    desired: np.ndarray, actual: Mapping[str, np.ndarray], magnify: float, title: str, path: Path
) -> Path:
    """3-D position errors at the grid vertices (arrows magnified), one panel per controller.

    ``desired`` (m, 3) and ``actual[controller]`` (m, 3) in cm.
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11.0, 5.0))
    fig.subplots_adjust(left=0.02, right=0.98, bottom=0.05, top=0.88, wspace=0.05)
    for k, c in enumerate(CONTROLLERS):
        ax = fig.add_subplot(1, 2, k + 1, projection="3d")
        e = magnify * (actual[c] - desired)
        ax.scatter(*desired.T, color="0.5", s=6)
        ax.quiver(*desired.T, *e.T, color="C3", arrow_length_ratio=0.15, lw=1.0)
        rms = float(np.sqrt(np.mean(np.sum((actual[c] - desired) ** 2, axis=1))))
        ax.set_title(f"{c}: RMS {rms:.4f} cm")
        ax.set_xlabel("X (cm)")
        ax.set_ylabel("Y (cm)")
        ax.set_zlabel("Z (cm)")
    fig.suptitle(f"{title}: position errors magnified {magnify:g}x")
    return save_png(fig, path)


def line_errors(errors: Mapping[str, np.ndarray], resolution_cm: float, path: Path) -> Path:
    """Line-length errors of the 1-D lines (Table 6-6), design and signature bars."""
    from matplotlib.figure import Figure

    n = len(errors["design"])
    fig = Figure(figsize=(7.0, 3.6))
    fig.subplots_adjust(left=0.12, right=0.98, bottom=0.15, top=0.88)
    ax = fig.subplots()
    x = np.arange(1, n + 1)
    for k, c in enumerate(CONTROLLERS):
        ax.bar(x + (k - 0.5) * 0.38, errors[c], width=0.38, color=f"C{k}", label=c)
    ax.axhspan(-resolution_cm, resolution_cm, color="0.85", label="cathetometer resolution")
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_xticks(x)
    ax.set_xlabel("line (Table 6-7)")
    ax.set_ylabel("length error (cm)")
    ax.legend(fontsize=8)
    ax.grid(axis="y", alpha=0.3)
    fig.suptitle("One-dimensional task: line-length errors (cf. Table 6-6)")
    return save_png(fig, path)
