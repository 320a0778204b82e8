"""Load the JSON schemas of ``schemas/`` and validate tables against them."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from functools import cache
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pipeline.errors import SchemaError

if TYPE_CHECKING:  # pyarrow where tables are made (a warm identify needs none: issue 18)
    import pyarrow as pa

UNITS = ("", "cm", "cm2", "deg", "s", "degF", "kg", "px")


@cache
def schema_dir() -> Path:
    """The schemas folder: ``pipeline/_schemas`` in a wheel, ``schemas/`` in a checkout."""
    packaged = resources.files("pipeline") / "_schemas"
    if packaged.is_dir():
        return Path(str(packaged))
    checkout = Path(__file__).resolve().parent.parent / "schemas"
    if checkout.is_dir():
        return checkout
    raise SchemaError(
        "schema folder not found",
        expected="pipeline/_schemas (installed) or schemas/ beside the package (checkout)",
        fix="reinstall armsig (`make install`)",
    )


def _read_json(path: Path) -> dict[str, Any]:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError as exc:
        raise SchemaError(f"no schema file {path}", fix="check the schema name") from exc
    except json.JSONDecodeError as exc:
        raise SchemaError(f"{path}: not valid JSON", got=str(exc)) from exc
    if not isinstance(data, dict):
        raise SchemaError(f"{path}: expected a JSON object", got=type(data).__name__)
    return data


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a JSON number")


def _finite_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(f"number {text} overflows")
    return value


_STRICT = json.JSONDecoder(parse_constant=_no_constant)
_STRICT_FINITE = json.JSONDecoder(parse_constant=_no_constant, parse_float=_finite_float)


def strict_json(text: str, *, finite: bool = False) -> Any:
    """Parse JSON as RFC 8259 defines it: ``NaN`` and ``Infinity``, which Python's parser
    accepts, raise ``ValueError``. With ``finite``, so do numbers that overflow to infinity
    (``1e999``); that costs a Python call per number, so the high-volume recording channels
    leave it to their range checks instead."""
    return (_STRICT_FINITE if finite else _STRICT).decode(text)


@cache
def compiled_validator(relative_path: str, detailed: bool = True) -> Callable[[Any], Any]:
    """``schemas/<relative_path>`` (a JSON Schema) compiled with fastjsonschema, once per
    process; the validator raises ``fastjsonschema.JsonSchemaValueException`` naming the
    field. ``detailed=False`` compiles a third of the code (~10 ms instead of ~30 ms for the
    signature schema) and still names the field, but fastjsonschema 2.22 cannot compile
    ``const`` that way (use a one-value ``enum``)."""
    import fastjsonschema

    schema = _read_json(schema_dir() / relative_path)
    return fastjsonschema.compile(schema, detailed_exceptions=detailed)  # type: ignore[no-any-return]


def expected_in_words(rule: str, definition: dict[str, Any]) -> str:
    """What a JSON Schema wanted, in words, from the failed ``rule`` of ``definition`` (a
    fastjsonschema ``JsonSchemaValueException``'s ``rule`` and ``definition``)."""
    if rule == "enum":
        return " | ".join(repr(v) for v in definition["enum"])
    if rule == "oneOf":
        options = definition["oneOf"]
        return definition.get("description") or " or ".join(o.get("type", "?") for o in options)
    if rule == "additionalProperties":
        keys = [*definition.get("properties", {}), *definition.get("patternProperties", {})]
        return "one of the keys " + ", ".join(keys)
    if rule == "required":
        return "the keys " + ", ".join(definition["required"])
    if rule == "pattern":
        return f"a string matching {definition['pattern']}"
    if rule in definition:
        return f"{rule} {definition[rule]!r}"
    return str(definition.get("type", rule))


def first_non_finite(value: Any, key: str = "") -> tuple[str, float] | None:
    """The first ``nan`` or ``inf`` in a parsed document (TOML has them; a schema's
    ``minimum`` lets ``nan`` through): its dotted key and value, else None."""
    if isinstance(value, float) and not math.isfinite(value):
        return key, value
    items = value.items() if isinstance(value, dict) else enumerate(value) if isinstance(
        value, list) else ()  # fmt: skip
    for k, v in items:
        sub = f"{key}[{k}]" if isinstance(k, int) else (f"{key}.{k}" if key else str(k))
        bad = first_non_finite(v, sub)
        if bad is not None:
            return bad
    return None


@cache
def mcap_json_schema(channel: str) -> dict[str, Any]:
    """JSON Schema of an MCAP channel's messages (``schemas/mcap/<channel>.json``)."""
    return _read_json(schema_dir() / "mcap" / f"{channel}.json")


@cache
def arrow_schema(name: str) -> pa.Schema:
    """Arrow schema of a table, with ``unit`` and ``description`` in each field's metadata."""
    import pyarrow as pa

    types = {
        "int32": pa.int32(),
        "int64": pa.int64(),
        "float64": pa.float64(),
        "bool": pa.bool_(),
        "string": pa.string(),
        "list<float64>": pa.list_(pa.float64()),
        "list<string>": pa.list_(pa.string()),
    }
    path = schema_dir() / "arrow" / f"{name}.json"
    doc = _read_json(path)
    fields = []
    for k, f in enumerate(doc.get("fields", [])):
        where = f"{path}: fields[{k}]"
        try:
            fname, ftype, unit = f["name"], f["type"], f["unit"]
        except KeyError as exc:
            raise SchemaError(f"{where}: missing key {exc}", expected="name, type, unit") from exc
        if ftype not in types:
            raise SchemaError(f"{where}: unknown type", expected=", ".join(types), got=repr(ftype))
        if unit not in UNITS:
            raise SchemaError(
                f"{where}: unknown unit", expected=", ".join(map(repr, UNITS)), got=repr(unit)
            )
        if unit and not fname.endswith("_" + unit):
            raise SchemaError(
                f"{where}: column '{fname}' carries unit '{unit}'"
                f" but its name does not end in '_{unit}'"
            )
        meta = {"unit": unit, "description": f.get("description", "")}
        fields.append(
            pa.field(fname, types[ftype], nullable=bool(f.get("nullable", False)), metadata=meta)
        )
    meta = {"schema_name": doc.get("name", name), "schema_version": str(doc.get("version", 1))}
    return pa.schema(fields, metadata=meta)


def arrow_table(
    name: str, columns: dict[str, Any], metadata: dict[bytes, bytes] | None = None
) -> pa.Table:
    """The table of schema ``name`` (:func:`arrow_schema`) holding ``columns`` (one array
    or list per field, by name), with ``metadata`` added to the schema's."""
    import pyarrow as pa

    schema = arrow_schema(name)
    if metadata:
        schema = schema.with_metadata({**(schema.metadata or {}), **metadata})
    return pa.table({f.name: pa.array(columns[f.name], f.type) for f in schema}, schema=schema)


def validate_table(table: pa.Table, name: str, source: str = "table") -> pa.Table:
    """Check a table against schema ``name`` and return it cast to that schema.

    Columns must match by name and order, types must be castable without loss,
    and non-nullable columns must hold no nulls.

    Raises
    ------
    SchemaError
        Naming the source, the column, what was expected and what arrived.
    """
    import pyarrow as pa

    schema = arrow_schema(name)
    if table.column_names != schema.names:
        raise SchemaError(
            f"{source}: columns do not match schema '{name}'",
            expected=str(schema.names),
            got=str(table.column_names),
        )
    for field in schema:
        col = table.column(field.name)
        if not field.nullable and col.null_count:
            raise SchemaError(
                f"{source}: column '{field.name}' has {col.null_count} nulls", expected="no nulls"
            )
    try:
        return table.cast(schema, safe=True)
    except (pa.ArrowInvalid, pa.ArrowNotImplementedError) as exc:
        raise SchemaError(f"{source}: cannot cast to schema '{name}'", got=str(exc)) from exc
