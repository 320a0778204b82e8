"""Arrow IPC files of stage outputs: atomic writes, provenance metadata, content hashes."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.ipc as ipc

from pipeline.atomic import atomic_write
from pipeline.errors import StageError

META_PREFIX = "armsig."


def content_hash(table: pa.Table) -> str:
    """SHA-256 of the table's data and column types (schema metadata excluded)."""
    bare = table.replace_schema_metadata(None)
    bare = pa.Table.from_batches(
        bare.to_batches(), schema=pa.schema([f.remove_metadata() for f in bare.schema])
    )
    sink = pa.BufferOutputStream()
    with ipc.new_stream(sink, bare.schema) as writer:
        writer.write_table(bare)
    return hashlib.sha256(sink.getvalue().to_pybytes()).hexdigest()


def write_table(path: Path, table: pa.Table, provenance: dict[str, Any]) -> pa.Table:
    """Write ``table`` to ``path`` atomically with ``provenance`` in its schema metadata."""
    meta = dict(table.schema.metadata or {})
    for key, value in provenance.items():
        meta[(META_PREFIX + key).encode()] = json.dumps(value, sort_keys=True).encode()
    out = table.replace_schema_metadata(meta)
    with atomic_write(path, "wb") as fh:
        with ipc.new_file(fh, out.schema) as writer:
            writer.write_table(out)
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
    meta = schema.metadata or {}
    out = {}
    for k, v in meta.items():
        key = k.decode()
        if key.startswith(META_PREFIX):
            out[key[len(META_PREFIX) :]] = json.loads(v)
    return out


def read_table(path: Path) -> pa.Table:
    """Read a whole stage file."""
    try:
        with pa.OSFile(str(path), "rb") as source:
            return ipc.open_file(source).read_all()
    except (pa.ArrowInvalid, OSError) as exc:
        raise StageError(
            f"{path}: unreadable stage file", got=str(exc), fix="rerun with --force"
        ) from exc
