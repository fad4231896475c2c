"""The `baseline` variant: the detector's own 3d output, placed in the scene, scored as it is.

MediaPipe's world landmarks are hip-centred and metric, in the frame of the viewing ray through
the hips (docs/mediapipe_error.md, Frame of the world landmarks); they are rotated into camera
axes by that ray, found from the detected hips, as the kinematic fit does. Per frame the root
translation t that best re-projects them onto the 2d detections is solved in closed form
(confidence-weighted linear least squares, re-weighted by depth so the residual approximates
pixels). The world frame then comes from the known camera, else from a level-camera guess:
gravity along camera +y, the ground a low percentile of the per-frame lowest foot landmark.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np

from physpose.benchmark.variants import VariantContext, register_variant
from physpose.errors import PhysposeError
from physpose.joints import JOINT_NAMES, LANDMARK_INDEX, joints_from_landmarks
from physpose.observations import Observations
from physpose.pinhole import hip_ray_frames
from physpose.reconstruction import Reconstruction

_FOOT = [LANDMARK_INDEX[n] for n in ("left_heel", "right_heel", "left_foot_index",
                                     "right_foot_index")]
# World axes of a level camera in camera axes: x_w = x_c, y_w = z_c (forward), z_w = -y_c (up).
_R_CAM2WORLD_LEVEL = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
_MIN_DEPTH = 0.3  # m, closest admissible root depth


@dataclass(frozen=True)
class BaselineConfig:
    """Settings of the baseline placement."""

    min_confidence: float = 0.2     # landmarks below this confidence do not place the root
    reweight_iterations: int = 3    # depth re-weightings of the linear translation solve
    ground_percentile: float = 10.0  # % of frames whose lowest foot landmark is below the ground
    ray_aligned_world: bool = True  # False: the world landmarks taken in camera axes (until stop 74)


def guess_intrinsics(image_size: tuple[int, int]) -> np.ndarray:
    """(3, 3) pinhole guess: focal length = image diagonal (~53 deg diagonal field of view)."""
    width, height = image_size
    focal = float(np.hypot(width, height))
    return np.array([[focal, 0.0, width / 2.0], [0.0, focal, height / 2.0], [0.0, 0.0, 1.0]])


def solve_root_translation(world_landmarks: np.ndarray, keypoints2d: np.ndarray, K: np.ndarray,
                           cfg: BaselineConfig = BaselineConfig()) -> tuple[np.ndarray, np.ndarray]:
    """Per-frame translation placing hip-centred landmarks so they re-project onto detections.

    world_landmarks: (T, 33, 3) m, camera axes; keypoints2d: (T, 33, 3) px + confidence.
    Returns t: (T, 3) camera-frame root positions (m) and ok: (T,) bool, frames with at least
    three confident landmarks (t is NaN elsewhere).
    """
    W = np.asarray(world_landmarks, dtype=float)
    kp = np.asarray(keypoints2d, dtype=float)
    a = (kp[..., 0] - K[0, 2]) / K[0, 0]   # (T, 33) normalised image coordinates
    b = (kp[..., 1] - K[1, 2]) / K[1, 1]
    conf = np.where(kp[..., 2] >= cfg.min_confidence, kp[..., 2], 0.0)
    ok = (conf > 0).sum(1) >= 3
    ones, zeros = np.ones_like(a), np.zeros_like(a)
    # rows: tx - a tz = a Wz - Wx ; ty - b tz = b Wz - Wy
    A = np.concatenate([np.stack([ones, zeros, -a], -1), np.stack([zeros, ones, -b], -1)], 1)
    rhs = np.concatenate([a * W[..., 2] - W[..., 0], b * W[..., 2] - W[..., 1]], 1)
    t = np.zeros((len(W), 3))
    depth_w = np.ones_like(conf)
    for _ in range(1 + cfg.reweight_iterations):
        w = np.concatenate([conf * depth_w] * 2, 1)                   # (T, 66)
        AtA = np.einsum("tri,tr,trj->tij", A, w, A) + 1e-9 * np.eye(3)
        Atb = np.einsum("tri,tr,tr->ti", A, w, rhs)
        t[ok] = np.linalg.solve(AtA[ok], Atb[ok][..., None])[..., 0]
        t[:, 2] = np.maximum(t[:, 2], _MIN_DEPTH)
        depth = W[..., 2] + t[:, None, 2]
        depth_w = 1.0 / np.maximum(depth, _MIN_DEPTH) ** 2  # algebraic -> pixel residual
    t[~ok] = np.nan
    return t, ok


def level_ground_frame(landmarks_cam: np.ndarray, percentile: float) -> np.ndarray:
    """(4, 4) T_world2cam of a level camera whose floor lies under the lowest foot landmarks.

    landmarks_cam: (T, 33, 3) camera-frame positions, m.
    """
    up = -landmarks_cam[:, _FOOT, 1]                  # height above the camera, (T, 4)
    ground = float(np.percentile(up.min(axis=1), percentile))
    T_cam2world = np.eye(4)
    T_cam2world[:3, :3] = _R_CAM2WORLD_LEVEL
    T_cam2world[2, 3] = -ground                       # camera height above that floor
    return np.linalg.inv(T_cam2world)


def place_landmarks(obs: Observations, K: np.ndarray, cfg: BaselineConfig) -> np.ndarray:
    """(T, 33, 3) camera-frame landmarks: world landmarks shifted by the solved root."""
    if obs.world_landmarks is None:
        raise PhysposeError("the baseline needs MediaPipe world landmarks", path=obs.source,
                            remedy="use observations from `physpose observe` or a keypoints "
                                   "file with world_landmarks")
    world = np.array(obs.world_landmarks, dtype=float)
    if cfg.ray_aligned_world:
        kp = np.asarray(obs.keypoints2d, dtype=float)
        weight = np.where(kp[..., 2] >= cfg.min_confidence, kp[..., 2], 0.0)
        world = np.einsum("tij,tkj->tki", hip_ray_frames(kp[..., :2], weight, K), world)
    t, ok = solve_root_translation(world, obs.keypoints2d, K, cfg)
    ok &= obs.valid
    if not ok.any():
        raise PhysposeError("no frame has enough confident landmarks to place the person",
                            path=obs.source, remedy="check the detections")
    frames = np.arange(obs.num_frames)
    good = np.flatnonzero(ok)
    for d in range(3):  # frames without evidence take interpolated translations and poses
        t[:, d] = np.interp(frames, good, t[good, d])
    nearest = good[np.clip(np.searchsorted(good, frames), 0, len(good) - 1)]
    world[~ok] = world[nearest[~ok]]
    return world + t[:, None, :]


def baseline(obs: Observations, context: VariantContext,
             cfg: BaselineConfig = BaselineConfig()) -> Reconstruction:
    """Score the detector itself: MediaPipe world landmarks placed by 2d re-projection."""
    start = time.perf_counter()
    K = next((k for k in (context.camera_K, obs.camera_K) if k is not None), None)
    K_source = "given" if K is not None else "guessed"
    K = guess_intrinsics(obs.image_size) if K is None else np.asarray(K, dtype=float)
    landmarks_cam = place_landmarks(obs, K, cfg)
    if context.camera_T_world2cam is not None:
        T_world2cam = np.asarray(context.camera_T_world2cam, dtype=float)
    else:
        T_world2cam = level_ground_frame(landmarks_cam, cfg.ground_percentile)
    T_cam2world = np.linalg.inv(T_world2cam)
    landmarks = landmarks_cam @ T_cam2world[:3, :3].T + T_cam2world[:3, 3]
    return Reconstruction(
        fps=obs.fps, joint_names=JOINT_NAMES, joints_kinematic=joints_from_landmarks(landmarks),
        camera_K=K, camera_T_world2cam=T_world2cam, landmarks_kinematic=landmarks,
        keypoints2d=np.asarray(obs.keypoints2d),
        meta={"variant": "baseline", "config": asdict(cfg), "camera_K": K_source,
              "timings_s": {"placement": time.perf_counter() - start}})


register_variant("baseline", baseline)
