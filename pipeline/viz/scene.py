"""The messages of ``viz.mcap``: a session's frames, features and measured points.

Everything is placed in the frame ``sensor`` (the frame of the measurements and of the
signature). Frame names: ``signature/base`` (S̄_0), ``signature/<joint>`` (the frame
moved by that joint), ``signature/tool``; the same under ``design/`` below
``design/world``, the design model's world placed in the sensor frame by the
signature's design alignment ``sensor_from_design_base``, and ``design/probe``: the
design tool followed by the alignment's ``design_flange_to_signature_tool``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyarrow as pa

from pipeline.kinematics.chain import link_frames
from pipeline.kinematics.transforms import invert_transform
from pipeline.signature.file import Signature
from pipeline.sweeps import WHOLE_ARM_SWEEPS, sweep_name
from pipeline.viz import foxglove as fg

SENSOR = "sensor"
TF_TOPIC = "/tf"
FEATURES_TOPIC = "/features"
#: Length of the joint-axis arrows (cm); a fixed size reads better than one scaled by
#: the circle's radius, which ranges from ~1 cm (wrist) to ~100 cm (shoulder).
AXIS_ARROW_CM = 15.0
CIRCLE_SEGMENTS = 96  # a 100 cm circle drawn within 0.05 cm (r (1 - cos(pi/96)))
#: Colour of joint i's features and points (cycled): the 10 of matplotlib's tab10.
PALETTE: tuple[fg.RGBA, ...] = tuple(
    (int(h[0:2], 16) / 255, int(h[2:4], 16) / 255, int(h[4:6], 16) / 255, 1.0)
    for h in ("1f77b4 ff7f0e 2ca02c d62728 9467bd 8c564b e377c2 7f7f7f bcbd22 17becf".split())
)


@dataclass(frozen=True)
class VizMessage:
    """One message of ``viz.mcap``: topic, schema name and JSON-ready payload."""

    topic: str
    schema: str
    payload: fg.Json
    time_ns: int = 0  # log time; a camera session's images are 1 s apart (viz.camera)


def measured_topic(sweep: int) -> str:
    """Topic of a sweep's measured positions: ``/measured/joint_<i>`` for joint i's sweep,
    ``/measured/<name>`` for the whole-arm ones (tool, check, poses: :func:`sweep_name`)."""
    if sweep in WHOLE_ARM_SWEEPS:
        return f"/measured/{sweep_name(sweep)}"
    return f"/measured/joint_{sweep}"


def frame_messages(sig: Signature, q: np.ndarray) -> list[VizMessage]:
    """FrameTransforms of the signature's and the design model's frames at readings
    ``q`` (n,) in rad / cm."""
    names = ["base", *(j.name for j in sig.robot.joints), "tool"]
    out = [fg.frame_transform(SENSOR, "design/world", sig.sensor_from_design_base)]
    for prefix, root, F in (
        ("signature", SENSOR, link_frames(sig.chain, q)),
        ("design", "design/world", link_frames(sig.robot.design_chain(), q)),
    ):
        parent, T_parent = root, np.eye(4)
        for name, T in zip(names, F, strict=True):
            child = f"{prefix}/{name}"
            out.append(fg.frame_transform(parent, child, invert_transform(T_parent) @ T))
            parent, T_parent = child, T
    # Where the design model puts the probe: its distance to signature/tool is the design
    # model's error at q (the alignment X, Y is a best fit over the workspace).
    out.append(fg.frame_transform("design/tool", "design/probe", sig.design_flange_to_tool))
    return [VizMessage(TF_TOPIC, "foxglove.FrameTransform", m) for m in out]


def _unit(v: np.ndarray) -> np.ndarray:
    return np.asarray(v / np.linalg.norm(v), float)


def _feature_entity(f: dict[str, object], label: str, rgba: fg.RGBA) -> fg.Json:
    """A joint's fitted circle (revolute) or line of translation (prismatic), its axis
    arrow and its label, in the sensor frame (cm in, metres out)."""
    axis = _unit(np.array([f["axis_x"], f["axis_y"], f["axis_z"]], float))
    centre = np.array([f["center_x_cm"], f["center_y_cm"], f["center_z_cm"]], float)
    if f["type"] == "prismatic":
        half = 0.5 * float(f["travel_cm"] or 0.0)  # type: ignore[arg-type]
        path = centre + np.outer([-half, half], axis)
    else:
        first = np.array([f["first_x_cm"], f["first_y_cm"], f["first_z_cm"]], float)
        u = first - centre
        u = _unit(u - (u @ axis) * axis)  # toward the first target, in the plane (4.50)
        v = np.cross(axis, u)
        t = np.linspace(0.0, 2.0 * np.pi, CIRCLE_SEGMENTS + 1)[:, None]
        path = centre + float(f["radius_cm"]) * (np.cos(t) * u + np.sin(t) * v)  # type: ignore[arg-type]
    return fg.scene_entity(
        SENSOR,
        f"joint_{f['joint']}",
        lines=[fg.line_strip(path, rgba)],
        arrows=[fg.arrow(centre, axis, AXIS_ARROW_CM, rgba)],
        texts=[fg.text(centre + 0.5 * AXIS_ARROW_CM * axis, label, rgba)],
    )


def feature_messages(sig: Signature, features: pa.Table) -> list[VizMessage]:
    """One SceneUpdate with every joint's fitted feature, joined by ``joint``: every joint
    of a sweep session; the swept joints of a session with a pose set (none, some or all:
    a pose set's joints have no circle of their own)."""
    rows = {int(r["joint"]): r for r in features.to_pylist()}
    entities = []
    for i, j in enumerate(sig.robot.joints, start=1):
        if i not in rows:  # the features stage refuses a sweep session without one
            continue
        rgba = PALETTE[(i - 1) % len(PALETTE)]
        entities.append(_feature_entity(rows[i], f"joint {i} {j.name}", rgba))
    return [VizMessage(FEATURES_TOPIC, "foxglove.SceneUpdate", fg.scene_update(entities))]


def point_messages(positions: pa.Table) -> list[VizMessage]:
    """One PointCloud per sweep of its measured target positions (rows without a
    position, every cycle dropped or rejected, are left out)."""
    cols = {
        c: positions.column(c).to_numpy(zero_copy_only=False)  # a null position: NaN
        for c in ("sweep", "step", "x_cm", "y_cm", "z_cm")
    }
    xyz = np.column_stack([cols["x_cm"], cols["y_cm"], cols["z_cm"]]).astype(float)
    keep = np.isfinite(xyz).all(axis=1)
    out = []
    for sweep in sorted(set(cols["sweep"].tolist())):
        rows = keep & (cols["sweep"] == sweep)
        order = np.argsort(cols["step"][rows], kind="stable")  # by the key, not file order
        out.append(
            VizMessage(
                measured_topic(int(sweep)),
                "foxglove.PointCloud",
                fg.point_cloud(SENSOR, xyz[rows][order]),
            )
        )
    return out
