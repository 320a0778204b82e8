"""The sessions the repository commits, by a rule a user's session cannot break.

The README walk creates sessions of the user's own under ``sessions/`` (``robot8``, an
import, a plan); a test that globbed ``sessions/*`` took those as committed (issue 44).
The committed sessions are the ones git tracks (``git ls-files``); outside a git
checkout (an unpacked archive) they are the Makefile's ``sessions`` target, robot1-7.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SESSIONS = ROOT / "sessions"
FALLBACK = tuple(f"robot{i}" for i in range(1, 8))  # the Makefile's `sessions` target


def committed_sessions(file: str = "recording.mcap") -> list[Path]:
    """The committed session folders holding ``file``, sorted: the git-tracked
    ``sessions/*/file`` (every other folder under ``sessions/`` is a user's)."""
    try:
        out = subprocess.run(
            ["git", "ls-files", "-z", "--", f"sessions/*/{file}"],
            cwd=ROOT,
            capture_output=True,
            check=True,
            timeout=60,
        ).stdout.decode()
    except (OSError, subprocess.SubprocessError):  # no git, or not a checkout
        return [SESSIONS / n for n in FALLBACK if (SESSIONS / n / file).is_file()]
    tracked = {Path(p).parent.name for p in out.split("\0") if p.count("/") == 2}
    return sorted(SESSIONS / n for n in tracked)
