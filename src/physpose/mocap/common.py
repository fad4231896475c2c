"""`MocapClip` (ground-truth motion in the project's world frame) and what every reader shares.

Readers produce a `SkeletonMotion` (anatomical points in the file's own axes, metres, at the
file's rate); `finish_clip` turns it into a `MocapClip`: z up, the floor at z = 0, the project's
21 joints (`JOINT_NAMES`), resampled to the target rate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from physpose.errors import PhysposeError
from physpose.joints import JOINT_INDEX, JOINT_NAMES
from physpose.mocap.rotations import orthonormalize

SIDES = ("l", "r")
# Points a reader must provide: the 16 joints MediaPipe observes directly, plus the head centre
# (between the ears) and the top of the head.
LIMB_JOINTS = tuple(n for n in JOINT_NAMES if n[:2] in ("l_", "r_"))
ANATOMICAL_POINTS = LIMB_JOINTS + ("head", "head_top")
STILL_SPEED = 0.15       # m/s, a foot whose heel-toe midpoint moves slower than this stands still
MIN_STILL_FRAMES = 3     # fewer still-foot samples than this: floor from FLOOR_PERCENTILE instead
FLOOR_PERCENTILE = 5.0   # % of frames whose lowest sole point lies below that fallback floor
HEIGHT_PERCENTILE = 95.0  # body height: this percentile of the head-top height ...
STANDING_FOOT_HEIGHT = 0.03  # m, ... over frames where both feet are at most this high
# A leading rest or calibration pose (e.g. a T-pose in frame 0), held still, joined to the motion
# by a jump: a first-second step whose mean point displacement is at least START_JUMP_MIN and
# START_JUMP_RATIO times the largest step of the second after it. The frames before it are
# dropped.
START_JUMP_MIN = 0.1     # m
START_JUMP_RATIO = 4.0
START_JUMP_WITHIN = 1.0  # s
SOURCE_FPS_RANGE = (1.0, 2000.0)  # Hz, a motion file's own rate (median frame step)
MAX_GAP_S = 1.0          # s, the longest step between two frames of a capture
REST_EXTENT = (0.7, 2.3)  # m, plausible largest rest-pose extent of a person (height or span)
# Rigid segments (constant length in every clip): thigh, shin, heel, upper arm, forearm, pelvis.
BONES: tuple[tuple[str, str], ...] = tuple(
    (f"{s}_{a}", f"{s}_{b}") for s in SIDES for a, b in (
        ("hip", "knee"), ("knee", "ankle"), ("ankle", "heel"), ("shoulder", "elbow"),
        ("elbow", "wrist"))) + (("l_hip", "r_hip"),)


@dataclass(frozen=True, eq=False)
class SkeletonMotion:
    """Anatomical points of one clip as a reader computed them: file axes, metres, file rate."""

    name: str
    source: str
    times: np.ndarray               # (T,) s, increasing
    points: dict[str, np.ndarray]   # ANATOMICAL_POINTS -> (T, 3) m
    head_rot: np.ndarray            # (T, 3, 3) columns: face forward, left, up (along the head)
    hand_rot: np.ndarray            # (T, 2, 3, 3) [l, r]; columns: wrist->fingers, ->thumb, x cross y
    up: np.ndarray                  # (3,) the file's world up axis
    leading_frames_dropped: int = 0  # file frames left out before `times` (`leading_jump`)


@dataclass(frozen=True, eq=False)
class MocapClip:
    """Ground-truth motion: world frame, metres, z up, floor at z = 0, uniform rate."""

    name: str
    source: str                     # the file it came from
    fps: float                      # Hz, rate of every per-frame array
    joints: np.ndarray              # (T, 21, 3) under JOINT_NAMES
    head_top: np.ndarray            # (T, 3) top of the head
    head_rot: np.ndarray            # (T, 3, 3) world-from-head; columns: forward, left, up
    hand_rot: np.ndarray            # (T, 2, 3, 3) [l, r]; columns: wrist->fingers, ->thumb, x cross y
    source_fps: float               # Hz, the file's own rate
    floor_offset: float             # m, file floor height (z up) that was subtracted
    meta: dict = field(default_factory=dict)  # source_frames, source_duration (s),
    #                                           leading_frames_dropped (`leading_jump`)

    def __post_init__(self) -> None:
        t = self.joints.shape[0]
        shapes = {"joints": (t, len(JOINT_NAMES), 3), "head_top": (t, 3),
                  "head_rot": (t, 3, 3), "hand_rot": (t, 2, 3, 3)}
        for key, shape in shapes.items():
            value = getattr(self, key)
            if value.shape != shape:
                raise PhysposeError(f"{key} has shape {value.shape}, expected {shape}",
                                    path=self.source)
            if not np.isfinite(value).all():
                raise PhysposeError(f"{key} holds non-finite values", path=self.source,
                                    frame=int(np.argmax(~np.isfinite(value.reshape(t, -1)).all(1))))

    @property
    def num_frames(self) -> int:
        return int(self.joints.shape[0])

    @property
    def times(self) -> np.ndarray:
        """(T,) seconds from the first frame."""
        return np.arange(self.num_frames) / self.fps

    def joint(self, name: str) -> np.ndarray:
        """(T, 3) trajectory of one joint."""
        return self.joints[:, JOINT_INDEX[name]]


def read_lines(path: Path, kind: str) -> list[str]:
    """Text lines of a motion file; an unreadable file raises PhysposeError."""
    try:
        return path.read_text(errors="replace").splitlines()
    except OSError as exc:
        raise PhysposeError(f"cannot read {kind} file ({exc})", path=path) from None


def line_error(path: Path, lineno: int, problem: str, remedy: str) -> PhysposeError:
    """The error for a malformed line of a motion file."""
    return PhysposeError(f"line {lineno}: {problem}", path=path, remedy=remedy)


def infer_up_axis(points: dict[str, np.ndarray]) -> np.ndarray:
    """The signed principal axis closest to the median ankles->head direction. -> (3,)"""
    v = points["head"] - 0.5 * (points["l_ankle"] + points["r_ankle"])
    v = np.median(v / np.linalg.norm(v, axis=1, keepdims=True), axis=0)
    axis = int(np.argmax(np.abs(v)))
    up = np.zeros(3)
    up[axis] = np.sign(v[axis])
    return up


def rotation_to_z_up(up: np.ndarray) -> np.ndarray:
    """Proper rotation R (3, 3) with R @ up = (0, 0, 1) for a signed principal axis `up`."""
    z = np.array([0.0, 0.0, 1.0])
    if np.allclose(up, z):
        return np.eye(3)
    if np.allclose(up, -z):
        return np.diag([1.0, -1.0, -1.0])
    axis = np.cross(up, z)
    axis /= np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + k + k @ k  # Rodrigues for a 90-degree turn (up is orthogonal to z)


def _check_finite(motion: SkeletonMotion) -> None:
    """Refuse a NaN or infinite value (or a zero quaternion's NaN) with its file frame."""
    for key, value in [*motion.points.items(), ("head_rot", motion.head_rot),
                       ("hand_rot", motion.hand_rot)]:
        bad = ~np.isfinite(value.reshape(len(value), -1)).all(axis=1)
        if bad.any():
            raise PhysposeError(f"{key} is not finite (a NaN or infinite value, or a zero-length "
                                "quaternion, in the file)", path=motion.source,
                                frame=int(np.argmax(bad)) + motion.leading_frames_dropped,
                                remedy="fix or cut that frame of the file (frames count from 0)")


def _source_rate(times: np.ndarray, source: str, first_frame: int) -> float:
    """The file's own frame rate (median step), after checking its frame times: increasing,
    finite, at 1-2000 Hz and without a gap over MAX_GAP_S (which would resample into
    millions of frames). Errors count frames from `first_frame`, the file's index of times[0]."""
    dts = np.diff(times)
    if len(times) < 2 or not np.isfinite(times).all() or (dts <= 0).any():
        bad = int(np.argmax(~(np.isfinite(dts) & (dts > 0)))) + 1 if len(dts) else None
        raise PhysposeError("frame times must increase (at least two frames)", path=source,
                            frame=None if bad is None else bad + first_frame,
                            remedy="give each frame a positive, finite frame time")
    source_fps = float(1.0 / np.median(dts))
    lo, hi = SOURCE_FPS_RANGE
    if not lo <= source_fps <= hi:
        raise PhysposeError(f"the file's frame rate {source_fps:g} Hz is outside {lo:g}-{hi:g} "
                            "Hz", path=source,
                            remedy="check the frame time, in seconds per frame (BVH 'Frame "
                                   "Time:', a DeepMimic row's first value; 0.008333 for 120 Hz)")
    gap = int(np.argmax(dts))
    if dts[gap] > MAX_GAP_S:
        raise PhysposeError(f"{dts[gap]:g} s between frames {gap + first_frame} and "
                            f"{gap + 1 + first_frame}", path=source, frame=gap + 1 + first_frame,
                            remedy=f"a capture has no gaps over {MAX_GAP_S:g} s: fix the frame's "
                                   "time step")
    return source_fps


def finish_clip(motion: SkeletonMotion, target_fps: float | None) -> MocapClip:
    """Z up, trunk joints, floor at z = 0 and a uniform rate (`target_fps`; None keeps the file's)."""
    if target_fps is not None and not (math.isfinite(target_fps)
                                       and 0 < target_fps <= SOURCE_FPS_RANGE[1]):
        raise PhysposeError(f"target_fps {target_fps} must be a positive rate up to "
                            f"{SOURCE_FPS_RANGE[1]:g} Hz",
                            path=motion.source,
                            remedy="use e.g. 25, or None to keep the file's own rate")
    missing = set(ANATOMICAL_POINTS) - motion.points.keys()
    if missing:
        raise PhysposeError(f"reader produced no {sorted(missing)}", path=motion.source)
    _check_finite(motion)
    r = rotation_to_z_up(motion.up)
    pts = {k: v @ r.T for k, v in motion.points.items()}
    head_rot = r @ motion.head_rot
    hand_rot = r @ motion.hand_rot

    times = motion.times - motion.times[0]
    source_fps = _source_rate(times, motion.source, motion.leading_frames_dropped)
    floor = estimate_floor(pts, times)
    for v in pts.values():
        v[:, 2] -= floor

    pelvis = 0.5 * (pts["l_hip"] + pts["r_hip"])
    thorax = 0.5 * (pts["l_shoulder"] + pts["r_shoulder"])
    # Same definitions as physpose.joints.joints_from_landmarks (head = between the ears).
    trunk = {"pelvis": pelvis, "thorax": thorax, "spine": 0.5 * (pelvis + thorax),
             "head": pts["head"], "neck": 0.5 * (thorax + pts["head"])}
    joints = np.stack([trunk[n] if n in trunk else pts[n] for n in JOINT_NAMES], axis=1)

    fps = float(target_fps) if target_fps is not None else source_fps
    new_t = np.arange(0.0, times[-1] + 1e-9, 1.0 / fps)
    if len(new_t) < 2:
        raise PhysposeError(f"the clip lasts {times[-1]:g} s: under two frames at {fps:g} Hz",
                            path=motion.source, remedy="use a longer clip")
    joints, head_top = resample(times, joints, new_t), resample(times, pts["head_top"], new_t)
    head_rot = orthonormalize(resample(times, head_rot, new_t))
    hand_rot = orthonormalize(resample(times, hand_rot, new_t))
    return MocapClip(name=motion.name, source=motion.source, fps=fps, joints=joints,
                     head_top=head_top, head_rot=head_rot, hand_rot=hand_rot,
                     source_fps=source_fps, floor_offset=floor,
                     meta={"source_frames": len(times), "source_duration": float(times[-1]),
                           "leading_frames_dropped": motion.leading_frames_dropped})


def leading_jump(positions: np.ndarray, times: np.ndarray) -> int:
    """How many leading frames a jump separates from the rest (0: none; see START_JUMP_MIN).

    Many exports start with the skeleton's rest pose (a T-pose) for retargeting, one frame
    before the capture: no body moves like that, and a detector simulated on it would see a
    different person in frame 0.

    positions: (T, P, 3) m, the skeleton's joints; times: (T,) s.
    """
    step = np.linalg.norm(np.diff(positions, axis=0), axis=-1).mean(axis=1)  # (T-1,) m
    times = times - times[0]
    for k in np.flatnonzero(times[1:] <= START_JUMP_WITHIN):
        if step[k] < START_JUMP_MIN:
            continue
        if k and step[:k].max() > START_JUMP_MIN / 4:
            return 0    # the frames before it move: not a held pose, the motion itself jumps
        after = step[k + 1:][times[k + 2:] <= times[k + 1] + START_JUMP_WITHIN]
        if len(after) >= 3 and step[k] > START_JUMP_RATIO * after.max():
            return int(k + 1)
    return 0


def estimate_floor(points: dict[str, np.ndarray], times: np.ndarray) -> float:
    """Floor height (z up), m: the median height of a still foot's lower sole point.

    points: z-up "{l,r}_{heel,toe}" -> (T, 3); times: (T,) s. With too few still-foot frames
    (a clip always in motion), a low percentile of the lowest sole point per frame instead.
    """
    still = _still_sole_heights(points, times, STILL_SPEED)
    if len(still) >= MIN_STILL_FRAMES:
        return float(np.median(still))
    soles = np.stack([points[f"{s}_{p}"][:, 2] for s in SIDES for p in ("heel", "toe")], axis=1)
    return float(np.percentile(soles.min(axis=1), FLOOR_PERCENTILE))


def _still_sole_heights(points: dict[str, np.ndarray], times: np.ndarray,
                        max_speed: float) -> np.ndarray:
    """Lower sole point height (K,) of each foot in the frames where it stands still."""
    out = []
    for s in SIDES:
        sole = np.stack([points[f"{s}_heel"], points[f"{s}_toe"]], axis=1)  # (T, 2, 3)
        mid = sole.mean(axis=1)
        speed = np.linalg.norm(np.gradient(mid[:, :2], times, axis=0), axis=1)
        out.append(sole[speed < max_speed, :, 2].min(axis=1))
    return np.concatenate(out)


def resample(times: np.ndarray, values: np.ndarray, new_times: np.ndarray) -> np.ndarray:
    """Linear interpolation along axis 0. values: (T, ...) -> (len(new_times), ...)."""
    flat = values.reshape(len(times), -1)
    out = np.stack([np.interp(new_times, times, flat[:, k]) for k in range(flat.shape[1])], 1)
    return out.reshape((len(new_times),) + values.shape[1:])


def body_height(clip: MocapClip) -> float:
    """Standing height estimate, m: a high percentile of the head-top height over the frames
    with both feet on the floor (all frames if there are none, e.g. a clip always in the air)."""
    feet = np.stack([np.minimum(clip.joint(f"{s}_heel")[:, 2], clip.joint(f"{s}_toe")[:, 2])
                     for s in SIDES], axis=1)
    both_down = (feet < STANDING_FOOT_HEIGHT).all(axis=1)
    heights = clip.head_top[both_down, 2] if both_down.any() else clip.head_top[:, 2]
    return float(np.percentile(heights, HEIGHT_PERCENTILE))


def bone_lengths(clip: MocapClip) -> dict[str, np.ndarray]:
    """Per-frame length (T,) of each rigid segment in BONES, keyed 'a-b'."""
    return {f"{a}-{b}": np.linalg.norm(clip.joint(a) - clip.joint(b), axis=1) for a, b in BONES}


def stance_foot_heights(clip: MocapClip, max_speed: float = STILL_SPEED) -> np.ndarray:
    """Heights (K,) m of each foot's lower sole point (heel or toe) in the frames where that
    foot stands still (heel-toe midpoint slower than `max_speed` m/s horizontally)."""
    points = {f"{s}_{p}": clip.joint(f"{s}_{p}") for s in SIDES for p in ("heel", "toe")}
    return _still_sole_heights(points, clip.times, max_speed)
