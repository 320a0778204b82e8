"""What ``pipeline simulate`` can set (:class:`SimulationOptions`, boundary units), the checks
it makes before simulating anything, and the options as ``rig-truth.json`` records them."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from pipeline.errors import ArmsigError
from pipeline.rig import tracker
from pipeline.rig.true_robot import ErrorSigmas
from pipeline.robots import get_robot

FAULTS = ("bias", "dropouts", "outliers")
SENSORS = ("sonic", "tracker", "camera")
#: Camera set-ups (:mod:`pipeline.rig.camera`).
SETUPS = ("eye-to-hand", "eye-in-hand")
#: ``lab``: temperature linear in height, one slow drift (uniform 70 °F when noiseless);
#: ``drifting``: a speed of sound exactly linear in height drifting with periods of 8-45
#: min (:func:`pipeline.rig.atmosphere.drifting_linear_air`), noiseless or not.
AIRS = ("lab", "drifting")


@dataclass(frozen=True)
class SimulationOptions:
    """Everything ``pipeline simulate`` can set (boundary units)."""

    robot: str = "puma560"
    seed: int = 1
    sigmas: ErrorSigmas = field(default_factory=ErrorSigmas)
    noise_factor: float = 1.0
    points: int = 100  # N_i (Section 6.4)
    repeats: int = 10  # N_avg (Section 6.4)
    faults: tuple[str, ...] = ()
    wac_error_cm: float = 0.0  # W_AC calibration error (Section 7.3)
    noiseless: bool = False
    max_sweep_deg: float = 300.0  # cap of every revolute sweep (B-3 experiments)
    resettle_counts: int = 0  # held joints re-settle by ±1..K counts between sweeps
    sensor: str = "sonic"  # or "tracker" (pipeline.rig.tracker)
    targets: int = 1  # tracker: reflectors per sweep (a nest), ids T1..TK
    nest_on_axis: int = 0  # tracker: joint whose sweep's last reflector is on its axis
    check: int = 0  # tracker: validation configurations (sweep "check")
    poses: int = 0  # tracker: random whole-arm configurations identified (sweep "poses")
    sweeps: bool = True  # joint sweeps and the tool measurement (False: a pose set only)
    plan_file: str = ""  # tracker or camera: a pose plan (pipeline plan) recorded as the pose set
    six_d: bool = False  # tracker: the pose set's tool target also measures its orientation
    air: str = "lab"  # or "drifting" (AIRS)
    log_jitter_s: float = 0.0  # each measurement logged U(0, this) s after it was measured
    compliance_mm: float = 0.0  # the true joints deflect under gravity (RMS flange move, mm)
    harmonic_deg: float = 0.0  # the true joints' first-harmonic angle errors (RMS, deg)
    payloads_kg: tuple[float, ...] = ()  # payloads on the flange, cycled over the pose set
    backlash_mm: float = 0.0  # the true joints' backlash under gravity (RMS flange move, mm)
    robot_id: str = ""  # the arm's own id (serial), recorded in /robot/description ("": none)
    # camera (issue 39, pipeline.rig.camera): the set-up, the target file ("" the default
    # ChArUco board), the image size and nominal focal length (px), the true lens's
    # distortion (k1, k2, p1, p2, k3) and the pixel noise σ (px per coordinate)
    setup: str = "eye-to-hand"
    target_file: str = ""
    resolution_px: tuple[int, int] = (1280, 960)
    focal_px: float = 1000.0
    distortion: tuple[float, float, float, float, float] = (-0.12, 0.05, 5e-4, -3e-4, 0.0)
    pixel_noise_px: float = 0.2
    # rendered images (issue 40, ``--images``): the detections come from images of the
    # target drawn through the true lens (pipeline.rig.camera_render), blurred by a Gaussian
    # of σ ``blur_px``, dimmed towards the corners by ``vignette`` and with grey-level noise
    # of σ ``grey_noise`` (of 255); ``--noiseless``: none of the three
    images: bool = False
    blur_px: float = 0.5
    grey_noise: float = 2.0
    vignette: float = 0.3


def check_options(opts: SimulationOptions) -> None:
    bad = [f for f in opts.faults if f not in FAULTS]
    if bad:
        raise ArmsigError(
            f"unknown fault {bad[0]!r}", expected=", ".join(FAULTS), fix="--faults bias,dropouts"
        )
    numbers = {
        **{f"sigmas.{k}": v for k, v in asdict(opts.sigmas).items()},
        "noise_factor": opts.noise_factor,
        "max_sweep_deg": opts.max_sweep_deg,
    }
    for name, value in numbers.items():
        if not (np.isfinite(value) and value >= 0.0):
            raise ArmsigError(
                f"simulation option {name} must be a finite number >= 0", got=repr(value)
            )
    if not (0.0 < opts.max_sweep_deg <= 720.0 and np.isfinite(opts.wac_error_cm)):
        raise ArmsigError(
            "simulation options out of range",
            expected="0 < max_sweep_deg <= 720 and a finite wac_error_cm",
            got=f"max_sweep_deg={opts.max_sweep_deg}, wac_error_cm={opts.wac_error_cm}",
        )
    _check_tracker(opts)
    _check_camera(opts)
    if opts.air not in AIRS:
        raise ArmsigError(
            f"unknown air {opts.air!r}", expected=" or ".join(AIRS), fix="--air drifting"
        )
    if not all(np.isfinite(m) and 0.0 <= m <= 1000.0 for m in opts.payloads_kg):
        raise ArmsigError(
            "simulation option payloads_kg out of range",
            expected="masses from 0 to 1000 kg",
            got=repr(list(opts.payloads_kg)),
            fix="--payloads 0,10",
        )
    for name, top in (("compliance_mm", 10.0), ("harmonic_deg", 1.0), ("backlash_mm", 10.0)):
        value = getattr(opts, name)
        if not (np.isfinite(value) and 0.0 <= value <= top):
            raise ArmsigError(
                f"simulation option {name} out of range", expected=f"0 to {top}", got=repr(value)
            )
    if not (np.isfinite(opts.log_jitter_s) and 0.0 <= opts.log_jitter_s <= 60.0):
        raise ArmsigError(
            "simulation option log_jitter_s out of range",
            expected="0 to 60 s",
            got=repr(opts.log_jitter_s),
            fix="--log-jitter-s 1",
        )
    if opts.robot_id:
        from pipeline.contract.channels import check_robot_id

        check_robot_id(opts.robot_id)
    if opts.points < 3 or opts.repeats < 1:
        raise ArmsigError(
            "too few measurements",
            expected="--points >= 3 and --repeats >= 1",
            got=f"points={opts.points}, repeats={opts.repeats}",
        )
    if opts.resettle_counts < 0:
        raise ArmsigError(
            "simulation option resettle_counts must be >= 0",
            got=str(opts.resettle_counts),
            fix="--resettle-counts 2 (or 0: held joints never move)",
        )


def options_for_truth(opts: SimulationOptions) -> dict[str, object]:
    """The options as rig-truth.json records them; ``resettle_counts``, ``air`` and
    ``log_jitter_s`` only when set, so that sessions simulated without them keep their
    bytes."""
    out = {**asdict(opts), "faults": list(opts.faults), "payloads_kg": list(opts.payloads_kg)}
    camera = ("setup", "target_file", "resolution_px", "focal_px", "distortion", "pixel_noise_px")
    for name in camera:  # a camera session's own; the others keep their bytes
        if opts.sensor != "camera":
            del out[name]
        elif isinstance(out[name], tuple):
            out[name] = list(out[name])
    for name, default in (
        ("resettle_counts", 0), ("air", "lab"), ("log_jitter_s", 0.0),
        ("poses", 0), ("sweeps", True), ("plan_file", ""), ("six_d", False),
        ("compliance_mm", 0.0), ("harmonic_deg", 0.0), ("payloads_kg", []),
        ("backlash_mm", 0.0), ("robot_id", ""),
    ):  # fmt: skip
        if out[name] == default:
            del out[name]
    for name in ("images", "blur_px", "grey_noise", "vignette"):  # rendered images only
        if not opts.images:
            del out[name]
    return out


def _check_tracker(opts: SimulationOptions) -> None:
    if opts.sensor not in SENSORS:
        raise ArmsigError(
            f"unknown sensor {opts.sensor!r}", expected=", ".join(SENSORS), fix="--sensor tracker"
        )
    point_only = (
        opts.targets != 1 or opts.nest_on_axis or opts.check or opts.poses or opts.plan_file
    )
    if opts.six_d and not (opts.poses or opts.plan_file):
        raise ArmsigError(
            "--six-d measures the pose set's tool orientation: there is no pose set",
            expected="--poses N or --plan FILE with --sensor tracker",
            fix="--poses 30 --six-d",
        )
    if opts.plan_file and opts.poses:
        raise ArmsigError(
            "--plan and --poses both give the pose set",
            expected="one of them: the poses of a plan file, or N random poses",
            fix="drop --poses (the plan file says how many)",
        )
    if opts.sensor == "camera":
        return
    if opts.sensor == "sonic" and (point_only or not opts.sweeps):
        raise ArmsigError(
            "--targets, --nest-on-axis, --check, --poses and --no-sweeps need a point sensor",
            expected="--sensor tracker",
            got=f"--sensor {opts.sensor}",
        )
    in_range = 0 <= opts.check <= 10_000 and 0 <= opts.poses <= 100_000
    if not 1 <= opts.targets <= tracker.MAX_TARGETS or not in_range:
        raise ArmsigError(
            "tracker options out of range",
            expected=f"--targets 1 to {tracker.MAX_TARGETS}, --check 0 to 10000, "
            "--poses 0 to 100000",
            got=f"--targets {opts.targets}, --check {opts.check}, --poses {opts.poses}",
        )
    if not opts.sweeps and opts.poses == 0 and not opts.plan_file:
        raise ArmsigError(
            "--no-sweeps leaves nothing to identify",
            expected="joint sweeps, or a pose set (--poses N)",
            fix="--poses 50 --no-sweeps",
        )
    robot = get_robot(opts.robot)
    j = opts.nest_on_axis
    if j and not (1 <= j <= robot.n_joints and not robot.prismatic[j - 1] and opts.targets > 1):
        raise ArmsigError(
            f"--nest-on-axis {j}: no revolute joint {j} with a nest of several targets",
            expected=f"a revolute joint of {robot.name} (1 to {robot.n_joints}) and --targets >= 2",
            fix="--targets 3 --nest-on-axis 6",
        )


def _check_camera(opts: SimulationOptions) -> None:
    if opts.sensor != "camera":
        if opts.images:
            raise ArmsigError("--images applies to --sensor camera", got=f"--sensor {opts.sensor}",
                              fix="--sensor camera, or drop --images")  # fmt: skip
        return
    if opts.setup not in SETUPS:
        raise ArmsigError(
            f"unknown camera set-up {opts.setup!r}", expected=" or ".join(SETUPS),
            fix="--setup eye-in-hand",
        )  # fmt: skip
    if not (4 <= opts.poses <= 100_000 or (opts.plan_file and opts.poses == 0)):
        raise ArmsigError(
            "a camera session is a set of images at random poses",
            expected="--poses from 4 to 100000 (one image per pose), or --plan FILE",
            got=f"--poses {opts.poses}",
            fix="--poses 40",
        )
    others = {
        "--targets": opts.targets != 1, "--nest-on-axis": opts.nest_on_axis != 0,
        "--check": opts.check != 0, "--six-d": opts.six_d,
        "--compliance-mm": opts.compliance_mm != 0, "--harmonic-deg": opts.harmonic_deg != 0,
        "--payloads": bool(opts.payloads_kg), "--backlash-mm": opts.backlash_mm != 0,
    }  # fmt: skip
    given = [k for k, v in others.items() if v]
    if given:
        raise ArmsigError(
            f"{given[0]} does not apply to --sensor camera",
            expected="--setup, --target, --resolution, --focal-px, --distortion, "
            "--pixel-noise and --poses (or --plan)",
            fix=f"drop {given[0]}",
        )
    if not opts.images and (opts.blur_px, opts.grey_noise, opts.vignette) != (0.5, 2.0, 0.3):
        raise ArmsigError("--blur-px, --grey-noise and --vignette apply to rendered images",
                          fix="add --images, or drop them")  # fmt: skip
    if not (0 <= opts.blur_px <= 20 and 0 <= opts.grey_noise <= 100 and 0 <= opts.vignette < 1):
        raise ArmsigError("rendered image options out of range",
                          expected="--blur-px 0 to 20, --grey-noise 0 to 100, --vignette 0 to <1",
                          got=f"{opts.blur_px}, {opts.grey_noise}, {opts.vignette}")  # fmt: skip
    w, h = opts.resolution_px
    numbers = (opts.focal_px, opts.pixel_noise_px, *opts.distortion)
    if not (64 <= w <= 20_000 and 64 <= h <= 20_000 and np.isfinite(numbers).all()
            and 10.0 <= opts.focal_px <= 100_000 and 0.0 <= opts.pixel_noise_px <= 100.0
            and np.abs(opts.distortion).max() <= 10.0):  # fmt: skip
        raise ArmsigError(
            "camera options out of range",
            expected="a resolution of 64 to 20000 px a side, --focal-px 10 to 100000, "
            "--pixel-noise 0 to 100 px, distortion coefficients within ±10",
            got=f"{w}x{h} px, focal {opts.focal_px} px, noise {opts.pixel_noise_px} px, "
            f"distortion {list(opts.distortion)}",
        )
