"""Triangle meshes of MuJoCo's primitive geoms (sizes as MuJoCo gives them), for the glTF export.

Round solids are lathed from a profile around the z axis, which is each geom's main axis in
MuJoCo; boxes are built face by face so their normals stay flat.
"""

from __future__ import annotations

import numpy as np

from physpose.render.bodymotion import GeomShape

_SEGMENTS = 16  # vertices around the z axis
_RINGS = 6      # latitude rings per hemisphere


def geom_mesh(geom: GeomShape) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mesh of one geom in its own frame: vertices (V, 3) m, unit normals (V, 3), faces (F, 3)."""
    r, h, z = geom.size
    if geom.kind == "box":
        return box_mesh(np.array(geom.size))
    if geom.kind == "capsule":
        return lathe(_capsule_profile(r, h))
    if geom.kind == "sphere":
        return lathe(_capsule_profile(r, 0.0))
    if geom.kind == "ellipsoid":
        v, n, f = lathe(_capsule_profile(1.0, 0.0))
        n = n / np.array([r, h, z])
        return v * np.array([r, h, z]), n / np.linalg.norm(n, axis=1, keepdims=True), f
    if geom.kind == "cylinder":
        return lathe(_cylinder_profile(r, h))
    raise ValueError(f"no mesh for geom kind {geom.kind!r}")


def _capsule_profile(radius: float, half_length: float) -> np.ndarray:
    """(P, 4) profile rows (radius, z, normal_r, normal_z) from the bottom pole to the top."""
    rows = []
    for sign in (-1.0, 1.0):
        lat = np.linspace(-np.pi / 2, 0, _RINGS + 1) if sign < 0 else np.linspace(0, np.pi / 2,
                                                                                  _RINGS + 1)
        for a in lat:
            rows.append((radius * np.cos(a), sign * half_length + radius * np.sin(a),
                         np.cos(a), np.sin(a)))
    return np.array(rows)


def _cylinder_profile(radius: float, half_length: float) -> np.ndarray:
    return np.array([(0, -half_length, 0, -1), (radius, -half_length, 0, -1),
                     (radius, -half_length, 1, 0), (radius, half_length, 1, 0),
                     (radius, half_length, 0, 1), (0, half_length, 0, 1)], dtype=float)


def lathe(profile: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Revolve a (P, 4) profile (radius, z, normal_r, normal_z) around z into a closed mesh."""
    phi = np.linspace(0, 2 * np.pi, _SEGMENTS, endpoint=False)
    c, s = np.cos(phi)[None, :], np.sin(phi)[None, :]
    rad, z, nr, nz = (profile[:, k:k + 1] for k in range(4))
    p, n = len(profile), _SEGMENTS
    verts = np.stack([rad * c, rad * s, np.broadcast_to(z, (p, n))], axis=-1)
    norms = np.stack([nr * c, nr * s, np.broadcast_to(nz, (p, n))], axis=-1)
    faces = []
    for i in range(p - 1):
        for j in range(n):
            a, b = i * n + j, i * n + (j + 1) % n
            faces += [(a, b, b + n), (a, b + n, a + n)]
    faces = np.array(faces, dtype=np.int64)
    verts, norms = verts.reshape(-1, 3), norms.reshape(-1, 3)
    # Drop triangles collapsed at the poles (both base vertices on the axis).
    area = np.linalg.norm(np.cross(verts[faces[:, 1]] - verts[faces[:, 0]],
                                   verts[faces[:, 2]] - verts[faces[:, 0]]), axis=1)
    return verts, norms, faces[area > 1e-12]


def box_mesh(half: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A box with half-extents (3,): 24 vertices (flat normals), 12 triangles."""
    verts, norms, faces = [], [], []
    for axis in range(3):
        u, v = (axis + 1) % 3, (axis + 2) % 3
        for sign in (-1.0, 1.0):
            normal = np.zeros(3)
            normal[axis] = sign
            base = len(verts)
            for du, dv in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                p = np.zeros(3)
                p[axis], p[u], p[v] = sign * half[axis], du * half[u], dv * half[v]
                verts.append(p)
                norms.append(normal)
            quad = [(0, 1, 2), (0, 2, 3)] if sign > 0 else [(0, 2, 1), (0, 3, 2)]
            faces += [(base + a, base + b, base + c) for a, b, c in quad]
    return np.array(verts), np.array(norms), np.array(faces, dtype=np.int64)


def plane_mesh(center: np.ndarray, half: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A square in the ground plane z = 0 around center (2,), facing +z."""
    cx, cy = center
    verts = np.array([(cx - half, cy - half, 0), (cx + half, cy - half, 0),
                      (cx + half, cy + half, 0), (cx - half, cy + half, 0)], dtype=float)
    norms = np.tile([0.0, 0.0, 1.0], (4, 1))
    return verts, norms, np.array([(0, 1, 2), (0, 2, 3)], dtype=np.int64)
