"""Batched pose optimisation: a `Problem` (frames, evidence, settings) and its stages.

Every stage minimises the one objective (`objective.py`) over all frames at once with
L-BFGS-B; joint limits are box bounds (and a penalty term). The initial poses come from
closed-form inverse kinematics on MediaPipe's world landmarks, the root depth from the body's
metric size against its image size.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np

from physpose.fk import fk
from physpose.kinematics import objective
from physpose.kinematics.config import DEPTH_SCALE_RANGE, PoseConfig
from physpose.kinematics.evidence import Evidence, data_for, pad
from physpose.kinematics.ik import inverse_kinematics
from physpose.kinematics.objective import Fixed, Params, Settings
from physpose.kinematics.optim import minimize
from physpose.kinematics.surface import SurfacePoints
from physpose.skeleton import DOF_LIMITS

_LOG_DEPTH_SCALE_RANGE = tuple(np.log(DEPTH_SCALE_RANGE))
_LOG_WORLD_SCALE_RANGE = (np.log(0.7), np.log(1.4))
_LOG_FOCAL_RANGE = np.log(3.0)  # focal within x/÷ 3 of its prior


@dataclass(frozen=True, eq=False)
class Problem:
    """The objective's fixed parts for one set of frames (padded to `length`)."""

    frames: np.ndarray     # (n,) indices into the evidence
    length: int            # padded number of frames
    fixed: Fixed
    data: objective.Data
    settings: Settings
    hard_limits: bool = True

    def run(self, params: Params, free: tuple[str, ...], weights: dict, iterations: int,
            tolerance: float = 1e-8) -> tuple[Params, dict[str, float]]:
        """Minimise the weighted objective over the free parameters; returns them and the
        final value of every term."""
        w = {k: jnp.asarray(v) for k, v in weights.items()}
        settings = self._settings(weights)

        def value_and_grad(p: Params):
            (value, _), grads = objective.value_and_grad(p, self.fixed, self.data, w, settings)
            return value, grads

        f0 = float(np.exp(np.asarray(self.fixed.log_focal_prior)))
        bounds = {"log_depth_scale": _LOG_DEPTH_SCALE_RANGE,
                  "log_world_scale": _LOG_WORLD_SCALE_RANGE,
                  "log_focal": (np.log(f0) - _LOG_FOCAL_RANGE, np.log(f0) + _LOG_FOCAL_RANGE)}
        if self.hard_limits:
            bounds["angles"] = (DOF_LIMITS[:, 0], DOF_LIMITS[:, 1])
        result = minimize(value_and_grad, params, free, bounds=bounds, iterations=iterations,
                          tolerance=tolerance)
        return result.params, self.evaluate(result.params, weights)

    def evaluate(self, params: Params, weights: dict) -> dict[str, float]:
        """Every term's weighted value (and 'total') at params."""
        w = {k: jnp.asarray(v) for k, v in weights.items()}
        (value, terms), _ = objective.value_and_grad(params, self.fixed, self.data, w,
                                                     self._settings(weights))
        out = {k: float(weights[k]) * float(terms[k]) for k in objective.TERMS
               if float(weights[k]) != 0.0}
        out["total"] = float(value)
        return out

    def _settings(self, weights: dict) -> Settings:
        return dataclasses.replace(self.settings, ground_on=float(weights["ground"]) != 0.0)

    def with_plane(self, plane: np.ndarray) -> Problem:
        return Problem(self.frames, self.length, self.fixed,
                       self.data._replace(plane=jnp.asarray(plane, dtype=float)),
                       self.settings, self.hard_limits)


def settings_from(cfg: PoseConfig, ground, shape_cfg, camera_cfg, surface: SurfacePoints
                  ) -> Settings:
    """Settings from the stage configs and the surface sampling's layout."""
    return Settings(
        sigma_2d=cfg.sigma_2d, sigma_3d=cfg.sigma_3d, depth_ratio=cfg.depth_sigma_ratio,
        robust_c=cfg.robust_c, sigma_velocity=cfg.sigma_velocity,
        sigma_acceleration=cfg.sigma_acceleration,
        sigma_angle_acceleration=cfg.sigma_angle_acceleration, k=ground.k_pose,
        delta=ground.delta,
        foot_delta=ground.foot_delta_pose, body_weight=ground.body_weight,
        ground_scale=ground.pose_scale, contact_height=ground.contact_height,
        sigma_skate=ground.sigma_skate,
        bone_log_sigma=shape_cfg.bone_log_sigma,
        depth_log_centre=float(np.log(cfg.depth_scale_prior_centre)),
        depth_log_sigma=cfg.depth_scale_log_sigma,
        focal_log_sigma=camera_cfg.focal_log_sigma, surface_blocks=surface.blocks,
        left_foot=tuple(int(i) for i in np.flatnonzero(surface.left_foot)),
        right_foot=tuple(int(i) for i in np.flatnonzero(surface.right_foot)))


def initial_pose(ev: Evidence, frames: np.ndarray, bones: np.ndarray, K: np.ndarray,
                 depth_scale: float, world_scale: float
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(root_pos (n, 3), root_rot (n, 3, 3), angles (n, 48)) for the frames, camera axes.

    Poses by inverse kinematics on MediaPipe's landmarks (frames without evidence take their
    nearest valid frame's); the root where the body's metric size matches its image size.
    """
    source = ev.nearest_valid()[frames]
    world = ev.world_cam(depth_scale, world_scale)[source]
    root_rot, angles = inverse_kinematics(world, bones)
    _, rel = fk(bones, np.zeros((len(frames), 3)), root_rot, angles)
    w = ev.weight[source]
    wsum = np.maximum(w.sum(1, keepdims=True), 1e-9)
    uv = ev.uv[source]
    uv_mean = (uv * w[..., None]).sum(1) / wsum
    rel_mean = (rel * w[..., None]).sum(1) / wsum
    spread2 = np.sqrt((w * np.sum((uv - uv_mean[:, None]) ** 2, -1)).sum(1) / wsum[:, 0])
    spread3 = np.sqrt((w * np.sum((rel[..., :2] - rel_mean[:, None, :2]) ** 2, -1)).sum(1)
                      / wsum[:, 0])
    depth = K[0, 0] * spread3 / np.maximum(spread2, 1e-6) - rel_mean[:, 2]
    depth = np.clip(depth, 0.5, 200.0)
    xy = (uv_mean - K[:2, 2]) / np.diag(K)[:2] * (depth + rel_mean[:, 2])[:, None]
    root_pos = np.concatenate([xy - rel_mean[:, :2], depth[:, None]], axis=1)
    return root_pos, root_rot, angles


def make_params(root_pos, root_rot_delta, angles, bones, depth_scale, world_scale, focal,
                length) -> Params:
    """Params padded to `length` frames."""
    return Params(root_pos=pad(root_pos, length), root_rotvec=pad(root_rot_delta, length),
                  angles=pad(angles, length), log_bones=np.log(np.asarray(bones, float)),
                  log_depth_scale=np.asarray(np.log(depth_scale)),
                  log_world_scale=np.asarray(np.log(world_scale)),
                  log_focal=np.asarray(np.log(focal)))


def make_problem(ev: Evidence, frames: np.ndarray, length: int, R0: np.ndarray, K: np.ndarray,
                 focal_prior: float, root_depth: np.ndarray, surface_offset: np.ndarray,
                 height: float | None, settings: Settings, plane: np.ndarray,
                 hard_limits: bool, support: np.ndarray | None = None) -> Problem:
    """A Problem over `frames` (indices into ev) with reference orientations R0 (n, 3, 3) and
    the reprojection's metres-per-pixel from the root depths (n,); support (n,): the height
    above the plane the feet stand on in each frame (default 0, the floor)."""
    fixed = Fixed(R0=jnp.asarray(pad(R0, length)), principal=jnp.asarray(K[:2, 2]),
                  surface_offset=jnp.asarray(surface_offset),
                  height=jnp.asarray(float(height or 0.0)),
                  log_focal_prior=jnp.asarray(np.log(focal_prior)))
    m_per_px = np.maximum(root_depth, 0.5) / K[0, 0]
    data = data_for(ev, frames, m_per_px, plane, length, support)
    return Problem(frames=np.asarray(frames), length=length, fixed=fixed, data=data,
                   settings=settings, hard_limits=hard_limits)


def unpadded(params: Params, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(root_pos, root_rotvec, angles) of the first n frames as NumPy arrays."""
    return (np.asarray(params.root_pos)[:n], np.asarray(params.root_rotvec)[:n],
            np.asarray(params.angles)[:n])
