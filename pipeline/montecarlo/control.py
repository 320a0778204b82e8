"""Signature-based control of simulated Puma 560s (Sections 7.2.3, 7.3, 7.4.3-7.4.5).

For a batch of robots at once, the whole identification chain of ``pipeline
identify`` with the pipeline's own functions:

1. true target and probe positions of the session plan (:mod:`pipeline.rig.plan`)
   on each robot's true kinematics (model (7.1) with drawn ε);
2. slant ranges of N_avg digitize cycles per configuration
   (:func:`pipeline.rig.digitizer.digitize`: (7.9) noise × k, 0.01 cm quantization);
3. speed-of-sound compensation and triangulation with the *recorded* digitizer
   geometry (:func:`pipeline.sensor.compensation.compensate`), so a W_AC
   calibration error propagates (Section 7.3);
4. the outlier-robust mean of the cycles (:func:`pipeline.stages.triangulate.robust_mean`);
5. features (the ``features`` stage's default: repeated least-squares plane,
   oriented normal, circle), frames (4.49)-(4.51) and the probe tool
   (:func:`pipeline.stages.frames.tool_from_probe`): the signature chain;
6. Newton-Raphson control (5.4) of the Table 7-1 poses from the design
   inverse, and the true robot's flange poses at the commanded readings.

As in Section 7.2.3 only sensor errors enter: still air at 70 °F, exact joint
readings, targets where the plan puts them. The controlled frame is the
flange, as for design-model control, so the two controllers are compared on
the same poses. The signature's tool is the probe; the flange-to-probe
transform and the sensor-to-base transform (F.3) are the rig's known
calibration, taken from the noiseless identification of the same robot (so
with zero noise the error is zero up to the solver tolerance).
"""

from __future__ import annotations

import numpy as np

from pipeline.evaluation.grid12 import grid12_targets, indices34
from pipeline.kinematics.chain import SerialChain, forward_kinematics
from pipeline.kinematics.ik import newton_raphson
from pipeline.kinematics.transforms import Array, invert_transform
from pipeline.montecarlo.design import design_joints
from pipeline.montecarlo.identification import (
    Rig,
    SensorSetting,
    identify,
    measured_positions,
    positions_from_ranges,
    reference_tool_pose,
    rig_for,
    slant_ranges,
    true_chains,
    true_positions,
)

#: Robots per batch: ~6,000 cycles per robot at N_i = 100, N_avg = 10; 25 robots keep
#: the largest temporaries near 30 MB and measured fastest (10: 1.84 s, 25: 1.70 s,
#: 50: 2.06 s of CPU per 100 robots).
BATCH = 25

#: Three lines of the one-dimensional grid task of Section 7.3 (Figure 7-3):
#: X 60 cm, Y 40 cm, Z 50 cm, in the ideal base frame, tool as in Table 7-1.
LINE3_ENDPOINTS_CM = np.array(
    [
        [[-30.0, 40.0, 50.0], [30.0, 40.0, 50.0]],
        [[0.0, 40.0, 50.0], [0.0, 80.0, 50.0]],
        [[0.0, 60.0, 30.0], [0.0, 60.0, 80.0]],
    ]
)
LINE3_NAMES = ("x_line_length_error_cm", "y_line_length_error_cm", "z_line_length_error_cm")


def _repeat(chain: SerialChain, m: int) -> SerialChain:
    """A batched chain (B robots) repeated for m targets each: batch B·m."""
    return SerialChain(
        links=np.repeat(chain.links, m, axis=0),
        prismatic=chain.prismatic,
        base=np.repeat(chain.base, m, axis=0),
        tool=np.repeat(chain.tool, m, axis=0),
        joint_offsets=chain.joint_offsets,
    )


def signature_control(
    rig: Rig, true: SerialChain, signature: SerialChain, reference_tool: Array, T: Array
) -> Array:
    """Flange poses (B, m, 4, 4) reached when each signature controls its true robot, step 6.

    Parameters
    ----------
    true : SerialChain
        True robots, links (B, 1, 6, 4, 4), base = mounting frame.
    signature : SerialChain
        Identified chains (batch B).
    reference_tool : ndarray, shape (B, 4, 4)
        :func:`reference_tool_pose` of the same robots.
    T : ndarray, shape (m, 4, 4)
        Desired flange poses in the ideal base frame.
    """
    b, m = signature.links.shape[0], T.shape[0]
    sensor_from_base = rig.sensor_from_base
    qs = rig.q_signature
    flange = forward_kinematics(true, qs)[:, 0]  # (B, 4, 4)
    # flange -> signature tool: the rig's calibration, from the noiseless identification
    probe_from_flange = invert_transform(sensor_from_base @ flange) @ reference_tool
    T_sig = sensor_from_base @ T[None] @ probe_from_flange[:, None]  # (B, m, 4, 4)
    q0 = np.tile(design_joints(T), (b, 1))  # Section 5.2: design inverse of the pose
    res = newton_raphson(_repeat(signature, m), T_sig.reshape(-1, 4, 4), q0, rig.resolution)
    return forward_kinematics(true, res.q.reshape(b, m, -1))


def signature_poses(
    setting: SensorSetting, seeds: list[np.random.SeedSequence], T: Array
) -> tuple[Array, Array]:
    """Reached (B, m, 4, 4) and desired (m, 4, 4) flange poses of one batch of robots."""
    rig = rig_for(setting.points, setting.radius_cm, setting.wac_error_cm, setting.repeats)
    true = true_chains(setting, seeds)
    p_true = true_positions(rig, true)
    signature = identify(rig, measured_positions(rig, setting, p_true, seeds))
    reference = reference_tool_pose(rig, p_true)
    return signature_control(rig, true, signature, reference, T), T


def signature_indices(setting: SensorSetting, seeds: list[np.random.SeedSequence]) -> Array:
    """The 34 indices (B, 34) of signature control on the 12-vertex grid."""
    reached, desired = signature_poses(setting, seeds, grid12_targets())
    return indices34(reached, desired)


def line3_targets() -> Array:
    """The six end points (6, 4, 4) of :data:`LINE3_ENDPOINTS_CM`, Table 7-1's tool orientation."""
    T = np.tile(grid12_targets()[0], (6, 1, 1))
    T[:, :3, 3] = LINE3_ENDPOINTS_CM.reshape(6, 3)
    return T


def _line_lengths(reached: Array, desired: Array) -> Array:
    """Actual minus desired lengths (B, 3) of the three lines from end-point poses (B, 6, 4, 4)."""
    pa = reached[..., :3, 3].reshape(-1, 3, 2, 3)
    pd = desired[:, :3, 3].reshape(3, 2, 3)
    actual = np.linalg.norm(pa[..., 1, :] - pa[..., 0, :], axis=-1)
    out: Array = actual - np.linalg.norm(pd[:, 1] - pd[:, 0], axis=-1)
    return out


def line3_errors(setting: SensorSetting, seeds: list[np.random.SeedSequence]) -> Array:
    """Actual minus desired lengths (B, 3) of the X, Y, Z lines of Section 7.3 (cm)."""
    reached, desired = signature_poses(setting, seeds, line3_targets())
    return _line_lengths(reached, desired)


def misalignment_all(values: tuple[float, ...], seeds: list[np.random.SeedSequence]) -> Array:
    """Section 7.3 for every W_AC error at once: (S, B, 3) line-length errors (cm).

    As in the laboratory experiment, only the calibration data change: each robot's
    slant ranges are simulated once and identified with every recorded W_AC (common
    random numbers, so the settings are compared on the same recordings).
    """
    base = SensorSetting()
    rig0 = rig_for(base.points, None, 0.0, base.repeats)
    true = true_chains(base, seeds)
    p_true = true_positions(rig0, true)
    raw = slant_ranges(rig0, base, p_true, seeds)
    reference = reference_tool_pose(rig0, p_true)
    T = line3_targets()
    out = []
    for w in values:
        rig = rig_for(base.points, None, float(w), base.repeats)
        signature = identify(rig, positions_from_ranges(rig, raw, base.repeats))
        out.append(_line_lengths(signature_control(rig, true, signature, reference, T), T))
    return np.stack(out)


def noise_setting(k: float, seeds: list[np.random.SeedSequence]) -> Array:
    """Section 7.4.3: (7.9) times k."""
    return signature_indices(SensorSetting(noise_factor=k), seeds)


def points_setting(n: float, seeds: list[np.random.SeedSequence]) -> Array:
    """Section 7.4.4: N_i points per circle."""
    return signature_indices(SensorSetting(points=int(n)), seeds)


def radius_setting(r: float, seeds: list[np.random.SeedSequence]) -> Array:
    """Section 7.4.5: every target at radius R_nom (cm)."""
    return signature_indices(SensorSetting(radius_cm=r), seeds)


def misalignment_setting(w: float, seeds: list[np.random.SeedSequence]) -> Array:
    """Section 7.3: W_AC recorded ``w`` cm off its true 203 cm."""
    return line3_errors(SensorSetting(wac_error_cm=w), seeds)
