"""Robot descriptions: built-in robots and user description files."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from pipeline.errors import UnknownRobotError
from pipeline.robots.description import RobotDescription, description_from_dict, load_description

__all__ = [
    "RobotDescription",
    "builtin_names",
    "get_robot",
    "load_description",
    "description_from_dict",
]


def builtin_names() -> list[str]:
    """Names of the robots shipped with armsig."""
    data = resources.files("pipeline.robots") / "data"
    return sorted(p.name[: -len(".toml")] for p in data.iterdir() if p.name.endswith(".toml"))


def get_robot(name_or_path: str | Path) -> RobotDescription:
    """A built-in robot by name, or a description file by path."""
    name = str(name_or_path)
    if name in builtin_names():
        ref = resources.files("pipeline.robots") / "data" / f"{name}.toml"
        with resources.as_file(ref) as path:
            return load_description(path)
    p = Path(name)
    if p.suffix == ".toml" or p.exists():
        return load_description(p)
    raise UnknownRobotError(
        f"unknown robot '{name}'",
        expected="a built-in name (" + ", ".join(builtin_names()) + ") or a .toml description file",
        fix="`pipeline robots` lists the built-in robots",
    )
