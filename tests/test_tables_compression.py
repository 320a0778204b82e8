"""Stage tables are written zstd-compressed; the content hash does not depend on it and
stage files written uncompressed (before compression) still read and count as fresh."""

from __future__ import annotations

import shutil
from pathlib import Path

import pyarrow as pa
import pyarrow.ipc as ipc
import pytest

from pipeline.stages.runner import stage_path, status
from pipeline.stages.tables import check_table, content_hash, read_table, write_table


def _compressed(path: Path) -> bool:
    """Whether the file is smaller than its table written uncompressed (pyarrow does not
    expose a file's codec; zstd shrinks these tables 1.8 to 9 times)."""
    table = read_table(path)
    plain = pa.BufferOutputStream()
    with ipc.new_file(plain, table.schema) as writer:
        writer.write_table(table)
    return path.stat().st_size < 0.9 * plain.getvalue().size


def _rewrite_uncompressed(path: Path) -> None:
    """The stage file as armsig wrote it before compression: same table and provenance."""
    table = read_table(path)
    with pa.OSFile(str(path), "wb") as fh, ipc.new_file(fh, table.schema) as writer:
        writer.write_table(table)


def test_hash_independent_of_compression(tmp_path: Path) -> None:
    n = 5000
    table = pa.table({"x_cm": pa.array([float(i % 7) for i in range(n)]), "k": list(range(n))})
    write_table(tmp_path / "z.arrow", table, {"content_hash": content_hash(table)})
    with pa.OSFile(str(tmp_path / "p.arrow"), "wb") as fh, ipc.new_file(fh, table.schema) as writer:
        writer.write_table(table)
    zipped, plain = read_table(tmp_path / "z.arrow"), read_table(tmp_path / "p.arrow")
    assert zipped.replace_schema_metadata(None).equals(plain)
    assert content_hash(zipped) == content_hash(plain) == content_hash(table)
    assert (tmp_path / "z.arrow").stat().st_size * 3 < (tmp_path / "p.arrow").stat().st_size


def test_stage_files_are_compressed(identified_session: Path) -> None:
    for name in ("ranges", "compensate"):
        assert _compressed(stage_path(identified_session, name)), name


@pytest.mark.parametrize("name", ["ranges", "frames", "smodel"])
def test_uncompressed_stage_file_still_fresh(
    identified_session: Path, tmp_path: Path, name: str
) -> None:
    d = tmp_path / "s"
    shutil.copytree(identified_session, d)
    path = stage_path(d, name)
    before = read_table(path)
    _rewrite_uncompressed(path)
    assert not _compressed(path)
    checked = check_table(path, name)
    assert checked.problem == ""
    assert checked.table is not None and checked.table.equals(before)
    assert {s.name: s.state for s in status(d)}[name] == "fresh"
