"""The recorded rig geometry is used as recorded, or refused in one line (issue 13)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

import pipeline.rig.simulate as simulate
from pipeline.errors import ArmsigError
from pipeline.features.checks import spacing_warnings
from pipeline.identify import identify
from pipeline.rig.atmosphere import Atmosphere
from pipeline.rig.audit import audit
from pipeline.rig.digitizer import DigitizerModel, digitize
from pipeline.sensor.geometry import check_geometry, default_geometry
from pipeline.sensor.triangulation import Trilateration

MIRROR = np.array([-1.0, 1.0, 1.0])  # microphone A (and D, the rods) at -X


def _mirrored(*args):
    g = default_geometry(*args)
    return dataclasses.replace(
        g, microphones=g.microphones * MIRROR, rod_sparkers=g.rod_sparkers * MIRROR
    )


def test_noiseless_recording_with_microphone_a_at_minus_x_is_exact(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Before: every target triangulated to its mirror image, 124 cm RMS, no warning."""
    placed = simulate.default_sensor_from_base

    def mirrored_placement(robot):
        T = placed(robot).copy()
        T[0, 3] *= -1.0  # the robot stands in front of the mirrored microphones
        return T

    monkeypatch.setattr(simulate, "default_geometry", _mirrored)
    monkeypatch.setattr(simulate, "default_sensor_from_base", mirrored_placement)
    simulate.simulate_session(
        tmp_path, simulate.SimulationOptions(seed=11, noiseless=True, points=12, repeats=1)
    )
    identify(tmp_path, report=False)
    r = audit(tmp_path, configurations=300)
    assert r.signature.max_position_cm <= 1e-6, r.signature


@pytest.mark.parametrize("layout", ["thesis", "mirrored", "rotated"])
def test_trilateration_in_any_layout_finds_the_point(layout: str) -> None:
    abc = default_geometry().microphones[:3]
    if layout == "mirrored":
        abc = abc * MIRROR
    elif layout == "rotated":  # 20° about Z, 10° about X, moved: Z still out of the wall
        c, s = np.cos(np.radians(20)), np.sin(np.radians(20))
        rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
        c, s = np.cos(np.radians(10)), np.sin(np.radians(10))
        rx = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
        abc = abc @ (rx @ rz).T + [5.0, -3.0, 1.0]
    p = np.array([[60.0, 80.0, 90.0], [-40.0, 20.0, 150.0]])
    s = np.linalg.norm(p[:, None, :] - abc[None], axis=-1)
    assert np.abs(Trilateration.from_microphones(abc)(s) - p).max() < 1e-9


def _bad(what: str):
    g = default_geometry()
    mics, rods = g.microphones.copy(), g.rod_sparkers.copy()
    if what == "collinear_microphones":
        mics[0] = [0.0, -100.0, 0.0]
    elif what == "wall_not_facing_z":
        mics[:3] = mics[:3][:, [2, 1, 0]]  # the A-B-C plane contains Z
    elif what == "d_level_with_b":
        mics[3] = mics[3] + (g.height(mics[1]) - g.height(mics[3])) * g.up
    elif what == "rod_swapped":
        rods[[0, 1]] = rods[[1, 0]]
    elif what == "rod_not_level":
        rods[1] = rods[1] + 2.0 * g.up
    elif what == "rod_off_line":  # level, but sparker 1 off the line from B to sparker 2
        rods[0] = rods[0] + 2.0 * np.cross(g.up, rods[1] - mics[1]) / np.linalg.norm(
            rods[1] - mics[1]
        )
    elif what == "rod_wrong_length":
        rods[3] = rods[2] + (rods[3] - rods[2]) * 1.01
    elif what == "rod_at_other_microphone":
        rods[[0, 1]] = rods[[2, 3]]
    elif what == "empty_window":
        return dataclasses.replace(g, range_min_cm=250.0, range_max_cm=30.0)
    return dataclasses.replace(g, microphones=mics, rod_sparkers=rods)


@pytest.mark.parametrize(
    ("what", "match"),
    [
        ("collinear_microphones", "triangle"),
        ("wall_not_facing_z", "does not face"),
        ("d_level_with_b", "same height"),
        # issue 33: each message names the rule of (E.1) that the rod breaks
        ("rod_swapped", "sparkers 1 and 2 .*: sparker 1 must be the near one"),
        ("rod_not_level", "sparkers 1 and 2 .*: the rod must be level with microphone B"),
        ("rod_off_line", "sparkers 1 and 2 .*: sparker 1 must be on the line from microphone B"),
        ("rod_wrong_length", "sparkers 3 and 4 .*: sparkers 3 and 4 must be rod_length_cm apart"),
        ("rod_at_other_microphone", "sparkers 1 and 2 .*: the rod must be level with microphone B"),
        ("empty_window", "empty range window"),
    ],
)
def test_unusable_layouts_are_refused_in_one_line(what: str, match: str) -> None:
    with pytest.raises(ArmsigError, match=match) as exc:
        check_geometry(_bad(what))
    assert "\n" not in str(exc.value)


def test_every_default_and_mirrored_layout_passes() -> None:
    check_geometry(default_geometry())
    check_geometry(default_geometry(143.0, 143.0, 203.5))  # a W_AC calibration error
    check_geometry(_mirrored())


def test_the_digitizer_never_reports_a_range_outside_its_window() -> None:
    """Before: noise or a spurious echo could carry a reported range past 30-250 cm."""
    g = default_geometry()
    model = DigitizerModel(geometry=g, noise_factor=1.0, outlier_prob=0.5)
    rng = np.random.default_rng(0)
    target = np.array([80.0, 60.0, 100.0]) + rng.normal(0, 20, (400, 3))
    raw = digitize(model, Atmosphere(), target, np.zeros(400), rng)
    heard = raw[~np.isnan(raw)]
    assert heard.size and heard.min() >= g.range_min_cm and heard.max() <= g.range_max_cm


def test_uneven_spacing_warnings_carry_units() -> None:
    """Before: step sizes of revolute joints were printed in radians without a unit."""

    def uneven(steps: np.ndarray, extent: float, angular: bool) -> str:
        out = spacing_warnings(steps, np.array([extent]), np.array([0.0]), "x", angular=angular)
        (msg,) = [m for m in out if "uniformly" in m]
        return msg

    assert "from 2° to 6°, mean 3°" in uneven(np.radians([[2.0, 2.0, 6.0, 2.0]]), 40.0, True)
    assert "from 1 cm to 3 cm" in uneven(np.array([[1.0, 1.0, 3.0]]), 5.0, False)
