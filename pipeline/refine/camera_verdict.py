"""The verdict of a camera session (issue 39): the rules of :mod:`pipeline.refine.verdict`
(docs/verdict.md) with the held-out evidence in pixels.

The rules in cm are judged as for every session by :func:`~pipeline.refine.verdict.judge`
(design plausibility, convergence, the predicted RMS tool error against the reach, the χ²
of the whitened pixels, parameters held, a stated requirement); a camera measures no
held-out tool position, so the held-out rules are judged here on the held-out images'
reprojection errors (:mod:`pipeline.refine.camera_holdout`), with the same thresholds:

- the held-out RMS beyond ``holdout_ratio`` × its prediction (CHECK), beyond
  ``holdout_fail_ratio`` × (FAIL: the model does not generalise);
- the measured gain, the design chain's hand-eye fit's held-out RMS over the signature's,
  below ``min_gain`` (CHECK), and the signature's per-image mean squares significantly
  larger (``gain_sigmas`` standard errors of the paired mean difference: FAIL);

each below :data:`FLOOR_PX` no finding (a noiseless session's rounding).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from pipeline.refine.verdict import (
    CHECK,
    FAIL,
    PASS,
    Evidence,
    Reason,
    Thresholds,
    Verdict,
    judge,
    predicted_part,
    with_first_reason,
)

#: Held-out pixel errors below this are no finding, however many σ: a thousandth of a
#: pixel, a fiftieth of a good corner detector's ~0.05 px, above a noiseless session's
#: ~1e-9 px of rounding.
FLOOR_PX = 1e-3


@dataclass(frozen=True)
class PixelHoldout:
    """Per held-out image: its RMS reprojection error, its prediction and the design's
    (px, each (h,))."""

    rms_px: np.ndarray
    expected_px: np.ndarray
    design_px: np.ndarray

    @property
    def rms(self) -> float:
        return float(np.sqrt(np.mean(self.rms_px**2)))

    @property
    def expected(self) -> float:
        return float(np.sqrt(np.mean(self.expected_px**2)))

    @property
    def design(self) -> float:
        return float(np.sqrt(np.mean(self.design_px**2)))

    @property
    def gain(self) -> float | None:
        return self.design / self.rms if self.rms > 0 else None

    @property
    def worse_sigmas(self) -> float | None:
        """The signature's per-image mean square minus the design's, in standard errors of
        that paired mean (positive: worse); None with fewer than 2 images."""
        d = self.rms_px**2 - self.design_px**2
        if len(d) < 2:
            return None
        se = float(np.std(d, ddof=1) / np.sqrt(len(d)))
        return float(np.mean(d) / se) if se > 0 else 0.0


def pixel_reasons(h: PixelHoldout, t: Thresholds) -> list[Reason]:
    """The held-out rules in pixels (module docstring)."""
    out = []
    e, x = h.rms, h.expected
    if e > t.holdout_ratio * max(x, FLOOR_PX):
        fails = x >= FLOOR_PX and e > t.holdout_fail_ratio * x
        ratio, rule = (t.holdout_fail_ratio, "holdout_fail_ratio") if fails else (
            t.holdout_ratio, "holdout_ratio")  # fmt: skip
        text = f"held-out reprojection RMS {e:.4g} px > {ratio:g} × its prediction {x:.4g} px"
        text += (
            ": the model does not generalise beyond the images it was fitted to" if fails else ""
        )
        out.append(Reason(FAIL if fails else CHECK, rule, e / x if x > 0 else None, ratio, text))
    g = h.gain
    if g is not None and g < t.min_gain and e - t.min_gain * h.design > FLOOR_PX:
        z = h.worse_sigmas
        worse = z is not None and z > t.gain_sigmas
        text = (
            f"the signature is {'worse than' if worse else 'no better than'} the design chain's "
            f"hand-eye fit on images the fit did not see: held-out {e:.4g} px against "
            f"{h.design:.4g} px ({g:.3g}× < {t.min_gain:g}×"
            + (
                ""
                if z is None
                else f"; {abs(z):.2g} standard errors {'worse' if z > 0 else 'better'}"
            )
            + ")"
        )
        out.append(Reason(FAIL if worse else CHECK, "min_gain", g, t.min_gain, text))
    return out


def camera_line(level: str, e: Evidence, h: PixelHoldout, sigma_px: float) -> str:
    """``PASS  predicted 0.05 cm RMS (95 % 0.08), held-out 0.21 px (predicted there 0.2),
    31× the design chain held out (6.5 → 0.21 px), χ²/dof 0.97 (stated σ 0.2 px)``."""
    parts = [p for p in (predicted_part(e),) if p]
    parts.append(f"held-out {h.rms:.2g} px (predicted there {h.expected:.2g})")
    if h.gain is not None and h.design > FLOOR_PX:
        parts.append(f"{h.gain:.3g}× the design chain held out ({h.design:.2g} → {h.rms:.2g} px)")
    if e.chi2_per_dof is not None:
        parts.append(f"χ²/dof {e.chi2_per_dof:.2f} (stated σ {sigma_px:.3g} px)")
    return f"{level}  " + ", ".join(parts)


def judge_camera(e: Evidence, h: PixelHoldout, sigma_px: float, t: Thresholds) -> Verdict:
    """The verdict of a camera session: :func:`judge` on ``e`` (no held-out numbers in
    cm) and :func:`pixel_reasons` of ``h``; the held-out pixel rules yield to a stated
    requirement as the held-out cm rules do (module docstring of
    :mod:`pipeline.refine.verdict`), the gain rule does not."""
    v = judge(replace(e, holdout_rms_cm=None, holdout_design_rms_cm=None), t)
    pixel = pixel_reasons(h, t)
    if t.requirement:
        pixel = [r for r in pixel if r.rule == "min_gain" or r.level == FAIL]
    held = [replace(r, text=f"{len(e.held)} parameter(s) the images cannot identify, held at "
                            f"their start: {', '.join(e.held)} (the report's Held line says what "
                            "to measure)") if r.rule == "identified" else r
            for r in v.findings]  # fmt: skip
    found = sorted((*held, *pixel), key=lambda r: r.level != FAIL)
    level = FAIL if any(r.level == FAIL for r in found) else CHECK if found else PASS
    reasons = tuple(r.text for r in found)
    line = with_first_reason(camera_line(level, e, h, sigma_px), level, reasons)
    return Verdict(level, reasons, line, tuple(found), v.decided_by)
