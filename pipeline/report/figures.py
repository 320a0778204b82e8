"""Figures of the identification report: residuals per joint (Figures 6-11 to 6-13).

matplotlib is imported inside the functions, and only its object-oriented API
(no pyplot, no global backend switch), so importing this module stays cheap.
"""

from __future__ import annotations

import contextlib
import math
import os
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np


@dataclass(frozen=True)
class JointResiduals:
    """Residuals of one joint's sweep (cm) against its encoder readings (deg or cm)."""

    joint: int
    name: str
    unit: str
    q: np.ndarray
    normal: np.ndarray
    radial: np.ndarray | None  # None for a prismatic joint


def joint_residuals(rows: Sequence[dict[str, Any]], robot: Any) -> list[JointResiduals]:
    """Rows of the ``residuals`` table grouped by joint of ``robot``, in step order."""
    out = []
    for i, j in enumerate(robot.joints, start=1):
        r = sorted((x for x in rows if x["joint"] == i), key=lambda x: x["step"])
        q = "q_cm" if j.prismatic else "q_deg"
        radial = [x["radial_cm"] for x in r]
        out.append(
            JointResiduals(
                joint=i,
                name=j.name,
                unit=j.unit,
                q=np.array([x[q] for x in r], float),
                normal=np.array([x["normal_cm"] for x in r], float),
                radial=None if j.prismatic else np.array(radial, float),
            )
        )
    return out


def _grid(n: int) -> tuple[int, int]:
    cols = min(3, n)
    return math.ceil(n / cols), cols


#: Labelled ticks per axis (at most, plus one): drawing tick labels is most of a figure's
#: cost (605 texts over the report's 21 axes with matplotlib's default of up to 9 per axis).
TICKS = 4
#: PNG compression (zlib level): 1 writes the report's PNGs ~6 % larger than matplotlib's
#: default 6 in about half of the encoding time.
PNG_COMPRESSION = 1


def few_ticks(ax: Any) -> None:
    """At most :data:`TICKS` + 1 labelled ticks on each axis of ``ax``, at nice numbers."""
    from matplotlib.ticker import MaxNLocator

    ax.xaxis.set_major_locator(MaxNLocator(TICKS))
    ax.yaxis.set_major_locator(MaxNLocator(TICKS))


def panel_figure(n: int) -> tuple[Any, list[Any]]:
    """A new figure of ``n`` panels in a grid (object-oriented API, no pyplot), its axes."""
    from matplotlib.figure import Figure

    rows, cols = _grid(n)
    fig = Figure(figsize=(4.2 * cols, 3.2 * rows))
    # Fixed margins: constrained layout cost ~1.5 s of the report for the same look.
    fig.subplots_adjust(left=0.08, right=0.98, bottom=0.1, top=0.9, wspace=0.3, hspace=0.45)
    axes = fig.subplots(rows, cols, squeeze=False).ravel()
    for ax in axes[n:]:
        ax.set_visible(False)
    for ax in axes[:n]:
        few_ticks(ax)
    return fig, list(axes[:n])


class Panels:
    """One figure of ``n`` panels, drawn again for each joint figure of a report.

    Building the axes and their ticks is about half of drawing a figure; :meth:`clear`
    takes the data, labels and legends off so the next figure reuses them. The PNG is
    the same, byte for byte, as that of a new figure (``tests/test_report_figures.py``).
    """

    def __init__(self, n: int) -> None:
        self.n = n
        self.fig, self.axes = panel_figure(n)
        self._used = False

    def clear(self) -> tuple[Any, list[Any]]:
        """The figure and its axes, as a new :func:`panel_figure` would give them."""
        if self._used:
            for legend in list(self.fig.legends):
                legend.remove()
            for ax in self.axes:
                for artist in [*ax.lines, *ax.patches, *ax.texts, *ax.collections]:
                    artist.remove()
                ax.grid(False)
                ax.set_title("")
                ax.set_xlabel("")
                ax.set_ylabel("")
                ax.relim()
                ax.set_xlim(0.0, 1.0)  # a new axes' view, then autoscaled again
                ax.set_ylim(0.0, 1.0)
                ax.set_autoscale_on(True)
        self._used = True
        return self.fig, self.axes


def _panels(n: int, panels: Panels | None) -> tuple[Any, list[Any]]:
    if panels is None:
        return panel_figure(n)
    if panels.n != n:
        raise ValueError(f"panels of {panels.n} joints given for {n} joints")
    return panels.clear()


def save_png(fig: Any, path: Path) -> Path:
    """Save ``fig`` to a temp file beside ``path``, then rename it over ``path``."""
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        fig.savefig(tmp, format="png", dpi=90, pil_kwargs={"compress_level": PNG_COMPRESSION})
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise
    return path


def residuals_vs_q(
    joints: Sequence[JointResiduals], path: Path, panels: Panels | None = None
) -> Path:
    """Figure 6-11 for every joint: normal (*) and radial (o) residuals against the reading
    (``panels``: a figure to draw on again, see :class:`Panels`; default a new one)."""
    fig, axes = _panels(len(joints), panels)
    for ax, j in zip(axes, joints, strict=True):
        ax.axhline(0.0, color="0.6", lw=0.8)
        ax.plot(j.q, j.normal, "*", ms=6, color="C0", label="normal")
        if j.radial is not None:
            ax.plot(j.q, j.radial, "o", ms=4, mfc="none", color="C3", label="radial")
        ax.set_title(f"joint {j.joint} ({j.name})", y=1.0)
        ax.set_xlabel(f"q{j.joint} ({j.unit})")
        ax.set_ylabel("residual (cm)")
        ax.grid(alpha=0.3)
    handles, labels = max((ax.get_legend_handles_labels() for ax in axes), key=lambda h: len(h[0]))
    fig.legend(handles, labels, loc="outside upper right", ncols=len(labels))
    fig.suptitle("Residuals against the joint reading (cf. Figure 6-11)")
    return save_png(fig, path)


def residual_histograms(
    joints: Sequence[JointResiduals], kind: str, path: Path, panels: Panels | None = None
) -> Path:
    """Figures 6-12 (``kind="normal"``) and 6-13 (``"radial"``) with a fitted normal curve
    (``panels``: as for :func:`residuals_vs_q`)."""
    fig, axes = _panels(len(joints), panels)
    for ax, j in zip(axes, joints, strict=True):
        values = j.normal if kind == "normal" else j.radial
        ax.set_title(f"joint {j.joint} ({j.name})", y=1.0)
        ax.set_xlabel(f"{kind} residual (cm)")
        ax.set_ylabel("count")
        if values is None or len(values) < 2:
            ax.text(0.5, 0.5, f"no {kind} residuals", ha="center", transform=ax.transAxes)
            continue
        # One filled step patch, not a bar per bin: same look, a fraction of the drawing time.
        # Exact data (residuals within 1e-9 cm, rounding only) get one bin: numpy's "auto"
        # bins cannot split a range of a few ulps.
        bins: Any = "auto" if float(np.ptp(values)) > 1e-9 else 1
        counts, edges, _ = ax.hist(
            values, bins=bins, color="C0", alpha=0.7, edgecolor="k", histtype="stepfilled"
        )
        mu, sd = float(np.mean(values)), float(np.std(values, ddof=1))
        if sd > 0:
            x = np.linspace(edges[0], edges[-1], 200)
            pdf = np.exp(-0.5 * ((x - mu) / sd) ** 2) / (sd * math.sqrt(2 * math.pi))
            ax.plot(x, pdf * len(values) * (edges[1] - edges[0]), color="C3", lw=1.2)
        ax.text(0.02, 0.95, f"s = {sd:.4f} cm", transform=ax.transAxes, va="top", fontsize=8)
    title = "plane-of-rotation (normal)" if kind == "normal" else "circle-of-rotation (radial)"
    figure_no = "6-12" if kind == "normal" else "6-13"
    fig.suptitle(f"Histograms of the {title} residuals (cf. Figure {figure_no})")
    return save_png(fig, path)
