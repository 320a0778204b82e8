"""The fit against a floor (issue 45): a plain dense numpy Gauss-Newton of the same
least squares, side by side with armsig's fit on the same pose sets.

The floor fits the same kinematics to the same points: the design chain's constant
transforms ``C_1 = base, C_{i+1} = K̄_i`` (the last one times the tool), each corrected by a
6-dof right perturbation, every joint turning about its frame's z, one point per target on
the last frame; the whole tracker frame registered by the first. That is 6 (n + 1) + 3 t
parameters of which the points identify the same 4 n + 3 t as armsig's S-Model (Stone's
count; the rest are redundant), so each step is the minimum-norm least-squares step
(``numpy.linalg.lstsq`` on the dense 3 N × P Jacobian, analytic: a translation column is
the frame's axis, a rotation column the axis crossed with the lever). It starts at the
design chain registered to the points by Kabsch and stops when a step changes the sum of
squares by less than 1e-12 of it. One BLAS thread, as armsig's stages run.

Printed per pose set: armsig's fit CPU (stages ``frames`` and ``refine`` of a cold
``pipeline identify --param refine.nongeometric=none --param refine.loss=linear``: the
rigid chain, unweighted by a robust loss, the floor's problem), the floor's CPU, their
ratio (issue 45's goal ≤ 2) and both RMS residuals (the same optimum to the weights'
difference: armsig weighs each point by its recorded σ and the encoders' rounding, the
floor weighs them equally). ``python -m bench.fit_floor``; ``BENCH_RUNS`` runs, median.
A second line per set: armsig's fit in a warm process (:data:`_WARM`), the floor's own
state: the cold identify's fit includes the one-off imports its stages make on first use.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import polars as pl
from threadpoolctl import threadpool_limits

from bench.pose_sets import UR10, real_ur10_c
from pipeline.kinematics.chain import SerialChain, link_frames
from pipeline.robots import get_robot
from pipeline.units import joints_to_internal

RUNS = int(os.environ.get("BENCH_RUNS", "3"))
ARMSIG_FIT = ("--param", "refine.nongeometric=none", "--param", "refine.loss=linear")


def read_pose_set(d: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Joint readings (N, n) in degrees, measured points (M, 3) cm and each point's pose
    row (M,), joined by (sweep, step) from the session's stage tables."""
    joints = pl.read_ipc(d / "stages" / "joints.arrow")
    wide = joints.pivot(on="joint", index=["sweep", "step"], values="q_deg").sort("sweep", "step")
    pos = pl.read_ipc(d / "stages" / "positions.arrow").select(
        "sweep", "step", "target", "x_cm", "y_cm", "z_cm"
    )
    rows = wide.with_row_index("row").select("sweep", "step", "row")
    points = pos.join(rows, on=["sweep", "step"], how="inner").sort("target", "row")
    q = wide.drop("sweep", "step").to_numpy()
    xyz = points.select("x_cm", "y_cm", "z_cm").to_numpy()
    target = points["target"].to_numpy()
    _, t_index = np.unique(target, return_inverse=True)
    return q, xyz, np.stack([points["row"].to_numpy(), t_index], axis=1)


def _exp(delta: np.ndarray) -> np.ndarray:
    """exp of a 6-vector (ρ, φ) as a 4 × 4 (rotation by Rodrigues, translation ρ: a
    first-order step, exact enough for Gauss-Newton's update)."""
    rho, phi = delta[:3], delta[3:]
    a = float(np.linalg.norm(phi))
    K = np.array([[0, -phi[2], phi[1]], [phi[2], 0, -phi[0]], [-phi[1], phi[0], 0]])
    R = np.eye(3) if a < 1e-15 else (
        np.eye(3) + np.sin(a) / a * K + (1 - np.cos(a)) / a**2 * K @ K
    )  # fmt: skip
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, rho
    return T


def _rz(q: np.ndarray) -> np.ndarray:
    c, s = np.cos(q), np.sin(q)
    R = np.zeros((*q.shape, 4, 4))
    R[..., 0, 0], R[..., 0, 1], R[..., 1, 0], R[..., 1, 1] = c, -s, s, c
    R[..., 2, 2] = R[..., 3, 3] = 1.0
    return R


def _kabsch(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The rigid motion (4, 4) taking points ``a`` onto ``b`` (least squares)."""
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    U, _, Vt = np.linalg.svd((a - ca).T @ (b - cb))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    T = np.eye(4)
    T[:3, :3] = Vt.T @ D @ U.T
    T[:3, 3] = cb - T[:3, :3] @ ca
    return T


def _frames(C: np.ndarray, Rz: np.ndarray) -> np.ndarray:
    """(N, n + 1, 4, 4): the frame after each ``C_i`` (where its perturbation acts)."""
    n = Rz.shape[1]
    G = np.empty((len(Rz), n + 1, 4, 4))
    G[:, 0] = C[0]
    for i in range(n):
        G[:, i + 1] = G[:, i] @ Rz[:, i] @ C[i + 1]
    return G


def _points(G: np.ndarray, tool: np.ndarray, pose: np.ndarray, target: np.ndarray) -> np.ndarray:
    last = G[pose, -1]
    return np.einsum("mij,mj->mi", last[:, :3, :3], tool[target]) + last[:, :3, 3]


def floor_fit(
    chain: SerialChain, q: np.ndarray, xyz: np.ndarray, rows: np.ndarray, iterations: int = 50
) -> tuple[np.ndarray, int]:
    """The floor's Gauss-Newton (module docstring), a step halved until it lowers the sum
    of squares: the residuals (M, 3) cm at its optimum and the iterations taken. ``q``
    (N, n) internal units (rad), revolute joints."""
    n = chain.n_joints
    C = np.concatenate([chain.base[None], chain.links], axis=0).copy()  # C_1 … C_{n+1}
    C[-1] = C[-1] @ chain.tool
    offsets = np.zeros(n) if chain.joint_offsets is None else chain.joint_offsets
    Rz = _rz(q - offsets)  # (N, n, 4, 4)
    pose, target = rows[:, 0], rows[:, 1]
    n_t = int(target.max()) + 1
    tool = np.zeros((n_t, 3))
    G0 = link_frames(chain, q)[:, n + 1]  # the design's tool frame: registered by Kabsch
    C[0] = _kabsch(G0[pose, :3, 3], xyz) @ C[0]
    p_count = 6 * (n + 1) + 3 * n_t
    G = _frames(C, Rz)
    r = _points(G, tool, pose, target) - xyz
    ssr, taken = float(np.sum(r * r)), 0
    for it in range(1, iterations + 1):
        taken = it
        p = r + xyz
        J = np.zeros((len(p), 3, p_count))
        for i in range(n + 1):
            R = G[pose, i, :3, :3]
            lever = p - G[pose, i, :3, 3]
            J[:, :, 6 * i : 6 * i + 3] = R
            # rotation about ω = R e_k: (R e_k) × lever = -lever × (R e_k)
            J[:, :, 6 * i + 3 : 6 * i + 6] = -np.cross(lever[:, :, None], R, axis=1)
        for t in range(n_t):
            on = target == t
            J[on, :, 6 * (n + 1) + 3 * t : 6 * (n + 1) + 3 * t + 3] = G[pose[on], n, :3, :3]
        step = np.linalg.lstsq(J.reshape(-1, p_count), -r.reshape(-1), rcond=1e-10)[0]
        for _ in range(30):  # halve the step until it lowers the sum of squares
            C_new = np.array([C[i] @ _exp(step[6 * i : 6 * i + 6]) for i in range(n + 1)])
            tool_new = tool + step[6 * (n + 1) :].reshape(n_t, 3)
            G_new = _frames(C_new, Rz)
            r_new = _points(G_new, tool_new, pose, target) - xyz
            ssr_new = float(np.sum(r_new * r_new))
            if ssr_new <= ssr:
                break
            step = step / 2
        else:
            break
        done = ssr - ssr_new <= 1e-12 * ssr
        C, tool, G, r, ssr = C_new, tool_new, G_new, r_new, ssr_new
        if done:
            break
    return r, taken


def armsig_fit(exe: str, d: Path) -> tuple[float, float]:
    """CPU of armsig's fit (frames + refine) in a cold identify, and its RMS residual per
    coordinate (cm) from the refine stage's χ² and stated σ."""
    for f in (d / "stages").glob("*.arrow"):
        f.unlink()
    out = subprocess.run([exe, "identify", str(d), "--no-report", "--json", *ARMSIG_FIT],
                         capture_output=True, text=True)  # fmt: skip
    if out.returncode not in (0, 4):
        raise RuntimeError(f"identify {d}: {out.stderr.strip()}")
    stages = json.loads(out.stdout)["stages"]
    cpu = sum(r["cpu_seconds"] for r in stages if r["name"] in ("frames", "refine"))
    import pyarrow.ipc as ipc

    meta = ipc.open_file(d / "stages" / "refine.arrow").schema.metadata
    s = json.loads(meta[b"armsig.refine"])
    sigma = float(pl.read_ipc(d / "stages" / "positions.arrow")["sigma_cm"].median())
    return cpu, sigma * float(np.sqrt(s["chi2"] / (s["dof"] + s["identifiability"]["rank"])))


#: A child that runs the same fit ``RUNS + 1`` times in one process (``identify`` with
#: ``force``) and prints each run's fit CPU: the first pays the imports its stages make on
#: first use (``scipy.linalg`` for the identifiability analysis), the rest do not, as the
#: floor, which runs in this warm process, does not.
_WARM = """
import json, sys
from pipeline.identify import identify
ov = json.loads(sys.argv[3])
cpu = []
for _ in range(int(sys.argv[2]) + 1):
    runs = identify(sys.argv[1], force=True, overrides=ov, report=False).runs
    cpu.append(sum(r.cpu_seconds for r in runs if r.name in ("frames", "refine")))
print(json.dumps(cpu))
"""


def armsig_fit_warm(d: Path) -> float:
    """Median CPU of armsig's fit in a process that has already run it once."""
    from pipeline.cli.options import stage_params

    overrides = json.dumps(stage_params(list(ARMSIG_FIT[1::2])))  # the cold command's
    out = subprocess.run([sys.executable, "-c", _WARM, str(d), str(RUNS), overrides],
                         capture_output=True, text=True, check=True)  # fmt: skip
    return statistics.median(json.loads(out.stdout)[1:])


def measure(exe: str, d: Path, label: str, robot: str) -> None:
    chain = get_robot(robot).design_chain()
    floor, ours = [], []
    for _ in range(RUNS):
        cpu, rms = armsig_fit(exe, d)  # writes the stage tables the floor reads
        ours.append(cpu)
        q_deg, xyz, rows = read_pose_set(d)
        q = joints_to_internal(q_deg, chain.prismatic)
        with threadpool_limits(1):
            c0 = time.process_time()
            r, its = floor_fit(chain, q, xyz, rows)
            floor.append(time.process_time() - c0)
    f, a = statistics.median(floor), statistics.median(ours)
    w = armsig_fit_warm(d)
    print(f"{label:36s} armsig fit {a:6.3f} s  floor {f:6.3f} s ({its} iterations)  "
          f"fit / floor {a / f:5.2f} (goal <= 2)  rms {rms:.5f} / "
          f"{np.sqrt(np.mean(r**2)):.5f} cm")  # fmt: skip
    print(f"{'':36s} armsig fit in a warm process {w:6.3f} s  fit / floor {w / f:5.2f}")


def main() -> None:
    exe = str(Path(sys.executable).parent / "pipeline")
    print(f"the fit against a dense numpy Gauss-Newton floor (issue 45), median of {RUNS}")
    with tempfile.TemporaryDirectory() as tmp:
        for n in (1000, 10_000):
            d = Path(tmp) / f"ur10_{n}"
            cmd = [exe, "simulate", str(d), "--robot", str(UR10), "--sensor", "tracker",
                   "--poses", str(n), "--no-sweeps"]  # fmt: skip
            subprocess.run(cmd, check=True, capture_output=True)
            measure(exe, d, f"UR10 simulated, {n:,} poses", str(UR10))
        r = real_ur10_c(exe, Path(tmp))
        if isinstance(r, str):
            print(f"{'UR10 real, Series C':36s} skipped: {r}")
        else:
            measure(exe, r, "UR10 real, Series C (2,773 poses)", str(UR10))


if __name__ == "__main__":
    main()
