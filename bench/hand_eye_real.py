"""industrial_calibration's real image sets (issue 40): armsig's camera fit of a session of
flange poses beside an independent reference and OpenCV's closed forms.

Per set (``../shared/realdata/industrial_calibration``: the ChArUco set, eye-to-hand, and
the modified circle grid, eye-in-hand), on armsig's own detections:

- armsig (:func:`pipeline.refine.hand_eye.fit_hand_eye`): the given intrinsics held, no
  distortion (the default robust loss, and plain least squares), and the intrinsics and
  distortion fitted in the same fit;
- the reference (:func:`reference_fit`): plain ``scipy.optimize.least_squares`` over the
  two hand-eye transforms (12 numbers) with ``cv2.projectPoints`` and the given lens,
  started from OpenCV's ``calibrateRobotWorldHandEye`` (Shah); and the same after
  ``cv2.calibrateCamera`` (the lens and distortion first, then the hand-eye);
- OpenCV's closed forms: ``calibrateHandEye`` (Tsai, Park, Horaud, Andreff, Daniilidis;
  the fixed body then the mean of its per-view poses) and ``calibrateRobotWorldHandEye``
  (Shah, Li), each with ``method=`` by keyword (opencv #27625).

Each row: the RMS reprojection per corner with the given lens (px; "fitted" rows with
their own lens), and how far both hand-eye transforms are from the reference's optimum
(mm, degrees, the worse of the two). Then the held-out images (:func:`held_out`, the
``hand_eye_holdout`` stage's folds) with the lens given and fitted: the in-sample RMS,
the held-out one, its prediction, the closed-form start's and the worst image's.
``python -m bench.hand_eye_real``.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

ROOT = Path(__file__).resolve().parent.parent
REALDATA = Path(os.environ.get("ARMSIG_REALDATA", ROOT.parent / "shared" / "realdata"))
SETS = (
    ("test_set_charuco", "ChArUco, eye-to-hand"),
    ("test_set_10x10", "circle grid, eye-in-hand"),
)
HAND_EYE = ("TSAI", "PARK", "HORAUD", "ANDREFF", "DANIILIDIS")
ROBOT_WORLD = ("SHAH", "LI")


@dataclass(frozen=True)
class RealSet:
    """A set's detections (armsig's), flange poses (m, 4, 4, cm), given lens, set-up."""

    image: np.ndarray
    local: np.ndarray
    uv: np.ndarray
    flange: np.ndarray
    lens: Any
    setup: str


def load(folder: str) -> RealSet:
    """Read and detect a set as ``pipeline import --format images`` does."""
    from pipeline.importers.images import read_image_set

    s = read_image_set(REALDATA / "industrial_calibration" / folder / "cal_data.yaml")
    kept = [e for e in s.images if e.found.kept]
    ids, local = s.target.points()
    at = [np.searchsorted(ids, e.found.point_ids) for e in kept]
    image = np.concatenate([np.full(len(a), i) for i, a in enumerate(at)])
    return RealSet(image, np.concatenate([local[a] for a in at]),
                   np.concatenate([e.found.uv_px for e in kept]),
                   np.array([e.flange_in_base for e in kept]), s.lens, s.setup)  # fmt: skip


def _pose(x: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = Rotation.from_rotvec(x[:3]).as_matrix(), x[3:]
    return T


def _vec(T: np.ndarray) -> np.ndarray:
    return np.concatenate([Rotation.from_matrix(T[:3, :3]).as_rotvec(), T[:3, 3]])


def camera_from_target(s: RealSet, fixed: np.ndarray, tool: np.ndarray) -> np.ndarray:
    """The target in the camera (m, 4, 4) at every flange pose: ``fixed`` the fixed body
    in the base, ``tool`` the flange's body in the flange."""
    inv = np.linalg.inv
    if s.setup == "eye-to-hand":
        return inv(fixed) @ s.flange @ tool
    return inv(s.flange @ tool) @ fixed


def residuals(s: RealSet, fixed: np.ndarray, tool: np.ndarray, K: Any, dist: Any) -> np.ndarray:
    """Projected minus detected pixels (D, 2) through ``cv2.projectPoints``."""
    import cv2

    T = camera_from_target(s, fixed, tool)
    out = np.zeros_like(s.uv)
    for i in range(len(T)):
        at = s.image == i
        rvec = cv2.Rodrigues(T[i, :3, :3])[0]
        out[at] = cv2.projectPoints(s.local[at], rvec, T[i, :3, 3], K, dist)[0][:, 0] - s.uv[at]
    return out


def rms(r: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(r**2, axis=1))))


def views(s: RealSet, K: Any, dist: Any) -> np.ndarray:
    """Every view's target pose in the camera (m, 4, 4): ``cv2.solvePnP``."""
    import cv2

    T = np.tile(np.eye(4), (len(s.flange), 1, 1))
    for i in range(len(T)):
        at = s.image == i
        _, rvec, tvec = cv2.solvePnP(s.local[at], s.uv[at], K, dist)
        T[i, :3, :3], T[i, :3, 3] = cv2.Rodrigues(rvec)[0], tvec.ravel()
    return T


def robot_world(s: RealSet, method: str, K: Any, dist: Any) -> tuple[np.ndarray, np.ndarray]:
    """(fixed in base, flange's body in flange) of ``cv2.calibrateRobotWorldHandEye``."""
    import cv2

    T = views(s, K, dist)
    moving = T if s.setup == "eye-in-hand" else np.linalg.inv(T)  # c: moves with the flange
    g = np.linalg.inv(s.flange)
    Rw, tw, Rc, tc = cv2.calibrateRobotWorldHandEye(
        list(moving[:, :3, :3]), list(moving[:, :3, 3]), list(g[:, :3, :3]), list(g[:, :3, 3]),
        method=getattr(cv2, f"CALIB_ROBOT_WORLD_HAND_EYE_{method}"),
    )  # fmt: skip
    wTb, cTg = np.eye(4), np.eye(4)
    wTb[:3, :3], wTb[:3, 3], cTg[:3, :3], cTg[:3, 3] = Rw, np.ravel(tw), Rc, np.ravel(tc)
    return np.linalg.inv(wTb), np.linalg.inv(cTg)


def hand_eye(s: RealSet, method: str, K: Any, dist: Any) -> tuple[np.ndarray, np.ndarray]:
    """(fixed in base, flange's body in flange) of ``cv2.calibrateHandEye``; the other
    transform the mean of its per-view values (translation mean, rotation chordal mean)."""
    import cv2

    T = views(s, K, dist)
    g = s.flange if s.setup == "eye-in-hand" else np.linalg.inv(s.flange)  # eye-to-hand:
    R, t = cv2.calibrateHandEye(  # base2gripper in place of gripper2base gives cam2base
        list(g[:, :3, :3]), list(g[:, :3, 3]), list(T[:, :3, :3]), list(T[:, :3, 3]),
        method=getattr(cv2, f"CALIB_HAND_EYE_{method}"),
    )  # fmt: skip
    X = np.eye(4)
    X[:3, :3], X[:3, 3] = R, np.ravel(t)
    if s.setup == "eye-in-hand":  # X: camera in flange; the target in base per view
        per_view = s.flange @ X @ T
    else:  # X: camera in base; the target in flange per view
        per_view = np.linalg.inv(s.flange) @ X @ T
    mean = np.eye(4)
    mean[:3, :3] = Rotation.from_matrix(per_view[:, :3, :3]).mean().as_matrix()
    mean[:3, 3] = per_view[:, :3, 3].mean(axis=0)
    return (mean, X) if s.setup == "eye-in-hand" else (X, mean)


def reference_fit(
    s: RealSet, K: Any, dist: Any, start: tuple[np.ndarray, np.ndarray] | None = None
) -> tuple[np.ndarray, np.ndarray, float]:
    """Plain least squares over both hand-eye transforms with the lens ``K``, ``dist``
    held (``scipy.optimize.least_squares``, ``cv2.projectPoints``): (fixed in base,
    flange's body in flange, rms px); started at :func:`robot_world` (Shah)."""
    from scipy.optimize import least_squares

    fixed, tool = start or robot_world(s, "SHAH", K, dist)

    def f(x: np.ndarray) -> np.ndarray:
        return residuals(s, _pose(x[:6]), _pose(x[6:]), K, dist).ravel()

    tol = 1e-15  # to the optimum's rounding: the comparison is at 1e-3 mm
    sol = least_squares(f, np.concatenate([_vec(fixed), _vec(tool)]), method="lm", xtol=tol,
                        ftol=tol, gtol=tol, max_nfev=20000)  # fmt: skip
    return _pose(sol.x[:6]), _pose(sol.x[6:]), rms(sol.fun.reshape(-1, 2))


def difference(
    a: tuple[np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray]
) -> tuple[float, float]:
    """The worse of the two transforms' distances: translation (mm), rotation (deg)."""
    mm = max(10 * float(np.linalg.norm(x[:3, 3] - y[:3, 3])) for x, y in zip(a, b, strict=True))
    deg = max(float(np.degrees(Rotation.from_matrix(x[:3, :3].T @ y[:3, :3]).magnitude()))
              for x, y in zip(a, b, strict=True))  # fmt: skip
    return mm, deg


def detections(s: RealSet) -> Any:
    """The set's :class:`~pipeline.refine.camera_fit.Detections` (σ 0.2 px, the default)."""
    from pipeline.refine.hand_eye import flange_detections

    return flange_detections(s.image, s.local, s.uv, np.full(len(s.uv), 0.2), len(s.flange))


def armsig_fit(s: RealSet, intrinsics: str, loss: str = "soft_l1") -> Any:
    from pipeline.refine.hand_eye import fit_hand_eye

    return fit_hand_eye(detections(s), s.flange, s.lens, s.setup, intrinsics, loss=loss)


def held_out(s: RealSet, intrinsics: str) -> tuple[float, Any]:
    """(The in-sample RMS, :class:`~pipeline.refine.hand_eye_holdout.HandEyeHeldOut`) of
    the ``hand_eye_holdout`` stage's default folds."""
    from pipeline.refine.hand_eye_holdout import hand_eye_folds, hand_eye_holdout

    fold = hand_eye_folds(len(s.flange))
    assert fold is not None  # both sets have more than MIN_IMAGES images
    h = hand_eye_holdout(detections(s), s.flange, s.lens, s.setup, fold, intrinsics=intrinsics)
    return armsig_fit(s, intrinsics).rms_px, h


def rows(s: RealSet) -> list[tuple[str, float, float, float]]:
    """(method, rms px, mm and degrees from the reference optimum) of every method."""
    import cv2

    from pipeline.refine.hand_eye import fixed_in_base, tool_in_flange

    K, dist = s.lens.opencv()
    ref = reference_fit(s, K, dist)
    out = [("reference: scipy least squares, given lens", ref[2], 0.0, 0.0)]
    for intrinsics, loss in (("fixed", "soft_l1"), ("fixed", "linear"), ("fitted", "soft_l1")):
        c0 = time.process_time()
        fit = armsig_fit(s, intrinsics, loss)
        cpu = time.process_time() - c0
        pair = (fixed_in_base(fit), tool_in_flange(fit))
        out.append((f"armsig, lens {intrinsics}, {loss} ({cpu:.2f} s CPU)", fit.rms_px,
                    *difference(pair, ref[:2])))  # fmt: skip
    obj = [s.local[s.image == i].astype(np.float32) for i in range(len(s.flange))]
    img = [s.uv[s.image == i].astype(np.float32) for i in range(len(s.flange))]
    size = (s.lens.width_px, s.lens.height_px)
    _, K1, d1, *_ = cv2.calibrateCamera(obj, img, size, K.copy(), dist.copy(),
                                        flags=cv2.CALIB_USE_INTRINSIC_GUESS)  # fmt: skip
    after = reference_fit(s, K1, d1)
    out.append(("cv2.calibrateCamera, then the reference hand-eye", after[2],
                 *difference(after[:2], ref[:2])))  # fmt: skip
    for m in HAND_EYE:
        pair = hand_eye(s, m, K, dist)
        out.append((f"cv2.calibrateHandEye {m}", rms(residuals(s, *pair, K, dist)),
                    *difference(pair, ref[:2])))  # fmt: skip
    for m in ROBOT_WORLD:
        pair = robot_world(s, m, K, dist)
        out.append((f"cv2.calibrateRobotWorldHandEye {m}", rms(residuals(s, *pair, K, dist)),
                    *difference(pair, ref[:2])))  # fmt: skip
    return out


def main() -> None:
    if not (REALDATA / "industrial_calibration").is_dir():
        print(f"hand-eye on real images: skipped, no {REALDATA / 'industrial_calibration'}")
        return
    for folder, what in SETS:
        s = load(folder)
        print(f"{folder} ({what}): {len(s.flange)} images, {len(s.uv)} points")
        print(f"  {'method':58s} {'rms px':>8s} {'mm':>8s} {'deg':>7s}")
        for name, px, mm, deg in rows(s):
            print(f"  {name:58s} {px:8.3f} {mm:8.3f} {deg:7.3f}")
        print(
            f"  held out (5 folds): {'lens':8s} {'in px':>7s} {'held px':>8s} "
            f"{'predicted':>9s} {'start px':>8s} {'worst image':>11s}"
        )
        for intrinsics in ("fixed", "fitted"):
            inside, h = held_out(s, intrinsics)
            print(
                f"  {'':20s}{intrinsics:8s} {inside:7.3f} {h.overall(h.rms_px):8.3f} "
                f"{h.overall(h.expected_px):9.3f} {h.overall(h.start_rms_px):8.3f} "
                f"{h.rms_px.max():11.3f}"
            )


if __name__ == "__main__":
    main()
