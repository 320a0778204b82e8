"""A laser-tracker file of a coupled arm as a controller exports it (issue 29): each joint
swept alone for a few stops, three reflectors on the tool measured at every stop, the
controller's readings (the elbow's reading follows the shoulder) in degrees, points in mm,
space-separated.

Made from a noiseless simulated tracker session of a coupled Puma 560 (``pipeline
simulate``): its joint states give the readings of every stop (the simulator records
readings through the inverse coupling), its ``rig-truth.json`` the true arm, at whose joint
values the reflectors are placed."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from pipeline.kinematics.chain import forward_kinematics
from pipeline.kinematics.transforms import trans
from pipeline.rig.audit import true_chain
from pipeline.rig.simulate import SimulationOptions, simulate_session
from pipeline.robots.description import load_description
from pipeline.stages.recording import read_recording
from pipeline.units import joints_to_internal

PUMA = Path(__file__).resolve().parent.parent / "pipeline" / "robots" / "data" / "puma560.toml"
#: FANUC-style coupling: the elbow's joint value is its reading plus this times the
#: shoulder's reading (the controller's elbow reading follows the shoulder).
ELBOW_PER_SHOULDER = -1.0
#: The three reflectors from the true tool point, last link frame (cm): a 6 cm triangle.
REFLECTORS_CM = {"a": (0.0, 0.0, 0.0), "b": (0.0, 6.0, 0.0), "c": (-3.0, 3.0, 4.0)}
STOPS = 6


def coupled_robot(folder: Path, elbow_per_shoulder: float = ELBOW_PER_SHOULDER) -> Path:
    """The Puma 560 description with a ``[coupling]``: joint 3 = reading 3 +
    ``elbow_per_shoulder`` × reading 2, the other joints their readings."""
    c = np.eye(6)
    c[2, 1] = elbow_per_shoulder
    rows = ", ".join("[" + ", ".join(f"{v:g}" for v in r) + "]" for r in c)
    name = f"puma_coupled_{elbow_per_shoulder:g}"
    p = folder / f"{name}.toml"
    text = PUMA.read_text().replace('name = "puma560"', f'name = "{name}"')
    p.write_text(f"{text}\n[coupling]\nmatrix = [{rows}]\noffset = [0, 0, 0, 0, 0, 0]\n")
    return p


def tracker_file(folder: Path, robot_toml: Path, home_turned: bool = False) -> tuple[Path, Path]:
    """The file and the simulated session whose ``rig-truth.json`` is the truth. Rows as
    measured: sweeps 6 to 1, then the tool at home (it joins sweep 1's run: only joint 1
    changes). ``home_turned``: the home row first instead, joint 6 reading a turn away
    (+360 deg; it joins sweep 6's run), so that no row reads home exactly."""
    sim = folder / "sim"
    opts = SimulationOptions(robot=str(robot_toml), seed=3, noiseless=True, points=STOPS,
                             repeats=1, sensor="tracker")  # fmt: skip
    simulate_session(sim, opts)
    rec = read_recording(sim / "recording.mcap")
    robot = load_description(robot_toml)
    readings = rec.q_encoder[np.argsort(rec.joint_t_s, kind="stable")]
    if home_turned:
        readings = np.vstack([readings[-1:] + [0, 0, 0, 0, 0, 360.0], readings[:-1]])
    truth = json.loads((sim / "rig-truth.json").read_text())
    tool = np.array(truth["true_tool_in_last_link_cm"])
    T = forward_kinematics(
        true_chain(truth), joints_to_internal(robot.joints_from_readings(readings), robot.prismatic)
    )
    cells = [list(r) for r in readings]
    for k, row in enumerate(cells):
        for local in REFLECTORS_CM.values():
            row += list((T[k] @ trans(*(tool + local)))[:3, 3] * 10.0)
    head = [f"J{j + 1}" for j in range(robot.n_joints)]
    head += [f"{t}_{a}" for t in REFLECTORS_CM for a in "xyz"]
    body = "\n".join(" ".join(f"{c:.10f}" for c in row) for row in cells)
    path = folder / "tracker.txt"
    path.write_text(" ".join(head) + "\n" + body + "\n")
    return path, sim


def tracker_map(
    folder: Path, sweeps: str = "", select: dict[int, dict[int, float]] | None = None
) -> Path:
    """The map of :func:`tracker_file` (targets a, b, c; a the tool): its sweeps inferred,
    or with ``select`` (joint -> held joint values) chosen by ``[[sweeps.select]]``;
    ``sweeps``: more lines of its [sweeps] table."""
    parts = ['delimiter = " "\nlength_unit = "mm"']
    for t in REFLECTORS_CM:
        parts.append(f'[[targets]]\nid = "{t}"\n' + "\n".join(f'{a} = "{t}_{a}"' for a in "xyz"))
    parts += [f'[[joints]]\ncolumn = "J{j}"\nunit = "deg"' for j in range(1, 7)]
    parts.append("[sweeps]\n" + ('column = "infer"\n' if select is None else "") + sweeps)
    for joint, held in (select or {}).items():
        values = ", ".join(f'"{k}" = {v!r}' for k, v in held.items())
        parts.append(f"[[sweeps.select]]\njoint = {joint}\nheld = {{ {values} }}")
    p = folder / "map.toml"
    p.write_text("\n\n".join(parts) + "\n")
    return p
