"""Quaternion helpers (w, x, y, z), vectorised over leading dimensions."""

from __future__ import annotations

import numpy as np

_CONJ = np.array([1.0, -1.0, -1.0, -1.0])


def multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a b of quaternions (..., 4)."""
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack([aw * bw - ax * bx - ay * by - az * bz,
                     aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw], axis=-1)


def conjugate(q: np.ndarray) -> np.ndarray:
    """The inverse rotation of unit quaternions (..., 4)."""
    return q * _CONJ


def about_axis(angle: np.ndarray, axis: int) -> np.ndarray:
    """Rotations by angle (...) rad about coordinate axis 0, 1 or 2: (..., 4)."""
    q = np.zeros(np.shape(angle) + (4,))
    q[..., 0] = np.cos(0.5 * angle)
    q[..., 1 + axis] = np.sin(0.5 * angle)
    return q


def normalised(q: np.ndarray) -> np.ndarray:
    """Quaternions (..., 4) scaled to unit length (a zero one stays zero)."""
    return q / np.maximum(np.linalg.norm(q, axis=-1, keepdims=True), 1e-12)


def half_angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """arccos |<a, b>| (rad, half the angle between the rotations), computed as
    atan2(|v|, |w|) of (w, v) = a* b, which keeps its precision near zero."""
    rel = multiply(conjugate(a), b)
    return np.arctan2(np.linalg.norm(rel[..., 1:], axis=-1), np.abs(rel[..., 0]))
