"""The kinematic objective over all frames: parameters, fixed inputs and the weighted terms.

One jitted function serves every stage (shape fit on the seed frames, inverse kinematics, root
placement, +O, +G, +T): which parameters are free is the optimiser's choice and which terms
count is the weights' (traced, so changing them does not recompile). Only the clip length (kept
to a few padded sizes) and `Settings` trigger a compilation.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from physpose.kinematics import losses
from physpose.kinematics.losses import Data, Pose
from physpose.kinematics.surface import SurfacePoints
from physpose.shape import HEAD_TOP_PER_EAR_WIDTH, BodyShape
from physpose.skeleton import BONE_INDEX, NUM_BONES

TERMS: tuple[str, ...] = (
    "reprojection", "world_landmarks", "pose_prior", "joint_limits", "temporal_velocity",
    "temporal_acceleration", "temporal_angles", "ground", "ground_skate", "depth_scale_prior",
    "bone_prior",
    "focal_prior")
# Stature = this vector . bones (shape.stature_from_bones, linear in the bones).
_STATURE = np.zeros(NUM_BONES)
for _name in ("ankle_height", "shank", "thigh", "trunk", "neck"):
    _STATURE[BONE_INDEX[_name]] = 1.0
_STATURE[BONE_INDEX["ear_width"]] = HEAD_TOP_PER_EAR_WIDTH
# Bone lengths per metre of stature of the average adult (shape.py's proportions).
BONE_PROPORTIONS: np.ndarray = BodyShape.from_height(1.0).bones()


class Params(NamedTuple):
    """Everything the fit can move. T frames; scalars are 0-d arrays."""

    root_pos: np.ndarray         # (T, 3) pelvis position, camera axes, m
    root_rotvec: np.ndarray      # (T, 3) pelvis rotation relative to Fixed.R0 (rotation vector)
    angles: np.ndarray           # (T, 48) hinge angles, rad
    log_bones: np.ndarray        # (13,) log bone lengths (before the height constraint)
    log_depth_scale: np.ndarray  # () log of MediaPipe's depth compression factor
    log_world_scale: np.ndarray  # () log of MediaPipe's metric scale relative to the body's
    log_focal: np.ndarray        # () log focal length, px


class Fixed(NamedTuple):
    """Inputs the parameters are measured against besides the observations (Data)."""

    R0: np.ndarray               # (T, 3, 3) reference root orientations
    principal: np.ndarray        # (2,) principal point, px
    surface_offset: np.ndarray   # (P, 3) surface points in their segments' frames
    height: np.ndarray           # () the person's stature (m) when known, else 0
    log_focal_prior: np.ndarray  # () prior mean of log focal


@dataclass(frozen=True)
class Settings:
    """Static constants of the terms (hashable: a change recompiles)."""

    sigma_2d: float
    sigma_3d: float
    depth_ratio: float
    robust_c: float
    sigma_velocity: float
    sigma_acceleration: float
    sigma_angle_acceleration: float
    k: int
    delta: float
    foot_delta: float
    body_weight: float
    ground_scale: float
    contact_height: float
    sigma_skate: float
    bone_log_sigma: float
    depth_log_centre: float
    depth_log_sigma: float
    focal_log_sigma: float
    surface_blocks: tuple[tuple[int, int, int], ...]  # SurfacePoints.blocks
    left_foot: tuple[int, ...]    # indices of the left sole points
    right_foot: tuple[int, ...]
    ground_on: bool = False       # compute the ground term (else it is 0)

    def surface(self, offset) -> SurfacePoints:
        """SurfacePoints with this layout and the given (P, 3) offsets (array or tracer)."""
        segment = np.concatenate([np.full(b - a, s) for s, a, b in self.surface_blocks])
        left, right = np.zeros(len(segment), bool), np.zeros(len(segment), bool)
        left[list(self.left_foot)] = True
        right[list(self.right_foot)] = True
        return SurfacePoints(segment=segment, offset=offset, left_foot=left, right_foot=right)


def bones_of(params: Params, fixed: Fixed):
    """Bone lengths (13,): exp(log_bones), rescaled to the known stature when there is one."""
    b = jnp.exp(params.log_bones)
    scale = jnp.where(fixed.height > 0, fixed.height / (b @ _STATURE), 1.0)
    return b * scale


def camera_K(params: Params, fixed: Fixed):
    f = jnp.exp(params.log_focal)
    return jnp.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]]) * f + jnp.array(
        [[0.0, 0.0, fixed.principal[0]], [0.0, 0.0, fixed.principal[1]], [0.0, 0.0, 1.0]])


def posed(params: Params, fixed: Fixed) -> Pose:
    root_rot = fixed.R0 @ losses.rotvec_matrix(params.root_rotvec)
    return losses.pose_body(bones_of(params, fixed), params.root_pos, root_rot, params.angles)


def terms(params: Params, fixed: Fixed, data: Data, s: Settings) -> dict[str, jax.Array]:
    """Every term's value (unweighted)."""
    pose = posed(params, fixed)
    K = camera_K(params, fixed)
    log_b = jnp.log(bones_of(params, fixed))
    log_prop = jnp.log(BONE_PROPORTIONS * (jnp.exp(log_b) @ _STATURE))
    world = data._replace(world=data.world * jnp.exp(params.log_world_scale))
    return {
        "reprojection": losses.cost_reprojection(pose, data, K, s.sigma_2d, s.robust_c),
        "world_landmarks": losses.cost_world_landmarks(
            pose, world, jnp.exp(params.log_depth_scale), s.sigma_3d, s.depth_ratio,
            s.robust_c),
        "pose_prior": losses.cost_pose_prior(pose, data),
        "joint_limits": losses.cost_joint_limits(pose, data),
        "temporal_velocity": losses.cost_temporal_velocity(pose, data, s.sigma_velocity),
        "temporal_acceleration": losses.cost_temporal_acceleration(pose, data,
                                                                   s.sigma_acceleration),
        "temporal_angles": losses.cost_temporal_angles(pose, data, s.sigma_angle_acceleration),
        "ground": losses.cost_ground(pose, data, s.surface(fixed.surface_offset), s.k, s.delta,
                                     s.foot_delta, s.body_weight, s.ground_scale) if s.ground_on else 0.0,
        "ground_skate": losses.cost_ground_skate(
            pose, data, s.surface(fixed.surface_offset), s.contact_height, s.sigma_skate)
        if s.ground_on else 0.0,
        "depth_scale_prior": ((params.log_depth_scale - s.depth_log_centre)
                              / s.depth_log_sigma) ** 2,
        "bone_prior": jnp.sum(((log_b - log_prop) / s.bone_log_sigma) ** 2),
        "focal_prior": ((params.log_focal - fixed.log_focal_prior) / s.focal_log_sigma) ** 2,
    }


def total(params: Params, fixed: Fixed, data: Data, weights: dict, s: Settings):
    t = terms(params, fixed, data, s)
    return sum(weights[k] * t[k] for k in TERMS), t


@functools.partial(jax.jit, static_argnames=("s",))
def value_and_grad(params: Params, fixed: Fixed, data: Data, weights: dict, s: Settings):
    """((total, terms), d total / d params)."""
    return jax.value_and_grad(total, has_aux=True)(params, fixed, data, weights, s)


def weight_dict(**nonzero: float) -> dict[str, np.ndarray]:
    """A full weights mapping over TERMS: the given ones, zero elsewhere."""
    unknown = set(nonzero) - set(TERMS)
    if unknown:
        raise ValueError(f"unknown terms {sorted(unknown)}")
    return {k: np.asarray(float(nonzero.get(k, 0.0))) for k in TERMS}
