"""``--json`` on every command that reports (issue 30 item 6): one JSON document on stdout
that ``jq`` parses, numbers at full precision, warnings and progress on stderr only.

The commands tested elsewhere: identify, status, ik (test_cli_conventions.py), fk
(test_fk_file.py), export (test_export_cli.py), evaluate, compensate, validate, plan,
warmup, fleet identify (test_fleet.py)."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from import_data import TWO_LINK, TWO_LINK_MAP, two_link_table
from typer.testing import CliRunner

from pipeline.cli import app
from pipeline.cli.output import print_json
from pipeline.robots import builtin_names, get_robot

runner = CliRunner()


def _doc(args: list[str]) -> Any:
    """The JSON document a command printed (exit 0), through jq when installed."""
    r = runner.invoke(app, [*args, "--json"])
    assert r.exit_code == 0, r.output
    if shutil.which("jq"):
        jq = subprocess.run(["jq", "-c", "."], input=r.stdout, capture_output=True, text=True)
        assert jq.returncode == 0 and len(jq.stdout.splitlines()) == 1, jq.stderr
    return json.loads(r.stdout)


def test_robots_json_lists_every_builtin_with_its_limits() -> None:
    doc = _doc(["robots"])
    assert [r["name"] for r in doc] == list(builtin_names())
    puma = doc[0]
    rob = get_robot(puma["name"])
    assert puma["n_joints"] == rob.n_joints == len(puma["joints"])
    j = puma["joints"][0]
    assert (j["lower"], j["upper"], j["unit"]) == (rob.joints[0].lower, rob.joints[0].upper, "deg")
    assert j["encoder_resolution"] == rob.joints[0].encoder_resolution  # full precision


def test_show_json_holds_every_row_at_full_precision(identified_session: Path) -> None:
    from pipeline.stages.runner import stage_path
    from pipeline.stages.tables import read_table

    table = read_table(stage_path(identified_session, "positions"))
    doc = _doc(["show", str(identified_session), "positions"])
    assert doc["n_rows"] == table.num_rows == len(doc["rows"])  # all rows, not 20
    assert doc["provenance"]["stage"] == "positions"
    x = next(c for c in doc["columns"] if c["name"] == "x_cm")
    assert x["unit"] == "cm" and x["type"] == "double" and x["description"]
    want = [None if v is None or np.isnan(v) else v for v in table["x_cm"].to_pylist()]
    assert [row["x_cm"] for row in doc["rows"]] == want  # bit for bit (NaN as null)
    few = _doc(["show", str(identified_session), "positions", "--rows", "3", "--columns", "x_cm"])
    assert len(few["rows"]) == 3 and set(few["rows"][0]) == {"x_cm"}


def test_viz_json(identified_session: Path, tmp_path: Path) -> None:
    out = tmp_path / "v.mcap"
    doc = _doc(["viz", str(identified_session), "--out", str(out), "--q", "1 2 3 4 5 6"])
    assert doc["path"] == str(out) and out.is_file()
    assert doc["configuration"] == [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
    assert doc["messages"] == sum(doc["topics"].values()) > 0 and doc["outside_limits"] == []


def test_simulate_json(tmp_path: Path) -> None:
    d = tmp_path / "sim"
    doc = _doc(["simulate", str(d), "--points", "6", "--repeats", "1", "--sigma-p", "0.0125"])
    assert doc["recording"] == str(d / "recording.mcap") and doc["session"] == str(d)
    assert doc["bytes"] == (d / "recording.mcap").stat().st_size
    assert doc["rig_truth"] == str(d / "rig-truth.json")
    assert doc["options"]["sigmas"]["position_cm"] == 0.0125 and doc["options"]["points"] == 6


def test_import_json(tmp_path: Path) -> None:
    src = two_link_table(tmp_path / "two.csv")
    (tmp_path / "map.toml").write_text(TWO_LINK_MAP)
    d = tmp_path / "imported"
    args = ["import", str(src), str(d), "--format", "table", "--robot", str(TWO_LINK)]
    doc = _doc([*args, "--map", str(tmp_path / "map.toml")])
    assert doc["recording"] == str(d / "recording.mcap") and (d / "recording.mcap").is_file()
    assert doc["format"] == "table" and doc["targets"] == ["a", "b"]
    assert doc["configurations"] == 7 + 7 and doc["check"] == 0 and doc["poses"] == 0
    assert doc["tool"]["signature_q"] == [0.0, 0.0] and doc["tool"]["warning"] is None


def test_montecarlo_json_carries_the_summary(tmp_path: Path) -> None:
    from pipeline.stages.tables import read_table

    out = tmp_path / "mc"
    doc = _doc(["montecarlo", "--study", "machining", "--robots", "4", "--out", str(out)])
    (study,) = doc["studies"]
    assert study["study"] == "machining" and study["robots"] == 4
    assert study["folder"] == str(out / "machining") and doc["report"] == str(out / "montecarlo.md")
    summary = read_table(out / "machining" / "summary.arrow")
    assert len(study["mean"]) == len(study["settings"]) == 5
    assert len(study["mean"][0]) == len(study["indices"]) == len(study["index_units"])
    # The same numbers as the summary table (cm indices, first setting), to the bit.
    i = next(k for k, u in enumerate(study["index_units"]) if u == "cm")
    assert study["mean"][0][i] in summary.column("mean_cm").to_pylist()


def test_ik_convergence_json(identified_session: Path) -> None:
    doc = _doc(["ik-convergence", str(identified_session)])
    assert [t["method"] for t in doc] == ["nr", "jacobi", "nr", "jacobi"]
    first = doc[0]["iterations"]
    assert [r["iteration"] for r in first] == list(range(len(first)))
    r = first[0]
    assert r["radial_cm"] == pytest.approx(np.linalg.norm([r["x_cm"], r["y_cm"], r["z_cm"]]))
    assert first[-1]["radial_cm"] < 1e-6 < r["radial_cm"]


def test_print_json_writes_nan_as_null_and_times_as_iso(capsys: pytest.CaptureFixture) -> None:
    import datetime as dt

    when = dt.datetime(2026, 1, 2, 3, 4, 5, tzinfo=dt.UTC)
    print_json({"a": [1.0, float("nan"), np.float64("inf")], "t": when, "x": 0.1 + 0.2})
    doc = json.loads(capsys.readouterr().out)  # strict JSON: no NaN token
    assert doc == {"a": [1.0, None, None], "t": "2026-01-02T03:04:05+00:00", "x": 0.1 + 0.2}


def test_fleet_report_json(tmp_path: Path) -> None:
    """fleet report --json names the report it wrote (a fleet.arrow of one failed row)."""
    from pipeline.fleet.row import empty_row
    from pipeline.fleet.run import TABLE_NAME, write_fleet

    row = empty_row(str(tmp_path / "s"), "identify")
    row["error"] = "refused"
    write_fleet(tmp_path / TABLE_NAME, [row], "identify", 1.0)
    doc = _doc(["fleet", "report", str(tmp_path)])
    assert doc == {"report": str(tmp_path / "fleet-report" / "fleet.md")}
    assert (tmp_path / "fleet-report" / "fleet.md").is_file()


def test_every_command_has_json() -> None:
    """Every command reports something (a result, or the files it wrote): each takes --json."""
    import typer

    without, stack = [], [("", typer.main.get_command(app))]
    while stack:
        path, cmd = stack.pop()
        sub = getattr(cmd, "commands", None)
        if sub:
            stack.extend((f"{path} {name}".strip(), c) for name, c in sub.items())
        elif not any("--json" in p.opts for p in cmd.params):
            without.append(path)
    assert without == []
