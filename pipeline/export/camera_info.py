"""A camera session's lens as ROS ``camera_info`` YAML (issue 39; the text:
:mod:`pipeline.sensor.camera_info`): ``SESSION/export/camera_info.yaml`` from the
signature file's ``camera`` section, its numbers checked by reading the text back."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.atomic import check_new_file, check_writable, write_text_atomic
from pipeline.errors import ArmsigError
from pipeline.sensor.camera import Intrinsics
from pipeline.sensor.camera_info import camera_info_text, intrinsics_from_camera_info
from pipeline.signature.file import FILE_NAME, signature_from_document
from pipeline.signature.session import load_session_document
from pipeline.signature.verdict import verdict_gate

FILE = "camera_info.yaml"


@dataclass(frozen=True)
class CameraInfoResult:
    """What was written: the path, the lens (OpenCV's names) and its largest change on
    reading the text back (relative)."""

    path: str
    intrinsics: dict[str, float]
    max_relative_error: float
    verdict: str | None = None
    verdict_warning: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def signature_intrinsics(camera: dict[str, Any]) -> Intrinsics:
    """The lens of a signature file's ``camera`` section."""
    values = [r["value"] for r in camera["intrinsics"]]
    return Intrinsics.from_vector(camera["width_px"], camera["height_px"], values)


def export_camera_info(
    session_dir: str | Path,
    out: str | Path | None = None,
    force: bool = False,
    accept_verdict: bool = False,
) -> CameraInfoResult:
    """Write the session's lens as ``camera_info`` YAML (module docstring); ``out``
    defaults to ``SESSION/export/camera_info.yaml`` (armsig's folder, rewritten), an
    existing ``out`` needs ``force``. A session without a camera is refused in one line."""
    sdir = Path(session_dir)
    doc = load_session_document(sdir / FILE_NAME)
    sig = signature_from_document(doc, str(sdir / FILE_NAME))
    if sig.camera is None:
        raise ArmsigError(
            f"{sdir}: --format camera-info needs a camera session",
            expected="a signature identified from camera images (docs/camera.md)",
            got="a signature without a camera section",
            fix="export the chain with --format urdf, dh, mdh or json",
        )
    if out is None:
        path = sdir / "export" / FILE
        check_writable(path.parent, "export folder", folder=True)
    else:
        path = check_new_file(out, "--out", force)
    warning = verdict_gate(sig.verdict, str(sdir), accept_verdict)
    lens = signature_intrinsics(sig.camera)
    text = camera_info_text(lens, sdir.resolve().name)
    back = intrinsics_from_camera_info(text, str(path)).vector()
    k = lens.vector()
    err = float(np.max(np.abs(back - k) / np.maximum(np.abs(k), 1.0)))
    write_text_atomic(path, text)
    status = None if sig.verdict is None else sig.verdict.status
    named = dict(zip(("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"), k.tolist(),
                     strict=True))  # fmt: skip
    return CameraInfoResult(str(path), named, err, status, warning)
