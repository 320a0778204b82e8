"""Camera targets: planar grids of known points, described in a target file (TOML).

A target file (``schemas/camera/target.json``) names the kind, ``rows`` × ``columns``,
``spacing_cm`` and, for boards with markers, ``marker_cm`` and the OpenCV ``dictionary``.
:meth:`Target.points` gives every point's id and its coordinates in the target's frame
(cm, Z = 0 on the board, X along a row, Y down the columns), with OpenCV's geometry and
ids where OpenCV has a board of that kind:

- ``checkerboard`` and ``charuco``: the ``(rows − 1) · (columns − 1)`` inner corners of
  ``rows × columns`` squares of side ``spacing_cm``, id ``r · (columns − 1) + c`` at
  ``((c + 1) s, (r + 1) s)`` (``cv2.aruco.CharucoBoard((columns, rows), ...)``'s
  ``getChessboardCorners()`` and ChArUco corner ids);
- ``circles``: a symmetric grid of circle centres, id ``r · columns + c`` at ``(c s, r s)``
  (``cv2.findCirclesGrid``'s order for a ``(columns, rows)`` pattern); with
  ``origin_dot = true`` (industrial_calibration's "modified circle grid") id 0 is the larger
  dot and Z = X × Y points into the board (:mod:`pipeline.sensor.detect`);
- ``aruco`` and ``apriltag``: ``rows × columns`` markers of side ``marker_cm`` whose first
  corners are ``spacing_cm`` apart, marker ``first_id + r · columns + c``; its four corners
  (OpenCV's order: top-left, top-right, bottom-right, bottom-left) have ids
  ``4 · marker + k`` (``cv2.aruco.GridBoard((columns, rows), marker, spacing − marker,
  ...)``'s ``getObjPoints()``).

Whether a detector needs the whole board in view: a checkerboard and a circle grid are
found whole or not at all; ChArUco corners and markers are found one by one
(:attr:`Target.whole_board`).
"""

from __future__ import annotations

import tomllib
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from pipeline.errors import ArmsigError, one_line
from pipeline.schemas import compiled_validator, expected_in_words, first_non_finite

SCHEMA = "camera/target.json"
KINDS = ("checkerboard", "charuco", "circles", "aruco", "apriltag")
#: Markers in each OpenCV predefined dictionary (``bytesList.shape[0]``; tested against it).
DICTIONARY_SIZES = {
    **{f"DICT_{b}X{b}_{n}": n for b in (4, 5, 6, 7) for n in (50, 100, 250, 1000)},
    "DICT_ARUCO_ORIGINAL": 1024,
    "DICT_ARUCO_MIP_36h12": 250,
    "DICT_APRILTAG_16h5": 30,
    "DICT_APRILTAG_25h9": 35,
    "DICT_APRILTAG_36h10": 2320,
    "DICT_APRILTAG_36h11": 587,
}
_MARKERS = ("charuco", "aruco", "apriltag")
_FIX = "correct the target file (schemas/camera/target.json, docs/camera.md)"


@dataclass(frozen=True)
class Target:
    """A planar target (module docstring); lengths in cm."""

    kind: str
    rows: int
    columns: int
    spacing_cm: float
    marker_cm: float = 0.0
    dictionary: str = ""
    first_id: int = 0
    origin_dot: bool = False  # circles: a larger dot marks the origin (issue 40)

    @property
    def whole_board(self) -> bool:
        """A detector finds this target whole or not at all (checkerboard, circles)."""
        return self.kind in ("checkerboard", "circles")

    @property
    def markers(self) -> int:
        """Markers on the board (ChArUco: one in every other square, as OpenCV lays them)."""
        if self.kind == "charuco":
            return self.rows * self.columns // 2
        return self.rows * self.columns if self.kind in ("aruco", "apriltag") else 0

    def points(self) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64]]:
        """Point ids (N,) and their coordinates in the target frame (N, 3), cm."""
        s = self.spacing_cm
        if self.kind in ("checkerboard", "charuco"):
            r, c = np.divmod(np.arange((self.rows - 1) * (self.columns - 1)), self.columns - 1)
            xy = np.stack([(c + 1) * s, (r + 1) * s], axis=1)
        elif self.kind == "circles":
            r, c = np.divmod(np.arange(self.rows * self.columns), self.columns)
            xy = np.stack([c * s, r * s], axis=1)
        else:
            r, c = np.divmod(np.arange(self.rows * self.columns), self.columns)
            m = self.marker_cm
            corner = np.array([[0.0, 0.0], [m, 0.0], [m, m], [0.0, m]])
            xy = (np.stack([c * s, r * s], axis=1)[:, None, :] + corner[None]).reshape(-1, 2)
            ids = (self.first_id + np.arange(self.rows * self.columns))[:, None] * 4
            return (ids + np.arange(4)[None]).reshape(-1).astype(np.int64), _plane(xy)
        return np.arange(len(xy), dtype=np.int64), _plane(xy)

    def to_dict(self) -> dict[str, Any]:
        """The target as its file states it (keys with their default value left out)."""
        out = asdict(self)
        defaults = (("marker_cm", 0.0), ("dictionary", ""), ("first_id", 0), ("origin_dot", False))
        for key, default in defaults:
            if out[key] == default:
                del out[key]
        return out


def _plane(xy: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    return np.concatenate([xy, np.zeros((len(xy), 1))], axis=1).astype(np.float64)


def _refuse(src: str, key: str, what: str, expected: str, got: Any) -> ArmsigError:
    return ArmsigError(f"{src}: {key}: {what}", expected=expected,
                       got=one_line(repr(got), 80), fix=_FIX)  # fmt: skip


def target_from_dict(data: Any, src: str = "target") -> Target:
    """A target from its parsed file ``data``, checked against the schema and for what
    one key's schema cannot say (markers and their dictionary); ``src`` names it."""
    from fastjsonschema import JsonSchemaValueException

    bad = first_non_finite(data)
    if bad is not None:
        raise _refuse(src, bad[0], "is not a finite number", "a finite number", bad[1])
    try:
        compiled_validator(SCHEMA)(data)
    except JsonSchemaValueException as exc:
        name = str(exc.name)
        key = name.removeprefix("data").removeprefix(".") or "target"
        what = one_line(exc.message.removeprefix(name).strip(), 80)
        expected = expected_in_words(str(exc.rule), exc.definition or {})
        raise _refuse(src, key, what, expected, exc.value) from None
    target = Target(**data)
    _check_markers(src, target)
    return target


def _check_markers(src: str, t: Target) -> None:
    if t.origin_dot and t.kind != "circles":
        raise _refuse(src, "origin_dot", "only a circle grid has an origin dot",
                      "no origin_dot", t.origin_dot)  # fmt: skip
    if t.kind not in _MARKERS:
        for key in ("marker_cm", "dictionary", "first_id"):
            if key in t.to_dict():
                raise _refuse(src, key, f"a {t.kind} has no markers", "no marker keys",
                              getattr(t, key))  # fmt: skip
        return
    if not t.marker_cm or not t.dictionary:
        raise _refuse(src, "marker_cm" if not t.marker_cm else "dictionary",
                      f"a {t.kind} target needs marker_cm and dictionary",
                      'marker_cm = 3.0 and dictionary = "DICT_5X5_100"', t.to_dict())  # fmt: skip
    if t.marker_cm >= t.spacing_cm:
        raise _refuse(src, "marker_cm", "is not smaller than spacing_cm",
                      f"a marker side below {t.spacing_cm} cm", t.marker_cm)  # fmt: skip
    if (t.kind == "apriltag") != t.dictionary.startswith("DICT_APRILTAG_"):
        raise _refuse(src, "dictionary", f"is not a dictionary of {t.kind} markers",
                      "DICT_APRILTAG_* for apriltag, the others for aruco and charuco",
                      t.dictionary)  # fmt: skip
    if t.kind == "charuco" and t.first_id:
        raise _refuse(src, "first_id", "a charuco board's markers start at 0", "no first_id",
                      t.first_id)  # fmt: skip
    size = DICTIONARY_SIZES[t.dictionary]
    if t.first_id + t.markers > size:
        raise _refuse(src, "dictionary", f"has {size} markers, the board needs ids "
                      f"{t.first_id}..{t.first_id + t.markers - 1}",
                      "a larger dictionary or fewer rows and columns", t.dictionary)  # fmt: skip


def target_from_toml(text: str, src: str = "target") -> Target:
    """A target from the text of its TOML file (module docstring)."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ArmsigError(f"{src}: not a TOML file", got=one_line(str(exc), 80),
                          fix=_FIX) from None  # fmt: skip
    return target_from_dict(data, src)
