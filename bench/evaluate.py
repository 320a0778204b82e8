"""Cold and warm `pipeline evaluate` on robot3, wall time including interpreter start.

- cold, identified: the session's identification is cached, the evaluation is not
  (no evaluation.mcap, no evaluate_* stages, no report): teach, plan, run the rig,
  score and write the report;
- cold, from the recording: the identification too;
- warm: nothing changed, nothing to do (issue 6: "does no work").
"""

from __future__ import annotations

import shutil
import sys
import tempfile
from pathlib import Path

from bench.identify import ROOT, _run

REPEATS = 3


def _fresh(src: Path, dst: Path, identified: bool) -> None:
    """``dst`` as a copy of ``src`` without its evaluation (and, unless ``identified``,
    without its identification)."""
    shutil.rmtree(dst, ignore_errors=True)
    if identified:
        shutil.copytree(src, dst, ignore=shutil.ignore_patterns("evaluat*", ".evaluation*"))
    else:
        dst.mkdir()
        for name in ("recording.mcap", "rig-truth.json"):
            shutil.copy(src / name, dst)


def main() -> None:
    exe = str(Path(sys.executable).with_name("pipeline"))
    src = ROOT / "sessions" / "robot3"
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp) / "robot3"
        for label, identified in (("identified", True), ("from the recording", False)):
            cold = []
            for _ in range(REPEATS):
                _fresh(src, d, identified)
                cold.append(_run([exe, "evaluate", str(d)])[0])
            rows.append((f"cold, {label}", min(cold)))
        warm = [_run([exe, "evaluate", str(d)])[0] for _ in range(REPEATS)]
        rows.append(("warm", min(warm)))
    for label, sec in rows:
        print(f"{'pipeline evaluate robot3, ' + label + f' (best of {REPEATS})':64s} {sec:9.3f} s")


if __name__ == "__main__":
    main()
