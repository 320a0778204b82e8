"""Stage tables are checked when read: edited, truncated, foreign, garbage provenance and
wrong-schema files make their stage stale (status says why) and a run recomputes them."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.ipc as ipc
import pytest

from pipeline.errors import StageError
from pipeline.identify import identify
from pipeline.signature.file import load_signature
from pipeline.stages.runner import run, stage_path, status
from pipeline.stages.tables import EDITED, content_hash, read_table


def _write(path: Path, table: pa.Table) -> None:
    with pa.OSFile(str(path), "wb") as fh, ipc.new_file(fh, table.schema) as writer:
        writer.write_table(table)


def _edit_value(path: Path, column: str, delta: float) -> None:
    """Change one number, keeping the provenance (as a user's pyarrow script would)."""
    table = read_table(path)
    values = table.column(column).to_numpy().copy()
    values[0] += delta
    k = table.schema.get_field_index(column)
    _write(path, table.set_column(k, table.schema.field(k), pa.array(values)))


def _garbage_provenance(path: Path) -> None:
    table = read_table(path)
    meta = dict(table.schema.metadata)
    meta[b"armsig.params"] = b"{not json"
    _write(path, table.replace_schema_metadata(meta))


def _other_schema(path: Path) -> None:
    """Drop a column and record the content hash of what is left: only the schema is off."""
    table = read_table(path)
    table = table.drop_columns([table.column_names[-1]])
    meta = dict(table.schema.metadata)
    meta[b"armsig.content_hash"] = json.dumps(content_hash(table)).encode()
    _write(path, table.replace_schema_metadata(meta))


CORRUPTIONS = {
    "edited": (lambda p: _edit_value(p, "px_cm", 0.5), EDITED),
    "truncated": (
        lambda p: p.write_bytes(p.read_bytes()[: p.stat().st_size // 2]),
        "not a readable",
    ),
    "foreign": (lambda p: p.write_text("joint,x_cm\n1,2\n"), "not a readable"),
    "garbage_provenance": (_garbage_provenance, "provenance metadata is not JSON"),
    "other_schema": (_other_schema, "columns differ from schemas/arrow/frames.json"),
}


def _links(sdir: Path) -> np.ndarray:
    return load_signature(sdir / "signature.json").chain.links


@pytest.mark.parametrize("case", CORRUPTIONS)
def test_corrupt_stage_is_stale_and_recomputed(
    identified_session: Path, tmp_path: Path, case: str
) -> None:
    d = shutil.copytree(identified_session, tmp_path / "s")
    corrupt, reason = CORRUPTIONS[case]
    corrupt(stage_path(d, "frames"))
    (d / "signature.json").unlink()  # rebuilt from the stage files
    st = {s.name: s for s in status(d)}
    assert st["frames"].state == "stale" and reason in st["frames"].reason
    assert st["smodel"].state == "stale" and st["signature"].state == "missing"
    assert {s.name for s in status(d) if s.state != "fresh"} == {
        "frames",
        "refine",
        "chain",
        "smodel",
        "dh",
        "uncertainty",
        "holdout",
        "verdict",
        "signature",
    }
    runs = {r.name: r.action for r in identify(d, report=False).runs}
    assert runs["frames"] == "ran" and runs["signature"] == "written"
    assert {s.state for s in status(d)} == {"fresh"}
    np.testing.assert_array_equal(_links(d), _links(identified_session))


def test_edited_smodel_then_from_smodel(identified_session: Path, tmp_path: Path) -> None:
    """Issue 13's case: smodel.arrow edited, then ``identify --from smodel``."""
    d = shutil.copytree(identified_session, tmp_path / "s")
    _edit_value(stage_path(d, "smodel"), "b_cm", 1.0)
    assert {s.name: s.reason for s in status(d)}["smodel"] == EDITED
    identify(d, from_stage="smodel", report=False)
    assert {s.state for s in status(d)} == {"fresh"}
    assert read_table(stage_path(d, "smodel")).equals(
        read_table(stage_path(identified_session, "smodel"))
    )
    np.testing.assert_array_equal(_links(d), _links(identified_session))


def test_only_refuses_a_corrupt_input(identified_session: Path, tmp_path: Path) -> None:
    d = shutil.copytree(identified_session, tmp_path / "s")
    _edit_value(stage_path(d, "positions"), "x_cm", 0.5)
    before = stage_path(d, "features").read_bytes()
    with pytest.raises(StageError, match="needs 'positions', whose file fails") as exc:
        run(d, only="features")
    assert "\n" not in str(exc.value) and "without --only" in str(exc.value)
    assert stage_path(d, "features").read_bytes() == before


def test_a_good_input_serves_only(identified_session: Path, tmp_path: Path) -> None:
    d = shutil.copytree(identified_session, tmp_path / "s")
    assert {r.name: r.action for r in run(d, only="features")}["features"] == "ran"


def test_a_warm_run_vouches_for_no_file(identified_session: Path, tmp_path: Path) -> None:
    """Every read checks a stage file's data as it is now: after a warm run found it fresh,
    a value edited in place (same size, same modification time) is stale."""
    d = shutil.copytree(identified_session, tmp_path / "s")
    path = stage_path(d, "frames")
    _write(path, read_table(path))  # uncompressed: other bytes, the same data
    assert {r.action for r in run(d)} == {"cached"}
    before = path.stat()
    _edit_value(path, "px_cm", 0.5)
    os.utime(path, ns=(before.st_atime_ns, before.st_mtime_ns))
    assert path.stat().st_size == before.st_size
    assert {s.name: s.reason for s in status(d)}["frames"] == EDITED
