"""``pipeline plan``: the poses, or the joint sweeps, that give a wanted accuracy
(docs/plan.md): a tracker's poses (:mod:`pipeline.planning`), a camera's
(:mod:`pipeline.planning.camera`, docs/camera.md) or joint sweeps
(:mod:`pipeline.planning.sweeps`)."""

from __future__ import annotations

import math
from typing import Annotated, Any

import typer

from pipeline.cli.options import (
    DISTORTION,
    FOCAL_PX,
    PIXEL_NOISE,
    RESOLUTION,
    DistortionOption,
    FocalOption,
    JsonOption,
    PixelNoiseOption,
    ResolutionOption,
    Sensor,
    Setup,
    SetupOption,
    TargetFileOption,
    choice,
    distortion_terms,
    optional_session_path,
    resolution_px,
)
from pipeline.cli.output import print_json, warn
from pipeline.errors import ArmsigError, positive_in_range

commands = typer.Typer()


@commands.command("plan")
def plan_(
    out: Annotated[
        str, typer.Argument(help="The plan to write (CSV of joint readings, docs/plan.md).")
    ],
    robot: Annotated[
        str | None, typer.Option(help="Built-in robot name or description .toml.")
    ] = None,
    from_session: Annotated[
        str | None,
        typer.Option(
            "--from",
            help="An identified session with a pose set (a folder, or a NAME for "
            "sessions/NAME): choose its most informative poses (re-calibration with fewer), "
            "instead of random candidates of --robot.",
            callback=optional_session_path,
        ),
    ] = None,
    poses: Annotated[int | None, typer.Option(min=1, help="Poses to plan (at most; 50).")] = None,
    target_rms_mm: Annotated[
        float | None,
        typer.Option(
            help="Plan the fewest measurements whose audited RMS tool error stays under this "
            "with 95 % probability."
        ),
    ] = None,
    sigma_mm: Annotated[
        float | None,
        typer.Option(help="Point noise per coordinate (default: the sensor's law, docs/rig.md)."),
    ] = None,
    candidates: Annotated[
        int | None,
        typer.Option(min=1, help="Random candidate poses (10,000; a camera's seen: 3,000)."),
    ] = None,
    seed: Annotated[int, typer.Option(min=0, help="Seed of the candidates.")] = 0,
    sweeps: Annotated[
        bool,
        typer.Option(
            "--sweeps",
            help="Plan joint sweeps (points per sweep and range per joint, (6.11)-(6.13)) "
            "instead of poses.",
        ),
    ] = False,
    sensor: Annotated[
        Sensor | None,
        choice(
            "sonic (sweeps only; their default), tracker (the default for poses) or camera "
            "(poses for a camera calibration, --setup; docs/camera.md)."
        ),
    ] = None,
    setup: SetupOption = Setup.eye_to_hand,
    target_file: TargetFileOption = "",
    resolution: ResolutionOption = RESOLUTION,
    focal_px: FocalOption = FOCAL_PX,
    distortion: DistortionOption = DISTORTION,
    pixel_noise: PixelNoiseOption = PIXEL_NOISE,
    plane_sigma_deg: Annotated[
        float | None, typer.Option(help="Sweeps: wanted σ of every plane-of-rotation (deg).")
    ] = None,
    center_sigma_mm: Annotated[
        float | None, typer.Option(help="Sweeps: wanted σ of every center-of-rotation (mm).")
    ] = None,
    points: Annotated[
        int | None, typer.Option(min=5, max=1000, help="Sweeps: points per sweep, N_i, fixed.")
    ] = None,
    repeats: Annotated[
        int, typer.Option(min=1, max=100, help="Sweeps, sonic: cycles per position, N_avg.")
    ] = 10,
    json_out: JsonOption = False,
    force: Annotated[bool, typer.Option(help="Replace an existing file.")] = False,
) -> None:
    """Plan a measurement: the poses, or the joint sweeps, that give a wanted accuracy
    (docs/plan.md)."""
    from pipeline.planning import plan_from_session, plan_poses, write_plan
    from pipeline.planning.camera import plan_from_camera_session
    from pipeline.robots import get_robot
    from pipeline.stages.recording_points import MAX_SIGMA_CM, MIN_SIGMA_CM

    for name, value, low, high, unit, example in (
        ("--sigma-mm", sigma_mm, MIN_SIGMA_CM * 10, MAX_SIGMA_CM * 10, "mm", "0.02"),
        ("--target-rms-mm", target_rms_mm, 0.0, math.inf, "mm", "0.1"),
        ("--center-sigma-mm", center_sigma_mm, 0.0, math.inf, "mm", "0.02"),
        ("--plane-sigma-deg", plane_sigma_deg, 0.0, math.inf, "deg", "0.005"),
    ):
        positive_in_range(name, value, low, high, unit=unit, fix=f"{name} {example}")
    target = None if target_rms_mm is None else target_rms_mm / 10.0
    sigma = None if sigma_mm is None else sigma_mm / 10.0
    if (robot is None) == (from_session is None):
        raise ArmsigError(
            "plan needs one of --robot and --from",
            expected="--robot ROBOT (random candidates) or --from SESSION (its recorded poses)",
            fix="pipeline plan OUT.csv --robot puma560 --poses 50",
        )
    camera_given = {"--setup": setup != Setup.eye_to_hand, "--target": target_file != "",
                    "--resolution": resolution != RESOLUTION, "--focal-px": focal_px != FOCAL_PX,
                    "--distortion": distortion != DISTORTION,
                    "--pixel-noise": pixel_noise != PIXEL_NOISE}  # fmt: skip
    camera_session = from_session is not None and _camera_session(from_session)
    if sensor != Sensor.camera and not camera_session and any(camera_given.values()):
        what = next(k for k, v in camera_given.items() if v)
        raise ArmsigError(f"{what} is for --sensor camera",
                          fix=f"add --sensor camera, or drop {what}")  # fmt: skip
    sweep_only = {"--plane-sigma-deg": plane_sigma_deg, "--center-sigma-mm": center_sigma_mm,
                  "--points": points}  # fmt: skip
    if sweeps:
        if sensor == Sensor.camera:
            raise ArmsigError("--sweeps plans joint sweeps of a point sensor, not a camera's "
                              "images", expected="--sensor sonic or tracker with --sweeps",
                              fix="drop --sweeps (a camera plan is poses)")  # fmt: skip
        if from_session is not None or poses is not None:
            raise ArmsigError("--sweeps plans joint sweeps, not poses",
                              fix="drop --from and --poses (or --sweeps)")  # fmt: skip
        assert robot is not None
        _sweep_plan(out, get_robot(robot), sensor or Sensor.sonic, plane_sigma_deg,
                    None if center_sigma_mm is None else center_sigma_mm / 10.0, target, sigma,
                    points, repeats, json_out, force, robot)  # fmt: skip
        return
    given = [k for k, v in sweep_only.items() if v is not None]
    if given or sensor == Sensor.sonic:
        what = (given or ["--sensor sonic"])[0]
        fix = "add --sweeps, or drop it (pose plans are the tracker's)"
        raise ArmsigError(f"{what} is for sweep plans", fix=fix)
    n_poses = 50 if poses is None else poses
    inputs: list[str] = []  # what the plan was made from: never overwritten by --force
    if sensor == Sensor.camera or camera_session:
        if sigma is not None:
            raise ArmsigError("--sigma-mm is a tracker's point noise",
                              fix="--pixel-noise for a camera")  # fmt: skip
    if from_session is not None and (sensor == Sensor.camera or camera_session):
        if any(camera_given.values()):
            what = next(k for k, v in camera_given.items() if v)
            raise ArmsigError(f"{what} with --from: the session's own camera is planned",
                              fix=f"drop {what}")  # fmt: skip
        rob, result = plan_from_camera_session(from_session, n_poses, target)
    elif sensor == Sensor.camera:
        assert robot is not None
        rob = get_robot(robot)
        result = _camera_plan(rob, n_poses, target, candidates, seed, setup, target_file,
                              resolution, focal_px, distortion, pixel_noise)  # fmt: skip
        inputs = [robot, *([target_file] if target_file else [])]
    elif from_session is not None:
        if sigma is not None:
            raise ArmsigError("--sigma-mm is for --robot", fix="drop --sigma-mm: --from "
                              "weighs each pose by its recorded noise")  # fmt: skip
        rob, result = plan_from_session(from_session, n_poses, target)
    else:
        assert robot is not None
        rob = get_robot(robot)
        result = plan_poses(rob, n_poses, target, sigma, candidates or 10_000, seed)
        inputs = [robot]
    what = (f"camera {setup.value}" if robot is not None else "camera") if (
        sensor == Sensor.camera or camera_session) else ""  # fmt: skip
    path = write_plan(out, rob, result, force, inputs=inputs, sensor=what)
    if json_out:
        print_json({"path": str(path), **result.to_dict()})
        return
    typer.echo(
        f"wrote {path}: {len(result.q)} {'images' if what else 'poses'}, predicted RMS tool error "
        f"{result.rms_cm * 10:.3g} mm (under {result.rms_q95_cm * 10:.3g} mm with 95 % "
        f"probability; 95 % of the workspace under {result.p95_cm * 10:.3g} mm); "
        f"as many random {'visible ' if what else ''}poses: {result.random_rms_cm * 10:.3g} mm"
    )
    _warn_plan(target, target_rms_mm, result.rms_q95_cm, result.unidentified, "poses (--poses)")


def _warn_plan(
    target: float | None, target_mm: float | None, q95: float, unidentified: tuple[str, ...],
    more: str,
) -> None:  # fmt: skip
    """The warnings of ``plan``: a target not met, parameters not identifiable."""
    if target is not None and q95 > target:
        typer.echo(
            f"warning: the plan stays under {q95 * 10:.3g} mm with 95 % probability, above "
            f"the target {target_mm:g} mm; plan more {more}",
            err=True,
        )
    if unidentified:
        typer.echo("warning: not identifiable from this plan: " + ", ".join(unidentified),
                   err=True)  # fmt: skip


def _sweep_plan(
    out: str,
    robot: Any,
    sensor: Sensor,
    plane_sigma_deg: float | None,
    center_sigma_cm: float | None,
    target: float | None,
    sigma: float | None,
    points: int | None,
    repeats: int,
    json_out: bool,
    force: bool,
    source: str,
) -> None:
    """``plan --sweeps``: :func:`pipeline.planning.sweeps.plan_sweeps`, written and printed
    (``source``: the robot as given, an input ``--force`` never replaces)."""
    from pipeline.cli.output import print_json
    from pipeline.features.accuracy import MAX_POINTS
    from pipeline.planning.sweeps import plan_sweeps, write_sweep_plan

    plan = plan_sweeps(robot, sensor.value, plane_sigma_deg, center_sigma_cm, target, sigma,
                       points, repeats)  # fmt: skip
    path = write_sweep_plan(out, robot, plan, force, inputs=(source,))
    if json_out:
        print_json({"path": str(path), **plan.to_dict()})
        return
    typer.echo(f"wrote {path}: {plan.positions} positions ({sensor.value}"
               + (f", {plan.n_avg} cycles each" if plan.n_avg > 1 else "") + ")")  # fmt: skip
    typer.echo("joint          range              radius  points  plane σ_δ   center σ_c  law")
    for s in plan.sweeps:
        typer.echo(
            f"{s.joint} {s.name:11s} {s.first:7.1f} .. {s.last:7.1f} {s.radius_cm:6.2f} cm "
            f"{s.points:6d}  {s.plane_sigma_deg:8.3g}°  {s.center_sigma_cm * 10:8.3g} mm  {s.law}"
        )
    typer.echo(
        f"predicted RMS tool error {plan.rms_cm * 10:.3g} mm (under {plan.rms_q95_cm * 10:.3g} "
        f"mm with 95 % probability; 95 % of the workspace under {plan.p95_cm * 10:.3g} mm)"
    )
    unmet = [f"{s.joint} {s.name}" for s in plan.sweeps if s.law != "line" and (
        (plane_sigma_deg is not None and s.plane_sigma_deg > plane_sigma_deg)
        or (center_sigma_cm is not None and s.center_sigma_cm > center_sigma_cm))]  # fmt: skip
    if unmet:
        warn(
            f"the wanted plane / center σ is not met by sweep {', '.join(unmet)} at "
            f"{points or MAX_POINTS} points per sweep (the table says what is reached); "
            + ("drop --points" if points else "measure a longer sweep or with less noise")
        )
    more = "points (--target-rms-mm is capped at 1000 per sweep)"
    target_mm = None if target is None else target * 10
    _warn_plan(target, target_mm, plan.rms_q95_cm, plan.unidentified, more)


def _camera_session(folder: str) -> bool:
    """Whether ``folder`` is an identified camera session (it has a ``camera_fit``)."""
    from pathlib import Path

    from pipeline.stages.runner import stage_path

    return stage_path(Path(folder), "camera_fit").is_file()


def _camera_plan(
    robot: Any, n_poses: int, target: float | None, candidates: int | None, seed: int,
    setup: Setup, target_file: str, resolution: str, focal_px: float, distortion: str,
    pixel_noise: float,
) -> Any:  # fmt: skip
    """``plan --sensor camera``: :func:`pipeline.planning.camera.plan_camera_poses` of the
    camera ``simulate --sensor camera`` takes."""
    from pipeline.planning.camera import CANDIDATES, camera_rig, plan_camera_poses
    from pipeline.rig.camera_session import read_target

    rig = camera_rig(setup.value, read_target(target_file), resolution_px(resolution), focal_px,
                     distortion_terms(distortion), pixel_noise)  # fmt: skip
    return plan_camera_poses(robot, rig, n_poses, target, candidates or CANDIDATES, seed)
