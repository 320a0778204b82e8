"""Compensated robot programs (``pipeline compensate --program``): a URScript, KRL or RAPID
program with each motion target rewritten for a controller that keeps its nominal model,
every other byte as it was (RoboDK's "filter program").

Each target (:mod:`pipeline.control.program_formats`) is read in the design base frame:

- a **pose** is where the program wants the tool. The signature solves the joint readings
  that put the real arm's tool there (:func:`~pipeline.control.controller.solve_poses`,
  from the readings of the target solved before it (:func:`in_solve_order`): the solution
  a controller reaches from where the arm is), and the target becomes the design model's
  pose at those readings, ``design(q) · Y`` (as ``compensate --targets``);
- a **joint** target is where the program was taught on the nominal model: its pose is
  ``design(q) · Y``, and the target becomes the signature's readings for that pose,
  solved from the taught readings.

A target the signature cannot reach keeps its text and is named (exit 3 in the CLI), so
no target is changed silently. The tool is the signature's, or ``tool`` (the controller's
tool data), as :func:`pipeline.control.poses.tool_controller`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.control.poses import RunRecord, tool_controller
from pipeline.control.program_formats import Target
from pipeline.errors import ArmsigError

#: The largest program read (bytes): programs of 100,000 targets are a few MB.
MAX_PROGRAM_BYTES = 64 * 1024 * 1024


@dataclass(frozen=True)
class CompensatedProgram(RunRecord):
    """What :func:`compensate_program` wrote; ``summary``: its one line for people."""

    program: str
    dialect: str
    out: str
    tool: str
    targets: int
    poses: int
    joints: int
    rewritten: int
    failed_lines: list[int]
    partial_lines: list[int]
    max_correction_cm: float
    max_correction_deg: float
    summary: str
    verdict: str | None = None
    verdict_warning: str | None = None


def dialect_of(path: Path, dialect: str | None) -> str:
    """``dialect``, else the one of the file's suffix (:data:`SUFFIXES`); one line if none."""
    from pipeline.control.program_formats import DIALECTS, SUFFIXES

    d = dialect or SUFFIXES.get(path.suffix.lower())
    if d not in DIALECTS:
        raise ArmsigError(
            f"--program {path}: which robot language is it?",
            expected=f"a suffix {', '.join(sorted(SUFFIXES))}, or --dialect {' | '.join(DIALECTS)}",
            got=repr(dialect or path.suffix),
            fix="--dialect urscript (or krl, rapid)",
        )
    return d


def read_program(path: Path) -> str:
    """The program's text, one character per byte (latin-1: written back byte for byte)."""
    if not path.is_file():
        raise ArmsigError(f"--program {path}: no such file", fix="check the path")
    size = path.stat().st_size
    if size > MAX_PROGRAM_BYTES:
        raise ArmsigError(
            f"--program {path}: {size:,} bytes", expected=f"at most {MAX_PROGRAM_BYTES:,}",
            fix="split the program",
        )  # fmt: skip
    return path.read_bytes().decode("latin-1")


def in_solve_order(targets: list[Target]) -> list[Target]:
    """The targets in the order they are solved, each from the previous one's readings:
    from the first joint target (the program's first known configuration) to the end,
    then back from it to the start; in program order from q^s when there is none."""
    first = next((k for k, t in enumerate(targets) if t.kind == "joints"), 0)
    return targets[first:] + targets[:first][::-1]


def compensate_program(
    session: str | Path,
    program: str | Path,
    out: str | Path,
    *,
    dialect: str | None = None,
    tool: Sequence[float] | None = None,
    method: str = "nr",
    force: bool = False,
    accept_verdict: bool = False,
) -> CompensatedProgram:
    """Write ``program`` with its targets compensated to ``out`` (module docstring)."""
    from pipeline.atomic import atomic_write
    from pipeline.control.controller import solve_poses
    from pipeline.control.program_formats import READERS, rewrite
    from pipeline.control.targets import check_output
    from pipeline.kinematics.transforms import pose_error, xyz_rpy_from_transform

    src = Path(program)
    d = dialect_of(src, dialect)
    text = read_program(src)
    tc = tool_controller(session, tool, accept_verdict)
    ctl = tc.controller
    robot = ctl.robot
    found = READERS[d](text, robot.n_joints, robot.prismatic)
    if not found.targets:
        raise ArmsigError(
            f"--program {src}: no motion target found ({d})",
            expected="literal targets of motion instructions (docs/compensate.md, Programs)",
            fix="check --dialect, or give the targets as a table with --targets",
        )
    check_output(out, src, force, f"{src.stem}.compensated{src.suffix}", "--program")
    edits, failed = [], []
    dp_max = dth_max = 0.0
    near = None
    for t in in_solve_order(found.targets):
        if t.kind == "pose":
            wanted = t.value
            start = near
        else:
            wanted = ctl.poses(t.value[None], design=True).matrix[0]
            start = t.value
        xyz, rpy = xyz_rpy_from_transform(wanted)
        q, res = solve_poses(ctl, xyz[None], np.degrees(rpy)[None], None, method, start)
        if not res.converged[0] and start is not None:  # far from there: the default start
            q, res = solve_poses(ctl, xyz[None], np.degrees(rpy)[None], None, method, None)
        if not res.converged[0]:
            failed.append(t.line)
            continue
        near = q[0]
        command = ctl.poses(q, design=True).matrix[0]
        new = t.render(command if t.kind == "pose" else q[0])
        edits += list(zip(t.spans, new, strict=True))
        # a pose: the command's change; joints: the error the compensation removes there
        was = command if t.kind == "pose" else ctl.poses(t.value[None]).matrix[0]
        dp, dth = pose_error(wanted, was)
        dp_max, dth_max = max(dp_max, float(dp)), max(dth_max, float(np.degrees(dth)))
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(out) as f:
        f.write(rewrite(text, edits).encode("latin-1"))  # type: ignore[arg-type]
    n = len(found.targets)
    poses = sum(t.kind == "pose" for t in found.targets)
    summary = (
        f"wrote {out}: {n - len(failed)} of {n} targets compensated ({poses} poses, "
        f"{n - poses} joint targets; {d})"
        + (f"; {len(found.partial)} partial targets left as they are" if found.partial else "")
    )
    return CompensatedProgram(
        str(src), d, str(out), tc.label, n, poses, n - poses, n - len(failed), failed,
        found.partial, dp_max, dth_max, summary, tc.verdict, tc.warning,
    )  # fmt: skip
