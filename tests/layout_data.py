"""One simulated UR10 pose set written in the layouts labs use (issue 42): one file, seven
files, one file per quantity joined by row, stacked rows (points_per_pose, a pose column),
MATLAB v5 and v7.3, rows with NaN. Numbers are written to 17 significant digits, so every
layout holds the same doubles and imports to the same recording values."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from import_data import UR10

from pipeline.kinematics.chain import forward_kinematics
from pipeline.robots.description import load_description
from pipeline.units import joints_to_internal

#: Two reflectors on the flange (mm, last D-H frame): the tool point first.
REFLECTORS_MM = {"tmac": np.array([50.0, 0.0, 100.0]), "r2": np.array([0.0, 60.0, 100.0])}
JOINTS = [f"j{j}" for j in range(1, 7)]
TOP = 'length_unit = "mm"\nsweep = "poses"\ntool_target = "tmac"\nsigma = 0.01\n'


@dataclass(frozen=True)
class PoseSet:
    """Readings (rad) and the reflectors' points (mm) of ``n`` poses."""

    q_rad: np.ndarray  # (n, 6)
    points_mm: dict[str, np.ndarray]  # id -> (n, 3)


def pose_set(n: int = 42, seed: int = 3, noise_mm: float = 0.01) -> PoseSet:
    """Random UR10 configurations, the design model's reflector points plus tracker noise."""
    robot = load_description(UR10)
    rng = np.random.default_rng(seed)
    q = np.deg2rad(rng.uniform(-170.0, 170.0, (n, 6)))
    T = forward_kinematics(robot.design_chain(), joints_to_internal(np.rad2deg(q), robot.prismatic))
    pts = {t: np.einsum("kij,j->ki", T[:, :3, :3], local) + T[:, :3, 3] * 10.0
           + rng.normal(0.0, noise_mm, (n, 3)) for t, local in REFLECTORS_MM.items()}  # fmt: skip
    return PoseSet(q, pts)


def _csv(path: Path, head: list[str], cols: list[np.ndarray]) -> Path:
    data = np.column_stack(cols)
    body = "\n".join(",".join(repr(float(v)) for v in row) for row in data)
    path.write_text(",".join(head) + "\n" + body + "\n")
    return path


def _targets(file: dict[str, str] | None = None, cols: dict[str, list[str]] | None = None) -> str:
    out = []
    for t in REFLECTORS_MM:
        xyz = (cols or {}).get(t, [f"{t}_{a}" for a in "xyz"])
        f = f'file = "{file[t]}"\n' if file else ""
        out.append(f'[[targets]]\nid = "{t}"\n{f}' + "".join(
            f'{a} = "{c}"\n' for a, c in zip("xyz", xyz, strict=True)))  # fmt: skip
    return "\n".join(out)


def _joints(file: str | None = None, cols: list[str] | None = None) -> str:
    f = f'file = "{file}"\n' if file else ""
    return "\n".join(f'[[joints]]\n{f}column = "{c}"\nunit = "rad"\n' for c in cols or JOINTS)


def one_file(ps: PoseSet, folder: Path, name: str = "poses.csv") -> tuple[list[Path], str]:
    """Every quantity of a pose in one row of one file."""
    head = JOINTS + [f"{t}_{a}" for t in REFLECTORS_MM for a in "xyz"]
    cols = [ps.q_rad, *ps.points_mm.values()]
    return [_csv(folder / name, head, cols)], TOP + _targets() + _joints()


def seven_files(ps: PoseSet, folder: Path) -> tuple[list[Path], str]:
    """The rows split into seven files of the same columns (one per measurement region)."""
    paths = []
    for k, idx in enumerate(np.array_split(np.arange(len(ps.q_rad)), 7)):
        part = PoseSet(ps.q_rad[idx], {t: p[idx] for t, p in ps.points_mm.items()})
        paths += one_file(part, folder, f"region_{k + 1}.csv")[0]
    return paths, one_file(ps, folder)[1]


def per_quantity(ps: PoseSet, folder: Path) -> tuple[list[Path], str]:
    """Joints in one file, each reflector in its own file (x, y, z), row i of each pose i."""
    paths = [_csv(folder / "joints.csv", JOINTS, [ps.q_rad])]
    for t, p in ps.points_mm.items():
        paths.append(_csv(folder / f"{t}.csv", ["x", "y", "z"], [p]))
    files = {t: f"{t}.csv" for t in REFLECTORS_MM}
    cols = {t: ["x", "y", "z"] for t in REFLECTORS_MM}
    return paths, TOP + _targets(files, cols) + _joints("joints.csv")


def stacked(ps: PoseSet, folder: Path) -> tuple[list[Path], str]:
    """Two points per pose as consecutive rows of x, y, z; the joints once per pose in
    another file."""
    pts = np.stack([ps.points_mm[t] for t in REFLECTORS_MM], axis=1).reshape(-1, 3)
    paths = [_csv(folder / "joints.csv", JOINTS, [ps.q_rad]),
             _csv(folder / "points.csv", ["x", "y", "z"], [pts])]  # fmt: skip
    files = {t: "points.csv" for t in REFLECTORS_MM}
    cols = {t: ["x", "y", "z"] for t in REFLECTORS_MM}
    text = "points_per_pose = 2\n" + TOP + _targets(files, cols) + _joints("joints.csv")
    return paths, text


def pose_column(ps: PoseSet, folder: Path) -> tuple[list[Path], str]:
    """One file, one row per point: a pose index, the joints repeated, x, y, z."""
    n = len(ps.q_rad)
    pts = np.stack([ps.points_mm[t] for t in REFLECTORS_MM], axis=1).reshape(-1, 3)
    pose = np.repeat(np.arange(1, n + 1), 2).astype(float)
    paths = [_csv(folder / "points.csv", ["pose", *JOINTS, "x", "y", "z"],
                  [pose, np.repeat(ps.q_rad, 2, axis=0), pts])]  # fmt: skip
    cols = {t: ["x", "y", "z"] for t in REFLECTORS_MM}
    return paths, 'pose_column = "pose"\n' + TOP + _targets(None, cols) + _joints()


def mat_file(ps: PoseSet, folder: Path, version: str) -> tuple[list[Path], str]:
    """A ``.mat`` file: Q (n x 6, rad), one n x 3 matrix per reflector (mm); v5 by scipy,
    v7.3 (HDF5, column-major as MATLAB writes it) by h5py."""
    arrays = {"Q": ps.q_rad, **{f"P_{t}": p for t, p in ps.points_mm.items()}}
    path = folder / f"poses_{version}.mat"
    if version == "v5":
        from scipy.io import savemat

        savemat(path, arrays)
    else:
        write_v73(path, arrays)
    cols = {t: [f"P_{t}:{k}" for k in (1, 2, 3)] for t in REFLECTORS_MM}
    return [path], TOP + _targets(None, cols) + _joints(None, [f"Q:{j}" for j in range(1, 7)])


def write_v73(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """A MATLAB v7.3 file: a 512-byte header, then HDF5, each matrix stored transposed."""
    import h5py

    with h5py.File(path, "w", userblock_size=512) as f:
        for k, v in arrays.items():
            f.create_dataset(k, data=np.asarray(v).T)
    header = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: armsig test HDF5 schema 1.00 ."
    with path.open("r+b") as f:
        f.write(header.ljust(116) + b"\x00" * 8 + b"\x00\x02IM")


#: Three reflectors fixed on the base (mm, the tracker's frame at the first pose).
BASE_MM = {"b1": np.array([800.0, 0.0, 0.0]), "b2": np.array([0.0, 800.0, 0.0]),
           "b3": np.array([-600.0, -600.0, 50.0])}  # fmt: skip


def drifting(ps: PoseSet, drift_mm: float, seed: int = 5, noise_mm: float = 0.01) -> PoseSet:
    """The pose set measured by a tracker that drifts (a random walk of its placement,
    ``drift_mm`` RMS at the last pose at 1 m), with the three base reflectors read at
    every pose (tracker noise ``noise_mm``)."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(seed)
    n = len(ps.q_rad)
    step = drift_mm / np.sqrt(n) / np.sqrt(3)
    shift = np.cumsum(rng.normal(0.0, step, (n, 3)), axis=0)
    turn = np.cumsum(rng.normal(0.0, step / 1000.0, (n, 3)), axis=0)  # rad: drift_mm at 1 m
    pts = {t: p.copy() for t, p in ps.points_mm.items()}
    pts |= {t: np.tile(b, (n, 1)) + rng.normal(0.0, noise_mm, (n, 3)) for t, b in BASE_MM.items()}
    for r in range(n):
        R = Rotation.from_rotvec(turn[r]).as_matrix()
        for t in pts:
            pts[t][r] = R @ pts[t][r] + shift[r]
    return PoseSet(ps.q_rad, pts)


def fixed_map(text: str) -> str:
    """A one-file map with the base reflectors as fixed targets."""
    extra = "".join(f'[[targets]]\nid = "{t}"\nfixed = true\n'
                    + "".join(f'{a} = "{t}_{a}"\n' for a in "xyz") for t in BASE_MM)  # fmt: skip
    return text.replace("[[joints]]", extra + "\n[[joints]]", 1)


def one_file_all(ps: PoseSet, folder: Path, name: str = "poses.csv") -> Path:
    """Every target of the pose set (arm and base) in one row of one file."""
    head = JOINTS + [f"{t}_{a}" for t in ps.points_mm for a in "xyz"]
    return _csv(folder / name, head, [ps.q_rad, *ps.points_mm.values()])
