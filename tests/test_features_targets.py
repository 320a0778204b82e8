"""Several targets of one sweep (pipeline/features/targets.py): conditioning and the
combined feature, on exact circles about a known axis."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.features.targets import TargetFit, combine, why_ill_conditioned, why_not_usable
from pipeline.stages.features import _fit_row

AXIS = np.array([1.0, 2.0, 2.0]) / 3.0
ORIGIN = np.array([10.0, -5.0, 40.0])


def _circle(radius: float, height: float, phase: float) -> np.ndarray:
    """Positions (12, 3) of a target at ``radius`` and ``height`` on the axis, sweeping 200°."""
    u = np.cross(AXIS, [0.0, 0.0, 1.0])
    u /= np.linalg.norm(u)
    v = np.cross(AXIS, u)
    q = np.radians(np.linspace(0.0, 200.0, 12)) + phase
    return ORIGIN + height * AXIS + radius * (np.cos(q)[:, None] * u + np.sin(q)[:, None] * v)


def _fit(name: str, radius: float, height: float, phase: float, sigma: float) -> TargetFit:
    p = _circle(radius, height, phase)
    return TargetFit(name, len(p), sigma, _fit_row(p, False, "lsq"))


def test_exact_circles_combine_to_their_axis() -> None:
    fits = [_fit("A", 30.0, 5.0, 0.0, 0.001), _fit("B", 20.0, 9.0, 0.7, 0.001)]
    row = combine(fits, prismatic=False)
    assert np.allclose(row["axis"], AXIS, atol=1e-12)
    d = row["center"] - ORIGIN  # on the axis, in the first target's plane
    assert np.allclose(d, 5.0 * AXIS, atol=1e-9)
    assert np.allclose(row["first"], fits[0].row["first"])
    assert combine(fits[:1], prismatic=False) == fits[0].row  # one target: its own fit


@pytest.mark.parametrize(
    ("radius", "sigma", "used"),
    [(30.0, 0.001, True), (0.5, 0.001, False), (15.0, 1.0, False), (25.0, 1.0, True)],
)
def test_radius_must_exceed_one_cm_and_twenty_sigma(
    radius: float, sigma: float, used: bool
) -> None:
    why = why_ill_conditioned(_fit("A", radius, 0.0, 0.0, sigma), prismatic=False)
    assert (why is None) == used
    if not used:
        assert why is not None and why.startswith(f"radius {radius:.3g} cm (on or near the axis)")


def test_a_target_that_does_not_move_is_not_fitted() -> None:
    assert why_not_usable(0.004, 0.001, prismatic=False) is not None
    assert why_not_usable(0.6, 0.001, prismatic=False) is None  # a 0.6 cm arc spans 1.2 cm
