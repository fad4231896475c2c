"""Cuts in a video: found where the whole picture changes at once, not where the camera pans
or the light changes, and told by the observe stage with their times."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np

from physpose.observations import Observations
from physpose.observe import ObserveConfig, _detect_all, unbridge_cuts
from physpose.scene_cuts import CutFinder, Signature, cut_message, is_cut
from physpose.video import plan_frames, probe


def _scene(seed: int, size=(320, 180)) -> np.ndarray:
    """A picture of coloured blocks on a coloured ground, larger than `size` so that it can
    pan; another seed gives other colours."""
    rng = np.random.default_rng(seed)
    height, width = size[1] + 40, size[0] + 80
    picture = np.empty((height, width, 3), np.uint8)
    picture[:] = rng.integers(0, 256, 3)
    for _ in range(12):
        x, y = rng.integers(0, width - 40), rng.integers(0, height - 30)
        w, h = rng.integers(20, 120), rng.integers(15, 80)
        picture[y:y + h, x:x + w] = rng.integers(0, 256, 3)
    return cv2.GaussianBlur(picture, (0, 0), 1.5)


def _view(scene: np.ndarray, dx: int, size=(320, 180)) -> np.ndarray:
    return np.ascontiguousarray(scene[20:20 + size[1], dx:dx + size[0]])


def test_a_pan_or_a_change_of_light_is_not_a_cut_but_another_picture_is():
    a, b = _scene(0), _scene(1)
    first = Signature(_view(a, 0))
    assert not is_cut(first, Signature(_view(a, 6)))                       # the camera pans
    brighter = cv2.convertScaleAbs(_view(a, 0), alpha=1.0, beta=12)
    assert not is_cut(first, Signature(brighter))                          # exposure changes
    assert is_cut(first, Signature(_view(b, 0)))                           # another shot
    assert is_cut(Signature(np.zeros_like(_view(a, 0))), first)            # from black
    assert cut_message([]) is None
    assert "cuts at 0.40, 2.00 s" in cut_message([0.4, 2.0])


def test_observe_says_where_the_video_cuts(tmp_path, caplog):
    path = tmp_path / "two_shots.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 25, (320, 180))
    for i in range(20):
        writer.write(_view(_scene(0 if i < 10 else 1), 2 * (i % 10)))
    writer.release()
    info = probe(path)
    with caplog.at_level("WARNING", logger="physpose.observe"):
        _detect_all(info, plan_frames(info, 25), ObserveConfig(use_cache=False), progress=False,
                    check=False, cuts=(cuts := CutFinder()))
    assert "the video cuts at 0.40 s" in caplog.text and str(path) in caplog.text
    assert cuts.frames == [10]


def _finder(pictures: list[np.ndarray]) -> CutFinder:
    finder = CutFinder()
    for picture in pictures:
        finder.see(picture)
    return finder


def test_a_blackout_within_a_shot_is_no_cut_but_a_change_of_shot_is():
    a, b = _scene(0), _scene(1)
    black = np.zeros_like(_view(a, 0))
    blackout = _finder([_view(a, k) for k in range(10)] + [black, black]
                       + [_view(a, 10 + k) for k in range(3)])
    assert blackout.frames == [] and not blackout.between(9, 12)
    to_black_and_on = _finder([_view(a, k) for k in range(10)] + [black, black]
                              + [_view(b, k) for k in range(3)])
    assert to_black_and_on.frames == [10] and to_black_and_on.between(9, 12)


def test_a_gap_filled_across_a_cut_is_left_open_and_others_stay_filled():
    # Detections at 0-2, 5-9 and 12-14; the gaps 3-4 and 10-11 were interpolated. The video
    # cuts at frame 11 to another scene: the person after it may be another one.
    t = 15
    a, b = _scene(0), _scene(1)
    cuts = _finder([_view(a, k) for k in range(11)] + [_view(b, k) for k in range(4)])
    assert cuts.frames == [11]
    detected = np.ones(t, bool)
    detected[[3, 4, 10, 11]] = False
    keypoints = np.random.default_rng(0).uniform(40, 140, (t, 33, 3))
    keypoints[..., 2] = 0.9
    obs = Observations(source="clip", fps=25.0, image_size=(320, 180),
                       timestamps=np.arange(t) / 25.0, keypoints2d=keypoints,
                       detected=detected, interpolated=~detected,
                       world_landmarks=keypoints / 100.0)
    kept = unbridge_cuts(obs, cuts)
    assert kept.interpolated.tolist() == [i in (3, 4) for i in range(t)]
    assert not kept.keypoints2d[10:12].any() and not kept.world_landmarks[10:12].any()
    np.testing.assert_array_equal(kept.keypoints2d[3:5], keypoints[3:5])
    np.testing.assert_array_equal(kept.detected, detected)
    assert unbridge_cuts(obs, _finder([_view(a, k) for k in range(t)])) is obs


def test_the_command_line_prints_the_cut(tmp_path):
    # Where no logging is configured (the console script), observe's warnings reach stderr
    # through Python's last resort; collecting them for the cache must not swallow them.
    path = tmp_path / "two_shots.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 25, (320, 180))
    for i in range(20):
        writer.write(_view(_scene(0 if i < 10 else 1), 2 * (i % 10)))
    writer.release()
    env = {**os.environ, "PHYSPOSE_CACHE_DIR": str(tmp_path / "cache")}
    physpose = Path(sys.executable).with_name("physpose")  # the installed console script
    proc = subprocess.run([str(physpose), "observe", str(path), "--out", str(tmp_path / "out"),
                           "--no-overlay"], capture_output=True, text=True, env=env, timeout=300)
    assert "the video cuts at 0.40 s" in proc.stderr      # then: nobody in it, exit 2
    assert proc.returncode == 2 and "person was found in only 0 of 20" in proc.stderr


def _frames(video: Path, count: int) -> list[np.ndarray]:
    cap = cv2.VideoCapture(str(video))
    frames = [cap.read()[1] for _ in range(count)]
    cap.release()
    return frames


def test_a_cut_between_two_views_of_one_room_is_found(pose2sim_demo):
    """pose2sim's cameras film one room: their pictures differ by no more than a shot's own
    largest changes in colour and grey, and had not counted as cuts. Aligned, their structure
    differs; within each view's own frames nothing is found."""
    views = [_frames(pose2sim_demo / "videos" / f"cam0{k}.mp4", 12) for k in (1, 2, 3, 4)]
    for a, b in ((0, 1), (0, 2), (1, 2), (1, 3), (2, 3), (0, 3)):
        finder = CutFinder()
        for image in views[a] + views[b]:
            finder.see(image)
        assert finder.frames == [12], (a, b)
    for frames in views:
        finder = CutFinder()
        for image in frames:
            finder.see(image)
        assert finder.frames == []
