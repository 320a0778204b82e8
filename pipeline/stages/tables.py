"""Arrow IPC files of stage outputs: atomic writes, provenance metadata, content hashes,
and the check that a file read back is the one that was written."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.ipc as ipc

from pipeline.atomic import atomic_write, write_text_atomic
from pipeline.errors import StageError
from pipeline.schemas import arrow_schema

META_PREFIX = "armsig."
#: Stage files are written zstd-compressed (~5x smaller, ~2 ms more per read); files written
#: uncompressed before still read, and the content hash does not depend on it.
WRITE_OPTIONS = ipc.IpcWriteOptions(compression="zstd")
#: Why a stage file whose data no longer hashes to its recorded content hash is stale.
EDITED = "file differs from the hash recorded when it was written (edited or corrupt)"
#: File in ``stages/`` naming the SHA-256 of the bytes of each stage file that passed its
#: full check (or was written by armsig): a file with those very bytes is the same file,
#: so its next check skips re-hashing its data (see :func:`check_table`).
VERIFIED = ".verified.json"


def content_hash(table: pa.Table) -> str:
    """SHA-256 of the table's data and column types (schema metadata excluded).

    The table is re-serialized uncompressed here, so the hash is the same whether the file
    it came from was compressed or not."""
    bare = table.replace_schema_metadata(None)
    bare = pa.Table.from_batches(
        bare.to_batches(), schema=pa.schema([f.remove_metadata() for f in bare.schema])
    )
    sink = pa.BufferOutputStream()
    with ipc.new_stream(sink, bare.schema, options=ipc.IpcWriteOptions()) as writer:
        writer.write_table(bare)
    return hashlib.sha256(sink.getvalue().to_pybytes()).hexdigest()


def write_table(path: Path, table: pa.Table, provenance: dict[str, Any]) -> pa.Table:
    """Write ``table`` to ``path`` atomically with ``provenance`` in its schema metadata."""
    return write_checked(path, table, provenance).table  # type: ignore[return-value]


def write_checked(path: Path, table: pa.Table, provenance: dict[str, Any]) -> CheckedTable:
    """:func:`write_table`, returning the table as written with the SHA-256 of the file's
    bytes (:attr:`CheckedTable.file_sha256`)."""
    meta = dict(table.schema.metadata or {})
    for key, value in provenance.items():
        meta[(META_PREFIX + key).encode()] = json.dumps(value, sort_keys=True).encode()
    out = table.replace_schema_metadata(meta)
    sink = pa.BufferOutputStream()
    with ipc.new_file(sink, out.schema, options=WRITE_OPTIONS) as writer:
        writer.write_table(out)
    data = sink.getvalue().to_pybytes()
    with atomic_write(path, "wb") as fh:
        fh.write(data)
    return CheckedTable(out, provenance, "", hashlib.sha256(data).hexdigest())


def _provenance(schema: pa.Schema, path: Path) -> dict[str, Any]:
    out = {}
    for k, v in (schema.metadata or {}).items():
        key = k.decode("utf-8", "replace")
        if key.startswith(META_PREFIX):
            try:
                out[key[len(META_PREFIX) :]] = json.loads(v)
            except ValueError as exc:  # JSONDecodeError and UnicodeDecodeError
                raise StageError(
                    f"{path}: provenance '{key}' is not JSON",
                    got=str(exc),
                    fix="rerun with --force",
                ) from exc
    return out


def read_provenance(path: Path) -> dict[str, Any]:
    """The ``armsig.*`` metadata of a stage file (reads the footer only)."""
    try:
        with pa.OSFile(str(path), "rb") as source:
            schema = ipc.open_file(source).schema
    except (pa.ArrowInvalid, OSError) as exc:
        raise StageError(
            f"{path}: unreadable stage file", got=str(exc), fix="rerun with --force"
        ) from exc
    return _provenance(schema, path)


def read_table(path: Path) -> pa.Table:
    """Read a whole stage file."""
    try:
        with pa.OSFile(str(path), "rb") as source:
            return ipc.open_file(source).read_all()
    except (pa.ArrowInvalid, OSError) as exc:
        raise StageError(
            f"{path}: unreadable stage file", got=str(exc), fix="rerun with --force"
        ) from exc


class CheckedTable:
    """A stage file read back and checked. ``problem`` is empty when the file is the one
    that was written: readable, provenance JSON, columns of its schema, data hashing to
    its recorded ``content_hash``; otherwise it says why not (and ``table`` is None).

    ``file_sha256``: SHA-256 of the file's bytes ("" when unknown or failing). A file
    known by those bytes keeps them (``data``) and decodes its table when first asked."""

    def __init__(
        self,
        table: pa.Table | None,
        provenance: dict[str, Any] | None = None,
        problem: str = "",
        file_sha256: str = "",
        data: bytes | None = None,
    ) -> None:
        self._table = table
        self.provenance = {} if provenance is None else provenance
        self.problem = problem
        self.file_sha256 = file_sha256
        self._data = data

    @property
    def table(self) -> pa.Table | None:
        if self._table is None and self._data is not None:
            with ipc.open_file(pa.py_buffer(self._data)) as reader:
                self._table = reader.read_all()
            self._data = None
        return self._table


def _columns(schema: pa.Schema) -> list[tuple[str, pa.DataType, bool, bytes | None]]:
    return [(f.name, f.type, f.nullable, (f.metadata or {}).get(b"unit")) for f in schema]


def check_table(path: Path, name: str, verified_sha256: str | None = None) -> CheckedTable:
    """Read stage ``name``'s file and check it against its schema and its recorded hash.

    ``verified_sha256``: the SHA-256 of the bytes of this file when it last passed this
    check (:data:`VERIFIED`). A file with exactly those bytes is not re-hashed (the costly
    part of a check: ~4 ms a table); every other file gets the full check.
    """
    try:
        data = path.read_bytes()
        digest = hashlib.sha256(data).hexdigest()
        known = digest == verified_sha256
        with ipc.open_file(pa.py_buffer(data)) as reader:
            table = None if known else reader.read_all()  # known: decoded when asked
            schema = reader.schema
        if table is not None:
            table.validate(full=True)  # before hashing: corrupt buffers must not be touched
    except (OSError, pa.ArrowInvalid):
        return CheckedTable(None, {}, "not a readable Arrow file (truncated, corrupt or foreign)")
    try:
        prov = _provenance(schema, path)
    except StageError:
        return CheckedTable(None, {}, "its provenance metadata is not JSON (corrupt)")
    if _columns(schema) != _columns(arrow_schema(name)):
        return CheckedTable(None, prov, f"columns differ from schemas/arrow/{name}.json")
    if "content_hash" not in prov:
        return CheckedTable(None, prov, "no content hash recorded (not written by armsig)")
    if table is not None and content_hash(table) != prov["content_hash"]:
        return CheckedTable(None, prov, EDITED)
    return CheckedTable(table, prov, "", digest, data if known else None)


def read_verified(stages_dir: Path) -> dict[str, str]:
    """The :data:`VERIFIED` record of a ``stages/`` folder ({} when absent or unreadable:
    every file then gets the full check)."""
    try:
        doc = json.loads((stages_dir / VERIFIED).read_text())
    except (OSError, ValueError):
        return {}
    if not isinstance(doc, dict):
        return {}
    return {k: v for k, v in doc.items() if isinstance(k, str) and isinstance(v, str)}


def write_verified(stages_dir: Path, verified: dict[str, str]) -> None:
    """Replace the :data:`VERIFIED` record unless it already says ``verified``."""
    if read_verified(stages_dir) != verified:
        write_text_atomic(stages_dir / VERIFIED, json.dumps(verified, indent=1, sort_keys=True))
