"""Batched rotation matrices for the motion-capture readers (Euler angles, quaternions)."""

from __future__ import annotations

import numpy as np


def axis_rotation(axis: str, angle: np.ndarray) -> np.ndarray:
    """Rotation about a principal axis ('x', 'y' or 'z'). angle: (...,) rad -> (..., 3, 3)."""
    angle = np.asarray(angle, dtype=float)
    c, s = np.cos(angle), np.sin(angle)
    one, zero = np.ones_like(angle), np.zeros_like(angle)
    rows = {
        "x": ((one, zero, zero), (zero, c, -s), (zero, s, c)),
        "y": ((c, zero, s), (zero, one, zero), (-s, zero, c)),
        "z": ((c, -s, zero), (s, c, zero), (zero, zero, one)),
    }[axis.lower()]
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def euler_matrix(angles: np.ndarray, order: str) -> np.ndarray:
    """Product R_order[0](a0) @ R_order[1](a1) @ ... of axis rotations.

    angles: (..., len(order)) rad; order: axis letters, e.g. "zyx" (BVH channel order).
    Returns (..., 3, 3).
    """
    angles = np.asarray(angles, dtype=float)
    out = np.broadcast_to(np.eye(3), angles.shape[:-1] + (3, 3)).copy()
    for i, axis in enumerate(order):
        out = out @ axis_rotation(axis, angles[..., i])
    return out


def quat_matrix(quat_wxyz: np.ndarray) -> np.ndarray:
    """Rotation matrices of (not necessarily unit) quaternions.

    quat_wxyz: (..., 4) w, x, y, z -> (..., 3, 3).
    """
    q = np.asarray(quat_wxyz, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):  # a zero quaternion: NaN, which the
        q = q / np.linalg.norm(q, axis=-1, keepdims=True)  # loaders report with its frame
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def orthonormalize(mats: np.ndarray) -> np.ndarray:
    """Nearest rotation matrices (SVD projection). mats: (..., 3, 3) -> (..., 3, 3)."""
    u, _, vt = np.linalg.svd(mats)
    d = np.sign(np.linalg.det(u @ vt))
    u = u.copy()
    u[..., :, -1] *= d[..., None]
    return u @ vt


def frame_from_axes(primary: np.ndarray, secondary: np.ndarray) -> np.ndarray:
    """Rotation with first column `primary`, second in the (primary, secondary) plane.

    primary, secondary: (..., 3) -> (..., 3, 3) with columns (x, y, z = x cross y).
    """
    x = primary / np.linalg.norm(primary, axis=-1, keepdims=True)
    y = secondary - np.sum(secondary * x, axis=-1, keepdims=True) * x
    y = y / np.linalg.norm(y, axis=-1, keepdims=True)
    return np.stack([x, y, np.cross(x, y)], axis=-1)
