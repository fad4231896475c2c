"""A tiny humanoid (MjSpec) and a synthetic walking result, for the output tests.

The body has a free root, 13 hinges, capsules, a sphere head and box feet, and one site per
project joint so the joint arrays come from the same kinematics as the bodies.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import mujoco
import numpy as np

from physpose.joints import JOINT_NAMES, LANDMARK_NAMES, joints_from_landmarks
from physpose.reconstruction import Reconstruction

FPS = 25.0  # Hz
IMAGE_SIZE = (320, 240)  # px


def _hinge(body, name: str, axis) -> None:
    body.add_joint(name=name, type=mujoco.mjtJoint.mjJNT_HINGE, axis=axis, range=[-2.5, 2.5])


def _capsule(body, name: str, fromto, radius: float = 0.05) -> None:
    body.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_CAPSULE, fromto=fromto, size=[radius, 0, 0])


def _site(body, name: str, pos) -> None:
    body.add_site(name=name, pos=pos, size=[0.01, 0, 0])


def tiny_humanoid_mjcf(obstacle: bool = True) -> str:
    """MJCF of a 12-body humanoid standing at the origin (ground plane, optional box obstacle)."""
    spec = mujoco.MjSpec()
    world = spec.worldbody
    world.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[5, 5, 0.1])
    if obstacle:
        world.add_geom(name="step", type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.3, 0.3, 0.1],
                       pos=[1.5, 0.8, 0.1])
    pelvis = world.add_body(name="pelvis", pos=[0, 0, 0.95])
    pelvis.add_freejoint(name="root")
    _capsule(pelvis, "pelvis_geom", [0, -0.1, 0, 0, 0.1, 0], 0.08)
    _site(pelvis, "pelvis", [0, 0, 0])
    torso = pelvis.add_body(name="torso", pos=[0, 0, 0.1], quat=[0.9962, 0, 0.0872, 0])
    _hinge(torso, "abdomen_x", [1, 0, 0])
    _hinge(torso, "abdomen_y", [0, 1, 0])
    _capsule(torso, "torso_geom", [0, 0, 0.05, 0, 0, 0.4], 0.1)
    _site(torso, "spine", [0, 0, 0.1])
    _site(torso, "thorax", [0, 0, 0.4])
    _site(torso, "neck", [0, 0, 0.5])
    head = torso.add_body(name="head", pos=[0, 0, 0.6])
    _hinge(head, "neck_y", [0, 1, 0])
    head.add_geom(name="head_geom", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.1, 0, 0])
    _site(head, "head", [0, 0, 0])
    for side, sy in (("l", 1.0), ("r", -1.0)):
        arm = torso.add_body(name=f"{side}_upper_arm", pos=[0, 0.2 * sy, 0.4])
        _hinge(arm, f"{side}_shoulder_x", [1, 0, 0])
        _hinge(arm, f"{side}_shoulder_y", [0, 1, 0])
        _capsule(arm, f"{side}_upper_arm_geom", [0, 0, 0, 0, 0, -0.28], 0.04)
        _site(arm, f"{side}_shoulder", [0, 0, 0])
        fore = arm.add_body(name=f"{side}_forearm", pos=[0, 0, -0.3])
        _hinge(fore, f"{side}_elbow", [0, 1, 0])
        _capsule(fore, f"{side}_forearm_geom", [0, 0, 0, 0, 0, -0.25], 0.035)
        _site(fore, f"{side}_elbow", [0, 0, 0])
        _site(fore, f"{side}_wrist", [0, 0, -0.26])
        thigh = pelvis.add_body(name=f"{side}_thigh", pos=[0, 0.1 * sy, -0.05])
        _hinge(thigh, f"{side}_hip_x", [1, 0, 0])
        _hinge(thigh, f"{side}_hip_y", [0, 1, 0])
        _hinge(thigh, f"{side}_hip_z", [0, 0, 1])
        _capsule(thigh, f"{side}_thigh_geom", [0, 0, 0, 0, 0, -0.4], 0.06)
        _site(thigh, f"{side}_hip", [0, 0, 0])
        shin = thigh.add_body(name=f"{side}_shin", pos=[0, 0, -0.42])
        _hinge(shin, f"{side}_knee", [0, 1, 0])
        _capsule(shin, f"{side}_shin_geom", [0, 0, 0, 0, 0, -0.38], 0.05)
        _site(shin, f"{side}_knee", [0, 0, 0])
        foot = shin.add_body(name=f"{side}_foot", pos=[0, 0, -0.4])
        _hinge(foot, f"{side}_ankle", [0, 1, 0])
        foot.add_geom(name=f"{side}_foot_geom", type=mujoco.mjtGeom.mjGEOM_BOX,
                      size=[0.1, 0.04, 0.03], pos=[0.05, 0, -0.05])
        _site(foot, f"{side}_ankle", [0, 0, 0])
        _site(foot, f"{side}_heel", [-0.05, 0, -0.08])
        _site(foot, f"{side}_toe", [0.15, 0, -0.08])
    return spec.to_xml()


def walking_qpos(model: mujoco.MjModel, num_frames: int, fps: float = FPS,
                 phase: float = 0.0) -> np.ndarray:
    """(T, nq) a body walking along +x while turning slowly, with swinging limbs."""
    t = np.arange(num_frames) / fps
    qpos = np.tile(model.qpos0, (num_frames, 1))
    qpos[:, 0] = 0.8 * t
    qpos[:, 1] = 0.1 * np.sin(2 * t)
    qpos[:, 2] = 0.9 + 0.02 * np.sin(4 * np.pi * t)
    yaw = 0.3 * t  # rad, slow turn
    qpos[:, 3] = np.cos(yaw / 2)
    qpos[:, 6] = np.sin(yaw / 2)
    for j in range(1, model.njnt):
        adr = model.jnt_qposadr[j]
        qpos[:, adr] = 0.6 * np.sin(2 * np.pi * t + 0.7 * j + phase)
    return qpos


def joints_and_landmarks(mjcf: str, qpos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Joint positions (T, 21, 3) from the sites, and 33 landmarks placed on those joints."""
    model = mujoco.MjModel.from_xml_string(mjcf)
    data = mujoco.MjData(model)
    sites = [model.site(n).id for n in JOINT_NAMES]
    joints = np.zeros((len(qpos), len(JOINT_NAMES), 3))
    for i, q in enumerate(qpos):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        joints[i] = data.site_xpos[sites]
    lm_joint = {"left": "l_", "right": "r_"}
    landmarks = np.zeros((len(qpos), len(LANDMARK_NAMES), 3))
    for k, name in enumerate(LANDMARK_NAMES):
        side = name.split("_")[0]
        part = name.split("_")[-1]
        guess = lm_joint.get(side, "") + {"index": "wrist", "pinky": "wrist", "thumb": "wrist",
                                          "foot": "toe", "eye": "head", "ear": "head",
                                          "inner": "head", "outer": "head", "left": "head",
                                          "right": "head", "nose": "head"}.get(part, part)
        if guess not in JOINT_NAMES:
            guess = "head"
        landmarks[:, k] = joints[:, JOINT_NAMES.index(guess)]
    return joints, landmarks


def camera() -> tuple[np.ndarray, np.ndarray]:
    """K (3, 3) and T_world2cam (4, 4) of a camera 5 m to the -y side, looking at the walker."""
    w, h = IMAGE_SIZE
    k = np.array([[300.0, 0, w / 2], [0, 300.0, h / 2], [0, 0, 1]])
    r_cam2world = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]]).T  # columns: cam x, y, z
    center = np.array([1.0, -5.0, 1.0])
    t = np.eye(4)
    t[:3, :3] = r_cam2world.T
    t[:3, 3] = -r_cam2world.T @ center
    return k, t


def make_reconstruction(num_frames: int = 30, physics: bool = True, qpos_kinematic: bool = True,
                        meta: dict | None = None, obstacle: bool = True) -> Reconstruction:
    """A synthetic result: kinematic and physics motions of the tiny humanoid, slightly apart."""
    mjcf = tiny_humanoid_mjcf(obstacle)
    model = mujoco.MjModel.from_xml_string(mjcf)
    q_kin = walking_qpos(model, num_frames)
    q_phys = walking_qpos(model, num_frames, phase=0.15)
    j_kin, lm_kin = joints_and_landmarks(mjcf, q_kin)
    j_phys, lm_phys = joints_and_landmarks(mjcf, q_phys)
    k, t = camera()
    cam = (t[:3, :3] @ lm_kin.reshape(-1, 3).T + t[:3, 3:]).T
    px = (k @ cam.T).T
    kp = np.concatenate([px[:, :2] / px[:, 2:], np.ones((len(px), 1))], axis=1)
    windows = [{"start": 0.4 * i, "end": 0.4 * i + 0.6,
                "terms": {"com": 0.1 / (i + 1), "pose": 0.05 * (i + 1), "2d": 3.0 - 0.2 * i}}
               for i in range(3)]
    base_meta = {"metrics": {"mpjpe_g_mm": 41.5, "foot_skate_pct": 3.2},
                 "dynamics": {"windows": windows}}
    assert np.allclose(joints_from_landmarks(lm_kin)[:, 5], j_kin[:, 5])
    grf, cop, torques = synthetic_forces(model, num_frames)
    return Reconstruction(
        fps=FPS, joint_names=JOINT_NAMES, joints_kinematic=j_kin, camera_K=k,
        camera_T_world2cam=t, landmarks_kinematic=lm_kin,
        keypoints2d=kp.reshape(num_frames, len(LANDMARK_NAMES), 3),
        joints_physics=j_phys if physics else None,
        qpos_physics=q_phys if physics else None,
        landmarks_physics=lm_phys if physics else None,
        body_mjcf=mjcf if (physics or qpos_kinematic) else None,
        qpos_kinematic=q_kin if qpos_kinematic else None,
        grf_physics=grf if physics else None, cop_physics=cop if physics else None,
        torques_physics=torques if physics else None,
        meta=base_meta if meta is None else meta)


def synthetic_forces(model: mujoco.MjModel, num_frames: int
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(grf (T, 3, 3), cop (T, 2, 3), torques (T, 48)) of a walk: the weight passes from foot to
    foot, the left foot is in the air (no centre of pressure) in the first quarter of each
    cycle; the torques a smooth pattern."""
    weight = float(model.body_subtreemass[0]) * 9.81
    phase = 2 * np.pi * np.arange(num_frames) / 20.0
    share = np.clip(0.5 + 0.7 * np.sin(phase), 0.0, 1.0)
    grf = np.zeros((num_frames, 3, 3))
    grf[:, 0, 2], grf[:, 1, 2] = weight * share, weight * (1.0 - share)
    grf[:, :2, 0] = 0.1 * grf[:, :2, 2] * np.cos(phase)[:, None]
    cop = np.zeros((num_frames, 2, 3))
    cop[:, 0, 1], cop[:, 1, 1] = 0.1, -0.1
    cop[:, :, 0] = 0.3 * np.arange(num_frames)[:, None] / FPS
    cop[share <= 0.0, 0] = np.nan
    torques = 20.0 * np.sin(phase[:, None] + np.arange(48)[None])
    return grf, cop, torques


def write_video(path: Path, num_frames: int, fps: float = 30.0) -> Path:
    """A short synthetic video (IMAGE_SIZE, a moving gradient) readable by OpenCV."""
    w, h = IMAGE_SIZE
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), fps, (w, h))
    assert writer.isOpened()
    x = np.linspace(0, 255, w, dtype=np.float32)
    for i in range(num_frames):
        frame = np.zeros((h, w, 3), np.uint8)
        frame[..., 1] = ((x[None, :] + 8 * i) % 256).astype(np.uint8)
        frame[..., 2] = 90
        writer.write(frame)
    writer.release()
    return path


def save_result(tmp_path: Path, **kwargs) -> Path:
    """Write a synthetic result folder and return it."""
    out = tmp_path / "result"
    make_reconstruction(**kwargs).save(out / "reconstruction.npz")
    return out
