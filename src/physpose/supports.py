"""Supports the scene lacks but the kinematic estimate shows: where the person is held up by
something physpose was not told about, the simplest such thing.

- `support_boxes`: a box on the floor under feet that stay raised (`diagnostics.raised_runs`:
  the person stands on a box, a step, a ledge); `support_heights`: its top frame by frame,
  for the kinematic fit to stand the feet on.
- `seated_runs` / `seat_boxes`: a seat under a person who sits (thighs level, the trunk well
  behind the feet, still, for a second or more): no body can hold that on its feet alone, so
  without a seat the simulated body falls backwards.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from physpose.joints import JOINT_INDEX
from physpose.metrics import foot_points
from physpose.reconstruction import frame_runs
from physpose.scene import Box

SUPPORT_MARGIN = 0.3       # m added on every side of the feet's extent for a support box
RESTING_SPEED = 0.5        # m/s, a foot slower than this rests on its support
ON_SUPPORT = 0.1           # m, feet further below a support's top are stepping on or off it


def _resting_soles(soles: np.ndarray, runs: list[tuple[int, int, float]], fps: float
                   ) -> list[tuple[int, int, np.ndarray]]:
    """(first, last, both feet's sole points (N, 2, P, 3) in its N resting frames) of each run
    with frames in which the lower foot is slower than RESTING_SPEED (runs without such
    frames are left out). soles: (T, 2, P, 3) the motion's `foot_points`."""
    centres = soles.mean(axis=2)                                 # (T, 2, 3)
    speed = np.linalg.norm(np.gradient(centres, axis=0), axis=-1) * fps
    lower = soles[..., 2].min(axis=2).argmin(axis=1)             # (T,) the lower foot
    resting = speed[np.arange(len(soles)), lower] < RESTING_SPEED
    out = []
    for a, b, _ in runs:
        frames = a + np.flatnonzero(resting[a:b + 1])
        if len(frames):
            out.append((a, b, soles[frames]))
    return out


def _top(resting: np.ndarray) -> float:
    """A support's top under resting soles (N, 2, P, 3): the 10th percentile of their lowest
    point (they stand on it, not in it)."""
    return float(np.percentile(resting[..., 2].min(axis=(1, 2)), 10))


def support_boxes(joints: np.ndarray, runs: list[tuple[int, int, float]], fps: float,
                  heights: np.ndarray | None = None) -> tuple[Box, ...]:
    """One box per `raised_runs` stretch, standing on the floor under the feet where they
    rest (the lower foot slower than RESTING_SPEED; a stretch can end in a leap off the
    support): its top at the 10th percentile of the resting feet's lowest point (they stand
    on it, not in it), or where the kinematic fit stood the feet on a support in the
    stretch (heights: its (T,) `support_heights`), at that top; its sides SUPPORT_MARGIN
    beyond where the resting soles are. The estimate says that something holds the person
    up there; this is the simplest such thing. A stretch without resting frames gets none."""
    if not runs:
        return ()
    boxes = []
    for a, b, resting in _resting_soles(foot_points(np.asarray(joints, dtype=float)), runs,
                                        fps):
        fitted = 0.0 if heights is None else float(np.max(heights[a:b + 1]))
        top = fitted if fitted > 0 else _top(resting)
        points = resting.reshape(-1, 3)
        lo = points[:, :2].min(axis=0) - SUPPORT_MARGIN
        hi = points[:, :2].max(axis=0) + SUPPORT_MARGIN
        centre = 0.5 * (lo + hi)
        boxes.append(Box(center=(float(centre[0]), float(centre[1]), top / 2),
                         size=(float(hi[0] - lo[0]), float(hi[1] - lo[1]), top)))
    return tuple(boxes)


def support_heights(joints: np.ndarray, runs: list[tuple[int, int, float]], fps: float
                    ) -> np.ndarray:
    """(T,) the height the feet stand on in each frame of a motion (T, 21, 3): the top of
    `support_boxes`' box through each raised run, 0 (the floor) elsewhere, in the run's
    frames whose feet are more than ON_SUPPORT below that top (stepping up or down: a top
    above them would push them up) and where the person sits (`seated_runs`: feet hanging
    from a seat are raised but stand on nothing)."""
    joints = np.asarray(joints, dtype=float)
    heights = np.zeros(len(joints))
    if not runs:
        return heights
    soles = foot_points(joints)
    lowest = soles[..., 2].min(axis=(1, 2))
    for a, b, resting in _resting_soles(soles, runs, fps):
        top = _top(resting)
        on = lowest[a:b + 1] >= top - ON_SUPPORT
        heights[a:b + 1] = np.where(on, top, 0.0)
    for a, b, _ in seated_runs(joints, fps):
        heights[a:b + 1] = 0.0
    return heights


SEAT_THIGH_ANGLE = np.radians(35.0)  # thighs within this of level ...
SEAT_BEHIND = 0.15        # m, ... the trunk this far outside the standing feet's outline ...
SEAT_SPEED = 0.3          # m/s, ... moving slower than this horizontally ...
SEAT_SECONDS = 1.0        # ... for at least this long: the person sits
SEAT_BELOW_HIP = 0.08     # m, the thighs' underside below the hip joint centres (the body
                          # model's thigh radius, 0.07 m at 1.75 m, and a centimetre: a seat a
                          # little low drops the body a little, one too high pushes it up)
SEAT_MIN_HEIGHT = 0.2     # m, a lower seat is the floor (someone lying or sitting on it)
SEAT_THICKNESS = 0.1      # m, the seat is a slab, so feet tucked under it stay free
STANDING_SOLE = 0.05      # m, a sole point this low stands on the floor
_TRUNK = [JOINT_INDEX[n] for n in ("pelvis", "spine", "thorax", "l_shoulder", "r_shoulder")]


def _outside(point: np.ndarray, outline: np.ndarray) -> float:
    """How far (m) a 2d point lies outside the convex outline of 2d points (<= 0 inside;
    the largest distance past one of its edges' lines, exact off an edge's middle)."""
    if len(outline) == 0:
        return np.inf
    try:
        hull = ConvexHull(outline)
    except (QhullError, ValueError):          # fewer than 3 points, or all in a line
        return float(np.linalg.norm(outline - point, axis=1).min())
    return float((hull.equations[:, :2] @ point + hull.equations[:, 2]).max())


def _hips_and_thighs(joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(T, 2, 3) hip joints (left, right) and (T, 2, 3) hip-to-knee vectors."""
    hips = joints[:, [JOINT_INDEX["l_hip"], JOINT_INDEX["r_hip"]]]
    return hips, joints[:, [JOINT_INDEX["l_knee"], JOINT_INDEX["r_knee"]]] - hips


def seated_runs(joints: np.ndarray, fps: float) -> list[tuple[int, int, float]]:
    """(first, last, seat height m) of each stretch of at least SEAT_SECONDS in which a motion
    (T, 21, 3; world z up, floor at 0) sits: both thighs within SEAT_THIGH_ANGLE of level,
    the trunk (pelvis, spine, thorax, shoulders) more than SEAT_BEHIND outside the outline of
    the sole points standing on the floor (or no foot standing) and moving slower than
    SEAT_SPEED, and the seat (SEAT_BELOW_HIP under the hips, 10th percentile) at least
    SEAT_MIN_HEIGHT up. A squat keeps the trunk over the feet; lying keeps the hips low."""
    joints = np.asarray(joints, dtype=float)
    t = len(joints)
    if t < 3:
        return []
    hips, thighs = _hips_and_thighs(joints)
    level = np.abs(np.arcsin(np.clip(thighs[..., 2] / np.maximum(
        np.linalg.norm(thighs, axis=-1), 1e-9), -1, 1))) < SEAT_THIGH_ANGLE
    trunk = joints[:, _TRUNK, :2].mean(axis=1)
    speed = np.linalg.norm(np.gradient(trunk, axis=0), axis=-1) * fps
    soles = foot_points(joints).reshape(t, -1, 3)
    behind = np.array([_outside(trunk[k], soles[k, soles[k, :, 2] < STANDING_SOLE, :2])
                       for k in range(t)])
    sitting = level.all(axis=1) & (behind > SEAT_BEHIND) & (speed < SEAT_SPEED)
    out = []
    for a, b in frame_runs(sitting):
        seat = float(np.percentile(hips[a:b + 1, :, 2].mean(axis=1), 10)) - SEAT_BELOW_HIP
        if (b - a + 1) / fps >= SEAT_SECONDS and seat >= SEAT_MIN_HEIGHT:
            out.append((a, b, seat))
    return out


def seat_boxes(joints: np.ndarray, runs: list[tuple[int, int, float]]) -> tuple[Box, ...]:
    """One seat per `seated_runs` stretch: a SEAT_THICKNESS slab (a chair seat, turned with
    the thighs) with its top at the run's seat height, from 0.25 m behind the hip joints to
    55 % of the way to the knees (the calves hang clear of it), 0.15 m wider than the hips on
    each side."""
    joints = np.asarray(joints, dtype=float)
    boxes = []
    for a, b, top in runs:
        hips, thighs = _hips_and_thighs(joints[a:b + 1])
        forward = np.median(thighs[..., :2].reshape(-1, 2), axis=0)
        forward /= max(np.linalg.norm(forward), 1e-9)
        thigh = float(np.median(np.linalg.norm(thighs, axis=-1)))
        half_width = 0.5 * float(np.median(np.linalg.norm(hips[:, 0] - hips[:, 1], axis=-1)))
        centre = np.median(hips.mean(axis=1)[:, :2], axis=0)
        back, front = -0.25, 0.55 * thigh
        middle = centre + 0.5 * (back + front) * forward
        thickness = min(SEAT_THICKNESS, top)
        boxes.append(Box(center=(float(middle[0]), float(middle[1]), top - thickness / 2),
                         size=(front - back, 2 * (half_width + 0.15), thickness),
                         yaw=float(np.arctan2(forward[1], forward[0]))))
    return tuple(boxes)
