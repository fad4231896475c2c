"""Detector simulator on a small synthetic clip: camera, landmarks, noise model, determinism."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from physpose.detector_sim import (
    DetectorSimConfig,
    look_at_camera,
    simulate_detections,
    synthesize_landmarks,
)
from physpose.errors import PhysposeError
from physpose.joints import (
    JOINT_INDEX,
    JOINT_NAMES,
    LANDMARK_INDEX,
    LANDMARK_NAMES,
    joints_from_landmarks,
)
from physpose.metrics import project
from physpose.mocap import MocapClip
from physpose.pinhole import ray_frame

NOISELESS = DetectorSimConfig.noiseless(distance=4.0)


def walking_clip(frames: int = 50, fps: float = 25.0, speed: float = 1.0) -> MocapClip:
    """A rigid standing figure (facing +x, 1.75 m) gliding along +x (m/s), swinging its arms."""
    p = {"pelvis": (0, 0, 0.95), "spine": (0, 0, 1.175), "thorax": (0, 0, 1.40),
         "neck": (0, 0, 1.49), "head": (0, 0, 1.58), "shoulder": (0, 0.18, 1.40),
         "elbow": (0, 0.20, 1.12), "wrist": (0, 0.21, 0.88), "hip": (0, 0.09, 0.95),
         "knee": (0.02, 0.10, 0.50), "ankle": (0, 0.10, 0.08), "heel": (-0.06, 0.10, 0.0),
         "toe": (0.19, 0.10, 0.0)}
    pose = np.array([p[n] if n in p else
                     np.multiply(p[n[2:]], (1, 1 if n[0] == "l" else -1, 1))
                     for n in JOINT_NAMES], dtype=float)
    t = np.arange(frames) / fps
    joints = pose[None].repeat(frames, 0)
    joints[..., 0] += speed * t[:, None]
    for side in ("l", "r"):   # wrists swing back and forth
        joints[:, JOINT_INDEX[f"{side}_wrist"], 0] += 0.2 * np.sin(2 * np.pi * t)
    hand = np.stack([[0, 0, -1.0], [1.0, 0, 0], [0, -1.0, 0]], axis=1)  # down, thumb forward
    return MocapClip(name="glide", source="synthetic", fps=fps, joints=joints,
                     head_top=joints[:, JOINT_INDEX["head"]] + [0, 0, 0.17],
                     head_rot=np.broadcast_to(np.eye(3), (frames, 3, 3)).copy(),
                     hand_rot=np.broadcast_to(hand, (frames, 2, 3, 3)).copy(),
                     source_fps=fps, floor_offset=0.0)


def test_landmarks_reproduce_the_joints_and_face_forward():
    clip = walking_clip(5)
    lm = synthesize_landmarks(clip)
    assert lm.shape == (5, 33, 3)
    assert joints_from_landmarks(lm) == pytest.approx(clip.joints)
    nose, head = lm[:, LANDMARK_INDEX["nose"]], clip.joint("head")
    assert (nose[:, 0] - head[:, 0] > 0.08).all()                # the face looks along +x
    assert (lm[:, LANDMARK_INDEX["left_eye"], 1] > lm[:, LANDMARK_INDEX["right_eye"], 1]).all()
    thumb = lm[:, LANDMARK_INDEX["left_thumb"]] - clip.joint("l_wrist")
    assert (thumb[:, 0] > 0.03).all() and (thumb[:, 2] < -0.03).all()   # forward and below the wrist


def test_camera_looks_at_the_subject_from_the_configured_place():
    clip = walking_clip()
    cfg = DetectorSimConfig(distance=5.0, height=1.5, azimuth_deg=0.0)
    K, T = look_at_camera(clip, cfg)
    R = T[:3, :3]
    assert R @ R.T == pytest.approx(np.eye(3)) and np.linalg.det(R) == pytest.approx(1.0)
    centre = -R.T @ T[:3, 3]
    target = clip.joint("pelvis").mean(axis=0)
    assert centre[2] == pytest.approx(1.5)
    assert centre[:2] - target[:2] == pytest.approx([5.0, 0.0])   # in front: subject faces +x
    uv = project(target, K, T)
    assert uv == pytest.approx([960.0, 540.0])                      # looked-at point: centre
    assert K[0, 0] == pytest.approx(960.0 / np.tan(np.deg2rad(30.0)))
    side = look_at_camera(clip, dataclasses.replace(cfg, azimuth_deg=90.0))[1]
    assert (-side[:3, :3].T @ side[:3, 3])[1] - target[1] == pytest.approx(5.0)  # at its left


def test_camera_placement_survives_a_facing_that_averages_out():
    clip = walking_clip(speed=0.0)
    half = clip.num_frames // 2
    pelvis = clip.joint("pelvis")[:, None]
    turned = clip.joints.copy()                      # the second half faces -x: a half turn
    turned[half:, :, :2] = 2 * pelvis[half:, :, :2] - turned[half:, :, :2]
    clip = dataclasses.replace(clip, joints=turned)
    left = clip.joint("l_hip") - clip.joint("r_hip")
    assert left.mean(axis=0) == pytest.approx(np.zeros(3), abs=1e-12)
    cfg = DetectorSimConfig(distance=5.0, height=1.5, azimuth_deg=0.0)
    K, T = look_at_camera(clip, cfg)
    assert np.isfinite(T).all()
    centre = -T[:3, :3].T @ T[:3, 3]                 # in front of the first frame's facing (+x)
    assert centre[:2] - pelvis.mean(axis=0)[0, :2] == pytest.approx([5.0, 0.0])
    stacked = clip.joints.copy()                     # hips one above the other: no facing at all
    stacked[:, JOINT_INDEX["l_hip"]] = stacked[:, JOINT_INDEX["r_hip"]] + [0.0, 0.0, 0.18]
    T = look_at_camera(dataclasses.replace(clip, joints=stacked), cfg)[1]
    assert np.isfinite(T).all()


def test_auto_distance_keeps_everything_in_view():
    clip = walking_clip()
    sim = simulate_detections(clip, dataclasses.replace(NOISELESS, distance=None))
    uv = sim.landmarks2d
    assert (uv > 0).all() and (uv[..., 0] < 1920).all() and (uv[..., 1] < 1080).all()
    assert sim.observations.detected.all()


def test_noiseless_simulation_is_the_projection_of_the_truth():
    clip = walking_clip()
    sim = simulate_detections(clip, NOISELESS)
    obs = sim.observations
    assert obs.keypoints2d[..., :2] == pytest.approx(project(sim.landmarks, sim.camera_K,
                                                             sim.camera_T_world2cam))
    R = sim.camera_T_world2cam[:3, :3]
    hips = 0.5 * (sim.landmarks[:, LANDMARK_INDEX["left_hip"]]
                  + sim.landmarks[:, LANDMARK_INDEX["right_hip"]])
    centred = (sim.landmarks - hips[:, None]) @ R.T                          # camera axes
    # MediaPipe's frame: the camera's turned so that z runs along the ray through the hips.
    hips_cam = hips @ R.T + sim.camera_T_world2cam[:3, 3]
    cam_from_ray = ray_frame(hips_cam / np.linalg.norm(hips_cam, axis=-1, keepdims=True))
    assert obs.world_landmarks == pytest.approx(np.einsum("tji,tkj->tki", cam_from_ray,
                                                          centred))       # R^T x
    assert obs.world_landmarks[:, LANDMARK_INDEX["nose"], 1].mean() < -0.5   # head up = -y
    assert (cam_from_ray @ [0, 0, 1]) == pytest.approx(hips_cam / np.linalg.norm(
        hips_cam, axis=-1, keepdims=True))
    camera_axes = simulate_detections(clip, dataclasses.replace(NOISELESS, ray_aligned_world=False))
    assert camera_axes.observations.world_landmarks == pytest.approx(centred)
    assert obs.fps == 25.0 and obs.image_size == (1920, 1080) and obs.camera_K is None
    assert obs.timestamps == pytest.approx(np.arange(50) / 25.0)


def test_noiseless_config_keeps_the_confidence_model_and_takes_overrides():
    cfg = DetectorSimConfig.noiseless(seed=3, azimuth_deg=60.0)
    assert cfg.seed == 3 and cfg.azimuth_deg == 60.0
    assert cfg.far_side_drop == DetectorSimConfig().far_side_drop > 0
    assert cfg.outlier_rate == cfg.swap_rate == cfg.sigma_2d_white == cfg.sigma_3d_drift == 0.0
    assert cfg.depth_scale_mean == cfg.scale_bias_mean == 1.0


def test_same_seed_same_output_other_seed_other_output():
    clip = walking_clip()
    a = simulate_detections(clip, DetectorSimConfig(seed=7))
    b = simulate_detections(clip, DetectorSimConfig(seed=7))
    c = simulate_detections(clip, DetectorSimConfig(seed=8))
    for key in ("keypoints2d", "world_landmarks"):
        assert np.array_equal(getattr(a.observations, key), getattr(b.observations, key))
        assert not np.allclose(getattr(a.observations, key), getattr(c.observations, key))
    assert np.array_equal(a.outliers, b.outliers) and np.array_equal(a.swapped, b.swapped)


def test_two_clips_of_the_same_length_get_their_own_noise():
    # The benchmark crops long clips to the same 100 frames: their noise, outliers, swaps and
    # per-clip biases must still be drawn for each clip.
    walk = walking_clip()
    other = dataclasses.replace(walk, name="another_walk")
    cfg = DetectorSimConfig(seed=7)
    a, b = simulate_detections(walk, cfg), simulate_detections(other, cfg)
    assert not np.allclose(a.observations.keypoints2d, b.observations.keypoints2d)
    assert not np.allclose(a.observations.world_landmarks, b.observations.world_landmarks)
    assert not np.array_equal(a.outliers, b.outliers)


def person_size(sim) -> np.ndarray:
    """(T,) long side of the 2d bounding box of the true landmarks and head top, px."""
    top = project(sim.joints[:, JOINT_INDEX["head"]] + [0, 0, 0.17], sim.camera_K,
                  sim.camera_T_world2cam)
    outline = np.concatenate([sim.landmarks2d, top[:, None]], axis=1)
    return np.ptp(outline, axis=1).max(axis=1)


def test_2d_noise_scales_with_the_person_in_the_image():
    clip = walking_clip()
    cfg = DetectorSimConfig(distance=4.0, seed=3)
    small = simulate_detections(clip, cfg)
    big = simulate_detections(clip, dataclasses.replace(cfg, image_size=(3840, 2160)))
    err_small = small.observations.keypoints2d[..., :2] - small.landmarks2d
    err_big = big.observations.keypoints2d[..., :2] - big.landmarks2d
    assert err_big == pytest.approx(2 * err_small)


def test_noise_levels_follow_the_config():
    clip = walking_clip(400, speed=0.0)
    cfg = dataclasses.replace(NOISELESS, sigma_2d_white=0.01, sigma_3d_white=0.02, seed=1,
                              depth_noise_ratio=2.0, azimuth_deg=0.0)  # frontal: all unhidden
    sim = simulate_detections(clip, cfg)
    front = [LANDMARK_INDEX[n] for n in ("nose", "left_shoulder", "right_shoulder")]
    err2d = sim.observations.keypoints2d[:, front, :2] - sim.landmarks2d[:, front]
    size = person_size(sim)
    assert 400 < size.mean() < 800
    assert (err2d / size[:, None, None]).std() == pytest.approx(0.01, rel=0.1)   # gain 1
    err3d = sim.observations.world_landmarks[:, front] - sim.world_landmarks[:, front]
    assert err3d[..., 0].std() == pytest.approx(0.02, rel=0.1)
    assert err3d[..., 2].std() == pytest.approx(0.04, rel=0.1)   # depth: 2x lateral


def test_a_limb_errs_as_a_whole():
    """MediaPipe's 3d error moves a limb together and keeps its bones' lengths (measured on
    pose2sim); independent noise per landmark stretched them twice as much."""
    clip = walking_clip(400, speed=0.0)
    noisy = dataclasses.replace(NOISELESS, sigma_3d_white=0.03, seed=3, azimuth_deg=0.0)
    at = {n: LANDMARK_INDEX[n] for n in ("left_hip", "left_knee", "left_ankle",
                                         "left_foot_index", "left_elbow", "left_wrist")}

    def measure(cfg):
        sim = simulate_detections(clip, cfg)
        err = sim.observations.world_landmarks - sim.world_landmarks
        corr = np.corrcoef(err[:, at["left_knee"], 0], err[:, at["left_ankle"], 0])[0, 1]
        wl = sim.observations.world_landmarks
        thigh = np.linalg.norm(wl[:, at["left_knee"]] - wl[:, at["left_hip"]], axis=-1)
        return corr, thigh.std(), err[:, at["left_wrist"], 0].std()

    corr, thigh_sd, wrist_sd = measure(noisy)
    corr0, thigh_sd0, wrist_sd0 = measure(dataclasses.replace(
        noisy, noise_chain_correlation=0.0, bone_stretch_removed=0.0))
    assert abs(corr0) < 0.15 and corr > 0.5
    assert thigh_sd < 0.5 * thigh_sd0
    assert wrist_sd == pytest.approx(wrist_sd0, rel=0.15)   # each landmark's error stays


@pytest.mark.parametrize("field, value", [("noise_chain_correlation", 1.0),
                                          ("noise_chain_correlation", -0.1),
                                          ("bone_stretch_removed", 1.2)])
def test_noise_structure_out_of_range_is_refused(field, value):
    # (a correlation of 1.2 had given NaN landmarks, reported as a malformed keypoints file)
    with pytest.raises(PhysposeError, match=field):
        DetectorSimConfig(**{field: value})


def test_scale_and_depth_bias_are_per_clip():
    clip = walking_clip()
    cfg = dataclasses.replace(NOISELESS, scale_bias_sigma=0.1, depth_scale_mean=0.8, seed=2)
    sim = simulate_detections(clip, cfg)
    wl, true = sim.observations.world_landmarks, sim.world_landmarks
    ratio_x = wl[..., 0][np.abs(true[..., 0]) > 0.05] / true[..., 0][np.abs(true[..., 0]) > 0.05]
    ratio_z = wl[..., 2][np.abs(true[..., 2]) > 0.05] / true[..., 2][np.abs(true[..., 2]) > 0.05]
    assert np.ptp(ratio_x) < 1e-9 and abs(ratio_x[0] - 1.0) > 1e-3   # one scale for the clip
    assert ratio_z == pytest.approx(0.8 * ratio_x[0])


def test_lean_bias_rotates_about_the_hips_and_camera_x():
    clip = walking_clip()
    sim = simulate_detections(clip, dataclasses.replace(NOISELESS, lean_bias_sigma_deg=10.0))
    wl, true = sim.observations.world_landmarks, sim.world_landmarks
    assert np.linalg.norm(wl, axis=-1) == pytest.approx(np.linalg.norm(true, axis=-1))
    assert wl[..., 0] == pytest.approx(true[..., 0])
    assert np.abs(wl[..., 2] - true[..., 2]).max() > 0.01


def test_far_side_landmarks_are_less_confident():
    clip = walking_clip()
    cfg = dataclasses.replace(NOISELESS, azimuth_deg=90.0)   # camera at the subject's left
    conf = simulate_detections(clip, cfg).observations.keypoints2d[..., 2]
    def mean(side: str, part: str) -> float:
        return float(conf[:, LANDMARK_INDEX[f"{side}_{part}"]].mean())

    for part in ("elbow", "knee", "ankle"):   # limbs: 0.2-0.4 m apart in depth
        assert mean("right", part) < mean("left", part) - 0.5 * cfg.far_side_drop
    for part in ("shoulder", "hip"):          # trunk: MediaPipe's confidence saturates there
        assert mean("right", part) == pytest.approx(mean("left", part), abs=0.02)


def test_landmarks_behind_the_torso_are_less_confident():
    clip = walking_clip(speed=0.0)
    joints = clip.joints.copy()
    for side, y in (("l", 0.05), ("r", -0.05)):   # hands folded in front of the belly
        joints[:, JOINT_INDEX[f"{side}_wrist"]] = (0.2, y, 1.1)
    clip = dataclasses.replace(clip, joints=joints)
    wrist = LANDMARK_INDEX["left_wrist"]
    front = simulate_detections(clip, dataclasses.replace(NOISELESS, azimuth_deg=0.0))
    back = simulate_detections(clip, dataclasses.replace(NOISELESS, azimuth_deg=180.0))
    conf_front = front.observations.keypoints2d[:, wrist, 2].mean()
    conf_back = back.observations.keypoints2d[:, wrist, 2].mean()
    assert conf_back < conf_front - 0.3


def test_outliers_and_swaps():
    clip = walking_clip(200, speed=0.0)
    sim = simulate_detections(clip, dataclasses.replace(NOISELESS, outlier_rate=0.1, seed=4))
    jump = np.linalg.norm(sim.observations.keypoints2d[..., :2] - sim.landmarks2d, axis=-1)
    assert sim.outliers.mean() == pytest.approx(0.1, abs=0.02)
    size = person_size(sim)[:, None]
    assert (jump[sim.outliers] >= (0.13 * size - 1e-6).repeat(33, 1)[sim.outliers]).all()
    assert (jump[~sim.outliers] < 1e-6).all()
    kp = sim.observations.keypoints2d
    in_view = ((kp[..., :2] >= 0) & (kp[..., :2] <= (1920, 1080))).all(axis=-1)
    assert (kp[sim.outliers & in_view, 2] >= 0.5).all()      # moderately high confidence
    assert (kp[~in_view, 2] <= 0.05).all()                   # outside the image: low

    sim = simulate_detections(clip, dataclasses.replace(NOISELESS, swap_rate=0.2, seed=4))
    kp = sim.observations.keypoints2d[..., :2]
    assert sim.swapped.any()
    left, right = LANDMARK_INDEX["left_knee"], LANDMARK_INDEX["right_knee"]
    rows = sim.swapped[:, left]
    assert kp[rows, left] == pytest.approx(sim.landmarks2d[rows, right])
    assert kp[~rows, left] == pytest.approx(sim.landmarks2d[~rows, left])
    assert (sim.swapped[:, left] == sim.swapped[:, right]).all()


def test_the_outlier_mask_marks_the_detections_after_their_swaps():
    clip = walking_clip(200, speed=0.0)
    sim = simulate_detections(clip, dataclasses.replace(NOISELESS, outlier_rate=0.1,
                                                        swap_rate=0.2, seed=4))
    truth, expected = sim.landmarks2d, sim.landmarks2d.copy()   # where each slot's belongs
    for k, name in enumerate(LANDMARK_NAMES):
        if name.startswith("left_"):
            j, rows = LANDMARK_INDEX["right_" + name[5:]], sim.swapped[:, k]
            expected[rows, k], expected[rows, j] = truth[rows, j], truth[rows, k]
    jump = np.linalg.norm(sim.observations.keypoints2d[..., :2] - expected, axis=-1)
    assert (sim.outliers & sim.swapped).any()
    assert (jump[sim.outliers] > 1.0).all() and (jump[~sim.outliers] < 1e-6).all()
