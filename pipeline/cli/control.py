"""Control commands: a session's signature (or a design model) driven (fk, ik,
compensate, ik-convergence). The work is in :mod:`pipeline.control`."""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Annotated

import typer

from pipeline.cli.options import (
    AcceptVerdict,
    ExportFrame,
    JsonOption,
    Method,
    PayloadOption,
    PumaBranch,
    SessionArg,
    choice,
    finite,
    joint_values,
)
from pipeline.cli.output import NotReached, print_json, report, warn, warn_outside_limits
from pipeline.errors import ArmsigError
from pipeline.stages.base import session_or_robot

commands = typer.Typer()

#: x y z (cm) rx ry rz (deg, fixed axes)
Pose = tuple[float, float, float, float, float, float]


@commands.command()
def fk(
    robot: Annotated[
        str,
        typer.Argument(
            help="Identified session (a folder or a NAME for sessions/NAME), built-in robot "
            "name or path to a .toml description.",
            callback=session_or_robot,
        ),
    ],
    q: Annotated[
        str | None, typer.Option("--q", help="Joint values, comma or space separated (deg / cm).")
    ] = None,
    q_file: Annotated[
        str | None,
        typer.Option(
            "--q-file",
            help="Many configurations: an Arrow IPC file (or .csv with a header) with columns "
            "q1_deg, q2_deg, ... (cm for prismatic joints), as `ik --targets` writes.",
        ),
    ] = None,
    out: Annotated[
        str | None,
        typer.Option(help="Arrow file for the poses of --q-file (an `ik --targets` input)."),
    ] = None,
    force: Annotated[bool, typer.Option(help="Replace an existing --out file.")] = False,
    design: Annotated[
        bool, typer.Option(help="For a session: the design model's pose of the session's tool.")
    ] = False,
    payload_kg: PayloadOption = None,
    frame: Annotated[
        ExportFrame,
        choice(
            "For a session, the world frame of the pose: design-base (default: the design "
            "base placed by the design alignment, what `ik --pose` takes back) or sensor "
            "(where the points were measured: the prediction of a measurement)."
        ),
    ] = ExportFrame.design_base,
    as_json: JsonOption = False,
) -> None:
    """Print the tool pose at joint values Q (a session's signature or a design model).

    For a session: the pose of its signature's tool in the design base frame (what
    `pipeline ik SESSION --pose` takes back), or with --frame sensor in the sensor frame
    (what the tracker would measure); with --design, the design model's pose of that
    tool. For a robot: the pose of its design tool frame (the last D-H frame times the
    description's [tool]: the flange when it states none) in its base frame. The output
    names the frame and the point. --json prints every number at full precision; --q-file takes many
    configurations (with --out or --json).
    """
    import numpy as np

    from pipeline.control.poses import payload_warning, poses_of_file, tool_pose

    if (q is None) == (q_file is None):  # a usage error (exit 2), as a missing option
        raise typer.BadParameter(
            "give one of '--q' and '--q-file'", param_hint="'--q' / '--q-file'"
        )
    if q_file is not None:
        if out is None and not as_json:
            raise ArmsigError("--q-file needs --out or --json", fix="--out poses.arrow")
        done = poses_of_file(
            robot,
            q_file,
            design=design,
            out=out,
            force=force,
            frame=frame.value,
            payload_kg=payload_kg,
        )
        if as_json:
            print_json(done.to_dict())
        else:
            typer.echo(f"wrote {done.out}: {len(done.q)} poses of {done.robot} ({done.frame})")
        if note := payload_warning(robot, payload_kg):
            warn(note)
        outside = sum(1 for names in done.poses.outside_limits if names)
        if outside:
            warn(f"{outside} configuration(s) outside joint limits (column outside_limits)")
        return
    if out is not None:
        raise ArmsigError("--out is for --q-file", fix="drop --out, or give --q-file")
    assert q is not None
    values = joint_values(q, "--q")
    pose = tool_pose(robot, values, design=design, payload_kg=payload_kg, frame=frame.value)
    where = frame.value if Path(robot).is_dir() else "base"  # a description: its base frame
    point = _fk_point(robot, design)
    if as_json:
        print_json(
            {
                "q": values,
                "frame": where,
                "point": point,
                "xyz_cm": pose.xyz_cm.tolist(),
                "rpy_deg": pose.rpy_deg.tolist(),
                "matrix": pose.matrix.tolist(),
                "outside_limits": list(pose.outside_limits),
            }
        )
    else:
        with np.printoptions(precision=6, suppress=True):
            typer.echo(f"frame   = {where}")
            typer.echo(f"point   = {point}")
            typer.echo(f"xyz_cm  = {pose.xyz_cm}")
            typer.echo(f"rpy_deg = {pose.rpy_deg}")
            typer.echo("T =")
            typer.echo(str(pose.matrix))
    if note := payload_warning(robot, payload_kg):
        warn(note)
    warn_outside_limits(pose.outside_limits)


def _fk_point(robot: str, design: bool) -> str:
    """What ``fk`` gives the pose of: a session's signature tool (or the design model's
    pose of it), or a description's design tool frame, the last D-H frame times its
    ``[tool]`` (the flange when it states none)."""
    if Path(robot).is_dir():
        return "the signature's tool, by the design model" if design else "the signature's tool"
    return "the design tool: the last D-H frame times the description's [tool]"


@commands.command()
def ik(
    session: SessionArg,
    pose: Annotated[
        Pose | None,
        typer.Option(help="x y z (cm) rx ry rz (deg, fixed axes) in the design base frame."),
    ] = None,
    branch: Annotated[
        PumaBranch | None,
        choice("Puma branch, e.g. right-up-noflip (default: that of --near, else of q^s)."),
    ] = None,
    method: Annotated[Method, choice("nr (Newton-Raphson) or jacobi.")] = Method.nr,
    targets: Annotated[
        str | None, typer.Option(help="Arrow file: x_cm y_cm z_cm rx_deg ry_deg rz_deg [branch].")
    ] = None,
    out: Annotated[str | None, typer.Option(help="Arrow file for the joints of --targets.")] = None,
    force: Annotated[bool, typer.Option(help="Replace an existing --out file.")] = False,
    tool: Annotated[
        Pose | None,
        typer.Option(
            help="User tool x y z (cm) rx ry rz (deg, fixed axes) in the design flange frame; "
            "poses are then for that tool (default: the signature's tool)."
        ),
    ] = None,
    near: Annotated[
        str | None,
        typer.Option(
            help="Start near these joint readings (deg / cm, comma or space separated): "
            "the Puma takes their branch unless --branch is given; other arms return "
            "the solution the search from there reaches (default: the signature's q^s)."
        ),
    ] = None,
    accept_verdict: AcceptVerdict = False,
    payload_kg: PayloadOption = None,
    as_json: JsonOption = False,
) -> None:
    """Joint readings that put the identified tool at a pose (signature-based control)."""
    from pipeline.control.poses import solve_pose, solve_targets

    q_near = None if near is None else joint_values(near, "--near")
    user_tool = None if tool is None else finite(tool, "--tool")
    if targets is not None:
        if out is None:
            raise ArmsigError("--targets needs --out", fix="--out joints.arrow")
        if pose is not None:
            raise ArmsigError(
                "--pose and --targets both given", expected="one of them", fix="drop one"
            )
        done = solve_targets(
            session,
            targets,
            out,
            method=method.value,
            tool=user_tool,
            near=q_near,
            force=force,
            accept_verdict=accept_verdict,
            payload_kg=payload_kg,
        )
        report(done, as_json, done.summary)
        if done.failed:
            raise NotReached
        return
    if pose is None:
        raise ArmsigError("give --pose x y z rx ry rz, or --targets FILE --out FILE")
    from pipeline.kinematics.kernels import interpreted

    solve = functools.partial(
        solve_pose,
        session,
        finite(pose, "--pose"),
        branch=None if branch is None else branch.value,
        method=method.value,
        tool=user_tool,
        near=q_near,
        accept_verdict=accept_verdict,
        payload_kg=payload_kg,
    )
    # One target in a process that then exits: Newton-Raphson's kernels run as Python, the
    # same arithmetic, without loading numba (~0.5 s of CPU; pipeline.kinematics.kernels).
    r = interpreted(solve) if method == Method.nr else solve()
    report(
        r,
        as_json,
        "q = " + "  ".join(f"{v:.4f} {u}" for v, u in zip(r.q, r.units, strict=True)),
        f"{r.status} after {r.iterations} iterations; "
        f"residual {r.position_error_cm:.2e} cm, {r.orientation_error_deg:.2e} deg",
    )
    if r.status == "out_of_limits":
        warn(
            "no solution on the branch inside the joint limits (±360° turns and the wrist "
            f"flip tried); outside: {', '.join(r.outside_limits)}; try: another --branch"
        )
    else:
        warn_outside_limits(r.outside_limits)
    if r.branch_changed:
        warn("no solution on the requested branch; this one is on another")
    if not r.converged:
        raise NotReached


@commands.command()
def compensate(
    session: SessionArg,
    targets: Annotated[
        str | None,
        typer.Option(
            help="Arrow file of desired poses: x_cm y_cm z_cm rx_deg ry_deg rz_deg [branch], "
            "design base frame (as `ik --targets`)."
        ),
    ] = None,
    program: Annotated[
        str | None,
        typer.Option(
            help="Or a robot program (URScript .script, KUKA KRL .src/.dat, ABB RAPID .mod) "
            "whose motion targets are rewritten, every other byte kept (docs/compensate.md)."
        ),
    ] = None,
    dialect: Annotated[
        str | None,
        typer.Option(
            help="The --program's language when its suffix does not say: urscript, krl or rapid."
        ),  # fmt: skip
    ] = None,
    out: Annotated[
        str, typer.Option(help="The compensated file (Arrow for --targets, else a program).")
    ] = "",
    force: Annotated[bool, typer.Option(help="Replace an existing --out file.")] = False,
    tool: Annotated[
        Pose | None,
        typer.Option(
            help="The nominal controller's tool x y z (cm) rx ry rz (deg, fixed axes) in the "
            "design flange frame (default: the signature's tool)."
        ),
    ] = None,
    method: Annotated[Method, choice("nr (Newton-Raphson) or jacobi.")] = Method.nr,
    accept_verdict: AcceptVerdict = False,
    as_json: JsonOption = False,
) -> None:
    """Poses to command to a controller that keeps its nominal (design) model, so that the
    real arm reaches the desired ones (docs/compensate.md)."""
    from pipeline.control.compensate import compensate_targets

    if (targets is None) == (program is None):
        raise ArmsigError("give one of --targets and --program", fix="--targets poses.arrow")
    if not out:
        raise ArmsigError("--out is needed", fix="--out compensated.arrow (or a program file)")
    user_tool = None if tool is None else finite(tool, "--tool")
    if program is not None:
        _compensate_program(session, program, dialect, out, user_tool, method, force,
                            accept_verdict, as_json)  # fmt: skip
        return
    assert targets is not None
    done = compensate_targets(
        session,
        targets,
        out,
        tool=user_tool,
        method=method.value,
        force=force,
        accept_verdict=accept_verdict,
    )
    report(
        done,
        as_json,
        done.summary,
        f"largest correction {done.max_correction_cm:.4f} cm, {done.max_correction_deg:.4f} deg",
    )
    if done.failed:
        warn(f"{done.failed} target(s) not reached: no compensated pose (null; column status)")
        raise NotReached


def _compensate_program(
    session: str, program: str, dialect: str | None, out: str, tool: list[float] | None,
    method: Method, force: bool, accept_verdict: bool, as_json: bool,
) -> None:  # fmt: skip
    """``compensate --program``: :func:`pipeline.control.programs.compensate_program`."""
    from pipeline.control.programs import compensate_program

    done = compensate_program(session, program, out, dialect=dialect, tool=tool,
                              method=method.value, force=force,
                              accept_verdict=accept_verdict)  # fmt: skip
    report(
        done,
        as_json,
        done.summary,
        f"largest correction {done.max_correction_cm:.4f} cm, {done.max_correction_deg:.4f} deg",
    )
    if done.partial_lines:
        warn(f"targets stating only some axes left as they are: lines {done.partial_lines}")
    if done.failed_lines:
        warn(f"not reached, left as they are: lines {done.failed_lines}")
        raise NotReached


@commands.command("ik-convergence")
def ik_convergence(
    session: SessionArg,
    seed: Annotated[
        int, typer.Option(min=0, help="Seed of the target and the poor signature.")
    ] = 3,
    as_json: JsonOption = False,
) -> None:
    """Per-iteration errors of Newton-Raphson and Jacobi (Tables 5-1, 5-2, Section 5.4)."""
    from pipeline.control.convergence import convergence_tables, format_tables

    tables = convergence_tables(session, seed=seed)
    if as_json:
        print_json([t.to_dict() for t in tables])
        return
    typer.echo(format_tables(tables))


@commands.command()
def warmup(
    everything: Annotated[
        bool,
        typer.Option(
            "--all",
            help="Also the Jacobi solver (`ik --method jacobi`) and signatures with "
            "non-geometric terms, which otherwise compile on first use (~12 s of CPU).",
        ),
    ] = False,
    as_json: JsonOption = False,
) -> None:
    """Compile the numerical kernels the commands use by default now (`make install` runs
    it): the first `ik` then answers as fast as a later one. Cached per checkout; ~25 s
    of CPU once (docs/scale.md)."""
    import time

    from pipeline.control.warmup import warm_all

    t0 = time.perf_counter()
    warmed = warm_all(everything)
    seconds = time.perf_counter() - t0
    if as_json:
        print_json({"seconds": seconds, "robots": [w.__dict__ for w in warmed]})
        return
    for w in warmed:
        typer.echo(f"{w.robot:10s} {w.calls:3d} solves  max error {w.max_error_cm:.1e} cm  "
                   f"{w.seconds:6.1f} s")  # fmt: skip
    typer.echo(f"kernels compiled and cached in {seconds:.1f} s")
