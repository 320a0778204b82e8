"""Robot descriptions in modified D-H (Craig) and with fixed rows (issue 42): the same
arm as its standard D-H description to 1e-12 cm on 1,000 configurations; a fixed row
between moving joints, or mixed conventions, refused in one line."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

from pipeline.errors import RobotDescriptionError
from pipeline.kinematics.chain import forward_kinematics
from pipeline.kinematics.dh import dh_link
from pipeline.robots.description import description_from_dict

UR10 = Path(__file__).resolve().parent.parent / "examples" / "ur10_ipa" / "ur10.toml"


def _fk(robot, q: np.ndarray) -> np.ndarray:  # type: ignore[no-untyped-def]
    return forward_kinematics(robot.design_chain(), np.deg2rad(q))


def _modified(doc: dict) -> dict:  # type: ignore[type-arg]
    """The standard description ``doc`` written in modified D-H: row i takes the previous
    row's a and α; the last row's a and α go to the tool (zero on the UR10)."""
    rows = [j["dh"] for j in doc["joints"]]
    assert rows[-1]["a_cm"] == 0.0 and rows[-1]["alpha_deg"] == 0.0
    out = {**doc, "joints": []}
    for k, j in enumerate(doc["joints"]):
        prev = rows[k - 1] if k else {"a_cm": 0.0, "alpha_deg": 0.0}
        mdh = {"alpha_deg": prev["alpha_deg"], "a_cm": prev["a_cm"],
               "theta_deg": rows[k]["theta_deg"], "d_cm": rows[k]["d_cm"]}  # fmt: skip
        out["joints"].append({**{key: v for key, v in j.items() if key != "dh"}, "mdh": mdh})
    return out


def test_modified_dh_is_the_same_arm() -> None:
    doc = tomllib.loads(UR10.read_text())
    doc["base"] = {"xyz_cm": [3.0, -2.0, 50.0], "rpy_deg": [1.0, -2.0, 30.0]}
    std = description_from_dict(doc)
    mod = description_from_dict(_modified(doc))
    q = std.random_configurations(1000, seed=3)
    diff = np.abs(_fk(std, q)[:, :3, 3] - _fk(mod, q)[:, :3, 3]).max()
    assert diff <= 1e-12, diff
    assert [j.dh for j in mod.joints] == [j.dh for j in std.joints]


def _link(r: dict) -> np.ndarray:  # type: ignore[type-arg]
    return dh_link(np.deg2rad(r["theta_deg"]), r["d_cm"], r["a_cm"], np.deg2rad(r["alpha_deg"]))


def test_fixed_rows_fold_into_base_and_tool() -> None:
    doc = tomllib.loads(UR10.read_text())
    torso = {
        "name": "torso",
        "type": "fixed",
        "dh": {"theta_deg": 30.0, "d_cm": 80.0, "a_cm": 12.0, "alpha_deg": 0.0},
    }
    flange = {"name": "adapter", "type": "fixed",
              "dh": {"theta_deg": 0.0, "d_cm": 5.0, "a_cm": 0.0, "alpha_deg": 90.0}}  # fmt: skip
    robot = description_from_dict({**doc, "joints": [torso, *doc["joints"], flange]})
    plain = description_from_dict(doc)
    assert robot.n_joints == 6
    q = plain.random_configurations(1000, seed=4)
    want = _link(torso["dh"]) @ _fk(plain, q) @ _link(flange["dh"])
    diff = np.abs(_fk(robot, q)[:, :3, 3] - want[:, :3, 3]).max()
    assert diff <= 1e-12, diff


@pytest.mark.parametrize(
    ("edit", "fragment"),
    [
        (lambda d: {**d, "joints": [*d["joints"][:3],
                                    {"name": "x", "type": "fixed", "dh": d["joints"][0]["dh"]},
                                    *d["joints"][3:]]},
         "joints[3] is fixed between moving joints"),
        (lambda d: {**d, "joints": [_modified(d)["joints"][0], *d["joints"][1:]]},
         "some joints give mdh (modified D-H) and some dh"),
        (lambda d: {**_modified(d), "base": {"xyz_cm": ["a", 0, 0]}},
         "d.toml: base: xyz_cm and rpy_deg must be lists of three numbers"),
    ],
)  # fmt: skip
def test_bad_conventions_one_line(edit, fragment: str) -> None:  # type: ignore[no-untyped-def]
    doc = tomllib.loads(UR10.read_text())
    with pytest.raises(RobotDescriptionError) as err:
        description_from_dict(edit(doc), "d.toml")
    assert fragment in str(err.value)
