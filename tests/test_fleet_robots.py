"""Issue 43, item 3: fleet semantics. An arm is its robot id (serial), recorded by
``simulate``/``import --robot-id``: drift is per robot id, never between two arms of one
model; ``fleet.md`` has a verdict column and counts the FAILs; ``fleet`` exits 4 when a
session's verdict is FAIL (as ``identify`` does); the figures' text lies inside them."""

from __future__ import annotations

import shutil
from pathlib import Path

import polars as pl
import pytest
from import_data import TABLE, sscanss2_text
from test_fleet import threads  # noqa: F401  (the fixture, shared)
from test_verdict_plausibility import TABLE_VALUES
from typer.testing import CliRunner

from pipeline.cli import EXIT_REFUSED, EXIT_VERDICT_FAIL, app
from pipeline.fleet.report import accuracy_figure, drift_figure, gain_figure, load_rows
from pipeline.fleet.run import TABLE_NAME
from pipeline.importers import import_file
from pipeline.rig.simulate import SimulationOptions, simulate_session

pytest.importorskip("distributed")


def _swapped_table(tmp: Path) -> Path:
    """SScanSS-2's table with x and y swapped: a mirror image, verdict FAIL (plausibility,
    tests/test_verdict_plausibility.py)."""
    rows = []
    for line in sscanss2_text(TABLE, TABLE_VALUES, digits=15).splitlines():
        c = line.split("\t")
        c[1], c[2] = c[2], c[1]
        rows.append("\t".join(c))
    src = tmp / "swapped.txt"
    src.write_text("\n".join(rows) + "\n")
    return src


@pytest.fixture(scope="module")
def fleet_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two Puma arms (robot ids P-0001, P-0002; one model), each measured twice (the
    second session a copy: the same arm, no drift), and a table imported with its x and y
    swapped (robot id T-7, verdict FAIL)."""
    root = tmp_path_factory.mktemp("fleet-ids")
    for rid, seed in (("P-0001", 1), ("P-0002", 2)):
        opts = SimulationOptions(seed=seed, points=12, repeats=1, sensor="tracker",
                                 robot_id=rid)  # fmt: skip
        first = root / f"{rid}-a"
        simulate_session(first, opts)
        shutil.copytree(first, root / f"{rid}-b")
    import_file(_swapped_table(root.parent), "sscanss2", TABLE, root / "table", robot_id="T-7")
    return root


def test_drift_per_robot_id_verdict_column_and_exit_4(fleet_dir: Path, threads) -> None:  # noqa: F811
    address = threads.scheduler.address
    res = CliRunner().invoke(app, ["fleet", "identify", str(fleet_dir), "--scheduler", address])
    assert res.exit_code == EXIT_VERDICT_FAIL, res.output
    lines = res.stderr.splitlines()
    assert lines[-1].startswith("error: 1 of 5 sessions have the verdict FAIL: "), res.stderr
    assert str(fleet_dir / "table") in lines[-1]
    df = pl.scan_ipc(fleet_dir / TABLE_NAME).collect()
    names = [Path(s).name for s in df["session"].to_list()]
    ids = dict(zip(names, df["robot_id"].to_list(), strict=True))
    assert ids == {"P-0001-a": "P-0001", "P-0001-b": "P-0001", "P-0002-a": "P-0002",
                   "P-0002-b": "P-0002", "table": "T-7"}  # fmt: skip
    assert df.filter(pl.col("robot_id") == "T-7")["verdict"].to_list() == ["FAIL"]
    rep = CliRunner().invoke(app, ["fleet", "report", str(fleet_dir)])
    assert rep.exit_code == 0, rep.output
    text = (fleet_dir / "fleet-report" / "fleet.md").read_text()
    assert text.startswith("# Fleet: 5 sessions, 0 failed, 1 with verdict FAIL\n"), text[:80]
    table_row = next(x for x in text.splitlines() if f"{fleet_dir / 'table'} |" in x)
    assert "| sscanss2_table | T-7 | points | FAIL |" in table_row, table_row
    # drift: each arm against itself (0: the same recording), never P-0001 against P-0002
    # (their signatures differ by millimetres: a model-name grouping compared them)
    drift = [x for x in text.splitlines() if x.startswith("| P-000")]
    assert [x.split(" | ")[0] for x in drift] == ["| P-0001", "| P-0002"], drift
    assert all(float(x.split(" | ")[2].rstrip(" |")) < 1e-9 for x in drift), drift
    from pipeline.fleet.report import current_signatures

    rows = load_rows(fleet_dir)
    sigs = current_signatures(rows)
    a, b = (next(sigs[r["session"]][0] for r in rows if r["robot_id"] == i)
            for i in ("P-0001", "P-0002"))  # fmt: skip
    from pipeline.signature.alignment import chain_alignment

    assert chain_alignment(b.chain, a.chain, b.robot)[2] > 1e-3  # cm: two different arms


def test_a_session_without_a_robot_id_is_compared_with_none(
    tmp_path: Path,
    threads,  # noqa: F811
) -> None:
    from pipeline.fleet.report import write_fleet_report
    from pipeline.fleet.run import run_fleet

    d = tmp_path / "f"
    for i in (1, 2):
        simulate_session(d / f"s{i}", SimulationOptions(seed=i, points=12, repeats=1,
                                                        sensor="tracker"))  # fmt: skip
    run_fleet("identify", [str(d)], threads, d, progress=None)
    text = write_fleet_report(d).read_text()
    assert text.count("no robot id recorded: not compared with other sessions") == 2, text
    assert all(r["robot_id"] is None for r in load_rows(d))


def test_a_bad_robot_id_is_one_line(tmp_path: Path) -> None:
    res = CliRunner().invoke(app, ["simulate", str(tmp_path / "s"), "--robot-id", "a b"])
    lines = res.stderr.splitlines()
    assert res.exit_code == EXIT_REFUSED and len(lines) == 1 and "bad --robot-id" in lines[0]
    assert not (tmp_path / "s" / "recording.mcap").exists()


def _clipped(fig) -> list[str]:
    """The drawn texts of ``fig`` that reach outside it (at its saved size): each axes'
    and the figure's own tight boxes hold exactly what is drawn (a tick outside the view
    is not)."""
    fig.canvas.draw()  # the Agg canvas of matplotlib.figure.Figure's savefig
    renderer = fig.canvas.get_renderer()
    box = fig.bbox
    out = []
    for ax in fig.axes:
        if not ax.get_visible():
            continue
        e = ax.get_tightbbox(renderer)
        if e.x0 < box.x0 - 0.5 or e.y0 < box.y0 - 0.5 or e.x1 > box.x1 + 0.5 or e.y1 > box.y1 + 0.5:
            out.append(ax.get_ylabel() or ax.get_xlabel() or "an axes")
    title = fig._suptitle  # the title, when it has one
    if title is not None:
        e = title.get_window_extent(renderer)
        if e.y1 > box.y1 + 0.5 or e.x0 < box.x0 - 0.5 or e.x1 > box.x1 + 0.5:
            out.append(title.get_text())
    return out


def test_fleet_figures_are_not_clipped(fleet_dir: Path, threads) -> None:  # noqa: F811
    """Long robot ids as rotated ticks, long axis labels: nothing outside the figure
    (with the fixed margins alone, the ticks and the gain label were cut)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from pipeline.fleet.report import current_signatures, drift
    from pipeline.fleet.run import run_fleet

    run_fleet("identify", [str(fleet_dir)], threads, fleet_dir, progress=None)
    rows = [{**r, "robot_id": f"{r['robot_id']}-SERIAL-0123456789"} for r in load_rows(fleet_dir)]
    steps = drift(rows, current_signatures(rows))
    for fig in (gain_figure(rows), accuracy_figure(rows), drift_figure(steps)):
        FigureCanvasAgg(fig)
        assert _clipped(fig) == [], _clipped(fig)
    from pipeline.report.figures import panel_figure

    fig, axes = panel_figure(2)  # the same ticks without the layout: cut
    FigureCanvasAgg(fig)
    axes[0].set_xticks(range(4), [r["robot_id"] for r in rows[:4]], rotation=30, ha="right")
    assert _clipped(fig)


def test_an_older_fleet_table_is_refused_in_one_line(tmp_path: Path) -> None:
    """A fleet.arrow of schema 1 (no robot_id column) made ``fleet report`` fail with a
    KeyError (exit 70); it is refused in one line."""
    from pipeline.fleet.row import fleet_table
    from pipeline.stages.tables import write_table

    old = fleet_table([]).drop_columns(["robot_id"])
    meta = {b"schema_name": b"fleet", b"schema_version": b"1"}
    write_table(tmp_path / TABLE_NAME, old.replace_schema_metadata(meta), {"command": "identify"})
    res = CliRunner().invoke(app, ["fleet", "report", str(tmp_path)])
    lines = res.stderr.splitlines()
    assert res.exit_code == EXIT_REFUSED and len(lines) == 1, res.output
    assert "written by another armsig (fleet.arrow schema 1)" in lines[0]
