"""`pipeline fleet identify` of 20 sessions on a 2-worker local cluster against a sequential
loop, and the Monte-Carlo noise study (500 robots) on Dask against the process pool
(issue 17 targets: fleet speed-up >= 1.6x; Dask within 10 % of the pool).

Sessions: copies of the committed recordings robot1..robot7, cycled to 20 folders.
Sequential: :func:`pipeline.identify.identify` in a loop in this process, after one
untimed session (imports, numba caches warm): the fastest sequential way. The fleet
time is run_fleet's wall on a freshly started cluster; the cluster start (the workers'
imports, done by their preload) is printed apart and included in the second ratio.
Every identification is cold (no stages) and writes its report, as `pipeline identify`
does. The machine is shared: the lines say what was measured, not a guarantee.
"""

from __future__ import annotations

import resource
import shutil
import tempfile
import time
from pathlib import Path

from pipeline.fleet.engine import FLEET_PRELOAD, dask_client
from pipeline.fleet.run import run_fleet
from pipeline.identify import identify
from pipeline.montecarlo.engine import run_study
from pipeline.montecarlo.studies import get_study

ROOT = Path(__file__).resolve().parent.parent
SESSIONS = 20
WORKERS = 2
ROBOTS = 500


def _sessions(folder: Path) -> list[Path]:
    out = []
    for i in range(SESSIONS):
        d = folder / f"s{i:02d}"
        d.mkdir(parents=True)
        shutil.copy(ROOT / f"sessions/robot{i % 7 + 1}/recording.mcap", d)
        out.append(d)
    return out


def _peak_rss_mb() -> float:
    """Peak resident memory of this process (MB; Linux reports kB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def fleet() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        warm = _sessions(Path(tmp) / "warm")[0]
        identify(warm)  # untimed: imports and numba caches
        seq = _sessions(Path(tmp) / "seq")
        t0, c0 = time.perf_counter(), time.process_time()
        for d in seq:
            identify(d)
        t_seq, c_seq = time.perf_counter() - t0, time.process_time() - c0
        fl = Path(tmp) / "fleet"
        _sessions(fl)
        t0 = time.perf_counter()
        with dask_client(None, WORKERS, preload=FLEET_PRELOAD, share_cores=True) as client:
            t_start = time.perf_counter() - t0
            c0s, c0 = client.run(time.process_time), time.process_time()
            r = run_fleet("identify", [str(fl)], client, fl, progress=None)
            c1s, c_here = client.run(time.process_time), time.process_time() - c0
            rss = client.run(_peak_rss_mb)
        t_all = time.perf_counter() - t0
    assert not r.failed, r.failed
    per = sorted(row["task_s"] for row in r.rows)
    c_fleet = sum(c1s[w] - c0s[w] for w in c1s)
    c_start = sum(c0s.values())  # each worker process from its spawn: imports, preload
    print(f"{'identify, sequential loop in one process':52s} {t_seq:7.1f} s "
          f"({t_seq / SESSIONS:.2f} s per session)")  # fmt: skip
    print(f"{'fleet identify, 2 workers (run_fleet wall)':52s} {r.wall_s:7.1f} s "
          f"speed-up {t_seq / r.wall_s:.2f}x")  # fmt: skip
    print(f"{'fleet identify incl. cluster start and stop':52s} {t_all:7.1f} s "
          f"speed-up {t_seq / t_all:.2f}x (start {t_start:.1f} s)")  # fmt: skip
    print(f"{'fleet task time per session: median, max':52s} {per[len(per) // 2]:7.2f} s "
          f"{per[-1]:.2f} s")  # fmt: skip
    print(f"{'fleet worker peak RSS (max over workers)':52s} {max(rss.values()):7.0f} MB")
    # CPU seconds do not depend on what else runs on the machine (much less than wall time):
    # on 2 idle cores, a balanced fleet would take c_fleet / 2.
    print(f"{'CPU: sequential, fleet workers (sum)':52s} {c_seq:7.1f} s {c_fleet:.1f} s; "
          f"speed-up on 2 idle cores at this CPU {2 * c_seq / c_fleet:.2f}x")  # fmt: skip
    print(f"{'CPU: fleet workers incl. their start (sum)':52s} {c_start + c_fleet:7.1f} s "
          f"(start {c_start:.1f} s); speed-up on 2 idle cores at this CPU "
          f"{2 * c_seq / (c_start + c_fleet):.2f}x")  # fmt: skip
    print(f"{'CPU: this process (client and scheduler) in the run':52s} {c_here:7.1f} s")


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def montecarlo() -> None:
    study = get_study("noise")
    t0, c0 = time.perf_counter(), _children_cpu()
    pool = run_study(study, ROBOTS, seed=0, workers=WORKERS, progress=None)
    t_pool, c_pool = time.perf_counter() - t0, _children_cpu() - c0
    t0 = time.perf_counter()
    with dask_client(None, WORKERS) as client:
        t_start = time.perf_counter() - t0
        c0s = client.run(time.process_time)
        on_dask = run_study(study, ROBOTS, seed=0, progress=None, client=client)
        c1s = client.run(time.process_time)
    t_dask = time.perf_counter() - t0
    c_dask = sum(c1s[w] - c0s[w] for w in c1s)
    same = bool((pool.values == on_dask.values).all())
    print(f"{'montecarlo noise 500 robots, process pool (2)':52s} {t_pool:7.1f} s "
          f"CPU {c_pool:.1f} s")  # fmt: skip
    print(f"{'montecarlo noise 500 robots, Dask (2 workers)':52s} {on_dask.wall_s:7.1f} s "
          f"CPU {c_dask:.1f} s; wall ratio {on_dask.wall_s / t_pool:.3f}, CPU ratio "
          f"{c_dask / c_pool:.3f}; incl. cluster start+stop {t_dask:.1f} s "
          f"(start {t_start:.1f} s); identical: {same}")  # fmt: skip


def main() -> None:
    fleet()
    montecarlo()


if __name__ == "__main__":
    main()
