"""Synthetic clips for the kinematic-fit tests: a known body walking in front of a known camera,
seen as perfect (or noisy) MediaPipe-style observations."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from physpose.fk import fk_qpos, segment_frames
from physpose.joints import LANDMARK_INDEX
from physpose.kinematics.surface import place, surface_points
from physpose.metrics import project, transform_points
from physpose.observations import Observations
from physpose.pinhole import rays, rotation_to
from physpose.shape import BodyShape
from physpose.skeleton import DOF_NAMES, NQ

IMAGE_SIZE = (1280, 720)
FOCAL = 900.0
_HIPS = [LANDMARK_INDEX["left_hip"], LANDMARK_INDEX["right_hip"]]


@dataclass(frozen=True, eq=False)
class SyntheticClip:
    observations: Observations
    shape: BodyShape
    qpos: np.ndarray          # (T, 55) world
    K: np.ndarray
    T_world2cam: np.ndarray
    landmarks_cam: np.ndarray  # (T, 33, 3)


def look_at(eye: np.ndarray, target: np.ndarray, roll_deg: float = 0.0) -> np.ndarray:
    """(4, 4) T_world2cam of an OpenCV camera at eye looking at target (world z up)."""
    fwd = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    down = np.cross(fwd, right)
    R = np.stack([right, down, fwd])
    R = Rotation.from_rotvec(np.radians(roll_deg) * np.array([0.0, 0.0, 1.0])).as_matrix() @ R
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, -R @ eye
    return T


def walking_qpos(shape: BodyShape, frames: int, fps: float = 25.0, speed: float = 0.8,
                 heading_deg: float = 90.0) -> np.ndarray:
    """(T, 55) a stylised walk along the world heading, soles near z = 0."""
    t = np.arange(frames) / fps
    phase = 2 * np.pi * 0.9 * t
    q = np.zeros((frames, NQ))
    heading = np.radians(heading_deg)
    direction = np.array([np.cos(heading), np.sin(heading)])
    q[:, :2] = speed * t[:, None] * direction
    q[:, 3:7] = np.array([np.cos(heading / 2), 0.0, 0.0, np.sin(heading / 2)])

    def set_dof(name: str, values: np.ndarray) -> None:
        q[:, 7 + DOF_NAMES.index(name)] = values

    set_dof("l_hip_y", -0.35 * np.sin(phase))
    set_dof("r_hip_y", 0.35 * np.sin(phase))
    set_dof("l_knee_y", 0.35 + 0.3 * np.sin(phase + 1.0))
    set_dof("r_knee_y", 0.35 - 0.3 * np.sin(phase + 1.0))
    set_dof("l_shoulder_y", 0.3 * np.sin(phase))
    set_dof("r_shoulder_y", -0.3 * np.sin(phase))
    set_dof("l_shoulder_x", 0.15 + 0 * t)
    set_dof("r_shoulder_x", -0.15 + 0 * t)
    set_dof("l_elbow_y", -0.5 + 0 * t)
    set_dof("r_elbow_y", -0.5 + 0 * t)
    set_dof("spine_y", 0.05 + 0 * t)
    # Root height so that the lowest sole sample touches the ground in every frame.
    surface = surface_points(shape)
    pos, rot = segment_frames(shape.bones(), q[:, :3], q[:, 3:7], q[:, 7:])
    soles = place(surface, pos, rot)[:, surface.left_foot | surface.right_foot]
    q[:, 2] = -soles[..., 2].min(axis=1)
    return q


def synthetic_clip(frames: int = 12, *, noise_px: float = 0.0, noise_3d: float = 0.0,
                   seed: int = 0, shape: BodyShape | None = None,
                   T_world2cam: np.ndarray | None = None, with_K: bool = True,
                   fps: float = 25.0, depth_scale: float = 1.0,
                   edit_qpos: Callable[[np.ndarray], np.ndarray] | None = None) -> SyntheticClip:
    """A walking body seen by a static camera, as Observations (world landmarks in the ray
    frame of the hips, like MediaPipe's, with the default fit configuration; their depth along
    the ray x depth_scale). edit_qpos changes the walk's (T, 55) qpos before it is seen (e.g.
    to raise the arms)."""
    rng = np.random.default_rng(seed)
    shape = shape or BodyShape.from_height(1.75)
    q = walking_qpos(shape, frames, fps)
    if edit_qpos is not None:
        q = edit_qpos(q.copy())
    K = np.array([[FOCAL, 0.0, IMAGE_SIZE[0] / 2], [0.0, FOCAL, IMAGE_SIZE[1] / 2],
                  [0.0, 0.0, 1.0]])
    if T_world2cam is None:
        T_world2cam = look_at(np.array([0.3, -4.5, 1.4]), np.array([0.3, 0.0, 0.9]))
    _, lm_world = fk_qpos(shape.bones(), q)
    lm_cam = transform_points(T_world2cam, lm_world)
    uv = project(lm_world, K, T_world2cam) + noise_px * rng.standard_normal(lm_world.shape[:2]
                                                                              + (2,))
    hips = lm_cam[:, _HIPS].mean(axis=1)
    R_ray = rotation_to(np.array([0.0, 0.0, 1.0]), rays(K, uv[:, _HIPS].mean(axis=1)))
    world = np.einsum("tji,tpj->tpi", R_ray, lm_cam - hips[:, None]) * [1.0, 1.0, depth_scale]
    world = world + noise_3d * rng.standard_normal(world.shape)
    kp = np.concatenate([uv, np.ones(uv.shape[:2] + (1,))], axis=-1)
    obs = Observations(source="synthetic", fps=fps, image_size=IMAGE_SIZE,
                       timestamps=np.arange(frames) / fps, keypoints2d=kp,
                       detected=np.ones(frames, bool), interpolated=np.zeros(frames, bool),
                       world_landmarks=world, camera_K=K if with_K else None,
                       frame_indices=np.arange(frames))
    return SyntheticClip(observations=obs, shape=shape, qpos=q, K=K, T_world2cam=T_world2cam,
                         landmarks_cam=lm_cam)
