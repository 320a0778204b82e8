"""Recording commands: the built-in robots, and a session recorded on the simulated rig
or imported from a file of measured points (robots, simulate, import)."""

from __future__ import annotations

import dataclasses
from typing import Annotated, Any

import typer

from pipeline.cli.options import (
    DISTORTION,
    FOCAL_PX,
    PIXEL_NOISE,
    RESOLUTION,
    Air,
    DistortionOption,
    Fault,
    FocalOption,
    ForceRecording,
    ImportFormat,
    JsonOption,
    NewSessionArg,
    PixelNoiseOption,
    ResolutionOption,
    RobotIdOption,
    Sensor,
    Setup,
    SetupOption,
    StrictOption,
    TargetFileOption,
    choice,
    choice_list,
    choices_of,
    distortion_terms,
    joint_values,
    new_session_folder,
    resolution_px,
)
from pipeline.cli.output import print_json, warn
from pipeline.errors import ArmsigError

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
    setup: SetupOption = Setup.eye_to_hand,
    target: TargetFileOption = "",
    resolution: ResolutionOption = RESOLUTION,
    focal_px: FocalOption = FOCAL_PX,
    distortion: DistortionOption = DISTORTION,
    pixel_noise: PixelNoiseOption = PIXEL_NOISE,
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
