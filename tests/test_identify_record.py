"""The record of a session's last complete identify (issue 18): a warm run that finds the
folder and the code unchanged returns exactly what the runner would, and anything else
gets the runner's full check."""

import json
import os
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

import pipeline.stages.runner as runner
from pipeline.cli import app
from pipeline.identify import IdentifyResult, identify
from pipeline.identify import record as identify_record


@pytest.fixture
def session(identified_session: Path, tmp_path: Path) -> Path:
    """A copy of an identified session after one complete run with its report."""
    d = tmp_path / "s"
    shutil.copytree(identified_session, d)
    identify(d)
    return d


@pytest.fixture
def runner_calls(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Counts the runner's full runs (the record answers without one)."""
    calls: list[int] = []
    full = runner.run

    def counted(*args: Any, **kwargs: Any) -> Any:
        calls.append(1)
        return full(*args, **kwargs)

    monkeypatch.setattr(runner, "run", counted)
    return calls


def _outcome(r: IdentifyResult) -> tuple[Any, ...]:
    runs = [(x.name, x.action, x.rows) for x in r.runs]
    return runs, r.signature, r.report, r.warnings, r.verdict


def test_a_warm_run_returns_what_the_runner_returns(session: Path, runner_calls: list[int]) -> None:
    recalled = identify(session)
    assert runner_calls == []
    (session / identify_record.RECORD).unlink()
    checked = identify(session)
    assert runner_calls == [1]
    assert _outcome(recalled) == _outcome(checked)
    assert all(x.action == "cached" for x in checked.runs)
    assert checked.verdict and checked.report and checked.signature


def test_the_command_prints_the_same(session: Path) -> None:
    cli = CliRunner()
    recalled = cli.invoke(app, ["identify", str(session)])
    (session / identify_record.RECORD).unlink()
    checked = cli.invoke(app, ["identify", str(session)])
    assert recalled.exit_code == checked.exit_code == 0
    assert recalled.stdout == checked.stdout
    assert "PASS" in recalled.stdout or "CHECK" in recalled.stdout


def _flip_a_byte(d: Path) -> None:
    path = d / "stages" / "dh.arrow"
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0x01
    path.write_bytes(bytes(data))


def _edit_the_record(d: Path) -> None:
    doc = json.loads((d / identify_record.RECORD).read_text())
    doc["run"]["verdict"] = "PASS" if "CHECK" in doc["run"]["verdict"] else "CHECK"
    (d / identify_record.RECORD).write_text(json.dumps(doc))


CHANGES: dict[str, Callable[[Path], None]] = {
    "a stage file's byte": _flip_a_byte,
    "debris of a killed write": lambda d: (d / "stages" / ".dh.arrow.x1.tmp").write_bytes(b""),
    "an empty pending folder": lambda d: (d / "stages" / ".pending").mkdir(),
    "a figure removed": lambda d: next((d / "report").glob("*.png")).unlink(),
    "the signature edited": lambda d: (d / "signature.json").write_text(
        (d / "signature.json").read_text().replace('"warnings"', '"warnings" ', 1)
    ),
    "the recording grown": lambda d: (d / "recording.mcap").write_bytes(
        (d / "recording.mcap").read_bytes() + b"\0"
    ),
    "a garbled record": lambda d: (d / identify_record.RECORD).write_text("{"),
    "a record of another format": lambda d: (d / identify_record.RECORD).write_text("[]"),
    "no record": lambda d: (d / identify_record.RECORD).unlink(),
    "the record's verdict edited": _edit_the_record,
}


@pytest.mark.parametrize("change", CHANGES)
def test_any_change_gets_the_full_check(
    session: Path, runner_calls: list[int], change: str
) -> None:
    CHANGES[change](session)
    try:
        identify(session)
    except Exception:  # a refused input (e.g. the grown recording): the runner decided
        pass
    assert runner_calls == [1]


def test_a_linked_folder_has_no_record(session: Path, runner_calls: list[int]) -> None:
    # os.walk does not enter a linked folder, so its files could change unseen
    shutil.move(session / "report", session.parent / "report-elsewhere")
    (session / "report").symlink_to(session.parent / "report-elsewhere")
    identify(session)
    identify(session)
    assert runner_calls == [1, 1]


def test_a_record_that_cannot_be_written_is_no_error(
    identified_session: Path, tmp_path: Path, runner_calls: list[int]
) -> None:
    d = tmp_path / "s"
    shutil.copytree(identified_session, d)
    (d / identify_record.RECORD).unlink(missing_ok=True)
    (d / identify_record.RECORD).mkdir()  # not writable as a file, even by root
    assert identify(d, report=False).signature is not None
    assert identify(d, report=False).signature is not None
    assert runner_calls == [1, 1]
    assert not [p for p in (d / "stages").iterdir() if p.name.endswith(".tmp")]


@pytest.mark.parametrize("stamp", ["code_digest", "library_stamps"])
def test_other_code_or_libraries_get_the_full_check(
    session: Path, runner_calls: list[int], monkeypatch: pytest.MonkeyPatch, stamp: str
) -> None:
    monkeypatch.setattr(identify_record, stamp, lambda: "other")
    identify(session)
    assert runner_calls == [1]
    identify(session)  # the record of this code
    assert runner_calls == [1]


@pytest.mark.parametrize(
    "options",
    [{"force": True}, {"from_stage": "dh"}, {"only": "dh"}, {"overrides": {"dh": {}}}],
)
def test_options_get_the_full_check(
    session: Path, runner_calls: list[int], options: dict[str, Any]
) -> None:
    identify(session, **options)
    assert runner_calls == [1]


def test_without_the_report_is_another_record(session: Path, runner_calls: list[int]) -> None:
    assert identify(session, report=False).report is None
    assert runner_calls == [1]
    assert identify(session, report=False).report is None
    assert runner_calls == [1]
    assert identify(session).report is not None
    assert len(runner_calls) == 2


def test_the_record_is_written_only_by_a_complete_plain_run(
    identified_session: Path, tmp_path: Path
) -> None:
    d = tmp_path / "s"
    shutil.copytree(identified_session, d)
    (d / identify_record.RECORD).unlink(missing_ok=True)
    identify(d, force=True)
    assert not (d / identify_record.RECORD).exists()
    identify(d)
    doc = json.loads((d / identify_record.RECORD).read_text())
    assert doc["key"]["session"] == identify_record.session_digest(d)


def test_the_code_digest_sees_a_touched_file(tmp_path: Path) -> None:
    (tmp_path / "m.py").write_text("x = 1\n")
    (tmp_path / "__pycache__").mkdir()
    before = identify_record.code_digest((tmp_path,))
    (tmp_path / "__pycache__" / "m.cpython-311.pyc").write_bytes(b"bytecode")
    assert identify_record.code_digest((tmp_path,)) == before  # caches are not code
    st = (tmp_path / "m.py").stat()
    os.utime(tmp_path / "m.py", ns=(st.st_atime_ns, st.st_mtime_ns + 1))
    assert identify_record.code_digest((tmp_path,)) != before
    (tmp_path / "n.py").write_text("")
    assert identify_record.code_digest((tmp_path,)) != before


def test_the_code_digest_covers_every_stage_module() -> None:
    import pipeline.stages.dh as dh

    path = Path(dh.__file__)
    st = path.stat()
    before = identify_record.code_digest()
    try:
        os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns + 1))
        assert identify_record.code_digest() != before
    finally:
        os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns))
    assert identify_record.code_digest() == before
