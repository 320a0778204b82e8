"""Simulated identification of a batch of robots: steps 1-5 of :mod:`pipeline.montecarlo.control`.

The whole chain of ``pipeline identify`` with the pipeline's own functions, on
arrays with a leading robot axis: the session plan's configurations on each
robot's true kinematics, digitizer slant ranges, speed-of-sound compensation and
triangulation with the recorded geometry, the outlier-robust cycle mean, the
feature fits, the S-Model frames and the probe tool.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cache

import numpy as np
import numpy.typing as npt

from pipeline.errors import ArmsigError
from pipeline.features.circle import fit_circle
from pipeline.features.plane import fit_plane_lsq, orient_normal
from pipeline.kinematics.chain import SerialChain
from pipeline.kinematics.signature import frame_from_features, signature_chain
from pipeline.kinematics.transforms import Array
from pipeline.montecarlo.design import puma_eps_batch
from pipeline.montecarlo.stats import generators
from pipeline.rig.atmosphere import Atmosphere
from pipeline.rig.digitizer import DigitizerModel, digitize
from pipeline.rig.plan import (
    TABLE_F_1_Z_CM,
    MeasurementPlan,
    default_sensor_from_base,
    plan_measurements,
    target_positions,
    tool_positions,
)
from pipeline.rig.true_robot import ErrorSigmas
from pipeline.robots import get_robot, puma560
from pipeline.sensor.compensation import compensate
from pipeline.sensor.geometry import W_AB_CM, W_AC_CM, W_BC_CM, DigitizerGeometry, default_geometry
from pipeline.stages.frames import tool_from_probe
from pipeline.stages.triangulate import Params as TriangulateParams
from pipeline.stages.triangulate import robust_mean
from pipeline.units import joints_to_internal


@dataclass(frozen=True)
class SensorSetting:
    """One setting of a signature-control study (boundary units).

    ``radius_cm`` None keeps Table 6-1's radii; ``sigmas`` are the manufacturing
    errors of the true robots (signature control does not depend on them).
    """

    noise_factor: float = 1.0
    points: int = 100
    radius_cm: float | None = None
    wac_error_cm: float = 0.0
    repeats: int = 10
    quantize: bool = True
    sigmas: ErrorSigmas = field(default_factory=ErrorSigmas)


@dataclass(frozen=True, eq=False)
class Rig:
    """What all robots of a setting share: plan, geometries, configurations."""

    plan: MeasurementPlan
    sensor_from_base: Array
    geometry_true: DigitizerGeometry
    geometry_recorded: DigitizerGeometry
    q_cmd: Array  # (C, 6) rad: sweeps n..1 in plan order, then the tool probe
    rows: dict[int, npt.NDArray[np.intp]]  # joint -> rows of its sweep; 0 -> tool row
    q_signature: Array  # (6,) rad
    resolution: Array  # (6,) rad


@cache
def _plan(points: int, radius_cm: float | None, repeats: int) -> MeasurementPlan:
    """The session plan (2 s: cached per process). It is made on the nominal digitizer
    geometry, as an operator plans once for the rig; ``pipeline simulate`` plans on the
    recorded one, which differs only in the W_AC study, by at most 1 cm."""
    robot = get_robot("puma560")
    local = None
    if radius_cm is not None:
        local = [(float(radius_cm), 0.0, z) for z in TABLE_F_1_Z_CM]
    return plan_measurements(
        robot,
        default_geometry(),
        default_sensor_from_base(robot),
        points,
        repeats,
        target_local=local,
    )


@cache
def rig_for(points: int, radius_cm: float | None, wac_error_cm: float, repeats: int) -> Rig:
    """The session plan and digitizer of one setting (as ``pipeline simulate`` makes them)."""
    robot = get_robot("puma560")
    sensor_from_base = default_sensor_from_base(robot)
    recorded = default_geometry(W_AB_CM, W_BC_CM, W_AC_CM + wac_error_cm)
    plan = _plan(points, radius_cm, repeats)
    qs = np.array(plan.signature_q)
    q_rows, rows, start = [], {}, 0
    for sweep in plan.sweeps:
        values = np.array(sweep.q_values)
        if not np.all(np.diff(values) > 0):  # the features stage orders points by reading
            raise ArmsigError("plan sweep not increasing", got=f"joint {sweep.joint}")
        q = np.tile(qs, (len(values), 1))
        q[:, sweep.joint - 1] = values
        q_rows.append(q)
        rows[sweep.joint] = np.arange(start, start + len(values))
        start += len(values)
    q_rows.append(qs[None])
    rows[0] = np.array([start])
    pris = robot.prismatic
    return Rig(
        plan=plan,
        sensor_from_base=sensor_from_base,
        geometry_true=default_geometry(),
        geometry_recorded=recorded,
        q_cmd=joints_to_internal(np.concatenate(q_rows), pris),
        rows=rows,
        q_signature=joints_to_internal(qs, pris),
        resolution=joints_to_internal(robot.encoder_resolution, pris),
    )


def _child(seed: np.random.SeedSequence, k: int) -> np.random.SeedSequence:
    """Child ``k`` of a robot's seed (what ``seed.spawn`` would give, without its state)."""
    return np.random.SeedSequence(seed.entropy, spawn_key=(*seed.spawn_key, k))


def true_chains(setting: SensorSetting, seeds: list[np.random.SeedSequence]) -> SerialChain:
    """True robots (model (7.1)), links (B, 1, 6, 4, 4): one per seed, a broadcast axis for q."""
    eps = puma_eps_batch([_child(s, 0) for s in seeds], setting.sigmas)
    chain = puma560.simulator_chain(eps)
    return SerialChain(
        links=chain.links[:, None], prismatic=chain.prismatic, base=chain.base[:, None]
    )


def true_positions(rig: Rig, chain: SerialChain) -> Array:
    """Sensor-frame target (and probe) positions (B, C, 3) at every planned configuration."""
    out = []
    for sweep in rig.plan.sweeps:
        q = rig.q_cmd[rig.rows[sweep.joint]]
        local = np.array(sweep.target_local_cm)
        out.append(target_positions(chain, rig.sensor_from_base, q, sweep.joint, local))
    tool = np.array(rig.plan.tool_local_cm)
    out.append(tool_positions(chain, rig.sensor_from_base, rig.q_cmd[rig.rows[0]], tool))
    return np.concatenate(out, axis=-2)


def slant_ranges(
    rig: Rig, setting: SensorSetting, p_true: Array, seeds: list[np.random.SeedSequence]
) -> Array:
    """Raw slant ranges (B, C·N_avg, 5, 4) of N_avg digitize cycles per configuration, step 2."""
    b, c, _ = p_true.shape
    a = setting.repeats
    streams = generators([_child(s, 1) for s in seeds])
    z = np.stack([g.standard_normal((c * a, 5, 4)) for g in streams])
    model = DigitizerModel(
        rig.geometry_true, noise_factor=setting.noise_factor, quantize=setting.quantize
    )
    cycles = np.repeat(p_true, a, axis=1).reshape(-1, 3)
    # Still air: no time dependence; the rng is not drawn from (no drop-outs or outliers).
    raw = digitize(
        model, Atmosphere(), cycles, np.zeros(len(cycles)), np.random.default_rng(0),
        standard_normal=z.reshape(-1, 5, 4),
    )  # fmt: skip
    return raw.reshape(b, c * a, 5, 4)


def positions_from_ranges(rig: Rig, raw: Array, repeats: int) -> Array:
    """Compensate with the recorded geometry and average the cycles: (B, C, 3), steps 3-4."""
    b = raw.shape[0]
    res = compensate(raw, rig.geometry_recorded)
    if not res.valid.all():
        raise ArmsigError(
            "Monte-Carlo: a simulated cycle has no position",
            expected="every target within the digitizer's range (the plan keeps a margin)",
            got=f"{int((~res.valid).sum())} invalid cycles",
        )
    tri = TriangulateParams()
    p = res.p_cm.reshape(b, -1, repeats, 3)
    mean, _ = robust_mean(p, tri.reject_k, tri.floor_cm)
    return mean


def measured_positions(
    rig: Rig, setting: SensorSetting, p_true: Array, seeds: list[np.random.SeedSequence]
) -> Array:
    """Digitize, compensate and average: measured positions (B, C, 3), steps 2-4."""
    raw = slant_ranges(rig, setting, p_true, seeds)
    return positions_from_ranges(rig, raw, setting.repeats)


def _sweep_frame(pts: Array) -> Array:
    """``S̄_{i-1}`` (B, 4, 4) from sweep i's positions (B, N, 3) in increasing readings
    (as ``stages.features.sweep_points`` orders them), with the features stage's default
    plane method ``lsq``."""
    plane = fit_plane_lsq(pts)
    axis = orient_normal(plane.normal, pts)
    circle = fit_circle(pts, plane)
    return frame_from_features(axis, circle.center, pts[:, 0])  # Eq. (4.49), (4.50)


def identify(rig: Rig, p: Array) -> SerialChain:
    """Signature chains (batch B, with the probe tool) from measured positions (B, C, 3), step 5."""
    n = len(rig.q_signature)
    frames = np.zeros((p.shape[0], n + 1, 4, 4))
    for i in range(1, n + 1):
        frames[:, i - 1] = _sweep_frame(p[:, rig.rows[i]])
    frames[:, n] = frames[:, n - 1]  # S̄_n = S̄_{n-1}
    pris = np.zeros(n, bool)
    bare = signature_chain(frames, rig.q_signature, pris)
    tool = tool_from_probe(bare, rig.q_signature, p[:, rig.rows[0][0]])
    return signature_chain(frames, rig.q_signature, pris, tool)


def reference_tool_pose(rig: Rig, p_true: Array) -> Array:
    """Signature tool pose (B, 4, 4) at q^s of the noiseless identification, sensor frame.

    At the signature readings every joint motion is the identity, so the tool pose
    is ``S̄_n · tool``: the orientation of joint n's frame and the probe position.
    Only joint n's sweep is fitted (the full noiseless chain gives the same pose).
    """
    n = len(rig.q_signature)
    S = _sweep_frame(p_true[:, rig.rows[n]])  # S̄_n = S̄_{n-1}
    S[:, :3, 3] = p_true[:, rig.rows[0][0]]  # the tool's origin is the probe
    return S
