"""Audit a simulated session: identified signature and design model against the rig's truth.

Only this module and the tests read ``rig-truth.json``. Both models are
compared with the true robot over random configurations within the joint
limits, after the best-fit constant base and tool alignment
(``T_true ≈ X · T_model · Y``), because a model's base and tool frames are
conventions (Section 4.3.5) while its internal kinematics are what the
identification measures. Positions are compared at the true tool point (the
point the session measured as its tool), not at the flange: an error of the
tool's orientation would otherwise count, on the lever from the tool point to the
flange, as a position error the signature never claimed (issue 26: on 20 pose-set
sessions audited/predicted was 1.31 at the flange and 1.01 at the tool point).
The truth's joints sit where the simulator put them: its non-geometric terms and its
backlash (an error no signature has, :mod:`pipeline.rig.backlash`) included.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.errors import ArmsigError
from pipeline.kinematics.alignment import fit_alignment
from pipeline.kinematics.chain import SerialChain, forward_kinematics
from pipeline.kinematics.nongeometric import NonGeometric, Terms
from pipeline.kinematics.transforms import pose_error, trans
from pipeline.rig.backlash import Backlash
from pipeline.rig.true_robot import where_joints_sit
from pipeline.robots.description import JOINT_TYPES
from pipeline.stages.frames import chain_from_frames
from pipeline.stages.runner import stage_path
from pipeline.stages.session import session_robot
from pipeline.stages.tables import read_table

#: Most random configurations: 1e5 keep the (m, n, 4, 4) stacks of the audit near 100 MB.
MAX_CONFIGURATIONS = 100_000
_RESIMULATE = "simulate the session again (`pipeline simulate NAME --force`)"


@dataclass(frozen=True)
class ModelError:
    """Errors of one model against the truth, cm and degrees."""

    max_position_cm: float
    rms_position_cm: float
    max_orientation_deg: float
    rms_orientation_deg: float


@dataclass(frozen=True)
class AuditResult:
    session: str
    configurations: int
    signature: ModelError
    design: ModelError

    @property
    def improvement(self) -> float:
        """Design RMS position error over signature RMS position error."""
        return self.design.rms_position_cm / max(self.signature.rms_position_cm, 1e-300)

    def to_dict(self) -> dict[str, object]:
        return {**asdict(self), "improvement_rms_position": self.improvement}


def read_truth(path: Path) -> dict[str, Any]:
    """The parsed ``rig-truth.json`` of a simulated session (one-line error if unreadable)."""
    try:
        truth = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, RecursionError, json.JSONDecodeError) as exc:
        raise ArmsigError(
            f"{path}: not a readable JSON file", got=str(exc), fix=_RESIMULATE
        ) from exc
    if not isinstance(truth, dict):
        raise ArmsigError(f"{path}: not a JSON object", got=type(truth).__name__, fix=_RESIMULATE)
    return truth


def _array(value: Any, shape: tuple[int, ...], field: str) -> np.ndarray:
    """``value`` as a finite float array of ``shape``, else a one-line error naming ``field``."""
    try:
        out = np.array(value, float)
    except (TypeError, ValueError):
        out = np.full(0, np.nan)
    if out.shape != shape or not np.isfinite(out).all():
        raise ArmsigError(
            f"rig-truth.json: field {field!r} is malformed",
            expected=f"finite numbers of shape {shape}",
            got=f"shape {out.shape}" if out.shape != shape else "a value that is not finite",
            fix=_RESIMULATE,
        )
    return out


def true_chain(truth: dict[str, Any]) -> SerialChain:
    """The true robot of ``rig-truth.json`` (sensor frame, encoder readings in rad / cm)
    to its flange (no tool)."""
    tk = truth.get("true_kinematics")
    if not isinstance(tk, dict):
        raise ArmsigError(
            "rig-truth.json: no field 'true_kinematics'",
            expected="the ground truth `pipeline simulate` writes",
            fix=_RESIMULATE,
        )
    types = tk.get("joint_types")
    if not (isinstance(types, list) and types and all(t in JOINT_TYPES for t in types)):
        raise ArmsigError(
            "rig-truth.json: field 'true_kinematics.joint_types' is malformed",
            expected=f"a list of {' or '.join(JOINT_TYPES)}",
            got=repr(types)[:80],
            fix=_RESIMULATE,
        )
    n = len(types)
    return SerialChain(
        links=_array(tk.get("links"), (n, 4, 4), "true_kinematics.links"),
        prismatic=np.array([t == "prismatic" for t in types]),
        base=_array(tk.get("base"), (4, 4), "true_kinematics.base"),
    )


def true_tool_chain(truth: dict[str, Any]) -> SerialChain:
    """:func:`true_chain` with its tool the true tool point (``true_tool_in_last_link_cm``,
    a translation of the last link frame): the point the identification measured, where
    the signature's accuracy is claimed and predicted (stage ``uncertainty``)."""
    chain = true_chain(truth)  # its checks first: a truth without kinematics says so
    tip = _array(truth.get("true_tool_in_last_link_cm"), (3,), "true_tool_in_last_link_cm")
    return dataclasses.replace(chain, tool=trans(*tip))


def true_nongeometric(truth: dict[str, Any], robot: Any) -> NonGeometric | None:
    """The true robot's ``true_nongeometric`` terms on ``robot``'s design chain
    (:func:`pipeline.rig.true_robot.draw_nongeometric`); None for a rigid robot."""
    ng = truth.get("true_nongeometric")
    if ng is None:
        return None
    names = ng.get("terms") if isinstance(ng, dict) else None
    if not (isinstance(names, list) and all(isinstance(x, str) for x in names)):
        raise ArmsigError(
            "rig-truth.json: field 'true_nongeometric.terms' is malformed",
            expected="a list of term names",
            fix=_RESIMULATE,
        )
    beta = _array(ng.get("coefficients"), (len(names),), "true_nongeometric.coefficients")
    try:
        terms = Terms.from_names(names)
    except (ValueError, IndexError) as exc:
        raise ArmsigError(
            "rig-truth.json: field 'true_nongeometric.terms' is malformed",
            got=str(exc)[:80],
            fix=_RESIMULATE,
        ) from exc
    payloads = _payloads_kg(truth)
    return NonGeometric(
        terms,
        beta,
        robot.design_chain(),
        payload_kg=payloads[0] if payloads else 0.0,
        measured_payloads_kg=payloads,
    )


def _payloads_kg(truth: dict[str, Any]) -> tuple[float, ...]:
    """The payloads (kg) the session measured, smallest first (none: empty)."""
    return tuple(sorted(float(p) for p in truth.get("options", {}).get("payloads_kg", [])))


def true_backlash(truth: dict[str, Any], robot: Any) -> Backlash | None:
    """The true joints' backlash of ``rig-truth.json`` (``true_backlash``,
    :mod:`pipeline.rig.backlash`) on ``robot``'s design chain; None without."""
    doc = truth.get("true_backlash")
    if doc is None:
        return None
    if not isinstance(doc, dict):
        raise ArmsigError(
            "rig-truth.json: field 'true_backlash' is malformed",
            expected="an object with offsets and masses_kg",
            fix=_RESIMULATE,
        )
    n = robot.n_joints
    offsets = _array(doc.get("offsets"), (n,), "true_backlash.offsets")
    masses = _array(doc.get("masses_kg"), (n,), "true_backlash.masses_kg")
    return Backlash(offsets, masses, robot.design_chain())


def _aligned_errors(T_true: np.ndarray, T_model: np.ndarray) -> ModelError:
    X, Y = fit_alignment(T_true, T_model)
    dp, dth = pose_error(T_true, X @ T_model @ Y)
    dth = np.degrees(dth)
    return ModelError(
        float(dp.max()),
        float(np.sqrt(np.mean(dp**2))),
        float(dth.max()),
        float(np.sqrt(np.mean(dth**2))),
    )


def _truth_and_robot(sdir: Path, configurations: int) -> tuple[SerialChain, Any, dict[str, Any]]:
    """The true chain, the session's robot and the truth, after the audit's checks."""
    if not 1 <= configurations <= MAX_CONFIGURATIONS:
        raise ArmsigError(
            "--configurations out of range",
            expected=f"1 to {MAX_CONFIGURATIONS}",
            got=str(configurations),
            fix="--configurations 1000",
        )
    truth_path = sdir / "rig-truth.json"
    if not truth_path.is_file():
        raise ArmsigError(
            f"{sdir}: no rig-truth.json",
            expected="a simulated session (the audit needs the simulator's ground truth)",
            fix="audit only sessions made by `pipeline simulate`",
        )
    if not stage_path(sdir, "chain").is_file():
        raise ArmsigError(
            f"{sdir}: not identified yet", fix=f"run `pipeline identify {sdir}` first"
        )
    doc = read_truth(truth_path)
    n = true_chain(doc).n_joints
    robot = session_robot(read_table(stage_path(sdir, "session")))
    if n != robot.n_joints:
        raise ArmsigError(
            f"{truth_path}: the true robot has {n} joints",
            expected=f"the {robot.n_joints} joints of the session's robot {robot.name}",
            fix=_RESIMULATE,
        )
    return true_tool_chain(doc), robot, doc


def _true_poses(
    sdir: Path, configurations: int, seed: int, payload_kg: float | None = None
) -> tuple[np.ndarray, Any, np.ndarray]:
    """The true tool poses (m, 4, 4) at ``configurations`` random readings of the session's
    robot (its non-geometric terms and its backlash included, under ``payload_kg`` when
    given, else the smallest payload the session measured), the robot, and the readings
    (m, n)."""
    truth, robot, doc = _truth_and_robot(sdir, configurations)
    q = robot.random_configurations(configurations, seed)
    if payload_kg is None:
        payload_kg = min(_payloads_kg(doc), default=0.0)
    ng = true_nongeometric(doc, robot)
    if ng is not None:
        ng = replace(ng, payload_kg=payload_kg)  # the truth has every payload's terms
    joints = where_joints_sit(q, ng, true_backlash(doc, robot), payload_kg)
    return forward_kinematics(truth, joints), robot, q


def table_errors(
    session_dir: str | Path,
    tables: tuple[str, ...] = ("frames", "chain"),
    configurations: int = 1000,
    seed: int = 0,
) -> dict[str, ModelError]:
    """Errors against the truth of the chains held by stage tables ``tables`` (``frames``:
    the thesis S-Model; ``chain``: the signature, refined unless refinement is off), over
    the same configurations as :func:`audit`. For studies and benchmarks that compare the
    two."""
    sdir = Path(session_dir)
    T_true, robot, q = _true_poses(sdir, configurations, seed)
    return {t: _aligned_errors(T_true, _table_poses(sdir, t, robot, q)) for t in tables}


def _table_poses(
    sdir: Path, table: str, robot: Any, q: np.ndarray, payload_kg: float | None = None
) -> np.ndarray:
    """Tool poses (m, 4, 4) of the chain stage table ``table`` holds at readings ``q``:
    the signature (``chain``) with the non-geometric terms its ``refine`` table fitted
    (:func:`pipeline.stages.refine.nongeometric_model`; under ``payload_kg`` when given),
    the thesis S-Model (``frames``) rigid, as it has none."""
    from pipeline.stages.refine import nongeometric_model

    chain = chain_from_frames(read_table(stage_path(sdir, table)), robot.prismatic)
    ng = None
    if table == "chain":
        ng = nongeometric_model(read_table(stage_path(sdir, "refine")), robot)
        if ng is not None and payload_kg is not None:
            ng = ng.with_payload(payload_kg)
    return forward_kinematics(chain, q if ng is None else ng.effective(q))


def audit(
    session_dir: str | Path,
    configurations: int = 1000,
    seed: int = 0,
    payload_kg: float | None = None,
) -> AuditResult:
    """Compare the identified signature and the design model with the truth over
    ``configurations`` (1 to :data:`MAX_CONFIGURATIONS`) random configurations; under
    ``payload_kg`` on the flange when given (the truth's and the signature's
    non-geometric terms at that payload; None: the smallest the session measured)."""
    sdir = Path(session_dir)
    T_true, robot, q = _true_poses(sdir, configurations, seed, payload_kg)
    return AuditResult(
        session=str(sdir),
        configurations=configurations,
        signature=_aligned_errors(T_true, _table_poses(sdir, "chain", robot, q, payload_kg)),
        design=_aligned_errors(T_true, forward_kinematics(robot.design_chain(), q)),
    )
