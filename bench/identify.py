"""Cold and warm `pipeline identify` on robot3, wall time including interpreter start.

Issue 4 targets: cold (every stage from the recording) <= 2 s, warm (all cached) <= 0.5 s.
Issue 13: cold no slower than before by more than 10 %. With ``BENCH_BASELINE=DIR`` (another
armsig checkout with its own ``.venv``, e.g. a ``git worktree`` of an older commit) the two
are run alternately in the same run and the ratio is printed, since the machines are shared
and noisy.
"""

from __future__ import annotations

import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RUNS = int(os.environ.get("BENCH_RUNS", "5"))


def _wall(cmd: list[str]) -> float:
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True)
    return time.perf_counter() - t0


def _cpu() -> float:
    """User + system CPU seconds of every finished child process so far."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _cold(exe: str, d: Path) -> float:
    for name in ("stages", "report"):
        shutil.rmtree(d / name, ignore_errors=True)
    (d / "signature.json").unlink(missing_ok=True)
    return _wall([exe, "identify", str(d)])


def main() -> None:
    exes = {"this checkout": str(Path(sys.executable).with_name("pipeline"))}
    base = os.environ.get("BENCH_BASELINE")
    if base:
        exes["baseline " + base] = str(Path(base) / ".venv" / "bin" / "pipeline")
    cold: dict[str, list[float]] = {k: [] for k in exes}
    cold_cpu: dict[str, list[float]] = {k: [] for k in exes}
    warm: dict[str, list[float]] = {k: [] for k in exes}
    with tempfile.TemporaryDirectory() as tmp:
        dirs = {label: Path(tmp) / str(k) / "robot3" for k, label in enumerate(exes)}
        for label, exe in exes.items():  # one untimed run each: numba and .pyc caches
            dirs[label].mkdir(parents=True)
            shutil.copy(ROOT / "sessions/robot3/recording.mcap", dirs[label])
            _cold(exe, dirs[label])
        for _ in range(RUNS):  # alternate, so both see the same machine load
            for label, exe in exes.items():
                c0 = _cpu()
                cold[label].append(_cold(exe, dirs[label]))
                cold_cpu[label].append(_cpu() - c0)
        for _ in range(RUNS):
            for label, exe in exes.items():
                warm[label].append(_wall([exe, "identify", str(dirs[label])]))
    for label in exes:
        name = f"pipeline identify robot3, cold CPU, {label}"
        print(f"{name:60s} {min(cold_cpu[label]):7.3f} s (best of {RUNS}, user + system)")
        for what, times in (("cold", cold[label]), ("warm", warm[label])):
            name = f"pipeline identify robot3, {what}, {label}"
            print(f"{name:60s} {min(times):7.3f} s (best of {RUNS})")
    if base:
        c_this, c_base = (min(cold[k]) for k in exes)
        w_this, w_base = (min(warm[k]) for k in exes)
        u_this, u_base = (min(cold_cpu[k]) for k in exes)
        print(
            f"this / baseline: cold {c_this / c_base:.3f} (CPU {u_this / u_base:.3f}), "
            f"warm {w_this / w_base:.3f}"
        )
