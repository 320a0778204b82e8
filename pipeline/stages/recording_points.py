"""Read the ``/points`` channel of a point-sensor recording (``schemas/mcap/points.json``).

What one message's schema cannot check, refused with one line naming the key: a key
``(sweep, step, target)`` recorded twice, a sweep or step the plan does not have, a
target id the plan does not list for its sweep (``plan.sweeps[].targets``,
``plan.poses.targets``; ``plan.tool_targets`` for the tool sweep, else
``plan.tool_target``, its only target), a ``plan.tool_targets`` without
``plan.tool_target`` among them, a pose set of several targets without its
``plan.tool_target``, ``sigma_cm``
together with ``cov_cm2``, a covariance that is not symmetric positive definite, a σ
under :data:`MIN_SIGMA_CM`, a quaternion that is not of unit length. Pairing with the
joint states is the caller's.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pipeline.errors import RecordingError
from pipeline.schemas import mcap_json_schema
from pipeline.stages.recording_keys import (
    KEY_FIX,
    key_text,
    message_keys,
    refuse_duplicates,
    seconds_after,
)
from pipeline.sweeps import POSES_SWEEP, TOOL_SWEEP, sweep_name

TOPIC = "/points"
#: A recorded covariance may be asymmetric by this fraction of its largest entry: the
#: rounding of a writer that prints 15 significant digits, far below a transposed or
#: mistyped entry.
SYMMETRY_REL = 1e-9
#: A recorded quaternion's length may differ from 1 by this much: a float32 quaternion
#: renormalised in float32 is within 1e-7; a non-rotation is off by far more.
UNIT_TOL = 1e-6
#: The smallest standard deviation of a coordinate taken (cm): 1 nm, below any instrument's
#: statement; a σ far below it (1e-200 cm) squares to zero in float64 and broke the fit's
#: whitening (a LinAlgError, issue 44).
MIN_SIGMA_CM = 1e-7
#: The largest (cm), and the farthest coordinate from the sensor's origin (cm, the
#: contract's ±1,000 m): schemas/mcap/points.json's maxima of sigma_cm and x_cm.
MAX_SIGMA_CM = float(mcap_json_schema("points")["properties"]["sigma_cm"]["maximum"])
MAX_COORD_CM = float(mcap_json_schema("points")["properties"]["x_cm"]["maximum"])


def no_points() -> dict[str, np.ndarray]:
    """The point arrays of a sonic recording: zero rows."""
    return {
        "point_sweep": np.zeros(0, np.int64),
        "point_step": np.zeros(0, np.int64),
        "point_target": np.zeros(0, str),
        "point_t_s": np.zeros(0),
        "points_cm": np.zeros((0, 3)),
        "point_sigma_cm": np.zeros(0),
        "point_cov_cm2": np.zeros((0, 3, 3)),
        "point_wxyz": np.zeros((0, 4)),
        "point_orientation_sigma_deg": np.zeros(0),
    }


def read_points(
    p: Path,
    msgs: list[tuple[int, dict[str, Any]]],
    plan: dict[str, Any],
    n_points: dict[int, int | None],
    t0: int,
    blocks: dict[str, np.ndarray] | None = None,
) -> dict[str, np.ndarray]:
    """The ``point_*`` arrays of :class:`pipeline.stages.recording.Recording`, sorted by
    ``(sweep, step, target)``; ``n_points``: sweep id -> planned positions; ``t0``: the
    earliest joint state's log time (ns); ``blocks``: the point rows of the
    ``/points/block`` messages (:mod:`pipeline.stages.recording_blocks`), checked there
    (None: none)."""
    payloads = [m for _, m in msgs]
    n = len(msgs)
    sweep, step = message_keys(p, TOPIC, payloads, n_points)
    cols = {
        "point_sweep": sweep,
        "point_step": step,
        "point_target": np.array([m["target"] for m in payloads], str),
        "t_ns": np.array([t for t, _ in msgs], np.uint64),
        "points_cm": np.array([[m["x_cm"], m["y_cm"], m["z_cm"]] for m in payloads], float).reshape(
            -1, 3
        ),  # fmt: skip
        "point_sigma_cm": np.full(n, np.nan),
        "point_cov_cm2": np.full((n, 3, 3), np.nan),
        "point_wxyz": np.full((n, 4), np.nan),
        "point_orientation_sigma_deg": np.full(n, np.nan),
    }
    message = np.arange(n)
    if blocks is not None:
        cols = blocks if not n else {k: np.concatenate([v, blocks[k]]) for k, v in cols.items()}
        message = np.r_[message, np.full(len(blocks["point_step"]), -1)]
    order = np.lexsort((cols["point_target"], cols["point_step"], cols["point_sweep"]))
    if not (order == np.arange(len(order))).all():  # blocks are written in key order
        cols = {k: v[order] for k, v in cols.items()}
        message = message[order]
    sweep, step, target = cols["point_sweep"], cols["point_step"], cols["point_target"]
    refuse_duplicates(p, TOPIC, sweep, step, target=target)
    _refuse_unplanned_targets(p, sweep, step, target, plan)
    sigma, cov = cols["point_sigma_cm"], cols["point_cov_cm2"]
    wxyz, sigma_o = cols["point_wxyz"], cols["point_orientation_sigma_deg"]
    for k in np.flatnonzero(message >= 0):
        m = payloads[message[k]]
        if "cov_cm2" not in m and "orientation_wxyz" not in m and "orientation_sigma_deg" not in m:
            if "sigma_cm" in m:
                sigma[k] = m["sigma_cm"]
            continue  # nothing else to check: the key's text only for a message below
        key = key_text(sweep[k], step[k], target=target[k])
        if "sigma_cm" in m and "cov_cm2" in m:
            raise RecordingError(
                f"{p}: {TOPIC} {key} carries both sigma_cm and cov_cm2",
                expected="one uncertainty per point: sigma_cm (isotropic) or cov_cm2 (3x3)",
                fix="record either, not both (schemas/mcap/points.json)",
            )
        if "sigma_cm" in m:
            sigma[k] = checked_sigma(p, key, float(m["sigma_cm"]))
        if "cov_cm2" in m:
            cov[k] = _checked_cov(p, key, np.array(m["cov_cm2"], float))
        if "orientation_wxyz" in m:
            wxyz[k] = checked_quaternion(p, key, np.array(m["orientation_wxyz"], float))
        if "orientation_sigma_deg" in m:
            if "orientation_wxyz" not in m:
                raise RecordingError(
                    f"{p}: {TOPIC} {key} carries orientation_sigma_deg without orientation_wxyz",
                    expected="the σ of a recorded orientation, beside it",
                    fix="record orientation_wxyz, or drop orientation_sigma_deg",
                )
            sigma_o[k] = m["orientation_sigma_deg"]
    tiny = np.flatnonzero(sigma < MIN_SIGMA_CM)  # the messages the loop read unchecked
    if tiny.size:
        first = int(tiny[0])
        key = key_text(sweep[first], step[first], target=target[first])
        checked_sigma(p, key, float(sigma[first]))
    cols["point_t_s"] = seconds_after(cols.pop("t_ns"), t0)
    return cols


def _refuse_unplanned_targets(
    p: Path, sweep: np.ndarray, step: np.ndarray, target: np.ndarray, plan: dict[str, Any]
) -> None:
    """Targets of a joint sweep within its ``targets`` and of the pose set within
    ``plan.poses.targets`` (when listed); the tool sweep measures ``tool_targets`` (when
    given: the targets on the last link, ``tool_target`` among them), else ``tool_target``
    (when given), else exactly one target, and a pose set of several targets needs
    ``tool_target`` among them (which of its points is the tool)."""
    allowed: dict[int, list[str]] = {
        int(s["joint"]): list(s["targets"]) for s in plan["sweeps"] if "targets" in s
    }
    if "targets" in plan.get("poses", {}):
        allowed[POSES_SWEEP] = list(plan["poses"]["targets"])
    if "tool_targets" in plan and plan.get("tool_target") not in plan["tool_targets"]:
        raise RecordingError(
            f"{p}: /robot/description plan.tool_targets ({', '.join(plan['tool_targets'])}) "
            "does not hold plan.tool_target",
            expected="the tool point's target id among the targets on the last link",
            got=f"tool_target {plan.get('tool_target')}",
            fix="record plan.tool_target, one of plan.tool_targets",
        )
    if "tool_target" in plan:
        allowed[TOOL_SWEEP] = list(plan.get("tool_targets", [str(plan["tool_target"])]))
    for s, what in ((TOOL_SWEEP, "sweep tool measures"), (POSES_SWEEP, "the pose set measures")):
        measured = np.unique(target[sweep == s]).tolist()
        if "tool_target" not in plan and len(measured) > 1:
            raise RecordingError(
                f"{p}: {TOPIC} {what} {len(measured)} targets ({', '.join(measured)}) and "
                "plan.tool_target does not say which is the tool",
                expected="one target there, or plan.tool_target",
                fix="record plan.tool_target in /robot/description",
            )
        tool = plan.get("tool_target")
        if tool is not None and s == POSES_SWEEP and measured and tool not in measured:
            raise RecordingError(
                f"{p}: {TOPIC} the pose set never measures plan.tool_target {plan['tool_target']}",
                expected=f"the tool target among the pose set's targets ({', '.join(measured)})",
                fix="record the tool target at every pose, or name it in plan.tool_target",
            )
    bad = np.zeros(len(sweep), bool)
    for s, ids in allowed.items():
        bad |= (sweep == s) & ~np.isin(target, ids)
    if bad.any():
        k = int(np.argmax(bad))
        ids = allowed[int(sweep[k])]
        tool = "plan.tool_targets" if "tool_targets" in plan else "plan.tool_target"
        where = {TOOL_SWEEP: tool, POSES_SWEEP: "plan.poses targets"}.get(
            int(sweep[k]), "its plan.sweeps targets"
        )
        raise RecordingError(
            f"{p}: {TOPIC} {key_text(sweep[k], step[k], target=target[k])} names a target "
            f"that sweep {sweep_name(sweep[k])} does not plan",
            expected=f"a target of {where}: {', '.join(ids)}",
            got=f"target {target[k]}",
            fix=KEY_FIX,
        )


def _checked_cov(p: Path, key: str, c: np.ndarray) -> np.ndarray:
    """``c`` (3, 3), refused unless symmetric positive definite."""
    scale = float(np.max(np.abs(c)))
    if scale == 0.0 or np.max(np.abs(c - c.T)) > SYMMETRY_REL * scale:
        raise RecordingError(
            f"{p}: {TOPIC} {key} cov_cm2 is not symmetric",
            expected="cov_cm2[i][j] == cov_cm2[j][i]",
            got=str(c.tolist()),
            fix="record the covariance of (x, y, z) in cm^2",
        )
    c = 0.5 * (c + c.T)
    if np.linalg.eigvalsh(c)[0] <= 0.0:
        raise RecordingError(
            f"{p}: {TOPIC} {key} cov_cm2 is not positive definite",
            expected="a covariance with positive eigenvalues",
            got=f"eigenvalues {np.linalg.eigvalsh(c).tolist()}",
            fix="record the covariance of (x, y, z) in cm^2, or sigma_cm",
        )
    small = float(np.sqrt(np.linalg.eigvalsh(c)[0]))
    checked_sigma(p, key, small, "cov_cm2's smallest σ")
    return c


def checked_sigma(p: Path, key: str, sigma: float, what: str = "sigma_cm") -> float:
    """``sigma`` (cm), refused under :data:`MIN_SIGMA_CM`."""
    if not sigma >= MIN_SIGMA_CM:
        raise RecordingError(
            f"{p}: {TOPIC} {key} {what} is {sigma:g} cm, under {MIN_SIGMA_CM:g} cm (1 nm)",
            expected=f"a standard deviation of at least {MIN_SIGMA_CM:g} cm",
            fix="record the instrument's σ in cm (a σ in m or mm recorded as cm?)",
        )
    return sigma


def checked_quaternion(p: Path, key: str, q: np.ndarray) -> np.ndarray:
    """``q`` (4,), refused unless of unit length within :data:`UNIT_TOL`."""
    norm = float(np.linalg.norm(q))
    if abs(norm - 1.0) > UNIT_TOL:
        raise RecordingError(
            f"{p}: {TOPIC} {key} orientation_wxyz is not a unit quaternion",
            expected=f"length 1 (± {UNIT_TOL:g})",
            got=f"length {norm:.9g}",
            fix="normalise the quaternion (w, x, y, z) before recording it",
        )
    return q
