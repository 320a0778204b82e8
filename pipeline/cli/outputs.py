"""Output commands: a session's signature as files for other tools (export, viz)."""

from __future__ import annotations

from typing import Annotated

import typer

from pipeline.cli.options import (
    AcceptVerdict,
    ExportFormat,
    ExportFrame,
    JsonOption,
    SessionArg,
    choice,
    joint_values,
)
from pipeline.cli.output import print_json, report, warn, warn_outside_limits

commands = typer.Typer()


@commands.command()
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
    as_json: JsonOption = False,
) -> None:
    """Write viz.mcap for Foxglove's 3-D panel: frames, fitted features, measured points (m);
    of a camera session: its images with their corners, the frustum and both bodies."""
    from pipeline.viz.write import viz as run_viz

    r = run_viz(session, None if q is None else joint_values(q, "--q"), out)
    if as_json:  # the configuration in deg / cm, as --q takes it
        print_json(
            {
                "path": str(r.path),
                "messages": sum(r.topics.values()),
                "topics": r.topics,
                "configuration": r.configuration,
                "outside_limits": r.outside_limits,
                "display_frame": r.display_frame,
            }
        )
    else:
        shown = " ".join(f"{v:g}" for v in r.configuration)
        typer.echo(f"wrote {r.path}: {sum(r.topics.values())} messages on {len(r.topics)} topics")
        if r.configuration:
            typer.echo(f"link frames at q = {shown} (deg / cm); lengths in metres")
        else:  # a camera session (docs/viz.md): one image per second
            typer.echo("camera images, annotations and poses one per second; lengths in metres; "
                       f"display frame {r.display_frame}")  # fmt: skip
    warn_outside_limits(r.outside_limits)


@commands.command()
def export(
    session: SessionArg,
    format_: Annotated[
        ExportFormat | None,
        choice(
            "urdf, dh, mdh (Craig), json, ur-kinematics (UR's kinematics.yaml) or "
            "camera-info (a camera session's lens, ROS camera_info YAML) (docs/export.md); "
            "urdf with --onto.",
            "--format",
        ),
    ] = None,
    out: Annotated[
        str | None,
        typer.Option(help="Output file (default: SESSION/export/); an existing one needs --force."),
    ] = None,
    design: Annotated[bool, typer.Option(help="Export the design model instead.")] = False,
    frame: Annotated[
        ExportFrame | None,
        choice(
            "World frame: sensor, or design-base (the robot's base, via the design alignment; "
            "the default of urdf)."
        ),
    ] = None,
    onto: Annotated[
        str | None,
        typer.Option(
            help="A vendor URDF of this robot model: write it with the signature's joint "
            "origins and offsets, keeping its links, meshes, inertias and limits."
        ),
    ] = None,
    joint_map: Annotated[
        str | None,
        typer.Option(help="With --onto: armsig=vendor joint names, comma separated."),
    ] = None,
    offsets_only: Annotated[
        bool,
        typer.Option(
            help="With --onto: the signature as joint offsets alone, in <calibration "
            "rising> tags (robot_calibration's drivers), the vendor's geometry kept; "
            "states what that loses."
        ),
    ] = False,
    over: Annotated[
        str | None,
        typer.Option(
            help="A signature with non-geometric terms: fit the file's rigid chain over the "
            "configurations of this file (fk --q-file's: q1_deg, ...; Arrow or CSV), where "
            "the robot works, instead of 5,000 within the joint limits (a rigid signature is "
            "written exactly: not read)."
        ),
    ] = None,
    force: Annotated[bool, typer.Option(help="Replace an existing --out file.")] = False,
    accept_verdict: AcceptVerdict = False,
    as_json: JsonOption = False,
) -> None:
    """Export the session's signature (checked against its FK) as URDF, D-H or JSON, or
    onto a vendor's URDF."""
    from pipeline.errors import ArmsigError

    if onto is not None:
        if design or frame is not None or format_ not in (None, ExportFormat.urdf):
            raise ArmsigError(
                "--onto writes the signature into the vendor's URDF, in the vendor's root frame",
                expected="no --design, --frame, or --format other than urdf",
            )
        if offsets_only:
            from pipeline.export.offsets import export_offsets

            f = export_offsets(session, onto, out, joint_map, force, accept_verdict, over)
            shown = ", ".join(f"{k} {v:+.6g}" for k, v in f.offsets.items())
            report(f, as_json, f"wrote {f.path} ({f.vendor} with joint offsets of {session}: "
                   f"{shown} deg / cm; held: {', '.join(f.held) or 'none'})")  # fmt: skip
            warn(f.text())
            return
        from pipeline.export.onto import export_onto

        o = export_onto(session, onto, out, joint_map, force, accept_verdict, over)
        moved = max(o.origin_moves_mm.values())
        report(
            o,
            as_json,
            f"wrote {o.path} ({o.vendor} with the signature of {session}); same robot to "
            f"{o.same_robot_m:.1e} m; origins moved by up to {moved:.3g} mm; reproduces "
            f"the signature at {o.configurations} configurations to "
            f"{o.max_position_error_m:.1e} m, {o.max_orientation_error_rad:.1e} rad",
        )
        for w in (o.conventions_warning, o.sidecar_warning):
            if w:
                warn(w)
        return
    if offsets_only:
        raise ArmsigError("--offsets-only goes with --onto VENDOR.urdf")
    if format_ is ExportFormat.ur_kinematics:
        if design or frame is not None or joint_map is not None:
            raise ArmsigError(
                "--format ur-kinematics writes the signature in UR's own frames",
                expected="no --design, --frame or --joint-map",
            )
        from pipeline.export.ur_kinematics import export_ur_kinematics

        u = export_ur_kinematics(session, out, force, accept_verdict, over)
        report(
            u,
            as_json,
            f"wrote {u.path} (UR kinematics.yaml of {session}, hash {u.hash}); the xacro's "
            f"chain reproduces the calibrated chain at {u.configurations} configurations to "
            f"{u.max_position_error_m:.1e} m, {u.max_orientation_error_rad:.1e} rad",
        )
        if u.sidecar_warning:
            warn(u.sidecar_warning)
        return
    if format_ is ExportFormat.camera_info:
        if design or frame is not None or joint_map is not None or over is not None:
            raise ArmsigError(
                "--format camera-info writes the camera session's lens",
                expected="no --design, --frame, --joint-map or --over",
            )
        from pipeline.export.camera_info import export_camera_info

        c = export_camera_info(session, out, force, accept_verdict)
        report(c, as_json, f"wrote {c.path} (ROS camera_info of {session}'s lens; read back to "
               f"{c.max_relative_error:.1e} relative)")  # fmt: skip
        if c.verdict_warning:
            warn(c.verdict_warning)
        return
    if format_ is None or joint_map is not None:
        raise ArmsigError(
            "export needs --format (urdf, dh, mdh, json), or --onto VENDOR.urdf"
            + (" (--joint-map goes with --onto)" if joint_map is not None else "")
        )
    from pipeline.export import export as run_export

    r = run_export(
        session,
        format_.value,
        out=out,
        design=design,
        frame=None if frame is None else frame.value,
        force=force,
        accept_verdict=accept_verdict,
        over=over,
    )
    report(
        r,
        as_json,
        f"wrote {r.path} ({r.model}, {r.frame} frame); reproduces the chain at "
        f"{r.configurations} configurations to {r.max_position_error_m:.1e} m, "
        f"{r.max_orientation_error_rad:.1e} rad",
    )
    if r.sidecar_warning:
        warn(r.sidecar_warning)
