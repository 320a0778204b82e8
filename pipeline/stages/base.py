"""The stage contract: a name, a version, inputs, frozen parameters, one output schema.

A stage's ``compute`` is a pure function of its inputs (stage tables, or the
parsed recording for the extract stages) and its parameters.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import pyarrow as pa

RECORDING = "recording"


@dataclass(frozen=True)
class NoParams:
    """For stages without parameters."""


@dataclass(frozen=True)
class Stage:
    """One pipeline stage.

    Attributes
    ----------
    name : str
        Output file ``stages/<name>.arrow``; also the schema name in ``schemas/arrow``.
    version : int
        Bump when the computation changes: cached outputs become stale.
    inputs : tuple of str
        ``"recording"`` or names of earlier stages.
    params : frozen dataclass instance
        Default parameters.
    compute : callable
        ``compute(inputs, params) -> pa.Table``.
    summary : str
        One line for ``pipeline status``.
    """

    name: str
    version: int
    inputs: tuple[str, ...]
    params: Any
    compute: Callable[[Mapping[str, Any], Any], pa.Table]
    summary: str

    def params_dict(self, params: Any | None = None) -> dict[str, Any]:
        return dataclasses.asdict(params if params is not None else self.params)
