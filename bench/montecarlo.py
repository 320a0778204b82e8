"""Wall time of every Monte-Carlo study with 500 robots (issue 7 targets).

Targets on this 2-core machine: each design-control study <= 10 s, each
signature-control study <= 60 s, `--study all` <= 300 s. Compute is the
batched simulation; "with output" adds the Arrow tables and figures.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

from pipeline.montecarlo import features_study, output, report
from pipeline.montecarlo.engine import run_study
from pipeline.montecarlo.studies import SWEPT, get_study

ROBOTS = 500
WORKERS = 2


def main() -> None:
    total = 0.0
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        for name in SWEPT:
            t0 = time.perf_counter()
            res = run_study(get_study(name), ROBOTS, seed=0, workers=WORKERS, progress=None)
            output.write_study(out, res)
            wall = time.perf_counter() - t0
            total += wall
            label = f"montecarlo {name} ({ROBOTS} robots, {WORKERS} workers)"
            print(f"{label:52s} {res.wall_s:7.1f} s compute {wall:7.1f} s with output")
        t0 = time.perf_counter()
        feat = features_study.run_features(seed=0, progress=None)
        output.write_features(out, feat)
        report.write_report(out)
        wall = time.perf_counter() - t0
        total += wall
        label = "montecarlo features (36 configurations)"
        print(f"{label:52s} {feat.wall_s:7.1f} s compute {wall:7.1f} s with output")
    print(f"{'montecarlo all (sum of the above)':52s} {'':15s} {total:7.1f} s")


if __name__ == "__main__":
    main()
