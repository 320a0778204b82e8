"""Issue 43: ``pipeline compensate --program`` rewrites the motion targets of URScript, KUKA
KRL and ABB RAPID programs for a controller that keeps its nominal model, every other
byte unchanged.

A noisy simulated UR10 pose-set session; a program of 1,000 targets along a taught path
(joint steps of a few degrees, as a program moves), written in each language with poses
and joint targets, comments that hold target-shaped text, and data that are not targets
(a tool, a base frame). Checked: the nominal (design) model driven to each rewritten
target, from the taught configuration, reaches the pose the signature puts at the program's
target (1e-5 cm: the files' decimals); against the simulated arm's truth, the compensated
program's tool error is within 1.2x of signature control (the ``evaluate`` rule).
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from typer.testing import CliRunner

from pipeline.cli import EXIT_REFUSED, app
from pipeline.control.controller import solve_poses
from pipeline.control.program_formats import READERS
from pipeline.control.programs import compensate_program
from pipeline.control.session import session_controller
from pipeline.identify import identify
from pipeline.kinematics.chain import forward_kinematics
from pipeline.kinematics.ik.newton import newton_raphson
from pipeline.kinematics.transforms import xyz_rpy_from_transform
from pipeline.rig.audit import true_tool_chain
from pipeline.rig.simulate import SimulationOptions, simulate_session
from pipeline.units import joints_to_internal

UR10 = Path(__file__).resolve().parents[1] / "examples" / "ur10_ipa" / "ur10.toml"
N = 1000


@pytest.fixture(scope="module")
def setup(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, np.ndarray, np.ndarray]:
    """The session, the taught readings (N, 6) deg along a path, and the program's poses
    (N, 4, 4) cm: the nominal model's poses of the signature's tool there."""
    d = tmp_path_factory.mktemp("prog") / "s"
    simulate_session(d, SimulationOptions(robot=str(UR10), sensor="tracker", poses=150,
                                          sweeps=False, seed=7))  # fmt: skip
    identify(d, report=False)
    rng = np.random.default_rng(5)
    lo, hi = np.array([-150, -150, 20, -150, -150, -150]), np.array([150, -30, 150, 150, -20, 150])
    q = np.empty((N, 6))
    q[0] = (lo + hi) / 2
    for k in range(1, N):
        q[k] = np.clip(q[k - 1] + rng.normal(0.0, 4.0, 6), lo, hi)
    poses = session_controller(d).poses(q, design=True).matrix
    return d, q, poses


def _joint_target(k: int) -> bool:
    return k % 4 == 3  # every fourth target a joint target, the others poses


def urscript(q: np.ndarray, W: np.ndarray) -> str:
    out = ["def prog():", '  set_tcp(p[0.0, 0.0, 0.1, 0.0, 0.0, 0.0])  # "tool" # not a target',
           "  # movel(p[0.1, 0.2, 0.3, 0.0, 0.0, 0.0]) commented out"]  # fmt: skip
    for k, T in enumerate(W):
        if _joint_target(k):
            out.append(
                f"  movej([{', '.join(f'{v:.9f}' for v in np.radians(q[k]))}], a=1.4, v=1.05)"
            )
        else:
            v = (*(T[:3, 3] / 100), *Rotation.from_matrix(T[:3, :3]).as_rotvec())
            out.append(f"  global wp{k} = p[{', '.join(f'{x:.9f}' for x in v)}]")
            out.append(f"  movel(wp{k}, a=1.2, v=0.25)")
            if k == 1:  # an approach 1 cm above: its offset is in the tool, not a target
                out.append(f"  movel(pose_trans(wp{k}, p[0, 0, -0.01, 0, 0, 0]), a=1.2, v=0.25)")
    return "\n".join([*out, "end", ""])


def krl(q: np.ndarray, W: np.ndarray) -> str:
    out = ["&ACCESS RVP", "DEFDAT prog",
           "DECL FRAME TOOL_DATA1={X 0.0,Y 0.0,Z 100.0,A 0.0,B 0.0,C 0.0}",
           ";DECL E6POS XOLD={X 1.0,Y 2.0,Z 3.0,A 0.0,B 0.0,C 0.0,S 2,T 10}"]  # fmt: skip
    for k, T in enumerate(W):
        if _joint_target(k):
            axes = ",".join(f"A{i + 1} {v:.6f}" for i, v in enumerate(q[k]))
            out.append(f"DECL E6AXIS XP{k}={{{axes},E1 0.0,E2 0.0}}")
        else:
            a, b, c = Rotation.from_matrix(T[:3, :3]).as_euler("ZYX", degrees=True)
            x, y, z = T[:3, 3] * 10
            out.append(f"DECL E6POS XP{k}={{X {x:.6f},Y {y:.6f},Z {z:.6f},A {a:.6f},B {b:.6f},"
                       f"C {c:.6f},S 2,T 35,E1 0.0,E2 0.0}}")  # fmt: skip
    out.append("PTP {A1 45}  ; only one axis: partial")
    return "\r\n".join([*out, "ENDDAT", ""])


def rapid(q: np.ndarray, W: np.ndarray) -> str:
    out = ["MODULE Prog",
           "  PERS tooldata tGun:=[TRUE,[[0,0,100],[1,0,0,0]],[1,[0,0,1],[1,0,0,0],0,0,0]];",
           "  ! CONST robtarget pOld:=[[1,2,3],[1,0,0,0],[0,0,0,0],"
           "[9E9,9E9,9E9,9E9,9E9,9E9]];"]  # fmt: skip
    moves = []
    for k, T in enumerate(W):
        if _joint_target(k):
            j = ",".join(f"{v:.6f}" for v in q[k])
            out.append(f"  CONST jointtarget j{k}:=[[{j}],[9E9,9E9,9E9,9E9,9E9,9E9]];")
            moves.append(f"    MoveAbsJ j{k}, v100, fine, tGun;")
        else:
            x, y, z, w = Rotation.from_matrix(T[:3, :3]).as_quat()
            p = ",".join(f"{v:.6f}" for v in T[:3, 3] * 10)
            out.append(f"  CONST robtarget p{k}:=[[{p}],[{w:.9f},{x:.9f},{y:.9f},{z:.9f}],"
                       "[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];")  # fmt: skip
            moves.append(f"    MoveL p{k}, v100, fine, tGun;")
    return "\n".join([*out, "  PROC main()", *moves, "  ENDPROC", "ENDMODULE", ""])


WRITERS: dict[str, tuple[str, Callable[[np.ndarray, np.ndarray], str]]] = {
    "urscript": (".script", urscript), "krl": (".dat", krl), "rapid": (".mod", rapid),
}  # fmt: skip


def _skeleton(text: str, dialect: str) -> str:
    """The text with every target number replaced by '#': what must not change."""
    found = READERS[dialect](text, 6, np.zeros(6, bool))
    edits = sorted(s for t in found.targets for s in t.spans)
    out, at = [], 0
    for a, b in edits:
        out += [text[at:a], "#"]
        at = b
    return "".join(out) + text[at:]


@pytest.mark.parametrize("dialect", sorted(WRITERS))
def test_a_compensated_program_drives_the_nominal_model_to_the_signatures_poses(
    setup: tuple[Path, np.ndarray, np.ndarray], dialect: str, tmp_path: Path
) -> None:
    d, q, W = setup
    suffix, write = WRITERS[dialect]
    src, out = tmp_path / f"prog{suffix}", tmp_path / f"comp{suffix}"
    src.write_bytes(write(q, W).encode("latin-1"))
    r = compensate_program(d, src, out)
    assert r.targets == N and r.rewritten == N and not r.failed_lines, r.summary
    partial = [src.read_text().count("\n") - 1] if dialect == "krl" else []  # PTP {A1 45}
    assert r.joints == N // 4 and r.partial_lines == partial
    text = out.read_bytes().decode("latin-1")
    assert _skeleton(text, dialect) == _skeleton(src.read_bytes().decode("latin-1"), dialect)
    assert len(READERS[dialect](text, 6, np.zeros(6, bool)).targets) == N
    ctl = session_controller(d)
    design = ctl._design_model()  # the nominal controller: the design model, the same tool
    got = READERS[dialect](text, 6, np.zeros(6, bool)).targets
    q_cmd = np.empty((N, 6))
    for k, t in enumerate(got):
        if t.kind == "joints":
            q_cmd[k] = t.value
            continue
        res = newton_raphson(design, t.value[None], np.radians(q[k])[None], ctl.resolution)
        assert res.converged[0], k
        q_cmd[k] = np.degrees(res.q[0])
    reached = ctl.poses(q_cmd).matrix  # where the signature says the arm goes
    err = np.linalg.norm(reached[:, :3, 3] - W[:, :3, 3], axis=1)
    assert err.max() <= 1e-5, err.max()  # the files' decimals (1e-6 mm, 1e-9 m and rad)
    # against the simulated arm's truth: within 1.2x of signature control (evaluate's rule)
    truth = true_tool_chain(json.loads((d / "rig-truth.json").read_text()))
    X = ctl.sensor_from_base
    wanted = (X @ W)[:, :3, 3]
    xyz, rpy = xyz_rpy_from_transform(W)
    q_sig, res = solve_poses(ctl, xyz, np.degrees(rpy), None, "nr", q)
    assert res.converged.all()
    real = {k: forward_kinematics(truth, joints_to_internal(v, ctl.robot.prismatic))[:, :3, 3]
            for k, v in (("signature", q_sig), ("compensated", q_cmd))}  # fmt: skip
    rms = {k: float(np.sqrt(np.mean(np.sum((v - wanted) ** 2, axis=1)))) for k, v in real.items()}
    assert rms["compensated"] <= 1.2 * rms["signature"], rms
    assert r.max_correction_cm > 10 * rms["signature"]  # the programs were worth rewriting


def test_program_refusals_are_one_line(
    setup: tuple[Path, np.ndarray, np.ndarray], tmp_path: Path
) -> None:
    d, _, _ = setup
    run = CliRunner()
    empty = tmp_path / "empty.script"
    empty.write_text('def prog():\n  textmsg("no motion")\nend\n')
    odd = tmp_path / "prog.txt"
    odd.write_text("movel(p[0.1, 0.2, 0.3, 0, 0, 0])\n")
    cases = [
        (["--program", str(empty), "--out", str(tmp_path / "o.script")], "no motion target found"),
        (["--program", str(odd), "--out", str(tmp_path / "o.txt")], "which robot language is it?"),
        (
            ["--program", str(empty), "--targets", "t.arrow", "--out", "x"],
            "one of --targets and --program",
        ),
    ]
    for argv, message in cases:
        r = run.invoke(app, ["compensate", str(d), *argv])
        assert r.exit_code == EXIT_REFUSED and r.stderr.count("\n") == 1, r.output
        assert message in r.stderr
    r = run.invoke(app, ["compensate", str(d), "--program", str(odd), "--dialect", "urscript",
                         "--out", str(odd), "--force"])  # fmt: skip
    assert r.exit_code == EXIT_REFUSED and "is the --program file" in r.stderr, r.output
    assert odd.read_text() == "movel(p[0.1, 0.2, 0.3, 0, 0, 0])\n"
    assert not re.search(r"Traceback", r.output)


def test_plain_csv_of_poses_or_joints(
    setup: tuple[Path, np.ndarray, np.ndarray], tmp_path: Path
) -> None:
    """``compensate --targets`` reads and writes plain CSV: poses as the Arrow file does,
    and joint readings taught on the nominal model (the signature's readings for their
    pose come back in the same columns, the taught ones in ``taught_q...``)."""
    import polars as pl

    from pipeline.control.compensate import compensate_targets

    d, q, W = setup
    ctl = session_controller(d)
    xyz, rpy = xyz_rpy_from_transform(W[:50])
    values = np.column_stack([xyz, np.degrees(rpy)]).T
    names = ("x_cm", "y_cm", "z_cm", "rx_deg", "ry_deg", "rz_deg")
    poses = pl.DataFrame(dict(zip(names, values, strict=True)))
    poses.write_csv(tmp_path / "poses.csv")
    poses.write_ipc(tmp_path / "poses.arrow")
    compensate_targets(d, tmp_path / "poses.csv", tmp_path / "out.csv")
    compensate_targets(d, tmp_path / "poses.arrow", tmp_path / "out.arrow")
    a, b = pl.read_csv(tmp_path / "out.csv"), pl.read_ipc(tmp_path / "out.arrow")
    for c in ("x_cm", "rz_deg", "q1_deg", "correction_cm"):
        np.testing.assert_allclose(a[c].to_numpy(), b[c].to_numpy(), rtol=0, atol=1e-12)
    cols = [f"q{i}_deg" for i in range(1, 7)]
    pl.DataFrame(dict(zip(cols, q[:50].T, strict=True))).write_csv(tmp_path / "joints.csv")
    r = compensate_targets(d, tmp_path / "joints.csv", tmp_path / "jout.csv")
    assert r.failed == 0 and r.max_correction_cm > 0.05
    out = pl.read_csv(tmp_path / "jout.csv")
    np.testing.assert_array_equal(out[[f"taught_{c}" for c in cols]].to_numpy(), q[:50])
    reached = ctl.poses(out[cols].to_numpy()).matrix  # the real arm at the new readings
    err = np.linalg.norm(reached[:, :3, 3] - W[:50, :3, 3], axis=1)
    assert err.max() <= 1e-6, err.max()
