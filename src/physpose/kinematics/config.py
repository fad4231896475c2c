"""Settings of the kinematic fit, and the named variants of the paper's Table 1 (S ... SO+GT).

Every loss term has a weight under the same name in `PoseWeights`, so a stage's objective is
`sum(w[name] * term[name])` and each term is logged by name (`KinematicFit.losses`).
Lengths are metres, angles radians unless a name says otherwise.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from physpose.errors import PhysposeError, check_field, expect_type
from physpose.pinhole import DEFAULT_DIAGONAL_FOV_DEG

DEPTH_SCALE_RANGE = (0.3, 2.0)  # the fit's bounds on the factor on MediaPipe's depth

VARIANT_NAMES: tuple[str, ...] = ("S", "SO", "SO+G", "SO+T", "SO+GT")


@dataclass(frozen=True)
class CameraConfig:
    """Intrinsics when the observations carry none: square pixels, principal point at the
    image centre, focal length from a diagonal field of view, optionally refined (+O)."""

    diagonal_fov_deg: float = DEFAULT_DIAGONAL_FOV_DEG  # prior field of view, image diagonal
    refine_focal: bool = False       # optimise the focal length with the poses (weakly observable)
    focal_log_sigma: float = 0.25    # prior sigma of log(focal) when refined

    def __post_init__(self) -> None:
        if not 1.0 <= self.diagonal_fov_deg <= 170.0:
            raise PhysposeError(f"diagonal field of view {self.diagonal_fov_deg} degrees is "
                                "outside 1-170", remedy="use e.g. 55 (a phone's main camera), "
                                "or give the camera's intrinsics with --camera")


@dataclass(frozen=True)
class ShapeConfig:
    """The time-consistent shape (+S), fitted jointly with the poses of a few seed frames."""

    seed_frames: int = 5             # n in the paper: frames with the highest mean confidence
    seed_spacing_s: float = 0.2      # s, seed frames at least this far apart (when possible)
    bone_log_sigma: float = 0.12     # prior sigma of log(bone / proportional bone)
    iterations: int = 150            # L-BFGS iterations of each of the two shape steps


@dataclass(frozen=True)
class PoseWeights:
    """Weights of the pose objective's terms (keyed like the `_cost_<name>` terms).

    reprojection: confidence-weighted robust 2d error, pixels converted to metres at the
        person's depth and divided by sigma_2d. world_landmarks: MediaPipe's root-relative
        metric landmarks (camera axes), divided by sigma_3d (depth by depth_sigma_ratio x).
    pose_prior: Gaussian prior on the hinge angles (per-axis sigmas in losses.PRIOR_SIGMA).
    joint_limits: quadratic penalty outside skeleton.DOF_LIMITS (hard bounds also apply).
    temporal_*: +T smoothness: landmark velocities (the paper's first differences; off by
        default, they damp real motion, most of all in depth) and accelerations (m/s, m/s^2),
        hinge and root accelerations (rad/s^2), each divided by its sigma.
    ground: +G contact term (the paper's L_gp with the plane fixed). ground_skate: +GT, soles
        near the ground do not slide (not in the paper; it keeps the contacts +G makes still).
    """

    reprojection: float = 1.0
    world_landmarks: float = 1.0
    pose_prior: float = 1.0
    joint_limits: float = 100.0
    temporal_velocity: float = 0.0
    temporal_acceleration: float = 1.0
    temporal_angles: float = 1.0
    ground: float = 1.0
    ground_skate: float = 1.0
    depth_scale_prior: float = 1.0

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            check_field(self, f.name, math.isfinite(value) and value >= 0,
                        "finite and >= 0 (0 switches the term off)")


@dataclass(frozen=True)
class PoseConfig:
    """Per-frame pose optimisation (+O) and the robust residual scales."""

    weights: PoseWeights = PoseWeights()
    sigma_2d: float = 0.025            # m at the person's depth (~5 px at 1080p, 5 m)
    sigma_3d: float = 0.06             # m, MediaPipe world landmarks, lateral axes
    depth_sigma_ratio: float = 3.0     # MediaPipe's depth is far worse than its lateral axes
    robust_c: float = 5.0              # Geman-McClure: residuals beyond ~c sigma saturate
    min_confidence: float = 0.1        # landmarks below this confidence are ignored
    ray_aligned_world: bool = True     # MediaPipe's world landmarks face the ray to the hips
    # MediaPipe's depth x a per-clip factor = the body's; the factor's log-normal prior has
    # this median and this sigma of its log. Real MediaPipe's depth is flatter than the body's
    # but predicts it best unscaled (docs/mediapipe_error.md); a centre at 1 / 0.61 did not
    # help on real views (docs/dynamics_history.md, stop 66).
    depth_scale_prior_centre: float = 1.0
    depth_scale_log_sigma: float = 0.3
    sigma_velocity: float = 2.0        # m/s, +T landmark velocity scale
    sigma_acceleration: float = 60.0   # m/s^2, +T landmark acceleration scale
    sigma_angle_acceleration: float = 100.0  # rad/s^2, +T hinge acceleration scale
    iterations: int = 200              # L-BFGS iterations per pose stage
    init_iterations: int = 100         # ... of the 3d-only inverse kinematics (variant S)
    hard_limits: bool = True           # joint limits as L-BFGS-B bounds

    def __post_init__(self) -> None:
        expect_type(self.weights, PoseWeights, "PoseConfig.weights", "pass PoseWeights(...)")
        for name in ("sigma_2d", "sigma_3d", "depth_sigma_ratio", "robust_c", "sigma_velocity",
                     "sigma_acceleration", "sigma_angle_acceleration"):
            value = getattr(self, name)
            check_field(self, name, math.isfinite(value) and value > 0, "finite and > 0")
        low, high = DEPTH_SCALE_RANGE
        if not low <= self.depth_scale_prior_centre <= high:
            raise PhysposeError(
                f"depth_scale_prior_centre={self.depth_scale_prior_centre} is outside "
                f"{low}-{high}", remedy=f"centre MediaPipe's depth factor between {low} and "
                f"{high} (default 1)")
        if not self.depth_scale_log_sigma > 0:
            raise PhysposeError(f"depth_scale_log_sigma={self.depth_scale_log_sigma} must be > 0",
                                remedy="pass a positive sigma (default 0.3)")


@dataclass(frozen=True)
class GroundConfig:
    """The ground plane (+G): the paper's L_gp, k smallest signed distances clipped at delta.

    The paper's k = 20 counts vertices of GHUM's ~10^4-vertex mesh, about an eighth of a sole;
    our sole has surface.SOLE_GRID = 50 samples, so the same patch is k = 6.
    """

    k: int = 6                        # smallest signed distances per frame and point set
    k_pose: int = 20                  # the same when re-fitting poses: feet land flat
    delta: float = 0.2                # m, clip: frames in the air do not pull the plane
    body_weight: float = 2.0          # the whole-body term's weight against each foot's
    foot_delta_pose: float = 0.02     # m, clip of the foot terms when re-fitting poses
    pose_scale: float = 0.01          # m, L_gp divided by this when re-fitting poses
    contact_height: float = 0.01      # m, +GT: soles this high weigh 1/e in the skate term
    sigma_skate: float = 0.1          # m/s, +GT: sole sliding speed scale
    roll_sigma_deg: float = 30.0      # prior: the camera's roll about its optical axis
    balance_sigma_deg: float = 3.0    # prior: the mean support -> centre of mass direction
    depth_gain_sigma: float = 0.4     # plane fit: prior of g, depth errors = g x relative depth
    rounds: int = 1                   # (estimate T_g, re-fit poses) rounds
    level_percentile: float = 10.0    # no +G: % of frames whose lowest sole point is below z=0
    raised_supports: bool = True      # feet that stay raised (a box, a step) stand on its top

    def __post_init__(self) -> None:
        check_field(self, "rounds", self.rounds >= 1, "at least 1")


@dataclass(frozen=True)
class KinematicConfig:
    """The whole kinematic stage. `optimize_pose` (+O), `ground` (+G), `temporal` (+T)."""

    optimize_pose: bool = True
    ground: bool = True
    temporal: bool = True
    camera: CameraConfig = CameraConfig()
    shape: ShapeConfig = ShapeConfig()
    pose: PoseConfig = PoseConfig()
    ground_plane: GroundConfig = GroundConfig()
    fix_swaps: bool = True            # undo left/right limb swaps by temporal continuity
    use_cache: bool = True            # cache results (physpose.cache) by input and config
    compile_cache: bool = True        # keep JAX's compiled objectives on disk (cache_dir/jax)

    def __post_init__(self) -> None:
        if (self.ground or self.temporal) and not self.optimize_pose:
            raise PhysposeError("+G and +T need the pose optimisation (+O)",
                                remedy=f"use one of the variants {VARIANT_NAMES}")

    @property
    def variant(self) -> str:
        """The variant name of these flags ("S", "SO", "SO+G", "SO+T", "SO+GT")."""
        if not self.optimize_pose:
            return "S"
        extra = ("G" if self.ground else "") + ("T" if self.temporal else "")
        return "SO" + (f"+{extra}" if extra else "")

    @classmethod
    def preset(cls, variant: str = "SO+GT", **changes) -> KinematicConfig:
        """The configuration of a named variant (VARIANT_NAMES), with field overrides."""
        flags = {"S": (False, False, False), "SO": (True, False, False),
                 "SO+G": (True, True, False), "SO+T": (True, False, True),
                 "SO+GT": (True, True, True)}
        if variant not in flags:
            raise PhysposeError(f"unknown kinematic variant {variant!r}",
                                remedy=f"choose one of {', '.join(VARIANT_NAMES)}")
        o, g, t = flags[variant]
        return dataclasses.replace(cls(optimize_pose=o, ground=g, temporal=t), **changes)
