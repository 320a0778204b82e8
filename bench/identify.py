"""Cold and warm `pipeline identify` on robot3, and identify time against points per sweep.

Issue 4 targets: cold (every stage from the recording) <= 2 s, warm (all cached) <= 0.5 s.
Issue 18: cold CPU <= 0.5x and warm CPU <= 0.6x those of commit ace4dae, measured in the
same run; identify time linear or better in points per sweep from 400 to 1,600.

With ``BENCH_BASELINE=DIR[:DIR...]`` (other armsig checkout with its own ``.venv``, e.g.
``git worktree add --detach ../armsig-ace4dae ace4dae && make -C ../armsig-ace4dae install``)
all are run alternately in the same run and the ratios to each are printed, since the machines
are shared and noisy. CPU is user + system time of the child process (interpreter start,
imports, stages, signature and report included).
"""

from __future__ import annotations

import json
import math
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
#: Points per sweep of the scaling measurement (issue 18: 400 to 1,600).
SCALING_POINTS = (400, 800, 1600)
COLD_TARGET, WARM_TARGET = 0.5, 0.6


def _cpu() -> float:
    """User + system CPU seconds of every finished child process so far."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _run(cmd: list[str], env: dict[str, str] | None = None) -> tuple[float, float]:
    """Wall and CPU seconds of one command."""
    c0, t0 = _cpu(), time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True, env=env)
    return time.perf_counter() - t0, _cpu() - c0


def _clear(d: Path) -> None:
    """Leave only the recording: the next identify of ``d`` is cold."""
    for name in ("stages", "report"):
        shutil.rmtree(d / name, ignore_errors=True)
    (d / "signature.json").unlink(missing_ok=True)


def _cold(exe: str, d: Path) -> tuple[float, float]:
    _clear(d)
    return _run([exe, "identify", str(d)])


#: The stages of the refinement (issue 15), which commit ace4dae did not have.
REFINEMENT = ("refine", "uncertainty", "holdout", "verdict")
_REPORT_ALONE = (
    "import sys; from pipeline.report.identification import write_report; write_report(sys.argv[1])"
)


def _floor(exe: str, d: Path, cold_target_cpu: float | None) -> None:
    """Where a cold run's CPU goes: the report alone (a fresh process: imports, matplotlib,
    the PNGs) and the refinement's stages (their seconds from ``--json``; one thread, so
    wall ~ CPU on a quiet machine), against the issue-18 cold target when known."""
    refine: list[float] = []
    report: list[float] = []
    for _ in range(max(1, RUNS // 2)):
        _clear(d)
        out = subprocess.run(
            [exe, "identify", str(d), "--no-report", "--json"],
            check=True, capture_output=True, text=True,
        )  # fmt: skip
        stages = json.loads(out.stdout)["stages"]
        refine.append(sum(r["seconds"] for r in stages if r["name"] in REFINEMENT))
        shutil.rmtree(d / "report", ignore_errors=True)
        python = str(Path(exe).with_name("python"))
        env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}  # as the console script starts
        report.append(_run([python, "-c", _REPORT_ALONE, str(d)], env)[1])
    print(
        f"{'report alone (fresh process: imports, matplotlib, PNGs), CPU':60s} {min(report):7.3f} s"
    )
    print(f"{'refinement stages (' + ', '.join(REFINEMENT) + ')':60s} {min(refine):7.3f} s")
    if cold_target_cpu is not None:
        print(
            f"report + refinement {min(report) + min(refine):.3f} s against the cold target "
            f"{cold_target_cpu:.3f} s CPU (0.5 x the baseline's cold run)"
        )


def _scaling(exe: str, tmp: Path) -> None:
    """Cold identify CPU of simulated sessions against points per sweep; the fitted exponent."""
    from pipeline.rig.simulate import SimulationOptions, simulate_session

    cpu = []
    for n in SCALING_POINTS:
        d = tmp / f"p{n}"
        simulate_session(d, SimulationOptions(seed=3, points=n))
        _cold(exe, d)  # untimed: caches
        cpu.append(min(_cold(exe, d)[1] for _ in range(max(1, RUNS // 2))))
        name = f"pipeline identify, {n} points per sweep, cold CPU"
        print(f"{name:60s} {cpu[-1]:7.3f} s")
    x, y = (math.log(v) for v in SCALING_POINTS), (math.log(c) for c in cpu)
    xs, ys = list(x), list(y)
    mx, my = sum(xs) / len(xs), sum(ys) / len(ys)
    slope = sum((a - mx) * (b - my) for a, b in zip(xs, ys, strict=True)) / sum(
        (a - mx) ** 2 for a in xs
    )
    lo, hi = SCALING_POINTS[0], SCALING_POINTS[-1]
    verdict = "linear or better" if slope <= 1.0 else "WORSE than linear"
    print(f"identify CPU ~ P^{slope:.2f} for P = {lo} to {hi} points per sweep ({verdict})")


def main() -> None:
    exes = {"this checkout": str(Path(sys.executable).with_name("pipeline"))}
    bases = [b for b in os.environ.get("BENCH_BASELINE", "").split(os.pathsep) if b]
    for base in bases:  # several: e.g. ace4dae and main, all in the same run
        exes["baseline " + base] = str(Path(base) / ".venv" / "bin" / "pipeline")
    keys = ("cold", "cold CPU", "warm", "warm CPU")
    times: dict[str, dict[str, list[float]]] = {k: {w: [] for w in keys} for k in exes}
    with tempfile.TemporaryDirectory() as tmp:
        dirs = {label: Path(tmp) / str(k) / "robot3" for k, label in enumerate(exes)}
        for label, exe in exes.items():  # one untimed run each: numba and .pyc caches
            dirs[label].mkdir(parents=True)
            shutil.copy(ROOT / "sessions/robot3/recording.mcap", dirs[label])
            _cold(exe, dirs[label])
        for _ in range(RUNS):  # alternate, so both see the same machine load
            for label, exe in exes.items():
                wall, cpu = _cold(exe, dirs[label])
                times[label]["cold"].append(wall)
                times[label]["cold CPU"].append(cpu)
        for _ in range(RUNS):
            for label, exe in exes.items():
                wall, cpu = _run([exe, "identify", str(dirs[label])])
                times[label]["warm"].append(wall)
                times[label]["warm CPU"].append(cpu)
        for label in exes:
            for what in keys:
                name = f"pipeline identify robot3, {what}, {label}"
                print(f"{name:60s} {min(times[label][what]):7.3f} s (best of {RUNS})")
        this = times["this checkout"]
        for base in bases:
            other = times["baseline " + base]
            r = {w: min(this[w]) / min(other[w]) for w in keys}
            print(
                f"this / {base}: cold {r['cold']:.3f} (CPU {r['cold CPU']:.3f}, target <= "
                f"{COLD_TARGET}), warm {r['warm']:.3f} (CPU {r['warm CPU']:.3f}, target <= "
                f"{WARM_TARGET})"
            )
        if not bases:
            print(
                "(for the issue-18 ratios set BENCH_BASELINE to a checkout of ace4dae with "
                "its own .venv)"
            )
        first = min(times["baseline " + bases[0]]["cold CPU"]) if bases else None
        _floor(
            exes["this checkout"],
            dirs["this checkout"],
            None if first is None else COLD_TARGET * first,
        )
        if os.environ.get("BENCH_SCALING", "1") != "0":
            _scaling(exes["this checkout"], Path(tmp))
