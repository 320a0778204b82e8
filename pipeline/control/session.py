"""The controller of an identified session: its ``signature.json``, refused when stale."""

from __future__ import annotations

from pathlib import Path

from pipeline.control.controller import Controller
from pipeline.signature.file import FILE_NAME
from pipeline.signature.session import load_session_signature


def session_controller(session_dir: str | Path) -> Controller:
    """The controller of an identified session: its ``signature.json``, refused unless it
    matches the session's committed stages
    (:func:`pipeline.signature.session.load_session_signature`)."""
    return Controller.from_signature(load_session_signature(Path(session_dir) / FILE_NAME))
