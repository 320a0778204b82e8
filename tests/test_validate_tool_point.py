"""`validate --against ... --tool-point registered` (issue 42): a validation file that
measured another point on the tool, 1.2 mm from the session's, is judged with that point
located by the file's own fit (said so), not against the session's tool point."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from import_data import UR10
from layout_data import JOINTS, one_file, pose_set
from typer.testing import CliRunner

from pipeline.cli import EXIT_REFUSED, app
from pipeline.identify import identify
from pipeline.importers import import_file
from pipeline.kinematics.chain import forward_kinematics
from pipeline.robots.description import load_description
from pipeline.units import joints_to_internal

#: The second point (mm, last D-H frame): 1.2 mm from the session's tool point tmac.
SECOND_MM = np.array([50.0, 1.2, 100.0])


def _second_point_file(path: Path, n: int = 30) -> Path:
    robot = load_description(UR10)
    rng = np.random.default_rng(21)
    q = np.deg2rad(rng.uniform(-170.0, 170.0, (n, 6)))
    T = forward_kinematics(robot.design_chain(), joints_to_internal(np.rad2deg(q), robot.prismatic))
    p = T[:, :3, :3] @ SECOND_MM + T[:, :3, 3] * 10.0 + rng.normal(0.0, 0.01, (n, 3))
    rows = "\n".join(",".join(repr(float(v)) for v in r) for r in np.hstack([q, p]))
    path.write_text(",".join([*JOINTS, "x", "y", "z"]) + "\n" + rows + "\n")
    return path


def test_a_second_tool_point_registered(tmp_path: Path) -> None:
    paths, text = one_file(pose_set(), tmp_path)
    (tmp_path / "map.toml").write_text(text)
    import_file(str(paths[0]), "table", UR10, tmp_path / "s", tmp_path / "map.toml")
    identify(tmp_path / "s", report=False)
    other = _second_point_file(tmp_path / "second.csv")
    mp = tmp_path / "second.toml"
    cols = 'x = "x"\ny = "y"\nz = "z"\n'
    joints = text[text.index("[[joints]]") :]
    args = ["validate", str(tmp_path / "s"), "--against", str(other), "--format", "table",
            "--map", str(mp)]  # fmt: skip
    # named as the session's point, it is judged against it: the 1.2 mm between them
    mp.write_text(f'length_unit = "mm"\n[[targets]]\nid = "tmac"\n{cols}\n{joints}')
    wrong = json.loads(CliRunner().invoke(app, [*args, "--json"]).stdout)
    assert 0.10 < wrong["rms_cm"] < 0.14, wrong
    # named as itself: refused (not the session's tool point) unless --tool-point
    mp.write_text(f'length_unit = "mm"\n[[targets]]\nid = "p2"\n{cols}\n{joints}')
    refused = CliRunner().invoke(app, args)
    assert refused.exit_code == EXIT_REFUSED and "no target 'tmac'" in refused.stderr
    r = CliRunner().invoke(app, [*args, "--tool-point", "registered", "--json"])
    out = json.loads(r.stdout)
    assert out["tool_point"] == "registered" and out["target"] == "p2"
    assert out["rms_cm"] < 0.003, out  # the tracker noise (0.01 mm per axis), not 1.2 mm
    assert abs(out["tool_point_offset_cm"] - 0.12) < 0.005, out  # 1.2 mm from tmac
    text_out = CliRunner().invoke(app, [*args, "--tool-point", "registered"]).stdout
    line = next(ln for ln in text_out.splitlines() if "tool point registered" in ln)
    assert line.startswith("  tool point registered: located by the fit of this file at (")
    doc = (Path(__file__).resolve().parent.parent / "docs" / "import.md").read_text()
    assert line in doc, line  # docs/import.md quotes this run
    bad = CliRunner().invoke(app, [*args, "--tool-point", "p9"])
    assert bad.exit_code == EXIT_REFUSED and "--tool-point 'p9' is no target" in bad.stderr
    bad = CliRunner().invoke(app, [*args, "--tool-point", "p2"])
    assert bad.exit_code == EXIT_REFUSED and "needs tool_point_q in the map" in bad.stderr
    # located from its measurement at a known configuration (the file's first row)
    q0 = [float(v) for v in other.read_text().splitlines()[1].split(",")[:6]]
    q0_deg = [round(float(np.rad2deg(v)), 6) for v in q0]
    mp.write_text(f"tool_point_q = {q0_deg}\nlength_unit = \"mm\"\n[[targets]]\nid = \"p2\"\n"
                  f"{cols}\n{joints}")  # fmt: skip
    known = json.loads(CliRunner().invoke(app, [*args, "--tool-point", "p2", "--json"]).stdout)
    assert known["tool_point"] == "p2" and known["tool_point_rows"] == 1 and known["n"] == 29
    assert known["rms_cm"] < 0.004, known  # as measured: noise, not 1.2 mm
    assert abs(known["tool_point_offset_cm"] - 0.12) < 0.01, known
    mp.write_text(mp.read_text().replace("tool_point_q = [", "tool_point_q = [1.0, "))
    bad = CliRunner().invoke(app, [*args, "--tool-point", "p2"])
    assert bad.exit_code == EXIT_REFUSED and "tool_point_q has 7 values" in bad.stderr
