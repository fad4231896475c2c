"""The benchmark runner end to end on a tiny synthetic walk, with oracle and failing variants."""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from physpose.benchmark import VARIANTS, get_variant, register_variant, write_results
from physpose.benchmark.baseline import level_ground_frame, solve_root_translation
from physpose.benchmark.material import (Clip, Material, MaterialConfig, _observe_config,
                                         _reference_without, crop_mocap, load_clips, mocap_clip,
                                         uniform_fps)
from physpose.benchmark.oracle import FOOT_LANDMARKS, SOLE_JOINTS, STANCE_HEIGHT, truth_on_body
from physpose.benchmark.report import aggregate, render_markdown
from physpose.benchmark.runner import (BenchmarkConfig, results_document, run_benchmark, run_clips,
                                      run_variant)
from physpose.benchmark.scoring import TRUTH_ROW, truth_record
from physpose.cli import main
from physpose.errors import PhysposeError
from physpose.joints import JOINT_INDEX, JOINT_NAMES, LANDMARK_INDEX, joints_from_landmarks
from physpose.metrics import project, transform_points
from physpose.mocap import MocapClip
from physpose.multiview.reference import ReferenceConfig, triangulate_observations
from physpose.reconstruction import Reconstruction
from synthetic_video import make_video
from test_triangulate import _project, _rig

FPS = 25.0


def _walk(seconds: float = 1.2, fps: float = FPS) -> MocapClip:
    """A stick figure walking along +x at 1 m/s with swinging legs, z up, feet on z = 0."""
    t = np.arange(int(round(seconds * fps))) / fps
    phase = 2 * np.pi * 1.8 * t
    pts: dict[str, np.ndarray] = {}
    root = np.stack([t, 0 * t, 0.95 + 0 * t], 1)
    for sign, s in ((1, "l"), (-1, "r")):
        swing = sign * 0.2 * np.sin(phase)[:, None] * np.array([1.0, 0, 0])
        lift = np.maximum(0, sign * np.cos(phase))[:, None] * np.array([0, 0, 0.08])
        side = np.array([0, sign * 0.1, 0])
        pts[f"{s}_hip"] = root + side
        pts[f"{s}_knee"] = root + side + 0.5 * swing + lift + [0.03, 0, -0.45]
        pts[f"{s}_ankle"] = root + side + swing + lift + [0, 0, -0.87]
        pts[f"{s}_heel"] = pts[f"{s}_ankle"] + [-0.05, 0, -0.06]
        pts[f"{s}_toe"] = pts[f"{s}_ankle"] + [0.15, 0, -0.07]
        pts[f"{s}_shoulder"] = root + [0, sign * 0.18, 0.5]
        pts[f"{s}_elbow"] = pts[f"{s}_shoulder"] - 0.5 * swing + [0, 0, -0.3]
        pts[f"{s}_wrist"] = pts[f"{s}_elbow"] - 0.5 * swing + [0.05, 0, -0.27]
    head = root + [0, 0, 0.67]
    pelvis, thorax = root, root + [0, 0, 0.5]
    trunk = {"pelvis": pelvis, "thorax": thorax, "spine": 0.5 * (pelvis + thorax), "head": head,
             "neck": 0.5 * (thorax + head)}
    joints = np.stack([trunk.get(n, pts.get(n)) for n in JOINT_NAMES], 1)
    n = len(t)
    hand = np.array([[0, 1.0, 0], [0, 0, 1.0], [-1.0, 0, 0]]).T  # fingers down, thumb forward
    return MocapClip(name="walk", source="synthetic_walk.bvh", fps=fps, joints=joints,
                     head_top=head + [0, 0, 0.12], head_rot=np.tile(np.eye(3), (n, 1, 1)),
                     hand_rot=np.tile(hand, (n, 2, 1, 1)), source_fps=fps, floor_offset=0.0)


@pytest.fixture(scope="module")
def clip() -> Clip:
    return mocap_clip(_walk(), MaterialConfig(max_seconds=1.0), name="walk")


def test_noiseless_material_sees_the_truth(clip):
    clean = mocap_clip(_walk(), MaterialConfig(max_seconds=1.0, noiseless=True), name="walk")
    hips = [LANDMARK_INDEX["left_hip"], LANDMARK_INDEX["right_hip"]]
    truth = project(clean.truth.joints[:, [JOINT_INDEX["l_hip"], JOINT_INDEX["r_hip"]]],
                    clean.truth.K, clean.truth.T_world2cam)
    np.testing.assert_allclose(clean.observations.keypoints2d[:, hips, :2], truth, atol=1e-6)
    assert np.abs(clip.observations.keypoints2d[:, hips, :2] - truth).max() > 1.0  # default


def test_cli_noiseless_flag_reaches_the_material(tmp_path, monkeypatch):
    seen = {}

    def fake_run(materials, cfg, **kwargs):
        seen["cfg"] = cfg
        return results_document([], [], cfg)

    monkeypatch.setattr("physpose.cli.benchmark.run_benchmark", fake_run)
    clip_file = tmp_path / "x.bvh"
    clip_file.write_text("")  # exists; the fake runner does not read it
    assert main(["benchmark", "--mocap", str(clip_file), "--noiseless",
                 "--out", str(tmp_path / "out")]) == 0
    assert seen["cfg"].material.noiseless and not seen["cfg"].material.truth_input
    assert main(["benchmark", "--mocap", str(clip_file), "--truth-input",
                 "--out", str(tmp_path / "out")]) == 0
    assert not seen["cfg"].material.noiseless and seen["cfg"].material.truth_input


def test_slow_motion_footage_plays_the_capture_slower_and_is_scored_on_the_real_clock(
        clip, monkeypatch):
    slow = mocap_clip(_walk(fps=4 * FPS), MaterialConfig(max_seconds=1.0, slow_motion=4),
                      name="walk")
    obs = slow.observations
    assert obs.fps == FPS and obs.num_frames == 4 * clip.observations.num_frames
    assert obs.timestamps[-1] == pytest.approx((obs.num_frames - 1) / FPS)  # 4 s of footage
    assert slow.score_step == 4 and len(slow.truth.joints) == obs.num_frames
    # Every 4th frame is the motion at 25 Hz: the truth's own row matches the real-time clip's.
    assert truth_record(slow)["metrics"] == pytest.approx(truth_record(clip)["metrics"])
    # The truth's poses, one per footage frame, score zero on the real frames (what a slowed
    # clock costs is the physics': its gravity and speeds, not the scoring).
    monkeypatch.setitem(VARIANTS, "test_oracle", _oracle(slow, yaw_deg=0.0))
    row = run_variant("test_oracle", slow)
    for key in ("mpjpe_g_mm", "mpjpe_pa_mm", "velocity_error_mps", "mpjpe_2d_px"):
        assert row["metrics"][key] == pytest.approx(0.0, abs=1e-6), key
    monkeypatch.setitem(VARIANTS, "test_oracle_real", _oracle(clip, yaw_deg=0.0))
    real = run_variant("test_oracle_real", clip)   # accelerations read at the real rate
    assert row["metrics"]["jitter_mps2"] == pytest.approx(real["metrics"]["jitter_mps2"])


def test_cli_slow_motion_reaches_the_material_and_leaves_out_real_footage(tmp_path,
                                                                          monkeypatch):
    seen = {}

    def fake_run(materials, cfg, **kwargs):
        seen.update(cfg=cfg, materials=materials, skipped=kwargs.get("skipped"))
        return results_document([], [], cfg)

    monkeypatch.setattr("physpose.cli.benchmark.run_benchmark", fake_run)
    shared = [Material("mocap", tmp_path / "a.bvh"), Material("video", tmp_path / "b.mp4")]
    monkeypatch.setattr("physpose.cli.benchmark.shared_material", lambda: (shared, []))
    assert main(["benchmark", "--slow-motion", "4", "--out", str(tmp_path / "out")]) == 0
    assert seen["cfg"].material.slow_motion == 4
    assert [m.kind for m in seen["materials"]] == ["mocap"]
    assert any("b.mp4" in m and "motion capture only" in m for m in seen["skipped"])


def test_the_report_says_the_footage_was_slowed():
    slowed = render_markdown(results_document(
        [], [], BenchmarkConfig(material=MaterialConfig(slow_motion=3))))
    assert "3x slow footage, not declared" in slowed and "one frame in 3" in slowed
    assert "slow footage" not in render_markdown(results_document([], [], BenchmarkConfig()))


def test_slow_motion_is_refused_where_it_cannot_apply(tmp_path):
    with pytest.raises(PhysposeError, match="whole number"):
        MaterialConfig(slow_motion=0)
    video = tmp_path / "v.mp4"
    video.write_bytes(b"")
    with pytest.raises(PhysposeError, match="only motion capture"):
        load_clips(Material("video", video), MaterialConfig(slow_motion=2))


def _oracle(truth_clip: Clip, yaw_deg: float = 40.0):
    """A variant returning the truth in a world turned and shifted about z (with its camera)."""
    a = np.radians(yaw_deg)
    T_old2new = np.eye(4)
    T_old2new[:3, :3] = [[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]]
    T_old2new[:3, 3] = [3.0, -1.0, 0.0]

    def oracle(obs, context):
        joints = transform_points(T_old2new, truth_clip.truth.joints)
        return Reconstruction(
            fps=obs.fps, joint_names=JOINT_NAMES, joints_kinematic=joints,
            camera_K=truth_clip.truth.K,
            camera_T_world2cam=truth_clip.truth.T_world2cam @ np.linalg.inv(T_old2new),
            landmarks_kinematic=np.zeros((obs.num_frames, 33, 3)),
            keypoints2d=obs.keypoints2d)
    return oracle


def test_clip_is_cropped_and_carries_the_known_camera(clip):
    assert clip.observations.num_frames == 25
    assert clip.truth.joints.shape == (25, len(JOINT_NAMES), 3)
    np.testing.assert_array_equal(clip.context.camera_K, clip.truth.K)
    assert clip.context.camera_T_world2cam is None and clip.context.person_height is None


def test_oracle_scores_zero_whatever_its_world_yaw(clip, monkeypatch):
    monkeypatch.setitem(VARIANTS, "test_oracle", _oracle(clip))
    results, failures = run_clips([clip], ["test_oracle"], log=lambda m: None)
    assert not failures
    truth_row, row = results
    assert truth_row["variant"] == TRUTH_ROW and "mpjpe_g_mm" not in truth_row["metrics"]
    m, g = row["metrics"], row["ground"]
    for key in ("mpjpe_g_mm", "mpjpe_mm", "mpjpe_pa_mm", "velocity_error_mps", "mpjpe_2d_px"):
        assert m[key] == pytest.approx(0.0, abs=1e-6), key
    assert g["normal_angle_error_deg"] == pytest.approx(0.0, abs=1e-4)
    assert g["camera_height_error_pct"] == pytest.approx(0.0, abs=1e-6)
    assert m["foot_skate_pct"] == truth_row["metrics"]["foot_skate_pct"]


def test_a_displaced_estimate_scores_its_displacement(clip, monkeypatch):
    oracle = _oracle(clip, yaw_deg=0.0)

    def lifted(obs, context):  # every joint 10 cm too high except the first frame's offset
        rec = oracle(obs, context)
        joints = rec.joints_kinematic.copy()
        joints[1:, :, 2] += 0.1
        return rec.replace(joints_kinematic=joints)

    monkeypatch.setitem(VARIANTS, "test_lifted", lifted)
    (_, row), _ = run_clips([clip], ["test_lifted"], log=lambda m: None)
    frames = clip.observations.num_frames
    assert row["metrics"]["mpjpe_g_mm"] == pytest.approx(100 * (frames - 1) / frames, rel=1e-6)
    assert row["metrics"]["mpjpe_mm"] == pytest.approx(0.0, abs=1e-6)
    assert row["metrics"]["mpjpe_2d_px"] > 1


def test_baseline_on_the_simulated_walk(clip):
    (_, row), failures = run_clips([clip], ["baseline"], log=lambda m: None)
    assert not failures
    m = row["metrics"]
    assert 0 < m["mpjpe_pa_mm"] <= m["mpjpe_mm"] < 250
    assert m["mpjpe_2d_px"] < 40
    assert row["time_s"]["variant"] > 0 and "simulate" in row["time_s"]
    # the level-camera guess is off by the virtual camera's downward pitch
    assert 1 < row["ground"]["normal_angle_error_deg"] < 45


def test_video_kind_scores_against_detections(clip, monkeypatch):
    video = Clip(kind="video", name="v", source="v.mp4", observations=clip.observations,
                 context=clip.context, truth=None, timings_s={"observe": 0.0})
    K = clip.truth.K

    def on_rays(obs, context):  # puts every joint 3 m away along the ray of its detection
        uv = joints_from_landmarks(obs.keypoints2d[..., :2])
        rays = np.concatenate([uv, np.ones(uv.shape[:-1] + (1,))], -1) @ np.linalg.inv(K).T
        return Reconstruction(fps=obs.fps, joint_names=JOINT_NAMES, joints_kinematic=3 * rays,
                              camera_K=K, camera_T_world2cam=np.eye(4),
                              landmarks_kinematic=np.zeros((obs.num_frames, 33, 3)),
                              keypoints2d=obs.keypoints2d)

    monkeypatch.setitem(VARIANTS, "test_rays", on_rays)
    (row,), _ = run_clips([video], ["test_rays"], log=lambda m: None)
    assert row["metrics"]["mpjpe_2d_px"] == pytest.approx(0.0, abs=1e-6)
    assert "mpjpe_g_mm" not in row["metrics"] and "normal_angle_error_deg" not in row["ground"]


def test_failures_are_recorded_and_bugs_propagate(clip, monkeypatch):
    def refuses(obs, context):
        raise PhysposeError("cannot handle this clip")

    def buggy(obs, context):
        raise ZeroDivisionError

    monkeypatch.setitem(VARIANTS, "test_refuses", refuses)
    monkeypatch.setitem(VARIANTS, "test_buggy", buggy)
    results, failures = run_clips([clip], ["test_refuses"], log=lambda m: None)
    assert [r["variant"] for r in results] == [TRUTH_ROW]
    assert failures[0]["variant"] == "test_refuses" and "cannot handle" in failures[0]["error"]
    with pytest.raises(ZeroDivisionError):
        run_clips([clip], ["test_buggy"], log=lambda m: None)


def test_results_files(clip, tmp_path, monkeypatch):
    monkeypatch.setitem(VARIANTS, "test_oracle", _oracle(clip))
    results, failures = run_clips([clip], ["baseline", "test_oracle"], log=lambda m: None)
    doc = results_document(results, failures, BenchmarkConfig(variants=("baseline",)),
                           skipped=["no videos"], command="physpose benchmark --out x")
    json_path, md_path = write_results(doc, tmp_path / "out")
    loaded = json.loads(json_path.read_text())
    assert loaded["aggregate"]["mocap"]["test_oracle"]["mpjpe_g_mm"] == pytest.approx(0, abs=1e-6)
    assert set(loaded["aggregate"]["mocap"]) == {TRUTH_ROW, "baseline", "test_oracle"}
    md = md_path.read_text()
    assert "| Variant | MPJPE-G (mm) | MPJPE (mm) | MPJPE-PA (mm) | MPJPE-2d (px)" in md
    assert "| baseline |" in md and "| walk | test_oracle | 25 |" in md
    assert "skipped: no videos" in md


def test_aggregate_means_over_clips_ignoring_missing_values():
    rows = [{"kind": "video", "variant": "v", "metrics": {"a": 1.0, "b": float("nan")},
             "ground": {}, "time_s": {"variant": 2.0}},
            {"kind": "video", "variant": "v", "metrics": {"a": 3.0, "b": 4.0}, "ground": {},
             "time_s": {"variant": 4.0}}]
    agg = aggregate(rows)["video"]["v"]
    assert agg == {"a": 2.0, "b": 4.0, "time_s.variant": 3.0, "clips": 2}


def test_baseline_translation_is_exact_without_noise():
    rng = np.random.default_rng(0)
    world = rng.uniform(-0.4, 0.4, (6, 33, 3))
    world[:, 23:25] -= world[:, 23:25].mean(1, keepdims=True)
    t_true = np.stack([rng.uniform(-1, 1, 6), rng.uniform(-0.5, 0.5, 6), rng.uniform(3, 6, 6)], 1)
    K = np.array([[1200.0, 0, 640], [0, 1200.0, 360], [0, 0, 1]])
    cam = world + t_true[:, None]
    uv = cam @ K.T
    kp = np.concatenate([uv[..., :2] / uv[..., 2:], np.ones((6, 33, 1))], -1)
    kp[2, :31, 2] = 0.0  # only two confident landmarks: frame cannot be placed
    t, ok = solve_root_translation(world, kp, K)
    assert ok.tolist() == [True, True, False, True, True, True]
    np.testing.assert_allclose(t[ok], t_true[ok], atol=1e-6)
    assert np.isnan(t[2]).all()


def test_the_baseline_turns_the_world_landmarks_out_of_the_ray_frame():
    """The world landmarks come in the frame of the ray through the hips (MediaPipe's, and the
    simulator's since stop 74); seen from 4 m up, taking them in camera axes tilts the body
    by the ray's angle. Turned back by the detected hips' ray, they fall on the truth."""
    from physpose.benchmark.baseline import BaselineConfig, place_landmarks
    from physpose.detector_sim import DetectorSimConfig, simulate_detections

    sim = simulate_detections(_walk(), DetectorSimConfig.noiseless(height=4.0, distance=3.0))
    truth = transform_points(sim.camera_T_world2cam, sim.landmarks)
    error = {aligned: np.linalg.norm(place_landmarks(sim.observations, sim.camera_K,
                                                     BaselineConfig(ray_aligned_world=aligned))
                                     - truth, axis=-1).mean()
             for aligned in (True, False)}
    assert error[True] < 0.01 and error[False] > 0.05


def test_level_ground_frame_puts_the_lowest_feet_on_the_floor():
    lm = np.zeros((10, 33, 3))
    lm[..., 1] = 1.5            # camera y points down: everything 1.5 m below the camera
    lm[..., 2] = 4.0
    T = level_ground_frame(lm, percentile=10)
    world = transform_points(np.linalg.inv(T), lm)
    np.testing.assert_allclose(world[..., 2], 0.0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.inv(T)[:3, 3], [0, 0, 1.5])


def test_registry():
    assert get_variant("baseline") is VARIANTS["baseline"]
    with pytest.raises(PhysposeError, match="unknown variant 'nope'.*baseline"):
        get_variant("nope")
    with pytest.raises(ValueError, match="already registered"):
        register_variant("baseline", lambda obs, ctx: None)
    assert register_variant("baseline", VARIANTS["baseline"]) is VARIANTS["baseline"]


def test_uniform_fps():
    assert uniform_fps(60.0, 25.0) == 30.0
    assert uniform_fps(23.976, 25.0) == 23.976
    assert uniform_fps(100.0, 25.0) == 25.0


def test_cli_errors(tmp_path, capsys):
    assert main(["benchmark", "--variant", "nope", "--out", str(tmp_path)]) == 2
    assert "unknown variant(s) nope" in capsys.readouterr().err
    assert main(["benchmark", "--mocap", str(tmp_path / "x.bvh"), "--out", str(tmp_path)]) == 2
    assert "mocap input not found" in capsys.readouterr().err
    assert main(["benchmark", "--multiview", str(tmp_path), "--out", str(tmp_path)]) == 2
    assert "calibration" in capsys.readouterr().err
    assert main(["benchmark", "--variant", "list"]) == 0
    assert "baseline" in capsys.readouterr().out.split()
    assert main(["benchmark", "--video", str(tmp_path)]) == 2
    assert "--out" in capsys.readouterr().err


def test_a_later_segment_is_cut_from_its_start_and_named_by_it():
    walk = _walk()
    late = mocap_clip(walk, MaterialConfig(max_seconds=0.4, start_seconds=0.6), name="walk@0.6s")
    first = int(round(0.6 * walk.fps))
    assert late.truth.joints.shape[0] == int(round(0.4 * walk.fps))
    np.testing.assert_allclose(late.truth.joints[0], walk.joints[first])
    cut = crop_mocap(walk, 10.0, start_seconds=99.0)  # past the end: the last two frames
    np.testing.assert_array_equal(cut.joints, walk.joints[-2:])


def test_the_camera_azimuth_moves_the_virtual_camera():
    front = mocap_clip(_walk(), MaterialConfig(max_seconds=0.4), name="walk")
    side = mocap_clip(_walk(), MaterialConfig(max_seconds=0.4, camera_azimuth_deg=90.0),
                      name="walk")
    z_front, z_side = front.truth.T_world2cam[2, :3], side.truth.T_world2cam[2, :3]  # view axes
    angle = np.degrees(np.arccos(np.clip(z_front @ z_side, -1, 1)))
    assert angle == pytest.approx(60.0, abs=5.0)  # 30 -> 90 degrees about the vertical


def test_the_camera_height_raises_the_virtual_camera_to_look_down():
    default = mocap_clip(_walk(), MaterialConfig(max_seconds=0.4), name="walk")
    high = mocap_clip(_walk(), MaterialConfig(max_seconds=0.4, camera_height=3.0), name="walk")
    for clip, height in ((default, 1.3), (high, 3.0)):
        T = clip.truth.T_world2cam
        centre = -T[:3, :3].T @ T[:3, 3]
        assert centre[2] == pytest.approx(height)
    pitch = np.degrees(np.arcsin(-high.truth.T_world2cam[2, 2]))  # view axis below horizontal
    assert pitch > 10.0


@pytest.mark.parametrize("height", [0.0, -1.0, float("nan"), 50.0])
def test_a_camera_height_out_of_range_is_refused(height):
    with pytest.raises(PhysposeError, match="--camera-height"):
        MaterialConfig(camera_height=height)


def test_cli_start_past_a_clips_end_is_a_failure_naming_the_file(tmp_path, monkeypatch):
    from physpose.benchmark import material as material_module
    monkeypatch.setattr(material_module, "load_mocap", lambda path, target_fps: _walk())
    clip_file = tmp_path / "walk.bvh"
    clip_file.write_text("")
    out = tmp_path / "out"
    assert main(["benchmark", "--mocap", str(clip_file), "--start", "60", "--out", str(out)]) == 1
    doc = json.loads((out / "results.json").read_text())
    assert doc["config"]["material"]["start_seconds"] == 60.0
    (failure,) = doc["failures"]
    assert "walk.bvh" in failure["error"] and "--start" in failure["error"]


def test_a_video_segment_is_observed_from_its_start(tmp_path):
    video = make_video(tmp_path / "v.mp4", n_frames=60, fps=10.0)  # 6 s
    cfg = _observe_config(video, MaterialConfig(start_seconds=1.5, max_seconds=2.0))
    assert (cfg.start, cfg.end) == (1.5, 3.5)
    whole = _observe_config(video, MaterialConfig(max_seconds=10.0))
    assert (whole.start, whole.end) == (None, None)
    with pytest.raises(PhysposeError, match="past its end"):
        _observe_config(video, MaterialConfig(start_seconds=6.5))


@pytest.fixture(scope="module")
def truth_clip() -> Clip:
    return mocap_clip(_walk(), MaterialConfig(max_seconds=0.4, noiseless=True, truth_input=True),
                      name="walk")


def test_truth_input_reaches_only_the_context_it_is_asked_for(clip, truth_clip):
    assert clip.context.truth_landmarks is None and clip.context.truth_T_world2cam is None
    assert truth_clip.context.truth_landmarks.shape == (10, 33, 3)
    np.testing.assert_allclose(truth_clip.context.truth_T_world2cam, truth_clip.truth.T_world2cam)


def test_truth_variants_refuse_clips_without_the_truth(clip):
    for name in ("truth-ik", "truth-reference", "dynamics-truth"):
        with pytest.raises(PhysposeError, match="--truth-input"):
            get_variant(name)(clip.observations, clip.context)


def test_truth_ik_puts_the_recorded_motion_onto_the_body(truth_clip):
    record = run_variant("truth-ik", truth_clip)
    # The stick figure is not physpose's skeleton, so IK cannot match it exactly.
    assert record["metrics"]["mpjpe_g_mm"] < 30.0
    assert record["metrics"]["mpjpe_2d_px"] < 10.0


def _truth_fit_of(landmarks, T_world2cam, truth_clip):
    return truth_on_body(landmarks, truth_clip.observations.fps, truth_clip.truth.K, T_world2cam)


def test_truth_on_body_stands_where_the_recorded_feet_stood(truth_clip):
    landmarks = truth_clip.context.truth_landmarks
    kin = _truth_fit_of(landmarks, truth_clip.truth.T_world2cam, truth_clip)
    # The body's heel and foot-index sites sit above its soles, the recording's on them: the
    # IK'd body reaches lower, and its world's floor is moved down to where its soles stand.
    feet = [LANDMARK_INDEX[n] for n in FOOT_LANDMARKS]
    truth_low = landmarks[:, feet, 2].min(axis=1)
    standing = truth_low < STANCE_HEIGHT
    body_low = kin.joints[:, [JOINT_INDEX[n] for n in SOLE_JOINTS], 2].min(axis=1)
    assert standing.sum() >= 5
    level = np.median(truth_low[standing])
    assert abs(np.median(body_low - (truth_low - level))) < 1e-9
    assert abs(np.median(body_low[standing])) < 0.01
    # Only the floor moved: in the camera the body is where the landmarks put it.
    in_camera = transform_points(kin.T_world2cam, kin.landmarks)
    truth_in_camera = transform_points(truth_clip.truth.T_world2cam, landmarks)
    assert np.linalg.norm(in_camera - truth_in_camera, axis=-1).mean() < 0.03


def test_truth_on_body_does_not_depend_on_where_the_recording_put_its_floor(truth_clip):
    landmarks = truth_clip.context.truth_landmarks
    T = truth_clip.truth.T_world2cam
    kin = _truth_fit_of(landmarks, T, truth_clip)
    # The same recording with its world 5 cm higher (floor, feet and camera moved together).
    lowered = landmarks - np.array([0.0, 0.0, 0.05])
    T_lowered = T.copy()
    T_lowered[:3, 3] += T[:3, :3] @ np.array([0.0, 0.0, 0.05])
    moved = _truth_fit_of(lowered, T_lowered, truth_clip)
    np.testing.assert_allclose(moved.qpos, kin.qpos, atol=1e-6)
    np.testing.assert_allclose(transform_points(moved.T_world2cam, moved.joints),
                               transform_points(kin.T_world2cam, kin.joints), atol=1e-6)


def test_truth_reference_is_the_truth_prepared_for_the_physics(truth_clip):
    ik = run_variant("truth-ik", truth_clip)["metrics"]
    record = run_variant("truth-reference", truth_clip)
    metrics = record["metrics"]
    # On the floor with flat standing feet and low-passed: near the IK'd truth, not on it.
    assert metrics["penetration_mean_mm"] < 5.0
    assert ik["mpjpe_g_mm"] < metrics["mpjpe_g_mm"] < ik["mpjpe_g_mm"] + 20.0
    assert "restarts" not in metrics


def test_dynamics_truth_follows_the_truth_with_physics(truth_clip):
    record = run_variant("dynamics-truth", truth_clip)
    assert record["metrics"]["restarts"] == 0.0
    assert record["metrics"]["fallen_pct"] == 0.0
    assert record["metrics"]["mpjpe_g_mm"] < 150.0


def test_a_run_stopped_midway_keeps_the_material_it_finished(clip, tmp_path, monkeypatch):
    """The results so far are written after each piece of material; a bug (or Ctrl-C) on a
    later one leaves them, marked as incomplete, instead of nothing."""
    monkeypatch.setattr("physpose.benchmark.runner.load_clips",
                        lambda material, cfg: [replace(clip, name=material.path.stem)])
    oracle = _oracle(clip)

    def breaks_on_the_second(obs, context):
        if breaks_on_the_second.calls:
            raise ZeroDivisionError
        breaks_on_the_second.calls += 1
        return oracle(obs, context)
    breaks_on_the_second.calls = 0
    monkeypatch.setitem(VARIANTS, "test_breaks", breaks_on_the_second)
    out = tmp_path / "out"
    materials = [Material("mocap", Path(f"{name}.bvh")) for name in ("first", "second", "third")]
    with pytest.raises(ZeroDivisionError):
        run_benchmark(materials, BenchmarkConfig(variants=("test_breaks",)), log=lambda m: None,
                      on_progress=lambda doc: write_results(doc, out))
    kept = json.loads((out / "results.json").read_text())
    assert [(r["clip"], r["variant"]) for r in kept["results"]] == [
        ("first", TRUTH_ROW), ("first", "test_breaks")]
    assert kept["pending"] == ["second.bvh", "third.bvh"]
    assert "**Incomplete**" in (out / "results.md").read_text()
    assert sorted(p.name for p in out.iterdir()) == ["results.json", "results.md"]


def _multiview_scene(shift_px: float):
    """Four synthetic cameras round a person whose 33 landmarks every view sees exactly, but
    view 2, whose detections are all `shift_px` to the right; the true landmarks."""
    rng = np.random.default_rng(3)
    truth = rng.uniform([-0.4, -0.4, 0.0], [0.4, 0.4, 1.8], size=(6, 33, 3))
    P = _rig()
    uv = _project(P, truth)
    uv[2, ..., 0] += shift_px
    cameras = tuple(SimpleNamespace(name=f"cam{i}", projection=P[i], undistort=lambda px: px)
                    for i in range(4))
    views = tuple(SimpleNamespace(keypoints2d=np.concatenate([uv[i], np.ones((6, 33, 1))], -1),
                                  valid=np.ones(6, bool)) for i in range(4))
    return SimpleNamespace(cameras=cameras, views=views), truth


def test_a_view_can_be_scored_against_the_reference_its_own_detections_did_not_build():
    ref, truth = _multiview_scene(shift_px=15.0)
    cfg = ReferenceConfig()
    every = joints_from_landmarks(triangulate_observations(ref.cameras, ref.views,
                                                           cfg.triangulation).points)
    others = _reference_without(ref, 2, cfg, Path("rig"))
    expected = joints_from_landmarks(truth)
    # The shifted view pulls the reference built from every view towards itself; the one
    # built without it is where the other three views put the person.
    assert np.linalg.norm(every - expected, axis=-1).mean() > 0.002
    np.testing.assert_allclose(others, expected, atol=1e-6)
    with pytest.raises(PhysposeError, match="multiview_truth"):
        MaterialConfig(multiview_truth="mine")


def test_leaving_out_a_view_that_a_landmark_needs_is_a_clear_error():
    ref, _ = _multiview_scene(shift_px=0.0)
    for i in (0, 1):  # landmark 5 is seen by views 2 and 3 only
        ref.views[i].keypoints2d[:, 5, 2] = 0.0
    with pytest.raises(PhysposeError, match="without view cam2, landmarks \\[5\\]"):
        _reference_without(ref, 2, ReferenceConfig(), Path("rig"))


@pytest.mark.skipif(platform.machine() not in ("x86_64", "AMD64"),
                    reason="OpenBLAS core types named here are x86's")
def test_results_name_the_openblas_kernels_that_decide_the_digits():
    """The same run gives other digits under other OpenBLAS kernels (docs/benchmark.md), so
    the document names the ones in use, with the package that ships each library (NumPy's and
    SciPy's builds differ in age and can pick different kernels on one processor: stop 94's
    AMD EPYC got Cooperlake and SkylakeX); OPENBLAS_CORETYPE picks them."""
    code = ("import numpy; from physpose.benchmark.runner import machine_description; "
            "print(machine_description())")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env={**os.environ, "OPENBLAS_CORETYPE": "Nehalem"}, timeout=120,
                         check=True).stdout.strip()
    kernels = out.split("; OpenBLAS kernels ")[1].split(", ")
    assert {"Nehalem (numpy)", "Nehalem (scipy)"} <= set(kernels), out
    assert all(k.startswith("Nehalem (") for k in kernels), out
