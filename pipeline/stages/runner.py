"""Run the stages of a session, caching each in ``stages/<name>.arrow``.

A stage reruns only when its version, its parameters or the content hash of
one of its inputs changed (or when forced); otherwise it is reported cached.
Every output is validated against its schema and written with its provenance.

A run is all or nothing: outputs go to ``stages/.pending/`` and are renamed
into ``stages/`` only when every stage of the run succeeded, so a failing
run leaves the files of the last good run untouched.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import importlib
import os
import shutil
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pipeline import __version__
from pipeline.errors import ArmsigError, StageError
from pipeline.schemas import validate_table
from pipeline.stages.base import RECORDING, Stage
from pipeline.stages.lock import session_lock
from pipeline.stages.recording import file_sha256, read_recording
from pipeline.stages.tables import content_hash, read_provenance, read_table, write_table

#: Stage modules in pipeline order (each defines ``STAGE``).
STAGE_MODULES = (
    "session",
    "ranges",
    "joints",
    "compensate",
    "triangulate",
    "features",
    "residuals",
    "frames",
    "smodel",
    "dh",
)
#: Stage modules of ``pipeline evaluate`` (run after the identification, same runner).
EVALUATE_STAGE_MODULES = (
    "evaluate_teach",
    "evaluate_program",
    "evaluate_measurements",
    "evaluate_indices",
)
#: Stage inputs that are files of the session folder other than stage outputs:
#: name -> (file name, ``module:function`` that loads it from its path).
#: They are hashed by content, like the recording.
FILE_INPUTS = {
    "signature": ("signature.json", "pipeline.signature_file:load_signature"),
    "evaluation": ("evaluation.mcap", "pipeline.evaluation.recording:read_evaluation"),
}


def stages(modules: tuple[str, ...] = STAGE_MODULES) -> list[Stage]:
    """All stages of a stage list (default: the identification), in order."""
    return [importlib.import_module(f"pipeline.stages.{m}").STAGE for m in modules]


def _load_file_input(sdir: Path, name: str) -> Any:
    """Load a :data:`FILE_INPUTS` file of a session with its loader."""
    fname, loader = FILE_INPUTS[name]
    path = sdir / fname
    if not path.is_file():
        raise StageError(
            f"{sdir}: no {fname}", fix="run `pipeline identify` / `pipeline evaluate` first"
        )
    module, func = loader.split(":")
    return getattr(importlib.import_module(module), func)(path)


def stage_path(session_dir: Path, name: str) -> Path:
    """Where a stage's committed output lives."""
    return session_dir / "stages" / f"{name}.arrow"


def _pending_dir(session_dir: Path) -> Path:
    return session_dir / "stages" / ".pending"


@dataclass(frozen=True)
class StageStatus:
    """``state`` is fresh, stale or missing; ``reason`` says why."""

    name: str
    state: str
    reason: str


@dataclass(frozen=True)
class StageRun:
    """What the runner did with one stage: ``ran`` or ``cached``, and how long it took."""

    name: str
    action: str
    seconds: float
    rows: int


def _params(stage: Stage, overrides: Mapping[str, Mapping[str, Any]]) -> Any:
    over = dict(overrides.get(stage.name, {}))
    if not over:
        return stage.params
    known = {f.name: f for f in dataclasses.fields(stage.params)}
    for key, value in over.items():
        if key not in known:
            raise ArmsigError(
                f"stage '{stage.name}' has no parameter '{key}'",
                expected=", ".join(known) or "no parameters",
                fix="`pipeline status SESSION` lists the stages; see their modules for parameters",
            )
        default = getattr(stage.params, key)
        try:
            over[key] = (
                type(default)(value)
                if not isinstance(default, bool)
                else (
                    value if isinstance(value, bool) else str(value).lower() in ("1", "true", "yes")
                )
            )
        except (TypeError, ValueError) as exc:
            raise ArmsigError(
                f"parameter {stage.name}.{key} has the wrong type",
                expected=type(default).__name__,
                got=repr(value),
            ) from exc
    return dataclasses.replace(stage.params, **over)


class _Hashes:
    """Content hashes of the recording and of stage files, computed once per run."""

    def __init__(self, session_dir: Path) -> None:
        self.session_dir = session_dir
        self._cache: dict[str, str | None] = {}
        self.pending: set[str] = set()  # stages written in this run, not committed yet

    def path(self, name: str) -> Path:
        if name in self.pending:
            return _pending_dir(self.session_dir) / f"{name}.arrow"
        return stage_path(self.session_dir, name)

    def get(self, name: str) -> str | None:
        if name not in self._cache:
            if name == RECORDING:
                rec = self.session_dir / "recording.mcap"
                self._cache[name] = file_sha256(rec) if rec.is_file() else None
            elif name in FILE_INPUTS:
                f = self.session_dir / FILE_INPUTS[name][0]
                self._cache[name] = file_sha256(f) if f.is_file() else None
            else:
                path = self.path(name)
                self._cache[name] = (
                    read_provenance(path).get("content_hash") if path.is_file() else None
                )
        return self._cache[name]

    def set(self, name: str, value: str) -> None:
        self._cache[name] = value


def _check(stage: Stage, params: Any, hashes: _Hashes, stale: set[str]) -> StageStatus:
    path = hashes.path(stage.name)
    if not path.is_file():
        return StageStatus(stage.name, "missing", "never run")
    try:
        prov = read_provenance(path)
    except StageError:
        return StageStatus(stage.name, "stale", "file unreadable")
    if prov.get("stage_version") != stage.version:
        return StageStatus(
            stage.name, "stale", f"version {prov.get('stage_version')} -> {stage.version}"
        )
    if prov.get("params") != stage.params_dict(params):
        return StageStatus(stage.name, "stale", "parameters changed")
    for inp in stage.inputs:
        if inp in stale:
            return StageStatus(stage.name, "stale", f"input {inp} is stale or missing")
        if prov.get("inputs", {}).get(inp) != hashes.get(inp):
            return StageStatus(stage.name, "stale", f"input {inp} changed")
    return StageStatus(stage.name, "fresh", "inputs, parameters and version unchanged")


def status(
    session_dir: str | Path,
    overrides: Mapping[str, Mapping[str, Any]] | None = None,
    modules: tuple[str, ...] = STAGE_MODULES,
) -> list[StageStatus]:
    """Freshness of every stage of a session, and why (``modules``: the stage list,
    e.g. ``STAGE_MODULES + EVALUATE_STAGE_MODULES``; staleness propagates along it)."""
    sdir = Path(session_dir)
    hashes = _Hashes(sdir)
    out: list[StageStatus] = []
    stale: set[str] = set()
    for stage in stages(modules):
        st = _check(stage, _params(stage, overrides or {}), hashes, stale)
        if st.state != "fresh":
            stale.add(stage.name)
        out.append(st)
    return out


def run(
    session_dir: str | Path,
    *,
    force: bool = False,
    from_stage: str | None = None,
    only: str | None = None,
    overrides: Mapping[str, Mapping[str, Any]] | None = None,
    modules: tuple[str, ...] = STAGE_MODULES,
) -> list[StageRun]:
    """Bring every stage of a session up to date.

    Parameters
    ----------
    modules : the stage list (:data:`STAGE_MODULES` or :data:`EVALUATE_STAGE_MODULES`).
    force : rerun every stage.
    from_stage : rerun this stage and every later one.
    only : rerun just this stage (its inputs must exist).
    overrides : ``{stage: {param: value}}``.
    """
    sdir = Path(session_dir)
    if not (sdir / "recording.mcap").is_file():
        raise StageError(
            f"{sdir}: no recording.mcap",
            expected="a session folder holding recording.mcap",
            fix="`pipeline simulate NAME` records a simulated session",
        )
    all_stages = stages(modules)
    names = [s.name for s in all_stages]
    for opt, value in (("--from", from_stage), ("--only", only)):
        if value is not None and value not in names:
            raise ArmsigError(f"{opt}: unknown stage {value!r}", expected=", ".join(names))
    overrides = overrides or {}
    for key in overrides:
        if key not in names:
            raise ArmsigError(f"unknown stage {key!r} in parameters", expected=", ".join(names))
    runs: list[StageRun] = []
    with session_lock(sdir):
        pending = _pending_dir(sdir)
        shutil.rmtree(pending, ignore_errors=True)  # debris of a killed run
        hashes = _Hashes(sdir)
        try:
            _run_all(sdir, all_stages, names, hashes, runs, force, from_stage, only, overrides)
            for name in names:  # commit: every stage of the run succeeded
                if name in hashes.pending:
                    os.replace(pending / f"{name}.arrow", stage_path(sdir, name))
        finally:
            shutil.rmtree(pending, ignore_errors=True)
    return runs


def _run_all(
    sdir: Path,
    all_stages: list[Stage],
    names: list[str],
    hashes: _Hashes,
    runs: list[StageRun],
    force: bool,
    from_stage: str | None,
    only: str | None,
    overrides: Mapping[str, Mapping[str, Any]],
) -> None:
    """Bring each stage up to date in order, writing outputs to the pending folder."""
    stale: set[str] = set()
    forced_from = names.index(from_stage) if from_stage else None
    for k, stage in enumerate(all_stages):
        params = _params(stage, overrides)
        if only is not None and stage.name != only:
            runs.append(StageRun(stage.name, "skipped", 0.0, 0))
            continue
        st = _check(stage, params, hashes, stale)
        must = (
            force
            or only == stage.name
            or (forced_from is not None and k >= forced_from)
            or st.state != "fresh"
        )
        if not must:
            runs.append(StageRun(stage.name, "cached", 0.0, -1))
            continue
        t0 = time.perf_counter()
        # Dependants compare their recorded input hash with the new one in `hashes`.
        table = _run_one(sdir, stage, params, hashes)
        runs.append(StageRun(stage.name, "ran", time.perf_counter() - t0, table.num_rows))


def _run_one(sdir: Path, stage: Stage, params: Any, hashes: _Hashes) -> Any:
    inputs: dict[str, Any] = {}
    for inp in stage.inputs:
        if inp == RECORDING:
            inputs[inp] = read_recording(sdir / "recording.mcap", hashes.get(RECORDING))
        elif inp in FILE_INPUTS:
            inputs[inp] = _load_file_input(sdir, inp)
        else:
            path = hashes.path(inp)
            if not path.is_file():
                raise StageError(
                    f"{sdir}: stage '{stage.name}' needs '{inp}', which has not run",
                    fix=f"run `pipeline identify {sdir}` without --only",
                )
            inputs[inp] = read_table(path)
    try:
        table = stage.compute(inputs, params)
    except ArmsigError as exc:  # name the session and the stage, keep the cause's advice
        raise StageError(f"{sdir}: stage '{stage.name}': {exc}") from exc
    table = validate_table(table, stage.name, source=f"{sdir}: stage '{stage.name}'")
    digest = content_hash(table)
    provenance = {
        "stage": stage.name,
        "stage_version": stage.version,
        "params": stage.params_dict(params),
        "inputs": {inp: hashes.get(inp) for inp in stage.inputs},
        "content_hash": digest,
        "package_version": __version__,
        "created": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
    }
    hashes.pending.add(stage.name)
    write_table(hashes.path(stage.name), table, provenance)
    hashes.set(stage.name, digest)
    return table
