"""The images a recording references by content hash (``/camera/images``, issue 40), as a
stage input (:data:`pipeline.stages.base.IMAGES`).

The recording names each image (a path relative to ``/rig/description`` ``images_dir``,
itself absolute, or relative to the recording's folder)
and the SHA-256 of the bytes detected at import. The runner hashes the files as they are
now: the input's content hash is over every image's name and current hash, so a changed,
replaced or deleted image makes the stages that read it stale, and ``status`` names the
first image that is no longer the one the recording holds.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np


@dataclass(frozen=True)
class ImageRefs:
    """The referenced images: ``folder`` (None: the recording references none), per image
    its key (``sweep``, ``step``), ``file``, the SHA-256 ``recorded`` at import ("" when
    the file was missing then) and ``current`` now ("" when missing now)."""

    folder: Path | None
    sweep: np.ndarray
    step: np.ndarray
    file: tuple[str, ...]
    recorded: tuple[str, ...]
    current: tuple[str, ...]

    def digest(self) -> str:
        """The input's content hash (module docstring)."""
        h = hashlib.sha256()
        for f, c in zip(self.file, self.current, strict=True):
            h.update(f"{f}\t{c}\n".encode())
        return h.hexdigest()

    def changed(self) -> str | None:
        """One line naming the first image that is not the recording's, None if none."""
        for f, r, c in zip(self.file, self.recorded, self.current, strict=True):
            if r != c:
                now = "missing" if not c else f"SHA-256 {c[:12]}…"
                was = "missing" if not r else f"{r[:12]}…"
                return f"image {f} is not the one the recording holds (now {now}, recorded {was})"
        return None


def image_refs(rec: Any) -> ImageRefs:
    """The images of :class:`~pipeline.stages.recording.Recording` ``rec``, hashed now."""
    from pipeline.contract.digest import file_sha256

    folder = rec.rig.get("images_dir")
    if folder is None or not len(rec.image_file):
        none = np.zeros(0, np.int64)
        return ImageRefs(None, none, none, (), (), ())
    root = Path(rec.path).parent / folder  # relative: beside the recording (simulated)
    files = tuple(str(f) for f in rec.image_file)
    current = tuple(file_sha256(root / f) if (root / f).is_file() else "" for f in files)
    return ImageRefs(root, rec.image_sweep, rec.image_step, files,
                     tuple(str(h) for h in rec.image_sha256), current)  # fmt: skip
