"""Stage ``detections`` of an imported image set (issue 40): the target detected in the
images the recording references by content hash, here, as a cached stage.

Inputs: the recording and its images (:data:`pipeline.stages.base.IMAGES`: the runner
hashes the image files, so a changed image makes this stage stale and a rerun with the
same images detects nothing). An image that is not the one the recording holds (changed,
replaced, deleted since the import) is refused in one line naming it: the recording is
the contract (import the set again to take the new bytes). Each image present at import
is detected (:func:`pipeline.sensor.detect.detect_file`, the target of
``/rig/description``); one row per point found, as the recorded stage's
(:mod:`pipeline.stages.detections`, ``schemas/arrow/detections.json``), σ the one the
import stated. A recording that references no images: its recorded detections.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.errors import StageError
from pipeline.schemas import arrow_table
from pipeline.stages import detections
from pipeline.stages.base import IMAGES, RECORDING, NoParams, Stage


def compute(inputs: Mapping[str, Any], params: NoParams) -> pa.Table:
    from pipeline.sensor.detect import detect_file
    from pipeline.sensor.target import target_from_dict

    rec, refs = inputs[RECORDING], inputs[IMAGES]
    if refs.folder is None:
        return detections.compute(inputs, params)
    changed = refs.changed()
    if changed:
        raise StageError(
            f"{rec.path}: {changed}",
            fix="restore the image, or import the set again (`pipeline import ... --force`) "
            "to calibrate from the new one",
        )
    target = target_from_dict(rec.rig["target"], "/rig/description target")
    sigma = float(np.median(rec.detection_sigma_px)) if len(rec.detection_sigma_px) else 0.2
    rows: list[tuple[int, int, np.ndarray, np.ndarray]] = []
    for sweep, step, f, sha in zip(refs.sweep, refs.step, refs.file, refs.recorded, strict=True):
        if not sha:
            continue  # missing at import: dropped then, not part of the recording
        found, _ = detect_file(refs.folder / f, target)
        if found.kept:
            order = np.argsort(found.point_ids, kind="stable")
            rows.append((int(sweep), int(step), found.point_ids[order], found.uv_px[order]))
    rows.sort(key=lambda r: (r[0], r[1]))
    sizes = [len(r[2]) for r in rows]
    uv = np.concatenate([r[3] for r in rows]) if rows else np.zeros((0, 2))
    columns = {
        "sweep": np.repeat([r[0] for r in rows], sizes),
        "image": np.repeat([r[1] for r in rows], sizes),
        "point_id": np.concatenate([r[2] for r in rows]) if rows else np.zeros(0, np.int64),
        "u_px": uv[:, 0], "v_px": uv[:, 1], "sigma_px": np.full(len(uv), sigma),
    }  # fmt: skip
    return arrow_table("detections", columns)


STAGE = Stage(
    "detections",
    1,
    (RECORDING, IMAGES),
    NoParams(),
    compute,
    "target points detected in the images the recording references by content hash",
)
