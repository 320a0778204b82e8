"""Record a simulated camera session (``pipeline simulate NAME --sensor camera``).

The recording: ``/rig/description`` (sensor ``camera``: the set-up, the lens as the rig
states it, the target), ``/robot/description`` (a pose set, sweep ``poses``, one image per
configuration), ``/robot/joint_state`` and ``/camera/detections`` (per image: the point
ids found, their pixels and σ). ``rig-truth.json``: the true robot in the frame of the
fixed part (the camera for eye-to-hand, the target for eye-in-hand: the ``sensor`` frame
of the audit), the tool point (the target's origin, or the camera's centre, in the last
link), and under ``camera`` the true lens, both hand-eye transforms and the images a
detector dropped (:mod:`pipeline.rig.camera`).

With ``images`` (``--images``, issue 40) the detections are not the projected truth plus
noise: every image is rendered and detected (:mod:`pipeline.rig.camera_images`), the
PNGs written under ``images/`` and referenced by ``/camera/images`` (``/rig/description``
``images_dir``); an image the detector drops keeps its reference (after the kept ones)
and has no joint state.

With a pose plan (``--plan``, :func:`pipeline.planning.camera.plan_camera_poses`) the
images are taken at the plan's poses in its order; the ones the detector drops at the
true rig are left out (``rig-truth.json`` ``camera.dropped_images``, and ``plan_steps``:
the plan's step of every recorded image).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pipeline.contract.channels import CAMERA_IMAGE_CHANNELS
from pipeline.errors import ArmsigError
from pipeline.kinematics.chain import link_frames
from pipeline.kinematics.transforms import invert_transform
from pipeline.rig import camera
from pipeline.rig.options import SimulationOptions
from pipeline.rig.pose_file import read_pose_plan
from pipeline.rig.recorder import Message, refuse_existing_recording
from pipeline.rig.session_files import (
    T0_NS,
    joint_state,
    logged,
    robot_message,
    truth_common,
    write_session,
)
from pipeline.rig.true_robot import draw_true_robot
from pipeline.robots import get_robot
from pipeline.sensor.camera import project
from pipeline.sensor.target import Target, target_from_toml
from pipeline.units import joints_to_internal

IMAGE_S = 2.0  # move, settle and expose: one image every 2 s
#: Noisy pixels are recorded to 1e-4 px (far below σ); noiseless ones exactly.
PIXEL_DIGITS = 4


def read_target(path: str) -> Target:
    """The target of a target file (TOML), or :data:`camera.DEFAULT_TARGET` for ""."""
    if not path:
        return camera.DEFAULT_TARGET
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ArmsigError(
            f"cannot read the target file {path}", got=str(exc),
            fix="--target a TOML file as in docs/camera.md",
        ) from None  # fmt: skip
    return target_from_toml(text, path)


def simulate_camera(out: Path, opts: SimulationOptions, force: bool) -> Path:
    """Simulate and write a camera session (module docstring); returns the recording."""
    robot = get_robot(opts.robot)
    target = read_target(opts.target_file)
    ids, local = target.points()
    rng = np.random.default_rng(opts.seed)
    rng_robot, rng_world, rng_servo, rng_sensor = rng.spawn(4)
    true = draw_true_robot(robot, rng_robot, opts.sigmas)
    nominal = camera.nominal_intrinsics(*opts.resolution_px, opts.focal_px)
    lens = camera.true_intrinsics(nominal, opts.distortion, rng_world)
    fixed, on_flange = camera.placement(opts.setup, true.chain, robot.limits, target, rng_world)
    if opts.plan_file:  # a pose plan (`pipeline plan --sensor camera`): its poses, in order
        q_plan = read_pose_plan(Path(opts.plan_file), robot)
        q_cmd, dropped = camera.planned_images(q_plan, opts.setup, true.chain, target, fixed,
                                               on_flange, lens)  # fmt: skip
    else:
        q_cmd, dropped = camera.draw_images(opts.poses, opts.setup, true.chain, robot.limits,
                                            target, fixed, on_flange, lens, rng_world)  # fmt: skip
    res = robot.encoder_resolution
    if opts.noiseless:
        q_enc = q_reached = q_cmd.copy()
    else:  # each joint settles within ±1 count of its command; the encoder rounds
        q_reached = q_cmd + rng_servo.uniform(-1.0, 1.0, q_cmd.shape) * res
        q_enc = np.round(q_reached / res) * res
    n = robot.n_joints
    flange = link_frames(true.chain, joints_to_internal(q_reached, robot.prismatic))[:, n]
    T = camera.camera_from_target(opts.setup, fixed, on_flange, flange)
    image_msgs: list[dict[str, Any]] = []
    if opts.images:  # rendered and detected (pipeline.rig.camera_images)
        from pipeline.rig.camera_images import IMAGES_DIR, render_images
        from pipeline.sensor.detect import image_message

        refuse_existing_recording(out, force, "a simulated one")
        shots = render_images(out, opts, target, lens, T, rng_sensor)
        keep = np.array([s.found.kept for s in shots], bool)
        order = [*np.flatnonzero(keep), *np.flatnonzero(~keep)]
        image_msgs = [image_message(step, shots[k].file, shots[k].sha256, shots[k].found,
                                    (lens.width_px, lens.height_px))
                      for step, k in enumerate(order)]  # fmt: skip
        seen_uv = [(shots[k].found.point_ids, shots[k].found.uv_px) for k in order[: keep.sum()]]
        q_cmd, q_enc, flange = q_cmd[keep], q_enc[keep], flange[keep]
        dropped = {**dropped, "rendered_not_detected": int((~keep).sum())}
    else:
        _, found, _ = camera.detect(target, T, lens, local)
        uv = project(camera.camera_points(T, local), lens.vector())
        if not opts.noiseless:
            noise = rng_sensor.normal(0.0, opts.pixel_noise_px, uv.shape)
            uv = np.round(uv + noise, PIXEL_DIGITS)
        seen_uv = [(ids[found[k]], uv[k, found[k]]) for k in range(len(q_cmd))]
    n_images = len(seen_uv)
    plan = {
        "n_avg": 1, "order": ["poses"], "sweeps": [],
        "tool_local_cm": [round(float(v)) for v in on_flange[:3, 3]],  # the nominal mount
        "poses": {"n_points": n_images},
    }  # fmt: skip
    rig = rig_description(opts, nominal, target)
    if opts.images:
        rig["images_dir"] = IMAGES_DIR  # relative: the folder of the recording
    messages = [
        Message("/rig/description", T0_NS, rig),
        robot_message(
            robot, np.clip(0.0, robot.limits[:, 0], robot.limits[:, 1]), plan, opts.robot_id
        ),
    ]
    for k, m in enumerate(image_msgs):
        messages.append(Message("/camera/images", T0_NS + int(round(IMAGE_S * (k + 1) * 1e9)), m))
    for k, (seen_ids, seen) in enumerate(seen_uv):
        t_ns = T0_NS + int(round(IMAGE_S * (k + 1) * 1e9))
        messages.append(
            Message(
                "/robot/joint_state",
                t_ns,
                joint_state(robot, "poses", k, q_cmd[k], q_enc[k], opts.noiseless),
            )
        )
        messages.append(Message("/camera/detections", t_ns + 10**8, {
            "sweep": "poses", "step": k, "point_ids": [int(i) for i in seen_ids],
            "u_px": [float(u) for u in seen[:, 0]], "v_px": [float(v) for v in seen[:, 1]],
            "sigma_px": float(opts.pixel_noise_px or camera.STATED_SIGMA_PX),
        }))  # fmt: skip
    sensor_from_world = invert_transform(fixed)
    # the tool point: the target's origin (eye-to-hand) or the camera's centre (eye-in-hand)
    truth = truth_common(opts, robot, true, sensor_from_world, on_flange[:3, 3], {})
    truth["sensor"] = {"kind": "camera", "setup": opts.setup}
    truth["camera"] = camera_truth(opts.setup, lens, nominal, fixed, on_flange, target, dropped)
    tool_in_sensor = (sensor_from_world @ flange @ on_flange)[:, :3, 3]
    steps = list(range(n_images))
    truth["target_positions_cm"] = {
        "sweep": ["poses"] * n_images, "step": steps, "p": tool_in_sensor.tolist()
    }  # fmt: skip
    channels = CAMERA_IMAGE_CHANNELS if opts.images else None
    return write_session(out, force, logged(messages, opts), truth, "camera", channels)


def rig_description(opts: SimulationOptions, nominal: Any, target: Target) -> dict[str, Any]:
    """The ``/rig/description`` of the simulated camera."""
    return {
        "sensor": "camera",
        "instrument": "camera (simulated by armsig)",
        "setup": opts.setup,
        "camera": nominal.to_dict(),
        "target": target.to_dict(),
        "noise": {
            "model": "isotropic Gaussian per pixel coordinate",
            "source": "sub-pixel corner detection (OpenCV cornerSubPix), ~0.1-0.3 px",
        },
    }


def camera_truth(
    setup: str, lens: Any, nominal: Any, fixed: np.ndarray, on_flange: np.ndarray,
    target: Target, dropped: dict[str, Any],
) -> dict[str, Any]:  # fmt: skip
    """The ``camera`` part of ``rig-truth.json``: the true and nominal lens, the hand-eye
    transforms (4 × 4, cm; ``world``: the robot's base frame, ``flange``: its last link
    frame), and the images a detector dropped by reason."""
    poses = (
        {"camera_in_world": fixed.tolist(), "target_in_flange": on_flange.tolist()}
        if setup == "eye-to-hand"
        else {"target_in_world": fixed.tolist(), "camera_in_flange": on_flange.tolist()}
    )
    return {
        "setup": setup,
        "intrinsics_true": lens.to_dict(),
        "intrinsics_nominal": nominal.to_dict(),
        **poses,
        "target": target.to_dict(),
        "dropped_images": dropped,
    }
