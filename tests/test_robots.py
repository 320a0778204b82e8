"""Robot descriptions: built-ins, file format, clear errors."""

import numpy as np
import pytest

from pipeline.errors import ArmsigError, RobotDescriptionError, UnknownRobotError
from pipeline.robots import builtin_names, get_robot, load_description
from pipeline.robots.fk import design_pose

GOOD = """
name = "planar2"
[[joints]]
name = "j1"
type = "revolute"
limits = [-180, 180]
encoder_resolution = 0.01
dh = { theta_deg = 0.0, d_cm = 0.0, a_cm = 30.0, alpha_deg = 0.0 }
[[joints]]
name = "j2"
type = "prismatic"
limits = [0, 20]
encoder_resolution = 0.001
dh = { theta_deg = 0.0, d_cm = 5.0, a_cm = 0.0, alpha_deg = 0.0 }
[tool]
xyz_cm = [0, 0, 10]
"""


def test_builtins() -> None:
    assert {"puma560", "stanford"} <= set(builtin_names())
    st = get_robot("stanford")
    assert st.prismatic.tolist() == [False, False, True, False, False, False]
    assert get_robot("puma560").encoder_resolution.tolist() == [0.005] * 6


def test_load_good_file(tmp_path) -> None:
    p = tmp_path / "planar2.toml"
    p.write_text(GOOD)
    rob = get_robot(str(p))
    assert rob.name == "planar2" and rob.n_joints == 2
    pose = design_pose(rob, [90.0, 4.0])
    np.testing.assert_allclose(pose.xyz_cm, [0.0, 30.0, 19.0], atol=1e-12)
    assert pose.outside_limits == ()
    assert design_pose(rob, [0.0, 25.0]).outside_limits == ("j2",)


@pytest.mark.parametrize(
    ("edit", "field"),
    [
        (('type = "prismatic"', 'type = "helical"'), "'type'"),
        (("limits = [0, 20]", "limits = [20, 0]"), "'limits'"),
        (('name = "j1"\n', ""), "'name'"),
        (("encoder_resolution = 0.01", "encoder_resolution = -1"), "'encoder_resolution'"),
        (("a_cm = 30.0,", ""), "'a_cm'"),
        (('name = "planar2"', "name = 3"), "'name'"),
    ],
)
def test_bad_file_names_the_field(tmp_path, edit, field) -> None:
    p = tmp_path / "bad.toml"
    p.write_text(GOOD.replace(*edit, 1))
    with pytest.raises(RobotDescriptionError) as exc:
        load_description(p)
    msg = str(exc.value)
    assert field in msg and "bad.toml" in msg and "\n" not in msg


def test_unknown_robot_and_unreadable_file(tmp_path) -> None:
    with pytest.raises(UnknownRobotError, match="pipeline robots"):
        get_robot("no-such-robot")
    with pytest.raises(RobotDescriptionError, match="cannot read"):
        get_robot(str(tmp_path / "missing.toml"))
    bad = tmp_path / "x.toml"
    bad.write_text("name = [")
    with pytest.raises(RobotDescriptionError, match="not valid TOML"):
        get_robot(str(bad))


def test_wrong_joint_count() -> None:
    with pytest.raises(ArmsigError, match="expected 6 values"):
        design_pose(get_robot("puma560"), [0.0])
