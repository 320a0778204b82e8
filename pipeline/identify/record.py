"""The record of a session's last complete ``identify``: a warm run that finds nothing
changed answers from it, without the stage modules, numpy or pyarrow (issue 18).

Every stage is a pure function of its inputs, its version and its parameters, and the
signature and the report are functions of the stage tables. So a plain identify (no
``--force``, ``--from``, ``--only`` or ``--param``) of a session folder whose every
file holds the same bytes as when the last complete run ended, run by the same armsig
code, would find every stage, the signature and the report fresh and change nothing.
That run leaves ``stages/.identified.json``: a digest of the folder (every file's
path and SHA-256, every folder's path), a digest of the code (the path, size and
modification time of every file of the ``pipeline`` package and of the schemas, as
Python's own bytecode cache decides whether a module changed; the same of the
libraries' ``__init__`` files and the interpreter's version), and what a warm run
returns: the stage names, the signature's warnings and the verdict line, with their
SHA-256 (a record changed since it was written is no record).

A warm run that computes the same two digests returns that, every stage ``cached``.
Anything else misses and gets the runner's full check: a byte changed, a file added
or removed (the debris of a killed run too), a folder reached through a symbolic link,
other code, another option, a record that is missing, unreadable, edited or of another
format. The record is read and written under the session lock, and written atomically.
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import os
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from pipeline.atomic import write_text_atomic
from pipeline.contract.digest import file_sha256
from pipeline.errors import ArmsigError
from pipeline.stages.base import StageRun
from pipeline.stages.lock import LOCK_NAME

RECORD = Path("stages") / ".identified.json"
FORMAT = 1
#: The libraries a run computes and checks with: an upgrade (pip rewrites a package's
#: files) means a full check, as a new interpreter does.
LIBRARIES = ("numpy", "scipy", "pyarrow", "mcap", "zstandard", "fastjsonschema", "matplotlib")
#: What a warm run replays: every stage, then the signature, ``cached``.
CACHED = "cached"


class _Linked(Exception):
    """A folder reached through a symbolic link: its files are not walked, so a folder
    holding one has no record."""


def _files(root: Path, skip: set[Path]) -> Iterator[tuple[str, Path | None]]:
    """Every folder (path, None) and file (path, full path) under ``root``, sorted,
    paths relative to ``root``; ``__pycache__`` folders and ``skip`` are left out.
    Raises :class:`_Linked` at a folder that is a symbolic link."""
    for folder, dirs, names in os.walk(root):
        here = Path(folder)
        if any((here / d).is_symlink() for d in dirs):
            raise _Linked(here)
        dirs[:] = sorted(d for d in dirs if d != "__pycache__")
        yield str(here.relative_to(root)), None
        for name in sorted(names):
            path = here / name
            if path.relative_to(root) not in skip:
                yield str(path.relative_to(root)), path


def session_digest(sdir: Path) -> str:
    """SHA-256 over every file's path and bytes and every folder's path in the session
    folder, but the lock file and the record itself."""
    h = hashlib.sha256()
    for rel, path in _files(sdir, {Path(LOCK_NAME), RECORD}):
        h.update(f"{rel}\0".encode())
        if path is not None:
            h.update(file_sha256(path).encode())
    return h.hexdigest()


def _stamp(path: Path) -> str:
    """A file's size and modification time (ns): what Python's bytecode cache compares."""
    st = path.stat()
    return f"{st.st_size} {st.st_mtime_ns}"


def code_digest(roots: tuple[Path, ...] | None = None) -> str:
    """SHA-256 over the path, size and modification time (ns) of every file under
    ``roots`` (default: the ``pipeline`` package and the schemas folder, which a
    checkout keeps beside the package)."""
    if roots is None:
        from pipeline.schemas import schema_dir

        roots = tuple(dict.fromkeys((Path(__file__).resolve().parents[1], schema_dir())))
    h = hashlib.sha256()
    for root in roots:
        for rel, path in _files(root, set()):
            stamp = "" if path is None else _stamp(path)
            h.update(f"{root}\0{rel}\0{stamp}\0".encode())
    return h.hexdigest()


def library_stamps() -> list[str]:
    """The interpreter's version and path, and the path, size and modification time (ns)
    of each of :data:`LIBRARIES`' ``__init__`` file (found, not imported)."""
    stamps = [sys.version, sys.executable]
    for name in LIBRARIES:
        spec = importlib.util.find_spec(name)
        origin = None if spec is None else spec.origin
        stamps.append(f"{name} {origin} {'' if origin is None else _stamp(Path(origin))}")
    return stamps


def _key(sdir: Path, report: bool) -> dict[str, Any] | None:
    """What the record must match; None when the folder cannot have one."""
    try:
        return {
            "format": FORMAT,
            "report": report,
            "code": code_digest(),
            "libraries": library_stamps(),
            "session": session_digest(sdir),
        }
    except _Linked:
        return None


def _digest(payload: dict[str, Any]) -> str:
    return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()


def recall(sdir: Path, report: bool) -> dict[str, Any] | None:
    """What the last complete run of ``sdir`` returned, when the folder and the code are
    as it left them (call under the session lock); else None."""
    try:
        doc = json.loads((sdir / RECORD).read_text())
    except (OSError, ValueError):  # none, unreadable or not JSON: a miss
        return None
    if not isinstance(doc, dict) or not isinstance(doc.get("run"), dict):
        return None
    key = _key(sdir, report)
    if key is None or doc.get("key") != key or doc.get("digest") != _digest(doc["run"]):
        return None  # another folder, other code, or a record changed since written
    return doc["run"]  # type: ignore[no-any-return]


def remember(
    sdir: Path,
    report: bool,
    stages: list[str],
    signature: str,
    report_path: str | None,
    warnings: list[str],
    verdict: str | None,
) -> None:
    """Write the record of a complete plain run of ``sdir`` (under the session lock,
    after everything it writes): the paths are relative to ``sdir``."""
    key = _key(sdir, report)
    if key is None:
        return
    run = {
        "stages": stages,
        "signature": signature,
        "report": report_path,
        "warnings": warnings,
        "verdict": verdict,
    }
    doc = {"key": key, "run": run, "digest": _digest(run)}
    try:
        write_text_atomic(sdir / RECORD, json.dumps(doc, indent=1))
    except ArmsigError:  # the write's OSError, one line (e.g. a read-only stages folder, the
        pass  # record's name taken by a folder): a cache, so warm runs get the full check


def replay(run: dict[str, Any]) -> list[StageRun]:
    """The stage runs of a warm run: every stage of the record, then the signature,
    ``cached``."""
    return [StageRun(name, CACHED, 0.0, -1) for name in run["stages"]]
