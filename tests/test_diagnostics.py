"""Warnings on the input: the detector switching people, feet out of the picture, a person
standing above the modelled floor, dynamics windows without a valid sample."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from physpose import diagnostics
from physpose.cli.reconstruct import diagnostics_lines
from physpose.kinematics.camera import world_from_plane
from physpose.metrics import camera_height, camera_tilt


def _walker(frames: int, fps: float, speed_px: float = 300.0, size: float = 400.0) -> np.ndarray:
    """(T, 33, 3) detections of a person-sized point cloud crossing the image."""
    rng = np.random.default_rng(0)
    shape = rng.uniform(-0.5, 0.5, (33, 2)) * [0.4 * size, size]
    x = 200.0 + speed_px * np.arange(frames) / fps
    kp = np.ones((frames, 33, 3))
    kp[..., 0] = x[:, None] + shape[:, 0]
    kp[..., 1] = 500.0 + shape[:, 1]
    return kp


@pytest.mark.parametrize("fps", [25.0, 60.0])
def test_a_person_moving_like_a_person_does_not_jump(fps):
    kp = _walker(100, fps, speed_px=1200.0)   # 3 body heights per second: a sprint
    detected = np.ones(100, bool)
    detected[40:46] = False                    # a gap, bridged across
    assert diagnostics.person_jumps(kp, detected, fps) == []


def test_another_person_or_a_cut_is_a_jump():
    fps = 25.0
    kp = _walker(60, fps)
    kp[30:, :, 0] += 900.0                     # someone else, two body heights to the right
    assert diagnostics.person_jumps(kp, np.ones(60, bool), fps) == [30]
    near = _walker(60, fps)
    centre = near[40:, :, :2].mean(axis=1, keepdims=True)
    near[40:, :, :2] = centre + 2.5 * (near[40:, :, :2] - centre)  # a much nearer person
    assert diagnostics.person_jumps(near, np.ones(60, bool), fps) == [40]
    # Frames with too few confident landmarks neither jump nor hide a jump.
    kp[28:30, :, 2] = 0.0
    assert diagnostics.person_jumps(kp, np.ones(60, bool), fps) == [30]


def test_feet_above_the_floor_for_longer_than_a_jump(standing):
    joints, fps = standing
    assert diagnostics.raised_runs(joints, fps) == []
    up = joints.copy()
    up[10:40, :, 2] += 1.5                     # 1.2 s on a 1.5 m high box
    (run,) = diagnostics.raised_runs(up, fps)
    assert run[:2] == (10, 39) and run[2] == pytest.approx(1.5, abs=0.05)
    hop = joints.copy()
    hop[10:30, :, 2] += 0.5                    # 0.8 s in the air: a jump, not a support
    assert diagnostics.raised_runs(hop, fps) == []


def test_invalid_windows_are_merged_and_every_warning_names_frames_and_a_remedy():
    windows = [{"frames": [0, 24], "valid": False}, {"frames": [10, 34], "valid": False},
               {"frames": [20, 44], "valid": True}, {"frames": [50, 74], "valid": False}]
    # independent windows are cross-faded over their whole spans
    assert diagnostics.invalid_window_runs(windows, sequential=False) == [(0, 34), (50, 74)]
    # sequential windows give the output only their frames up to the next window's start
    assert diagnostics.invalid_window_runs(windows) == [(0, 19), (50, 74)]
    assert diagnostics.jumps_message([], 25.0) is None
    assert "142 (5.68 s)" in diagnostics.jumps_message([142], 25.0)
    assert "--start/--end" in diagnostics.jumps_message([142], 25.0)
    assert "--obstacle" in diagnostics.raised_message([(0, 142, 1.8)], 25.0)
    assert "0-142 (0.00-5.72 s)" in diagnostics.raised_message([(0, 142, 1.8)], 25.0)
    assert "puts a box" in diagnostics.raised_message([(0, 142, 1.8)], 25.0, supported=True)
    unsupported = diagnostics.raised_message([(0, 142, 1.8)], 25.0, supported=False)
    assert "no support was added" in unsupported and "puts a box" not in unsupported
    assert "joints_kinematic" in diagnostics.invalid_message([(0, 34)], 25.0)
    recon = SimpleNamespace(fps=25.0, slow_motion=1.0, meta={"diagnostics": {
        "person_jumps": [142], "raised": [[0, 142, 1.8]], "invalid_windows": []}})
    lines = diagnostics_lines(recon)
    assert len(lines) == 2 and "142" in lines[0] and "1.80 m up" in lines[1]
    assert "no support was added" in lines[1]
    recon.meta["diagnostics"]["supports"] = [[0.0, 0.0, 0.9, 1.5, 1.9, 1.8]]
    assert "puts a box" in diagnostics_lines(recon)[1]
    assert diagnostics_lines(SimpleNamespace(fps=25.0, slow_motion=1.0, meta={})) == []


def test_a_sequential_window_cut_short_counts_only_the_frames_it_kept():
    """Three windows that found no valid sample, each cut after 5 frames and followed by one
    from the cut (as on Sports2D's demo): frames 0-14 came from them, not their look-ahead."""
    windows = [{"frames": [0, 25], "valid": False, "cut_at": 5},
               {"frames": [5, 35], "valid": False, "cut_at": 10},
               {"frames": [10, 45], "valid": False, "cut_at": 15},
               {"frames": [15, 55], "valid": True}, {"frames": [20, 65], "valid": True}]
    assert diagnostics.invalid_window_runs(windows) == [(0, 14)]
    assert diagnostics.invalid_window_runs(windows, sequential=False) == [(0, 45)]


def test_forces_missing_from_resumed_windows_are_reported():
    import numpy as np

    grf = np.ones((30, 3, 3))
    grf[0:10] = np.nan  # windows from a checkpoint written before forces were recorded
    grf[20:22, 1, 2] = np.nan
    runs = diagnostics.unrecorded_force_runs(grf)
    assert runs == [(0, 9), (20, 21)]
    assert diagnostics.unrecorded_force_runs(np.ones((5, 3, 3))) == []
    assert diagnostics.unrecorded_force_runs(None) == []
    assert diagnostics.unrecorded_forces_message([], 25.0) is None
    message = diagnostics.unrecorded_forces_message(runs, 25.0)
    assert "0-9 (0.00-0.40 s), 20-21 (0.80-0.88 s)" in message and "--no-resume" in message
    recon = SimpleNamespace(fps=25.0, slow_motion=1.0, meta={"diagnostics": {"unrecorded_forces": [[0, 9]]}})
    assert diagnostics_lines(recon) == [diagnostics.unrecorded_forces_message([(0, 9)], 25.0)]


def test_feet_out_of_the_picture_or_unseen_are_counted_and_warned_about():
    kp = _walker(40, 25.0)                     # feet in the image, seen
    valid = np.ones(40, bool)
    feet = diagnostics.FOOT_LANDMARKS
    assert diagnostics.hidden_feet_share(kp, valid, (1920, 1080)) == 0.0
    kp[:10, feet, 1] = 1200.0                  # below the image's bottom edge
    kp[10:20, feet, 2] = 0.1                   # in the image, but not seen
    assert diagnostics.hidden_feet_share(kp, valid, (1920, 1080)) == pytest.approx(0.5)
    valid[20:] = False                         # only the frames with a person count
    assert diagnostics.hidden_feet_share(kp, valid, (1920, 1080)) == pytest.approx(1.0)
    assert diagnostics.hidden_feet_share(kp, np.zeros(40, bool), (1920, 1080)) == 0.0
    assert diagnostics.hidden_feet_message(0.2) is None
    assert "feet are out of the picture or hidden in 50%" in diagnostics.hidden_feet_message(0.5)
    recon = SimpleNamespace(fps=25.0, slow_motion=1.0, meta={"diagnostics": {"hidden_feet": 0.9}})
    assert "90%" in diagnostics_lines(recon)[0]


def test_the_seated_warning_names_frames_and_the_seat():
    from physpose.scene import Box
    seat = Box(center=(-0.1, 0.0, 0.33), size=(0.5, 0.48, 0.1))
    text = diagnostics.seated_message([(36, 75, 0.38)], (seat,), 25.0)
    assert "36-75" in text and "box:-0.10,0.00,0.33,0.50,0.48,0.10" in text
    assert "no seat was added" in diagnostics.seated_message([(36, 75, 0.38)], (), 25.0)
    assert diagnostics.seated_message([], (), 25.0) is None
    recon = SimpleNamespace(fps=25.0, slow_motion=1.0, meta={"diagnostics": {
        "seated": [[36, 75, 0.38]], "seats": [seat.spec()]}})
    assert "puts a seat there (box:-0.10" in diagnostics_lines(recon)[0]


def _stepping(period: float, seconds: float = 6.0, fps: float = 25.0, seed: int = 0,
              swing_px: float = 40.0):
    """(keypoints2d, valid) of a person stepping on the spot in the image: the ankles swing
    fore and aft in antiphase with the given period (s), torso 100 px, 2 px detector noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * fps)) / fps
    kp = np.zeros((len(t), 33, 3))
    kp[..., 2] = 0.9
    kp[:, [11, 12], :2] = [[290, 100], [310, 100]]
    kp[:, [23, 24], :2] = [[292, 200], [308, 200]]
    swing = swing_px * np.sin(2 * np.pi * t / period) if period \
        else np.cumsum(rng.normal(0, 8, len(t)))
    kp[:, 27, :2] = np.stack([300 + swing, np.full_like(t, 380)], 1)
    kp[:, 28, :2] = np.stack([300 - swing, np.full_like(t, 380)], 1)
    kp[..., :2] += rng.normal(0, 2, kp[..., :2].shape)
    return kp, np.ones(len(t), bool)


def test_a_stride_too_slow_for_real_time_hints_at_slow_motion():
    fps = 25.0
    walk = diagnostics.stride_period(*_stepping(1.1), fps)
    assert walk == pytest.approx(1.1, abs=0.05)
    assert diagnostics.slow_stride_message(walk) is None
    slowed = diagnostics.stride_period(*_stepping(2.8), fps)  # a run filmed ~4x slow
    assert slowed == pytest.approx(2.8, abs=0.05)
    hint = diagnostics.slow_stride_message(slowed)
    assert "every 2.8 s" in hint and "--slow-motion 2.3 to 4.0" in hint
    # Declared 2x, the real stride is still 1.4 s: no hint; declared 1.2x it would be 2.3 s.
    assert diagnostics.slow_stride_message(slowed / 2, 2.0) is None
    assert "declared 1.2x" in diagnostics.slow_stride_message(slowed / 1.2, 1.2)
    # No stride where the feet do not alternate periodically, or too few strides are seen.
    assert diagnostics.stride_period(*_stepping(0.0), fps) is None
    assert diagnostics.stride_period(*_stepping(2.8, seconds=3.5), fps) is None
    # Feet that hardly move apart (5 px against a 100 px torso) are no stride.
    assert diagnostics.stride_period(*_stepping(2.8, swing_px=5.0), fps) is None
    kp, valid = _stepping(2.8)
    assert diagnostics.stride_period(kp, valid & (np.arange(len(valid)) % 3 > 0), fps) is None
    found = {"stride_period": slowed}
    assert any("slow motion" in line for line in diagnostics.warning_lines(found, fps))
    # The result's own factor reaches the hint: declared 2x, a 1.4 s real stride is no hint.
    assert diagnostics.warning_lines({"stride_period": slowed / 2}, fps, 2.0) == []


def test_analysis_rates_above_the_measured_ones_are_warned_about():
    assert diagnostics.rate_message(25.0) is None and diagnostics.rate_message(50.0) is None
    line = diagnostics.rate_message(100.0)
    assert "analysed at 100 frames per second" in line and "--fps 25" in line
    assert diagnostics.warning_lines({}, 100.0) == [line]
    assert diagnostics.warning_lines({}, 25.0) == []



def test_detections_left_out_as_torn_are_warned_about_with_their_times():
    assert diagnostics.unsure_message([]) is None
    line = diagnostics.unsure_message([0.13, 0.23, 0.27])
    assert "3 frames" in line and "0.13, 0.23, 0.27 s into the video" in line
    assert "Torn detections" in line
    many = diagnostics.unsure_message([0.1 * k for k in range(11)])
    assert "and 3 more" in many and "1.00" not in many
    assert diagnostics.warning_lines({"unsure_detections": [0.13]}, 25.0) == [
        diagnostics.unsure_message([0.13])]


def test_long_label_exchanges_reach_the_summary():
    runs = {"legs": [[4, 23], [40, 60]], "arms": [[10, 30]]}
    line = diagnostics.label_exchange_message(runs, 25.0)
    assert "the legs' at frames 4-23 (0.16-0.96 s), 40-60 (1.60-2.44 s)" in line
    assert "the arms' at frames 10-30" in line and "fix_swaps=False" in line
    assert diagnostics.warning_lines({"label_exchanges": runs}, 25.0) == [line]
    assert diagnostics.warning_lines({"label_exchanges": None}, 25.0) == []


def test_a_camera_found_low_above_or_below_the_floor_is_warned_about():
    """The kinematic fit of a person lying throughout put the camera at -0.37 to +0.03 m above
    its floor in the benchmark's runs (the truth: 1.3 m; docs/kinematics.md, limits)."""
    for offset in (1.3, -0.37, 0.03):  # a pitched, rolled camera, the world origin off-centre
        n = np.array([0.1, -0.95, -0.3]) / np.linalg.norm([0.1, -0.95, -0.3])
        T = world_from_plane(n, offset, np.array([0.4, 0.2, 4.0]))
        assert camera_height(T) == pytest.approx(offset)
    assert diagnostics.camera_pose_message(1.3) is None
    assert diagnostics.camera_pose_message(None) is None
    assert diagnostics.camera_pose_message(float("nan")) is None
    assert diagnostics.camera_pose_message(diagnostics.LOW_CAMERA) is None
    line = diagnostics.camera_pose_message(-0.37)
    assert "the camera 0.37 m below it" in line and "lying" in line and "--start/--end" in line
    assert "the camera 0.29 m above it" in diagnostics.camera_pose_message(0.29)
    assert diagnostics.warning_lines({"camera_height": -0.37}, 25.0) == [line]
    assert diagnostics.warning_lines({"camera_height": 1.3}, 25.0) == []


def test_a_camera_found_tilted_far_from_upright_is_warned_about():
    """A body lying throughout, its floor found under the soles: motion-capture clips laid
    flat put the camera 29-127 degrees from upright, upright people at most 35.6 (stop 75)."""
    level = world_from_plane(np.array([0.0, -1.0, 0.0]), 1.3, np.array([0.0, 0.0, 4.0]))
    assert camera_tilt(level) == pytest.approx(0.0, abs=1e-6)
    for roll, pitch in ((0.0, 30.0), (50.0, 0.0), (30.0, 40.0), (-120.0, 10.0)):
        r, p = np.radians(roll), np.radians(pitch)
        up = np.array([np.sin(r) * np.cos(p), -np.cos(r) * np.cos(p), -np.sin(p)])
        T = world_from_plane(up, 1.3, np.array([0.0, 0.0, 4.0]))
        expected = np.degrees(np.arccos(np.cos(r) * np.cos(p)))
        assert camera_tilt(T) == pytest.approx(expected, abs=1e-6)
        line = diagnostics.camera_pose_message(1.3, camera_tilt(T))
        assert (line is not None) == (expected >= diagnostics.TILTED_CAMERA)
    line = diagnostics.camera_pose_message(1.3, 61.0)
    assert "tilts the camera 61 degrees from upright" in line and "lying" in line
    assert "on its side" in line
    both = diagnostics.camera_pose_message(-0.2, 61.0)
    assert "0.20 m below it and tilts the camera 61 degrees" in both
    assert diagnostics.warning_lines({"camera_height": 1.3, "camera_tilt": 61.0}, 25.0) == [line]
    assert diagnostics.warning_lines({"camera_height": 1.3, "camera_tilt": 35.6}, 25.0) == []
