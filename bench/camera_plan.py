"""Planned camera images against random ones (issue 39, ``pipeline plan --sensor camera``).

Per robot (Puma 560, UR10), set-up and image count (20, 40): one plan, made before any
seed (:func:`pipeline.planning.camera.plan_camera_poses`, seed-0 candidates), then per
seed a session simulated with the plan (``simulate --plan``) and one with as many random
images (``simulate --poses N``, the simulator's own draws), each fitted and audited as
:func:`bench.camera.one` does: the tool point's RMS error over 1,000 random
configurations against ``rig-truth.json`` (raw: a camera's frames are physical), and the
fit's own predicted RMS. Printed: the medians over the seeds, planned/random, and the
plan's prediction against its audited median. ``BENCH_CAMERA_SEEDS`` sets the seeds (5).
"""

from __future__ import annotations

import statistics
import tempfile
from pathlib import Path

from bench.camera import ROBOTS, SEEDS, one
from pipeline.planning import write_plan
from pipeline.planning.camera import camera_rig, plan_camera_poses
from pipeline.rig import camera
from pipeline.rig.options import SimulationOptions
from pipeline.robots import get_robot

SIZES = (20, 40)


def study(name: str, robot: str, setup: str, n: int, tmp: Path) -> dict:
    """One row of the table (module docstring)."""
    o = SimulationOptions()
    rig = camera_rig(setup, camera.DEFAULT_TARGET, o.resolution_px, o.focal_px, o.distortion,
                     o.pixel_noise_px)  # fmt: skip
    desc = get_robot(robot)
    plan = plan_camera_poses(desc, rig, n)
    f = write_plan(tmp / f"{name}-{setup}-{n}.csv", desc, plan, force=True)
    seeds = range(1, SEEDS + 1)
    planned = [one(tmp / "p", robot, setup, n, s, {"plan_file": str(f)}) for s in seeds]
    random = [one(tmp / "r", robot, setup, n, s) for s in seeds]

    def med(rows: list[dict], key: str) -> float:
        return statistics.median(r[key] for r in rows)

    return {
        "robot": name, "setup": setup, "images": n,
        "plan_pred_mm": 10 * plan.rms_cm, "plan_random_pred_mm": 10 * plan.random_rms_cm,
        "planned_mm": med(planned, "rms_mm"), "random_mm": med(random, "rms_mm"),
        "planned_aud_pred": statistics.median(r["rms_mm"] / r["pred_mm"] for r in planned),
        "random_aud_pred": statistics.median(r["rms_mm"] / r["pred_mm"] for r in random),
        "kept": min(r["images"] for r in planned),
    }  # fmt: skip


def main() -> None:
    print(f"camera plans (issue 39): {SEEDS} seeds, 0.2 px; medians of the tool point's RMS "
          "error (mm) over 1000 random configurations, raw")  # fmt: skip
    head = ("robot", "setup", "images", "plan predicted", "random predicted (plan)",
            "planned audited", "random audited", "planned/random", "audited/plan predicted",
            "aud/pred planned", "aud/pred random", "fewest kept")  # fmt: skip
    print(" | ".join(head), flush=True)
    with tempfile.TemporaryDirectory() as t:
        for name, robot in ROBOTS:
            for setup in ("eye-to-hand", "eye-in-hand"):
                for n in SIZES:
                    r = study(name, robot, setup, n, Path(t))
                    cells = (
                        name, setup, n, f"{r['plan_pred_mm']:.3f}",
                        f"{r['plan_random_pred_mm']:.3f}", f"{r['planned_mm']:.3f}",
                        f"{r['random_mm']:.3f}", f"{r['planned_mm'] / r['random_mm']:.2f}",
                        f"{r['planned_mm'] / r['plan_pred_mm']:.2f}",
                        f"{r['planned_aud_pred']:.2f}", f"{r['random_aud_pred']:.2f}", r["kept"],
                    )  # fmt: skip
                    print(" | ".join(map(str, cells)), flush=True)


if __name__ == "__main__":
    main()
