"""The camera model (pipeline.sensor.camera) against OpenCV's projectPoints, its Jacobians
against finite differences, and the intrinsics' round trips through OpenCV and ROS."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from pipeline.errors import ArmsigError
from pipeline.sensor.camera import Intrinsics, project, project_with_jacobians
from pipeline.sensor.camera_info import camera_info_text, intrinsics_from_camera_info

#: A strongly distorted lens (every term non-zero) and a plain pinhole.
LENSES = [
    Intrinsics(1280, 960, 1012.5, 1009.25, 641.3, 478.9, -0.28, 0.11, 1.2e-3, -8e-4, -0.021),
    Intrinsics(640, 480, 500.0, 500.0, 320.0, 240.0),
]


def _points(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    """Points 40-200 cm in front of the camera, within ±35° of its axis."""
    z = rng.uniform(40.0, 200.0, shape)
    xy = rng.uniform(-0.7, 0.7, (*shape, 2)) * z[..., None]
    return np.concatenate([xy, z[..., None]], axis=-1)


@pytest.mark.parametrize("lens", LENSES)
def test_projection_matches_opencv(lens: Intrinsics) -> None:
    p = _points(np.random.default_rng(3), (500,))
    K, d = lens.opencv()
    ref, _ = cv2.projectPoints(p, np.zeros(3), np.zeros(3), K, d)
    uv = project(p, lens.vector())
    assert np.abs(uv - ref[:, 0]).max() <= 1e-9  # px; both are double-precision formulas


def test_projection_is_batch_first() -> None:
    p = _points(np.random.default_rng(4), (4, 6, 5))
    v = LENSES[0].vector()
    uv = project(p, v)
    assert uv.shape == (4, 6, 5, 2)
    loop = np.array([project(q, v) for q in p.reshape(-1, 3)]).reshape(uv.shape)
    assert np.array_equal(uv, loop)


def test_point_behind_the_camera_has_no_pixel() -> None:
    uv = project(np.array([[1.0, 2.0, -50.0], [1.0, 2.0, 50.0]]), LENSES[0].vector())
    assert np.isnan(uv[0]).all() and np.isfinite(uv[1]).all()


@pytest.mark.parametrize("lens", LENSES)
def test_jacobians_match_finite_differences(lens: Intrinsics) -> None:
    p = _points(np.random.default_rng(5), (50,))
    v = lens.vector()
    _, d_point, d_intr = project_with_jacobians(p, v)
    h = 1e-5  # cm: central differences, error ~h² · u''' ≈ 1e-8 px/cm
    for i in range(3):
        e = np.zeros(3)
        e[i] = h
        fd = (project(p + e, v) - project(p - e, v)) / (2 * h)
        assert np.abs(fd - d_point[..., i]).max() < 1e-6 * (1 + np.abs(fd).max())
    for i in range(9):
        step = 1e-6 * max(1.0, abs(v[i]))  # relative step: focal lengths are ~1e3 px
        e = np.zeros(9)
        e[i] = step
        fd = (project(p, v + e) - project(p, v - e)) / (2 * step)
        assert np.abs(fd - d_intr[..., i]).max() < 1e-6 * (1 + np.abs(fd).max())


def test_jacobians_of_opencv_agree() -> None:
    """OpenCV's own Jacobian of projectPoints (columns f, c, distortion) agrees with ours."""
    lens = LENSES[0]
    p = _points(np.random.default_rng(6), (20,))
    K, d = lens.opencv()
    _, J = cv2.projectPoints(p, np.zeros(3), np.zeros(3), K, d)
    _, _, d_intr = project_with_jacobians(p, lens.vector())
    ours = d_intr.reshape(-1, 9)
    # OpenCV's columns: rvec(3), tvec(3), fx, fy, cx, cy, k1, k2, p1, p2, k3
    assert np.allclose(J[:, 6:15], ours, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("lens", LENSES)
def test_opencv_round_trip(lens: Intrinsics) -> None:
    K, d = lens.opencv()
    assert Intrinsics.from_opencv(K, d, lens.width_px, lens.height_px) == lens
    # OpenCV's calibrateCamera returns distCoeffs as (1, 5)
    assert Intrinsics.from_opencv(K, d[None], lens.width_px, lens.height_px) == lens


@pytest.mark.parametrize("lens", LENSES)
def test_camera_info_round_trip(lens: Intrinsics) -> None:
    text = camera_info_text(lens, "cell_camera")
    assert "distortion_model: plumb_bob" in text and "camera_name: cell_camera" in text
    assert intrinsics_from_camera_info(text) == lens


def test_camera_info_of_ros_reads() -> None:
    """A file as ROS camera_calibration writes it (its documented example's layout)."""
    text = """image_width: 640
image_height: 480
camera_name: narrow_stereo
camera_matrix:
  rows: 3
  cols: 3
  data: [430.2, 0, 306.5, 0, 430.8, 244.1, 0, 0, 1]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [-0.337, 0.1, 0.0011, -0.0005, 0]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]
projection_matrix:
  rows: 3
  cols: 4
  data: [430.2, 0, 306.5, 0, 0, 430.8, 244.1, 0, 0, 0, 1, 0]
"""
    lens = intrinsics_from_camera_info(text)
    assert (lens.fx, lens.cy, lens.k1, lens.p1, lens.k3) == (430.2, 244.1, -0.337, 0.0011, 0.0)


@pytest.mark.parametrize(
    "text, words",
    [
        ("[1, 2]", "not a YAML mapping"),
        ("image_width: 640\nimage_height: 480\ndistortion_model: equidistant\n", "distortion_mo"),
        ("image_width: 640\nimage_height: 480\ncamera_matrix: {data: [1, 2]}\n", "camera_matrix"),
        ("camera_matrix: {data: [1, 0, 1, 0, 1, 1, 0, 0, 1]}\n", "no image size"),
        ("a: [\n", "not YAML"),
    ],
)
def test_bad_camera_info_is_one_line(text: str, words: str) -> None:
    with pytest.raises(ArmsigError) as err:
        intrinsics_from_camera_info(text, "cam.yaml")
    assert words in str(err.value) and "\n" not in str(err.value)


def test_rational_model_is_refused() -> None:
    K = LENSES[1].camera_matrix()
    with pytest.raises(ArmsigError, match="CALIB_RATIONAL_MODEL"):
        Intrinsics.from_opencv(K, [0.1, 0, 0, 0, 0, 0.2, 0, 0], 640, 480)
    with pytest.raises(ArmsigError, match="fx, fy > 0"):
        Intrinsics(640, 480, -1.0, 500.0, 320.0, 240.0)
