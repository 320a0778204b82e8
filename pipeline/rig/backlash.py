"""Joint backlash under gravity: an error of the simulated arm that the kinematic model
does not have (issue 41).

A gear train's backlash lets a joint sit up to ``b_j`` off its reading, on the side the
load pushes it to. With the gravity torque about joint ``j`` from the lumped link masses
``m_k`` and a payload ``m_p`` at the flange,

    τ_j(q) = Σ_{k≥j} m_k h_jk(q) + m_p h_jn(q)        (kg·cm, per unit of g)

(the levers ``h_jk`` of :func:`pipeline.kinematics.nongeometric.gravity_levers`, on the
design chain at the readings, as the compliance truth takes them), joint ``j`` sits at

    q_j + b_j · sign(τ_j(q)).

The masses are the compliance truth's (:func:`pipeline.rig.true_robot.draw_backlash`), so
with both on, the backlash takes the side the compliance deflects to. A joint whose axis is
vertical (no gravity torque) or that carries no mass off its axis stays at its reading.

It is unmodelled by construction: the signature's compliance is linear in ``τ`` and its
harmonics are smooth in the joint's own angle; neither can take a step where ``τ_j``
changes sign. Only the simulator and the audit know it; the pipeline never reads it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from pipeline.kinematics.chain import SerialChain
from pipeline.kinematics.nongeometric import gravity_levers

Array = npt.NDArray[np.float64]

#: A torque of at most this (kg·cm) has no sign: a joint with a vertical axis, or with its
#: masses on its axis, has τ = 0 up to the levers' rounding (~1e-13 cm on a 1 m arm, times
#: ~10 kg: ~1e-12), which must not pick a side at random; a real load's torque is
#: millions of times larger (1 kg at 1 mm: 0.1 kg·cm).
TORQUE_ZERO_KG_CM = 1e-9


@dataclass(frozen=True, eq=False)
class Backlash:
    """The true joints' backlash: ``offsets`` ``b_j`` (n,) in rad (0 for a prismatic
    joint), the lumped link masses ``masses_kg`` (n,) that set the torques' signs, on the
    robot's ``design`` chain."""

    offsets: Array
    masses_kg: Array
    design: SerialChain

    def torques(self, q: npt.ArrayLike, payload_kg: npt.ArrayLike = 0.0) -> Array:
        """``τ`` (..., n) in kg·cm (per unit of g) at readings ``q`` (..., n) with the payload
        ``payload_kg`` (kg; a number or one per configuration (...,))."""
        h = gravity_levers(self.design, q)
        payload = np.asarray(payload_kg, float)[..., None]
        return np.asarray(h @ self.masses_kg + payload * h[..., -1], float)

    def deflection(self, q: npt.ArrayLike, payload_kg: npt.ArrayLike = 0.0) -> Array:
        """``b_j sign(τ_j)`` (..., n), rad, at readings ``q`` (..., n)."""
        tau = self.torques(q, payload_kg)
        side = np.where(np.abs(tau) <= TORQUE_ZERO_KG_CM, 0.0, np.sign(tau))
        return np.asarray(side * self.offsets, float)

    def to_truth(self) -> dict[str, object]:
        """``true_backlash`` of ``rig-truth.json`` (internal units, as ``true_nongeometric``)."""
        prismatic = np.asarray(self.design.prismatic, bool)
        return {
            "model": "q_j + b_j sign(sum_k m_k h_jk(q) + m_p h_jn(q)), design levers at the "
            "readings (pipeline/rig/backlash.py)",
            "offsets": self.offsets.tolist(),
            "units": ["cm" if p else "rad" for p in prismatic],
            "masses_kg": self.masses_kg.tolist(),
        }
