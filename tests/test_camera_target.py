"""Camera targets (pipeline.sensor.target) against OpenCV's own board geometry, and their
files' checks."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from pipeline.errors import ArmsigError
from pipeline.sensor.target import DICTIONARY_SIZES, Target, target_from_toml


def _dictionary(name: str) -> cv2.aruco.Dictionary:
    return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name))


@pytest.mark.parametrize("rows, columns", [(4, 5), (7, 10), (6, 6)])
def test_charuco_and_checkerboard_corners_are_opencvs(rows: int, columns: int) -> None:
    board = cv2.aruco.CharucoBoard((columns, rows), 4.0, 3.0, _dictionary("DICT_5X5_100"))
    ref = np.asarray(board.getChessboardCorners(), float)
    for kind, extra in (("charuco", dict(marker_cm=3.0, dictionary="DICT_5X5_100")),
                        ("checkerboard", {})):  # fmt: skip
        ids, local = Target(kind, rows, columns, 4.0, **extra).points()  # type: ignore[arg-type]
        assert np.array_equal(ids, np.arange(len(ref)))  # ChArUco corner ids index these
        assert np.abs(local - ref).max() < 1e-6  # OpenCV stores float32 cm
    charuco = Target("charuco", rows, columns, 4.0, 3.0, "DICT_5X5_100")
    assert charuco.markers == len(board.getIds())


@pytest.mark.parametrize(
    "kind, dictionary", [("aruco", "DICT_4X4_50"), ("apriltag", "DICT_APRILTAG_36h11")]
)
def test_marker_grid_is_opencvs_grid_board(kind: str, dictionary: str) -> None:
    rows, columns, marker, spacing, first = 3, 4, 3.0, 4.5, 7
    ids_ref = np.arange(first, first + rows * columns, dtype=np.int32)
    board = cv2.aruco.GridBoard(
        (columns, rows), marker, spacing - marker, _dictionary(dictionary), ids_ref
    )
    ref = np.asarray(board.getObjPoints(), float)  # (markers, 4, 3)
    ids, local = Target(kind, rows, columns, spacing, marker, dictionary, first).points()
    assert np.abs(local - ref.reshape(-1, 3)).max() < 1e-6
    assert np.array_equal(ids.reshape(-1, 4) // 4, np.repeat(board.getIds()[:, None], 4, 1))
    assert np.array_equal(ids % 4, np.tile(np.arange(4), rows * columns))


def test_circle_grid_is_opencvs_pattern_order() -> None:
    """cv2.findCirclesGrid of a drawn symmetric grid returns the centres in our order."""
    rows, columns, px = 4, 5, 40
    image = np.full((rows * px + 2 * px, columns * px + 2 * px), 255, np.uint8)
    for r in range(rows):
        for c in range(columns):
            cv2.circle(image, (px + c * px + px // 2, px + r * px + px // 2), 12, 0, -1)
    found, centers = cv2.findCirclesGrid(image, (columns, rows), flags=cv2.CALIB_CB_SYMMETRIC_GRID)
    assert found
    ids, local = Target("circles", rows, columns, 2.0).points()
    # the detected centres are the local points scaled to px (20 px per cm) and shifted
    expected = local[:, :2] * (px / 2.0) + px + px // 2
    assert np.abs(centers[:, 0] - expected).max() < 0.5  # px: the drawn discs' rounding
    assert np.array_equal(ids, np.arange(rows * columns))


def test_dictionary_sizes_are_opencvs() -> None:
    for name, size in DICTIONARY_SIZES.items():
        assert _dictionary(name).bytesList.shape[0] == size, name


def test_target_file_round_trip() -> None:
    text = 'kind = "charuco"\nrows = 5\ncolumns = 7\nspacing_cm = 4.0\nmarker_cm = 3.0\n'
    text += 'dictionary = "DICT_5X5_100"\n'
    t = target_from_toml(text, "board.toml")
    assert t == Target("charuco", 5, 7, 4.0, 3.0, "DICT_5X5_100")
    assert Target(**t.to_dict()) == t


@pytest.mark.parametrize(
    "text, words",
    [
        ('kind = "chess"\nrows = 5\ncolumns = 7\nspacing_cm = 4.0\n', "kind"),
        ('kind = "circles"\nrows = 5\ncolumns = 7\n', "spacing_cm"),
        ('kind = "circles"\nrows = 5\ncolumns = 7\nspacing_cm = nan\n', "spacing_cm"),
        ('kind = "circles"\nrows = 5\ncolumns = 7\nspacing_cm = 0\n', "spacing_cm"),
        ('kind = "circles"\nrows = 1\ncolumns = 7\nspacing_cm = 2\n', "rows"),
        ('kind = "circles"\nrows = 5\ncolumns = 7\nspacing_cm = 2\ncolour = 1\n', "colour"),
        ('kind = "circles"\nrows = 5\ncolumns = 7\nspacing_cm = 2\nmarker_cm = 1\n', "marker"),
        ('kind = "aruco"\nrows = 5\ncolumns = 7\nspacing_cm = 4\nmarker_cm = 3\n', "dictionary"),
        ('kind = "aruco"\nrows = 5\ncolumns = 7\nspacing_cm = 4\nmarker_cm = 4\n'
         'dictionary = "DICT_4X4_50"\n', "smaller"),
        ('kind = "apriltag"\nrows = 5\ncolumns = 7\nspacing_cm = 4\nmarker_cm = 3\n'
         'dictionary = "DICT_4X4_50"\n', "apriltag"),
        ('kind = "aruco"\nrows = 8\ncolumns = 7\nspacing_cm = 4\nmarker_cm = 3\n'
         'dictionary = "DICT_4X4_50"\n', "has 50 markers"),
        ("kind = \n", "not a TOML file"),
    ],
)  # fmt: skip
def test_bad_target_file_is_one_line(text: str, words: str) -> None:
    with pytest.raises(ArmsigError) as err:
        target_from_toml(text, "board.toml")
    message = str(err.value)
    assert words in message and "board.toml" in message and "\n" not in message


def test_the_example_target_file_is_the_simulators_default() -> None:
    from pathlib import Path

    from pipeline.rig.camera import DEFAULT_TARGET

    path = Path(__file__).resolve().parents[1] / "examples" / "charuco_6x8.toml"
    target = target_from_toml(path.read_text(encoding="utf-8"), str(path))
    assert target == DEFAULT_TARGET and len(target.points()[0]) == 35
