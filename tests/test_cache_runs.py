"""What a run leaves behind: no temp-file debris, a failed run's outputs in stages/failed/
with advice pointing there, and ``status`` honest about a folder that is no session."""

from __future__ import annotations

import dataclasses
import shutil
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
from typer.testing import CliRunner

from pipeline.cli import app
from pipeline.errors import StageError
from pipeline.identify import identify
from pipeline.stages import features
from pipeline.stages.runner import failed_dir, run, stage_path, status


def test_next_run_removes_temp_debris(identified_session: Path, tmp_path: Path) -> None:
    d = shutil.copytree(identified_session, tmp_path / "s")
    (d / "report").mkdir()
    debris = [
        d / ".signature.json.k3j2h1gf.tmp",
        d / "stages" / ".ranges.arrow.a8d7f6e5.tmp",
        d / "report" / ".report.md.q9w8e7r6.tmp",
    ]
    kept = [d / "notes.tmp", d / "report" / ".inputs.json", d / "stages" / "mine.txt"]
    for f in debris + kept:
        f.write_text("x")
    identify(d, report=False)
    assert [f for f in debris if f.exists()] == []
    assert all(f.exists() for f in kept)


def _failing_features(monkeypatch) -> None:
    """features fails as on a sweep whose echoes were all lost: the real message."""
    stage = features.STAGE

    def compute(inputs, params):
        pos = inputs["positions"]
        k = pos.schema.get_field_index("x_cm")
        lost = pos.set_column(k, "x_cm", pa.nulls(pos.num_rows, pa.float64()).fill_null(np.nan))
        return stage.compute({**inputs, "positions": lost}, params)

    monkeypatch.setattr(features, "STAGE", dataclasses.replace(stage, compute=compute))


def test_failed_run_keeps_its_outputs_and_points_at_them(
    identified_session: Path, tmp_path: Path, monkeypatch
) -> None:
    d = shutil.copytree(identified_session, tmp_path / "s")
    good = stage_path(d, "positions").read_bytes()
    _failing_features(monkeypatch)
    with pytest.raises(StageError, match="sweep 1: 0 usable") as exc:
        run(d, force=True)
    msg = str(exc.value)
    assert "\n" not in msg
    assert "stages/failed/positions.arrow" in msg and "stages/positions.arrow" not in msg
    failed = failed_dir(d)
    assert sorted(p.name for p in failed.iterdir()) == [
        "compensate.arrow",
        "joints.arrow",
        "positions.arrow",
        "ranges.arrow",
        "session.arrow",
        "triangulate.arrow",
    ]
    assert stage_path(d, "positions").read_bytes() == good  # the last good run's
    monkeypatch.undo()
    identify(d, report=False)
    assert not failed.exists()


def test_a_full_disk_during_identify_names_the_cause(
    identified_session: Path, tmp_path: Path, monkeypatch
) -> None:
    """Issue 32: a full disk while a stage was written surfaced as a FileNotFoundError about
    stages/.pending (exit 70), hiding the cause. The third stage's write fails with ENOSPC
    (inside the atomic write, as a real one would): one line naming the file and the cause."""
    import errno

    from pipeline.atomic import atomic_write
    from pipeline.stages import runner

    d = shutil.copytree(identified_session, tmp_path / "s")
    good = stage_path(d, "positions").read_bytes()
    real, calls = runner.write_table, []

    def full(path: Path, table: pa.Table, provenance: dict) -> pa.Table:
        calls.append(path)
        if len(calls) < 3:
            return real(path, table, provenance)
        with atomic_write(path):
            raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(runner, "write_table", full)
    r = CliRunner().invoke(app, ["identify", str(d), "--force"])
    assert r.exit_code == 1, r.output
    assert r.stderr.startswith("error: ") and len(r.stderr.splitlines()) == 1, r.stderr
    assert f"{calls[2].name}: No space left on device" in r.stderr, r.stderr
    assert stage_path(d, "positions").read_bytes() == good  # the committed stages untouched
    assert not list(d.rglob("*.tmp"))


def test_cached_input_keeps_advice_on_the_committed_file(
    identified_session: Path, tmp_path: Path, monkeypatch
) -> None:
    d = shutil.copytree(identified_session, tmp_path / "s")
    _failing_features(monkeypatch)
    with pytest.raises(StageError) as exc:
        run(d, from_stage="features")  # positions is cached: its file is this run's input
    assert "stages/positions.arrow" in str(exc.value) and not failed_dir(d).exists()


@pytest.mark.parametrize("kind", ["no_folder", "no_recording"])
def test_status_of_a_folder_that_is_no_session(tmp_path: Path, kind: str) -> None:
    d = tmp_path / "nope"
    if kind == "no_recording":
        d.mkdir()
    with pytest.raises(StageError, match="no recording.mcap"):
        status(d)
    r = CliRunner().invoke(app, ["status", str(d)])
    assert r.exit_code == 1
    assert r.output.count("\n") == 1 and "no recording.mcap" in r.output
    assert not d.exists() or list(d.iterdir()) == []  # nothing created


def test_cli_status_lists_the_signature(identified_session: Path) -> None:
    r = CliRunner().invoke(app, ["status", str(identified_session)])
    assert r.exit_code == 0
    lines = [line.split(None, 2) for line in r.output.splitlines()]
    names = [line[0] for line in lines]
    assert names.index("signature") == names.index("verdict") + 1  # the last stage judged
    assert lines[names.index("signature")][1:] == ["fresh", "matches the committed stages"]
