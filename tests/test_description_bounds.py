"""Robot descriptions have bounds: 1-12 joints, limits within ±720° / ±1000 cm, finite
numbers, lengths within ±1000 cm; a malformed description is one line naming the field.

Before the bounds, revolute limits of ±1e6° passed and made the planner allocate 24 GB.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from pipeline.cli import app
from pipeline.errors import RobotDescriptionError
from pipeline.robots import get_robot
from pipeline.robots.description import (
    MAX_ANGLE_DEG,
    MAX_JOINTS,
    MAX_LENGTH_CM,
    description_from_dict,
    description_to_dict,
)
from tests.test_any_robot import _toml

SCARA = description_to_dict(get_robot("scara"))  # RRPR: joint 2 (index 2) is prismatic
Edit = Callable[[dict[str, Any]], None]


def _joint(k: int, **fields: Any) -> Edit:
    return lambda d: d["joints"][k].update(fields)


def _dh(k: int, **fields: Any) -> Edit:
    return lambda d: d["joints"][k]["dh"].update(fields)


def _copies(n: int) -> Edit:
    def edit(d: dict[str, Any]) -> None:
        d["joints"] = [{**d["joints"][0], "name": f"j{i}"} for i in range(n)]

    return edit


OUT_OF_BOUNDS = [
    ("revolute limits ±1e6 deg", _joint(0, limits=[-1e6, 1e6]), "'limits'"),
    ("revolute limit -721 deg", _joint(0, limits=[-721.0, 0.0]), "'limits'"),
    ("prismatic limit 1001 cm", _joint(2, limits=[0.0, 1001.0]), "'limits'"),
    ("13 joints", _copies(MAX_JOINTS + 1), "'joints'"),
    ("0 joints", _copies(0), "'joints'"),
    ("d 1e4 cm", _dh(0, d_cm=1e4), "'d_cm'"),
    ("a -1001 cm", _dh(1, a_cm=-1001.0), "'a_cm'"),
    ("theta 1e6 deg", _dh(0, theta_deg=1e6), "'theta_deg'"),
    ("alpha nan", _dh(0, alpha_deg=float("nan")), "'alpha_deg'"),
    ("resolution above the travel", _joint(0, encoder_resolution=400.0), "'encoder_resolution'"),
    ("resolution 0", _joint(0, encoder_resolution=0.0), "'encoder_resolution'"),
    ("resolution inf", _joint(0, encoder_resolution=float("inf")), "'encoder_resolution'"),
    ("limits as text", _joint(0, limits=["a", "b"]), "'limits'"),
    ("limits of one", _joint(0, limits=[1.0]), "'limits'"),
    ("limit true", _joint(0, limits=[True, 2.0]), "'limits'"),
    ("dh a list", _joint(0, dh=[1, 2]), "'dh'"),
    ("base 2000 cm", lambda d: d.update(base={"xyz_cm": [2000.0, 0.0, 0.0]}), "'xyz_cm'"),
    ("base true", lambda d: d.update(base={"xyz_cm": [True, 0.0, 0.0]}), "'xyz_cm'"),
    ("tool rpy 1e4 deg", lambda d: d.update(tool={"rpy_deg": [0.0, 1e4, 0.0]}), "'rpy_deg'"),
    ("notes a number", lambda d: d.update(notes=3), "'notes'"),
    ("joints a table", lambda d: d.update(joints={"a": 1}), "'joints'"),
    ("joint a number", lambda d: d["joints"].__setitem__(1, 5), "joints[1]"),
    # issue 44: an empty joint name passed simulate and import; identify then refused the
    # signature.json it wrote itself, and its advice (re-run identify) looped
    ("joint name empty", _joint(1, name=""), "'name' is not a usable name"),
    ("joint name spaces", _joint(1, name=" elbow "), "'name' is not a usable name"),
    ("joint name newline", _joint(1, name="el\nbow"), "'name' is not a usable name"),
    ("joint name a comma", _joint(1, name="a,b"), "'name' is not a usable name"),
    ("robot name empty", lambda d: d.update(name=""), "'name' is not a usable name"),
]


@pytest.mark.parametrize(
    ("edit", "field"), [c[1:] for c in OUT_OF_BOUNDS], ids=[c[0] for c in OUT_OF_BOUNDS]
)
def test_out_of_bounds_is_one_line_naming_the_field(edit: Edit, field: str) -> None:
    doc = copy.deepcopy(SCARA)
    edit(doc)
    with pytest.raises(RobotDescriptionError) as exc:
        description_from_dict(doc, source="robot.toml")
    msg = str(exc.value)
    assert field in msg and "robot.toml" in msg and "\n" not in msg


@pytest.mark.parametrize("doc", [None, [], "puma560", 3.0], ids=repr)
def test_a_description_that_is_not_a_table(doc: object) -> None:
    # A recorded /robot/description whose "robot" is not an object: one line, not a TypeError.
    with pytest.raises(RobotDescriptionError, match="is not a table"):
        description_from_dict(doc, source="/robot/description")  # type: ignore[arg-type]


def test_the_bounds_themselves_are_accepted() -> None:
    doc = copy.deepcopy(SCARA)
    _copies(MAX_JOINTS)(doc)
    for j in doc["joints"]:
        j["type"], j["limits"] = "revolute", [-MAX_ANGLE_DEG, MAX_ANGLE_DEG]
    doc["joints"][2].update(type="prismatic", limits=[-MAX_LENGTH_CM, MAX_LENGTH_CM])
    doc["joints"][3]["dh"].update(d_cm=MAX_LENGTH_CM, a_cm=-MAX_LENGTH_CM)
    doc["base"] = {"xyz_cm": [MAX_LENGTH_CM, 0.0, 0.0], "rpy_deg": [MAX_ANGLE_DEG, 0.0, 0.0]}
    robot = description_from_dict(doc)
    assert robot.n_joints == MAX_JOINTS and robot.limits[2].tolist() == [-1000.0, 1000.0]


def test_cli_refuses_huge_limits_in_one_line(tmp_path: Path) -> None:
    doc = copy.deepcopy(SCARA)
    _joint(0, limits=[-1e6, 1e6])(doc)
    p = tmp_path / "huge.toml"
    p.write_text(_toml(doc))
    fk = ["fk", str(p), "--q", "0 0 0 0"]
    for args in (fk, ["simulate", str(tmp_path / "s"), "--robot", str(p)]):
        r = CliRunner().invoke(app, args)
        assert r.exit_code == 1, r.output
        assert r.stderr.startswith("error: ") and len(r.stderr.splitlines()) == 1
        assert "'limits' is out of bounds" in r.stderr and "720" in r.stderr
    assert not (tmp_path / "s").exists()
