"""Pinhole intrinsics with square pixels and the principal point at the image centre (NumPy
only, so the observe stage can use them without loading JAX)."""

from __future__ import annotations

import numpy as np

DEFAULT_DIAGONAL_FOV_DEG = 55.0   # the field of view assumed where none is known


def focal_from_fov(image_size: tuple[int, int], diagonal_fov_deg: float) -> float:
    """Focal length (px) giving the field of view across the image diagonal."""
    half_diagonal = 0.5 * float(np.hypot(*image_size))
    return half_diagonal / float(np.tan(np.radians(diagonal_fov_deg) / 2))


def intrinsics(image_size: tuple[int, int], focal: float) -> np.ndarray:
    """(3, 3) K with square pixels and the principal point at the image centre."""
    width, height = image_size
    return np.array([[focal, 0.0, width / 2.0], [0.0, focal, height / 2.0], [0.0, 0.0, 1.0]])
