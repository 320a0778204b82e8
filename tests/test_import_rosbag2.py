"""Issue 43: ``pipeline import --format rosbag2`` reads a ROS 2 bag (rosbag2's MCAP
storage, CDR) as a cell records it: JointState at 50 Hz through stops and moves, points
from PointStamped and PoseStamped topics and from TF, stamped in their headers. The bags
here are written by rosbags (the maintained ROS 2 bag library, its ROS 2 Humble types),
read by armsig through mcap-ros2-support: two implementations of the format.

A simulated sweep session (the coupled-arm helper's Puma, three reflectors) and a pose set
(the UR10 pose-set table), written as bags with motion between the stops, identify as the
same rows imported from a table do; the samples taken while the arm moved or settled are
dropped and counted; a bag without a topic, a frame or a still period is one line.
"""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from coupled_table import PUMA, REFLECTORS_CM, tracker_file, tracker_map
from import_data import UR10, pose_set_map, pose_set_table
from typer.testing import CliRunner

from pipeline.cli import EXIT_REFUSED, app
from pipeline.errors import ImportFileError
from pipeline.identify import identify
from pipeline.importers import import_file
from pipeline.rig.audit import audit
from pipeline.robots.description import load_description
from pipeline.signature.session import load_session_signature
from pipeline.stages.runner import stage_path
from pipeline.stages.tables import read_table

rosbags = pytest.importorskip("rosbags", reason="rosbags writes the test bags (the test extra)")

STOP_S, MOVE_S, SETTLE_S = 2.0, 1.0, 0.5  # each stop, each move between stops, the settle
JOINT_HZ, POINT_HZ = 50, 10
FAR_M = 1.0  # points taken while moving or settling are put a metre off: kept, they'd show


def write_bag(
    path: Path, names: list[str], q_rad: np.ndarray, points_m: dict[str, np.ndarray],
    how: dict[str, str], orientation: np.ndarray | None = None,
) -> dict[str, int]:  # fmt: skip
    """A rosbag2 (MCAP) of stops at joint values ``q_rad`` (m, n) with the points
    ``points_m`` (target -> (m, 3)) measured during each stop; ``how`` says each target's
    channel (``point``: PointStamped /tracker/<id>, ``pose``: PoseStamped, ``tf``: /tf
    tracker -> <id>). Joints move linearly between stops; every point sample taken during
    a move or the first SETTLE_S of a stop is FAR_M off (and none other: the reader's
    settle rule, to the sample). Returns the count of those."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    Time, Header = T["builtin_interfaces/msg/Time"], T["std_msgs/msg/Header"]
    JS, PS = T["sensor_msgs/msg/JointState"], T["geometry_msgs/msg/PointStamped"]
    Pose, PoseS = T["geometry_msgs/msg/Pose"], T["geometry_msgs/msg/PoseStamped"]
    Point, Quat = T["geometry_msgs/msg/Point"], T["geometry_msgs/msg/Quaternion"]
    V3, TFM = T["geometry_msgs/msg/Vector3"], T["tf2_msgs/msg/TFMessage"]
    TS, Tr = T["geometry_msgs/msg/TransformStamped"], T["geometry_msgs/msg/Transform"]

    def header(t_ns: int, frame: str = "") -> object:
        return Header(stamp=Time(sec=t_ns // 10**9, nanosec=t_ns % 10**9), frame_id=frame)

    period = STOP_S + MOVE_S
    end = len(q_rad) * period
    far = {t: 0 for t in points_m}
    with Writer(path, version=8, storage_plugin=StoragePlugin.MCAP) as w:
        cj = w.add_connection("/joint_states", JS.__msgtype__, typestore=ts)
        conns: dict[str, object] = {}
        for t, kind in how.items():
            if kind == "tf":
                conns.setdefault("/tf", w.add_connection("/tf", TFM.__msgtype__, typestore=ts))
            else:
                msg_type = PS if kind == "point" else PoseS
                conns[t] = w.add_connection(f"/tracker/{t}", msg_type.__msgtype__, typestore=ts)
        events: list[tuple[int, Callable[[], None]]] = []
        for k in range(round(end * JOINT_HZ)):
            t_s = k / JOINT_HZ
            i, into = divmod(t_s, period)
            i = int(i)
            q = q_rad[i]
            if into > STOP_S and i + 1 < len(q_rad):
                q = q + (q_rad[i + 1] - q) * (into - STOP_S) / MOVE_S
            t_ns = round(t_s * 1e9)
            msg = JS(header=header(t_ns), name=names, position=np.array(q, float),
                     velocity=np.zeros(0), effort=np.zeros(0))  # fmt: skip
            events.append(
                (t_ns, lambda m=msg, t=t_ns: w.write(cj, t, ts.serialize_cdr(m, JS.__msgtype__)))
            )
        for k in range(round(end * POINT_HZ)):
            t_s = k / POINT_HZ + 0.013  # not on a joint sample
            i, into = divmod(t_s, period)
            i = min(int(i), len(q_rad) - 1)
            last = i == len(q_rad) - 1  # the arm stays at the last stop to the end
            still = SETTLE_S <= into and (into <= STOP_S or last)
            t_ns = round(t_s * 1e9)
            for t, kind in how.items():
                p = points_m[t][i] + (0.0 if still else FAR_M)
                far[t] += not still
                if kind == "point":
                    m = PS(header=header(t_ns, "tracker"), point=Point(x=p[0], y=p[1], z=p[2]))
                    data = ts.serialize_cdr(m, PS.__msgtype__)
                elif kind == "pose":
                    o = (1.0, 0.0, 0.0, 0.0) if orientation is None else orientation[i]
                    m = PoseS(header=header(t_ns, "tracker"), pose=Pose(
                        position=Point(x=p[0], y=p[1], z=p[2]),
                        orientation=Quat(w=o[0], x=o[1], y=o[2], z=o[3])))  # fmt: skip
                    data = ts.serialize_cdr(m, PoseS.__msgtype__)
                else:
                    move = Tr(translation=V3(x=p[0], y=p[1], z=p[2]),
                              rotation=Quat(x=0.0, y=0.0, z=0.0, w=1.0))  # fmt: skip
                    edge = TS(header=header(t_ns, "tracker"), child_frame_id=t, transform=move)
                    m = TFM(transforms=[edge])
                    data = ts.serialize_cdr(m, TFM.__msgtype__)
                conn = conns["/tf" if kind == "tf" else t]
                events.append((t_ns, lambda c=conn, d=data, tt=t_ns: w.write(c, tt, d)))
        for _, write in sorted(events, key=lambda e: e[0]):
            write()
    return far


def bag_map(folder: Path, names: list[str], how: dict[str, str], top: str = "") -> Path:
    lines = [top, "[rosbag2]", 'joint_states = "/joint_states"', 'frame = "tracker"',
             "joint_names = [" + ", ".join(f'"{n}"' for n in names) + "]"]  # fmt: skip
    for t, kind in how.items():
        where = f'tf = "{t}"' if kind == "tf" else f'topic = "/tracker/{t}"'
        lines += ["[[rosbag2.targets]]", f'id = "{t}"', where]
    p = folder / "bag.toml"
    p.write_text("\n".join(lines) + "\n")
    return p


def _chain(session: Path) -> np.ndarray:
    """The signature's chain (links, base, tool, offsets) as one array, cm and rad."""
    c = load_session_signature(session / "signature.json").chain
    return np.concatenate([c.links.ravel(), c.base.ravel(), c.tool.ravel(), c.joint_offsets])


@pytest.fixture(scope="module")
def sweeps(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, Path]:
    """A simulated Puma tracker sweep session's stops, as a table and as a bag; both imported."""
    d = tmp_path_factory.mktemp("bag")
    src, sim = tracker_file(d, PUMA)
    rows = np.loadtxt(src, skiprows=1)
    robot = load_description(PUMA)
    names = [j.name for j in robot.joints]
    points = {t: rows[:, 6 + 3 * k : 9 + 3 * k] / 1000.0 for k, t in enumerate(REFLECTORS_CM)}
    how = {"a": "point", "b": "tf", "c": "pose"}
    far = write_bag(d / "bag", names, np.radians(rows[:, :6]), points, how)
    import_file(src, "table", PUMA, d / "table", tracker_map(d))
    mp = bag_map(d, names, how, '[sweeps]\ncolumn = "infer"')
    out = import_file(d / "bag", "rosbag2", PUMA, d / "fromBag", mp)
    shutil.copy(sim / "rig-truth.json", d / "fromBag" / "rig-truth.json")  # for the audit
    assert out.rows.notes and f"{sum(far.values())} point samples" in out.rows.notes[0]
    return d / "table", d / "fromBag", d


def test_a_bag_of_sweeps_imports_as_its_table(sweeps: tuple[Path, Path, Path]) -> None:
    table, bag, _ = sweeps
    for s in (table, bag):
        identify(s, report=False)
    np.testing.assert_allclose(_chain(bag), _chain(table), rtol=0, atol=1e-9)
    fit = read_table(stage_path(bag, "validation")).column("error_cm").to_numpy()
    assert fit.max() <= 1e-6
    r = audit(bag, configurations=500)  # the simulated arm's truth, as its recording gives
    assert r.signature.max_position_cm <= 1e-6, r.signature


def test_a_bag_of_a_pose_set_imports_as_its_table(tmp_path: Path) -> None:
    src, q_deg = pose_set_table(tmp_path / "p.csv", n=40, sep=",", decimal=".", unit="rad")
    cols = np.genfromtxt(src, delimiter=",", names=True)
    robot = load_description(UR10)
    names = [j.name for j in robot.joints]
    q = np.column_stack([cols[f"j{j}"] for j in range(1, 7)])
    points = {
        t: np.column_stack([cols[f"{t}_{a}"] for a in "xyz"]) / 1000.0 for t in ("tmac", "r2")
    }
    how = {"tmac": "point", "r2": "tf"}
    write_bag(tmp_path / "bag", names, q, points, how)
    table_map = tmp_path / "t.toml"
    table_map.write_text(pose_set_map(sep=",", decimal=".", sigma="stated"))
    import_file(src, "table", UR10, tmp_path / "table", table_map)
    top = 'sweep = "poses"\ntool_target = "tmac"\nsigma = 0.02'
    mp = bag_map(tmp_path, names, how, top)
    argv = ["import", str(tmp_path / "bag"), str(tmp_path / "fromBag"), "--format", "rosbag2",
            "--robot", str(UR10), "--map", str(mp)]  # fmt: skip
    r = CliRunner().invoke(app, argv)
    assert r.exit_code == 0, r.output
    assert "warning: 40 stops where the arm stood still" in r.stderr, r.stderr
    for s in ("table", "fromBag"):
        identify(tmp_path / s, report=False)
    np.testing.assert_allclose(_chain(tmp_path / "fromBag"), _chain(tmp_path / "table"), atol=1e-9)


def test_a_bag_without_its_topics_frames_or_stops_is_one_line(
    sweeps: tuple[Path, Path, Path],
) -> None:
    _, _, d = sweeps
    names = [j.name for j in load_description(PUMA).joints]
    cases = {
        "no topic /tracker/x": {"a": "point", "x": "point"},
        r"TF frame 'y' \(target y\) is never located": {"a": "point", "y": "tf"},
    }
    for message, how in cases.items():
        mp = bag_map(d, names, how)
        with pytest.raises(ImportFileError, match=message) as e:
            import_file(d / "bag", "rosbag2", PUMA, d / "bad", mp)
        assert "\n" not in str(e.value)
    mp = bag_map(d, names, {"a": "point"})
    mp.write_text(mp.read_text().replace("[rosbag2]", "[rosbag2]\nsettle_s = 5"))
    with pytest.raises(ImportFileError, match="no stop with a point: 0 stops"):
        import_file(d / "bag", "rosbag2", PUMA, d / "bad", mp)
    mp.write_text(mp.read_text().replace('"/joint_states"', '"/joints"'))
    r = CliRunner().invoke(app, ["import", str(d / "bag"), str(d / "bad"), "--format", "rosbag2",
                                 "--robot", str(PUMA), "--map", str(mp)])  # fmt: skip
    assert r.exit_code == EXIT_REFUSED and r.stderr.count("\n") == 1, r.output
    assert "no topic /joints" in r.stderr and "/joint_states" in r.stderr
    assert not (d / "bad").exists() or not (d / "bad" / "recording.mcap").exists()
