"""The static pinhole camera of the fit and the world frame it places the person in.

The fit works in OpenCV camera axes (x right, y down, z forward). The output world frame
(../shared/DESIGN.md) follows from a ground plane {x : n . x + d = 0} given in camera axes,
n the unit up normal: world z = n (ground z = 0, so the camera is d above it), world x = the
camera's viewing direction projected onto the ground (so the camera looks along +x, and at
world yaw 0 the person seen from the front faces -x), y = z x x, and the origin on the ground
below the person's pelvis in the first frame with a detection.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from physpose.errors import PhysposeError
from physpose.metrics import camera_height
from physpose.pinhole import focal_from_fov, intrinsics  # noqa: F401 (the fit's camera)

UP_LEVEL = np.array([0.0, -1.0, 0.0])  # the up direction of a level camera, camera axes


SQUARE_PIXELS = 0.01  # fy / fx may differ from 1 by this much (calibrations: about 1e-4)


def check_intrinsics(K: np.ndarray, source: str) -> np.ndarray:
    """K as a float (3, 3) array; PhysposeError if it is not a plausible pinhole matrix."""
    K = np.asarray(K, dtype=float)
    if K.shape != (3, 3) or not np.isfinite(K).all() or K[0, 0] <= 0 or K[1, 1] <= 0 \
            or not np.allclose(K[2], [0.0, 0.0, 1.0]):
        raise PhysposeError(f"camera intrinsics {K.tolist()} are not a pinhole matrix",
                            path=source, remedy="give K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]")
    if abs(K[1, 1] / K[0, 0] - 1.0) > SQUARE_PIXELS:
        raise PhysposeError(f"camera intrinsics have fx = {K[0, 0]:g} and fy = {K[1, 1]:g} px: "
                            "physpose fits one focal length (square pixels), and would drop fy",
                            path=source, remedy="resample the video to square pixels (its height "
                            "scaled by fx / fy, cy with it) and give K with fy = fx")
    return K


def project(K, points):
    """Pixels of camera-frame points: (..., 3) -> (..., 2). Works on NumPy and JAX arrays."""
    z = points[..., 2:3]
    xp = jnp if isinstance(points, jnp.ndarray) else np
    z = xp.maximum(z, 1e-3)
    uv = points[..., :2] / z
    return uv * xp.stack([K[0, 0], K[1, 1]]) + xp.stack([K[0, 2], K[1, 2]])


def world_from_plane(normal: np.ndarray, offset: float, origin_cam: np.ndarray) -> np.ndarray:
    """(4, 4) T_world2cam of the world frame of a ground plane (see the module docstring).

    normal: (3,) up normal in camera axes; offset: d in n . x + d = 0 (the camera height, m);
    origin_cam: (3,) a camera-frame point whose ground projection becomes the world origin.
    """
    n = np.asarray(normal, dtype=float)
    n = n / np.linalg.norm(n)
    forward = np.array([0.0, 0.0, 1.0]) - n[2] * n
    if np.linalg.norm(forward) < 1e-6:  # camera looking straight down: use its image up
        forward = -np.array([0.0, 1.0, 0.0]) + n[1] * n
    x = forward / np.linalg.norm(forward)
    y = np.cross(n, x)
    R_cam2world = np.stack([x, y, n])          # rows: world axes in camera coordinates
    o = np.asarray(origin_cam, dtype=float)
    o = o - (n @ o + offset) * n               # the origin's foot point on the plane
    T_cam2world = np.eye(4)
    T_cam2world[:3, :3] = R_cam2world
    T_cam2world[:3, 3] = -R_cam2world @ o
    return np.linalg.inv(T_cam2world)


def plane_from_world(T_world2cam: np.ndarray) -> tuple[np.ndarray, float]:
    """(normal (3,), offset) in camera axes of the world's ground z = 0."""
    return T_world2cam[:3, :3] @ np.array([0.0, 0.0, 1.0]), camera_height(T_world2cam)
