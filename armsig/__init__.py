"""armsig's Python API: ``armsig.load(session)`` (the work is in :mod:`pipeline.api`;
docs/api.md)."""

from pipeline.api import Arm, load
from pipeline.errors import ArmsigError

__all__ = ["Arm", "ArmsigError", "load"]
