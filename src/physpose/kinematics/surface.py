"""Points on the body's surface, per segment, for the ground-plane terms (the paper's mesh M).

The points are sampled on the geoms of the simulated body (`physpose.body.build_body`), so the
ground the fit estimates is the one the simulated body stands on: a grid on each foot box's
sole, the corners of the hand boxes, and rings on every capsule.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from physpose.body import build_body, segment_masses
from physpose.shape import BodyShape
from physpose.skeleton import SEGMENT_NAMES

SOLE_GRID = (10, 5)   # sole points per foot: along the foot, across it
CAPSULE_RINGS = 3     # rings along each capsule's axis (ends included)
RING_POINTS = 6       # points per ring


@dataclass(frozen=True, eq=False)
class SurfacePoints:
    """Surface samples in their segments' frames.

    segment: (P,) int segment index (skeleton.SEGMENT_NAMES); offset: (P, 3) metres in that
    segment's frame; left_foot, right_foot: (P,) bool, the sole points of each foot.
    """

    segment: np.ndarray
    offset: np.ndarray
    left_foot: np.ndarray
    right_foot: np.ndarray

    @property
    def num_points(self) -> int:
        return int(self.segment.shape[0])

    @property
    def blocks(self) -> tuple[tuple[int, int, int], ...]:
        """(segment, start, stop) of the runs of points on one segment, in order."""
        return blocks_of(self.segment)


def blocks_of(segment: np.ndarray) -> tuple[tuple[int, int, int], ...]:
    """Runs (segment, start, stop) of equal values in a (P,) segment index array."""
    seg = np.asarray(segment)
    starts = np.flatnonzero(np.r_[True, seg[1:] != seg[:-1]])
    stops = np.r_[starts[1:], len(seg)]
    return tuple((int(seg[a]), int(a), int(b)) for a, b in zip(starts, stops))


def _box_points(half: np.ndarray, sole: bool) -> np.ndarray:
    if sole:
        u = np.linspace(-1.0, 1.0, SOLE_GRID[0]) * half[0]
        v = np.linspace(-1.0, 1.0, SOLE_GRID[1]) * half[1]
        uu, vv = np.meshgrid(u, v, indexing="ij")
        return np.stack([uu.ravel(), vv.ravel(), np.full(uu.size, -half[2])], axis=-1)
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    return corners * half


def _capsule_points(radius: float, half_length: float) -> np.ndarray:
    phi = np.linspace(0.0, 2 * np.pi, RING_POINTS, endpoint=False)
    ring = radius * np.stack([np.cos(phi), np.sin(phi), np.zeros_like(phi)], axis=-1)
    rings = [ring + [0.0, 0.0, z] for z in np.linspace(-half_length, half_length, CAPSULE_RINGS)]
    poles = np.array([[0.0, 0.0, -half_length - radius], [0.0, 0.0, half_length + radius]])
    return np.concatenate(rings + [poles])


def surface_points(shape: BodyShape) -> SurfacePoints:
    """Sample the surface of the body built from `shape` (geoms in segment frames)."""
    model = build_body(shape).model
    segments, offsets, left, right = [], [], [], []
    for g in range(model.ngeom):
        body = int(model.geom_bodyid[g])
        if body == 0:
            continue  # scene geoms
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g) or ""
        size = model.geom_size[g]
        if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX:
            local = _box_points(size, sole=name.endswith("_foot"))
        elif model.geom_type[g] == mujoco.mjtGeom.mjGEOM_CAPSULE:
            local = _capsule_points(size[0], size[1])
        else:
            continue
        rot = np.zeros(9)
        mujoco.mju_quat2Mat(rot, model.geom_quat[g])
        points = model.geom_pos[g] + local @ rot.reshape(3, 3).T
        segments.append(np.full(len(points), body - 1))  # body ids follow the segments
        offsets.append(points)
        left.append(np.full(len(points), name == "l_foot"))
        right.append(np.full(len(points), name == "r_foot"))
    return SurfacePoints(segment=np.concatenate(segments), offset=np.concatenate(offsets),
                         left_foot=np.concatenate(left), right_foot=np.concatenate(right))


def place(points: SurfacePoints, seg_pos, seg_rot, xp=np):
    """World positions (..., P, 3) of the points given segment frames from fk.segment_frames:
    positions (..., 17, 3) and rotations (..., 17, 3, 3). One product per run of points on a
    segment (no gathers: the gradient stays cheap)."""
    off = xp.asarray(points.offset)
    return xp.concatenate([seg_pos[..., s, None, :] + xp.einsum("...ij,pj->...pi",
                                                                seg_rot[..., s, :, :], off[a:b])
                           for s, a, b in points.blocks], axis=-2)


def centre_of_mass(shape: BodyShape, points: SurfacePoints, posed: np.ndarray) -> np.ndarray:
    """Approximate centres of mass (T, 3) of posed surface points (T, P, 3): each segment's
    mass (body.segment_masses) at the centroid of its points."""
    masses = segment_masses(shape)
    total = np.zeros(posed.shape[:-2] + (3,))
    weight = 0.0
    for s, name in enumerate(SEGMENT_NAMES):
        on = points.segment == s
        if on.any():
            total += masses[name] * posed[..., on, :].mean(axis=-2)
            weight += masses[name]
    return total / weight
