"""The ``/points/block`` channel: a sweep's configurations as binary columns (issue 45).

One message (``schemas/mcap/points_block.json``) carries up to :data:`BLOCK_ROWS`
consecutive steps of one sweep: what ``/robot/joint_state`` and ``/points`` carry one
message per configuration and target, as little-endian C-order arrays, base64 in the
JSON envelope. JSON number arrays are too slow for a million rows (9 columns of a million
floats: 4.0 s to dump, 1.7 s to load); base64 round-trips every float64 bit for bit and
decodes at numpy speed. :func:`block_payload` writes a block, :func:`block_columns` reads
one back, each column's dtype and length checked (one line naming the column).
"""

from __future__ import annotations

import binascii
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.errors import RecordingError

BLOCK_TOPIC = "/points/block"
JOINT_TOPIC, POINT_TOPIC = "/robot/joint_state", "/points"
BLOCK_SCHEMA = "points_block"
#: Rows per block: 65,536 rows of a 6-joint, 1-target block with σ are a 9.8 MB message, far
#: under the reader's 256 MiB chunk bound, and a million rows are 16 messages; wider rows
#: (many targets) are fewer a block, at most :data:`BLOCK_BYTES` of columns.
BLOCK_ROWS = 1 << 16
BLOCK_BYTES = 1 << 25
_FIX = "repair the rig's writer; the schema is the contract (schemas/mcap/points_block.json)"


@dataclass(frozen=True)
class Column:
    """A column's dtype (little-endian) and its shape after the rows: ``J`` joints, ``T``
    targets, or a number."""

    dtype: str
    shape: tuple[str | int, ...]


COLUMNS = {
    "dt_ns": Column("<i8", ()),
    "q_commanded": Column("<f8", ("J",)),
    "q_encoder": Column("<f8", ("J",)),
    "points_cm": Column("<f8", ("T", 3)),
    "sigma_cm": Column("<f8", ("T", 3)),
    "orientation_wxyz": Column("<f8", (4,)),
    "payload_kg": Column("<f8", ()),
    "source_file": Column("<i4", ()),
    "source_line": Column("<i8", ()),
    "tracker_drift_cm": Column("<f8", ()),
    "tracker_residual_cm": Column("<f8", ()),
}


def rows_per_block(columns: dict[str, np.ndarray]) -> int:
    """How many rows of ``columns`` (rows first) a block takes: :data:`BLOCK_ROWS`, fewer
    when they would hold more than :data:`BLOCK_BYTES`."""
    row = sum(a[:1].nbytes for a in columns.values())
    return max(1, min(BLOCK_ROWS, BLOCK_BYTES // max(row, 1)))


def _encoded(values: np.ndarray, col: Column) -> str:
    return binascii.b2a_base64(np.ascontiguousarray(values, col.dtype).data, newline=False).decode(
        "ascii"
    )


def block_payload(
    sweep: str | int,
    first_step: int,
    units: list[str],
    targets: list[str],
    columns: dict[str, np.ndarray],
    **fields: Any,
) -> dict[str, Any]:
    """A ``/points/block`` message: ``columns`` name -> array of :data:`COLUMNS` (rows
    first); ``fields``: ``source_files``, ``orientation_sigma_deg`` when given."""
    rows = len(columns["dt_ns"])
    return {
        "sweep": sweep,
        "first_step": int(first_step),
        "rows": rows,
        "units": list(units),
        "targets": list(targets),
        **fields,
        "columns": {name: _encoded(a, COLUMNS[name]) for name, a in columns.items()},
    }


def block_columns(p: Path, k: int, payload: dict[str, Any]) -> dict[str, np.ndarray]:
    """The decoded columns of block message ``k`` (schema-valid ``payload``), each of its
    dtype and shape; a column that is not base64 or not of its length is refused."""
    rows, n_joints, n_targets = payload["rows"], len(payload["units"]), len(payload["targets"])
    dims = {"J": n_joints, "T": n_targets}
    out: dict[str, np.ndarray] = {}
    for name, text in payload["columns"].items():
        col = COLUMNS[name]
        shape = (rows, *(d if isinstance(d, int) else dims[d] for d in col.shape))
        try:
            raw = binascii.a2b_base64(text, strict_mode=True)
        except (binascii.Error, ValueError) as exc:
            raise RecordingError(
                f"{p}: {BLOCK_TOPIC} message {k} column {name} is not base64",
                got=str(exc),
                fix=_FIX,
            ) from None
        want = int(np.prod(shape)) * np.dtype(col.dtype).itemsize
        if len(raw) != want:
            raise RecordingError(
                f"{p}: {BLOCK_TOPIC} message {k} column {name} holds {len(raw):,} bytes",
                expected=f"{want:,} bytes: {col.dtype} of shape {shape}",
                fix=_FIX,
            )
        out[name] = np.frombuffer(raw, col.dtype).reshape(shape).astype(col.dtype[1:])
    return out


def noise_fields(sigma: Any) -> dict[str, Any]:
    """A ``/points`` message's uncertainty of a point's σ of x, y, z (cm): ``sigma_cm``
    when they are equal, else the diagonal ``cov_cm2`` of their squares."""
    if sigma[0] == sigma[1] == sigma[2]:
        return {"sigma_cm": float(sigma[0])}
    return {"cov_cm2": [[float(s * s) if r == c else 0.0 for c, s in enumerate(sigma)]
                        for r in range(3)]}  # fmt: skip


def row_messages(
    p: Path, messages: dict[str, list[tuple[int, dict[str, Any]]]]
) -> dict[str, list[tuple[int, dict[str, Any]]]]:
    """``messages`` (topic -> (time in ns, payload), as :func:`~pipeline.contract.mcap_read.
    read_mcap` gives them) with every ``/points/block`` message replaced by the
    ``/robot/joint_state`` and ``/points`` messages it stands for, one per row and per row
    and target, in its row order: what a block means, for inspecting a recording (the
    session reader decodes blocks column-wise, :mod:`pipeline.stages.recording_blocks`)."""
    out = {t: list(v) for t, v in messages.items() if t != BLOCK_TOPIC}
    joints, points = out.setdefault(JOINT_TOPIC, []), out.setdefault(POINT_TOPIC, [])
    for k, (t_ns, m) in enumerate(messages.get(BLOCK_TOPIC, [])):
        cols = {name: a.tolist() for name, a in block_columns(p, k, m).items()}
        files = m.get("source_files")
        for r in range(m["rows"]):
            t, key = t_ns + cols["dt_ns"][r], {"sweep": m["sweep"], "step": m["first_step"] + r}
            q = cols["q_commanded"][r]
            state = {**key, "q_commanded": q, "q_encoder": cols["q_encoder"][r] if
                     "q_encoder" in cols else list(q), "units": m["units"]}  # fmt: skip
            for name in ("payload_kg", "tracker_drift_cm", "tracker_residual_cm"):
                if name in cols and cols[name][r] == cols[name][r]:  # NaN: not recorded
                    state[name] = cols[name][r]
            if files is not None:
                state["source_file"] = files[cols["source_file"][r]]
            if cols.get("source_line", [0] * (r + 1))[r] > 0:
                state["source_line"] = cols["source_line"][r]
            joints.append((t, state))
            for j, target in enumerate(m["targets"]):
                x, y, z = cols["points_cm"][r][j]
                point = {**key, "target": target, "x_cm": x, "y_cm": y, "z_cm": z}
                if j == 0 and "orientation_wxyz" in cols:
                    point["orientation_wxyz"] = cols["orientation_wxyz"][r]
                    if "orientation_sigma_deg" in m:
                        point["orientation_sigma_deg"] = m["orientation_sigma_deg"]
                if "sigma_cm" in cols:
                    point.update(noise_fields(cols["sigma_cm"][r][j]))
                points.append((t, point))
    return out
