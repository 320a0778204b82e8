"""Issue 39's hand-eye alone: the chain held at its design, as the peers do, on the
sessions of the accuracy study (``bench.camera``: Puma and UR10, both set-ups, 40 and 150
images, default pixel noise 0.2 px, ``SEEDS`` seeds).

Per session, the two hand-eye transforms (the fixed body in the base: eye-to-hand the
camera, eye-in-hand the target; the flange's body on the flange: the target or the
camera) of

- armsig's reprojection fit with the chain at its design (``fit_camera(...,
  chain="design")``), the lens fitted, and the lens held at ``cv2.calibrateCamera``'s
  (the start's calibration: the peers' lens);
- OpenCV's closed forms on the design's flange poses at the readings and the PnP poses of
  that lens (:mod:`bench.hand_eye_real`: ``calibrateHandEye`` Tsai, Park, Horaud, Andreff,
  Daniilidis, the other transform the mean of its per-view values;
  ``calibrateRobotWorldHandEye`` Shah, Li);
- armsig's whole-chain fit (for reference: the chain fitted too; audited in the truth's
  frames by alignment, :func:`pipeline.rig.camera_audit.audit_camera_fit`),

each against the truth's transforms (mm, deg). The primary transform is the one
``calibrateHandEye`` gives (eye-to-hand: the camera in the base; eye-in-hand: the camera
on the flange); ranks are over the 9 hand-eye-alone methods. Printed per row: each
method's median over the seeds, armsig's median rank, how often it is at most the
session's best, and at most the method best by median. ``python -m bench.camera_hand_eye``
(the study, 30 minutes on the shared 2-core machine; ``BENCH_CAMERA_SEEDS``; ``--perfect``:
:func:`perfect`); ``make bench`` runs :func:`quick`.
"""

from __future__ import annotations

import json
import statistics
import tempfile
from pathlib import Path

import numpy as np

from bench.camera import ROBOTS, SEEDS, get_desc, tables
from bench.hand_eye_real import HAND_EYE, ROBOT_WORLD, RealSet, hand_eye, robot_world

SETUPS = ("eye-to-hand", "eye-in-hand")
ARMSIG = ("armsig, lens fitted", "armsig, lens from calibrateCamera")
METHODS = (*ARMSIG, *(f"calibrateHandEye {m}" for m in HAND_EYE),
           *(f"calibrateRobotWorldHandEye {m}" for m in ROBOT_WORLD))  # fmt: skip
WHOLE = "armsig, whole chain fitted"


def session(d: Path, robot: str, setup: str, images: int, seed: int,
            extra: dict | None = None) -> dict[str, tuple[float, float, float, float]]:  # fmt: skip
    """Every method's errors of one simulated session: (fixed mm, fixed deg, flange mm,
    flange deg) against the truth (module docstring); ``extra``: more simulation options."""
    from pipeline.kinematics.chain import link_frames
    from pipeline.kinematics.transforms import invert_transform
    from pipeline.refine.camera_fit import fit_camera
    from pipeline.rig.camera_audit import audit_camera_fit, pose_errors, true_hand_eye
    from pipeline.rig.simulate import SimulationOptions, simulate_session
    from pipeline.sensor.camera import Intrinsics
    from pipeline.stages import camera_fit

    opts = SimulationOptions(robot=robot, sensor="camera", setup=setup, poses=images,
                             seed=seed, **(extra or {}))  # fmt: skip
    simulate_session(d, opts, force=True)
    truth = json.loads((d / "rig-truth.json").read_text())
    want = true_hand_eye(truth)
    t = tables(d)
    det, design, lens, _ = camera_fit.detections_for_fit(t)
    n = design.n_joints
    F_s = link_frames(design, det.q_signature[None])[0, n]

    def held(fit) -> tuple[np.ndarray, np.ndarray]:  # (fixed in base, body on flange)
        T = fit.tool_poses(det.q_signature[None], det.q_signature)[0]
        return np.asarray(fit.fixed_in_base), np.asarray(invert_transform(F_s) @ T)

    pairs = {}
    fit = fit_camera(det, design, lens, setup, chain="design")
    pairs[ARMSIG[0]] = held(fit)
    calib = Intrinsics.from_vector(lens.width_px, lens.height_px, fit.start.intrinsics)
    pairs[ARMSIG[1]] = held(fit_camera(det, design, calib, setup, "fixed", chain="design"))
    s = RealSet(det.image, det.local, det.uv, link_frames(design, det.q)[:, n], calib, setup)
    K, dist = calib.opencv()
    for m in HAND_EYE:
        pairs[f"calibrateHandEye {m}"] = hand_eye(s, m, K, dist)
    for m in ROBOT_WORLD:
        pairs[f"calibrateRobotWorldHandEye {m}"] = robot_world(s, m, K, dist)
    out = {}
    for name, pair in pairs.items():
        (p0, a0), (p1, a1) = (pose_errors(T, W) for T, W in zip(pair, want, strict=True))
        out[name] = (10 * float(p0), float(a0), 10 * float(p1), float(a1))
    a = audit_camera_fit(fit_camera(det, design, lens, setup), truth, get_desc(t),
                         det.q_signature)  # fmt: skip
    out[WHOLE] = (10 * a.fixed_position_cm, a.fixed_orientation_deg,
                  10 * a.flange_position_cm, a.flange_orientation_deg)  # fmt: skip
    return out


def primary(setup: str, e: tuple[float, float, float, float]) -> tuple[float, float]:
    """(mm, deg) of the transform ``calibrateHandEye`` gives (module docstring)."""
    return (e[0], e[1]) if setup == "eye-to-hand" else (e[2], e[3])


def summary(setup: str, runs: list[dict]) -> dict[str, object]:
    """Medians over the seeds, armsig's ranks and how often it is at most the best, for
    position (mm) and rotation (deg) of the primary transform, per armsig variant."""
    med = {m: tuple(statistics.median(r[m][k] for r in runs) for k in range(4))
           for m in (*METHODS, WHOLE)}  # fmt: skip
    out: dict[str, object] = {"median": med}
    for k, unit in enumerate(("mm", "deg")):
        by_median = min(METHODS[2:], key=lambda m: primary(setup, med[m])[k])
        for a in ARMSIG:
            mine = [primary(setup, r[a])[k] for r in runs]
            others = [[primary(setup, r[m])[k] for m in METHODS[2:]] for r in runs]
            rank = [1 + sum(o < v for o in row) for v, row in zip(mine, others, strict=True)]
            out[a, unit] = (
                statistics.median(rank),
                sum(v <= min(row) for v, row in zip(mine, others, strict=True)),
                sum(v <= primary(setup, r[by_median])[k] for v, r in zip(mine, runs, strict=True)),
                by_median,
            )
    return out


def table(robots=ROBOTS, sizes: tuple[int, ...] = (40, 150), seeds: int = SEEDS,
          extra: dict | None = None) -> None:  # fmt: skip
    """The study (module docstring) over ``robots``, both set-ups, ``sizes`` images and
    ``seeds`` seeds; ``extra``: more simulation options of every session."""
    print(f"camera hand-eye alone (chain at design), 0.2 px, median of {seeds} seeds "
          f"{extra or ''}; mm / deg of the fixed body in the base, then of the flange's "
          "body on the flange")  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:
        for name, robot in robots:
            for setup in SETUPS:
                for images in sizes:
                    runs = [session(Path(tmp) / "s", robot, setup, images, seed, extra)
                            for seed in range(1, seeds + 1)]  # fmt: skip
                    _print(f"{name} {setup} {images}", setup, runs, seeds)


def _print(row: str, setup: str, runs: list[dict], seeds: int) -> None:
    s = summary(setup, runs)
    med = s["median"]
    assert isinstance(med, dict)
    for m in (*METHODS, WHOLE):
        f0, d0, f1, d1 = med[m]
        print(f"  {row} | {m} | {f0:.3f} / {d0:.4f} | {f1:.3f} / {d1:.4f}")
    for a in ARMSIG:
        for unit in ("mm", "deg"):
            rank, best, by_median, which = s[a, unit]  # type: ignore[misc]
            print(f"  {row} | {a} | primary {unit}: median rank {rank:g} of 8 | <= the "
                  f"session's best {best}/{seeds} | <= {which} (best by median) "
                  f"{by_median}/{seeds}", flush=True)  # fmt: skip


def quick() -> None:
    """``make bench``: both robots and set-ups, 40 images, 3 seeds."""
    table(ROBOTS, (40,), 3)


def perfect() -> None:
    """The same problem with the true robot equal to the design (no manufacturing error;
    the readings still rounded): the peers' problem without the chain's error, where a
    reprojection fit is the maximum-likelihood estimate. Puma, 40 images, 3 seeds."""
    from pipeline.rig.true_robot import ErrorSigmas

    table(ROBOTS[:1], (40,), 3, {"sigmas": ErrorSigmas(0.0, 0.0, 0.0)})


if __name__ == "__main__":
    import sys

    if "--perfect" in sys.argv:
        perfect()
    else:
        table()
