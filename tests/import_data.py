"""Small foreign files for the import tests, written from a design model's FK (tmp_path)."""

from __future__ import annotations

import json
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


def two_link_table(path: Path, robot_toml: Path = TWO_LINK) -> Path:
    """A CSV with a header: j1_deg, j2_rad, x/y/z of two targets (mm), in sweep order
    (of the two-link arm, or another two-joint ``robot_toml``)."""
    rows = []
    for j, vals in enumerate(TWO_LINK_VALUES):
        for v in vals:
            q = np.zeros(2)
            q[j] = v
            p = tool_points_mm(robot_toml, q[None])[0]
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


UR10 = ROOT / "examples" / "ur10_ipa" / "ur10.toml"
#: The pose set's reflectors in the last D-H frame (mm): the tool point off the flange axis
#: and a second reflector beside it.
POSE_REFLECTORS_MM = {"tmac": np.array([50.0, 0.0, 100.0]), "r2": np.array([0.0, 60.0, 100.0])}


def pose_set_table(
    path: Path,
    n: int = 40,
    sep: str = ";",
    decimal: str = ",",
    unit: str = "rad",
    seed: int = 1,
) -> tuple[Path, np.ndarray]:
    """A UR10 pose set of ``n`` random configurations (design model, noiseless): joints
    (``unit``), two reflectors x/y/z (mm) with σ columns, Euler angles XYZ (deg) of the
    tool reflector's frame. Returns the file and the readings (deg)."""
    from scipy.spatial.transform import Rotation

    robot = load_description(UR10)
    rng = np.random.default_rng(seed)
    q = rng.uniform(-170.0, 170.0, (n, robot.n_joints))
    T = forward_kinematics(robot.design_chain(), joints_to_internal(q, robot.prismatic))
    cells: list[list[float]] = [list(np.deg2rad(r) if unit == "rad" else r) for r in q]
    for k in range(n):
        for local in POSE_REFLECTORS_MM.values():
            p = T[k, :3, :3] @ local + T[k, :3, 3] * 10.0
            cells[k] += [*p, 0.01, 0.02, 0.03]
        cells[k] += list(Rotation.from_matrix(T[k, :3, :3]).as_euler("XYZ", degrees=True))
    head = [f"j{j + 1}" for j in range(robot.n_joints)]
    for t in POSE_REFLECTORS_MM:
        head += [f"{t}_{a}" for a in ("x", "y", "z", "sx", "sy", "sz")]
    head += ["rx", "ry", "rz"]

    def fmt(c: float) -> str:
        return f"{c:.12g}".replace(".", decimal)

    body = "\n".join(sep.join(fmt(c) for c in row) for row in cells)
    path.write_text(sep.join(head) + "\n" + body + "\n")
    return path, q


def pose_set_map(
    sep: str = ";", decimal: str = ",", unit: str = "rad", sigma: str = "axes", extra: str = ""
) -> str:
    """The map of :func:`pose_set_table`; ``sigma``: axes (sigma_x/y/z columns), column
    (one σ column), stated (``sigma = 0.02``) or none."""
    top = [f"delimiter = {json.dumps(sep)}", f"decimal = {decimal!r}", 'length_unit = "mm"',
           'sweep = "poses"', 'tool_target = "tmac"']  # fmt: skip
    if sigma == "stated":
        top.append("sigma = 0.02")
    parts = ["\n".join(top), extra]
    for t in ("r2", "tmac"):  # the tool target second: tool_target picks it
        cols = "\n".join(f'{a} = "{t}_{a}"' for a in "xyz")
        if sigma == "axes":
            cols += "\n" + "\n".join(f'sigma_{a} = "{t}_s{a}"' for a in "xyz")
        elif sigma == "column":
            cols += f'\nsigma = "{t}_sx"'
        parts.append(f'[[targets]]\nid = "{t}"\n{cols}')
    parts += [f'[[joints]]\ncolumn = "j{j}"\nunit = "{unit}"' for j in range(1, 7)]
    parts.append('[orientation]\nrx = "rx"\nry = "ry"\nrz = "rz"\nunit = "deg"\nconvention = "XYZ"')
    return "\n\n".join(p for p in parts if p) + "\n"
