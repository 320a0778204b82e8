"""Schema loader: units in names and metadata, validation errors."""

import json

import pyarrow as pa
import pytest

from pipeline import schemas
from pipeline.errors import SchemaError


@pytest.mark.parametrize(
    "name", sorted(p.stem for p in (schemas.schema_dir() / "arrow").glob("*.json"))
)
def test_every_arrow_schema_loads_with_units(name) -> None:
    s = schemas.arrow_schema(name)
    for f in s:
        unit = f.metadata[b"unit"].decode()
        assert unit in schemas.UNITS
        assert not unit or f.name.endswith("_" + unit)
        assert f.metadata[b"description"]


@pytest.mark.parametrize(
    "name", sorted(p.stem for p in (schemas.schema_dir() / "mcap").glob("*.json"))
)
def test_every_mcap_schema_is_json_schema(name) -> None:
    doc = schemas.mcap_json_schema(name)
    assert doc["type"] == "object" and "properties" in doc and "$schema" in doc
    json.dumps(doc)


def _joint_states(**overrides):
    cols = {
        "sweep": [1],
        "step": [0],
        "joint": [1],
        "q_cmd_deg": [10.0],
        "q_deg": [10.0],
        "q_cmd_cm": [None],
        "q_cm": [None],
        "t_s": [0.5],
        "payload_kg": pa.array([None], pa.float64()),
        "source_file": pa.array([None], pa.string()),
        "source_line": pa.array([None], pa.int32()),
        "tracker_drift_cm": pa.array([None], pa.float64()),
        "tracker_residual_cm": pa.array([None], pa.float64()),
    }
    cols.update(overrides)
    return pa.table(cols)


def test_validate_casts_and_checks() -> None:
    t = schemas.validate_table(_joint_states(), "joints")
    assert t.schema.field("q_deg").metadata[b"unit"] == b"deg"
    assert t.schema.field("sweep").type == pa.int32()


def test_validate_rejects_mismatch() -> None:
    with pytest.raises(SchemaError, match="columns do not match"):
        schemas.validate_table(_joint_states().drop(["t_s"]), "joints")
    with pytest.raises(SchemaError, match="nulls"):
        schemas.validate_table(_joint_states(t_s=[None]), "joints")
    with pytest.raises(SchemaError, match="cannot cast"):
        schemas.validate_table(_joint_states(sweep=["one"]), "joints")
    with pytest.raises(SchemaError, match="no schema file"):
        schemas.arrow_schema("no_such_table")
