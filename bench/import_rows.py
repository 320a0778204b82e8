"""Import of UR10 pose sets of 100,000 and 1,000,000 rows (issue 45: 1,000,000 rows in at
most 10 s), and identify's reading of the imported recording.

``python -m bench.import_rows [OTHER_ROOT] [--runs N]``: writes each pose set (mm, rad,
``;``-separated like the IPA files) to a temp folder, then times ``pipeline import`` in a
fresh process per run, this tree and, when given, ``OTHER_ROOT`` (a ``git archive`` of
another commit) alternating, ``N`` runs each (default 3); prints the medians of the wall
time, of the CPU time (user + system of the child: what a loaded machine changes least)
and of the child's peak resident memory, and the rows per second. Then times
``read_recording`` of this tree's 1,000,000-row recording in a fresh process. ``make
bench`` runs :func:`quick` (this tree, one run each).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
ROBOT = ROOT / "examples" / "ur10_ipa" / "ur10.toml"
SIZES = (100_000, 1_000_000)
RUNS = 3
MAP = """delimiter = ";"
length_unit = "mm"
sweep = "poses"
sigma = 0.05
[[targets]]
id = "tmac"
x = "x"
y = "y"
z = "z"
""" + "".join(f'[[joints]]\ncolumn = "j{j}"\nunit = "rad"\n' for j in range(1, 7))
READ = (
    "import sys, time; from pipeline.stages.recording import read_recording; "
    "t = time.perf_counter(); read_recording(sys.argv[1]); "
    "print(f'{time.perf_counter() - t:.3f}')"
)


def write_file(folder: Path, rows: int) -> tuple[Path, Path]:
    """The pose set's CSV of ``rows`` rows and its map."""
    from pipeline.kinematics.chain import forward_kinematics
    from pipeline.robots.description import load_description

    robot = load_description(ROBOT)
    q = np.random.default_rng(42).uniform(-np.pi, np.pi, (rows, 6))
    p = forward_kinematics(robot.design_chain(), q)[..., :3, 3] * 10.0  # cm -> mm
    data = folder / f"poses_{rows}.csv"
    head = ";".join([*(f"j{j}" for j in range(1, 7)), "x", "y", "z"])
    body = "\n".join(";".join(f"{v:.9g}" for v in r) for r in np.hstack([q, p]))
    data.write_text(f"{head}\n{body}\n")
    mp = folder / "map.toml"
    mp.write_text(MAP)
    return data, mp


def child(cmd: list[str], root: Path) -> tuple[float, float, float, str]:
    """Wall and CPU seconds, peak resident memory (GB) and stdout of ``cmd`` run in a
    fresh process with ``root`` on the path."""
    env = {**os.environ, "PYTHONPATH": str(root)}
    with tempfile.TemporaryFile() as err:
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, env=env, cwd=root, stdout=subprocess.PIPE, stderr=err)
        out = proc.stdout.read().decode() if proc.stdout else ""
        _, status, usage = os.wait4(proc.pid, 0)  # the child's own CPU and peak memory
        wall = time.perf_counter() - t0
        if os.waitstatus_to_exitcode(status):
            err.seek(0)
            raise RuntimeError(f"{' '.join(cmd)} failed: {err.read().decode()[-300:]}")
    return wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1e6, out


def run(root: Path, data: Path, mp: Path, session: Path) -> tuple[float, float, float]:
    """Wall, CPU seconds and peak memory (GB) of one ``pipeline import``."""
    cmd = [sys.executable, "-m", "pipeline", "import", str(data), str(session), "--format",
           "table", "--robot", str(ROBOT), "--map", str(mp), "--force"]  # fmt: skip
    return child(cmd, root)[:3]


def main(other: Path | None, runs: int = RUNS) -> None:
    trees = {"this tree": ROOT, **({str(other): other} if other is not None else {})}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for rows in SIZES:
            data, mp = write_file(folder, rows)
            times: dict[str, list[tuple[float, float, float]]] = {w: [] for w in trees}
            for _ in range(runs):
                for w, root in reversed(trees.items()):
                    times[w].append(run(root, data, mp, folder / f"s_{rows}_{len(times[w])}"))
            print(f"import of {rows:,} rows, median of {runs} run(s):")
            for w, t in times.items():
                wall, cpu, rss = (float(np.median([r[k] for r in t])) for k in range(3))
                print(f"  {w}: wall {wall:.2f} s, CPU {cpu:.2f} s ({rows / cpu:,.0f} rows/s of "
                      f"CPU), peak {rss:.2f} GB; runs (wall, CPU) "
                      f"{[(round(r[0], 1), round(r[1], 1)) for r in t]}")  # fmt: skip
            data.unlink()
        recording = folder / f"s_{SIZES[-1]}_0" / "recording.mcap"
        wall, cpu, rss, out = child([sys.executable, "-c", READ, str(recording)], ROOT)
        size = recording.stat().st_size / 1e6
        print(
            f"read_recording of the {SIZES[-1]:,}-row recording ({size:.0f} MB), a fresh "
            f"process: {float(out):.2f} s in the call; process wall {wall:.2f} s, CPU "
            f"{cpu:.2f} s, peak {rss:.2f} GB"
        )


def quick() -> None:
    """``make bench``: this tree, one run of each size."""
    main(None, runs=1)


if __name__ == "__main__":
    args = sys.argv[1:]
    n = RUNS
    if "--runs" in args:
        k = args.index("--runs")
        n = int(args[k + 1])
        del args[k : k + 2]
    main(Path(args[0]) if args else None, n)
