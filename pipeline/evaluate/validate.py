"""``pipeline validate --against``: a session's signature against the rows of a second
foreign file (parsed in memory, never written into the session), as is and after
registering the base (:mod:`pipeline.evaluation.validation`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pipeline.errors import ArmsigError, os_errors_refused
from pipeline.evaluation.validation import error_distances, model_points, position_errors
from pipeline.importers import OS_FIX, parse_foreign
from pipeline.importers.mapping import ImportMap, load_map
from pipeline.signature.file import FILE_NAME
from pipeline.signature.session import load_session_signature


def validate_against(
    session_dir: str | Path, path: str | Path, fmt: str, map_path: str | Path | None = None
) -> dict[str, Any]:
    """The signature of ``session_dir`` against every row of a second foreign file
    (parsed in memory, never written into the session): its first target vs the model."""
    sdir = Path(session_dir)
    with os_errors_refused(path, OS_FIX):
        sig = load_session_signature(sdir / FILE_NAME)
        imap = ImportMap() if map_path is None else load_map(Path(map_path))
        rows, _ = parse_foreign(Path(path), fmt, sig.robot, imap)
    target = next(iter(rows.targets))
    measured = rows.targets[target]
    ok = np.isfinite(rows.q).all(axis=1) & np.isfinite(measured).all(axis=1)
    if not ok.any():
        raise ArmsigError(f"{Path(path).name}: no row with finite readings and coordinates")
    q = sig.robot.joints_from_readings(rows.q[ok])
    model = model_points(sig.chain, q, sig.prismatic, sig.nongeometric)
    raw, reg = error_distances(model, measured[ok])
    return {
        "session": str(sdir),
        "file": Path(path).name,
        "format": fmt,
        "target": target,
        "rows_skipped": int((~ok).sum()),
        **position_errors(raw, reg).to_dict(),
    }
