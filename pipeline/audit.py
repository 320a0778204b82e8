"""Audit a simulated session: identified signature and design model against the rig's truth.

Only this module and the tests read ``rig-truth.json``. Both models are
compared with the true robot over random configurations within the joint
limits, after the best-fit constant base and tool alignment
(``T_true ≈ X · T_model · Y``), because a model's base and tool frames are
conventions (Section 4.3.5) while its internal kinematics are what the
identification measures.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from pipeline.errors import ArmsigError
from pipeline.kinematics.alignment import fit_alignment
from pipeline.kinematics.chain import SerialChain, forward_kinematics
from pipeline.kinematics.transforms import pose_error
from pipeline.stages.frames import chain_from_frames
from pipeline.stages.runner import stage_path
from pipeline.stages.session import session_robot
from pipeline.stages.tables import read_table
from pipeline.units import joints_to_internal


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


def true_chain(truth: dict) -> SerialChain:
    """The true robot of ``rig-truth.json`` (sensor frame, encoder readings in rad / cm)."""
    tk = truth["true_kinematics"]
    pris = np.array([t == "prismatic" for t in tk["joint_types"]])
    return SerialChain(links=np.array(tk["links"]), prismatic=pris, base=np.array(tk["base"]))


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


def audit(session_dir: str | Path, configurations: int = 1000, seed: int = 0) -> AuditResult:
    """Compare the identified signature and the design model with the truth."""
    sdir = Path(session_dir)
    truth_path = sdir / "rig-truth.json"
    if not truth_path.is_file():
        raise ArmsigError(
            f"{sdir}: no rig-truth.json",
            expected="a simulated session (the audit needs the simulator's ground truth)",
            fix="audit only sessions made by `pipeline simulate`",
        )
    frames_path = stage_path(sdir, "frames")
    if not frames_path.is_file():
        raise ArmsigError(
            f"{sdir}: not identified yet", fix=f"run `pipeline identify {sdir}` first"
        )
    truth = json.loads(truth_path.read_text())
    robot = session_robot(read_table(stage_path(sdir, "session")))
    pris = robot.prismatic
    sig = chain_from_frames(read_table(frames_path), pris)
    rng = np.random.default_rng(seed)
    lim = robot.limits
    q = joints_to_internal(
        rng.uniform(lim[:, 0], lim[:, 1], (configurations, robot.n_joints)), pris
    )
    T_true = forward_kinematics(true_chain(truth), q)
    return AuditResult(
        session=str(sdir),
        configurations=configurations,
        signature=_aligned_errors(T_true, forward_kinematics(sig, q)),
        design=_aligned_errors(T_true, forward_kinematics(robot.design_chain(), q)),
    )
