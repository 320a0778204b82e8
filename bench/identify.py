"""Cold and warm `pipeline identify` on robot3, wall time including interpreter start.

Issue 4 targets: cold (every stage from the recording) <= 2 s, warm (all cached) <= 0.5 s.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _wall(cmd: list[str]) -> float:
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True)
    return time.perf_counter() - t0


def main() -> None:
    exe = str(Path(sys.executable).with_name("pipeline"))
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp) / "robot3"
        d.mkdir()
        shutil.copy(ROOT / "sessions/robot3/recording.mcap", d)
        cold = []
        for _ in range(3):
            shutil.rmtree(d / "stages", ignore_errors=True)
            shutil.rmtree(d / "report", ignore_errors=True)
            cold.append(_wall([exe, "identify", str(d)]))
        warm = [_wall([exe, "identify", str(d)]) for _ in range(3)]
    print(f"{'pipeline identify robot3, cold (best of 3)':45s} {min(cold):9.3f} s")
    print(f"{'pipeline identify robot3, warm (best of 3)':45s} {min(warm):9.3f} s")
