"""Signature-based control (Chapter 5): poses in, encoder readings out.

A :class:`Controller` drives a robot with its identified signature. Poses are
given in the *design base frame* (the robot's mounting surface, as the design
model defines it) for the signature's tool; the controller maps them into the
signature's sensor frame with the base alignment stored in the signature file
(Section 5.3: design and signature models must share one physical base frame).

- Newton-Raphson (5.4) starts from the closed-form design inverse on the
  requested branch (Puma) or from a damped least-squares design inverse.
- Jacobi iterative (5.8) needs a closed-form design inverse: Puma only.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.errors import ArmsigError
from pipeline.kinematics.chain import SerialChain
from pipeline.kinematics.ik import IKResult, jacobi_iterative, newton_raphson
from pipeline.robots.description import RobotDescription
from pipeline.signature_file import Signature, load_signature
from pipeline.units import joints_to_internal

METHODS = ("nr", "jacobi")


def parse_branch(text: str | None):  # -> Branch | None
    """``right-up-noflip`` style branch names (see :class:`pipeline.robots.puma560.Branch`)."""
    if text is None:
        return None
    from pipeline.robots.puma560 import BRANCHES

    for b in BRANCHES:
        if b.label == text:
            return b
    raise ArmsigError(f"unknown branch {text!r}", expected=", ".join(b.label for b in BRANCHES))


@dataclass(frozen=True)
class Controller:
    """Inverse kinematics of one identified robot."""

    signature: Signature
    robot: RobotDescription
    sensor_from_base: np.ndarray  # X: design base frame -> sensor frame
    flange_to_tool: np.ndarray  # Y: design flange -> signature tool

    @classmethod
    def from_session(cls, session_dir: str | Path) -> Controller:
        """Load ``signature.json`` of an identified session."""
        import json

        from pipeline.robots.description import description_from_dict

        path = Path(session_dir) / "signature.json"
        sig = load_signature(path)
        doc = json.loads(path.read_text())
        try:
            robot = description_from_dict(doc["robot_description"], source=str(path))
            al = doc["design_alignment"]
            X = np.array(al["sensor_from_design_base"], float)
            Y = np.array(al["design_flange_to_signature_tool"], float)
        except KeyError as exc:
            raise ArmsigError(
                f"{path}: no {exc} in the signature",
                fix=f"re-run `pipeline identify {session_dir}`",
            ) from exc
        return cls(sig, robot, X, Y)

    @property
    def resolution(self) -> np.ndarray:
        """Encoder resolution in math units (rad / cm), shape (n,)."""
        return joints_to_internal(self.robot.encoder_resolution, self.robot.prismatic)

    def _design_in_sensor(self) -> SerialChain:
        d = self.robot.design_chain()
        return SerialChain(
            links=d.links,
            prismatic=d.prismatic,
            base=self.sensor_from_base @ d.base,
            tool=d.tool @ self.flange_to_tool,
            joint_offsets=d.joint_offsets,
        )

    def default_branch(self):  # -> Branch
        """The Puma branch of the signature configuration."""
        from pipeline.robots.puma560 import Branch, branch_of

        return Branch(*(int(v) for v in branch_of(self.signature.chain.joint_offsets)))

    def initial_estimate(self, T_sensor: np.ndarray, branch=None) -> np.ndarray:
        """q⁰: closed-form design inverse on ``branch`` (Puma) or damped least squares."""
        m = T_sensor.shape[0]
        q_sig = np.asarray(self.signature.chain.joint_offsets, float)
        qs = np.broadcast_to(q_sig, (m, self.robot.n_joints)).copy()
        if self.robot.name == "puma560":
            from pipeline.robots.puma560_control import puma_design_inverse

            inv = puma_design_inverse(
                branch or self.default_branch(),
                tool=self.flange_to_tool,
                base=self.sensor_from_base,
            )
            return inv(T_sensor, qs)
        design = self._design_in_sensor()
        res = newton_raphson(design, T_sensor, qs, self.resolution, max_iter=100, damping=1e-2)
        return res.q

    def solve(
        self, T_base: np.ndarray, branch=None, method: str = "nr", record_history: bool = False
    ) -> IKResult:
        """Encoder readings (rad / cm) that put the signature tool at ``T_base`` (m, 4, 4)."""
        if method not in METHODS:
            raise ArmsigError(f"unknown method {method!r}", expected=" or ".join(METHODS))
        T = np.asarray(T_base, float).reshape(-1, 4, 4)
        T_sensor = self.sensor_from_base @ T
        if self.robot.name == "puma560" and branch is None:
            branch = self.default_branch()
        q0 = self.initial_estimate(T_sensor, branch)
        if method == "nr":
            return newton_raphson(
                self.signature.chain, T_sensor, q0, self.resolution, record_history=record_history
            )
        if self.robot.name != "puma560":
            raise ArmsigError(
                f"{self.robot.name}: Jacobi iteration needs a closed-form design inverse",
                fix="use --method nr",
            )
        from pipeline.robots.puma560_control import puma_design_inverse

        inv = puma_design_inverse(branch, tool=self.flange_to_tool, base=self.sensor_from_base)
        return jacobi_iterative(
            self.signature.chain,
            self._design_in_sensor(),
            inv,
            T_sensor,
            q0,
            self.resolution,
            record_history=record_history,
        )
