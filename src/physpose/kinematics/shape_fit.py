"""The time-consistent body shape (+S): bone lengths fitted jointly with the poses of n seed
frames (the paper's n = 5 frames of highest confidence), against the 2d detections and
MediaPipe's metric 3d landmarks, with a prior towards average adult proportions.

Scale: MediaPipe's metric landmarks set it, unless the person's height is given; then the bones
are constrained to that stature and MediaPipe's scale becomes a free factor. MediaPipe's depth
compression (a per-clip factor on its depth along the viewing ray) is fitted here too.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from physpose.kinematics.config import KinematicConfig
from physpose.kinematics.evidence import Evidence, padded_length, seed_frames
from physpose.kinematics.objective import bones_of, weight_dict
from physpose.kinematics.pose_fit import Settings, initial_pose, make_params, make_problem
from physpose.shape import BodyShape, bone_lengths_from_landmarks, stature_from_bones
from physpose.skeleton import BONE_NAMES


@dataclass(frozen=True)
class ShapeFit:
    """Result of the shape step."""

    shape: BodyShape
    seeds: np.ndarray      # (n,) seed frame indices
    depth_scale: float     # MediaPipe's depth along the ray x this = the body's
    world_scale: float     # MediaPipe's metric landmarks x this = the body's scale
    losses: dict[str, float]


def fit_shape(ev: Evidence, K: np.ndarray, cfg: KinematicConfig, settings: Settings,
              surface_offset: np.ndarray, *, height: float | None = None,
              mass: float | None = None) -> ShapeFit:
    """Fit bone lengths and the seed frames' poses; the shape's radii follow from its stature
    and mass (shape.BodyShape.from_bone_lengths)."""
    seeds = seed_frames(ev, cfg.shape.seed_frames, int(round(cfg.shape.seed_spacing_s * ev.fps)))
    lengths = bone_lengths_from_landmarks(ev.world_cam()[seeds])
    bones = np.array([lengths[n] for n in BONE_NAMES])
    if height is not None:
        bones = bones * height / stature_from_bones(bones)
    depth_scale = cfg.pose.depth_scale_prior_centre  # the fit starts at its prior's centre
    root_pos, R0, angles = initial_pose(ev, seeds, bones, K, depth_scale, 1.0)
    length = padded_length(len(seeds))
    problem = make_problem(ev, seeds, length, R0, K, K[0, 0], root_pos[:, 2], surface_offset,
                           height, settings, np.zeros(4), cfg.pose.hard_limits)
    params = make_params(root_pos, np.zeros_like(root_pos), angles, bones, depth_scale, 1.0,
                         K[0, 0], length)
    w = cfg.pose.weights
    pose_terms = dict(reprojection=w.reprojection, world_landmarks=w.world_landmarks,
                      pose_prior=w.pose_prior, joint_limits=w.joint_limits)
    # Poses first (bones fixed), then everything together.
    params, _ = problem.run(params, ("root_pos", "root_rotvec", "angles"),
                            weight_dict(**pose_terms), cfg.shape.iterations)
    free = ("root_pos", "root_rotvec", "angles", "log_bones", "log_depth_scale")
    if height is not None:
        free += ("log_world_scale",)
    params, losses = problem.run(params, free, weight_dict(
        **pose_terms, bone_prior=1.0, depth_scale_prior=w.depth_scale_prior),
        cfg.shape.iterations)
    fitted = np.asarray(bones_of(params, problem.fixed))
    shape = BodyShape.from_bone_lengths(fitted, height=height, mass=mass)
    return ShapeFit(shape=shape, seeds=seeds,
                    depth_scale=float(np.exp(params.log_depth_scale)),
                    world_scale=float(np.exp(params.log_world_scale)), losses=losses)
