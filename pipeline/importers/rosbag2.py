"""``pipeline import --format rosbag2 BAG``: a ROS 2 bag (rosbag2's MCAP storage) of a
measurement, read into :class:`~pipeline.importers.rows.MeasuredRows`.

The bag is a folder (``metadata.yaml`` and one ``.mcap``) or its ``.mcap`` file. Its
messages are CDR, decoded by ``mcap-ros2-support`` from the message definitions the bag
carries (no hand-written CDR, no ROS installation). The map's ``[rosbag2]`` table
(``schemas/import/rosbag2.json``) names the topics:

- joint readings from ``sensor_msgs/JointState`` (by joint name; rad and m, REP 103);
- each target's position from a ``geometry_msgs/PointStamped`` or ``PoseStamped`` topic
  (the tool target's orientation too, with ``orientation_sigma_deg``), or from a TF frame
  (``/tf``, ``/tf_static``) located in the measuring ``frame``;
- times from the header stamps, not the bag's receive times.

**Settle rule.** The arm stood still where consecutive joint samples stay within
``still`` (deg / cm, default the encoder resolution) of the first sample of their run;
a run is a stop once it has lasted ``settle_s`` (default 0.5 s), and a sample counts
only from then on (the arm has settled) to the run's last joint sample. A stop's
readings and each target's position are the medians of its counted samples (exact for
repeated samples, robust to a stray one). Point samples outside every stop (taken while
the arm moved or settled) are dropped and counted; so are stops without a point. The
rows then form sweeps or a pose set as a table's do (the map's ``sweep``, ``check`` and
``[sweeps]``).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.errors import ImportFileError, one_line
from pipeline.importers.mapping import ImportMap
from pipeline.importers.rows import LENGTH_CM, MeasuredRows
from pipeline.robots.description import RobotDescription

#: The settle time when the map states none (s): a tracker's reading after a stop is
#: usually taken once the arm's servo error has decayed, within a few tenths of a second.
SETTLE_S = 0.5
POINT_TYPES = ("geometry_msgs/msg/PointStamped", "geometry_msgs/msg/PoseStamped")
TF_TOPICS = ("/tf", "/tf_static")
_FIX = "check the topics with `ros2 bag info BAG` (or an MCAP viewer) and the map's [rosbag2]"


@dataclass(frozen=True)
class Samples:
    """Time-stamped samples of one quantity: ``t_ns`` (m,) header stamps, ``values`` (m, k)."""

    t_ns: np.ndarray
    values: np.ndarray


@dataclass(frozen=True)
class BagRows:
    """What :func:`read_rosbag2` found: the rows, and what the settle rule dropped."""

    rows: MeasuredRows
    stops: int  # stops found (runs still for settle_s)
    empty_stops: int  # stops without a point sample, dropped
    moving: dict[str, int]  # target -> point samples outside every stop, dropped

    @property
    def note(self) -> str:
        dropped = sum(self.moving.values())
        per = ", ".join(f"{t} {n}" for t, n in self.moving.items() if n)
        return (
            f"{self.stops} stops where the arm stood still; {dropped} point samples taken "
            f"while it moved or settled dropped ({per or 'none'}); {self.empty_stops} stops "
            "without a point dropped"
        )


def bag_file(path: Path) -> Path:
    """The ``.mcap`` of a bag folder (or the file itself); one line when there is none."""
    if path.is_file():
        return path
    if path.is_dir():
        found = sorted(path.glob("*.mcap"))
        if len(found) == 1:
            return found[0]
        raise ImportFileError(
            f"{path}: {len(found)} .mcap files in the bag folder",
            expected="one .mcap file (rosbag2's MCAP storage; a split bag: merge it with "
            "`ros2 bag convert`)",
            fix="give the bag folder of one MCAP file, or the .mcap file itself",
        )
    raise ImportFileError(f"{path}: no such bag", fix="check the path")


def _unreadable(path: Path, exc: Exception) -> ImportFileError:
    return ImportFileError(
        f"{path.name}: not a readable ROS 2 bag", got=one_line(str(exc), 120),
        fix="check that it is rosbag2's MCAP storage with CDR messages",
    )  # fmt: skip


def bag_topics(path: Path) -> dict[str, str]:
    """Topic -> message type of every channel of the bag file ``path`` (its summary)."""
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    try:
        with path.open("rb") as fh:
            summary = make_reader(fh).get_summary()
    except (McapError, ValueError, KeyError, EOFError) as exc:
        raise _unreadable(path, exc) from None
    if summary is None:
        raise _unreadable(path, ValueError("no summary section (an unfinished recording?)"))
    kinds = {k: s.name for k, s in summary.schemas.items()}
    return {c.topic: kinds.get(c.schema_id, "") for c in summary.channels.values()}


def _messages(path: Path, topics: set[str]) -> Iterator[tuple[str, str, Any]]:
    """(topic, message type, decoded message) of ``topics`` in ``path``, in log order."""
    from mcap.exceptions import McapError
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    try:
        with path.open("rb") as fh:
            reader = make_reader(fh, decoder_factories=[DecoderFactory()])
            for schema, channel, _, decoded in reader.iter_decoded_messages(topics=list(topics)):
                yield channel.topic, schema.name if schema else "", decoded
    except (McapError, ValueError, KeyError, EOFError) as exc:
        raise _unreadable(path, exc) from None


def _stamp_ns(msg: Any) -> int:
    s = msg.header.stamp
    return int(s.sec) * 1_000_000_000 + int(s.nanosec)


def read_rosbag2(path: Path, imap: ImportMap, robot: RobotDescription) -> BagRows:
    """The stops of the bag ``path`` as rows (module docstring), before sweeps are formed."""
    cfg = _config(imap, robot, path)
    mcap = bag_file(path)
    have = bag_topics(mcap)
    _check_topics(cfg, have, mcap.name)
    topics = {cfg["joint_states"], *TF_TOPICS}
    topics |= {t["topic"] for t in cfg["targets"] if "topic" in t}
    joints: list[tuple[int, list[float]]] = []
    points: dict[str, list[tuple[int, list[float]]]] = {t["id"]: [] for t in cfg["targets"]}
    by_topic = {t["topic"]: t["id"] for t in cfg["targets"] if "topic" in t}
    tf_ids = {t["tf"]: t["id"] for t in cfg["targets"] if "tf" in t}
    tf = TfTree()
    for topic, kind, msg in _messages(mcap, topics & set(have)):
        if topic == cfg["joint_states"]:
            joints.append((_stamp_ns(msg), _joint_values(msg, cfg["names"], mcap.name)))
        elif topic in TF_TOPICS:
            for t in msg.transforms:
                tf.add(t, static=topic == "/tf_static")
                if t.child_frame_id in tf_ids:
                    where = tf.locate(t.child_frame_id, cfg["frame"], mcap.name)
                    if where is not None:
                        points[tf_ids[t.child_frame_id]].append((_stamp_ns(t), where))
        else:
            points[by_topic[topic]].append((_stamp_ns(msg), _point(msg, kind, cfg, mcap.name)))
    _check_frames(cfg, tf_ids, points, mcap.name)
    q = _readings(joints, robot)
    stops = settle(q, cfg["still"], cfg["settle_s"])
    return _rows(path, q, stops, points, cfg, robot)


def _config(imap: ImportMap, robot: RobotDescription, path: Path) -> dict[str, Any]:
    """The ``[rosbag2]`` table with its defaults; a map without one, or with a table's
    columns, is refused in one line."""
    src = imap.name
    if imap.rosbag2 is None:
        raise ImportFileError(
            f"{path.name}: --format rosbag2 needs a map with a [rosbag2] table",
            expected="joint_states and [[rosbag2.targets]] topics (docs/import.md, ROS 2 bags)",
            fix='e.g. [rosbag2] joint_states = "/joint_states"',
        )
    if imap.targets or imap.joints or imap.orientation or imap.payload_column is not None:
        raise ImportFileError(
            f"{src}: a rosbag2 map names topics in [rosbag2], not table columns",
            got="[[targets]], [[joints]], [orientation] or payload_column",
            fix="move the targets to [[rosbag2.targets]] (docs/import.md, ROS 2 bags)",
        )
    cfg = dict(imap.rosbag2)
    names = cfg.get("joint_names") or [j.name for j in robot.joints]
    if len(names) != robot.n_joints:
        raise ImportFileError(
            f"{src}: rosbag2.joint_names names {len(names)} joints",
            expected=f"the {robot.n_joints} joints of {robot.name}, base to tip",
            got=", ".join(names),
        )
    for t in cfg["targets"]:
        if ("topic" in t) == ("tf" in t):
            raise ImportFileError(
                f"{src}: rosbag2.targets {t['id']!r} needs one of topic and tf",
                got=", ".join(sorted(t)), fix='topic = "/tracker/point" or tf = "reflector"',
            )  # fmt: skip
    if any("tf" in t for t in cfg["targets"]) and "frame" not in cfg:
        raise ImportFileError(
            f"{src}: a TF target needs rosbag2.frame, the frame the points are measured in",
            fix='e.g. frame = "tracker"',
        )
    ids = [t["id"] for t in cfg["targets"]]
    if len(set(ids)) != len(ids):
        raise ImportFileError(f"{src}: rosbag2.targets names a target id twice", got=str(ids))
    still = cfg.get("still")
    cfg["still"] = np.broadcast_to(
        np.asarray(robot.encoder_resolution if still is None else still, float), robot.n_joints
    ).copy()
    cfg["settle_s"] = float(cfg.get("settle_s", SETTLE_S))
    cfg["names"] = list(names)
    cfg.setdefault("frame", None)
    cfg["tool"] = imap.tool_target or ids[0]
    return cfg


def _joint_values(msg: Any, names: list[str], src: str) -> list[float]:
    """The positions of ``names`` in a JointState (by name; NaN when it lacks one)."""
    at = {n: k for k, n in enumerate(msg.name)}
    missing = [n for n in names if n not in at]
    if missing and not at:
        return [float("nan")] * len(names)
    if missing:
        raise ImportFileError(
            f"{src}: a JointState has no joint {missing[0]!r}",
            expected="the robot's joints by name (rosbag2.joint_names)",
            got=", ".join(msg.name), fix="name the bag's joints in rosbag2.joint_names",
        )  # fmt: skip
    pos = list(msg.position)
    if len(pos) != len(msg.name):
        return [float("nan")] * len(names)
    return [float(pos[at[n]]) for n in names]


def _point(msg: Any, kind: str, cfg: dict[str, Any], src: str) -> list[float]:
    """x, y, z (m) of a PointStamped or PoseStamped (and w, x, y, z of its orientation);
    its frame must be the map's ``frame`` (the first one seen when the map states none)."""
    if kind not in POINT_TYPES:
        raise ImportFileError(
            f"{src}: topic message type {kind}", expected=" or ".join(POINT_TYPES),
            fix="name a point topic in rosbag2.targets, or its TF frame with tf =",
        )  # fmt: skip
    frame = msg.header.frame_id
    if cfg["frame"] is None:
        cfg["frame"] = frame
    if frame != cfg["frame"]:
        raise ImportFileError(
            f"{src}: a point in frame {frame!r}",
            expected=f"every point in one frame, {cfg['frame']!r} (rosbag2.frame)",
            fix="state rosbag2.frame, or record the points in one frame",
        )
    if kind.endswith("PointStamped"):
        p = msg.point
        return [p.x, p.y, p.z, np.nan, np.nan, np.nan, np.nan]
    p, o = msg.pose.position, msg.pose.orientation
    return [p.x, p.y, p.z, o.w, o.x, o.y, o.z]


def _check_topics(cfg: dict[str, Any], have: dict[str, str], src: str) -> None:
    """Refuse a bag without the named topics, or with another message type on them."""
    wanted = {cfg["joint_states"]: ("sensor_msgs/msg/JointState",)}
    wanted |= {t["topic"]: POINT_TYPES for t in cfg["targets"] if "topic" in t}
    if any("tf" in t for t in cfg["targets"]):
        wanted.setdefault("/tf", ("tf2_msgs/msg/TFMessage",))
    for topic, kinds in wanted.items():
        if topic not in have and not (topic == "/tf" and "/tf_static" in have):
            raise ImportFileError(
                f"{src}: no topic {topic}", expected="the topics the map's [rosbag2] names",
                got="topics " + (", ".join(sorted(have)) or "none"), fix=_FIX,
            )  # fmt: skip
        if topic in have and have[topic] not in kinds:
            raise ImportFileError(
                f"{src}: topic {topic} holds {have[topic] or 'messages without a schema'}",
                expected=" or ".join(kinds), fix=_FIX,
            )  # fmt: skip


def _check_frames(
    cfg: dict[str, Any], tf_ids: dict[str, str], points: dict[str, list[Any]], src: str
) -> None:
    """Refuse a TF target never located in the measuring frame, in one line."""
    for frame, target in tf_ids.items():
        if not points[target]:
            raise ImportFileError(
                f"{src}: TF frame {frame!r} (target {target}) is never located in frame "
                f"{cfg['frame']!r}",
                expected="a /tf or /tf_static chain from the measuring frame to it",
                fix="check rosbag2.frame and the target's tf name (ros2 run tf2_tools view_frames)",
            )


def _readings(joints: list[tuple[int, list[float]]], robot: RobotDescription) -> Samples:
    """The joint samples in time order, in deg / cm (from rad / m)."""
    joints.sort(key=lambda s: s[0])
    q = np.array([v for _, v in joints], float).reshape(-1, robot.n_joints)
    scale = np.where(robot.prismatic, LENGTH_CM["m"], np.degrees(1.0))
    t = np.array([s for s, _ in joints], np.int64)
    ok = np.isfinite(q).all(axis=1)
    return Samples(t[ok], q[ok] * scale)


def settle(q: Samples, still: np.ndarray, settle_s: float) -> list[tuple[int, int]]:
    """Stops: ``(first, last)`` sample indices of ``q``'s counted samples (module
    docstring: runs within ``still`` of their first sample, counted ``settle_s`` after it)."""
    out: list[tuple[int, int]] = []
    n, start = len(q.t_ns), 0
    settle_ns = round(settle_s * 1e9)
    while start < n:
        end = start + 1
        while end < n and (np.abs(q.values[end] - q.values[start]) <= still).all():
            end += 1
        counted = np.flatnonzero(q.t_ns[start:end] >= q.t_ns[start] + settle_ns)
        if counted.size:
            out.append((start + int(counted[0]), end - 1))
        start = end
    return out


def _rows(
    path: Path, q: Samples, stops: list[tuple[int, int]],
    points: dict[str, list[tuple[int, list[float]]]], cfg: dict[str, Any],
    robot: RobotDescription,
) -> BagRows:  # fmt: skip
    """One row per stop with a point: medians of its joint and point samples."""
    windows = np.array([(q.t_ns[a], q.t_ns[b]) for a, b in stops], np.int64).reshape(-1, 2)
    per: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    moving: dict[str, int] = {}
    for target, samples in points.items():
        t = np.array([s for s, _ in samples], np.int64)
        v = np.array([x for _, x in samples], float).reshape(-1, 7)
        k = np.searchsorted(windows[:, 0], t, side="right") - 1
        inside = (k >= 0) & (t <= windows[np.maximum(k, 0), 1]) if len(windows) else t < 0
        moving[target] = int((~inside).sum())
        per[target] = (np.where(inside, k, -1), v)
    keep = [s for s in range(len(stops)) if any((k == s).any() for k, _ in per.values())]
    targets = {t: np.full((len(keep), 3), np.nan) for t in per}
    orient = np.full((len(keep), 4), np.nan)
    for r, s in enumerate(keep):
        for target, (k, v) in per.items():
            if (k == s).any():
                med = np.median(v[k == s], axis=0)
                targets[target][r] = med[:3] * LENGTH_CM["m"]
                if target == cfg["tool"]:
                    orient[r] = med[3:]
    a = [stops[s][0] for s in keep]
    b = [stops[s][1] for s in keep]
    readings = np.array([np.median(q.values[i : j + 1], axis=0) for i, j in zip(a, b, strict=True)])
    use_orientation = cfg.get("orientation_sigma_deg") is not None and np.isfinite(orient).all()
    if cfg.get("orientation_sigma_deg") is not None and not use_orientation:
        raise ImportFileError(
            f"{path.name}: orientation_sigma_deg is stated, but target {cfg['tool']!r} has no "
            "orientation at every stop",
            expected="a geometry_msgs/PoseStamped topic for the tool target",
            fix="drop orientation_sigma_deg, or record the tool target's pose",
        )
    rows = MeasuredRows(
        path,
        tuple(f"stop {s + 1} (t = {q.t_ns[stops[s][0]] * 1e-9:.3f} s)" for s in keep),
        np.zeros(len(keep), np.int64),
        readings.reshape(-1, robot.n_joints),
        targets,
        orientation_wxyz=_unit_quaternions(orient) if use_orientation else None,
        orientation_sigma_deg=cfg.get("orientation_sigma_deg"),
    )
    return BagRows(rows, len(stops), len(stops) - len(keep), moving)


def _unit_quaternions(wxyz: np.ndarray) -> np.ndarray:
    return wxyz / np.linalg.norm(wxyz, axis=1, keepdims=True)


class TfTree:
    """The latest transform of each TF edge (child -> parent), and where a frame's origin
    is in another frame through them (cm → m is the caller's: values here are m)."""

    def __init__(self) -> None:
        self.parent: dict[str, tuple[str, np.ndarray]] = {}

    def add(self, t: Any, static: bool) -> None:
        tr, r = t.transform.translation, t.transform.rotation
        T = np.eye(4)
        T[:3, :3] = Rotation.from_quat([r.x, r.y, r.z, r.w]).as_matrix()
        T[:3, 3] = (tr.x, tr.y, tr.z)
        self.parent[t.child_frame_id] = (t.header.frame_id, T)

    def locate(self, frame: str, root: str, src: str) -> list[float] | None:
        """``frame``'s origin (x, y, z, m) and orientation (w, x, y, z) in ``root`` through
        the latest transforms; None while they do not connect the two."""
        T = np.eye(4)
        at, seen = frame, {frame}
        while at != root:
            if at not in self.parent:
                return None
            at, step = self.parent[at]
            T = step @ T
            if at in seen:
                raise ImportFileError(f"{src}: the TF tree has a cycle through {at!r}")
            seen.add(at)
        return self._done(T)

    @staticmethod
    def _done(T: np.ndarray) -> list[float]:
        x, y, z, w = Rotation.from_matrix(T[:3, :3]).as_quat()
        return [*T[:3, 3], w, x, y, z]
