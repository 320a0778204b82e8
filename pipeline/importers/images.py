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

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.atomic import TEMP_SUFFIX
from pipeline.contract.channels import CAMERA_IMAGE_CHANNELS, IMAGE_SET_CHANNELS
from pipeline.contract.digest import file_sha256
from pipeline.errors import ArmsigError, ImportFileError, one_line
from pipeline.importers.image_map import checked_document
from pipeline.importers.rows import LENGTH_CM
from pipeline.importers.sscanss2 import read_text
from pipeline.importers.write import SOURCE_METADATA, read_back, source_metadata
from pipeline.importers.yamlfile import load_yaml
from pipeline.rig.camera import STATED_SIGMA_PX
from pipeline.rig.recorder import Message, refuse_existing_recording, write_recording
from pipeline.robots.description import RobotDescription
from pipeline.sensor.camera import Intrinsics
from pipeline.sensor.detect import DetectorSettings, ImageDetection, detect_file, image_message
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
#: Stated σ of a detected point's u and v (px): the simulated camera's (issue 39), a prior
#: the fit's residuals judge. Measured: rendered ChArUco corners 0.03-0.04 px RMS from the
#: truth (tests/test_camera_detect.py); on the real images one pose per image through the
#: given lens leaves 0.24-1.05 px, lens distortion included, which no detector σ holds.
SIGMA_PX = STATED_SIGMA_PX


@dataclass(frozen=True)
class ImageEntry:
    """One image of the set: its path, its content hash ("" when missing), the flange
    pose in the base (4, 4, cm) or the joint readings (n, deg / cm), what the detector
    found."""

    file: str
    path: Path
    sha256: str
    flange_in_base: np.ndarray | None
    found: ImageDetection
    size_px: tuple[int, int] | None
    readings: np.ndarray | None = None


@dataclass(frozen=True)
class ImageSet:
    """An image set read and detected: the set-up, the lens, the target, the images."""

    source: Path
    setup: str
    lens: Intrinsics
    target: Target
    images: tuple[ImageEntry, ...]
    robot: RobotDescription | None = None  # the arm, when its joint readings are given

    @property
    def kept(self) -> int:
        return sum(e.found.kept for e in self.images)

    def drops(self) -> list[str]:
        """One line per dropped image: its file and why."""
        return [f"{e.file}: {e.found.dropped}: {e.found.why}" for e in self.images
                if not e.found.kept]  # fmt: skip


def _target(src: str, finder: dict[str, Any]) -> Target:
    """The armsig target of industrial_calibration's ``target_finder`` (m -> cm)."""
    import cv2

    from pipeline.sensor.target import DICTIONARY_SIZES, target_from_dict

    def _cm(m: float) -> float:  # m -> cm, without 1.8256000000000001 for 0.018256 m
        return round(float(m) * LENGTH_CM["m"], 9)

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
                "spacing_cm": _cm(finder["spacing"]), "origin_dot": True}  # fmt: skip
    else:
        names = {int(getattr(cv2.aruco, n)): n for n in DICTIONARY_SIZES}
        if finder["dictionary"] not in names:
            raise ImportFileError(f"{src}: target_finder: dictionary {finder['dictionary']} "
                                  "is not an OpenCV predefined dictionary",
                                  expected=f"one of {sorted(names)}", fix=_FIX)  # fmt: skip
        data = {"kind": "charuco", "rows": rows, "columns": cols,
                "spacing_cm": _cm(finder["chessboard_dim"]),
                "marker_cm": _cm(finder["aruco_marker_dim"]),
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
    p = checked_document(name, load_yaml(read_text(path), name), "import/flange_pose.json")
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
    sha = file_sha256(path) if path.is_file() else ""
    found, size = detect_file(path, target, settings)
    return sha, found, size


def read_image_set(path: str | Path, settings: DetectorSettings | None = None) -> ImageSet:
    """Read industrial_calibration's ``cal_data.yaml`` and detect every image it lists."""
    src_path = Path(path)
    src = src_path.name
    if not src_path.is_file():
        raise ImportFileError(f"{src_path}: no such file", fix="check the path")
    data = checked_document(src, load_yaml(read_text(src_path), src), "import/ic_cal_data.json")
    target = _target(src, data["target_finder"])
    root = src_path.parent
    named: dict[str, str] = {}
    for e in data["data"]:  # one pose file for two images: a copied entry, not two poses
        if e["pose"] in named:
            raise ImportFileError(f"{src}: {e['pose']} is the pose of {named[e['pose']]} and "
                                  f"of {e['image']}", expected="one pose file per image",
                                  fix="correct the entry's pose")  # fmt: skip
        named[e["pose"]] = e["image"]
    poses = [_pose(root / e["pose"], e["pose"], src) for e in data["data"]]
    files = [e["image"] for e in data["data"]]
    entries = _detected(src, root, files, target, settings, poses, None)
    setup = "eye-to-hand" if data["static_camera"] else "eye-in-hand"
    return ImageSet(src_path, setup, _lens(entries, data["intrinsics"]), target, entries)


def read_mapped_image_set(
    table: str | Path, map_path: str | Path, robot: RobotDescription | None,
    settings: DetectorSettings | None = None,
) -> ImageSet:  # fmt: skip
    """Read a table of images with a map (:mod:`pipeline.importers.image_map`) and detect
    every image it lists; ``robot``: the arm whose joint readings the table holds."""
    from pipeline.importers.image_map import load_image_map, read_image_table

    imap = load_image_map(Path(map_path))
    rows = read_image_table(Path(table), imap, robot)
    n = len(rows.files)
    poses = list(rows.flange_in_base) if rows.flange_in_base is not None else [None] * n
    readings = list(rows.readings) if rows.readings is not None else None
    entries = _detected(Path(table).name, imap.images, list(rows.files), imap.target, settings,
                        poses, readings)  # fmt: skip
    arm = robot if rows.readings is not None else None
    return ImageSet(Path(table), imap.setup, _lens(entries, imap.camera), imap.target, entries, arm)


def _detected(
    src: str, root: Path, files: list[str], target: Target, settings: DetectorSettings | None,
    poses: Sequence[np.ndarray | None], readings: list[np.ndarray] | None,
) -> tuple[ImageEntry, ...]:  # fmt: skip
    """Hash and detect each image (``files`` relative to ``root``); refuse two sizes, an
    image twice, fewer than :data:`MIN_IMAGES` kept."""
    entries = []
    for k, name in enumerate(files):
        sha, found, size = _detect(root / name, target, settings or DetectorSettings())
        q = None if readings is None else readings[k]
        entries.append(ImageEntry(name, root / name, sha, poses[k], found, size, q))
    sizes = {e.size_px for e in entries if e.size_px is not None}
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
            got=one_line(
                "; ".join(f"{x.file}: {x.found.dropped}" for x in entries if not x.found.kept), 200
            ),  # fmt: skip
            fix="check the target against the board in the images",
        )
    return tuple(entries)


def _lens(entries: tuple[ImageEntry, ...], k: dict[str, Any]) -> Intrinsics:
    """The stated lens, the image size read from the images."""
    w, h = next(e.size_px for e in entries if e.size_px is not None)
    extra = {n: float(k[n]) for n in ("k1", "k2", "p1", "p2", "k3") if n in k}
    return Intrinsics(w, h, float(k["fx"]), float(k["fy"]), float(k["cx"]), float(k["cy"]), **extra)


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
    """The recording's messages (module docstring). Kept images are steps 0, 1, ... of
    sweep ``poses`` in file order; with joint readings a dropped image has no joint state
    and its ``/camera/images`` step follows the kept ones."""
    from scipy.spatial.transform import Rotation

    rig: dict[str, Any] = {
        "sensor": "camera",
        "instrument": f"camera images ({s.source.name}, imported)",
        "setup": s.setup,
        "camera": s.lens.to_dict(),
        "target": s.target.to_dict(),
        "images_dir": str(_images_dir(s.images[0]).resolve()),
    }
    if s.robot is None:
        rig["arm"] = ARM_NOT_CALIBRATED
    messages = [Message("/rig/description", T0_NS, rig)]
    kept = [e for e in s.images if e.found.kept]
    order = kept + [e for e in s.images if not e.found.kept] if s.robot else list(s.images)
    if s.robot is not None:
        messages.append(_robot_message(s.robot, kept))
    for step, e in enumerate(order):
        t_ns = T0_NS + (step + 1) * STEP_NS
        f = e.found
        messages.append(Message("/camera/images", t_ns, _image_message(step, e)))
        if e.flange_in_base is not None:
            xyzw = Rotation.from_matrix(e.flange_in_base[:3, :3]).as_quat()
            messages.append(Message("/robot/flange_pose", t_ns, {
                "sweep": "poses", "step": step,
                "position_cm": [float(v) for v in e.flange_in_base[:3, 3]],
                "orientation_wxyz": [float(xyzw[3]), *(float(v) for v in xyzw[:3])],
            }))  # fmt: skip
        if not f.kept:
            continue
        if e.readings is not None:
            q = [float(v) for v in e.readings]
            units = [j.unit for j in s.robot.joints] if s.robot else []
            messages.append(Message("/robot/joint_state", t_ns, {
                "sweep": "poses", "step": step, "q_commanded": q, "q_encoder": q, "units": units,
            }))  # fmt: skip
        messages.append(Message("/camera/detections", t_ns + STEP_NS // 10, {
            "sweep": "poses", "step": step, "point_ids": [int(i) for i in f.point_ids],
            "u_px": [float(u) for u in f.uv_px[:, 0]],
            "v_px": [float(v) for v in f.uv_px[:, 1]], "sigma_px": SIGMA_PX,
        }))  # fmt: skip
    return messages


def _images_dir(e: ImageEntry) -> Path:
    """The folder the images' ``file`` names are relative to (``path = folder / file``)."""
    return e.path.parents[len(Path(e.file).parts) - 1]


def _image_message(step: int, e: ImageEntry) -> dict[str, Any]:
    return image_message(step, e.file, e.sha256, e.found, e.size_px)


def _robot_message(robot: RobotDescription, kept: list[ImageEntry]) -> Message:
    """``/robot/description`` of a session with joint readings: a pose set of the kept
    images, q^s the first one's readings, the tool point unknown (0: the camera fit
    finds the hand-eye transform)."""
    from pipeline.robots.description import description_to_dict

    first = kept[0].readings
    assert first is not None
    plan = {"n_avg": 1, "order": ["poses"], "sweeps": [], "tool_local_cm": [0.0, 0.0, 0.0],
            "poses": {"n_points": len(kept)}}  # fmt: skip
    return Message("/robot/description", T0_NS, {
        "robot": description_to_dict(robot), "signature_q": [float(v) for v in first],
        "plan": plan, "mode": "imported",
    })  # fmt: skip


def import_image_set(
    path: str | Path, session_dir: str | Path, force: bool = False,
    map_path: str | Path | None = None, robot_path: str | Path | None = None,
) -> tuple[ImageSet, Path]:  # fmt: skip
    """Read, detect and write ``session_dir/recording.mcap`` (module docstring): ``path``
    is industrial_calibration's ``cal_data.yaml``, or with ``map_path`` a table of images
    (and ``robot_path`` the arm whose joint readings it holds)."""
    from pipeline.robots.description import load_description

    if map_path is None:
        if robot_path is not None:
            raise ImportFileError(f"{Path(path).name}: cal_data.yaml holds flange poses, no "
                                  "joint readings: no --robot", fix="drop --robot")  # fmt: skip
        s = read_image_set(path)
    else:
        robot = None if robot_path is None else load_description(robot_path)
        s = read_mapped_image_set(path, map_path, robot)
    sdir = Path(session_dir)
    refuse_existing_recording(sdir, force, "the imported one")
    sdir.mkdir(parents=True, exist_ok=True)
    recording = sdir / "recording.mcap"
    channels = IMAGE_SET_CHANNELS if s.robot is None else CAMERA_IMAGE_CHANNELS
    meta = {
        SOURCE_METADATA: source_metadata(
            [s.source], FORMAT, None if map_path is None else Path(map_path)
        )
    }
    with session_lock(sdir):
        refuse_existing_recording(sdir, force, "the imported one")
        staged = sdir / f".{recording.name}.import{TEMP_SUFFIX}"  # debris if killed
        write_recording(staged, image_set_messages(s), channels, meta)
        if s.robot is not None:
            read_back(staged, s.source.name, "check the joint columns and their units")
        os.replace(staged, recording)
    return s, recording
