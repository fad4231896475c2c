"""Metrics against hand-computed answers on small synthetic motions."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from physpose import metrics as m
from physpose.errors import PhysposeError
from physpose.joints import JOINT_INDEX, JOINT_NAMES

FPS = 25.0


def standing_pose() -> np.ndarray:
    """A rough standing skeleton (21, 3), facing +x, feet flat on z = 0."""
    p = {
        "pelvis": (0, 0, 0.95), "spine": (0, 0, 1.15), "thorax": (0, 0, 1.40),
        "neck": (0, 0, 1.50), "head": (0, 0, 1.62),
        "shoulder": (0, 0.18, 1.42), "elbow": (0, 0.20, 1.15), "wrist": (0, 0.21, 0.90),
        "hip": (0, 0.09, 0.92), "knee": (0.02, 0.10, 0.50), "ankle": (0, 0.10, 0.08),
        "heel": (-0.06, 0.10, 0.0), "toe": (0.19, 0.10, 0.0),
    }
    out = np.zeros((len(JOINT_NAMES), 3))
    for name, k in JOINT_INDEX.items():
        if name[:2] in ("l_", "r_"):
            x, y, z = p[name[2:]]
            out[k] = (x, y if name[0] == "l" else -y, z)
        else:
            out[k] = p[name]
    return out


def motion(offsets: np.ndarray) -> np.ndarray:
    """The standing pose translated by per-frame offsets (T, 3). -> (T, 21, 3)"""
    return standing_pose()[None] + np.asarray(offsets, dtype=float)[:, None, :]


def rot_z(deg: float) -> np.ndarray:
    a = np.deg2rad(deg)
    return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])


def test_sliding_foot_in_contact_skates_every_frame():
    slide = motion(np.outer(np.arange(10), [0.03, 0, 0]))   # 3 cm per frame, feet on the floor
    assert m.foot_contacts(slide).all()
    assert m.foot_skate(slide, fps=25.0) == 100.0
    slow = motion(np.outer(np.arange(10), [0.015, 0, 0]))   # 1.5 cm per frame: below 2 cm
    assert m.foot_skate(slow, fps=25.0) == 0.0


def test_skate_reads_a_speed_so_the_frame_rate_does_not_change_it():
    """0.4 m/s is under the paper's 2 cm per frame at 25 fps (0.5 m/s); filmed at 12.5 fps the
    same slide moves 3.2 cm between frames and still does not skate, and 0.6 m/s skates at
    every rate."""
    for fps in (12.5, 25.0, 60.0):
        step = np.outer(np.arange(10), [1.0 / fps, 0, 0])
        assert m.foot_skate(motion(0.4 * step), fps=fps) == 0.0
        assert m.foot_skate(motion(0.6 * step), fps=fps) == 100.0
    with pytest.raises(ValueError, match="frame rate"):
        m.foot_skate(motion(0.4 * step), fps=0.0)


def test_foot_in_the_air_does_not_skate():
    lifted = motion(np.outer(np.arange(10), [0.05, 0, 0]) + [0, 0, 0.10])
    assert not m.foot_contacts(lifted).any()
    assert m.foot_skate(lifted, fps=25.0) == 0.0


def test_foot_rolling_over_its_toe_is_not_skate():
    frames = []
    for k in range(6):   # one foot: heel rises and moves forward 3 cm a frame, toe stays put
        pose = standing_pose()
        heel = JOINT_INDEX["l_heel"]
        pose[heel] += (0.03 * k, 0.0, 0.0)
        frames.append(pose)
    assert m.foot_skate(np.stack(frames), fps=25.0) == 0.0


def test_hovering_foot_floats():
    assert m.foot_float(motion(np.tile([0, 0, 0.01], (5, 1)))) == 100.0   # 1 cm up
    assert m.foot_float(motion(np.tile([0, 0, 0.03], (5, 1)))) == 0.0     # 3 cm up: in the air
    assert m.foot_float(motion(np.zeros((5, 3)))) == 0.0                  # standing
    one = motion(np.zeros((4, 3)))
    one[:2, JOINT_INDEX["r_heel"], 2] += 0.012    # right foot lifted 1.2 cm in 2 of 4 frames
    one[:2, JOINT_INDEX["r_toe"], 2] += 0.012
    one[:2, JOINT_INDEX["r_ankle"], 2] += 0.012
    assert m.foot_float(one) == 50.0


def test_contact_needs_n_points_below_threshold():
    pose = standing_pose()
    # Tilt the left foot toe-up by lifting the toe 8 cm: only the heel row stays below 5 mm.
    pose[JOINT_INDEX["l_toe"], 2] = 0.08
    contacts = m.foot_contacts(pose[None])
    assert contacts[0].tolist() == [False, True]
    points = m.foot_points(pose[None])[0, 0]
    assert points.shape == (72, 3)
    assert (points[:, 2] < 0.005).sum() == 6   # one row of the 12 x 6 grid


def test_contact_presets_differ_on_a_sunken_foot():
    sunken = motion(np.tile([0, 0, -0.01], (3, 1)))   # 1 cm into the floor
    assert m.foot_contacts(sunken, m.CONTACT_PRESETS["kinematics"]).all()
    assert not m.foot_contacts(sunken, m.CONTACT_PRESETS["dynamics"]).any()
    assert m.DYNAMIC_CONTACT.threshold == -0.015 and m.KINEMATIC_CONTACT.threshold == 0.005
    assert m.ground_penetration(sunken) == pytest.approx((10.0, 10.0))
    assert m.ground_penetration(motion(np.zeros((3, 3)))) == (0.0, 0.0)


def test_procrustes_removes_rotation_translation_and_scale():
    rng = np.random.default_rng(0)
    gt = motion(rng.normal(0, 0.1, (5, 3))) + rng.normal(0, 0.05, (5, 21, 3))
    est = 1.3 * gt @ rot_z(40).T + [0.5, -2.0, 0.3]
    assert m.mpjpe_pa(est, gt) == pytest.approx(0.0, abs=1e-6)
    assert m.mpjpe(est, gt) > 50.0
    mirrored = gt * [1, -1, 1]      # a reflection is not a rotation: PA must not undo it
    assert m.mpjpe_pa(mirrored, gt) > 10.0


def test_mpjpe_g_vs_mpjpe_on_translated_copies():
    gt = motion(np.outer(np.arange(5), [0.1, 0, 0]))
    shifted = gt + [1.0, 2.0, 0.5]                       # constant offset: both 0
    assert m.mpjpe_g(shifted, gt) == pytest.approx(0.0, abs=1e-9)
    assert m.mpjpe(shifted, gt) == pytest.approx(0.0, abs=1e-9)
    drift = gt + np.arange(5)[:, None, None] * [0.01, 0, 0]   # 1 cm more each frame
    assert m.mpjpe(drift, gt) == pytest.approx(0.0, abs=1e-9)
    assert m.mpjpe_g(drift, gt) == pytest.approx(np.mean([0, 10, 20, 30, 40]))


def test_mpjpe_root_alignment_is_per_frame():
    gt = motion(np.zeros((2, 3)))
    est = gt.copy()
    est[1] += 0.2                       # frame 1 translated by (0.2, 0.2, 0.2)
    est[:, JOINT_INDEX["l_wrist"]] += [0.03, 0.0, 0.04]   # wrist 5 cm off in both frames
    assert m.mpjpe(est, gt) == pytest.approx(50.0 / 21)
    assert m.mpjpe_g(est, gt) == pytest.approx(
        (50.0 / 21 + np.mean(np.linalg.norm(est[1] - gt[1], axis=-1)) * 1000) / 2)


def test_velocity_error_on_known_motions():
    t = np.arange(6)[:, None]
    gt = motion(np.zeros((6, 3)))
    est = motion(t * [0.02, 0, 0])                       # 0.5 m/s, truth still
    assert m.velocity_error(est, gt, FPS) == pytest.approx(0.5)
    along_x = motion(t * [0.04, 0, 0])                   # 1 m/s along x vs along y
    along_y = motion(t * [0, 0.04, 0]) + [3.0, 0, 0]
    assert m.velocity_error(along_y, along_x, FPS) == pytest.approx(0.0, abs=1e-9)
    faster = motion(t * [0.06, 0, 0])                    # 1.5 m/s vs 1 m/s
    assert m.velocity_error(faster, along_x, FPS) == pytest.approx(0.5)


def test_jitter_zero_for_constant_velocity_and_equal_to_acceleration():
    t = np.arange(8)[:, None] / FPS
    assert m.jitter(motion(t * [1.0, -0.5, 0.2]), FPS) == pytest.approx(0.0, abs=1e-9)
    accel = motion(0.5 * t ** 2 * [3.0, 0.0, 4.0])        # |a| = 5 m/s^2
    assert m.jitter(accel, FPS) == pytest.approx(5.0)


def test_mpjpe_2d_confidence_weighting():
    target = np.zeros((1, 2, 2))
    est = np.array([[[3.0, 4.0], [0.0, 10.0]]])          # errors 5 and 10 px
    assert m.mpjpe_2d(est, target) == pytest.approx(7.5)
    assert m.mpjpe_2d(est, target, np.array([[1.0, 0.0]])) == pytest.approx(5.0)
    assert m.mpjpe_2d(est, target, np.array([[3.0, 1.0]])) == pytest.approx(6.25)


def test_mpjpe_2d_without_weight_is_nan_and_refuses_negative_weights():
    target = np.zeros((1, 2, 2))
    est = np.array([[[3.0, 4.0], [0.0, 10.0]]])
    assert np.isnan(m.mpjpe_2d(est, target, np.zeros((1, 2))))   # nothing sure to compare
    with pytest.raises(ValueError, match="non-negative"):
        m.mpjpe_2d(est, target, np.array([[1.0, -1.0]]))
    with pytest.raises(ValueError, match="shape"):
        m.mpjpe_2d(est, target, np.ones((2, 2)))


def test_evaluate_compares_in_a_common_frame():
    gt = motion(np.outer(np.arange(6), [0.05, 0.01, 0]))
    T_world2cam = np.eye(4)
    T_world2cam[:3, :3] = np.array([[0, -1, 0], [0, 0, -1], [1, 0, 0]]) @ rot_z(20)
    T_world2cam[:3, 3] = [0.1, 1.0, 4.0]
    est_cam = m.transform_points(T_world2cam, gt)        # the estimate in camera coordinates
    T_cam2world = np.linalg.inv(T_world2cam)
    res = m.evaluate(gt, gt, fps=FPS, T_est2common=None, T_gt2common=T_world2cam)
    assert res["mpjpe_g_mm"] > 100                       # world vs camera frame: far apart
    res = m.evaluate(m.transform_points(T_cam2world, est_cam), gt, fps=FPS)
    assert res["mpjpe_g_mm"] == pytest.approx(0.0, abs=1e-6)
    assert res["velocity_error_mps"] == pytest.approx(0.0, abs=1e-9)
    assert {"mpjpe_mm", "mpjpe_pa_mm", "foot_skate_pct", "float_pct", "penetration_mean_mm",
            "penetration_max_mm", "jitter_mps2"} <= res.keys()
    assert "mpjpe_2d_px" not in res
    K = np.array([[1000.0, 0, 960], [0, 1000.0, 540], [0, 0, 1]])
    uv = m.project(gt, K, T_world2cam)
    res = m.evaluate(gt, fps=FPS, est_2d=uv + [3.0, 4.0], target_2d=uv)
    assert res["mpjpe_2d_px"] == pytest.approx(5.0)
    assert "mpjpe_g_mm" not in res


def test_fallen_counts_frames_with_the_head_below_half_the_references():
    stand = motion(np.zeros((10, 3)))
    lying = stand.copy()
    lying[6:, :, 2] *= 0.3                               # frames 6-9: everything near the floor
    assert m.fallen(lying, stand) == pytest.approx(40.0)
    assert m.fallen(stand, stand) == 0.0
    assert m.fallen(lying, lying) == 0.0                 # the reference lies down too: no fall
    res = m.evaluate(lying, stand, fps=FPS)
    assert res["fallen_pct"] == pytest.approx(40.0)      # defaults to the truth
    res = m.evaluate(lying, fps=FPS, fall_reference=stand)
    assert res["fallen_pct"] == pytest.approx(40.0)
    assert "fallen_pct" not in m.evaluate(lying, fps=FPS)


def test_a_head_only_a_little_lower_than_a_reference_down_on_the_floor_has_not_fallen():
    head = JOINT_INDEX["head"]
    ref = motion(np.zeros((4, 3)))
    est = ref.copy()
    ref[:, head, 2] = (0.15, 0.15, 0.7, 1.5)   # rolling on the floor, then crouching, standing
    est[:, head, 2] = (0.06, 0.14, 0.3, 0.7)
    # frame 0: under half the reference's height, but only 9 cm lower (both on the floor);
    # frames 2 and 3: under half and 40-80 cm lower
    assert m.fallen(est, ref) == pytest.approx(50.0)


def test_project_matches_pinhole_model():
    K = np.array([[800.0, 0, 320], [0, 800.0, 240], [0, 0, 1]])
    uv = m.project(np.array([[0.5, -0.25, 2.0]]), K, np.eye(4))
    assert uv == pytest.approx(np.array([[320 + 200.0, 240 - 100.0]]))


def test_shape_mismatch_is_rejected():
    with pytest.raises(ValueError):
        m.mpjpe(np.zeros((3, 21, 3)), np.zeros((4, 21, 3)))


@pytest.mark.parametrize("kwargs, match", [
    (dict(est=np.zeros((5, 33, 3)).tolist()), "33 joints given for 21 joint names"),
    (dict(fps=0.0), "frame rate 0.0 must be positive"),
    (dict(est_2d=np.zeros((5, 21, 2))), "needs both est_2d and target_2d"),
])
def test_evaluate_refuses_what_it_would_score_wrongly(kwargs, match):
    # (landmarks had been scored as joints, a zero rate gave a jitter of 0, and a lone est_2d
    # dropped MPJPE-2d without a word)
    args = dict(est=np.zeros((5, 21, 3)), fps=25.0) | kwargs
    with pytest.raises(PhysposeError, match=match):
        m.evaluate(args.pop("est"), **args)


@pytest.mark.parametrize("frames", [1, 2])
def test_a_motion_too_short_for_a_metric_scores_nan_without_warnings(frames):
    # Velocities need two frames, accelerations three; a metric a clip cannot have is NaN
    # (which the benchmark's means skip), and the others are still scored.
    gt = motion(np.zeros((frames, 3)))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = m.evaluate(gt + 0.01, gt, fps=FPS)
    assert np.isnan(res["jitter_mps2"])
    assert np.isnan(res["velocity_error_mps"]) == (frames == 1)
    assert np.isnan(res["foot_skate_pct"]) == (frames == 1)
    assert res["mpjpe_mm"] == pytest.approx(0.0, abs=1e-9)
    assert res["mpjpe_g_mm"] == pytest.approx(0.0, abs=1e-9)
