"""Issue 44: the suite after the README walk. A session a user creates under ``sessions/``
(the README's ``simulate robot8``, an ``import``) is not a committed session: the tests
that run over every committed session must collect the same cases with it present."""

from __future__ import annotations

import shutil
import subprocess
import sys
import uuid
from pathlib import Path

from committed import ROOT, SESSIONS, committed_sessions

# Every test module that runs once per committed session.
OVER_COMMITTED = ["tests/test_signature_file.py", "tests/test_evaluation.py"]


def _collected() -> list[str]:
    r = subprocess.run(
        [sys.executable, "-m", "pytest", "--collect-only", "-q", "-p", "no:cacheprovider"]
        + OVER_COMMITTED,
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    return [line for line in r.stdout.splitlines() if "::" in line]


def test_committed_sessions_are_the_tracked_seven() -> None:
    assert [d.name for d in committed_sessions()] == [f"robot{i}" for i in range(1, 8)]
    assert committed_sessions("evaluation.mcap") == committed_sessions()


def test_a_user_session_under_sessions_changes_no_collected_test() -> None:
    """Fails on the glob of ``sessions/*/recording.mcap``: the user's session (here a
    copy of robot3 and a second one whose recording is not MCAP at all) became a case."""
    before = _collected()
    users = [SESSIONS / f"user-{uuid.uuid4().hex[:8]}" for _ in range(2)]
    try:
        for d in users:
            d.mkdir()
        for f in ("recording.mcap", "evaluation.mcap"):
            shutil.copy(SESSIONS / "robot3" / f, users[0] / f)
            (users[1] / f).write_bytes(b"not an MCAP file\n")
        assert sorted(d.name for d in committed_sessions()) == [f"robot{i}" for i in range(1, 8)]
        after = _collected()
    finally:
        for d in users:
            shutil.rmtree(d, ignore_errors=True)
    assert after == before
    assert not any(d.name in line for d in users for line in after)
    assert sum("every_committed_session" in line for line in after) == 7


def test_no_test_globs_sessions() -> None:
    """Every test module that runs over the committed sessions uses the helper, and none
    globs ``sessions/`` itself."""
    for path in sorted((ROOT / "tests").glob("test_*.py")):
        if path.name != Path(__file__).name:
            text = path.read_text()
            assert '"sessions").glob' not in text and "ROBOT1.parent).glob" not in text, path
    for module in OVER_COMMITTED:
        assert "committed_sessions" in (ROOT / module).read_text(), module
