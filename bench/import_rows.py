"""Import time of a 100,000-row pose set (the most one import takes), this tree against
another checkout of armsig in the same run (issue 42: no slower than before).

``python -m bench.import_rows [OTHER_ROOT]``: writes a UR10 pose set of 100,000 rows (mm,
rad, ``;``-separated like the IPA files) to a temp folder, then times ``pipeline import``
in a fresh process per run, alternating this tree and ``OTHER_ROOT`` (a ``git archive`` of
the base commit), five runs each; prints the medians of the wall time and of the CPU time
(user + system of the child: what a loaded machine changes least) and their ratios.
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
ROWS = 100_000
RUNS = 5
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


def write_file(folder: Path) -> tuple[Path, Path]:
    """The pose set's CSV and its map."""
    from pipeline.kinematics.chain import forward_kinematics
    from pipeline.robots.description import load_description

    robot = load_description(ROBOT)
    q = np.random.default_rng(42).uniform(-np.pi, np.pi, (ROWS, 6))
    p = forward_kinematics(robot.design_chain(), q)[..., :3, 3] * 10.0  # cm -> mm
    data = folder / "poses.csv"
    head = ";".join([*(f"j{j}" for j in range(1, 7)), "x", "y", "z"])
    body = "\n".join(";".join(f"{v:.9g}" for v in r) for r in np.hstack([q, p]))
    data.write_text(f"{head}\n{body}\n")
    mp = folder / "map.toml"
    mp.write_text(MAP)
    return data, mp


def run(root: Path, data: Path, mp: Path, session: Path) -> tuple[float, float]:
    """Wall and CPU seconds of one ``pipeline import`` (a fresh process, ``root`` on the
    path)."""
    cmd = [sys.executable, "-m", "pipeline", "import", str(data), str(session), "--format",
           "table", "--robot", str(ROBOT), "--map", str(mp), "--force"]  # fmt: skip
    env = {**os.environ, "PYTHONPATH": str(root)}
    t0, c0 = time.perf_counter(), _child_cpu()
    subprocess.run(cmd, env=env, check=True, capture_output=True, cwd=root)
    return time.perf_counter() - t0, _child_cpu() - c0


def _child_cpu() -> float:
    import resource

    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def main(other: Path) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        data, mp = write_file(folder)
        times: dict[str, list[tuple[float, float]]] = {"this": [], "other": []}
        for _ in range(RUNS):
            times["other"].append(run(other, data, mp, folder / "s_other"))
            times["this"].append(run(ROOT, data, mp, folder / "s_this"))
    print(f"import of {ROWS:,} rows, median of {RUNS} runs each (alternating):")
    for k, kind in enumerate(("wall", "CPU")):
        med = {w: float(np.median([t[k] for t in v])) for w, v in times.items()}
        runs = {w: [round(t[k], 1) for t in v] for w, v in times.items()}
        print(
            f"  {kind}: this tree {med['this']:.2f} s {runs['this']}; {other} "
            f"{med['other']:.2f} s {runs['other']}; ratio {med['this'] / med['other']:.3f}"
        )


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT)
