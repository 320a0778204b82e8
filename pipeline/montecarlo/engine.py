"""Run a swept Monte-Carlo study: settings × robots, in batches, optionally in worker processes.

A :class:`Study` names the swept parameter, its values and a function that
evaluates a batch of robots (one seed sequence each) at one value. Batches are
independent and each robot has its own stream (:func:`~.stats.robot_seeds`),
so the result is the same for any batch size and any number of workers.
:func:`run_tasks` is where every study's tasks run (this process, a process pool or
Dask), the swept studies' batches and the ``verdict`` study's sessions alike.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from typing import Any, TextIO, TypeVar

import numpy as np

from pipeline.kinematics.transforms import Array
from pipeline.montecarlo.stats import Summary, robot_seeds, summarize
from pipeline.progress import Progress

#: ``(parameter value, seeds of a batch of robots) -> values (batch, K)``.
Evaluate = Callable[[float, list[np.random.SeedSequence]], Array]
#: ``(all parameter values, seeds of a batch) -> values (settings, batch, K)``.
EvaluateAll = Callable[[tuple[float, ...], list[np.random.SeedSequence]], Array]
T = TypeVar("T")


@dataclass(frozen=True)
class Study:
    """One swept study.

    Attributes
    ----------
    name : str
    title : str
        Axis label of the swept parameter for figures and the report.
    parameter : str
        Column name of the swept parameter, unit suffixed (``sigma_e_deg``).
    parameter_unit : str
        ``cm``, ``deg``, ``mm`` (the compliance study) or ``""``.
    values : tuple of float
        The settings.
    evaluate : Evaluate
        Picklable (module-level) so worker processes can run it.
    index_names, index_units : tuple of str
    index_signed : tuple of bool
    batch : int
        Robots per batch (memory: see each study).
    evaluate_all : EvaluateAll or None
        When given, every setting uses the same robots (common random numbers,
        seeded as setting 0) and one call evaluates a batch at all settings;
        ``evaluate`` is then unused.
    """

    name: str
    title: str
    parameter: str
    parameter_unit: str
    values: tuple[float, ...]
    evaluate: Evaluate
    index_names: tuple[str, ...]
    index_units: tuple[str, ...]
    index_signed: tuple[bool, ...]
    batch: int = 500
    evaluate_all: EvaluateAll | None = None


@dataclass(frozen=True)
class StudyResult:
    """Values (S, R, K) of every setting and robot, their summary, and the wall time (s)."""

    study: Study
    values: Array
    summary: Summary
    seed: int
    wall_s: float


def _run_batch(study: Study, settings: list[int], seeds: list[np.random.SeedSequence]) -> Array:
    """Values (len(settings), batch, K) of one job."""
    if study.evaluate_all is not None:
        return np.asarray(study.evaluate_all(study.values, seeds), float)
    return np.stack([np.asarray(study.evaluate(study.values[s], seeds), float) for s in settings])


def run_study(
    study: Study,
    robots: int = 500,
    seed: int = 0,
    workers: int = 1,
    progress: TextIO | None = sys.stderr,
    batch: int | None = None,
    client: Any = None,
) -> StudyResult:
    """Evaluate every setting of ``study`` on ``robots`` robots.

    Parameters
    ----------
    robots : int
        Robots per setting (≥ 2: the std needs two).
    seed : int
        Study seed; with the same seed the result is identical for any
        ``workers`` (and, up to the solver tolerance, any ``batch``).
    workers : int
        Worker processes (1: run in this process).
    progress : text stream or None
        Where the progress bar goes (None: silent).
    batch : int, optional
        Robots per batch; the study's default if omitted.
    client : distributed.Client, optional
        Run the batches as Dask tasks on this client instead (``workers`` unused); the
        same batches and seeds, so the same numbers.
    """
    if robots < 2:
        raise ValueError(f"--robots must be at least 2 (the std needs two), got {robots}")
    size = max(1, batch or study.batch)
    n_set = len(study.values)
    jobs: list[tuple[list[int], int, list[np.random.SeedSequence]]] = []
    if study.evaluate_all is not None:
        seeds = robot_seeds(seed, study.name, 0, robots)
        jobs = [(list(range(n_set)), a, seeds[a : a + size]) for a in range(0, robots, size)]
    else:
        for s in range(n_set):
            seeds = robot_seeds(seed, study.name, s, robots)
            jobs += [([s], a, seeds[a : a + size]) for a in range(0, robots, size)]
    bar = Progress(study.name, len(jobs), progress)
    t0 = time.perf_counter()
    tasks = [(study, st, sd) for st, _, sd in jobs]
    results = run_tasks(_run_batch, tasks, workers, bar, client)
    values = np.empty((n_set, robots, len(study.index_names)))
    for (settings, a, seeds), res in zip(jobs, results, strict=True):
        values[settings, a : a + len(seeds)] = res
    return StudyResult(study, values, summarize(values), seed, time.perf_counter() - t0)


def run_tasks(
    fn: Callable[..., T],
    tasks: list[tuple[Any, ...]],
    workers: int,
    bar: Progress,
    client: Any = None,
) -> list[T]:
    """``fn(*task)`` of every task, in submission order (deterministic assembly): as Dask
    tasks on ``client`` when given, else in a pool of ``workers`` processes, else (one
    worker) in this process. ``fn`` is a plain module-level function (picklable);
    placement and scheduling are the pool's or Dask's. ``bar`` steps once per task."""
    results: list[T] = []
    if client is not None:
        futures = client.map(fn, *zip(*tasks, strict=True), pure=False) if tasks else []
        for f in futures:
            results.append(f.result())
            bar.step()
    elif workers <= 1:
        for task in tasks:
            results.append(fn(*task))
            bar.step()
    else:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            futures = [pool.submit(fn, *task) for task in tasks]
            for f in futures:
                results.append(f.result())
                bar.step()
    return results
