"""Where a whole ``pipeline identify`` spends its CPU against its fit (issue 45), on the
pose sets of :mod:`bench.pose_sets`: a simulated UR10 of 1,000 poses and the real UR10
Series C (imported from ../shared/realdata into a temp folder, skipped when absent).

Per set, median of ``BENCH_RUNS`` cold runs (default 3), alternating the kinds so that
they see the same machine load:

- the process CPU (user + system of the child) of the real command, ``pipeline identify
  DIR`` (report included, the default) and ``--no-report``, and the fit's CPU (stages
  ``frames``: the design start, and ``refine``: the whole-chain fit, their
  ``cpu_seconds`` in ``--json``), with the ratios (the goal: identify / fit <= 2);
- the cost table: one more child process that imports every module a cold identify
  imports first (timed per package), then runs the stages and writes the report, timing
  each stage (``cpu_seconds``), the signature, and the report's parts (the IK
  convergence table, the non-geometric section, the figures' rendering to PNG).

``python -m bench.identify_cost`` runs it alone.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
RUNS = int(os.environ.get("BENCH_RUNS", "3"))
FIT = ("frames", "refine")
GOAL = 2.0
#: Module groups of the import rows (the first matching prefix names the group).
GROUPS = ("pipeline", "numpy", "scipy", "pyarrow", "matplotlib", "numba", "llvmlite", "typer")


def _child_cpu() -> float:
    import resource

    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _clear(d: Path) -> None:
    from bench.identify import _clear as clear

    clear(d)


def _env(**extra: str) -> dict[str, str]:
    """The children's environment: Python's own byte-code cache on (as in an
    installation; a session that turned it off would time compiling armsig's sources)."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    return {**env, **extra}


def _identify(d: Path, *extra: str) -> tuple[float, list[dict[str, Any]]]:
    """Process CPU and the ``--json`` stage rows of one cold ``pipeline identify``."""
    _clear(d)
    exe = str(Path(sys.executable).with_name("pipeline"))
    c0 = _child_cpu()
    out = subprocess.run([exe, "identify", str(d), "--json", *extra],
                         capture_output=True, text=True, env=_env())  # fmt: skip
    cpu = _child_cpu() - c0
    if out.returncode not in (0, 4):  # 4: a FAIL verdict is a finished run
        raise RuntimeError(f"identify {d} exited {out.returncode}: {out.stderr.strip()}")
    return cpu, json.loads(out.stdout)["stages"]


def _python(*args: str) -> str:
    env = _env(OPENBLAS_NUM_THREADS="1", PYTHONPATH=str(ROOT))  # as the CLI starts
    out = subprocess.run([sys.executable, *args], capture_output=True, text=True, env=env)
    if out.returncode:
        raise RuntimeError(f"{args}: {out.stderr.strip()}")
    return out.stdout


def _modules(d: Path) -> list[str]:
    """The modules a cold identify (with its report) imports, from a child process (which
    also leaves the byte-code cache of every module warm for the timed runs)."""
    _clear(d)
    code = (
        "import sys; from pipeline.identify import identify; identify(sys.argv[1]); "
        "print('\\n'.join(sorted(sys.modules)))"
    )
    return _python("-c", code, str(d)).split()


def _group(name: str) -> str:
    top = name.split(".")[0]
    return top if top in GROUPS else "other"


def child(d: Path, modules: list[str]) -> dict[str, Any]:
    """The cost table of one cold identify in this (fresh) process: imports per package,
    then each stage, the signature and the report's parts (CPU seconds)."""
    start = time.process_time()  # interpreter start, site, this module
    imports: dict[str, float] = defaultdict(float)
    for name in modules:
        if name in sys.modules:
            continue
        c0 = time.process_time()
        try:
            __import__(name)
        except Exception:  # noqa: BLE001 (a private module that imports only via its parent)
            pass
        imports[_group(name)] += time.process_time() - c0
    from pipeline.identify import identify
    from pipeline.report import identification as report

    parts: dict[str, float] = defaultdict(float)

    def timed(key: str, fn: Any) -> Any:
        def run(*a: Any, **k: Any) -> Any:
            c0 = time.process_time()
            try:
                return fn(*a, **k)
            finally:
                parts[key] += time.process_time() - c0

        return run

    report._convergence_section = timed("IK convergence table", report._convergence_section)
    report._nongeometric_part = timed("non-geometric section", report._nongeometric_part)
    for mod in [m for n, m in sys.modules.items() if n.startswith("pipeline.report")]:
        if hasattr(mod, "save_png"):
            mod.save_png = timed("figures: rendering to PNG", mod.save_png)
    _clear(d)
    c0 = time.process_time()
    result = identify(d, report=False)
    runner = time.process_time() - c0
    stages = {r.name: r.cpu_seconds for r in result.runs}
    c0 = time.process_time()
    report.write_report(d)
    total = time.process_time() - c0
    parts["the rest of the report"] = total - sum(parts.values())
    return {
        "start": start,
        "imports": dict(imports),
        "stages": stages,
        "runner": runner - sum(stages.values()),
        "report": dict(parts),
    }


def _median(rows: list[dict[str, float]]) -> dict[str, float]:
    return {k: statistics.median(r.get(k, 0.0) for r in rows) for k in rows[0]}


def measure(d: Path, label: str) -> None:
    """Print the ratios and the cost table of one session (``d``: a pose-set session)."""
    modules = _modules(d)
    full, bare, fit, fit_bare, tables = [], [], [], [], []
    for _ in range(RUNS):
        cpu, stages = _identify(d)
        full.append(cpu)
        fit.append(sum(r["cpu_seconds"] or 0.0 for r in stages if r["name"] in FIT))
        cpu, stages = _identify(d, "--no-report")
        bare.append(cpu)
        fit_bare.append(sum(r["cpu_seconds"] or 0.0 for r in stages if r["name"] in FIT))
        out = _python("-m", "bench.identify_cost", "--child", str(d), *modules)
        tables.append(json.loads(out))
    f = statistics.median(fit + fit_bare)
    alone = statistics.median(sum(t["stages"][k] for k in FIT) for t in tables)
    i, b = statistics.median(full), statistics.median(bare)
    print(f"{label}, median of {RUNS} cold runs (CPU, s)")
    print(
        f"  identify {i:6.2f}   --no-report {b:6.2f}   fit (frames + refine) as the command "
        f"ran it {f:6.2f}, its computation alone (modules imported before) {alone:6.2f}"
    )
    print(
        f"  identify / fit {i / f:5.2f} (/ the computation alone {i / alone:5.2f}), "
        f"--no-report {b / f:5.2f} ({b / alone:5.2f})   (goal <= {GOAL:g})"
    )
    rows: list[tuple[str, float]] = [
        ("interpreter start", statistics.median(t["start"] for t in tables))
    ]
    rows += [(f"imports: {k}", v) for k, v in _median([t["imports"] for t in tables]).items()]
    stages = _median([t["stages"] for t in tables])
    rows += [(f"stage {k}" + (" (fit)" if k in FIT else ""), v) for k, v in stages.items()]
    rows.append(("outside the stages (reading the recording, checks)",
                 statistics.median(t["runner"] for t in tables)))  # fmt: skip
    rows += [(f"report: {k}", v) for k, v in _median([t["report"] for t in tables]).items()]
    for name, v in sorted(rows, key=lambda r: -r[1]):
        if v >= 0.005:
            print(f"    {name:52s} {v:6.3f}")
    total = sum(v for _, v in rows)
    print(f"    {'sum of the rows (one process, imports first)':52s} {total:6.3f}")


def main() -> None:
    from bench.pose_sets import real_ur10_c, simulated_ur10

    exe = str(Path(sys.executable).with_name("pipeline"))
    with tempfile.TemporaryDirectory() as tmp:
        d = simulated_ur10(exe, Path(tmp))
        measure(d, "identify cost (issue 45): UR10 simulated, 1,000 poses")
        r = real_ur10_c(exe, Path(tmp))
        if isinstance(r, str):
            print(f"identify cost, UR10 real Series C: skipped ({r})")
            return
        measure(r, "identify cost (issue 45): UR10 real, Series C (2,773 poses)")


if __name__ == "__main__":
    if sys.argv[1:2] == ["--child"]:
        print(json.dumps(child(Path(sys.argv[2]), sys.argv[3:])))
    else:
        main()
