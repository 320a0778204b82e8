"""Run the stages of a session, caching each in ``stages/<name>.arrow``.

A stage reruns only when its version, its parameters or the content hash of
one of its inputs changed, when its file fails its check (unreadable, columns
of another schema, data no longer hashing to the recorded content hash), or
when forced; otherwise it is reported cached. Every output is validated
against its schema and written with its provenance.

A run is all or nothing: outputs go to ``stages/.pending/`` and are renamed
into ``stages/`` only when every stage of the run succeeded, so a failing
run leaves the files of the last good run untouched; its own outputs move to
``stages/failed/`` for inspection (removed by the next good run). Then, still
under the session lock, the run writes its product ``signature.json`` from the
committed identification stages unless the file there already matches them.

Stages compute with one BLAS thread (:func:`one_blas_thread`), so a stage's output is
the same bits on any machine, in any fleet worker and in a Monte-Carlo study.
"""

from __future__ import annotations

import contextlib
import dataclasses
import datetime as dt
import os
import shutil
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

from threadpoolctl import threadpool_limits

from pipeline import __version__
from pipeline.atomic import WRITE_FIX, remove_debris
from pipeline.contract.digest import file_sha256
from pipeline.errors import ArmsigError, StageError, os_errors_refused
from pipeline.heap import return_freed
from pipeline.progress import Progress
from pipeline.schemas import validate_table
from pipeline.stages.base import IMAGES, RECORDING, Stage, StageRun, session_folder
from pipeline.stages.catalog import (
    FILE_INPUTS,
    LAST_STAGE,
    PRODUCT,
    SENSOR_STAGE_MODULES,
    function_of,
    identification_names,
    is_identification,
    stages,
)
from pipeline.stages.image_inputs import image_refs
from pipeline.stages.lock import session_lock
from pipeline.stages.recording import read_recording
from pipeline.stages.session import session_kind
from pipeline.stages.tables import CheckedTable, check_table, content_hash, write_table

FAILED = "failed"


def identification_modules(session_dir: str | Path) -> tuple[str, ...]:
    """The identification stage modules of a session, by its recorded sensor kind."""
    return _Hashes(session_folder(session_dir)).identification_modules()


def _load_file_input(sdir: Path, name: str, hashes: _Hashes) -> Any:
    """Load a :data:`FILE_INPUTS` file of a session with its loader; the product's loader
    also gets the content hashes of the committed stages, already checked in this run."""
    fname, loader = FILE_INPUTS[name]
    path = sdir / fname
    if not path.is_file():
        raise StageError(
            f"{sdir}: no {fname}", fix="run `pipeline identify` / `pipeline evaluate` first"
        )
    if name == PRODUCT[0]:
        return function_of(loader)(path, {n: hashes.get(n) for n in hashes.identification()})
    return function_of(loader)(path)


def stage_path(session_dir: Path, name: str) -> Path:
    """Where a stage's committed output lives."""
    return session_dir / "stages" / f"{name}.arrow"


def _pending_dir(session_dir: Path) -> Path:
    return session_dir / "stages" / ".pending"


def failed_dir(session_dir: Path) -> Path:
    """Where the outputs of the last failed run wait for inspection."""
    return session_dir / "stages" / FAILED


@dataclass(frozen=True)
class StageStatus:
    """``state`` is fresh, stale or missing; ``reason`` says why."""

    name: str
    state: str
    reason: str


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
    """Content hashes of the recording, the file inputs and stage files (each stage file
    checked once per run: see :func:`pipeline.stages.tables.check_table`)."""

    def __init__(self, session_dir: Path) -> None:
        self.session_dir = session_dir
        self._files: dict[str, str | None] = {}
        self._tables: dict[str, CheckedTable | None] = {}
        self._product: tuple[str, str] | None = None
        self._sensor: str | None = None
        self._images: Any = None
        self.pending: set[str] = set()  # stages written in this run, not committed yet

    def sensor(self) -> str:
        """The recorded sensor kind: from the committed ``session`` table when it was made
        from this recording (cheap), else from the recording itself."""
        if self._sensor is None:
            checked = self.check("session")
            rec_hash = self.get(RECORDING)
            if (
                checked is not None
                and not checked.problem
                and checked.table is not None
                and checked.table.column("recording_sha256")[0].as_py() == rec_hash
            ):
                self._sensor = session_kind(checked.table)
            else:
                rec = read_recording(self.session_dir / "recording.mcap", rec_hash)
                self._sensor = rec.kind
        return self._sensor

    def identification_modules(self) -> tuple[str, ...]:
        return SENSOR_STAGE_MODULES[self.sensor()]

    def identification(self) -> tuple[str, ...]:
        """Stage names of the session's identification (product inputs)."""
        return identification_names(self.sensor())

    def path(self, name: str) -> Path:
        if name in self.pending:
            return _pending_dir(self.session_dir) / f"{name}.arrow"
        return stage_path(self.session_dir, name)

    def check(self, name: str) -> CheckedTable | None:
        """The checked stage file, or None when there is none."""
        if name not in self._tables:
            path = self.path(name)
            self._tables[name] = check_table(path, name) if path.is_file() else None
        return self._tables[name]

    def images(self) -> Any:
        """The images the recording references, hashed once per run (:data:`IMAGES`)."""
        if self._images is None:
            rec = read_recording(self.session_dir / "recording.mcap", self.get(RECORDING))
            self._images = image_refs(rec)
        return self._images

    def get(self, name: str) -> str | None:
        """Content hash of an input; None when it is missing or fails its check (a stage
        file, or the product when it does not match the committed stages)."""
        if name == IMAGES:
            return None if self.get(RECORDING) is None else self.images().digest()
        if name == RECORDING or name in FILE_INPUTS:
            if name not in self._files:
                fname = "recording.mcap" if name == RECORDING else FILE_INPUTS[name][0]
                f = self.session_dir / fname
                self._files[name] = file_sha256(f) if f.is_file() else None
                if name == PRODUCT[0] and self.product_status()[0] != "fresh":
                    self._files[name] = None
            return self._files[name]
        checked = self.check(name)
        if checked is None or checked.problem:
            return None
        return checked.provenance.get("content_hash")

    def product_status(self) -> tuple[str, str]:
        """``(state, reason)`` of the product file against the committed stages."""
        if self._product is None:
            check = function_of(PRODUCT[2])
            self._product = check(self.session_dir, {n: self.get(n) for n in self.identification()})
        return self._product

    def put(self, name: str, checked: CheckedTable) -> None:
        """Record a stage output written in this run."""
        self._tables[name] = checked


def committed_hashes(session_dir: str | Path) -> dict[str, str | None]:
    """Content hash of every committed identification stage output whose file passes its
    check (None: missing or failing it)."""
    return recorded_and_committed(session_dir)[1]


def recorded_and_committed(session_dir: str | Path) -> tuple[str | None, dict[str, str | None]]:
    """The SHA-256 of the session's recording (None: missing) and :func:`committed_hashes`,
    from one look at the files (the recording is hashed once)."""
    recorded, committed, _ = recorded_committed_outdated(session_dir)
    return recorded, committed


def recorded_committed_outdated(
    session_dir: str | Path,
) -> tuple[str | None, dict[str, str | None], list[tuple[str, Any, int]]]:
    """:func:`recorded_and_committed` and the committed identification stages that an older
    armsig wrote: ``(name, its stage version, this armsig's)`` for every stage whose
    recorded version is not the current one (``identify`` would recompute them), from the
    same look at the files."""
    hashes = _Hashes(Path(session_dir))
    committed = {n: hashes.get(n) for n in hashes.identification()}
    outdated = []
    for stage in stages(hashes.identification_modules()):
        checked = hashes.check(stage.name)
        if checked is None or checked.problem:
            continue  # missing or damaged: the content check says so
        version = checked.provenance.get("stage_version")
        if version != stage.version:
            outdated.append((stage.name, version, stage.version))
    return hashes.get(RECORDING), committed, outdated


def _check(
    stage: Stage, params: Any, hashes: _Hashes, stale: set[str], as_recorded: bool = False
) -> StageStatus:
    checked = hashes.check(stage.name)
    if checked is None:
        return StageStatus(stage.name, "missing", "never run")
    if checked.problem:
        return StageStatus(stage.name, "stale", checked.problem)
    prov = checked.provenance
    if prov.get("stage_version") != stage.version:
        return StageStatus(
            stage.name, "stale", f"version {prov.get('stage_version')} -> {stage.version}"
        )
    if not as_recorded and prov.get("params") != stage.params_dict(params):
        return StageStatus(stage.name, "stale", "parameters changed")
    for inp in stage.inputs:
        current = hashes.get(inp)
        if inp in stale or current is None:
            return StageStatus(stage.name, "stale", f"input {inp} is stale or missing")
        if prov.get("inputs", {}).get(inp) != current:
            why = hashes.images().changed() if inp == IMAGES else None
            return StageStatus(stage.name, "stale", f"input {inp} changed" + (
                f": {why}" if why else ""))  # fmt: skip
    return StageStatus(stage.name, "fresh", "inputs, parameters and version unchanged")


def status(
    session_dir: str | Path,
    overrides: Mapping[str, Mapping[str, Any]] | None = None,
    modules: tuple[str, ...] | None = None,
    as_recorded: bool = False,
) -> list[StageStatus]:
    """Freshness of every stage of a session, and why (``modules``: the stage list,
    e.g. ``identification_modules(s) + EVALUATE_STAGE_MODULES``; default: the session's
    identification; staleness propagates along it). A list holding the identification
    stages also gives the status of their product (``signature``) right after them.
    ``as_recorded``: each stage judged at the parameters it was computed with (its
    inputs and version still checked), for a command that shows what was identified,
    with ``--param`` or without."""
    sdir = session_folder(session_dir)
    hashes = _Hashes(sdir)
    modules = hashes.identification_modules() if modules is None else modules
    return _statuses(sdir, stages(modules), overrides or {}, hashes, as_recorded=as_recorded)


def _statuses(
    sdir: Path,
    all_stages: list[Stage],
    overrides: Mapping[str, Mapping[str, Any]],
    hashes: _Hashes,
    product: bool = True,
    as_recorded: bool = False,
) -> list[StageStatus]:
    out: list[StageStatus] = []
    stale: set[str] = set()
    has_product = product and is_identification({s.name for s in all_stages})
    for stage in all_stages:
        st = _check(stage, _params(stage, overrides), hashes, stale, as_recorded)
        if st.state != "fresh":
            stale.add(stage.name)
        out.append(st)
        if has_product and stage.name == LAST_STAGE:
            st = _product_status(hashes, stale)
            if st.state != "fresh":
                stale.add(st.name)
            out.append(st)
    return out


def _product_status(hashes: _Hashes, stale: set[str]) -> StageStatus:
    state, reason = hashes.product_status()
    behind = [n for n in hashes.identification() if n in stale]
    if state == "fresh" and behind:
        state, reason = "stale", f"built from stage {behind[0]}, which is stale or missing"
    return StageStatus(PRODUCT[0], state, reason)


def run(
    session_dir: str | Path,
    *,
    force: bool = False,
    from_stage: str | None = None,
    only: str | None = None,
    overrides: Mapping[str, Mapping[str, Any]] | None = None,
    modules: tuple[str, ...] | None = None,
    progress: TextIO | Progress | None = None,
) -> list[StageRun]:
    """Bring every stage of a session up to date, then (identification) its signature.

    Parameters
    ----------
    modules : the stage list (default: the session's identification, by its recorded
        sensor: :data:`SENSOR_STAGE_MODULES`; or :data:`EVALUATE_STAGE_MODULES`).
    force : rerun every stage and rewrite the signature.
    from_stage : rerun this stage and every later one.
    only : rerun just this stage (its inputs must exist and pass their checks).
    overrides : ``{stage: {param: value}}``.
    progress : where the progress line goes (:class:`pipeline.progress.Progress`; None:
        silent), or a bar of the caller's that each stage steps (``evaluate``'s, which
        also counts the rig's recordings and the report).

    Returns
    -------
    One :class:`StageRun` per stage; with the identification stages, a last one for
    the signature: ``written``, ``cached`` (the file matched), or ``not written``
    (a stage is stale after ``only``).
    """
    sdir = session_folder(session_dir)
    overrides = overrides or {}
    runs: list[StageRun] = []
    with session_lock(sdir):  # the recorded sensor (the stage list) is read under the lock
        hashes = _Hashes(sdir)
        all_stages = stages(hashes.identification_modules() if modules is None else modules)
        names = [s.name for s in all_stages]
        for opt, value in (("--from", from_stage), ("--only", only)):
            if value is not None and value not in names:
                raise ArmsigError(f"{opt}: unknown stage {value!r}", expected=", ".join(names))
        for key in overrides:
            if key not in names:
                raise ArmsigError(f"unknown stage {key!r} in parameters", expected=", ".join(names))
        pending = _pending_dir(sdir)
        shutil.rmtree(pending, ignore_errors=True)  # debris of a killed run
        for folder in (sdir, sdir / "stages", sdir / "report"):
            remove_debris(folder)  # temp files of killed atomic writes
        # the session's own stage list is an identification, signature or not (a camera
        # session of flange poses ends at its hand-eye); evaluate passes its own bar
        label = "identify" if modules is None or is_identification(set(names)) else "stages"
        own = not isinstance(progress, Progress)  # else the caller's bar, closed by it
        bar = (
            progress
            if isinstance(progress, Progress)
            else Progress(label, len(all_stages), progress, unit="stages")
        )
        try:
            try:
                _run_all(
                    sdir, all_stages, names, hashes, runs, force, from_stage, only, overrides, bar
                )
            except Exception as exc:
                with contextlib.suppress(OSError):  # a full disk: the run's own error is news
                    _keep_failed(sdir, names, hashes.pending)
                raise _pointing_at_failed(exc, sdir, hashes.pending) from exc
            for name in names:  # commit: every stage of the run succeeded
                if name in hashes.pending:
                    target = stage_path(sdir, name)  # chattr +i: one line naming it
                    with os_errors_refused(target, WRITE_FIX, always_path=True):
                        os.replace(pending / f"{name}.arrow", target)
            hashes.pending.clear()
            shutil.rmtree(failed_dir(sdir), ignore_errors=True)
        finally:
            if own:
                bar.close()
            shutil.rmtree(pending, ignore_errors=True)
        if is_identification(set(names)):
            runs.append(_write_product(sdir, all_stages, overrides, hashes, force))
    return runs


def _keep_failed(sdir: Path, names: list[str], written: set[str]) -> None:
    """Replace ``stages/failed/`` by the outputs this failed run wrote (if any)."""
    failed = failed_dir(sdir)
    shutil.rmtree(failed, ignore_errors=True)
    if written:
        failed.mkdir()
        for name in names:
            if name in written:
                os.replace(_pending_dir(sdir) / f"{name}.arrow", failed / f"{name}.arrow")


def _pointing_at_failed(exc: Exception, sdir: Path, written: set[str]) -> Exception:
    """``exc``, with advice that names ``stages/X.arrow`` of a stage this run rewrote
    pointing at ``stages/failed/X.arrow`` (``stages/X.arrow`` is the last good run's)."""
    msg = str(exc)
    new = msg
    for name in written:
        new = new.replace(f"stages/{name}.arrow", f"stages/{FAILED}/{name}.arrow")
    if new == msg or not isinstance(exc, ArmsigError):
        return exc
    return type(exc)(new)


def _write_product(
    sdir: Path,
    all_stages: list[Stage],
    overrides: Mapping[str, Mapping[str, Any]],
    hashes: _Hashes,
    force: bool,
) -> StageRun:
    """Write the signature from the committed stages unless a stage is stale (``--only``)
    or the file already matches them (and not ``force``)."""
    name, writer, _ = PRODUCT
    t0, c0 = time.perf_counter(), time.process_time()
    if any(st.state != "fresh" for st in _statuses(sdir, all_stages, overrides, hashes, False)):
        return StageRun(name, "not written", 0.0, 0)
    ident = {n: hashes.get(n) for n in hashes.identification()}
    with one_blas_thread():
        _, _, written = function_of(writer)(sdir, ident, force)
    action = "written" if written else "cached"
    return StageRun(name, action, time.perf_counter() - t0, -1, time.process_time() - c0)


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
    bar: Progress,
) -> None:
    """Bring each stage up to date in order, writing outputs to the pending folder."""
    stale: set[str] = set()
    forced_from = names.index(from_stage) if from_stage else None
    for k, stage in enumerate(all_stages):
        params = _params(stage, overrides)
        if k:
            bar.step()  # the stage before this one is done
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
        t0, c0 = time.perf_counter(), time.process_time()
        # Dependants compare their recorded input hash with the new one in `hashes`.
        table = _run_one(sdir, stage, params, hashes)
        return_freed()  # the stage's temporaries: not a floor under the next one's
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        runs.append(StageRun(stage.name, "ran", wall, table.num_rows, cpu))
    bar.step()


def one_blas_thread() -> threadpool_limits:
    """A context in which BLAS (OpenBLAS, MKL) runs on one thread. OpenBLAS's sums depend
    on its thread count: robot3's ``refine`` table differed in its last bits between 1 and
    2 threads, so a fleet worker or another machine would have written other content
    hashes. One thread was also faster: the refine stage took 0.69 s of CPU on robot3
    against 1.87 s with the default two (docs/refine.md)."""
    return threadpool_limits(1, user_api="blas")


def _run_one(sdir: Path, stage: Stage, params: Any, hashes: _Hashes) -> Any:
    inputs: dict[str, Any] = {}
    for inp in stage.inputs:
        if inp == RECORDING:
            inputs[inp] = read_recording(sdir / "recording.mcap", hashes.get(RECORDING))
        elif inp in FILE_INPUTS:
            inputs[inp] = _load_file_input(sdir, inp, hashes)
        elif inp == IMAGES:
            inputs[inp] = hashes.images()
        else:
            checked = hashes.check(inp)
            if checked is None or checked.table is None:
                why = (
                    "which has not run"
                    if checked is None
                    else f"whose file fails: {checked.problem}"
                )
                raise StageError(
                    f"{sdir}: stage '{stage.name}' needs '{inp}', {why}",
                    fix=f"run `pipeline identify {sdir}` without --only",
                )
            inputs[inp] = checked.table
    try:
        with one_blas_thread():
            table = stage.compute(inputs, params)
    except ArmsigError as exc:  # name the session and the stage, keep the cause's advice
        raise StageError(f"{sdir}: stage '{stage.name}': {exc}") from exc
    own = table.schema.metadata  # a stage's summary (e.g. refine's): kept through the cast
    table = validate_table(table, stage.name, source=f"{sdir}: stage '{stage.name}'")
    if own:
        table = table.replace_schema_metadata({**(table.schema.metadata or {}), **own})
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
    try:
        written = write_table(hashes.path(stage.name), table, provenance)
    except BaseException:  # not written: stages/failed/ must not look for it (issue 32)
        hashes.pending.discard(stage.name)
        raise
    hashes.put(stage.name, CheckedTable(written, provenance))
    return table
