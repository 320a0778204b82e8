"""YAML read strictly: PyYAML's safe loader that refuses a key given twice in a mapping,
any alias and nesting deeper than :data:`MAX_DEPTH`.

A repeated key would otherwise replace the earlier value silently (robot_cal_tools' time
keys: a measurement lost); aliases let a few hundred bytes expand to billions of values
(a "billion laughs" hung ``import`` while memory grew), and deep nesting ends in a
RecursionError (issue 32). Measurement files need neither. Refusals are one line naming
the file, the line and what was found; the document itself is never formatted into the
message.
"""

from __future__ import annotations

from typing import Any

import yaml

from pipeline.errors import ImportFileError, one_line

#: Characters of PyYAML's own parse error shown in a refusal.
_SHOWN = 200
#: Deepest nesting of sequences and mappings taken: robot_cal_tools' entries nest 3 deep
#: (entry, pose, value); Python's recursion limit (1,000 frames) is far above 64.
MAX_DEPTH = 64


class _Refused(Exception):
    """Raised inside the loader; :func:`load_yaml` turns it into an ImportFileError."""

    def __init__(self, what: str, mark: yaml.Mark | None, expected: str, fix: str) -> None:
        super().__init__(what)
        self.what, self.line, self.expected, self.fix = what, mark, expected, fix


class _StrictLoader(yaml.SafeLoader):
    _depth = 0

    def compose_node(self, parent: yaml.Node | None, index: Any) -> yaml.Node | None:
        if self.check_event(yaml.AliasEvent):  # type: ignore[no-untyped-call]
            mark = self.peek_event().start_mark  # type: ignore[no-untyped-call]
            raise _Refused("an alias (*name)", mark, "plain values: aliases are not read",
                           "write the values out in full")  # fmt: skip
        self._depth += 1
        try:
            if self._depth > MAX_DEPTH:
                mark = self.peek_event().start_mark  # type: ignore[no-untyped-call]
                raise _Refused(f"nested deeper than {MAX_DEPTH} levels", mark,
                               f"at most {MAX_DEPTH} nested sequences and mappings",
                               "check the file: a measurement file nests a few levels")  # fmt: skip
            return super().compose_node(parent, index)  # type: ignore[no-untyped-call,no-any-return]
        finally:
            self._depth -= 1

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        seen: set[Any] = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)  # type: ignore[no-untyped-call]
            try:
                twice = key in seen
                seen.add(key)
            except TypeError:  # an unhashable key: PyYAML's own error follows
                continue
            if twice:
                shown = one_line(repr(key), 60)
                raise _Refused(f"key {shown} appears twice", key_node.start_mark,
                               "each key once in a mapping (a repeated key would replace "
                               "the earlier value)", "delete or rename one of the two")  # fmt: skip
        return super().construct_mapping(node, deep)  # type: ignore[no-untyped-call,no-any-return]


def load_yaml(text: str, src: str) -> Any:
    """The YAML document ``text`` (of file ``src``) as Python values, strictly (module doc)."""
    try:
        return yaml.load(text, Loader=_StrictLoader)  # noqa: S506 (a SafeLoader subclass)
    except _Refused as exc:
        at = "" if exc.line is None else f" line {exc.line.line + 1}:"
        raise ImportFileError(
            f"{src}:{at} {exc.what}", expected=exc.expected, fix=exc.fix
        ) from None
    except yaml.YAMLError as exc:
        raise ImportFileError(f"{src}: not valid YAML", got=one_line(str(exc), _SHOWN)) from None
