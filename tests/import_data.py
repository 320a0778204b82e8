"""Small foreign files for the import tests, written from a design model's FK (tmp_path)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.kinematics.chain import forward_kinematics
from pipeline.robots.description import load_description
from pipeline.units import joints_to_internal

ROOT = Path(__file__).resolve().parent.parent
TWO_LINK = ROOT / "examples" / "sscanss2" / "two_link.toml"
TABLE = ROOT / "examples" / "sscanss2" / "table.toml"


def tool_points_mm(robot_toml: Path, q: np.ndarray) -> np.ndarray:
    """The design tool point (mm) at readings ``q`` (deg / cm), shape (R, 3)."""
    robot = load_description(robot_toml)
    T = forward_kinematics(robot.design_chain(), joints_to_internal(q, robot.prismatic))
    return T[..., :3, 3] * 10.0


def sscanss2_text(
    robot_toml: Path, values: list[list[float]], sep: str = "\t", digits: int = 9
) -> str:
    """SScanSS-2 rows: joint j moves alone through ``values[j]`` (deg / mm), home 0."""
    robot = load_description(robot_toml)
    lines = []
    for j, vals in enumerate(values):
        spec = robot.joints[j]
        for v in vals:
            q = np.zeros(robot.n_joints)
            q[j] = v / 10.0 if spec.prismatic else v
            p = tool_points_mm(robot_toml, q[None])[0]
            cells = [j + 1, *(f"{c:.{digits}f}" for c in p), v, spec.type, 0]
            lines.append(sep.join(str(c) for c in cells))
    return "\n".join(lines) + "\n"


TWO_LINK_VALUES = [list(range(-150, 151, 50)), list(range(-120, 121, 40))]


def two_link_table(path: Path) -> Path:
    """A CSV with a header: j1_deg, j2_rad, x/y/z of two targets (mm), in sweep order."""
    rows = []
    for j, vals in enumerate(TWO_LINK_VALUES):
        for v in vals:
            q = np.zeros(2)
            q[j] = v
            p = tool_points_mm(TWO_LINK, q[None])[0]
            rows.append([q[0], np.deg2rad(q[1]), *p, *(p + [0.0, 0.0, 0.5])])
    head = "j1_deg,j2_rad,x1,y1,z1,x2,y2,z2"
    body = "\n".join(",".join(f"{c:.12g}" for c in r) for r in rows)
    path.write_text(f"# exported by a tracker\n{head}\n{body}\n")
    return path


TWO_LINK_MAP = """
skip_rows = 1
length_unit = "mm"

[[targets]]
id = "a"
x = "x1"
y = "y1"
z = "z1"

[[targets]]
id = "b"
x = "x2"
y = "y2"
z = "z2"

[[joints]]
column = "j1_deg"
unit = "deg"

[[joints]]
column = "j2_rad"
unit = "rad"

[sweeps]
column = "infer"
tolerance = 0.01
"""
