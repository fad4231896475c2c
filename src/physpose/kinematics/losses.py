"""The terms of the kinematic objective, each a named function of (posed body, data) -> scalar.

A stage's objective is sum(weights[name] * TERMS[name](...)) (see `objective`). All terms are
means over frames of per-frame sums, so weights do not depend on the clip length. Residuals are
standardised (divided by their sigma) and, where outliers occur, passed through a Geman-McClure
function rho(x^2) = x^2 / (1 + x^2 / c^2), quadratic near zero and saturating at c^2.

Shapes: T frames, 33 landmarks, P surface points. Positions are camera axes, metres.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from physpose.fk import fk, segment_frames
from physpose.kinematics.surface import SurfacePoints, place
from physpose.skeleton import AXES, DOF_LIMITS, NUM_DOF, SEGMENTS

_HIPS = (23, 24)  # left_hip, right_hip in MediaPipe order

# Pose prior: sigma (rad) of each hinge about the rest pose, per joint kind and axis (y, x, z).
# Flexion axes are free, secondary axes and axial twists (barely observable) held closer.
_PRIOR_SIGMA_BY_JOINT = {
    "hip": (1.0, 0.35, 0.3), "knee": (1.2, 0.05, 0.15), "ankle": (0.4, 0.25, 0.25),
    "spine": (0.3, 0.2, 0.2), "thorax": (0.3, 0.2, 0.25), "neck": (0.35, 0.25, 0.4),
    "head": (0.35, 0.25, 0.4), "shoulder": (1.2, 1.0, 0.6), "elbow": (1.2, 0.05, 0.7),
    "wrist": (0.3, 0.5, 0.1),
}
PRIOR_SIGMA: np.ndarray = np.array([_PRIOR_SIGMA_BY_JOINT[s.name.split("_")[-1]][k]
                                    for s in SEGMENTS[1:] for k in range(len(AXES))])
assert PRIOR_SIGMA.shape == (NUM_DOF,)


class Pose(NamedTuple):
    """A posed body over T frames (camera axes)."""

    landmarks: jax.Array      # (T, 33, 3)
    seg_pos: jax.Array        # (T, 17, 3)
    seg_rot: jax.Array        # (T, 17, 3, 3)
    root_rot: jax.Array       # (T, 3, 3)
    angles: jax.Array         # (T, 48)


class Data(NamedTuple):
    """What the terms compare the pose with (arrays; fixed during one optimisation)."""

    uv: jax.Array             # (T, 33, 2) detections, px
    w2d: jax.Array            # (T, 33) confidence weights (0: ignore)
    m_per_px: jax.Array       # (T,) metres per pixel at the person's depth
    world: jax.Array          # (T, 33, 3) MediaPipe landmarks in the ray frame, hip-centred
    w3d: jax.Array            # (T, 33)
    R_ray: jax.Array          # (T, 3, 3) camera from ray frame (z along the ray to the hips)
    frame_weight: jax.Array   # (T,) 1 for real frames, 0 for padding
    plane: jax.Array          # (4,) ground n (3) and d: n . x + d = 0
    fps: jax.Array            # () Hz
    support: jax.Array        # (T,) m above the plane where the feet stand (0: the floor;
                              # a raised support's top, supports.support_heights)


def rotvec_matrix(v):
    """Rodrigues: rotation vectors (..., 3) -> (..., 3, 3), smooth at 0."""
    theta2 = jnp.sum(v * v, axis=-1)[..., None, None]
    small = theta2 < 1e-8
    theta2s = jnp.where(small, 1.0, theta2)
    theta = jnp.sqrt(theta2s)
    a = jnp.where(small, 1.0 - theta2 / 6.0, jnp.sin(theta) / theta)
    b = jnp.where(small, 0.5 - theta2 / 24.0, (1.0 - jnp.cos(theta)) / theta2s)
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    zero = jnp.zeros_like(x)
    k = jnp.stack([jnp.stack([zero, -z, y], -1), jnp.stack([z, zero, -x], -1),
                   jnp.stack([-y, x, zero], -1)], -2)
    return jnp.eye(3) + a * k + b * (k @ k)


def pose_body(bones, root_pos, root_rot, angles) -> Pose:
    """Forward kinematics of T frames: root_pos (T, 3), root_rot (T, 3, 3), angles (T, 48)."""
    pos, rot = segment_frames(bones, root_pos, root_rot, angles)
    _, landmarks = fk(bones, root_pos, root_rot, angles)  # XLA shares the segment frames
    return Pose(landmarks, pos, rot, root_rot, angles)


def _gm(x2, c):
    return x2 / (1.0 + x2 / (c * c))


def _frame_mean(per_frame, data: Data):
    return jnp.sum(per_frame * data.frame_weight) / jnp.maximum(jnp.sum(data.frame_weight), 1.0)


def cost_reprojection(pose: Pose, data: Data, K, sigma, c):
    """Robust 2d error of the 33 landmarks, in metres at the person's depth / sigma."""
    z = jnp.maximum(pose.landmarks[..., 2:3], 1e-2)
    uv = pose.landmarks[..., :2] / z * jnp.stack([K[0, 0], K[1, 1]]) + K[:2, 2]
    r = (uv - data.uv) * data.m_per_px[:, None, None] / sigma
    return _frame_mean(jnp.sum(data.w2d * _gm(jnp.sum(r * r, -1), c), -1), data)


def cost_world_landmarks(pose: Pose, data: Data, depth_scale, sigma, depth_ratio, c):
    """Robust error against MediaPipe's hip-centred landmarks, compared in the ray frame with
    MediaPipe's depth scaled by depth_scale and weighted 1/depth_ratio."""
    lm = pose.landmarks
    rel = lm - 0.5 * (lm[:, _HIPS[0]] + lm[:, _HIPS[1]])[:, None]
    rel_ray = jnp.einsum("tji,tpj->tpi", data.R_ray, rel)
    target = data.world * jnp.stack([1.0, 1.0, depth_scale])
    r = (rel_ray - target) / (sigma * jnp.array([1.0, 1.0, depth_ratio]))
    return _frame_mean(jnp.sum(data.w3d * _gm(jnp.sum(r * r, -1), c), -1), data)


def cost_pose_prior(pose: Pose, data: Data):
    """Gaussian prior on the hinge angles about the rest pose (PRIOR_SIGMA)."""
    return _frame_mean(jnp.sum((pose.angles / PRIOR_SIGMA) ** 2, -1), data)


def cost_joint_limits(pose: Pose, data: Data):
    """Squared excess (rad^2) beyond skeleton.DOF_LIMITS."""
    lo, hi = DOF_LIMITS[:, 0], DOF_LIMITS[:, 1]
    over = jnp.maximum(pose.angles - hi, 0.0) + jnp.maximum(lo - pose.angles, 0.0)
    return _frame_mean(jnp.sum(over ** 2, -1), data)


def _pair_weight(data: Data, lag: int):
    w = data.frame_weight
    out = w[lag:]
    for k in range(1, lag + 1):
        out = out * w[lag - k:len(w) - k]
    return out


def _pair_mean(per_pair, weight):
    return jnp.sum(per_pair * weight) / jnp.maximum(jnp.sum(weight), 1.0)


def cost_temporal_velocity(pose: Pose, data: Data, sigma):
    """(+T) Landmark velocities between consecutive frames (m/s / sigma), squared."""
    v = jnp.diff(pose.landmarks, axis=0) * data.fps / sigma
    return _pair_mean(jnp.sum(v * v, axis=(-1, -2)), _pair_weight(data, 1))


def cost_temporal_acceleration(pose: Pose, data: Data, sigma):
    """(+T) Landmark accelerations (m/s^2 / sigma), squared."""
    lm = pose.landmarks
    a = (lm[2:] - 2 * lm[1:-1] + lm[:-2]) * data.fps ** 2 / sigma
    return _pair_mean(jnp.sum(a * a, axis=(-1, -2)), _pair_weight(data, 2))


def cost_temporal_angles(pose: Pose, data: Data, sigma):
    """(+T) Hinge and root-orientation accelerations (rad/s^2 / sigma), squared (the root's
    from its rotation matrix, whose entries change like angles for small rotations)."""
    a, r = pose.angles, pose.root_rot
    da = a[2:] - 2 * a[1:-1] + a[:-2]
    dr = r[2:] - 2 * r[1:-1] + r[:-2]
    per = jnp.sum(da * da, -1) + 0.5 * jnp.sum(dr * dr, axis=(-1, -2))
    return _pair_mean(per * (data.fps ** 2 / sigma) ** 2, _pair_weight(data, 2))


def lowest(distances, k):
    """The k smallest values along the last axis: (..., P) -> (..., k)."""
    return -jax.lax.top_k(-distances, k)[0]


def ground_term(distances, k, delta):
    """The paper's per-frame ||min(delta, L_k(D))||_2 for signed distances (T, P) -> (T,)."""
    low = jnp.minimum(lowest(distances, k), delta)
    return jnp.sqrt(jnp.sum(low * low, -1) + 1e-8)


def signed_distances(surface: SurfacePoints, pose: Pose, plane, support=0.0):
    """Signed distances (T, P) of the surface points to the plane n . x + d = 0, raised by
    each frame's support height (T,) where there is one."""
    pts = place(surface, pose.seg_pos, pose.seg_rot, jnp)
    return pts @ plane[:3] + plane[3] - jnp.reshape(support, (-1, 1))


def cost_ground(pose: Pose, data: Data, surface: SurfacePoints, k, delta, foot_delta,
                body_weight, scale):
    """(+G) L_gp with the plane fixed, per `scale` metres: each foot's k lowest points (clipped
    at foot_delta) and body_weight x the whole body's (clipped at delta)."""
    dist = signed_distances(surface, pose, data.plane, data.support)
    per = body_weight * ground_term(dist, k, delta)
    for mask in (surface.left_foot, surface.right_foot):
        per = per + ground_term(dist[:, np.flatnonzero(mask)], k, foot_delta)
    return _frame_mean(per, data) / scale


def cost_ground_skate(pose: Pose, data: Data, surface: SurfacePoints, height_scale, sigma):
    """(+GT) Sliding of soles on the ground: horizontal velocities (m/s / sigma) of the sole
    points, each weighted by exp(-height / height_scale) (about 1 in contact, the weight itself
    not differentiated: the term must not lift feet to escape), mean over sole points. Heights
    are above each frame's support (data.support) where there is one."""
    soles = np.flatnonzero(surface.left_foot | surface.right_foot)
    pts = place(surface, pose.seg_pos, pose.seg_rot, jnp)[:, soles]
    n = data.plane[:3]
    h = jnp.maximum(pts @ n + data.plane[3] - data.support[:, None], 0.0)
    w = jax.lax.stop_gradient(jnp.exp(-0.5 * (h[1:] + h[:-1]) / height_scale))
    v = jnp.diff(pts, axis=0) * data.fps
    vh = v - (v @ n)[..., None] * n
    per = jnp.mean(w * jnp.sum(vh * vh, -1), -1) / sigma ** 2
    return _pair_mean(per, _pair_weight(data, 1))
