"""The manufactured robot: the design model plus random manufacturing errors.

Puma 560: model (7.1)-(7.8) with ε drawn per category (ERRATA.md lists which ε
is positional, orientational or encoder). Any other robot: a generic model, a
small random rigid perturbation of the base and of every link's constant
transform plus an encoder offset per joint, with the same three σ categories.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from pipeline.errors import ArmsigError
from pipeline.kinematics.chain import SerialChain, forward_kinematics
from pipeline.kinematics.nongeometric import NonGeometric, Terms, all_terms
from pipeline.kinematics.transforms import rot_x, rot_y, rot_z, trans, trans_z
from pipeline.rig.backlash import Backlash
from pipeline.robots import puma560
from pipeline.robots.description import RobotDescription


@dataclass(frozen=True)
class ErrorSigmas:
    """Standard deviations of the manufacturing errors (boundary units).

    Defaults σ_p = 0.03 cm, σ_o = 0.03°, σ_e = 0.3°: the middle of the ranges
    studied in Sections 7.4.1/7.4.2 (σ_p, σ_o in 0.01-0.05; σ_e in 0.1-0.5°).
    """

    position_cm: float = 0.03
    orientation_deg: float = 0.03
    encoder_deg: float = 0.3


@dataclass(frozen=True)
class TrueRobot:
    """A simulated physical robot.

    ``chain`` maps *encoder readings* (rad / cm) to the flange pose in the
    robot's mounting (base) frame; ``errors`` records what was drawn;
    ``nongeometric``: where the joints sit for given readings (compliance under gravity,
    joint-angle harmonics), None for a rigid robot; ``backlash``: the joints' backlash
    under gravity, an error the model does not have (:mod:`pipeline.rig.backlash`), None
    without.
    """

    chain: SerialChain
    errors: dict[str, object]
    nongeometric: NonGeometric | None = None
    backlash: Backlash | None = None


def where_joints_sit(
    q: npt.ArrayLike,
    nongeometric: NonGeometric | None,
    backlash: Backlash | None,
    payload_kg: npt.ArrayLike = 0.0,
) -> np.ndarray:
    """The true joint values (..., n) for readings ``q`` (..., n): the non-geometric terms'
    ``q + Δ(q)`` plus the backlash's ``b sign(τ(q))``, both under ``payload_kg`` (kg; a
    number or one per configuration): the simulator's and the audit's one definition."""
    q = np.asarray(q, float)
    out = q if nongeometric is None else nongeometric.effective(q, payload_kg)
    return out if backlash is None else out + backlash.deflection(q, payload_kg)


def _link_draws(seed: int, n: int) -> tuple[np.random.Generator, np.ndarray, np.ndarray]:
    """The stream of the true non-geometric terms (issue 27: apart from the rig's streams)
    after its first draws, the joint compliances ``c_j`` uniform in [0.5, 1.5] and the
    lumped link masses ``m_k`` uniform in [1, 10] kg (n each), which the compliance and
    the backlash share."""
    rng = np.random.default_rng([seed, 27])
    c = rng.uniform(0.5, 1.5, n)
    return rng, c, rng.uniform(1.0, 10.0, n)


def _rms_move_cm(design: SerialChain, q: np.ndarray, q_moved: np.ndarray) -> float:
    """RMS displacement (cm) of the design's tool frame origin (the flange when the
    description has no tool) from joint values ``q`` to ``q_moved`` (m, n)."""
    move = forward_kinematics(design, q_moved) - forward_kinematics(design, q)
    return float(np.sqrt(np.mean(np.sum(move[:, :3, 3] ** 2, axis=1))))


def draw_nongeometric(
    robot: RobotDescription,
    compliance_mm: float,
    harmonic_deg: float,
    seed: int,
    payloads_kg: tuple[float, ...] = (),
) -> NonGeometric | None:
    """The true non-geometric terms of a simulated robot (None when both sizes are 0),
    from their own stream of ``seed`` (the rig's other draws keep their values):

    - compliance: ``β_jk = s c_j m_k`` (:mod:`pipeline.kinematics.nongeometric`) with
      joint compliances ``c_j`` uniform in [0.5, 1.5] and lumped masses ``m_k`` uniform
      in [1, 10] kg, ``s`` chosen so that the RMS displacement of the flange over 500
      configurations drawn within the limits is ``compliance_mm`` without a payload (a
      UR10's is ~0.3 mm, issue 27); with ``payloads_kg`` the payload terms
      ``γ_j = s c_j`` (per kg) too, evaluated at the smallest payload by default;
    - harmonics: ``a_j, b_j ~ N(0, harmonic_deg / √2)`` per revolute joint (an RMS
      amplitude of ``harmonic_deg``: encoders and gears give ~0.005-0.02°).
    """
    kinds = ("compliance",) * (compliance_mm > 0) + ("harmonic",) * (harmonic_deg > 0)
    kinds += ("payload",) * (compliance_mm > 0 and len(payloads_kg) > 0)
    if not kinds:
        return None
    terms = all_terms(robot.prismatic, kinds)
    design = robot.design_chain()
    rng, c, m = _link_draws(seed, robot.n_joints)
    beta = np.array([c[j - 1] * m[k - 1] for j, k in terms.compliance])
    gamma = np.array([c[j - 1] for j in terms.payload])
    if terms.compliance:
        q = robot.random_configurations(500, seed)
        unit = NonGeometric(Terms(compliance=terms.compliance), beta * 1e-9, design)
        rms = _rms_move_cm(design, q, unit.effective(q)) / 1e-9  # cm
        beta *= compliance_mm / 10.0 / rms
        gamma *= compliance_mm / 10.0 / rms
    harm = rng.normal(0.0, np.radians(harmonic_deg) / np.sqrt(2.0), len(terms.harmonic))
    measured = tuple(sorted(set(float(p) for p in payloads_kg)))
    return NonGeometric(
        terms,
        np.concatenate([beta, gamma, harm]),
        design,
        payload_kg=measured[0] if measured else 0.0,
        measured_payloads_kg=measured,
    )


def draw_backlash(robot: RobotDescription, backlash_mm: float, seed: int) -> Backlash | None:
    """The true joints' backlash under gravity (:mod:`pipeline.rig.backlash`; None at 0):
    ``b_j = s u_j`` per revolute joint, ``u_j`` uniform in [0.5, 1.5] from a stream of its
    own (issue 41: the rig's and the compliance's draws keep their values), the torques'
    lumped masses those of the compliance truth (:func:`_link_draws`), and ``s`` such that
    the RMS displacement of the flange over 500 configurations drawn within the limits
    is ``backlash_mm`` without a payload (as ``--compliance`` is stated). Refused for an
    arm none of whose joints feels a gravity torque (a SCARA's axes are all vertical)."""
    if backlash_mm <= 0:
        return None
    design = robot.design_chain()
    _, _, m = _link_draws(seed, robot.n_joints)
    u = np.random.default_rng([seed, 41]).uniform(0.5, 1.5, robot.n_joints)
    u = np.where(robot.prismatic, 0.0, u)
    q = robot.random_configurations(500, seed)
    unit = Backlash(u * 1e-9, m, design)  # rad: small enough that the move is linear in it
    rms = _rms_move_cm(design, q, q + unit.deflection(q)) / 1e-9  # cm per unit of s
    if not rms > 0:
        raise ArmsigError(
            f"{robot.name}: no joint bears a gravity torque, so it has no backlash under gravity",
            expected="an arm with a joint whose axis is not vertical",
            got=f"--backlash-mm {backlash_mm:g}",
            fix="simulate without --backlash-mm",
        )
    return Backlash(u * (backlash_mm / 10.0 / rms), m, design)


def _small_rigid(rng: np.random.Generator, sig: ErrorSigmas) -> np.ndarray:
    p = rng.normal(0.0, sig.position_cm, 3)
    r = np.deg2rad(rng.normal(0.0, sig.orientation_deg, 3))
    return trans(*p) @ rot_x(r[0]) @ rot_y(r[1]) @ rot_z(r[2])


def draw_puma_eps(rng: np.random.Generator, sigmas: ErrorSigmas = ErrorSigmas()) -> np.ndarray:
    """Manufacturing errors ε1..ε39 of one Puma 560 (7.2)-(7.8), math units (cm / rad).

    Drawn category by category (positional, orientational, encoder), each a
    zero-mean Gaussian with its σ; this order fixes the random stream.

    Returns
    -------
    eps : ndarray, shape (39,)
    """
    eps = np.zeros(puma560.N_EPS)
    for idx, sigma in (
        (puma560.EPS_POSITIONAL, sigmas.position_cm),
        (puma560.EPS_ORIENTATIONAL, np.deg2rad(sigmas.orientation_deg)),
        (puma560.EPS_ENCODER, np.deg2rad(sigmas.encoder_deg)),
    ):
        eps[np.array(idx) - 1] = rng.normal(0.0, sigma, len(idx))
    return eps


def draw_true_robot(
    robot: RobotDescription, rng: np.random.Generator, sigmas: ErrorSigmas = ErrorSigmas()
) -> TrueRobot:
    """Draw one manufactured instance of ``robot``."""
    if robot.name == "puma560":
        eps = draw_puma_eps(rng, sigmas)
        errors: dict[str, object] = {
            "model": "puma560 (7.1)-(7.8)",
            "eps_math_units": eps.tolist(),
            "eps_positional_cm_index": list(puma560.EPS_POSITIONAL),
        }
        return TrueRobot(puma560.simulator_chain(eps), errors)
    design = robot.design_chain()
    links = design.links.copy()
    base = design.base @ _small_rigid(rng, sigmas)
    offsets = []
    for i in range(robot.n_joints):
        if design.prismatic[i]:
            off = rng.normal(0.0, sigmas.position_cm)
            motion = trans_z(off)
        else:
            off = np.deg2rad(rng.normal(0.0, sigmas.encoder_deg))
            motion = rot_z(off)
        offsets.append(float(off))
        links[i] = motion @ links[i] @ _small_rigid(rng, sigmas)
    chain = SerialChain(links=links, prismatic=design.prismatic, base=base, tool=design.tool)
    return TrueRobot(chain, {"model": "generic", "encoder_offsets_math_units": offsets})
