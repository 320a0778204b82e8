"""What every simulated session writes: joint states, the robot's description, the
truth's shared part, log times, and the recording with ``rig-truth.json`` beside it
(:mod:`pipeline.rig.simulate` for the sonic digitizer and the tracker,
:mod:`pipeline.rig.camera_session` for the camera)."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.atomic import remove_debris, write_text_atomic
from pipeline.contract.channels import SENSOR_CHANNELS
from pipeline.rig.options import SimulationOptions, options_for_truth
from pipeline.rig.recorder import Message, refuse_existing_recording, write_recording
from pipeline.robots.description import description_to_dict
from pipeline.stages.lock import session_lock

T0_NS = 1_767_225_600 * 10**9  # 2026-01-01T00:00:00Z: recordings carry no wall-clock time


def joint_state(
    robot: Any, sweep: int | str, step: int, q_cmd: np.ndarray, q_enc: np.ndarray, exact: bool,
    payload_kg: float = float("nan"),
) -> dict[str, Any]:  # fmt: skip
    """A /robot/joint_state payload: the controller's readings of joint values ``q_cmd`` and
    ``q_enc`` (deg / cm; through the inverse of the robot's coupling, if any), printed to
    1e-6 (commanded always, encoder unless ``exact``), and the payload (kg) when given."""
    cmd, enc = robot.readings_from_joints(q_cmd), robot.readings_from_joints(q_enc)
    out: dict[str, Any] = {
        "sweep": sweep,
        "step": step,
        "q_commanded": [round(float(v), 6) for v in cmd],
        "q_encoder": [float(v) if exact else round(float(v), 6) for v in enc],
        "units": [j.unit for j in robot.joints],
    }
    if np.isfinite(payload_kg):
        out["payload_kg"] = float(payload_kg)
    return out


def robot_message(
    robot: Any, signature_q: Any, plan: dict[str, Any], robot_id: str = ""
) -> Message:
    """The ``/robot/description`` message: design model, q^s as readings, the plan, and
    the arm's ``robot_id`` when it has one."""
    readings = robot.readings_from_joints(np.array(signature_q))
    payload = {
        "robot": description_to_dict(robot),
        "signature_q": [float(v) for v in readings],
        "plan": plan,
        "mode": "simulated",
    }
    if robot_id:
        payload["robot_id"] = robot_id
    return Message("/robot/description", T0_NS, payload)


def truth_common(
    opts: SimulationOptions,
    robot: Any,
    true: Any,
    sensor_from_base: np.ndarray,
    tool_true: np.ndarray,
    target_true: dict[int, np.ndarray],
) -> dict[str, Any]:
    """The part of ``rig-truth.json`` both sensors share (the audit reads the kinematics)."""
    return {
        "robot": robot.name,
        "seed": opts.seed,
        "options": options_for_truth(opts),
        "true_kinematics": {
            "frame": "sensor",
            "length_unit": "cm",
            "angle_unit": "deg",
            "joint_types": [j.type for j in robot.joints],
            "base": (sensor_from_base @ true.chain.base).tolist(),
            "links": true.chain.links.tolist(),
        },
        **nongeometric_truth(true),
        "true_tool_in_last_link_cm": tool_true.tolist(),
        "true_targets_local_cm": {str(k): v.tolist() for k, v in target_true.items()},
        "sensor_from_base": sensor_from_base.tolist(),
        "errors": true.errors,
    }


def nongeometric_truth(true: Any) -> dict[str, Any]:
    """``true_nongeometric`` of rig-truth.json (absent for a rigid robot): the terms and
    their coefficients in internal units (rad/cm, rad); ``true_backlash`` (absent without
    it): the error the model does not have (:meth:`pipeline.rig.backlash.Backlash.to_truth`)."""
    ng = true.nongeometric
    out: dict[str, Any] = {}
    if ng is not None:
        out["true_nongeometric"] = {
            "terms": list(ng.terms.names),
            "units": list(ng.terms.units),
            "coefficients": ng.coefficients.tolist(),
        }
    if true.backlash is not None:
        out["true_backlash"] = true.backlash.to_truth()
    return out


def logged(messages: list[Message], opts: SimulationOptions) -> list[Message]:
    """The messages as a logger writes them: each measurement logged ``U(0,
    log_jitter_s)`` after it was measured (its own stream of the seed), so that with a
    jitter of more than a cycle's 0.25 s cycles are logged out of measurement order. The
    measurement time (``publish_time``) stays; descriptions are logged when written."""
    if opts.log_jitter_s == 0.0:
        return messages
    rng = np.random.default_rng([opts.seed, 33])  # issue 33: apart from the rig's streams
    delay = rng.uniform(0.0, opts.log_jitter_s, len(messages))
    return [
        m if m.topic.endswith("/description") else replace(m, log_time_ns=m.time_ns + int(d * 1e9))
        for m, d in zip(messages, delay, strict=True)
    ]


def write_session(
    out: Path, force: bool, messages: list[Message], truth: dict[str, Any], sensor: str,
    channels: dict[str, str] | None = None,
) -> Path:  # fmt: skip
    """Write the recording (messages in log-time order) and ``rig-truth.json``; its
    channels are the sensor's unless ``channels`` are given."""
    # stable: descriptions stay first
    messages.sort(key=lambda m: m.time_ns if m.log_time_ns is None else m.log_time_ns)
    recording = out / "recording.mcap"
    out.mkdir(parents=True, exist_ok=True)
    # Under the session lock, like every pipeline run on the folder: no run reads a
    # recording half replaced, and a recording that appeared meanwhile is still refused.
    with session_lock(out):
        refuse_existing_recording(out, force, "a simulated one")
        remove_debris(out)  # the temp files of a killed simulate or import (issue 44)
        write_recording(recording, messages, channels or SENSOR_CHANNELS[sensor])
        write_text_atomic(out / "rig-truth.json", json.dumps(truth, indent=1) + "\n")
    return recording
