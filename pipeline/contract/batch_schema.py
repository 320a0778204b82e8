"""Whether every message of a channel is valid against its JSON Schema, column-wise.

The high-volume channels (thousands of ``/sonic/ranges`` cycles) are too many to
validate one at a time at the pipeline's speed budget, so :func:`all_valid` checks
a whole channel at once with numpy, reading its rules from the schema file. It
knows the keywords the schemas of ``schemas/mcap/`` use on such channels and is
strict where it is unsure (an ``integer`` must be a Python int, not 1.0; an unknown
keyword fails). ``True`` therefore means every message is valid; ``False`` means the
caller validates message by message with the compiled schema, which names the
first invalid field (or finds them valid after all, when only the strictness here
failed them).
"""

from __future__ import annotations

from collections.abc import Sequence
from itertools import chain
from typing import Any

import numpy as np

_ANNOTATIONS = {"$schema", "title", "description"}
_ABSENT = object()
_NUMBER = {int, float}
_WITH_TYPE = {"minimum", "maximum", "exclusiveMinimum", "items", "minItems", "maxItems"}


def all_valid(schema: dict[str, Any], values: Sequence[Any]) -> bool:
    """Whether every value of ``values`` is valid against ``schema`` (see module doc)."""
    return bool(_mask(schema, values).all())


def _mask(schema: dict[str, Any], values: Sequence[Any]) -> np.ndarray:
    """Per value: certainly valid against ``schema``."""
    ok = np.ones(len(values), bool)
    for key, rule in schema.items():
        if key in _ANNOTATIONS or key in _WITH_TYPE:
            continue
        if key == "type":
            ok &= _typed(schema, rule, values)
        elif key == "enum" or key == "const":
            allowed = rule if key == "enum" else [rule]
            if not all(isinstance(a, str) for a in allowed):
                return np.zeros(len(values), bool)
            ok &= np.fromiter((type(v) is str and v in allowed for v in values), bool, len(values))
        elif key == "oneOf":
            hits = sum(_mask(branch, values).astype(int) for branch in rule)
            ok &= hits == 1
        elif key == "required" or key == "properties":
            ok &= (
                _members(schema, values)
                if key == "properties" or "properties" not in schema
                else True
            )
        else:
            return np.zeros(len(values), bool)  # a keyword this module does not know
    return ok


def _members(schema: dict[str, Any], values: Sequence[Any]) -> np.ndarray:
    """Per value: an object holding the required members, each member valid."""
    ok = _of_types(values, {dict})
    dicts = values if ok.all() else [v if type(v) is dict else {} for v in values]
    props = schema.get("properties", {})
    for name in dict.fromkeys([*schema.get("required", ()), *props]):
        col = [d.get(name, _ABSENT) for d in dicts]
        if _ABSENT in col:
            present = np.fromiter((c is not _ABSENT for c in col), bool, len(col))
            if name in schema.get("required", ()):
                ok &= present
            col = [c for c in col if c is not _ABSENT]
        else:
            present = np.ones(len(col), bool)
        if name in props:
            inner = np.ones(len(dicts), bool)
            inner[present] = _mask(props[name], col)
            ok &= inner
    return ok


def _of_types(values: Sequence[Any], allowed: set[type]) -> np.ndarray:
    """Per value: its Python type is one of ``allowed`` (bool is not int)."""
    if set(map(type, values)) <= allowed:  # the common case, at C speed
        return np.ones(len(values), bool)
    return np.fromiter((type(v) in allowed for v in values), bool, len(values))


def _typed(schema: dict[str, Any], rule: str | list[str], values: Sequence[Any]) -> np.ndarray:
    types = {rule} if isinstance(rule, str) else set(rule)
    n = len(values)
    if types == {"object"}:
        return _of_types(values, {dict})
    if types == {"array"}:
        return _array(schema, values)
    allowed: set[type] = set()
    if "null" in types:
        allowed.add(type(None))
    if "number" in types:
        allowed |= _NUMBER
    if "integer" in types:
        allowed.add(int)
    if "string" in types:
        allowed.add(str)
    if types - {"null", "number", "integer", "string"}:
        return np.zeros(n, bool)
    ok = _of_types(values, allowed)
    bounds = [k for k in ("minimum", "maximum", "exclusiveMinimum") if k in schema]
    if not bounds:
        return ok
    if not allowed & _NUMBER:
        return np.zeros(n, bool)
    # Numbers as floats, anything else (null, a string) as NaN, which no bound passes.
    try:
        num = np.array(
            values
            if ok.all() and str not in allowed
            else [v if type(v) in _NUMBER else None for v in values],
            float,
        ).reshape(n)
    except OverflowError:  # an integer beyond float
        return np.zeros(n, bool)
    within = np.ones(n, bool)
    if "minimum" in schema:
        within &= num >= schema["minimum"]
    if "maximum" in schema:
        within &= num <= schema["maximum"]
    if "exclusiveMinimum" in schema:
        within &= num > schema["exclusiveMinimum"]
    # NaN stands for a value of another type (null, a string), which carries no bound;
    # a NaN number cannot arrive: the JSON decoder refuses it.
    return ok & (within | np.isnan(num))


def _array(schema: dict[str, Any], values: Sequence[Any]) -> np.ndarray:
    n = len(values)
    ok = _of_types(values, {list})
    lists = values if ok.all() else [v if type(v) is list else [] for v in values]
    lengths = np.fromiter(map(len, lists), np.int64, n)
    ok &= lengths >= schema.get("minItems", 0)
    if "maxItems" in schema:
        ok &= lengths <= schema["maxItems"]
    if "items" in schema:
        flat = list(chain.from_iterable(lists))
        bad = np.r_[0, np.cumsum(~_mask(schema["items"], flat))]
        ends = np.cumsum(lengths)
        ok &= bad[ends] - bad[ends - lengths] == 0
    return ok
