"""A camera that turns (pans, tilts) while filming: its rotation per frame, from the background.

physpose's kinematic fit and physics assume one static camera. A camera that turns on the spot
to follow the person (a pan in sports footage) breaks that: a runner kept in the middle of the
picture looks like one running on the spot, which no physical body can do on a static floor.
A turning camera sees the scene through a homography between any two frames, whatever the
depth: x_t ~ K R_t K^-1 x_ref. So `estimate_camera_motion` tracks background corners (outside
the person's box) from frame to frame with pyramidal Lucas-Kanade flow, fits a homography to
each pair by RANSAC, chains them to the clip's middle frame (the reference camera), and
`stabilize` maps the detections into that reference camera's image: the later stages then see
a static camera, whose picture is wider than the video. `Observations.homographies` keeps the
map back (reference pixels -> each frame's pixels) for drawing on the video.

The focal length is found from the homographies where the camera turns far enough
(K^-1 H K must be a rotation: self-calibration with square pixels and the principal point at
the image centre); it turns MediaPipe's camera-aligned world landmarks into the reference
camera's axes and becomes the observations' intrinsics where they have none.

A camera that also moves along (a tracking or dolly shot) shows parallax that no homography
explains, and one that zooms changes its focal length; then the homographies are no rotations
and nothing is changed (`CameraMotion.kind` says "moving"): physpose then still sees the person
move with the camera.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from physpose import video as videolib
from physpose.diagnostics import image_box_corners
from physpose.observations import Observations, map_keypoints
from physpose.pinhole import DEFAULT_DIAGONAL_FOV_DEG, focal_from_fov, intrinsics

WORK_LONG_SIDE = 640        # px, frames are tracked at this size
MAX_CORNERS = 400           # background corners tracked per frame pair
PERSON_MARGIN = 0.15        # the person's box grown by this many diagonals is left out
RANSAC_PX = 1.5             # px at WORK_LONG_SIDE, homography inlier threshold
MIN_INLIERS = 30            # a frame pair with fewer inliers is taken as not turning
STATIC_DEG = 2.0            # a camera turning less than this over the clip counts as static
MAX_SKEW = 0.1              # largest ||M M^T - I|| of a rotation from the homographies
MIN_CALIBRATION_DEG = 5.0   # the focal length is trusted from turns at least this large


@dataclass(frozen=True, eq=False)
class CameraMotion:
    """How the camera turned. homographies (T, 3, 3): reference-image pixels -> frame t's
    pixels (identity at the reference frame); rotations (T, 3, 3): directions in the reference
    camera -> frame t's camera; kind: "static", "turning" or "moving" (travels as well:
    not compensated)."""

    kind: str
    reference: int
    homographies: np.ndarray
    rotations: np.ndarray
    focal: float | None          # px, self-calibrated (None where the turn is too small)
    turned_deg: float            # largest angle between a frame's camera and the reference's
    skew: float                  # how far the homographies are from rotations (0: exactly)


def _person_boxes(obs: Observations, scale: float) -> np.ndarray:
    """(T, 4) boxes around the person (or the whole image where no landmarks), work pixels."""
    lo, hi, ok = image_box_corners(obs.keypoints2d)
    grow = PERSON_MARGIN * np.linalg.norm(hi - lo, axis=-1, keepdims=True)
    boxes = np.concatenate([lo - grow, hi + grow], axis=-1) * scale
    boxes[~ok] = np.nan
    return boxes


def _background(shape: tuple[int, int], box: np.ndarray) -> np.ndarray:
    mask = np.full(shape, 255, np.uint8)
    if np.isfinite(box).all():
        x0, y0, x1, y1 = np.round(box).astype(int)
        mask[max(y0, 0):max(y1, 0), max(x0, 0):max(x1, 0)] = 0
    return mask


def _pair_homography(prev: np.ndarray, this: np.ndarray, mask: np.ndarray
                     ) -> np.ndarray | None:
    """Homography prev -> this (work pixels) from tracked background corners; None if unsure."""
    corners = cv2.goodFeaturesToTrack(prev, MAX_CORNERS, 0.01, 8, mask=mask)
    if corners is None or len(corners) < MIN_INLIERS:
        return None
    moved, ok, _ = cv2.calcOpticalFlowPyrLK(prev, this, corners, None, winSize=(21, 21),
                                            maxLevel=3)
    back, ok_back, _ = cv2.calcOpticalFlowPyrLK(this, prev, moved, None, winSize=(21, 21),
                                                maxLevel=3)
    good = (ok[:, 0] == 1) & (ok_back[:, 0] == 1) & (
        np.linalg.norm((back - corners)[:, 0], axis=-1) < 0.5)
    if good.sum() < MIN_INLIERS:
        return None
    h, inliers = cv2.findHomography(corners[good], moved[good], cv2.RANSAC, RANSAC_PX)
    if h is None or inliers.sum() < MIN_INLIERS:
        return None
    return h / h[2, 2]


def frame_homographies(info: videolib.VideoInfo, plan: videolib.FramePlan,
                       obs: Observations) -> np.ndarray:
    """(T, 3, 3) homographies frame t-1 -> frame t in image pixels (identity at t = 0 and
    where too few background corners could be followed)."""
    scale = WORK_LONG_SIDE / max(info.image_size)
    size = (round(info.width * scale), round(info.height * scale))
    to_work = np.diag([scale, scale, 1.0])
    boxes = _person_boxes(obs, scale)
    steps = np.repeat(np.eye(3)[None], len(plan.indices), axis=0)
    prev = None
    for i, (_, image) in enumerate(videolib.read_frames(info, plan.indices)):
        gray = cv2.cvtColor(cv2.resize(image, size, interpolation=cv2.INTER_AREA),
                            cv2.COLOR_BGR2GRAY)
        if prev is not None:
            mask = _background(gray.shape, np.fmax(boxes[i - 1], boxes[i]))
            h = _pair_homography(prev, gray, mask)
            if h is not None:
                steps[i] = np.linalg.inv(to_work) @ h @ to_work
        prev = gray
    return steps


def _skews(homographies: np.ndarray, focal: float, image_size: tuple[int, int]) -> np.ndarray:
    """(T,) ||M M^T - I|| of M = K^-1 H K scaled to unit determinant: 0 for a rotation."""
    k = intrinsics(image_size, focal)
    m = np.linalg.inv(k) @ homographies @ k
    det = np.linalg.det(m)
    m = m / np.cbrt(det)[:, None, None]
    return np.linalg.norm(m @ np.swapaxes(m, 1, 2) - np.eye(3), axis=(1, 2))


def nearest_rotations(homographies: np.ndarray, k: np.ndarray) -> np.ndarray:
    """(T, 3, 3) rotations nearest K^-1 H K (SVD), directions reference -> frame t."""
    u, _, vt = np.linalg.svd(np.linalg.inv(k) @ homographies @ k)
    r = u @ vt
    return r * np.sign(np.linalg.det(r))[:, None, None]


def frame_cameras(homographies: np.ndarray, k: np.ndarray, t_world2cam: np.ndarray
                  ) -> np.ndarray:
    """(T, 4, 4) each frame's world -> camera transform: the reference camera t_world2cam
    turned by the rotation its homography makes under intrinsics k."""
    cameras = np.repeat(np.asarray(t_world2cam, dtype=float)[None], len(homographies), axis=0)
    turn = nearest_rotations(homographies, k)
    cameras[:, :3] = turn @ cameras[:, :3]
    return cameras


def self_calibrate(homographies: np.ndarray, image_size: tuple[int, int]) -> float:
    """The focal length (px) that makes the homographies most nearly rotations."""
    side = max(image_size)
    grid = side * np.exp(np.linspace(np.log(0.3), np.log(5.0), 80))
    cost = [float(np.mean(_skews(homographies, f, image_size) ** 2)) for f in grid]
    best = int(np.argmin(cost))
    fine = grid[max(best - 1, 0)] * np.exp(np.linspace(0, np.log(grid[min(best + 1, 79)]
                                                              / grid[max(best - 1, 0)]), 41))
    cost = [float(np.mean(_skews(homographies, f, image_size) ** 2)) for f in fine]
    return float(fine[int(np.argmin(cost))])


def _angles_deg(rotations: np.ndarray) -> np.ndarray:
    cos = np.clip((np.trace(rotations, axis1=1, axis2=2) - 1) / 2, -1.0, 1.0)
    return np.degrees(np.arccos(cos))


def estimate_camera_motion(info: videolib.VideoInfo, plan: videolib.FramePlan,
                           obs: Observations) -> CameraMotion:
    """How the camera turned over the planned frames (see the module docstring); obs: the
    person's detections there, whose image boxes are left out."""
    default_focal = focal_from_fov(info.image_size, DEFAULT_DIAGONAL_FOV_DEG) \
        if obs.camera_K is None else float(obs.camera_K[0, 0])
    steps = frame_homographies(info, plan, obs)
    t = len(steps)
    to_first = np.empty_like(steps)    # frame 0 pixels -> frame t pixels
    to_first[0] = np.eye(3)
    for i in range(1, t):
        to_first[i] = steps[i] @ to_first[i - 1]
        to_first[i] /= to_first[i][2, 2]
    reference = t // 2
    homographies = to_first @ np.linalg.inv(to_first[reference])
    homographies /= homographies[:, 2:, 2:]
    # Whether they are rotations at all is judged at the focal length that fits them best;
    # that focal length is trusted only where the turn is large enough to fix it.
    best = self_calibrate(homographies, info.image_size)
    skew = float(np.max(_skews(homographies, best, info.image_size)))
    turned_best = float(_angles_deg(nearest_rotations(
        homographies, intrinsics(info.image_size, best))).max())
    focal = best if turned_best >= MIN_CALIBRATION_DEG and skew <= MAX_SKEW else None
    rotations = nearest_rotations(homographies, intrinsics(info.image_size,
                                                           focal or default_focal))
    turned = float(_angles_deg(rotations).max())
    kind = "moving" if skew > MAX_SKEW else ("static" if turned < STATIC_DEG else "turning")
    return CameraMotion(kind=kind, reference=reference, homographies=homographies,
                        rotations=rotations, focal=focal, turned_deg=turned, skew=skew)


def stabilize(obs: Observations, motion: CameraMotion) -> Observations:
    """The observations as the reference camera sees them: keypoints mapped by the inverse
    homographies, world landmarks turned into its axes, and `homographies` set for the way
    back. Nothing changes unless the camera turned; the kind is recorded either way. Masks stay
    in each frame's own pixels. A self-calibrated focal length becomes camera_K where the
    observations have none."""
    if motion.kind != "turning":
        return obs.replace(camera_motion=motion.kind)
    kp = map_keypoints(obs.keypoints2d, np.linalg.inv(motion.homographies), obs.valid)
    world = obs.world_landmarks
    if world is not None:   # directions in frame t's camera -> the reference camera's
        world = np.einsum("tji,tnj->tni", motion.rotations, world)
    k = obs.camera_K
    if k is None and motion.focal is not None:
        k = intrinsics(obs.image_size, motion.focal)
    return obs.replace(keypoints2d=kp, world_landmarks=world, camera_K=k,
                       homographies=motion.homographies, camera_motion=motion.kind)
