"""industrial_calibration's real image sets through armsig's camera fit of flange poses
(issue 40; skipped when ``../shared/realdata`` or ``$ARMSIG_REALDATA`` is absent).

The numbers are the ones docs/camera.md states ("Real images"); the reference is plain
``scipy.optimize.least_squares`` over the two hand-eye transforms with
``cv2.projectPoints`` (:func:`bench.hand_eye_real.reference_fit`), on armsig's detections.
"""

from __future__ import annotations

import numpy as np
import pytest

from bench.hand_eye_real import REALDATA, armsig_fit, difference, held_out, load, reference_fit
from pipeline.refine.hand_eye import fixed_in_base, tool_in_flange

pytestmark = pytest.mark.skipif(
    not (REALDATA / "industrial_calibration").is_dir(),
    reason=f"no real images at {REALDATA / 'industrial_calibration'}",
)


@pytest.fixture(scope="module")
def charuco():
    return load("test_set_charuco")


@pytest.fixture(scope="module")
def circles():
    return load("test_set_10x10")


def test_charuco_given_lens_reaches_the_peers_optimum(charuco) -> None:
    """The given lens held, no distortion, all 16 images: 2.62 px RMS per corner (the
    peer, on its 14 images: 2.42 px; issue 40's bound 2.7), the hand-eye 0.15 mm and
    0.03° from the plain least-squares optimum (the robust loss's doing: with plain least
    squares armsig is the optimum to 1e-3 mm)."""
    K, dist = charuco.lens.opencv()
    ref = reference_fit(charuco, K, dist)
    fit = armsig_fit(charuco, "fixed")
    assert (len(charuco.flange), len(charuco.uv)) == (16, 382)
    assert fit.rms_px <= 2.7 and ref[2] <= 2.7
    mm, deg = difference((fixed_in_base(fit), tool_in_flange(fit)), ref[:2])
    assert mm < 2.0 and deg < 0.2  # measured 0.145 mm, 0.031°
    plain = armsig_fit(charuco, "fixed", "linear")
    mm, deg = difference((fixed_in_base(plain), tool_in_flange(plain)), ref[:2])
    assert mm < 1e-3 and deg < 1e-4 and abs(plain.rms_px - ref[2]) < 1e-6


def test_charuco_lens_fitted_below_the_peer(charuco) -> None:
    """The intrinsics and distortion fitted in the same fit: 1.09 px (the peer's
    calibrateCamera-then-hand-eye: 1.28 px), σ of every one of the nine intrinsics, with
    the error an image's points share counted (0.76 px per coordinate beside 0.38 px of
    independent scatter: refine/camera_readings.py)."""
    fit = armsig_fit(charuco, "fitted")
    assert fit.rms_px < 1.28
    sigma = fit.solution.sigma[-9:]
    assert np.isfinite(sigma).all() and (sigma > 0).all()
    assert sigma[:4].max() < 15.0  # px: measured 2.8, 2.9, 8.5, 5.4 (1.1, 1.1, 3.2, 1.9
    # with every point's error independent, which held-out images showed too small)


def test_circle_grid(circles) -> None:
    """15 images, 1,500 dots, camera on the flange: 2.46 px with the given lens (the peer:
    2.29 px on its own dot centres: not met), 1.80 px with the lens fitted (below it)."""
    assert (len(circles.flange), len(circles.uv)) == (15, 1500)
    given = armsig_fit(circles, "fixed")
    assert given.rms_px < 2.5
    fitted = armsig_fit(circles, "fitted")
    assert fitted.rms_px < 2.29


@pytest.mark.parametrize("name", ["charuco", "circles"])
def test_held_out_images(name: str, request: pytest.FixtureRequest) -> None:
    """Every image held out once (5 folds): the held-out RMS above the in-sample one, at
    its prediction (measured 0.99-1.22x the prediction with the error an image's points
    share counted, 1.47-1.61x without: docs/camera.md), below the closed-form start's;
    the lens fitted predicts held-out images better than the given one (ChArUco 1.73
    against 3.63 px, circle grid 2.56 against 3.39 px): fitting it is not over-fitting
    here."""
    s = request.getfixturevalue(name)
    out = {}
    for intrinsics in ("fixed", "fitted"):
        inside, h = held_out(s, intrinsics)
        held = h.overall(h.rms_px)
        assert inside < held < h.overall(h.start_rms_px)
        assert 0.8 < held / h.overall(h.expected_px) < 1.4
        out[intrinsics] = held
    assert out["fitted"] < 0.8 * out["fixed"]


def test_charuco_set_imports_and_identifies(tmp_path) -> None:
    """`pipeline import cal_data.yaml --format images` with no edit, then `identify`: all
    16 images detected by the detections stage, the camera calibrated with the given lens,
    the arm said not calibrated; the calibration file holds both transforms with σ."""
    import json

    from pipeline.identify import identify
    from pipeline.importers.images import import_image_set

    cal = REALDATA / "industrial_calibration" / "test_set_charuco" / "cal_data.yaml"
    import_image_set(cal, tmp_path / "s")
    result = identify(tmp_path / "s", overrides={"camera_fit": {"intrinsics": "fixed"}})
    assert {r.name: r.rows for r in result.runs}["detections"] == 382
    assert result.verdict is not None and "the arm is not calibrated" in result.verdict
    assert "px held out (predicted" in result.verdict
    doc = json.loads((tmp_path / "s" / "camera_calibration.json").read_text())
    assert doc["n_images"] == 16 and 2.5 < doc["rms_px"] <= 2.7  # measured 2.623
    assert all(0 < s < 0.1 for s in doc["camera_in_base"]["sigma_translation_cm"])
    assert all(0 < s < 0.5 for s in doc["target_in_flange"]["sigma_rotation_deg"])
    # measured 0.18-0.26° with the images' shared error (1.9 px per coordinate with the
    # given lens, beside 0.54 px independent) counted
