"""Recording commands: the built-in robots, and a session recorded on the simulated rig
or imported from a file of measured points (robots, simulate, import)."""

from __future__ import annotations

import dataclasses
import math
from typing import Annotated, Any

import typer

from pipeline.cli.options import (
    Air,
    Fault,
    ForceRecording,
    ImportFormat,
    JsonOption,
    NewSessionArg,
    RobotIdOption,
    Sensor,
    Setup,
    StrictOption,
    choice,
    choice_list,
    choices_of,
    joint_values,
    new_session_folder,
    optional_session_path,
)
from pipeline.cli.output import print_json, warn
from pipeline.errors import ArmsigError, positive_in_range

commands = typer.Typer()


@commands.command()
def robots(as_json: JsonOption = False) -> None:
    """List the built-in robots with their joints."""
    from pipeline.robots import builtin_names, get_robot

    described = [get_robot(name) for name in builtin_names()]
    if as_json:
        print_json(
            [_robot_dict(name, rob) for name, rob in zip(builtin_names(), described, strict=True)]
        )
        return
    for name, rob in zip(builtin_names(), described, strict=True):
        joints = ", ".join(
            f"{j.name} ({j.type[0].upper()}, {j.lower:g}..{j.upper:g} {j.unit})" for j in rob.joints
        )
        typer.echo(f"{name}: {rob.n_joints} joints: {joints}")


def _robot_dict(name: str, rob: Any) -> dict[str, Any]:
    """A built-in robot for ``robots --json``: its joints' types, limits and resolution."""
    joints = [
        {"name": j.name, "type": j.type, "unit": j.unit, "lower": j.lower, "upper": j.upper,
         "encoder_resolution": j.encoder_resolution}
        for j in rob.joints
    ]  # fmt: skip
    return {"name": name, "description": rob.name, "n_joints": rob.n_joints, "joints": joints}


@commands.command()
def simulate(
    name: NewSessionArg,
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
    faults: Annotated[str, choice_list("Comma-separated: bias, dropouts, outliers.", Fault)] = "",
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
        Sensor,
        choice(
            "sonic (the sparker digitizer), tracker (a laser tracker, docs/rig.md) or camera "
            "(a camera and a target, --setup; docs/camera.md)."
        ),
    ] = Sensor.sonic,
    setup: Annotated[
        Setup,
        choice(
            "Camera: eye-to-hand (a fixed camera watches a target on the flange) or "
            "eye-in-hand (a camera on the flange watches a fixed target)."
        ),
    ] = Setup.eye_to_hand,
    target: Annotated[
        str,
        typer.Option(
            help="Camera: target file (TOML, docs/camera.md); default a ChArUco "
            "board of 6 x 8 squares of 3.5 cm."
        ),
    ] = "",
    resolution: Annotated[
        str, typer.Option(help="Camera: image size in px, WIDTHxHEIGHT.")
    ] = "1280x960",
    focal_px: Annotated[
        float, typer.Option(min=10.0, max=100000.0, help="Camera: nominal focal length (px).")
    ] = 1000.0,
    distortion: Annotated[
        str, typer.Option(help="Camera: the true lens's k1, k2, p1, p2, k3 (OpenCV's order).")
    ] = "-0.12,0.05,0.0005,-0.0003,0",
    pixel_noise: Annotated[
        float, typer.Option(min=0.0, max=100.0, help="Camera: pixel noise σ per coordinate (px).")
    ] = 0.2,
    images: Annotated[
        bool,
        typer.Option(
            help="Camera: render every image (PNG beside the recording) and detect the target "
            "in it; --pixel-noise then only states σ (docs/camera.md)."
        ),
    ] = False,
    blur_px: Annotated[
        float, typer.Option(min=0.0, max=20.0, help="Camera --images: Gaussian blur σ (px).")
    ] = 0.5,
    grey_noise: Annotated[
        float,
        typer.Option(min=0.0, max=100.0, help="Camera --images: grey-level noise σ (of 255)."),
    ] = 2.0,
    vignette: Annotated[
        float,
        typer.Option(min=0.0, max=0.99, help="Camera --images: light lost in the corners (0-1)."),
    ] = 0.3,
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
    poses: Annotated[
        int,
        typer.Option(
            min=0, help="Tracker: random whole-arm configurations to identify from (sweep poses)."
        ),
    ] = 0,
    sweeps: Annotated[
        bool,
        typer.Option(
            help="Record the joint sweeps and the tool measurement (--no-sweeps: poses only)."
        ),
    ] = True,
    plan: Annotated[
        str,
        typer.Option(help="Tracker: record the poses of this pose plan (`pipeline plan`)."),
    ] = "",
    air: Annotated[
        Air,
        choice(
            "lab (temperature linear in height, one drift) or drifting (speed of sound "
            "linear in height, drifts of 8-45 min; also when noiseless), docs/rig.md."
        ),
    ] = Air.lab,
    log_jitter_s: Annotated[
        float,
        typer.Option(
            min=0.0, max=60.0, help="Log each measurement U(0, this) s after it was measured."
        ),
    ] = 0.0,
    six_d: Annotated[
        bool,
        typer.Option(
            "--six-d", help="Tracker: the pose set's tool target also measures its orientation."
        ),
    ] = False,
    compliance: Annotated[
        float,
        typer.Option(
            min=0.0,
            max=10.0,
            help="The true robot's joints deflect under gravity: RMS flange displacement "
            "over the joint ranges, mm (a UR10's ~0.3; docs/nongeometric.md).",
        ),
    ] = 0.0,
    joint_harmonics: Annotated[
        float,
        typer.Option(
            min=0.0,
            max=1.0,
            help="The true robot's joint-angle errors: first harmonic of each joint's own "
            "angle, RMS amplitude in deg (encoders and gears: ~0.005-0.02).",
        ),
    ] = 0.0,
    payloads: Annotated[
        str,
        typer.Option(
            help="Payloads on the flange, kg, comma separated: the pose set's poses cycle "
            "through them (recorded as joint_state payload_kg); two or more let the fit "
            "predict a changed payload (with --compliance)."
        ),
    ] = "",
    backlash_mm: Annotated[
        float,
        typer.Option(
            min=0.0,
            max=10.0,
            help="The true robot's joints have backlash under gravity, an error the model "
            "does not have: each sits b_j off its reading on the side its gravity torque "
            "pushes it to; RMS flange displacement over the joint ranges, mm "
            "(docs/rig.md#unmodelled-error-backlash).",
        ),
    ] = 0.0,
    robot_id: RobotIdOption = None,
    force: ForceRecording = False,
    as_json: JsonOption = False,
) -> None:
    """Record a simulated session: recording.mcap plus rig-truth.json."""
    from pipeline.rig.simulate import SimulationOptions, simulate_session
    from pipeline.rig.true_robot import ErrorSigmas

    folder = new_session_folder(name)
    opts = SimulationOptions(
        robot=robot,
        seed=seed,
        sigmas=ErrorSigmas(sigma_p, sigma_o, sigma_e),
        noise_factor=noise_factor,
        points=points,
        repeats=repeats,
        faults=choices_of(faults, Fault),
        wac_error_cm=wac_error_cm,
        noiseless=noiseless,
        max_sweep_deg=max_sweep_deg,
        resettle_counts=resettle_counts,
        sensor=sensor.value,
        targets=targets,
        nest_on_axis=nest_on_axis,
        check=check,
        poses=poses,
        sweeps=sweeps,
        plan_file=plan,
        air=air.value,
        log_jitter_s=log_jitter_s,
        six_d=six_d,
        compliance_mm=compliance,
        harmonic_deg=joint_harmonics,
        payloads_kg=tuple(joint_values(payloads, "--payloads", "0,10")),
        backlash_mm=backlash_mm,
        robot_id=robot_id or "",
        setup=setup.value,
        target_file=target,
        resolution_px=resolution_px(resolution),
        focal_px=focal_px,
        distortion=distortion_terms(distortion),
        pixel_noise_px=pixel_noise,
        images=images,
        blur_px=blur_px,
        grey_noise=grey_noise,
        vignette=vignette,
    )
    path = simulate_session(folder, opts, force=force)
    truth = folder / "rig-truth.json"
    if as_json:
        print_json({"session": str(folder), "recording": str(path), "bytes": path.stat().st_size,
                    "rig_truth": str(truth), "options": dataclasses.asdict(opts)})  # fmt: skip
        return
    typer.echo(f"wrote {path} ({path.stat().st_size / 1e6:.2f} MB) and {truth}")


def resolution_px(text: str) -> tuple[int, int]:
    """``--resolution WIDTHxHEIGHT`` as (width, height) px."""
    parts = text.lower().split("x")
    if len(parts) != 2 or not all(p.strip().isdigit() for p in parts):
        raise ArmsigError("--resolution must be WIDTHxHEIGHT in px", got=repr(text),
                          fix="--resolution 1280x960")  # fmt: skip
    return int(parts[0]), int(parts[1])


def distortion_terms(text: str) -> tuple[float, float, float, float, float]:
    """``--distortion k1,k2,p1,p2,k3``: five numbers."""
    values = joint_values(text, "--distortion", "-0.12,0.05,0,0,0")
    if len(values) != 5:
        raise ArmsigError("--distortion needs five numbers: k1, k2, p1, p2, k3 (OpenCV's order)",
                          got=repr(text), fix="--distortion -0.12,0.05,0,0,0")  # fmt: skip
    k1, k2, p1, p2, k3 = values
    return k1, k2, p1, p2, k3


@commands.command("import")
def import_(
    file: Annotated[
        list[str],
        typer.Argument(
            help="The foreign file(s) of measured points: paths or quoted globs, in "
            "order (one data set; joined by row when the map names a file per "
            "column group); a ROS 2 bag folder; images: cal_data.yaml or a table."
        ),
    ],
    name: NewSessionArg,
    format: Annotated[
        ImportFormat, choice("sscanss2, table, rct, mat, rosbag2 or images (docs/import.md).")
    ],
    robot: Annotated[
        str | None,
        typer.Option(help="Robot description .toml of the measured machine (not for images)."),
    ] = None,
    map: Annotated[
        str | None, typer.Option(help="Map file (TOML): columns, units, sweeps (docs/import.md).")
    ] = None,
    robot_id: RobotIdOption = None,
    force: ForceRecording = False,
    strict: StrictOption = False,
    as_json: JsonOption = False,
) -> None:
    """Convert file(s) of measured points into a point session (recording.mcap), or camera
    images into a camera session: industrial_calibration's cal_data.yaml as it is, or a
    table of images with joint readings or flange poses and --map (docs/import.md)."""
    from pipeline.importers import import_file
    from pipeline.sweeps import CHECK_SWEEP, POSES_SWEEP

    folder = new_session_folder(name)
    if format.value == "images":
        if len(file) != 1:
            raise ArmsigError("--format images takes one file", got=f"{len(file)} files",
                              fix="give the cal_data.yaml or the table of images")  # fmt: skip
        _import_images(file[0], folder, map, robot, force, as_json)
        return
    if robot is None:
        raise ArmsigError(f"--format {format.value} needs --robot",
                          fix="--robot ROBOT.toml, the measured machine's description")  # fmt: skip
    out = import_file(list(file), format.value, robot, folder, map, force, strict, robot_id)
    n_check = int((out.rows.sweep == CHECK_SWEEP).sum())
    n_poses = int((out.rows.sweep == POSES_SWEEP).sum())
    if as_json:
        print_json(
            {
                "session": str(folder),
                "recording": str(out.recording),
                "format": format.value,
                "robot": out.robot.name,
                "configurations": len(out.rows.where),
                "poses": n_poses,
                "check": n_check,
                "targets": sorted(out.rows.targets),
                "rows_dropped": out.rows.dropped,
                "notes": list(out.rows.notes),
                "tool": {
                    "note": out.tool.note,
                    "rows": out.tool.rows.tolist(),
                    "signature_q": out.tool.signature_q.tolist(),
                    "warning": out.tool.warning,
                },
            }
        )
    else:
        poses = f"{n_poses} poses, " if n_poses else ""
        typer.echo(
            f"wrote {out.recording}: {len(out.rows.where)} configurations "
            f"({poses}{n_check} for validation), tool from {out.tool.note}"
        )
    for note in out.rows.notes:  # rows dropped, σ floored, a bag's moving samples: said
        warn(note)
    if out.tool.warning:
        warn(out.tool.warning)


def _import_images(
    file: str, folder: Any, map: str | None, robot: str | None, force: bool, as_json: bool
) -> None:
    """``import --format images``: detect, record, one line per dropped image."""
    from pipeline.importers.images import import_image_set

    s, recording = import_image_set(file, folder, force, map, robot)
    points = sum(len(e.found.point_ids) for e in s.images)
    if as_json:
        print_json({
            "session": str(folder), "recording": str(recording), "format": "images",
            "setup": s.setup, "target": s.target.to_dict(), "images": len(s.images),
            "kept": s.kept, "points": points, "dropped": s.drops(),
        })  # fmt: skip
    else:
        typer.echo(
            f"wrote {recording}: {len(s.images)} images ({s.setup}), {s.kept} kept, "
            f"{points} points; "
            + ("flange poses without joint readings: the arm is not calibrated"
               if s.robot is None else f"joint readings of {s.robot.name}")
        )  # fmt: skip
    for line in s.drops():
        warn(line)


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
    candidates: Annotated[int, typer.Option(min=1, help="Random candidate poses.")] = 10_000,
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
        choice("sonic (sweeps only; their default) or tracker (the default for poses)."),
    ] = None,
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
    sweep_only = {"--plane-sigma-deg": plane_sigma_deg, "--center-sigma-mm": center_sigma_mm,
                  "--points": points}  # fmt: skip
    if sweeps:
        if from_session is not None or poses is not None:
            raise ArmsigError("--sweeps plans joint sweeps, not poses",
                              fix="drop --from and --poses (or --sweeps)")  # fmt: skip
        assert robot is not None
        _sweep_plan(out, get_robot(robot), sensor or Sensor.sonic, plane_sigma_deg,
                    None if center_sigma_mm is None else center_sigma_mm / 10.0, target, sigma,
                    points, repeats, json_out, force, robot)  # fmt: skip
        return
    given = [k for k, v in sweep_only.items() if v is not None]
    if sensor == Sensor.camera:  # issue 39: poses for a camera calibration are not planned yet
        raise ArmsigError("pipeline plan plans a tracker's poses, not a camera's",
                          expected="--sensor tracker (or no --sensor)",
                          fix="simulate camera images at random poses (`pipeline simulate "
                          "NAME --sensor camera --poses 40`)")  # fmt: skip
    if given or sensor == Sensor.sonic:
        what = (given or ["--sensor sonic"])[0]
        fix = "add --sweeps, or drop it (pose plans are the tracker's)"
        raise ArmsigError(f"{what} is for sweep plans", fix=fix)
    n_poses = 50 if poses is None else poses
    if from_session is not None:
        if sigma is not None:
            raise ArmsigError("--sigma-mm is for --robot", fix="drop --sigma-mm: --from "
                              "weighs each pose by its recorded noise")  # fmt: skip
        rob, result = plan_from_session(from_session, n_poses, target)
    else:
        assert robot is not None
        rob = get_robot(robot)
        result = plan_poses(rob, n_poses, target, sigma, candidates, seed)
    path = write_plan(out, rob, result, force, inputs=[robot] if robot else [])
    if json_out:
        print_json({"path": str(path), **result.to_dict()})
        return
    typer.echo(
        f"wrote {path}: {len(result.q)} poses, predicted RMS tool error "
        f"{result.rms_cm * 10:.3g} mm (under {result.rms_q95_cm * 10:.3g} mm with 95 % "
        f"probability; 95 % of the workspace under {result.p95_cm * 10:.3g} mm); "
        f"as many random poses: {result.random_rms_cm * 10:.3g} mm"
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
