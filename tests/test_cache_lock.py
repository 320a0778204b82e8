"""The session lock is the kernel's (flock): held by a live process only, whatever the lock
file holds; a second run gets one line at once; unusable lock paths are one line too."""

from __future__ import annotations

import errno
import os
import subprocess
import sys
from pathlib import Path

import pytest
from recording_data import locked_elsewhere
from typer.testing import CliRunner

from pipeline.cli import app
from pipeline.errors import SessionLockedError, StageError
from pipeline.stages import lock
from pipeline.stages.lock import LOCK_NAME, session_lock
from pipeline.stages.runner import run

HOLD = """
import sys
from pathlib import Path
from pipeline.stages.lock import session_lock
with session_lock(Path(sys.argv[1])):
    print("held", flush=True)
    sys.stdin.read()
"""


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    d = tmp_path / "s"
    d.mkdir()
    (d / "recording.mcap").write_bytes(b"not read: the lock comes first")
    return d


def _one_line(exc: pytest.ExceptionInfo) -> str:
    msg = str(exc.value)
    assert "\n" not in msg and "try:" in msg
    return msg


def test_a_second_process_is_refused_until_the_first_ends(folder: Path) -> None:
    holder = subprocess.Popen(
        [sys.executable, "-c", HOLD, str(folder)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout is not None and holder.stdout.readline() == "held\n"
        with pytest.raises(SessionLockedError, match="another pipeline run") as exc:
            run(folder)
        _one_line(exc)
        r = CliRunner().invoke(app, ["identify", str(folder)])
        assert r.exit_code == 1 and r.output.count("\n") == 1
        assert "another pipeline run" in r.output
    finally:
        holder.communicate("")  # stdin closed: the holder leaves the lock and exits
    assert holder.returncode == 0
    with session_lock(folder):  # free again
        pass


@pytest.mark.parametrize("content", ["", "999999999", "PID"])
def test_lock_file_content_does_not_matter(folder: Path, content: str) -> None:
    """An empty file (a run killed before writing its PID) or a PID (dead, or reused
    by a live process such as our parent) holds nothing: only a live flock does."""
    (folder / LOCK_NAME).write_text(str(os.getppid()) if content == "PID" else content)
    with session_lock(folder):
        assert (folder / LOCK_NAME).exists()


def test_reentrant_in_one_thread(folder: Path) -> None:
    with session_lock(folder), session_lock(folder):
        pass
    with session_lock(folder):
        pass


def test_lock_path_that_is_a_folder(folder: Path) -> None:
    (folder / LOCK_NAME).mkdir()
    with pytest.raises(SessionLockedError, match="cannot open the session lock") as exc:
        run(folder)
    assert "remove the folder" in _one_line(exc)


def test_read_only_session_folder(folder: Path, monkeypatch) -> None:
    """As root a chmod does not stop writes, so the kernel's answer is simulated."""
    real_open = os.open

    def read_only(path, flags, *args):
        if str(path).endswith(LOCK_NAME):
            raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(path))
        return real_open(path, flags, *args)

    monkeypatch.setattr(lock.os, "open", read_only)
    with pytest.raises(SessionLockedError, match="cannot open the session lock") as exc:
        run(folder)
    assert "Permission denied" in _one_line(exc) and "writable" in str(exc.value)


def test_no_such_folder_is_not_created(tmp_path: Path) -> None:
    with pytest.raises(StageError, match="no such session folder"):
        with session_lock(tmp_path / "nope"):
            pass
    assert not (tmp_path / "nope").exists()


def test_another_thread_is_refused(folder: Path) -> None:
    """Re-entrance is per thread: a second thread of the same process is another run."""
    with locked_elsewhere(folder):
        with pytest.raises(SessionLockedError, match="another pipeline run"):
            run(folder)
