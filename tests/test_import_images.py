"""``pipeline import --format images`` (pipeline.importers.images, issue 40):
industrial_calibration's real sets as they are, and bad inputs on a rendered set."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from pipeline.contract.channels import IMAGE_SET_CHANNELS
from pipeline.contract.digest import file_sha256
from pipeline.contract.mcap_read import read_mcap
from pipeline.errors import ImportFileError, RecordingError
from pipeline.importers.images import import_image_set
from pipeline.kinematics.transforms import rot_x, rot_z, trans
from pipeline.rig.camera_render import render
from pipeline.sensor.camera import Intrinsics
from pipeline.sensor.target import Target
from pipeline.stages.recording import read_recording

ROOT = Path(__file__).resolve().parents[1]
REALDATA = Path(os.environ.get("ARMSIG_REALDATA", ROOT.parent / "shared" / "realdata"))
IC = REALDATA / "industrial_calibration"
needs_ic = pytest.mark.skipif(not IC.is_dir(), reason=f"no real images at {IC}")


def _messages(recording: Path) -> dict[str, list[dict]]:
    msgs = read_mcap(recording, IMAGE_SET_CHANNELS, "re-import").messages
    return {t: [m for _, m in msgs[t]] for t in IMAGE_SET_CHANNELS}


@needs_ic
@pytest.mark.parametrize(
    "folder, setup, kept, points",
    [
        # 24 ChArUco corners in every image but image 14 (22)
        ("test_set_charuco", "eye-to-hand", 16, [24] * 14 + [22, 24]),
        ("test_set_10x10", "eye-in-hand", 15, [100] * 15),
    ],
)
def test_real_sets_import_as_they_are(
    tmp_path: Path, folder: str, setup: str, kept: int, points: list[int]
) -> None:
    """cal_data.yaml read unchanged: every image kept, its hash and flange pose (cm,
    w-first) recorded; the session says the arm cannot be calibrated, in one line."""
    s, recording = import_image_set(IC / folder / "cal_data.yaml", tmp_path / "s")
    assert (s.setup, s.kept, len(s.images)) == (setup, kept, kept)
    msgs = _messages(recording)
    by_image = {m["file"]: m for m in msgs["/camera/images"]}
    counts = {m["step"]: len(m["point_ids"]) for m in msgs["/camera/detections"]}
    files = [m["file"] for m in msgs["/camera/images"]]
    assert [counts[k] for k in range(kept)] == [points[int(Path(f).stem)] for f in files]
    for f, m in by_image.items():
        assert m["sha256"] == file_sha256(IC / folder / f) and m["dropped"] == ""
    rig = msgs["/rig/description"][0]
    assert rig["setup"] == setup and rig["arm"].startswith("not calibrated")
    pose0 = (IC / folder / "poses" / "0.yaml").read_text().split("\n")
    x = float(next(line for line in pose0 if line.startswith("x:")).split(":")[1])
    qw = float(next(line for line in pose0 if line.startswith("qw:")).split(":")[1])
    first = msgs["/robot/flange_pose"][files.index("images/0.png")]
    assert abs(first["position_cm"][0] - 100 * x) < 1e-9
    assert abs(abs(first["orientation_wxyz"][0]) - abs(qw)) < 1e-9
    with pytest.raises(RecordingError) as err:
        read_recording(recording)
    assert "arm cannot be calibrated" in str(err.value) and "\n" not in str(err.value)


TARGET = Target("charuco", 5, 7, 3.0, 2.2, "DICT_5X5_100")
LENS = Intrinsics(640, 480, 600.0, 600.0, 320.0, 240.0)
POSE = "x: {x}\ny: 0.5\nz: 0.4\nqx: 0.0\nqy: 0.0\nqz: 0.0\nqw: 1.0\n"


def _image_set(folder: Path, n: int = 5) -> Path:
    """A rendered ChArUco set of ``n`` images in industrial_calibration's layout."""
    (folder / "images").mkdir(parents=True)
    (folder / "poses").mkdir()
    centre = TARGET.points()[1].mean(axis=0)
    lines = ["data:"]
    for k in range(n):
        T = trans(0.0, 0.0, 45.0) @ rot_x(np.radians(10 + 5 * k)) @ rot_z(np.radians(20 * k))
        image = render(TARGET, np.asarray(T @ trans(*(-centre)), float), LENS, px_per_cm=20)
        cv2.imwrite(str(folder / "images" / f"{k}.png"), image)
        (folder / "poses" / f"{k}.yaml").write_text(POSE.format(x=0.1 * k))
        lines += [f"  - image: images/{k}.png", f"    pose: poses/{k}.yaml"]
    lines += [
        "target_finder:", "  type: CharucoGridTargetFinder", "  rows: 5", "  cols: 7",
        "  chessboard_dim: 0.03", "  aruco_marker_dim: 0.022", "  dictionary: 6",
        "intrinsics:", "  fx: 600.0", "  fy: 600.0", "  cx: 320.0", "  cy: 240.0",
        "static_camera: true",
    ]  # fmt: skip
    (folder / "cal_data.yaml").write_text("\n".join(lines) + "\n")
    return folder / "cal_data.yaml"


def test_rendered_set_imports(tmp_path: Path) -> None:
    """Every rendered image kept, every one of its 24 corners found."""
    s, recording = import_image_set(_image_set(tmp_path / "set"), tmp_path / "s")
    assert s.kept == 5 and s.drops() == []
    assert [len(m["point_ids"]) for m in _messages(recording)["/camera/detections"]] == [24] * 5


def test_bad_images_are_dropped_one_line_each(
    tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    """A missing image, a corrupted PNG and an image of another board are dropped, each
    with one line naming the file (libpng's own complaint kept off stderr); the set still
    imports from the three left."""
    cal = _image_set(tmp_path / "set", 6)
    images = tmp_path / "set" / "images"
    (images / "0.png").unlink()
    data = (images / "1.png").read_bytes()
    (images / "1.png").write_bytes(data[: len(data) // 3])  # truncated: not decodable
    other = Target("checkerboard", 6, 7, 3.0)
    centre = other.points()[1].mean(axis=0)
    T = np.asarray(trans(0.0, 0.0, 45.0) @ rot_x(0.2) @ trans(*(-centre)), float)
    cv2.imwrite(str(images / "2.png"), render(other, T, LENS, px_per_cm=20))
    s, recording = import_image_set(cal, tmp_path / "s")
    assert capfd.readouterr().err == ""
    drops = s.drops()
    assert s.kept == 3 and len(drops) == 3
    assert drops[0].startswith("images/0.png: missing")
    assert drops[1].startswith("images/1.png: unreadable")
    assert drops[2].startswith("images/2.png: not_found")
    assert all("\n" not in line for line in drops)
    recorded = _messages(recording)["/camera/images"]
    assert [m["dropped"] for m in recorded] == ["missing", "unreadable", "not_found", "", "", ""]
    assert recorded[0]["sha256"] == "" and recorded[1]["sha256"] == file_sha256(images / "1.png")


@pytest.mark.parametrize(
    "damage, words",
    [
        (
            lambda d: (d / "poses" / "3.yaml").write_text("x: 0.1\ny: 0.5\nz: 0.4\n"),
            "poses/3.yaml: file: must contain",
        ),  # a pose without its quaternion
        (
            lambda d: (d / "poses" / "3.yaml").write_text(POSE.format(x=0.1).replace("1.0", "0.5")),
            "poses/3.yaml: the quaternion is not a rotation",
        ),
        (lambda d: (d / "poses" / "3.yaml").unlink(), "poses/3.yaml: no such pose file"),
        (
            lambda d: (d / "cal_data.yaml").write_text(
                (d / "cal_data.yaml").read_text().replace("    pose: poses/2.yaml\n", "")
            ),
            "cal_data.yaml: data[2]: must contain",
        ),  # an entry naming no pose
        (
            lambda d: (d / "cal_data.yaml").write_text(
                (d / "cal_data.yaml").read_text().replace("  rows: 5\n", "")
            ),
            "cal_data.yaml: target_finder: must contain",
        ),
        (
            lambda d: (d / "cal_data.yaml").write_text(
                (d / "cal_data.yaml").read_text().replace("images/4.png", "images/0.png")
            ),
            "images/0.png is the same image as images/0.png",
        ),
        (lambda d: shutil.rmtree(d / "images"), "0 of 5 images kept"),
    ],  # fmt: skip
    ids=[
        "no quaternion",
        "not a rotation",
        "no pose file",
        "entry without pose",
        "finder without rows",
        "duplicate image",
        "no image left",
    ],  # fmt: skip
)
def test_bad_inputs_are_one_line(tmp_path: Path, damage: object, words: str) -> None:
    cal = _image_set(tmp_path / "set")
    damage(tmp_path / "set")  # type: ignore[operator]
    with pytest.raises(ImportFileError) as err:
        import_image_set(cal, tmp_path / "s")
    assert words in str(err.value) and "\n" not in str(err.value)
    assert not (tmp_path / "s" / "recording.mcap").exists()
