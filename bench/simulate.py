"""Wall time of `pipeline simulate` on the defaults (issue target: under 5 s)."""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench.kinematics import best_of
from pipeline.rig.simulate import SimulationOptions, simulate_session


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        opts = SimulationOptions(seed=3)
        inproc = best_of(lambda: simulate_session(Path(tmp) / "a", opts, force=True), 3)
        exe = Path(sys.executable).with_name("pipeline")
        t0 = time.perf_counter()
        subprocess.run(
            [str(exe), "simulate", str(Path(tmp) / "b"), "--seed", "3"],
            check=True,
            capture_output=True,
        )
        cli = time.perf_counter() - t0
    print(f"{'simulate_session (defaults, in process)':45s} {inproc:9.3f} s")
    print(f"{'pipeline simulate (defaults, with start-up)':45s} {cli:9.3f} s")
