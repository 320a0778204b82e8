"""The ``pipeline`` command line. Commands are thin; the work is in importable functions.

Only this module turns exceptions into exit codes, in one place (:class:`_Pipeline`):

==  =====================================================================
0   done
1   refused input or data (an :class:`~pipeline.errors.ArmsigError`)
2   usage error (unknown command or option, missing or malformed argument)
3   ``ik``: a target was not reached (the joints are still printed / written)
70  internal error: a bug in armsig (the traceback with ``ARMSIG_DEBUG=1``)
==  =====================================================================

Every error is one line on stderr starting ``error:``.
"""

from __future__ import annotations

import contextlib
import math
import os
import shlex
import sys
import traceback
import warnings
from collections.abc import Iterator, Sequence
from typing import Annotated, Any

import typer
from typer.core import TyperGroup

from pipeline.control.targets import session_controller
from pipeline.errors import ArmsigError, one_line

EXIT_REFUSED = 1
EXIT_USAGE = 2
EXIT_NOT_REACHED = 3
EXIT_INTERNAL = 70  # EX_SOFTWARE of sysexits.h
DEBUG_ENV = "ARMSIG_DEBUG"


def _fail(message: str, code: int) -> int:
    typer.echo(f"error: {one_line(message)}", err=True)
    return code


@contextlib.contextmanager
def _quiet_numpy(debug: bool) -> Iterator[None]:
    """No numpy floating-point or RuntimeWarning lines on stderr (unless ``debug``).

    armsig checks its numbers itself (finite inputs, dropouts as NaN, feature
    checks) and reports what matters as warnings of its own or as an error, so
    numpy's ``invalid value`` / ``divide by zero`` / ``Mean of empty slice`` lines
    would only precede those. They are all RuntimeWarnings (numpy's default error
    state warns), so the filter silences them without importing numpy: a warm
    ``identify`` needs none (issue 18). Other warning categories still print.
    """
    if debug:
        yield
        return
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        yield


class _Pipeline(TyperGroup):
    """The command group: maps every outcome of a command to one exit code."""

    def main(  # type: ignore[override]
        self,
        args: Sequence[str] | None = None,
        prog_name: str | None = None,
        complete_var: str | None = None,
        standalone_mode: bool = True,
        **extra: Any,
    ) -> Any:
        argv = list(sys.argv[1:] if args is None else args)
        prog = prog_name or "pipeline"
        debug = os.environ.get(DEBUG_ENV) == "1"
        try:
            with _quiet_numpy(debug):
                rv = super().main(argv, prog, complete_var, standalone_mode=False, **extra)
            code = rv if isinstance(rv, int) else 0  # an int: typer.Exit's code (--help: 0)
        except typer.TyperException as exc:  # the parser's: unknown option, bad value, ...
            where = getattr(getattr(exc, "ctx", None), "command_path", None) or prog
            code = _fail(f"{exc.format_message().rstrip('.')}; try: {where} --help", EXIT_USAGE)
        except typer.Abort:
            code = _fail("aborted", EXIT_REFUSED)
        except ArmsigError as exc:
            code = _fail(str(exc), EXIT_REFUSED)
        except (SystemExit, KeyboardInterrupt):
            raise
        except BaseException as exc:  # noqa: B036  (also a Rust panic of polars / pyarrow)
            if debug:
                traceback.print_exc()
            command = shlex.join([prog, *argv])
            code = _fail(
                f"internal error (a bug in armsig): {type(exc).__name__}: {exc}; "
                f"try: report it with the output of {DEBUG_ENV}=1 {command}",
                EXIT_INTERNAL,
            )
        if not standalone_mode:
            return code
        sys.exit(code)


app = typer.Typer(
    name="pipeline",
    help="armsig: identify a robot arm's kinematic signature and control it with it.",
    cls=_Pipeline,
    add_completion=True,
    pretty_exceptions_enable=False,
)


def _version(value: bool) -> None:
    if value:
        from pipeline import __version__

        typer.echo(f"armsig {__version__}")
        raise typer.Exit()


@app.callback()
def _main(
    version: Annotated[
        bool,
        typer.Option(
            "--version", callback=_version, is_eager=True, help="Print the version and exit."
        ),
    ] = False,
) -> None:
    pass  # the group's options; its help is the app's


def _print_json(data: Any) -> None:
    """``data`` as JSON on stdout, for ``jq`` and scripts."""
    import json

    typer.echo(json.dumps(data, indent=1))


@app.command()
def robots() -> None:
    """List the built-in robots with their joints."""
    from pipeline.robots import builtin_names, get_robot

    for name in builtin_names():
        rob = get_robot(name)
        joints = ", ".join(
            f"{j.name} ({j.type[0].upper()}, {j.lower:g}..{j.upper:g} {j.unit})" for j in rob.joints
        )
        typer.echo(f"{name}: {rob.n_joints} joints: {joints}")


def _joint_values(text: str, option: str) -> list[float]:
    """Joint values from a comma- or space-separated option (deg / cm)."""
    try:
        values = [float(v) for v in text.replace(",", " ").split()]
    except ValueError as exc:
        raise ArmsigError(
            f"{option} must hold numbers", got=repr(text), fix=f'{option} "0 -90 90 0 0 0"'
        ) from exc
    return _finite(values, option)


def _finite(values: Sequence[float], option: str) -> list[float]:
    """``values`` when every one is finite, else the one-line error of ``option``."""
    if not all(math.isfinite(v) for v in values):
        raise ArmsigError(
            f"{option} must hold finite numbers", got=" ".join(f"{v:g}" for v in values)
        )
    return list(values)


@app.command()
def fk(
    robot: Annotated[
        str,
        typer.Argument(
            help="Identified session folder, built-in robot name or path to a .toml description."
        ),
    ],
    q: Annotated[
        str, typer.Option("--q", help="Joint values, comma or space separated (deg / cm).")
    ],
    design: Annotated[
        bool, typer.Option(help="For a session: the design model's pose of the session's tool.")
    ] = False,
) -> None:
    """Print the tool pose at joint values Q (a session's signature or a design model).

    For a session: the pose of its signature's tool in the design base frame (what
    `pipeline ik SESSION --pose` takes back); with --design, the design model's pose
    of that tool. For a robot: the pose of its design flange.
    """
    from pathlib import Path

    import numpy as np

    values = _joint_values(q, "--q")
    if Path(robot).is_dir():

        pose = session_controller(robot).pose(values, design=design)
    else:
        from pipeline.robots import get_robot
        from pipeline.robots.fk import design_pose

        pose = design_pose(get_robot(robot), values)
    with np.printoptions(precision=6, suppress=True):
        typer.echo(f"xyz_cm  = {pose.xyz_cm}")
        typer.echo(f"rpy_deg = {pose.rpy_deg}")
        typer.echo("T =")
        typer.echo(str(pose.matrix))
    if pose.outside_limits:
        typer.echo(f"warning: outside joint limits: {', '.join(pose.outside_limits)}", err=True)


@app.command()
def simulate(
    name: Annotated[str, typer.Argument(help="Session name (sessions/NAME) or a folder path.")],
    robot: Annotated[
        str,
        typer.Option(
            help="Built-in robot (`pipeline robots`) or path to a .toml description file "
            "(schemas/robot_description.md)."
        ),
    ] = "puma560",
    seed: Annotated[int, typer.Option(min=0, help="Seed of every random draw.")] = 1,
    sigma_p: Annotated[
        float, typer.Option(min=0.0, help="Positional manufacturing error σ_p (cm).")
    ] = 0.03,
    sigma_o: Annotated[float, typer.Option(min=0.0, help="Orientational error σ_o (deg).")] = 0.03,
    sigma_e: Annotated[
        float, typer.Option(min=0.0, help="Encoder calibration error σ_e (deg).")
    ] = 0.3,
    noise_factor: Annotated[
        float, typer.Option(min=0.0, help="Multiplier of slant-range noise (7.9).")
    ] = 1.0,
    # The thesis used 5 to 100 positions and 10 cycles; the caps bound memory and file size.
    points: Annotated[
        int, typer.Option(min=3, max=1000, help="Positions per joint sweep, N_i.")
    ] = 100,
    repeats: Annotated[
        int, typer.Option(min=1, max=100, help="Digitize cycles per position, N_avg.")
    ] = 10,
    faults: Annotated[str, typer.Option(help="Comma-separated: bias, dropouts, outliers.")] = "",
    wac_error_cm: Annotated[
        float,
        typer.Option(
            min=-100.0, max=100.0, help="Error of the recorded W_AC calibration (cm), Section 7.3."
        ),
    ] = 0.0,
    noiseless: Annotated[
        bool, typer.Option(help="No range noise or quantization, uniform 70 °F, perfect servo.")
    ] = False,
    max_sweep_deg: Annotated[
        float,
        typer.Option(
            min=1.0, max=720.0, help="Cap of every revolute sweep (deg); under 180 violates B-3."
        ),
    ] = 300.0,
    resettle_counts: Annotated[
        int,
        typer.Option(
            min=0,
            max=1000,
            help="Held joints re-settle by ±1..K encoder counts between sweeps (0: never).",
        ),
    ] = 0,
    sensor: Annotated[
        str,
        typer.Option(
            help="sonic (the sparker digitizer) or tracker (a laser tracker, docs/rig.md)."
        ),
    ] = "sonic",
    targets: Annotated[
        int, typer.Option(min=1, help="Tracker: reflectors per sweep in a nest, ids T1..TK.")
    ] = 1,
    nest_on_axis: Annotated[
        int,
        typer.Option(min=0, help="Tracker: put this joint's last nest reflector on its axis."),
    ] = 0,
    check: Annotated[
        int, typer.Option(min=0, help="Tracker: random validation configurations (sweep check).")
    ] = 0,
    force: Annotated[
        bool, typer.Option(help="Replace the recording of an existing session (else refused).")
    ] = False,
) -> None:
    """Record a simulated session: recording.mcap plus rig-truth.json."""
    from pathlib import Path

    from pipeline.rig.simulate import SimulationOptions, simulate_session
    from pipeline.rig.true_robot import ErrorSigmas

    folder = Path(name) if ("/" in name or Path(name).is_absolute()) else Path("sessions") / name
    opts = SimulationOptions(
        robot=robot,
        seed=seed,
        sigmas=ErrorSigmas(sigma_p, sigma_o, sigma_e),
        noise_factor=noise_factor,
        points=points,
        repeats=repeats,
        faults=tuple(f.strip() for f in faults.split(",") if f.strip()),
        wac_error_cm=wac_error_cm,
        noiseless=noiseless,
        max_sweep_deg=max_sweep_deg,
        resettle_counts=resettle_counts,
        sensor=sensor,
        targets=targets,
        nest_on_axis=nest_on_axis,
        check=check,
    )
    path = simulate_session(folder, opts, force=force)
    typer.echo(f"wrote {path} ({path.stat().st_size / 1e6:.2f} MB) and {folder / 'rig-truth.json'}")


def _parse_params(values: list[str] | None) -> dict[str, dict[str, str]]:
    out: dict[str, dict[str, str]] = {}
    for item in values or []:
        key, sep, value = item.partition("=")
        stage, dot, name = key.partition(".")
        if not sep or not dot:
            raise ArmsigError(
                f"--param {item!r} is not STAGE.NAME=VALUE",
                fix="--param features.plane_method=eigen",
            )
        out.setdefault(stage, {})[name] = value
    return out


SessionArg = Annotated[str, typer.Argument(help="Session folder, e.g. sessions/robot3.")]
#: ``--json``: machine output on stdout (warnings and errors stay on stderr).
JsonOption = Annotated[bool, typer.Option("--json", help="Print JSON on stdout for machines.")]


@app.command("import")
def import_(
    file: Annotated[str, typer.Argument(help="The foreign file of measured points.")],
    name: Annotated[str, typer.Argument(help="Session name (sessions/NAME) or a folder path.")],
    format: Annotated[str, typer.Option(help="sscanss2 | table | rct (docs/import.md).")],
    robot: Annotated[str, typer.Option(help="Robot description .toml of the measured machine.")],
    map: Annotated[
        str | None, typer.Option(help="Map file (TOML): columns, units, sweeps (docs/import.md).")
    ] = None,
    force: Annotated[
        bool, typer.Option(help="Replace the recording of an existing session (else refused).")
    ] = False,
) -> None:
    """Convert a file of measured points into a point session (recording.mcap)."""
    from pathlib import Path

    from pipeline.importers import import_file

    folder = Path(name) if ("/" in name or Path(name).is_absolute()) else Path("sessions") / name
    out = import_file(file, format, robot, folder, map, force)
    n_check = int((out.rows.sweep < 0).sum())
    typer.echo(
        f"wrote {out.recording}: {len(out.rows.where)} configurations "
        f"({n_check} for validation), tool from {out.tool.note}"
    )


@app.command()
def validate(
    session: SessionArg,
    against: Annotated[str, typer.Option(help="A second file of measured points.")],
    format: Annotated[str, typer.Option(help="sscanss2 | table | rct (docs/import.md).")],
    map: Annotated[str | None, typer.Option(help="Map file (TOML) of the second file.")] = None,
    as_json: JsonOption = False,
) -> None:
    """The signature's position error on a second file (read in memory, nothing written)."""
    from pipeline.evaluate.validate import validate_against

    r = validate_against(session, against, format, map)
    if as_json:
        _print_json(r)
        return
    typer.echo(
        f"{r['file']}: {r['n']} points of target {r['target']} vs the signature of {session}"
    )
    typer.echo(
        f"  as measured:      mean {r['mean_cm']:.4g}  RMS {r['rms_cm']:.4g}  "
        f"max {r['max_cm']:.4g} cm"
    )
    if r["registered_rms_cm"] is None:
        typer.echo("  base registered:  not possible (fewer than 3 points, or collinear)")
    else:
        typer.echo(
            f"  base registered:  mean {r['registered_mean_cm']:.4g}  "
            f"RMS {r['registered_rms_cm']:.4g}  max {r['registered_max_cm']:.4g} cm"
        )


@app.command()
def identify(
    session: SessionArg,
    force: Annotated[bool, typer.Option(help="Rerun every stage.")] = False,
    from_: Annotated[
        str | None, typer.Option("--from", help="Rerun this stage and every later one.")
    ] = None,
    only: Annotated[str | None, typer.Option(help="Rerun just this stage.")] = None,
    param: Annotated[
        list[str] | None, typer.Option(help="Stage parameter, STAGE.NAME=VALUE (repeatable).")
    ] = None,
    report: Annotated[bool, typer.Option(help="Write report/report.md.")] = True,
    as_json: JsonOption = False,
) -> None:
    """Identify the arm signature of a recorded session (stages, signature.json, report)."""
    from pipeline.identify import identify as run_identify

    result = run_identify(
        session,
        force=force,
        from_stage=from_,
        only=only,
        overrides=_parse_params(param),
        report=report,
        progress=sys.stderr,
    )
    if as_json:
        _print_json(
            {
                "session": session,
                "stages": [_run_dict(r) for r in result.runs],
                "signature": None if result.signature is None else str(result.signature),
                "report": None if result.report is None else str(result.report),
                "warnings": result.warnings,
                "verdict": result.verdict,
            }
        )
    else:
        for r in result.runs:
            if r.action == "ran":
                typer.echo(f"  {r.name:12s} ran     {r.seconds * 1e3:7.1f} ms  {r.rows} rows")
            else:
                typer.echo(f"  {r.name:12s} {r.action}")
    for w in result.warnings:
        typer.echo(f"warning: {w}", err=True)
    if not as_json:
        typer.echo(f"signature: {result.signature or 'not written'}")
        if result.report:
            typer.echo(f"report:    {result.report}")
        if result.verdict:
            typer.echo(result.verdict)  # the last line (issue 15)


def _run_dict(r: Any) -> dict[str, Any]:
    """A :class:`~pipeline.stages.runner.StageRun` for ``--json`` (seconds and rows of a
    stage that ran, else null)."""
    ran = r.action == "ran"
    return {
        "name": r.name,
        "action": r.action,
        "seconds": round(r.seconds, 4) if ran else None,
        "rows": r.rows if ran else None,
    }


@app.command()
def status(
    session: SessionArg,
    as_json: JsonOption = False,
) -> None:
    """Show every stage of a session as fresh, stale or missing, and why.

    The identification stages, signature.json, then, once the session has an
    evaluation.mcap, the `pipeline evaluate` stages.
    """
    from pipeline.stages.runner import (
        EVALUATE_STAGE_MODULES,
        identification_modules,
        session_folder,
    )
    from pipeline.stages.runner import status as stage_status

    evaluated = (session_folder(session) / "evaluation.mcap").is_file()
    modules = identification_modules(session) + (EVALUATE_STAGE_MODULES if evaluated else ())
    states = stage_status(session, modules=modules)
    if as_json:
        _print_json([{"name": s.name, "state": s.state, "reason": s.reason} for s in states])
        return
    for st in states:
        typer.echo(f"  {st.name:21s} {st.state:8s} {st.reason}")


@app.command()
def show(
    session: SessionArg,
    stage: Annotated[str, typer.Argument(help="Stage name, e.g. features.")],
    rows: Annotated[int, typer.Option(help="Rows to print.")] = 20,
    columns: Annotated[
        str | None, typer.Option(help="Comma-separated columns to print (default: all).")
    ] = None,
) -> None:
    """Print a stage table (polars) with its provenance."""
    import json
    from pathlib import Path

    import polars as pl

    from pipeline.stages.runner import stage_path
    from pipeline.stages.tables import read_provenance, read_table

    path = stage_path(Path(session), stage)
    if not path.is_file():
        raise ArmsigError(f"{path}: no such stage output", fix=f"`pipeline status {session}`")
    typer.echo(json.dumps(read_provenance(path), indent=1, sort_keys=True))
    df = pl.DataFrame(read_table(path))  # a damaged file: one line, not a polars panic
    if columns:
        wanted = [c.strip() for c in columns.split(",") if c.strip()]
        unknown = [c for c in wanted if c not in df.columns]
        if unknown:
            raise ArmsigError(f"{path}: no column {unknown[0]!r}", expected=", ".join(df.columns))
        df = df.select(wanted)
    with pl.Config(tbl_rows=rows, tbl_cols=-1, tbl_width_chars=4000, fmt_str_lengths=60):
        typer.echo(df.head(rows))


@app.command()
def audit(
    session: SessionArg,
    as_json: JsonOption = False,
    configurations: Annotated[int, typer.Option(help="Random configurations.")] = 1000,
) -> None:
    """Compare the signature and the design model with a simulated session's truth."""
    from pipeline.rig.audit import audit as run_audit

    r = run_audit(session, configurations=configurations)
    if as_json:
        _print_json(r.to_dict())
        return
    typer.echo(f"{r.session}: {r.configurations} random configurations, best-fit base and tool")
    for name, e in (("signature", r.signature), ("design", r.design)):
        typer.echo(
            f"  {name:9s} position max {e.max_position_cm:.3e} cm  rms {e.rms_position_cm:.3e} cm"
            f"   orientation max {e.max_orientation_deg:.3e} deg"
            f"  rms {e.rms_orientation_deg:.3e} deg"
        )
    typer.echo(f"  design / signature RMS position error: {r.improvement:.1f}x")


@app.command()
def ik(
    session: SessionArg,
    pose: Annotated[
        tuple[float, float, float, float, float, float] | None,
        typer.Option(help="x y z (cm) rx ry rz (deg, fixed axes) in the design base frame."),
    ] = None,
    branch: Annotated[
        str | None, typer.Option(help="Puma branch, e.g. right-up-noflip (default: that of q^s).")
    ] = None,
    method: Annotated[str, typer.Option(help="nr (Newton-Raphson) or jacobi.")] = "nr",
    targets: Annotated[
        str | None, typer.Option(help="Arrow file: x_cm y_cm z_cm rx_deg ry_deg rz_deg [branch].")
    ] = None,
    out: Annotated[str | None, typer.Option(help="Arrow file for the joints of --targets.")] = None,
    tool: Annotated[
        tuple[float, float, float, float, float, float] | None,
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
    as_json: JsonOption = False,
) -> None:
    """Joint readings that put the identified tool at a pose (signature-based control)."""
    import numpy as np

    from pipeline.control.controller import solve_poses
    from pipeline.control.targets import solve_arrow
    from pipeline.kinematics.ik import STATUS_NAMES
    from pipeline.kinematics.transforms import transform_from_xyz_rpy

    ctl = session_controller(session)
    q_near = None if near is None else np.array(_joint_values(near, "--near"))
    tool_label = "signature"
    if tool is not None:
        _finite(tool, "--tool")
        ctl = ctl.with_tool(transform_from_xyz_rpy(tool[:3], np.deg2rad(tool[3:])))
        tool_label = "flange " + " ".join(f"{v:g}" for v in tool)
    if targets is not None:
        if out is None:
            raise ArmsigError("--targets needs --out", fix="--out joints.arrow")
        if pose is not None:
            raise ArmsigError(
                "--pose and --targets both given", expected="one of them", fix="drop one"
            )
        summary, failed = solve_arrow(ctl, targets, out, method, tool_label, q_near)
        if as_json:
            from pathlib import Path

            from pipeline.stages.tables import read_table

            n = read_table(Path(out)).num_rows
            _print_json(
                {"targets": n, "converged": n - failed, "failed": failed, "out": out,
                 "method": method, "tool": tool_label}
            )  # fmt: skip
        else:
            typer.echo(summary)
        if failed:
            raise typer.Exit(EXIT_NOT_REACHED)
        return
    if pose is None:
        raise ArmsigError("give --pose x y z rx ry rz, or --targets FILE --out FILE")
    _finite(pose, "--pose")
    q, res = solve_poses(ctl, np.array(pose[:3]), np.array(pose[3:]), [branch], method, q_near)
    units = [j.unit for j in ctl.robot.joints]
    status_name = STATUS_NAMES[int(res.status[0])]
    changed = res.branch_changed is not None and res.branch_changed[0]
    lim = ctl.robot.limits
    outside = [
        j.name
        for j, v, (lo, hi) in zip(ctl.robot.joints, q[0], lim, strict=True)
        if not lo <= v <= hi
    ]
    if as_json:
        _print_json(
            {
                "joints": [j.name for j in ctl.robot.joints],
                "units": units,
                "q": [float(v) for v in q[0]],
                "status": status_name,
                "converged": bool(res.converged[0]),
                "iterations": int(res.iterations[0]),
                "position_error_cm": float(res.position_error_cm[0]),
                "orientation_error_deg": float(np.degrees(res.orientation_error_rad[0])),
                "outside_limits": outside,
                "branch_changed": bool(changed),
                "tool": tool_label,
            }
        )
    else:
        typer.echo("q = " + "  ".join(f"{v:.4f} {u}" for v, u in zip(q[0], units, strict=True)))
        typer.echo(
            f"{status_name} after {int(res.iterations[0])} iterations; "
            f"residual {res.position_error_cm[0]:.2e} cm, "
            f"{np.degrees(res.orientation_error_rad[0]):.2e} deg"
        )
    if outside:
        typer.echo(f"warning: outside joint limits: {', '.join(outside)}", err=True)
    if changed:
        typer.echo("warning: no solution on the requested branch; this one is on another",
                   err=True)  # fmt: skip
    if not res.converged[0]:
        raise typer.Exit(EXIT_NOT_REACHED)


@app.command("ik-convergence")
def ik_convergence(
    session: SessionArg,
    seed: Annotated[
        int, typer.Option(min=0, help="Seed of the target and the poor signature.")
    ] = 3,
) -> None:
    """Per-iteration errors of Newton-Raphson and Jacobi (Tables 5-1, 5-2, Section 5.4)."""
    from pipeline.control.convergence import convergence_tables, format_tables

    typer.echo(format_tables(convergence_tables(session, seed=seed)))


@app.command()
def evaluate(
    session: SessionArg,
    as_json: JsonOption = False,
    perfect_servo: Annotated[
        bool, typer.Option(help="Simulated rig: no servo error, no encoder rounding.")
    ] = False,
    exact_instruments: Annotated[
        bool, typer.Option(help="Simulated rig: instrument readings not quantized.")
    ] = False,
    report: Annotated[bool, typer.Option(help="Write report/evaluation.md.")] = True,
) -> None:
    """Grid-touching tasks under design-model and signature control, recorded and scored."""
    from pipeline.evaluate import evaluate as run_evaluate

    rig = None
    if perfect_servo or exact_instruments:
        from pipeline.rig.evaluation import EvaluationRigOptions

        rig = EvaluationRigOptions(perfect_servo, exact_instruments)
    r = run_evaluate(session, rig=rig, report=report, progress=sys.stderr)
    if as_json:
        _print_json(r.summary)
        return
    for run in r.runs:
        typer.echo(f"  {run.name:22s} {run.action}")
    if r.recorded:
        typer.echo(f"  rig recorded: {', '.join(r.recorded)}")
    for name, task in r.summary["tasks"].items():
        med = task["median_improvement"]
        text = "inf" if med is None else f"{med:.2f}"
        typer.echo(f"{name:8s} {len(task['indices']):3d} indices, median improvement {text}")
    for name, why in r.summary["skipped"].items():
        typer.echo(f"warning: {name} skipped: {why}", err=True)
    if r.report:
        typer.echo(f"report: {r.report}")


@app.command()
def viz(
    session: SessionArg,
    q: Annotated[
        str | None,
        typer.Option(
            "--q",
            help="Joint values of the link frames, comma or space separated (deg / cm); "
            "default: the signature configuration q^s.",
        ),
    ] = None,
    out: Annotated[
        str | None, typer.Option(help="Output MCAP file (default: SESSION/viz.mcap).")
    ] = None,
) -> None:
    """Write viz.mcap for Foxglove's 3-D panel: frames, fitted features, measured points (m)."""
    from pipeline.viz.write import viz as run_viz

    r = run_viz(session, None if q is None else _joint_values(q, "--q"), out)
    shown = " ".join(f"{v:g}" for v in r.configuration)
    typer.echo(f"wrote {r.path}: {sum(r.topics.values())} messages on {len(r.topics)} topics")
    typer.echo(f"link frames at q = {shown} (deg / cm); lengths in metres")
    if r.outside_limits:
        typer.echo(f"warning: outside joint limits: {', '.join(r.outside_limits)}", err=True)


@app.command()
def export(
    session: SessionArg,
    format_: Annotated[
        str, typer.Option("--format", help="urdf, dh, mdh (Craig) or json (docs/export.md).")
    ],
    out: Annotated[
        str | None,
        typer.Option(help="Output file (default: SESSION/export/); an existing one needs --force."),
    ] = None,
    design: Annotated[bool, typer.Option(help="Export the design model instead.")] = False,
    frame: Annotated[
        str, typer.Option(help="World frame: sensor, or design-base (via the design alignment).")
    ] = "sensor",
    force: Annotated[bool, typer.Option(help="Replace an existing --out file.")] = False,
    as_json: JsonOption = False,
) -> None:
    """Export the session's signature (checked against its FK) as URDF, D-H or JSON."""
    from pipeline.export import export as run_export

    r = run_export(session, format_, out=out, design=design, frame=frame, force=force)
    if as_json:
        _print_json(r.to_dict())
        return
    typer.echo(
        f"wrote {r.path} ({r.model}, {r.frame} frame); reproduces the chain at "
        f"{r.configurations} configurations to {r.max_position_error_m:.1e} m, "
        f"{r.max_orientation_error_rad:.1e} rad"
    )


fleet_app = typer.Typer(
    help="Many sessions at once on Dask: one task per session, one fleet.arrow for all.",
    no_args_is_help=True,
)
app.add_typer(fleet_app, name="fleet")

FleetDirs = Annotated[
    list[str], typer.Argument(help="Session folders, or folders to search for sessions.")
]
SchedulerOption = Annotated[
    str | None,
    typer.Option(
        help="Dask scheduler tcp://HOST:PORT (else $DASK_SCHEDULER_ADDRESS, else a local "
        "cluster for this command; `local` forces it)."
    ),
]
FleetWorkers = Annotated[
    int | None,
    typer.Option(min=1, max=256, help="Workers of the local cluster (default: the cores)."),
]
FleetOut = Annotated[
    str | None, typer.Option(help="Folder of fleet.arrow (default: the first DIR).")
]


def _fleet(
    command: str, dirs: list[str], scheduler: str | None, workers: int | None, out: str | None
) -> None:
    """Run ``command`` over the sessions; print one line per session, and refuse (exit 1)
    when any session failed, after every other one is done and fleet.arrow is written."""
    from pipeline.atomic import check_writable
    from pipeline.fleet.engine import FLEET_PRELOAD, dask_client
    from pipeline.fleet.run import find_sessions, run_fleet

    sessions = find_sessions(dirs)  # refused before a cluster starts
    folder = check_writable(out or dirs[0], "--out", folder=True)
    with dask_client(scheduler, workers, preload=FLEET_PRELOAD, share_cores=True) as client:
        r = run_fleet(command, sessions, client, folder, progress=sys.stderr)
    for row in r.rows:
        if row["error"] is not None:
            typer.echo(f"  FAILED {row['session']}: {row['error']}")
            continue
        extra = (
            f"  check RMS {row['check_rms_cm']:.4g} cm" if row["check_rms_cm"] is not None
            else ""
        ) + (
            f"  gain {row['gain_evaluation']:.3g}" if row["gain_evaluation"] is not None else ""
        )  # fmt: skip
        typer.echo(f"  ok     {row['session']}: {row['signature_sha256'][:12]}{extra}")
        for w in row["warnings"]:
            typer.echo(f"warning: {row['session']}: {w}", err=True)
    typer.echo(f"{len(r.rows)} sessions in {r.wall_s:.1f} s; wrote {r.table}")
    if r.failed:
        raise ArmsigError(
            f"{len(r.failed)} of {len(r.rows)} sessions failed (the others are done)",
            fix=f"see the error column of {r.table}; a rerun redoes only what is stale",
        )


@fleet_app.command("identify")
def fleet_identify(
    dirs: FleetDirs,
    scheduler: SchedulerOption = None,
    workers: FleetWorkers = None,
    out: FleetOut = None,
) -> None:
    """`pipeline identify` on every session, one Dask task each; writes fleet.arrow."""
    _fleet("identify", dirs, scheduler, workers, out)


@fleet_app.command("evaluate")
def fleet_evaluate(
    dirs: FleetDirs,
    scheduler: SchedulerOption = None,
    workers: FleetWorkers = None,
    out: FleetOut = None,
) -> None:
    """`pipeline evaluate` on every session (design vs signature gain); writes fleet.arrow."""
    _fleet("evaluate", dirs, scheduler, workers, out)


@fleet_app.command("validate")
def fleet_validate(
    dirs: FleetDirs,
    scheduler: SchedulerOption = None,
    workers: FleetWorkers = None,
    out: FleetOut = None,
) -> None:
    """The validation (check) errors of every point session; sonic sessions have none."""
    _fleet("validate", dirs, scheduler, workers, out)


@fleet_app.command("report")
def fleet_report(
    folder: Annotated[str, typer.Argument(help="Folder holding fleet.arrow.")],
) -> None:
    """Write FOLDER/fleet-report/fleet.md with figures from FOLDER/fleet.arrow."""
    from pipeline.fleet.report import write_fleet_report

    typer.echo(f"wrote {write_fleet_report(folder)}")


@app.command()
def montecarlo(
    study: Annotated[
        str,
        typer.Option(
            help="encoder, machining, noise, points, radius, misalignment, features, refine "
            "(S-Model against refined signature; whole simulate + identify sessions, ~1.8 s of "
            "CPU per robot and setting) or all (refine last)."
        ),
    ],
    robots: Annotated[
        int, typer.Option(min=2, max=100_000, help="Simulated robots per setting.")
    ] = 500,
    seed: Annotated[int, typer.Option(min=0, help="Study seed (same seed, same numbers).")] = 0,
    out: Annotated[str, typer.Option(help="Output folder.")] = "montecarlo",
    workers: Annotated[
        int, typer.Option(min=1, max=256, help="Worker processes (or local Dask workers).")
    ] = 1,
    scheduler: Annotated[
        str | None,
        typer.Option(
            help="Run the batches on Dask: tcp://HOST:PORT, or `local` for a local cluster "
            "of --workers (same numbers as without)."
        ),
    ] = None,
) -> None:
    """Monte-Carlo study of design-model and signature control (Chapter 7, Appendix G)."""
    from pipeline.montecarlo.studies import run_montecarlo

    if scheduler is None:
        lines = run_montecarlo(study, robots, seed, out, workers, progress=sys.stderr)
    else:
        from pipeline.fleet.engine import dask_client

        with dask_client(scheduler, workers) as client:
            lines = run_montecarlo(study, robots, seed, out, progress=sys.stderr, client=client)
    for line in lines:
        typer.echo(line)


if __name__ == "__main__":  # pragma: no cover
    app()
