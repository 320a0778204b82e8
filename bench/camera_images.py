"""Rendered camera sessions (issue 40): ``simulate --sensor camera --images`` identified
through the ``detections`` stage that detects the PNGs, audited against the truth.

Per row: a UR10 session (eye-to-hand or eye-in-hand, ``IMAGES`` images of 1280 × 960 px,
the default ChArUco board and lens), noiseless (no blur, no noise, no vignette) or with
the defaults (0.5 px blur, 2 grey levels of noise, 30 % vignette), ``SEEDS`` seeds of the
latter. Printed: the tool point's RMS error over 1,000 random configurations (the fitted
chain against the truth, no alignment: :func:`bench.camera.one`), the corners' own error
(the detected pixels against the truth's projection at the recorded joints: RMS per
coordinate, and their mean, the bias), the session's corner-level Cramér-Rao bound (the
fit's unscaled covariance at the stated 0.2 px, rescaled to the corners' RMS: what a
detector with unbiased errors of that size would allow) and their ratio.
``BENCH_CAMERA_IMAGES_SEEDS``, ``BENCH_CAMERA_IMAGES``, ``BENCH_CAMERA_RESOLUTION`` and
``BENCH_CAMERA_FOCAL`` (px) set them; ``python -m bench.camera_images``.
"""

from __future__ import annotations

import json
import os
import statistics
import tempfile
from pathlib import Path

import numpy as np

from bench.camera import UR10, one, tables
from pipeline.kinematics.chain import link_frames
from pipeline.kinematics.transforms import invert_transform
from pipeline.rig.audit import true_chain
from pipeline.rig.camera_audit import true_hand_eye
from pipeline.robots.description import description_from_dict
from pipeline.sensor.camera import Intrinsics, project
from pipeline.sensor.target import target_from_dict
from pipeline.stages.base import RECORDING
from pipeline.units import joints_to_internal

SEEDS = int(os.environ.get("BENCH_CAMERA_IMAGES_SEEDS", "5"))
IMAGES = int(os.environ.get("BENCH_CAMERA_IMAGES", "40"))
RESOLUTION = tuple(int(v) for v in os.environ.get("BENCH_CAMERA_RESOLUTION", "1280x960").split("x"))
FOCAL_PX = float(os.environ.get("BENCH_CAMERA_FOCAL", "1000"))


def corner_errors(d: Path) -> np.ndarray:
    """(N, 2) px: every detected corner against the truth's projection of its point at the
    recorded joint readings (the encoder's; its rounding moves a pixel ~0.01 px)."""
    truth = json.loads((d / "rig-truth.json").read_text())
    t = tables(d)
    rec, det = t[RECORDING], t["detections"].to_pydict()
    target = target_from_dict(rec.rig["target"], "target")
    ids, local = target.points()
    desc = description_from_dict(rec.robot["robot"])
    q = joints_to_internal(rec.q_encoder, desc.prismatic)
    _, on_flange = true_hand_eye(truth)
    tool = link_frames(true_chain(truth), q)[:, desc.n_joints] @ on_flange  # in the sensor
    T = tool if truth["camera"]["setup"] == "eye-to-hand" else invert_transform(tool)
    lens = Intrinsics.from_dict(truth["camera"]["intrinsics_true"])
    row = {int(s): k for k, s in enumerate(rec.joint_step)}
    img = np.array([row[int(s)] for s in det["image"]])
    pts = local[np.searchsorted(ids, np.array(det["point_id"]))]
    p_cam = np.einsum("mij,mj->mi", T[img, :3, :3], pts) + T[img, :3, 3]
    uv = np.stack([det["u_px"], det["v_px"]], axis=1)
    return np.asarray(uv - project(p_cam, lens.vector()))


def session(d: Path, setup: str, seed: int, noiseless: bool) -> dict:
    extra = {"images": True, "noiseless": noiseless, "resolution_px": RESOLUTION,
             "focal_px": FOCAL_PX}  # fmt: skip
    r = one(d, UR10, setup, IMAGES, seed, extra)
    err = corner_errors(d)
    sigma = float(np.sqrt(np.mean(err**2)))
    r["corner_px"], r["bias_px"] = sigma, float(np.abs(err.mean(axis=0)).max())
    r["crb_corner_mm"] = r["crb_mm"] * sigma / 0.2  # the stated σ of a simulated session
    return r


def main() -> None:
    print(
        f"rendered camera sessions (issue 40): UR10, {IMAGES} images of "
        f"{RESOLUTION[0]}x{RESOLUTION[1]} px; tool point RMS over 1000 configurations"
    )
    head = ("setup", "rendering", "seed", "points", "audited mm", "corner px", "bias px",
            "CRB(corner) mm", "aud/CRB", "rms px", "lens rel")  # fmt: skip
    print(" | ".join(head))
    with tempfile.TemporaryDirectory() as tmp:
        for setup in ("eye-to-hand", "eye-in-hand"):
            runs = [("noiseless", 1, True)] + [("blurred", s, False) for s in range(1, SEEDS + 1)]
            ratios = []
            for kind, seed, quiet in runs:
                r = session(Path(tmp) / f"{setup}{seed}{kind}", setup, seed, quiet)
                ratio = r["rms_mm"] / r["crb_corner_mm"]
                if not quiet:
                    ratios.append(ratio)
                cells = (setup, kind, seed, r["points"], f"{r['rms_mm']:.4f}",
                         f"{r['corner_px']:.3f}", f"{r['bias_px']:.3f}",
                         f"{r['crb_corner_mm']:.4f}", f"{ratio:.2f}", f"{r['rms_px']:.3f}",
                         f"{r['k_rel']:.1e}")  # fmt: skip
                print(" | ".join(map(str, cells)), flush=True)
            print(
                f"{setup}: audited/CRB(corner) over {len(ratios)} seeds: median "
                f"{statistics.median(ratios):.2f}, max {max(ratios):.2f}",
                flush=True,
            )


def quick() -> None:
    """`make bench`'s entry: one noiseless rendered session (UR10, eye-in-hand), the floor
    detection leaves; the study is ``python -m bench.camera_images`` (~11 minutes)."""
    import time

    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        r = session(Path(tmp) / "s", "eye-in-hand", 1, True)
        wall = time.perf_counter() - t0
    print(f"rendered camera session (issue 40): UR10 eye-in-hand, {IMAGES} noiseless images of "
          f"{RESOLUTION[0]}x{RESOLUTION[1]} px: tool point {r['rms_mm']:.4f} mm RMS, corners "
          f"{r['corner_px']:.3f} px from the truth, CRB(corner) {r['crb_corner_mm']:.4f} mm; "
          f"{wall:.1f} s wall, simulation to fit")  # fmt: skip


if __name__ == "__main__":
    main()
