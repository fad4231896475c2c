"""Pinhole intrinsics with square pixels and the principal point at the image centre, and the
frame of a viewing ray (NumPy only, so the observe stage and the detector simulator can use
them without loading JAX)."""

from __future__ import annotations

import numpy as np

from physpose.joints import LANDMARK_INDEX

DEFAULT_DIAGONAL_FOV_DEG = 55.0   # the field of view assumed where none is known


def focal_from_fov(image_size: tuple[int, int], diagonal_fov_deg: float) -> float:
    """Focal length (px) giving the field of view across the image diagonal."""
    half_diagonal = 0.5 * float(np.hypot(*image_size))
    return half_diagonal / float(np.tan(np.radians(diagonal_fov_deg) / 2))


def intrinsics(image_size: tuple[int, int], focal: float) -> np.ndarray:
    """(3, 3) K with square pixels and the principal point at the image centre."""
    width, height = image_size
    return np.array([[focal, 0.0, width / 2.0], [0.0, focal, height / 2.0], [0.0, 0.0, 1.0]])


def rays(K: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    """Unit viewing directions (camera axes) of pixels (..., 2) -> (..., 3)."""
    xy = (np.asarray(pixels, dtype=float) - K[:2, 2]) / np.diag(K)[:2]
    d = np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], axis=-1)
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def rotation_to(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotations taking unit vectors a (..., 3) to b (..., 3): (..., 3, 3)."""
    a, b = np.broadcast_arrays(np.asarray(a, float), np.asarray(b, float))
    v = np.cross(a, b)
    c = np.sum(a * b, axis=-1)[..., None, None]
    vx = np.zeros(v.shape[:-1] + (3, 3))
    vx[..., 0, 1], vx[..., 0, 2], vx[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    vx = vx - np.swapaxes(vx, -1, -2)
    return np.eye(3) + vx + vx @ vx / np.maximum(1.0 + c, 1e-9)


def ray_frame(direction: np.ndarray) -> np.ndarray:
    """(..., 3, 3) camera-from-ray rotations: the smallest rotation taking the optical axis to
    each unit viewing direction (..., 3). MediaPipe's world landmarks are in that frame for
    the ray through the hips (docs/mediapipe_error.md, Frame of the world landmarks)."""
    return rotation_to(np.array([0.0, 0.0, 1.0]), direction)


def hip_ray_frames(uv: np.ndarray, weight: np.ndarray, K: np.ndarray) -> np.ndarray:
    """(T, 3, 3) camera-from-ray rotations for the ray through the hips' weighted mean pixel
    (uv (T, 33, 2) MediaPipe landmarks, weight (T, 33)); where neither hip weighs anything,
    through all the landmarks' weighted mean; the identity where nothing does."""
    hips = [LANDMARK_INDEX["left_hip"], LANDMARK_INDEX["right_hip"]]
    uv, weight = np.asarray(uv, dtype=float), np.asarray(weight, dtype=float)
    hip_weight = weight[:, hips].sum(axis=1, keepdims=True)
    hip = (uv[:, hips] * weight[:, hips, None]).sum(1) / np.maximum(hip_weight, 1e-9)
    total = weight.sum(axis=1, keepdims=True)
    mean = (uv * weight[..., None]).sum(1) / np.maximum(total, 1e-9)
    R = ray_frame(rays(K, np.where(hip_weight > 0, hip, mean)))
    R[total[:, 0] <= 0] = np.eye(3)
    return R
