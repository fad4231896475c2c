"""Physically real test motions: the body simulated under known smooth servo targets.

Used by the recovery test and the dynamics benchmark: the motion is given as the kinematic
input (and its projection as detections, confidence 1), so the optimiser's job is to find
targets that reproduce it. Motions start from the standing keyframe:

- ``stand``: quiet standing with a slow arm movement;
- ``shift``: a lateral weight shift (hips and ankles roll) with arm swings;
- ``step``: the weight shift plus lifting the unloaded foot about 5 cm and setting it down.

``sit`` starts seated instead (hips and knees bent 86 degrees, feet on the floor) on the seat
of `sitting_scene`, which the body must be built with, and leans the trunk forward and back.
"""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np

from physpose.body import Body, standing_qpos
from physpose.dynamics.init import lowest_point
from physpose.dynamics.objective import project
from physpose.dynamics.rollout import Simulator, make_state, sim_model
from physpose.joints import LANDMARK_INDEX
from physpose.metrics import transform_points
from physpose.kinematics.result import KinematicFit
from physpose.observations import Observations
from physpose.scene import Box, SceneConfig
from physpose.skeleton import DOF_NAMES, NV

MOTIONS = ("stand", "shift", "step")   # from standing, on the bare floor
SIT = "sit"                              # seated, on the seat of `sitting_scene`
SEAT_FLEXION = 1.5                       # rad, hips and knees of the seated pose
IMAGE_SIZE = (1280, 720)  # px
FOCAL = 1000.0            # px
CAMERA_DISTANCE = 4.0     # m in front of the person
CAMERA_HEIGHT = 1.2       # m


def _dof(name: str) -> int:
    return DOF_NAMES.index(name)


def _posed(body: Body, qpos: np.ndarray) -> mujoco.MjData:
    """The body's kinematics at qpos."""
    data = mujoco.MjData(body.model)
    data.qpos[:] = qpos
    mujoco.mj_kinematics(body.model, data)
    return data


def _lowest(body: Body, qpos: np.ndarray, segments: tuple[str, ...]) -> float:
    """Lowest z (m) of the named segments' geoms at qpos."""
    return lowest_point(body.model, _posed(body, qpos), {body.body_ids[n] for n in segments})


def seated_qpos(body: Body) -> np.ndarray:
    """(55,) the standing pose with hips and knees bent SEAT_FLEXION, lowered until the soles
    are on z = 0 (the thighs then rest on `sitting_scene`'s seat)."""
    q = standing_qpos(body).copy()
    for side in "lr":
        q[7 + _dof(f"{side}_hip_y")] = -SEAT_FLEXION
        q[7 + _dof(f"{side}_knee_y")] = SEAT_FLEXION
    q[2] -= _lowest(body, q, ("l_ankle", "r_ankle"))
    return q


def sitting_scene(body: Body) -> SceneConfig:
    """The body's scene plus the seat `seated_qpos` rests on: a 10 cm slab (a chair seat) under
    the thighs, its top where they are lowest, from 25 cm behind the hips to 55 % of the way
    to the knees (the calves hang clear of it), 15 cm wider than the hips on each side."""
    q = seated_qpos(body)
    top = _lowest(body, q, ("l_hip", "r_hip"))
    data = _posed(body, q)
    hip = data.xpos[body.body_ids["l_hip"]]
    knee = data.xpos[body.body_ids["l_knee"]]
    back, front = q[0] - 0.25, q[0] + 0.55 * (knee[0] - hip[0])
    half_width = abs(hip[1] - q[1]) + 0.15
    seat = Box(center=(0.5 * (back + front), float(q[1]), top - 0.05),
               size=(front - back, 2 * half_width, 0.1))
    return dataclasses.replace(body.scene, obstacles=body.scene.obstacles + (seat,))


def motion_targets(body: Body, kind: str, seconds: float) -> np.ndarray:
    """Servo targets (S, 48) at every simulation step of the named motion."""
    if kind not in (*MOTIONS, SIT):
        raise ValueError(f"unknown motion {kind!r}; choose one of {(*MOTIONS, SIT)}")
    q0 = seated_qpos(body) if kind == SIT else standing_qpos(body)
    dt = body.model.opt.timestep
    t = np.arange(int(round(seconds / dt))) * dt
    targets = np.tile(q0[7:], (len(t), 1))
    ease = np.minimum(t / 0.5, 1.0)
    wave = np.sin(np.pi * t) * ease  # 0.5 Hz
    targets[:, _dof("r_elbow_y")] -= 0.4 * (1.0 - np.cos(np.pi * t)) / 2.0
    if kind == "stand":
        return targets
    if kind == SIT:
        targets[:, _dof("spine_y")] -= 0.2 * (1.0 - np.cos(np.pi * t)) / 2.0
        return targets
    for side in "lr":
        targets[:, _dof(f"{side}_hip_x")] += 0.04 * wave
        targets[:, _dof(f"{side}_ankle_x")] -= 0.04 * wave
    targets[:, _dof("l_shoulder_y")] -= 0.3 * wave
    if kind == "step":
        lift = np.where((t > 0.45) & (t < 0.95), np.sin(np.pi * (t - 0.45) / 0.5), 0.0)
        targets[:, _dof("l_hip_y")] -= 0.4 * lift
        targets[:, _dof("l_knee_y")] += 0.7 * lift
    return targets


def virtual_camera() -> tuple[np.ndarray, np.ndarray]:
    """(K (3, 3), T_world2cam (4, 4)): a level camera in front of a person facing +x."""
    K = np.array([[FOCAL, 0.0, IMAGE_SIZE[0] / 2], [0.0, FOCAL, IMAGE_SIZE[1] / 2],
                  [0.0, 0.0, 1.0]])
    R = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, -1.0], [-1.0, 0.0, 0.0]])  # rows: cam x, y, z
    centre = np.array([CAMERA_DISTANCE, 0.0, CAMERA_HEIGHT])
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, -R @ centre
    return K, T


def simulated_clip(body: Body, kind: str = "step", seconds: float = 2.0, fps: float = 25.0
                   ) -> tuple[KinematicFit, Observations, np.ndarray]:
    """(kinematic input, detections, true targets (S, 48)) of a simulated motion."""
    targets = motion_targets(body, kind, seconds)
    if kind == SIT and not body.scene.obstacles:
        raise ValueError("the sit motion needs its seat: build the body with "
                         "sitting_scene(body) as its scene")
    sim = sim_model(body)
    start = seated_qpos(body) if kind == SIT else standing_qpos(body)
    state0 = make_state(sim, start, np.zeros(NV))
    with Simulator(sim, nthread=1) as simulator:
        traj = simulator.run(state0, targets[None])
    frames = np.arange(int(round(seconds * fps)) + 1)
    samples = traj.at(frames / (fps * sim.dt))
    if samples.broken.any():
        raise RuntimeError(f"the simulated {kind} motion broke")
    K, T = virtual_camera()
    landmarks = samples.landmarks[0]
    uv = project(landmarks, K, T)
    cam = transform_points(T, landmarks)
    hips = 0.5 * (cam[:, LANDMARK_INDEX["left_hip"]] + cam[:, LANDMARK_INDEX["right_hip"]])
    keypoints = np.concatenate([uv, np.ones(uv.shape[:-1] + (1,))], axis=-1)
    fit = KinematicFit(fps=fps, shape=body.shape, qpos=samples.qpos[0], joints=samples.joints[0],
                       landmarks=landmarks, camera_K=K, T_world2cam=T, variant="simulated",
                       ground_estimated=False)
    obs = Observations(source=f"simulated:{kind}", fps=fps, image_size=IMAGE_SIZE,
                       timestamps=frames / fps, keypoints2d=keypoints,
                       detected=np.ones(len(frames), dtype=bool),
                       interpolated=np.zeros(len(frames), dtype=bool),
                       world_landmarks=cam - hips[:, None], camera_K=K)
    return fit, obs, targets
