"""Pieces of the kinematic fit: inverse kinematics, swap repair, seed frames, evidence, CLI."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from test_kinematics_fixtures import synthetic_clip

from physpose.cli import main
from physpose.diagnostics import label_exchange_message
from physpose.fk import fk
from physpose.joints import LANDMARK_INDEX
from physpose.kinematics.config import KinematicConfig
from physpose.kinematics.evidence import gather_evidence, padded_length, seed_frames
from physpose.kinematics.fit import fit_kinematics
from physpose.kinematics.ik import angles_from_rotations, inverse_kinematics, segment_rotations
from physpose.kinematics.losses import rotvec_matrix
from physpose.kinematics import swaps
from physpose.kinematics.swaps import GROUPS, swap_paths, unswap
from physpose.reconstruction import Reconstruction
from physpose.shape import BodyShape
from physpose.skeleton import DOF_LIMITS, DOF_NAMES, NUM_DOF


def test_inverse_kinematics_of_everyday_poses():
    """Moderate poses (a third of each joint range, elbows and knees bent) come back to within
    a few centimetres from their landmarks alone."""
    rng = np.random.default_rng(3)
    shape = BodyShape.from_height(1.8)
    t = 64
    centre = DOF_LIMITS.mean(axis=1) * 0.3
    half = (DOF_LIMITS[:, 1] - DOF_LIMITS[:, 0]) * 0.15
    angles = rng.uniform(centre - half, centre + half, (t, NUM_DOF))
    for joint, sign in (("l_knee", 1), ("r_knee", 1), ("l_elbow", -1), ("r_elbow", -1)):
        angles[:, DOF_NAMES.index(f"{joint}_y")] = sign * rng.uniform(0.3, 1.2, t)
    R = Rotation.random(t, random_state=4).as_matrix()
    _, landmarks = fk(shape.bones(), np.zeros((t, 3)), R, angles)
    R2, angles2 = inverse_kinematics(landmarks, shape.bones())
    _, back = fk(shape.bones(), np.zeros((t, 3)), R2, angles2)
    err = np.linalg.norm(back - landmarks, axis=-1)
    assert np.median(err) < 0.02 and np.percentile(err, 90) < 0.06, np.median(err)


def test_inverse_kinematics_of_arms_raised_overhead():
    """Shoulders abducted past the horizontal (valid, within the limits) exist only in the
    second Euler form; the IK must not clip the first form's out-of-range angles instead."""
    shape = BodyShape.from_height(1.75)
    t = 30
    angles = np.zeros((t, NUM_DOF))
    raise_ = np.radians(np.linspace(30.0, 160.0, t))  # abduction through the horizontal
    for side, sign in (("l", 1.0), ("r", -1.0)):
        angles[:, DOF_NAMES.index(f"{side}_shoulder_x")] = sign * raise_
        angles[:, DOF_NAMES.index(f"{side}_elbow_y")] = -0.4
    R = np.tile(np.eye(3), (t, 1, 1))
    _, landmarks = fk(shape.bones(), np.zeros((t, 3)), R, angles)
    R2, angles2 = inverse_kinematics(landmarks, shape.bones())
    _, back = fk(shape.bones(), np.zeros((t, 3)), R2, angles2)
    wrists = [LANDMARK_INDEX["left_wrist"], LANDMARK_INDEX["right_wrist"]]
    assert np.linalg.norm(back - landmarks, axis=-1)[:, wrists].max() < 0.03
    # One form per stretch of frames: no 180-degree jumps in the recovered angles.
    assert np.abs(np.diff(angles2, axis=0)).max() < 0.5
    # A single frame, and none at all, still work.
    assert angles_from_rotations(segment_rotations(landmarks[:1], shape.bones())).shape == (
        1, NUM_DOF)
    assert angles_from_rotations(np.zeros((0, 17, 3, 3))).shape == (0, NUM_DOF)


def test_rotation_vector_matrix():
    v = np.array([[0.0, 0.0, 0.0], [0.3, -0.2, 0.5], [1e-6, 0.0, 0.0]])
    assert np.allclose(np.asarray(rotvec_matrix(v)), Rotation.from_rotvec(v).as_matrix(),
                       atol=1e-9)


def _swapped(ev, rows, parts):
    """The evidence with the left/right labels of `parts` exchanged in `rows` (2d and 3d)."""
    left = [LANDMARK_INDEX[f"left_{p}"] for p in parts]
    right = [LANDMARK_INDEX[f"right_{p}"] for p in parts]
    out = {}
    for name in ("uv", "world_ray"):
        a = getattr(ev, name).copy()
        a[np.ix_(rows, left)], a[np.ix_(rows, right)] = (getattr(ev, name)[np.ix_(rows, right)],
                                                         getattr(ev, name)[np.ix_(rows, left)])
        out[name] = a
    return type(ev)(**{**ev.__dict__, **out})


@pytest.fixture(scope="module")
def walk_evidence():
    clip = synthetic_clip(frames=30)
    return gather_evidence(clip.observations, clip.K, 0.1, True)


def test_swaps_are_found_and_undone(walk_evidence):
    ev = walk_evidence
    rows = np.arange(11, 15)
    bad = _swapped(ev, rows, GROUPS["legs"])
    states = swap_paths(bad)
    assert np.array_equal(np.flatnonzero(states["legs"]), rows)
    assert not states["arms"].any() and not states["trunk"].any()
    assert not any(s.any() for s in swap_paths(ev).values())
    repaired, long_runs = unswap(bad)
    assert not long_runs
    assert np.allclose(repaired.uv, ev.uv) and np.allclose(repaired.world_ray, ev.world_ray)


def test_legs_swapped_in_most_frames_are_repaired(walk_evidence):
    """Which of the two mirror-image labellings of the legs is right follows from the trunk
    (knees nearer their own hips), not from which one the detector gave more often."""
    rows = np.arange(4, 24)  # 20 of 30 frames
    states = swap_paths(_swapped(walk_evidence, rows, GROUPS["legs"]))
    assert np.array_equal(np.flatnonzero(states["legs"]), rows)
    assert not states["arms"].any() and not states["trunk"].any()


def test_a_labelling_and_its_mirror_image_move_at_the_same_cost(walk_evidence):
    """Each landmark's motion is weighted by its own confidences: with one side far less
    confident (seen from the side), exchanging a group's labels in every frame must not change
    its motion cost (it had, by the confidences' difference times the sides' motions)."""
    ev = walk_evidence
    weight = ev.weight.copy()
    for group in GROUPS.values():
        weight[:, [LANDMARK_INDEX[f"right_{p}"] for p in group]] *= 0.4
    ev = type(ev)(**{**ev.__dict__, "weight": weight})
    for group in GROUPS.values():
        cost = swaps._motion_costs(ev, group, 25.0)
        assert np.allclose(cost[:, 0, 0], cost[:, 1, 1]) and cost[:, 0, 0].sum() > 0
        assert np.allclose(cost[:, 0, 1], cost[:, 1, 0])


def test_long_repairs_are_reported(walk_evidence):
    _, long_runs = unswap(_swapped(walk_evidence, np.arange(4, 24), GROUPS["legs"]))
    assert long_runs == {"legs": [[4, 23]]}
    message = label_exchange_message(long_runs, 25.0)
    assert "the legs' at frames 4-23 (0.16-0.96 s)" in message
    assert label_exchange_message({}, 25.0) is None and label_exchange_message(None, 25.0) is None
    _, long_runs = unswap(_swapped(walk_evidence, np.arange(11, 15), GROUPS["legs"]))
    assert not long_runs


def test_a_long_repair_is_kept_with_the_fit_and_told_again_from_the_cache(tmp_path, monkeypatch,
                                                                          caplog):
    """The fit records its long label exchanges (the summary lists them) and warns of them
    whether it was computed or read from the cache (it had warned only when computed)."""
    monkeypatch.setenv("PHYSPOSE_CACHE_DIR", str(tmp_path))
    clip = synthetic_clip(frames=30)
    left = [LANDMARK_INDEX[f"left_{p}"] for p in GROUPS["legs"]]
    right = [LANDMARK_INDEX[f"right_{p}"] for p in GROUPS["legs"]]
    rows = np.arange(4, 24)
    kp, world = clip.observations.keypoints2d.copy(), clip.observations.world_landmarks.copy()
    for a in (kp, world):
        a[np.ix_(rows, left + right)] = a[np.ix_(rows, right + left)]
    obs = dataclasses.replace(clip.observations, keypoints2d=kp, world_landmarks=world)
    for _ in range(2):
        caplog.clear()
        with caplog.at_level("WARNING", logger="physpose.kinematics.fit"):
            fit = fit_kinematics(obs, KinematicConfig.preset("S"))
        assert fit.label_exchanges == {"legs": [[4, 23]]}
        assert "the legs' at frames 4-23" in caplog.text


def test_whole_body_flips_are_repaired(walk_evidence):
    rows = np.array([8, 9, 10, 11, 12, 20, 21])
    everything = tuple(p for parts in GROUPS.values() for p in parts)
    states = swap_paths(_swapped(walk_evidence, rows, everything))
    for name in GROUPS:
        assert np.array_equal(np.flatnonzero(states[name]), rows), name


def test_a_slow_3d_error_does_not_exchange_the_legs():
    """MediaPipe's 3d error drifts for a second at a time. Here it brings each leg 15 cm towards
    the other side over frames 15-45 (ramped in and out over 8 frames), which makes the knees'
    attachment favour the crossed labels; where the legs cross in the image, exchanging them
    cost no motion there. In 3d they stay apart, and the labels must stay as detected (before
    the 3d motion term, frames 19-40 were exchanged)."""
    clip = synthetic_clip(frames=60)
    ev = gather_evidence(clip.observations, clip.K, 0.1, True)
    world = ev.world_ray.copy()
    across = world[:, LANDMARK_INDEX["left_hip"]] - world[:, LANDMARK_INDEX["right_hip"]]
    across /= np.linalg.norm(across, axis=1, keepdims=True)
    t = np.arange(ev.num_frames)
    drift = 0.15 * np.clip(np.minimum((t - 15) / 8, (45 - t) / 8), 0.0, 1.0)[:, None] * across
    for part in GROUPS["legs"]:
        world[:, LANDMARK_INDEX[f"left_{part}"]] -= drift
        world[:, LANDMARK_INDEX[f"right_{part}"]] += drift
    states = swap_paths(type(ev)(**{**ev.__dict__, "world_ray": world}))
    assert not any(s.any() for s in states.values())


@pytest.mark.parametrize("gap, flipped", [((30, 38), (38, 42)), ((20, 40), (40, 44))])
def test_after_a_gap_the_labels_are_judged_afresh(gap, flipped):
    """Nothing but a weak motion term links the detections after a gap to those before, so the
    path may label them either way round: the whole body flipped for 4 frames just after the gap
    is repaired there, not read as the detector's labels being wrong everywhere else after it
    (before, every frame after the flip was exchanged)."""
    clip = synthetic_clip(frames=60)
    ev = gather_evidence(clip.observations, clip.K, 0.1, True)
    everything = tuple(p for parts in GROUPS.values() for p in parts)
    bad = _swapped(ev, np.arange(*flipped), everything)
    valid = bad.valid.copy()
    valid[gap[0]:gap[1]] = False
    weight = np.where(valid[:, None], bad.weight, 0.0)
    states = swap_paths(type(ev)(**{**bad.__dict__, "valid": valid, "weight": weight}))
    for name in GROUPS:
        assert np.array_equal(np.flatnonzero(states[name]), np.arange(*flipped)), name


@pytest.mark.parametrize("image_only", [False, True])
@pytest.mark.parametrize("seed", range(4))
def test_high_frame_rates_do_not_invent_swaps(seed, image_only, monkeypatch):
    """At 100 fps the landmarks move less between frames than the detector's noise. Jittery
    detections with 2 % outliers must not be read as swaps; before the motion scale had a
    floor, seeds 1 and 3 had the legs or the whole body exchanged in 59-258 of these 600
    group-frames. With the 3d motion term (exact 3d here) none are exchanged even without the
    floor, so the image's term is also checked alone (the 3d scale made too large to count)."""
    if image_only:
        monkeypatch.setattr(swaps, "MOTION_SIGMA_3D", 1e9)
    fps = 100.0
    clip = synthetic_clip(frames=200, fps=fps, noise_px=4.0, seed=seed)
    ev = gather_evidence(clip.observations, clip.K, 0.1, True)
    rng = np.random.default_rng(seed + 100)
    uv = ev.uv.copy()
    outlier = rng.random(uv.shape[:2]) < 0.02
    uv[outlier] += rng.normal(0.0, 60.0, (outlier.sum(), 2))   # ~ 2/3 of the torso, px
    states = swap_paths(type(ev)(**{**ev.__dict__, "uv": uv}))
    wrong = sum(int(s.sum()) for s in states.values())
    assert wrong <= 0.03 * len(GROUPS) * ev.num_frames


def test_seed_frames_pick_confident_spread_frames():
    clip = synthetic_clip(frames=40)
    ev = gather_evidence(clip.observations, clip.K, 0.1, True)
    ev.weight[:, :] = np.linspace(0.5, 1.0, 40)[:, None]  # later frames more confident
    seeds = seed_frames(ev, 5, 4)
    assert len(seeds) == 5 and seeds.max() == 39 and np.diff(seeds).min() >= 4
    assert list(seed_frames(ev, 5, 0)) == [35, 36, 37, 38, 39]


def test_padded_lengths_are_few():
    sizes = {padded_length(t) for t in range(1, 1000)}
    assert all(padded_length(t) >= t for t in range(1, 1000))
    assert len(sizes) <= 20 and max(padded_length(t) / t for t in range(16, 1000)) < 1.5


def test_cli_fit_writes_the_contract(tmp_path, monkeypatch):
    monkeypatch.setenv("PHYSPOSE_CACHE_DIR", str(tmp_path / "cache"))
    clip = synthetic_clip(frames=10, noise_px=1.0, noise_3d=0.02)
    obs_path = clip.observations.save(tmp_path / "observations.npz")
    (tmp_path / "K.json").write_text(json.dumps({"K": clip.K.tolist()}))
    out = tmp_path / "out"
    assert main(["fit", str(obs_path), "--out", str(out), "--variant", "SO",
                 "--camera", str(tmp_path / "K.json"), "--height", "1.75"]) == 0
    rec = Reconstruction.load(out)
    assert rec.num_frames == 10 and not rec.has_physics
    assert rec.qpos_kinematic.shape == (10, 55) and "<mujoco" in rec.body_mjcf
    assert np.allclose(rec.camera_K, clip.K)
    config = json.loads((out / "config.json").read_text())
    assert config["variant"] == "SO" and config["kinematics"]["optimize_pose"]
    assert (out / "overlay.mp4").stat().st_size > 0
    # The same observations declared 2x slow-motion footage: fitted on the real clock.
    slow = tmp_path / "slow"
    assert main(["fit", str(obs_path), "--out", str(slow), "--variant", "SO", "--camera",
                 str(tmp_path / "K.json"), "--slow-motion", "2", "--no-overlay"]) == 0
    rec = Reconstruction.load(slow)
    assert rec.fps == 2 * clip.observations.fps and rec.slow_motion == 2.0


def test_cli_fit_bad_input(tmp_path, capsys):
    assert main(["fit", str(tmp_path / "missing.npz"), "--out", str(tmp_path / "o")]) == 2
    assert "not found" in capsys.readouterr().err
    bad_k = tmp_path / "K.txt"
    bad_k.write_text("1 2 3\n")
    clip = synthetic_clip(frames=4)
    obs_path = clip.observations.save(tmp_path / "obs.npz")
    assert main(["fit", str(obs_path), "--out", str(tmp_path / "o"), "--camera",
                 str(bad_k)]) == 2
    assert "pinhole" in capsys.readouterr().err
    assert main(["fit", str(obs_path), "--out", str(tmp_path / "o"), "--fps", "10"]) == 2
    assert "apply to videos" in capsys.readouterr().err
    assert main(["fit", str(obs_path), "--out", str(tmp_path / "o"), "--start", "1"]) == 2
    assert "apply to videos" in capsys.readouterr().err
    qca = tmp_path / "Calib.qca.txt"
    qca.write_text("<?xml version='1.0'?>")
    assert main(["fit", str(obs_path), "--out", str(tmp_path / "o"), "--camera",
                 str(qca)]) == 2
    assert "not a readable XML calibration" in capsys.readouterr().err  # fit reads them now
    assert main(["fit", str(obs_path), "--out", str(tmp_path / "o"), "--height", "175"]) == 2
    assert "175" in capsys.readouterr().err  # before any work
    assert main(["fit", str(obs_path), "--out", str(tmp_path / "o"), "--slow-motion", "0"]) == 2
    assert "slow motion 0x is outside" in capsys.readouterr().err


def test_variant_flags_round_trip():
    for name in ("S", "SO", "SO+G", "SO+T", "SO+GT"):
        assert KinematicConfig.preset(name).variant == name
    with pytest.raises(Exception):
        KinematicConfig.preset("SO", nonsense=1)


def test_fit_observes_a_video_as_observe_does():
    """fit takes observe's video options (its remedies name --start/--end)."""
    from physpose.cli import build_parser  # noqa: PLC0415
    from physpose.cli.observe import config_from_args  # noqa: PLC0415

    args = build_parser().parse_args(["fit", "v.mp4", "--out", "o", "--start", "1.5", "--end",
                                      "3", "--person", "640,360", "--static-camera", "--fps",
                                      "20"])
    cfg = config_from_args(args)
    assert (cfg.start, cfg.end, cfg.person, cfg.stabilize, cfg.target_fps) == \
        (1.5, 3.0, (640.0, 360.0), False, 20.0)
