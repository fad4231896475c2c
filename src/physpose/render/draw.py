"""Drawing 3d things into images with OpenCV: pinhole projection, solids, skeletons, ground grid.

Cameras are (K (3, 3), T_world2cam (4, 4)) in OpenCV axes (x right, y down, z forward); every
point is in the world frame (z up, metres). Nothing here needs OpenGL.
"""

from __future__ import annotations

import cv2
import numpy as np

from physpose.render.bodymotion import GeomShape, quat_to_mat

NEAR = 0.05  # m: points closer to the camera plane than this are not drawn
_SUBPIXEL = 4  # bits of fixed-point precision for cv2 drawing
_SHIFT = 1 << _SUBPIXEL


def look_at(eye: np.ndarray, target: np.ndarray) -> np.ndarray:
    """T_world2cam (4, 4) of a camera at eye looking at target, image up = world +z."""
    forward = np.asarray(target, float) - np.asarray(eye, float)
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    r_world2cam = np.stack([right, down, forward])
    t = np.eye(4)
    t[:3, :3] = r_world2cam
    t[:3, 3] = -r_world2cam @ np.asarray(eye, float)
    return t


def to_camera(t_world2cam: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(..., 3) world points -> (..., 3) camera-frame points."""
    return points @ t_world2cam[:3, :3].T + t_world2cam[:3, 3]


def project(k: np.ndarray, t_world2cam: np.ndarray, points: np.ndarray) -> tuple[np.ndarray,
                                                                                 np.ndarray]:
    """Pixels (..., 2) of world points (..., 3) and a mask (...,) of points in front of the camera."""
    cam = to_camera(t_world2cam, points)
    z = cam[..., 2]
    safe = np.where(z > NEAR, z, 1.0)[..., None]
    px = (cam[..., :2] / safe) * np.diag(k)[:2] + k[:2, 2]
    return px, z > NEAR


def _fixed(px: np.ndarray) -> np.ndarray:
    return np.round(np.asarray(px) * _SHIFT).astype(np.int32)


def geom_samples(g: GeomShape) -> np.ndarray:
    """(K, 3) surface points of a geom in its own frame whose projected hull is its outline."""
    lat, lon = np.meshgrid(np.linspace(-np.pi / 2, np.pi / 2, 7), np.linspace(0, 2 * np.pi, 12,
                                                                               endpoint=False))
    sphere = np.stack([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)],
                      axis=-1).reshape(-1, 3)
    r, h, z = g.size
    if g.kind == "box":
        return np.array([(sx * r, sy * h, sz * z) for sx in (-1, 1) for sy in (-1, 1)
                         for sz in (-1, 1)], dtype=float)
    if g.kind == "capsule":
        return np.concatenate([sphere * r + [0, 0, h], sphere * r - [0, 0, h]])
    if g.kind == "cylinder":
        ring = np.stack([np.cos(lon[:, 0]), np.sin(lon[:, 0]), np.zeros(12)], axis=-1) * r
        return np.concatenate([ring + [0, 0, h], ring - [0, 0, h]])
    if g.kind == "ellipsoid":
        return sphere * np.array([r, h, z])
    return sphere * r


def draw_solids(image: np.ndarray, k: np.ndarray, t_world2cam: np.ndarray,
                samples: list[np.ndarray], centers: np.ndarray, quats: np.ndarray,
                color: tuple[int, int, int], alpha: float = 0.45) -> None:
    """Fill the outlines of convex solids, far to near, blended with alpha, outlined in colour.

    samples: per solid (K_i, 3) local surface points; centers (G, 3); quats (G, 4) world poses.
    """
    rot = quat_to_mat(quats)
    depth = to_camera(t_world2cam, centers)[:, 2]
    layer = image.copy() if alpha > 0 else image
    outlines = []
    for g in np.argsort(-depth):
        world = samples[g] @ rot[g].T + centers[g]
        px, front = project(k, t_world2cam, world)
        if not front.all():
            continue
        hull = cv2.convexHull(_fixed(px).reshape(-1, 1, 2))
        shade = 0.75 + 0.25 * (g % 2)
        if alpha > 0:
            cv2.fillConvexPoly(layer, hull, tuple(int(c * shade) for c in color), cv2.LINE_AA,
                               _SUBPIXEL)
        outlines.append(hull)
    if alpha > 0:
        cv2.addWeighted(layer, alpha, image, 1 - alpha, 0, dst=image)
    cv2.polylines(image, outlines, True, color, 1, cv2.LINE_AA, _SUBPIXEL)


def draw_skeleton(image: np.ndarray, k: np.ndarray, t_world2cam: np.ndarray, joints: np.ndarray,
                  edges: np.ndarray, color: tuple[int, int, int], thickness: int = 2) -> None:
    """Bones (E pairs of indices into joints (J, 3)) and joint dots."""
    px, front = project(k, t_world2cam, joints)
    fx = _fixed(px)
    for a, b in edges:
        if front[a] and front[b]:
            cv2.line(image, tuple(fx[a]), tuple(fx[b]), color, thickness, cv2.LINE_AA, _SUBPIXEL)
    for j in np.flatnonzero(front):
        cv2.circle(image, tuple(fx[j]), (thickness + 1) * _SHIFT, color, -1, cv2.LINE_AA,
                   _SUBPIXEL)


def clip_segment(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Clip a camera-frame segment to z >= NEAR; None when it lies wholly behind."""
    if a[2] < NEAR and b[2] < NEAR:
        return None
    if a[2] < NEAR or b[2] < NEAR:
        s = (NEAR - a[2]) / (b[2] - a[2])
        cut = a + s * (b - a)
        a, b = (cut, b) if a[2] < NEAR else (a, cut)
    return a, b


def draw_grid(image: np.ndarray, k: np.ndarray, t_world2cam: np.ndarray, center: np.ndarray,
              extent: float, step: float, color: tuple[int, int, int]) -> None:
    """Lines of the ground plane z = 0 every `step` m within `extent` m of center (2,)."""
    lo = np.floor((np.asarray(center) - extent) / step) * step
    ticks = [lo + i * step for i in range(int(np.ceil(2 * extent / step)) + 1)]
    for axis in range(2):
        for v in ticks:
            a = np.zeros(3)
            b = np.zeros(3)
            a[axis] = b[axis] = v[axis]
            a[1 - axis], b[1 - axis] = lo[1 - axis], ticks[-1][1 - axis]
            seg = clip_segment(to_camera(t_world2cam, a), to_camera(t_world2cam, b))
            if seg is None:
                continue
            pa, pb = ((p[:2] / p[2]) * np.diag(k)[:2] + k[:2, 2] for p in seg)
            cv2.line(image, tuple(_fixed(pa)), tuple(_fixed(pb)), color, 1, cv2.LINE_AA,
                     _SUBPIXEL)


def draw_ground_disc(image: np.ndarray, k: np.ndarray, t_world2cam: np.ndarray,
                     center_xy: np.ndarray, radius: float, color: tuple[int, int, int]) -> None:
    """A filled disc on the ground (a foot contact marker)."""
    phi = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    ring = np.stack([center_xy[0] + radius * np.cos(phi), center_xy[1] + radius * np.sin(phi),
                     np.zeros_like(phi)], axis=-1)
    px, front = project(k, t_world2cam, ring)
    if front.all():
        cv2.fillPoly(image, [_fixed(px).reshape(-1, 1, 2)], color, cv2.LINE_AA, _SUBPIXEL)
