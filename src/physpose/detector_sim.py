"""Detector simulator: ground-truth motion -> `Observations` as the observe stage makes from video.

A static virtual pinhole camera looks at the subject's mean position; MediaPipe's 33 landmarks
are synthesised from the ground-truth skeleton (`synthesize_landmarks`), projected to pixels with
noise in proportion to the person's size in the image, given confidences that drop for far-side
and torso-occluded landmarks, and corrupted by occasional outliers and left/right swaps (legs,
arms or the whole body); hip-centred world landmarks, in the frame of the viewing ray through
the hips (as MediaPipe's are, to within what the multi-view reference shows), get noise that is
larger along that ray, shared down each limb and turning its bones rather than stretching them
(stop 76), and per clip a scale error, a depth compression and a lean towards or away from the
camera. The draws depend on the seed and the clip's name, so two clips of
the same length get their own noise (before stop 69 they shared one draw). Same config, seed
and clip -> bit-identical output.

The default noise figures are in the constant block below, calibrated against real MediaPipe
error measured on the multi-view reference (docs/mediapipe_error.md); each says where it comes
from. Masks are not simulated (`Observations.masks` is None).
"""

from __future__ import annotations

import itertools
import zlib
from dataclasses import dataclass

import numpy as np

from physpose.errors import PhysposeError
from physpose.joints import JOINT_INDEX, LANDMARK_INDEX, LANDMARK_NAMES, NUM_LANDMARKS
from physpose.metrics import project, transform_points
from physpose.mocap.common import MocapClip, body_height
from physpose.mocap.rotations import axis_rotation
from physpose.observations import Observations
from physpose.pinhole import ray_frame

# --- Default noise model -------------------------------------------------------------------
# Measured on real MediaPipe (docs/mediapipe_error.md: the pose2sim demo, 4 views x 50 frames,
# leave-one-out multi-view reference; "pooled" = all views, "good views" = cam01/03/04). Before
# that measurement the priors were: 2d sigma ~5 px at 1080p, 3d mean error 50-70 mm, depth sigma
# ~2x lateral. Re-run the measurement and update these when the reference improves.
#
# 2d, per coordinate, as a fraction of the person's size in the image (the long side of its 2d
# bounding box): MediaPipe works on a crop around the person, so its error scales with the
# person, not the frame. Measured: white 4.2 px and robust total 15.1 px for a 738 px tall
# person (0.57 %, 2.05 %); the in-sample median (13.6 px) implies ~1.6 %, and the leave-one-out
# figure is inflated by the three-view reference's own error, so the target total is 1.8 %.
# The base sigmas below are for unhidden landmarks; with the occlusion gain the simulator's
# robust total comes out at 1.75 % (measured as in docs/mediapipe_error.md). Stop 75 set the
# far-side gain to 0 (below) and raised both by x 1.18, which keeps that total (scratch
# simcmp75.py: 1.83 % on its own measure before and after).
SIGMA_2D_WHITE = 0.0047        # x person size, frame-to-frame part
SIGMA_2D_DRIFT = 0.0148        # x person size, slowly varying part
# 3d world landmarks (hip-centred). Measured in camera axes, good views (cam01/03/04): 33-landmark
# mean error 125-178 mm (median 90-157), MPJPE 102-130 mm / MPJPE-PA 68-84 mm on the 21 joints,
# RMS per axis ~42 / 52 / 161 mm (x / y / z), scale (RMS radius ratio) 0.93-0.96, depth scale
# 0.51-0.75 (pooled 0.61), depth bias -40..+112 mm (a forward/backward lean). Simulated with
# these defaults, without swaps, on the 15 shared clips at 4 azimuths: mean 135 mm, median 119,
# MPJPE 129, MPJPE-PA 93, RMS 37 / 54 / 141 mm, scale 0.95, depth scale 0.60 (before stop 75;
# its far-side gain of 0 took the mean to 120 mm, and both sigmas x 1.27 bring it back to 136
# on scratch simcmp75.py's measure, 136 before).
SIGMA_3D_WHITE = 0.014         # m per lateral axis (camera x, y)
SIGMA_3D_DRIFT = 0.0305        # m per lateral axis, correlated over DRIFT_TIME
DEPTH_NOISE_RATIO = 2.5        # depth (camera z) sigma / lateral sigma
SCALE_BIAS_MEAN = 1.0          # per-clip multiplicative scale (the depth compression below
SCALE_BIAS_SIGMA = 0.03        # already brings the RMS-radius ratio to the measured 0.95)
DEPTH_SCALE_MEAN = 0.62        # per-clip factor on hip-relative depth: monocular 3d flattens it
DEPTH_SCALE_SIGMA = 0.09
LEAN_BIAS_SIGMA_DEG = 8.0      # per-clip tilt towards/away from the camera about the hips
DRIFT_TIME = 0.5               # s, correlation time of the drifting parts (not measured)
# Structure of the 3d error (stop 76, scratch errcorr76.py / bones76.py; docs/mediapipe_error.md,
# Structure of the 3d error): MediaPipe places a limb as a whole. On the good views the errors
# of neighbours down a limb correlate by 0.4-0.9 per axis (knee-ankle about 0.7, ankle-toe 0.9,
# nose-ear 0.75), and its bones keep their length: the frame-to-frame sd of a bone's length
# over the truth's is 0.06-0.08 on the legs, 0.05-0.12 on the arms. Independent noise per
# landmark gave 0.2-0.6 (from the per-clip biases alone) and 0.11-0.32. The hips are the world
# landmarks' origin, and their error follows the knees' little (-0.3 to 0.1 on the left, 0.3-0.5
# on the right), so the chains start below them.
LIMB_PARENT = {f"{side}_{child}": f"{side}_{parent}" for side in ("left", "right")
               for child, parent in (("knee", "hip"), ("ankle", "knee"), ("heel", "ankle"),
                                     ("foot_index", "ankle"), ("elbow", "shoulder"),
                                     ("wrist", "elbow"), ("pinky", "wrist"), ("index", "wrist"),
                                     ("thumb", "wrist"))}
NOISE_CHAIN_CORRELATION = 0.6  # a landmark's noise vs its parent's (LIMB_PARENT below the hips;
                               # the face's points vs the nose): gives 0.7-0.8 with the per-clip
                               # biases
BONE_STRETCH_REMOVED = 0.8     # share of the noise along hip-knee, knee-ankle, shoulder-elbow
                               # and elbow-wrist removed (the landmarks below moved alike):
                               # bone-length sd 0.06-0.08 (legs), 0.08-0.16 (arms)
# Outliers and swaps. Measured: 8.2 % of landmark-frames off by > 5 % of the image height
# (13 % of the person's height) pooled, 2.8-6.5 % in the views without swaps; whole-body
# left/right swaps in 6.5 % of the frames pooled (all in one view, 26 %).
OUTLIER_RATE = 0.04            # per landmark-frame: a jump by OUTLIER_OFFSET, confident
OUTLIER_OFFSET = (0.13, 0.40)  # x person size, range of the jump
OUTLIER_CONFIDENCE = (0.5, 0.8)
SWAP_RATE = 0.02               # per frame: a swap of the legs, the arms or the whole body starts
SWAP_FRAMES = (2, 8)           # its length, frames (inclusive range): legs swapped ~6.5 % of frames
# Confidence ("visibility") model.
BASE_CONFIDENCE = {"face": 0.98, "trunk": 0.99, "limb": 0.95, "distal": 0.90, "extremity": 0.85}
CONFIDENCE_JITTER = 0.03       # sigma of per-frame confidence noise
# Far side, measured on real MediaPipe (stop 75, scratch farside75.py; pose2sim's 4 oblique
# views, one subject, against the four-view reference; +- a cluster bootstrap): a limb landmark
# (knee, ankle, heel, foot_index, elbow, wrist; 1122 pair-frames) d metres behind its twin is
# less confident by 0.06 +- 0.03 at d 0.03-0.10, 0.10 +- 0.03 at 0.10-0.35 and 0.13-0.15
# beyond: drop 0.12 +- 0.03 at 0.25 m. Views differ (at d >= 0.25 m cam03 0.33, the others
# 0.03-0.07; the uneven sides of stop 74 are cam03's). Hips, shoulders and the face stay at
# 0.9998-1.0000 (FAR_SIDE_GROUPS). The far landmark's 2d error over its twin's is 1.00 (log SE
# 0.10; leave-one-out reference) at d >= 0.25 m, its world landmarks' 0.91 (0.09): no noise
# gain (the reference's own error bounds it below ~0.3). Before: 0.35 on every twin and gain
# 1.0, neither measured.
FAR_SIDE_DEPTH = 0.25          # m, far-side weight = clip(depth behind the partner / this, 0, 1)
FAR_SIDE_DROP = 0.12           # confidence lost by a fully far-side landmark
FAR_SIDE_GROUPS = ("limb", "distal", "extremity")   # the landmarks that lose it
FAR_NOISE_GAIN = 0.0           # 2d/3d sigma x (1 + gain * far-side weight)
# Torso occlusion stays a prior: on pose2sim the rule below flags only 13 landmark-frames (cam03's
# right hand; 0.54 less confident, 2d error x 3.4), too few to calibrate (scratch occluded75.py).
OCCLUDED_DROP = 0.45           # confidence lost behind the torso
OCCLUDED_MARGIN = 0.05         # m, behind the torso plane by more than this counts as occluded
OCCLUDED_NOISE_GAIN = 1.5      # 2d/3d sigma x (1 + gain) when occluded
OUTSIDE_CONFIDENCE = 0.05      # landmarks outside the image
# --- Anthropometric offsets for landmarks the skeleton lacks (adult, stature 1.70 m) ----------
REFERENCE_STATURE = 1.70       # m; offsets below scale with the clip's body height
# Head frame (forward, left, up) from the point between the ears: head breadth ~15 cm, eye
# separation ~63 mm, ear canal to nose tip ~10 cm, eyes ~1.5 cm above and mouth ~6 cm below it.
FACE_OFFSETS = {
    "nose": (0.105, 0.0, -0.02),
    "left_eye_inner": (0.090, 0.016, 0.015), "left_eye": (0.085, 0.032, 0.015),
    "left_eye_outer": (0.075, 0.048, 0.015),
    "right_eye_inner": (0.090, -0.016, 0.015), "right_eye": (0.085, -0.032, 0.015),
    "right_eye_outer": (0.075, -0.048, 0.015),
    "left_ear": (0.0, 0.075, 0.0), "right_ear": (0.0, -0.075, 0.0),
    "mouth_left": (0.090, 0.025, -0.06), "mouth_right": (0.090, -0.025, -0.06),
}
# Hand frame (wrist->fingers, ->thumb, normal): MediaPipe's pinky/index/thumb points are the
# knuckles; hand length ~19 cm, wrist to index knuckle ~9 cm, knuckle row ~8 cm wide.
HAND_OFFSETS = {"index": (0.090, 0.020, 0.0), "pinky": (0.080, -0.025, 0.0),
                "thumb": (0.050, 0.040, 0.0)}
# Landmarks equal to a ground-truth joint.
DIRECT = {f"{side}_{part}": f"{side[0]}_{joint}" for side in ("left", "right") for part, joint in (
    ("shoulder", "shoulder"), ("elbow", "elbow"), ("wrist", "wrist"), ("hip", "hip"),
    ("knee", "knee"), ("ankle", "ankle"), ("heel", "heel"), ("foot_index", "toe"))}
_GROUP = {"face": tuple(FACE_OFFSETS), "trunk": ("shoulder", "hip"),
          "limb": ("elbow", "knee"), "distal": ("wrist", "ankle"),
          "extremity": ("pinky", "index", "thumb", "heel", "foot_index")}
_SWAP_PARTS = {"legs": ("knee", "ankle", "heel", "foot_index"),
               "arms": ("elbow", "wrist", "pinky", "index", "thumb"),
               "body": tuple(n[5:] for n in LANDMARK_NAMES if n.startswith("left_"))}


@dataclass(frozen=True)
class DetectorSimConfig:
    """Virtual camera and detector noise. Angles in degrees, lengths in metres, 2d noise as a
    fraction of the person's size in the image (defaults and their sources: constants above)."""

    distance: float | None = None   # m, horizontal camera-subject distance; None: fit the motion
    height: float = 1.3             # m, camera centre above the ground
    azimuth_deg: float = 30.0       # 0: in front of the subject, 90: at its left side
    fov_deg: float = 60.0           # horizontal field of view
    image_size: tuple[int, int] = (1920, 1080)  # (width, height), px
    sigma_2d_white: float = SIGMA_2D_WHITE
    sigma_2d_drift: float = SIGMA_2D_DRIFT
    sigma_3d_white: float = SIGMA_3D_WHITE
    sigma_3d_drift: float = SIGMA_3D_DRIFT
    depth_noise_ratio: float = DEPTH_NOISE_RATIO
    scale_bias_mean: float = SCALE_BIAS_MEAN
    scale_bias_sigma: float = SCALE_BIAS_SIGMA
    depth_scale_mean: float = DEPTH_SCALE_MEAN
    depth_scale_sigma: float = DEPTH_SCALE_SIGMA
    lean_bias_sigma_deg: float = LEAN_BIAS_SIGMA_DEG
    drift_time: float = DRIFT_TIME
    noise_chain_correlation: float = NOISE_CHAIN_CORRELATION   # in [0, 1); 0: independent
    bone_stretch_removed: float = BONE_STRETCH_REMOVED         # in [0, 1]; 0: as before stop 76
    outlier_rate: float = OUTLIER_RATE
    swap_rate: float = SWAP_RATE
    far_side_drop: float = FAR_SIDE_DROP     # confidence model: see the constants above
    occluded_drop: float = OCCLUDED_DROP
    known_intrinsics: bool = False  # put K into the Observations (a calibrated camera)
    # World landmarks in the frame of the ray through the hips, as MediaPipe gives them: on
    # the four pose2sim views they are 6-12 mm nearer the reference rotated from that frame
    # than taken in camera axes (docs/mediapipe_error.md, Frame of the world landmarks). False:
    # camera axes, as the simulator had them until stop 74.
    ray_aligned_world: bool = True
    seed: int = 0

    @classmethod
    def noiseless(cls, **fields) -> DetectorSimConfig:
        """A detector that sees the truth: no 2d or 3d noise, per-clip biases, outliers or
        swaps (the confidence model stays). An oracle input: what a later stage loses on
        consistent, correct detections is its own error, not the detector's."""
        clean = dict(sigma_2d_white=0.0, sigma_2d_drift=0.0, sigma_3d_white=0.0,
                     sigma_3d_drift=0.0, scale_bias_mean=1.0, scale_bias_sigma=0.0,
                     depth_scale_mean=1.0, depth_scale_sigma=0.0, lean_bias_sigma_deg=0.0,
                     outlier_rate=0.0, swap_rate=0.0)
        return cls(**{**clean, **fields})

    def __post_init__(self) -> None:
        if not 0.0 <= self.noise_chain_correlation < 1.0:
            raise PhysposeError(f"noise_chain_correlation {self.noise_chain_correlation} is "
                                "outside [0, 1)", remedy="give a correlation from 0 to below 1")
        if not 0.0 <= self.bone_stretch_removed <= 1.0:
            raise PhysposeError(f"bone_stretch_removed {self.bone_stretch_removed} is outside "
                                "[0, 1]", remedy="give a share from 0 to 1")


@dataclass(frozen=True, eq=False)
class SimulatedCapture:
    """What the simulator made, with the truth it was made from."""

    observations: Observations
    camera_K: np.ndarray             # (3, 3)
    camera_T_world2cam: np.ndarray   # (4, 4)
    joints: np.ndarray               # (T, 21, 3) ground-truth joints, world, m
    landmarks: np.ndarray            # (T, 33, 3) ground-truth landmarks, world, m
    landmarks2d: np.ndarray          # (T, 33, 2) their noise-free projections, px
    world_landmarks: np.ndarray      # (T, 33, 3) noise-free hip-centred landmarks, m, in the
                                     # ray frame (camera axes without ray_aligned_world)
    outliers: np.ndarray             # (T, 33) bool, landmark replaced by an outlier
    swapped: np.ndarray              # (T, 33) bool, landmark exchanged with its left/right twin


def synthesize_landmarks(clip: MocapClip) -> np.ndarray:
    """MediaPipe's 33 landmarks from the ground truth, world frame. -> (T, 33, 3) m

    Joints observed directly are copied (so `joints_from_landmarks` returns the clip's joints);
    face points come from the head frame, hand points from the hand frames (offsets above,
    scaled by body height / REFERENCE_STATURE).
    """
    scale = body_height(clip) / REFERENCE_STATURE
    out = np.zeros((clip.num_frames, NUM_LANDMARKS, 3))
    for name, joint in DIRECT.items():
        out[:, LANDMARK_INDEX[name]] = clip.joints[:, JOINT_INDEX[joint]]
    head = clip.joints[:, JOINT_INDEX["head"]]
    for name, offset in FACE_OFFSETS.items():
        out[:, LANDMARK_INDEX[name]] = head + scale * clip.head_rot @ np.asarray(offset)
    for k, side in enumerate(("left", "right")):
        wrist = clip.joints[:, JOINT_INDEX[f"{side[0]}_wrist"]]
        for part, offset in HAND_OFFSETS.items():
            out[:, LANDMARK_INDEX[f"{side}_{part}"]] = (
                wrist + scale * clip.hand_rot[:, k] @ np.asarray(offset))
    return out


def _mean_facing(clip: MocapClip) -> np.ndarray:
    """The subject's mean horizontal facing direction (unit), from its hips' left direction.

    Where the clip-mean left direction has no horizontal part (a turn that averages out, hips
    stacked vertically), the first frame with one decides; failing that, world +x.
    """
    left = clip.joint("l_hip") - clip.joint("r_hip")
    for candidate in itertools.chain([left.mean(axis=0)], left):   # frames only if needed
        facing = np.array([candidate[1], -candidate[0], 0.0])   # left x up, made horizontal
        norm = np.linalg.norm(facing)
        if norm > 1e-6:
            return facing / norm
    return np.array([1.0, 0.0, 0.0])


def look_at_camera(clip: MocapClip, cfg: DetectorSimConfig) -> tuple[np.ndarray, np.ndarray]:
    """Intrinsics K (3, 3) and T_world2cam (4, 4) of the configured static camera."""
    width, height = cfg.image_size
    f = 0.5 * width / np.tan(np.deg2rad(cfg.fov_deg) / 2)
    K = np.array([[f, 0.0, width / 2], [0.0, f, height / 2], [0.0, 0.0, 1.0]])
    pelvis = clip.joint("pelvis")
    target = pelvis.mean(axis=0)
    facing = _mean_facing(clip)
    side = np.cross([0.0, 0.0, 1.0], facing)
    az = np.deg2rad(cfg.azimuth_deg)
    direction = np.cos(az) * facing + np.sin(az) * side  # from the subject towards the camera

    def extrinsics(distance: float) -> np.ndarray:
        centre = target + distance * direction
        centre[2] = cfg.height
        fwd = target - centre
        fwd /= np.linalg.norm(fwd)
        right = np.cross(fwd, [0.0, 0.0, 1.0])
        right /= np.linalg.norm(right)
        down = np.cross(fwd, right)
        T = np.eye(4)
        T[:3, :3] = np.stack([right, down, fwd])  # rows: camera axes in world coordinates
        T[:3, 3] = -T[:3, :3] @ centre
        return T

    if cfg.distance is not None:
        return K, extrinsics(cfg.distance)
    points = np.concatenate([synthesize_landmarks(clip), clip.head_top[:, None]], axis=1)
    margin = 0.05 * np.array([width, height])
    for distance in np.arange(2.5, 60.0, 0.25):
        T = extrinsics(distance)
        if (transform_points(T, points)[..., 2] <= 0.3).any():
            continue
        uv = project(points, K, T)
        if ((uv >= margin) & (uv <= np.array([width, height]) - margin)).all():
            return K, T
    return K, extrinsics(60.0)


def _drift(rng: np.random.Generator, shape: tuple, fps: float, tau: float) -> np.ndarray:
    """Unit-variance AR(1) noise along axis 0 with correlation time tau (s)."""
    a = np.exp(-1.0 / (fps * tau)) if tau > 0 else 0.0
    white = rng.standard_normal(shape)
    out = np.empty(shape)
    out[0] = white[0]
    for t in range(1, shape[0]):
        out[t] = a * out[t - 1] + np.sqrt(1 - a * a) * white[t]
    return out


# The chains of NOISE_CHAIN_CORRELATION, and the bones BONE_STRETCH_REMOVED holds.
_NOISE_PARENT = {**{c: p for c, p in LIMB_PARENT.items() if not p.endswith("_hip")},
                 **{name: "nose" for name in FACE_OFFSETS if name != "nose"}}
_KEPT_BONES = tuple((LIMB_PARENT[c], c) for c in LIMB_PARENT
                    if c.endswith(("knee", "ankle", "elbow", "wrist")))
# Both walks below go down the chains in MediaPipe's landmark order: parents come first.
assert all(LANDMARK_INDEX[p] < LANDMARK_INDEX[c]
           for c, p in (*LIMB_PARENT.items(), *_NOISE_PARENT.items()))


def _descendants(name: str) -> list[int]:
    """Landmark indices of `name` and everything below it in LIMB_PARENT."""
    out = [name]
    for child in sorted(LIMB_PARENT, key=LANDMARK_INDEX.get):
        if LIMB_PARENT[child] in out:
            out.append(child)
    return [LANDMARK_INDEX[n] for n in out]


def _chain_correlated(noise: np.ndarray, rho: float) -> np.ndarray:
    """(T, 33, D) unit-variance noise made to correlate by `rho` with each landmark's parent
    (_NOISE_PARENT; rho^2 two links down), each landmark's variance kept."""
    out = noise.copy()
    for name in LANDMARK_NAMES:
        parent = _NOISE_PARENT.get(name)
        if parent is not None:
            k, p = LANDMARK_INDEX[name], LANDMARK_INDEX[parent]
            out[:, k] = rho * out[:, p] + np.sqrt(1.0 - rho * rho) * noise[:, k]
    return out


def _remove_bone_stretch(noise: np.ndarray, true_pos: np.ndarray, share: float) -> np.ndarray:
    """(T, 33, 3) noise with `share` of its component along each of _KEPT_BONES (the child's
    noise minus the parent's, along the true bone, before the per-clip lean and depth
    compression: a first-order correction) taken off the bone's child and every landmark below
    it, so the limb turns rather than stretches."""
    out = noise.copy()
    for parent, child in _KEPT_BONES:
        p, c = LANDMARK_INDEX[parent], LANDMARK_INDEX[child]
        bone = true_pos[:, c] - true_pos[:, p]
        bone = bone / np.maximum(np.linalg.norm(bone, axis=-1, keepdims=True), 1e-9)
        along = np.sum((out[:, c] - out[:, p]) * bone, axis=-1, keepdims=True)
        out[:, _descendants(child)] -= (share * along * bone)[:, None]
    return out


def _visibility(lm_cam: np.ndarray, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Far-side weight in [0, 1] and torso occlusion (bool), both (T, 33)."""
    depth = lm_cam[..., 2]
    far = np.zeros(depth.shape)
    for k, name in enumerate(LANDMARK_NAMES):
        twin = name.replace("left", "#").replace("right", "left").replace("#", "right")
        if twin != name:
            far[:, k] = np.clip((depth[:, k] - depth[:, LANDMARK_INDEX[twin]]) / FAR_SIDE_DEPTH,
                                0.0, 1.0)
    quad = [LANDMARK_INDEX[n] for n in ("left_shoulder", "right_shoulder", "right_hip",
                                        "left_hip")]
    corners = uv[:, quad]                                   # (T, 4, 2)
    edges = np.roll(corners, -1, axis=1) - corners
    rel = uv[:, None, :, :] - corners[:, :, None, :]        # (T, 4, 33, 2)
    cross = edges[:, :, None, 0] * rel[..., 1] - edges[:, :, None, 1] * rel[..., 0]
    inside = (cross > 0).all(axis=1) | (cross < 0).all(axis=1)
    torso_depth = depth[:, quad].mean(axis=1, keepdims=True)
    occluded = inside & (depth > torso_depth + OCCLUDED_MARGIN)
    occluded[:, quad] = False
    return far, occluded


def _group(name: str) -> str:
    part = name.split("_", 1)[-1] if name.startswith(("left_", "right_")) else name
    return next(g for g, parts in _GROUP.items() if name in parts or part in parts)


def _confidence_base() -> np.ndarray:
    return np.array([BASE_CONFIDENCE[_group(name)] for name in LANDMARK_NAMES])


def _far_side_mask() -> np.ndarray:
    """(33,) 1 where a landmark loses confidence on the far side (FAR_SIDE_GROUPS), else 0."""
    return np.array([float(_group(name) in FAR_SIDE_GROUPS) for name in LANDMARK_NAMES])


def _swap_events(rng: np.random.Generator, t: int, rate: float) -> np.ndarray:
    """(T, 33) bool: landmarks exchanged with their twin (legs or arms, runs of frames)."""
    swapped = np.zeros((t, NUM_LANDMARKS), dtype=bool)
    starts = rng.random(t) < rate
    limbs = rng.integers(0, len(_SWAP_PARTS), t)
    lengths = rng.integers(SWAP_FRAMES[0], SWAP_FRAMES[1] + 1, t)
    for i in np.flatnonzero(starts):
        parts = list(_SWAP_PARTS.values())[limbs[i]]
        cols = [LANDMARK_INDEX[f"{s}_{p}"] for s in ("left", "right") for p in parts]
        swapped[i:i + lengths[i], cols] = True
    return swapped


def _apply_swaps(values: np.ndarray, swapped: np.ndarray) -> np.ndarray:
    out = values.copy()
    for k, name in enumerate(LANDMARK_NAMES):
        if name.startswith("left_"):
            j = LANDMARK_INDEX["right_" + name[5:]]
            rows = swapped[:, k]
            out[rows, k], out[rows, j] = values[rows, j], values[rows, k]
    return out


def simulate_detections(clip: MocapClip, cfg: DetectorSimConfig = DetectorSimConfig()
                        ) -> SimulatedCapture:
    """Noisy 2d/3d MediaPipe-style observations of a mocap clip from a virtual static camera."""
    rng = np.random.default_rng([cfg.seed, zlib.crc32(clip.name.encode())])
    t = clip.num_frames
    width, height = cfg.image_size
    K, T = look_at_camera(clip, cfg)
    lm = synthesize_landmarks(clip)
    lm_cam = transform_points(T, lm)
    uv_true = project(lm, K, T)
    far, occluded = _visibility(lm_cam, uv_true)
    gain = 1.0 + FAR_NOISE_GAIN * far + OCCLUDED_NOISE_GAIN * occluded     # (T, 33)
    outline = np.concatenate([uv_true, project(clip.head_top, K, T)[:, None]], axis=1)
    size = np.ptp(outline, axis=1).max(axis=1)[:, None, None]               # (T, 1, 1) px

    # 2d: white + drifting noise in proportion to the person's size, larger on hidden landmarks.
    noise2d = (cfg.sigma_2d_white * rng.standard_normal((t, NUM_LANDMARKS, 2))
               + cfg.sigma_2d_drift * _drift(rng, (t, NUM_LANDMARKS, 2), clip.fps,
                                             cfg.drift_time))
    uv = uv_true + size * gain[..., None] * noise2d
    conf = (_confidence_base()[None] - cfg.far_side_drop * far * _far_side_mask()
            - cfg.occluded_drop * occluded
            + CONFIDENCE_JITTER * rng.standard_normal((t, NUM_LANDMARKS)))

    # World landmarks: hip-centred, in the frame of the ray through the hips; per clip a lean,
    # a scale and a depth compression; noise larger along the viewing direction (its z).
    hips = 0.5 * (lm_cam[:, LANDMARK_INDEX["left_hip"]] + lm_cam[:, LANDMARK_INDEX["right_hip"]])
    wl_true = lm_cam - hips[:, None]
    if cfg.ray_aligned_world:
        ray = hips / np.linalg.norm(hips, axis=-1, keepdims=True)
        wl_true = np.einsum("tji,tkj->tki", ray_frame(ray), wl_true)     # R^T x, per frame
    scale = cfg.scale_bias_mean + cfg.scale_bias_sigma * rng.standard_normal()
    depth_scale = cfg.depth_scale_mean + cfg.depth_scale_sigma * rng.standard_normal()
    lean = axis_rotation("x", np.deg2rad(cfg.lean_bias_sigma_deg) * rng.standard_normal())
    axis_sigma = np.array([1.0, 1.0, cfg.depth_noise_ratio])
    rho = cfg.noise_chain_correlation
    noise3d = (cfg.sigma_3d_white * _chain_correlated(
        rng.standard_normal((t, NUM_LANDMARKS, 3)), rho)
        + cfg.sigma_3d_drift * _chain_correlated(
            _drift(rng, (t, NUM_LANDMARKS, 3), clip.fps, cfg.drift_time), rho)) * axis_sigma
    # The occlusion gain after: a hidden landmark's error grows by it, its neighbours' do not.
    noise3d = gain[..., None] * _remove_bone_stretch(noise3d, wl_true, cfg.bone_stretch_removed)
    wl = (wl_true @ lean.T) * np.array([1.0, 1.0, depth_scale]) * scale + noise3d

    # Outliers: a large jump with moderately high confidence; swaps: left/right exchanged.
    outliers = rng.random((t, NUM_LANDMARKS)) < cfg.outlier_rate
    angle = rng.uniform(0, 2 * np.pi, (t, NUM_LANDMARKS))
    jump = rng.uniform(*OUTLIER_OFFSET, (t, NUM_LANDMARKS)) * size[..., 0]
    uv = uv + outliers[..., None] * (jump[..., None] * np.stack([np.cos(angle), np.sin(angle)], -1))
    conf = np.where(outliers, rng.uniform(*OUTLIER_CONFIDENCE, (t, NUM_LANDMARKS)), conf)
    swapped = _swap_events(rng, t, cfg.swap_rate)
    # The outlier mask follows its detections into their swapped slots.
    uv, conf, wl, outliers = (_apply_swaps(v, swapped) for v in (uv, conf, wl, outliers))

    inside = ((uv >= 0) & (uv <= np.array([width, height]))).all(axis=-1)
    conf = np.clip(np.where(inside, conf, np.minimum(conf, OUTSIDE_CONFIDENCE)), 0.0, 1.0)
    detected = inside.mean(axis=1) >= 0.5
    kp = np.concatenate([uv, conf[..., None]], axis=-1)
    kp[~detected] = 0.0
    wl[~detected] = 0.0
    obs = Observations(
        source=f"simulated:{clip.source}", fps=clip.fps, image_size=(width, height),
        timestamps=clip.times, keypoints2d=kp, detected=detected,
        interpolated=np.zeros(t, dtype=bool), world_landmarks=wl,
        camera_K=K.copy() if cfg.known_intrinsics else None, frame_indices=np.arange(t))
    return SimulatedCapture(observations=obs, camera_K=K, camera_T_world2cam=T,
                            joints=clip.joints.copy(), landmarks=lm, landmarks2d=uv_true,
                            world_landmarks=wl_true, outliers=outliers, swapped=swapped)
