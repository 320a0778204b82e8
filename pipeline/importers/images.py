"""``pipeline import --format images``: a folder of camera images with the flange pose at
each image -> a camera session recording (issue 40; docs/import.md, "Image sets").

The file read is industrial_calibration's ``cal_data.yaml``, as it is
(``schemas/import/ic_cal_data.json``): ``data`` lists each image with its pose file (the
flange in the base, x, y, z m and qx, qy, qz, qw: ``schemas/import/flange_pose.json``),
``target_finder`` the board, ``intrinsics`` the lens, ``static_camera`` the set-up.

Each image is hashed (SHA-256) and detected here, at import
(:func:`pipeline.sensor.detect.detect_target`): the recording holds per image its file
and hash and why it was dropped (``/camera/images``), the points found in a kept one
(``/camera/detections``) and the flange pose (``/robot/flange_pose``, cm). The image bytes
stay beside the recording. A missing or unreadable image is dropped, not refused, with
one line naming it; the import is refused when fewer than :data:`MIN_IMAGES` remain.
Without joint readings the arm cannot be calibrated: ``/rig/description`` says so
(``arm``), and the stages refuse the session in one line naming why.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.contract.channels import IMAGE_SET_CHANNELS
from pipeline.contract.digest import file_sha256
from pipeline.errors import ArmsigError, ImportFileError, one_line
from pipeline.importers.rows import LENGTH_CM
from pipeline.importers.sscanss2 import read_text
from pipeline.importers.write import SOURCE_METADATA, source_metadata
from pipeline.importers.yamlfile import load_yaml
from pipeline.quiet import debugging
from pipeline.rig.recorder import Message, refuse_existing_recording, write_recording
from pipeline.schemas import compiled_validator, expected_in_words, first_non_finite
from pipeline.sensor.camera import Intrinsics
from pipeline.sensor.detect import DetectorSettings, ImageDetection, detect_target
from pipeline.sensor.target import Target
from pipeline.stages.lock import session_lock

FORMAT = "images"
#: Hand-eye calibration needs at least 3 poses with two non-parallel rotation axes.
MIN_IMAGES = 3
#: A stored quaternion's norm may differ from 1 by this much (rounding of a text file), as
#: for robot_cal_tools' files (importers/rct.py).
QUAT_NORM_TOL = 1e-3
#: The arm is not calibrated from flange poses: what /rig/description ``arm`` says.
ARM_NOT_CALIBRATED = (
    "not calibrated: flange poses from the robot's own kinematics, no joint readings; "
    "the camera's intrinsics and the hand-eye transforms only"
)
T0_NS = 1_767_225_600 * 10**9  # 2026-01-01T00:00:00Z: the recording carries no foreign time
STEP_NS = 10**9
_FIX = "correct the file (docs/import.md, Image sets)"
#: Stated σ of a detected point (px): OpenCV's corner refinement on real images, ~0.1-0.3 px.
SIGMA_PX = 0.2


@dataclass(frozen=True)
class ImageEntry:
    """One image of the set: its path, its content hash ("" when missing), the flange
    pose in the base (4, 4, cm), what the detector found."""

    file: str
    path: Path
    sha256: str
    flange_in_base: np.ndarray
    found: ImageDetection
    size_px: tuple[int, int] | None


@dataclass(frozen=True)
class ImageSet:
    """An image set read and detected: the set-up, the lens, the target, the images."""

    source: Path
    setup: str
    lens: Intrinsics
    target: Target
    images: tuple[ImageEntry, ...]

    @property
    def kept(self) -> int:
        return sum(e.found.kept for e in self.images)

    def drops(self) -> list[str]:
        """One line per dropped image: its file and why."""
        return [f"{e.file}: {e.found.dropped}: {e.found.why}" for e in self.images
                if not e.found.kept]  # fmt: skip


def _checked(src: str, data: Any, schema: str) -> Any:
    from fastjsonschema import JsonSchemaValueException

    bad = first_non_finite(data)
    if bad is not None:
        raise ImportFileError(f"{src}: {bad[0]}: is not a finite number", got=repr(bad[1]),
                              fix=_FIX)  # fmt: skip
    try:
        compiled_validator(schema)(data)
    except JsonSchemaValueException as exc:
        name = str(exc.name)
        key = name.removeprefix("data").removeprefix(".") or "file"
        raise ImportFileError(
            f"{src}: {key}: {one_line(exc.message.removeprefix(name).strip(), 80)}",
            expected=expected_in_words(str(exc.rule), exc.definition or {}),
            got=one_line(repr(exc.value), 80),
            fix=_FIX,
        ) from None
    return data


def _target(src: str, finder: dict[str, Any]) -> Target:
    """The armsig target of industrial_calibration's ``target_finder`` (m -> cm)."""
    import cv2

    from pipeline.sensor.target import DICTIONARY_SIZES, target_from_dict

    cm = LENGTH_CM["m"]
    rows, cols = int(finder["rows"]), int(finder["cols"])
    need: tuple[str, ...] = ("chessboard_dim", "aruco_marker_dim", "dictionary")
    if finder["type"] == "ModifiedCircleGridTargetFinder":
        need = ("spacing",)
    missing = [k for k in need if k not in finder]
    if missing:
        raise ImportFileError(
            f"{src}: target_finder: no {missing[0]}",
            expected=f"{finder['type']} with " + ", ".join(need),
            fix=_FIX,
        )
    if finder["type"] == "ModifiedCircleGridTargetFinder":
        data = {"kind": "circles", "rows": rows, "columns": cols,
                "spacing_cm": finder["spacing"] * cm, "origin_dot": True}  # fmt: skip
    else:
        names = {int(getattr(cv2.aruco, n)): n for n in DICTIONARY_SIZES}
        if finder["dictionary"] not in names:
            raise ImportFileError(f"{src}: target_finder: dictionary {finder['dictionary']} "
                                  "is not an OpenCV predefined dictionary",
                                  expected=f"one of {sorted(names)}", fix=_FIX)  # fmt: skip
        data = {"kind": "charuco", "rows": rows, "columns": cols,
                "spacing_cm": finder["chessboard_dim"] * cm,
                "marker_cm": finder["aruco_marker_dim"] * cm,
                "dictionary": names[finder["dictionary"]]}  # fmt: skip
    try:
        return target_from_dict(data, f"{src}: target_finder")
    except ArmsigError as exc:
        raise ImportFileError(str(exc)) from None


def _pose(path: Path, name: str, src: str) -> np.ndarray:
    """The flange in the base (4, 4, cm) of one pose file (``name``: as ``src`` names it)."""
    from scipy.spatial.transform import Rotation

    if not path.is_file():
        raise ImportFileError(f"{name}: no such pose file (named by {src})", fix=_FIX)
    p = _checked(name, load_yaml(read_text(path), name), "import/flange_pose.json")
    q = np.array([p["qx"], p["qy"], p["qz"], p["qw"]], float)
    norm = float(np.linalg.norm(q))
    if abs(norm - 1.0) > QUAT_NORM_TOL:
        raise ImportFileError(f"{name}: the quaternion is not a rotation",
                              expected=f"norm 1 ± {QUAT_NORM_TOL:g}", got=f"{norm:g}",
                              fix=_FIX)  # fmt: skip
    T = np.eye(4)
    T[:3, :3] = Rotation.from_quat(q / norm).as_matrix()  # scipy: x, y, z, w
    T[:3, 3] = np.array([p["x"], p["y"], p["z"]], float) * LENGTH_CM["m"]
    return T


def _detect(path: Path, target: Target, settings: DetectorSettings) -> tuple[
    str, ImageDetection, tuple[int, int] | None
]:  # fmt: skip
    """(sha256, detection, (width, height)) of one image; a missing or unreadable file is a
    drop."""
    import cv2

    from pipeline.sensor.detect import no_points

    if not path.is_file():
        return "", no_points("missing", "no such file"), None
    sha = file_sha256(path)
    with _libpng_quiet():
        image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)  # 8-bit grey, also from 16-bit
    if image is None:
        return sha, no_points("unreadable", "OpenCV cannot decode it (not an image, or "
                          "corrupted)"), None  # fmt: skip
    grey = np.asarray(image, np.uint8)
    return sha, detect_target(grey, target, settings), (grey.shape[1], grey.shape[0])


@contextlib.contextmanager
def _libpng_quiet() -> Iterator[None]:
    """libpng writes "libpng error: Read Error" straight to the process's stderr (fd 2)
    for a corrupted PNG, past Python and OpenCV's log level; armsig says it in one line
    itself, so fd 2 points at /dev/null while OpenCV decodes (unless ARMSIG_DEBUG=1)."""
    if debugging():
        yield
        return
    saved = os.dup(2)
    try:
        with open(os.devnull, "wb") as null:
            os.dup2(null.fileno(), 2)
            yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def read_image_set(path: str | Path, settings: DetectorSettings | None = None) -> ImageSet:
    """Read industrial_calibration's ``cal_data.yaml`` and detect every image it lists."""
    src_path = Path(path)
    src = src_path.name
    if not src_path.is_file():
        raise ImportFileError(f"{src_path}: no such file", fix="check the path")
    data = _checked(src, load_yaml(read_text(src_path), src), "import/ic_cal_data.json")
    target = _target(src, data["target_finder"])
    k = data["intrinsics"]
    root = src_path.parent
    entries = []
    sizes = set()
    settings = settings or DetectorSettings()
    for e in data["data"]:
        pose = _pose(root / e["pose"], e["pose"], src)
        image_path = root / e["image"]
        sha, found, size = _detect(image_path, target, settings)
        if size is not None:
            sizes.add(size)
        entries.append(ImageEntry(e["image"], image_path, sha, pose, found, size))
    if len(sizes) > 1:
        raise ImportFileError(
            f"{src}: images of {len(sizes)} sizes",
            expected="one camera, one image size",
            got=", ".join(f"{w} × {h}" for w, h in sorted(sizes)),
            fix=_FIX,
        )
    _refuse_duplicates(src, entries)
    kept = sum(x.found.kept for x in entries)
    if kept < MIN_IMAGES:
        raise ImportFileError(
            f"{src}: {kept} of {len(entries)} images kept",
            expected=f"at least {MIN_IMAGES} images with the target found",
            got="; ".join(f"{x.file}: {x.found.dropped}" for x in entries if not x.found.kept)[
                :200
            ],
            fix="check the target_finder against the board in the images",
        )
    w, h = sizes.pop()
    lens = Intrinsics(w, h, float(k["fx"]), float(k["fy"]), float(k["cx"]), float(k["cy"]))
    setup = "eye-to-hand" if data["static_camera"] else "eye-in-hand"
    return ImageSet(src_path, setup, lens, target, tuple(entries))


def _refuse_duplicates(src: str, entries: list[ImageEntry]) -> None:
    """The same image file twice, or the same bytes under two names, is one measurement
    counted twice."""
    seen: dict[str, str] = {}
    for e in entries:
        key = e.sha256 or f"missing:{e.file}"
        if key in seen:
            raise ImportFileError(
                f"{src}: {e.file} is the same image as {seen[key]}",
                expected="each image once",
                fix="delete one of the entries",
            )
        seen[key] = e.file


def image_set_messages(s: ImageSet) -> list[Message]:
    """The recording's messages (module docstring), one step per image in file order."""
    from scipy.spatial.transform import Rotation

    rig = {
        "sensor": "camera",
        "instrument": f"camera images ({s.source.name}, imported)",
        "setup": s.setup,
        "camera": s.lens.to_dict(),
        "target": s.target.to_dict(),
        "images_dir": str(s.source.parent.resolve()),
        "arm": ARM_NOT_CALIBRATED,
    }
    messages = [Message("/rig/description", T0_NS, rig)]
    for step, e in enumerate(s.images):
        t_ns = T0_NS + (step + 1) * STEP_NS
        f = e.found
        image: dict[str, Any] = {"sweep": "poses", "step": step, "file": e.file,
                                 "sha256": e.sha256, "dropped": f.dropped, "why": f.why,
                                 "markers": f.markers,
                                 "edge_width_px": None if np.isnan(f.edge_width_px)
                                 else round(f.edge_width_px, 3)}  # fmt: skip
        if e.size_px is not None:
            image["width_px"], image["height_px"] = e.size_px
        messages.append(Message("/camera/images", t_ns, image))
        xyzw = Rotation.from_matrix(e.flange_in_base[:3, :3]).as_quat()
        messages.append(Message("/robot/flange_pose", t_ns, {
            "sweep": "poses", "step": step,
            "position_cm": [float(v) for v in e.flange_in_base[:3, 3]],
            "orientation_wxyz": [float(xyzw[3]), *(float(v) for v in xyzw[:3])],
        }))  # fmt: skip
        if f.kept:
            messages.append(Message("/camera/detections", t_ns, {
                "sweep": "poses", "step": step, "point_ids": [int(i) for i in f.point_ids],
                "u_px": [float(u) for u in f.uv_px[:, 0]],
                "v_px": [float(v) for v in f.uv_px[:, 1]], "sigma_px": SIGMA_PX,
            }))  # fmt: skip
    return messages


def import_image_set(
    path: str | Path, session_dir: str | Path, force: bool = False
) -> tuple[ImageSet, Path]:
    """Read, detect and write ``session_dir/recording.mcap`` (module docstring)."""
    s = read_image_set(path)
    sdir = Path(session_dir)
    refuse_existing_recording(sdir, force, "the imported one")
    sdir.mkdir(parents=True, exist_ok=True)
    recording = sdir / "recording.mcap"
    with session_lock(sdir):
        refuse_existing_recording(sdir, force, "the imported one")
        meta = {SOURCE_METADATA: source_metadata(s.source, FORMAT, None)}
        write_recording(recording, image_set_messages(s), IMAGE_SET_CHANNELS, meta)  # atomic
    return s, recording
