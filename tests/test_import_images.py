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
from pipeline.errors import ImportFileError
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
    w-first) recorded; the session reads as a camera session of flange poses."""
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
    rec = read_recording(recording)  # a camera session of flange poses (no arm: issue 40)
    assert (rec.kind, len(rec.flange_step), len(rec.joint_step)) == ("camera-flange", kept, 0)
    assert rec.flange_in_base_cm[files.index("images/0.png"), 0, 3] == pytest.approx(100 * x)


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
        (
            lambda d: (d / "cal_data.yaml").write_text(
                (d / "cal_data.yaml").read_text().replace("poses/4.yaml", "poses/3.yaml")
            ),
            "poses/3.yaml is the pose of images/3.png and of images/4.png",
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
        "duplicate pose",
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


PUMA = ROOT / "pipeline" / "robots" / "data" / "puma560.toml"
MAP = """images = "set/images"
image_column = "image"
target = "board.toml"
setup = "eye-to-hand"
[camera]
fx = 600.0
fy = 600.0
cx = 320.0
cy = 240.0
"""
JOINTS = "".join(f'[[joints]]\ncolumn = "q{j}"\nunit = "rad"\n' for j in range(1, 7))


def _mapped(tmp_path: Path, table: str, extra: str) -> tuple[Path, Path]:
    _image_set(tmp_path / "set", 4)
    (tmp_path / "board.toml").write_text(
        'kind = "charuco"\nrows = 5\ncolumns = 7\nspacing_cm = 3.0\nmarker_cm = 2.2\n'
        'dictionary = "DICT_5X5_100"\n'
    )
    (tmp_path / "map.toml").write_text(MAP + extra)
    (tmp_path / "table.csv").write_text(table)
    return tmp_path / "table.csv", tmp_path / "map.toml"


def _joint_table(rows: int = 4, first: str = "image") -> str:
    lines = [f"{first},q1,q2,q3,q4,q5,q6"]
    lines += [f"{k}.png," + ",".join(f"{0.1 * (k + j):.2f}" for j in range(6)) for k in range(rows)]
    return "\n".join(lines) + "\n"


def test_table_with_joint_readings_is_a_camera_session(tmp_path: Path) -> None:
    """A table of images and joint readings (rad) with a map: the camera session of
    issue 39's contract (pose set, joint states in deg, detections) that identify reads,
    with the images by hash beside it."""
    table, mp = _mapped(tmp_path, _joint_table(), JOINTS)
    s, recording = import_image_set(table, tmp_path / "s", map_path=mp, robot_path=PUMA)
    assert s.robot is not None and s.kept == 4
    rec = read_recording(recording)
    assert rec.sensor == "camera" and len(np.unique(rec.detection_step)) == 4
    assert len(rec.detection_point) == 4 * 24
    assert np.allclose(rec.q_encoder[1], np.degrees([0.1, 0.2, 0.3, 0.4, 0.5, 0.6]))
    images = read_mcap(recording, {"/camera/images": "camera_images"}, "x").messages
    assert [m["sha256"] for _, m in images["/camera/images"]] == [
        file_sha256(tmp_path / "set" / "images" / f"{k}.png") for k in range(4)
    ]
    assert "arm" not in rec.rig


def test_table_with_flange_poses(tmp_path: Path) -> None:
    """[flange] columns (m, quaternion): an image set whose arm is not calibrated."""
    table = "image,x,y,z,qx,qy,qz,qw\n" + "".join(
        f"{k}.png,{0.1 * k},0.5,0.4,0,0,0,1\n" for k in range(4)
    )
    flange = '[flange]\nx = "x"\ny = "y"\nz = "z"\nqx = "qx"\nqy = "qy"\nqz = "qz"\nqw = "qw"\n'
    path, mp = _mapped(tmp_path, table, flange)
    s, recording = import_image_set(path, tmp_path / "s", map_path=mp)
    assert s.robot is None and s.kept == 4
    poses = _messages(recording)["/robot/flange_pose"]
    assert [p["position_cm"][0] for p in poses] == pytest.approx([0.0, 10.0, 20.0, 30.0])


@pytest.mark.parametrize(
    "table, extra, robot, words",
    [
        (_joint_table(first="file"), JOINTS, PUMA, "table.csv: line 1: missing column 'image'"),
        (_joint_table().replace("q6", "q9"), JOINTS, PUMA, "missing column 'q6' (joint 6)"),
        (_joint_table(), JOINTS, None, "map.toml: [[joints]] needs --robot"),
        (_joint_table(), JOINTS.replace('"rad"', '"rd"'), PUMA, "map.toml: joints[0].unit"),
        (_joint_table(), JOINTS + '[flange]\nx = "x"\n', PUMA, "map.toml: flange: must contain"),
        (_joint_table().replace("0.30", "nan"), JOINTS, PUMA, "line 2: joint 4 is missing"),
        (_joint_table().replace("0.50", "9.0"), JOINTS, PUMA, "identify would refuse"),
    ],
    ids=[
        "no image column",
        "no joint column",
        "no robot",
        "bad unit",
        "flange incomplete",
        "empty cell",
        "beyond the limits",
    ],  # fmt: skip
)
def test_bad_maps_and_tables_are_one_line(
    tmp_path: Path, table: str, extra: str, robot: Path | None, words: str
) -> None:
    path, mp = _mapped(tmp_path, table, extra)
    with pytest.raises(ImportFileError) as err:
        import_image_set(path, tmp_path / "s", map_path=mp, robot_path=robot)
    assert words in str(err.value) and "\n" not in str(err.value)
    assert not (tmp_path / "s" / "recording.mcap").exists()


def test_dropped_image_in_a_joint_table(tmp_path: Path) -> None:
    """A missing image of a table with joint readings is dropped: no joint state, its
    /camera/images step after the kept ones; the recording is identify's to read."""
    table, mp = _mapped(tmp_path, _joint_table(), JOINTS)
    (tmp_path / "set" / "images" / "1.png").unlink()
    s, recording = import_image_set(table, tmp_path / "s", map_path=mp, robot_path=PUMA)
    assert s.kept == 3 and s.drops() == ["1.png: missing: no such file"]
    rec = read_recording(recording)
    assert list(rec.joint_step) == [0, 1, 2]
    assert np.allclose(rec.q_encoder[1], np.degrees([0.2, 0.3, 0.4, 0.5, 0.6, 0.7]))  # image 2
    images = read_mcap(recording, {"/camera/images": "camera_images"}, "x").messages
    assert [(m["step"], m["file"]) for _, m in images["/camera/images"]] == [
        (0, "0.png"), (1, "2.png"), (2, "3.png"), (3, "1.png")
    ]  # fmt: skip


def test_cli_import_images(tmp_path: Path) -> None:
    """`pipeline import cal_data.yaml NAME --format images`: one line written, one warning
    line per dropped image, exit 0; a refusal is one line and exit EXIT_REFUSED."""
    from typer.testing import CliRunner

    from pipeline.cli import EXIT_REFUSED, app

    cal = _image_set(tmp_path / "set", 4)
    (tmp_path / "set" / "images" / "3.png").write_bytes(b"not a png")
    runner = CliRunner()
    r = runner.invoke(app, ["import", str(cal), str(tmp_path / "s"), "--format", "images"])
    assert r.exit_code == 0, r.output
    assert r.stdout.startswith("wrote ") and "4 images (eye-to-hand), 3 kept, 72 points" in r.stdout
    assert r.stderr.splitlines() == [
        "warning: images/3.png: unreadable: OpenCV cannot decode it (not an image, or corrupted)"
    ]
    args = ["import", str(cal), str(tmp_path / "t"), "--format", "images", "--robot", str(PUMA)]
    r = runner.invoke(app, args)
    assert r.exit_code == EXIT_REFUSED and len(r.stderr.splitlines()) == 1
    assert "no --robot" in r.stderr
