"""Video probing, frame-rate resampling and clear errors for files that are not usable videos."""

from __future__ import annotations

import os
import shutil
import subprocess

import cv2
import numpy as np
import pytest
from synthetic_video import frame_value, make_video, tag_rotation, truncate

from physpose.errors import PhysposeError
from physpose.video import (VideoInfo, drift_message, plan_frames, probe, read_frames,
                            timing_drift)


def _info(fps: float, frames: int) -> VideoInfo:
    return VideoInfo(path=None, fps=fps, frame_count=frames, width=64, height=48)


@pytest.mark.parametrize("ext", [".mp4", ".avi", ".mov"])
def test_probe_reports_rate_count_and_size(tmp_path, ext):
    info = probe(make_video(tmp_path / f"v{ext}", 20, fps=30, size=(64, 48)))
    assert (info.fps, info.frame_count, info.image_size) == (30.0, 20, (64, 48))
    assert info.duration == pytest.approx(20 / 30)


def test_resample_60_to_25_picks_nearest_source_frames():
    plan = plan_frames(_info(60, 100), 25)
    # target times k/25 s -> source frames round(2.4 k)
    assert plan.indices[:8].tolist() == [0, 2, 5, 7, 10, 12, 14, 17]
    assert len(plan.indices) == 42  # ceil(100 / 60 * 25) targets in [0, 1.667) s
    np.testing.assert_allclose(plan.timestamps, plan.indices / 60)
    assert np.abs(plan.timestamps - np.arange(42) / 25).max() <= 0.5 / 60 + 1e-12
    assert plan.fps == 25 and plan.note == ""


def test_resample_at_the_source_rate_keeps_every_frame():
    plan = plan_frames(_info(25, 30), 25)
    assert plan.indices.tolist() == list(range(30))


def test_never_upsamples_and_says_so():
    plan = plan_frames(_info(24, 48), 60)
    assert plan.fps == 24 and plan.indices.tolist() == list(range(48))
    assert "24 fps" in plan.note and "60" in plan.note


def test_time_range_selects_frames_inside_it():
    plan = plan_frames(_info(50, 500), 25, start=2.0, end=3.0)
    assert plan.indices.tolist() == list(range(100, 150, 2))
    assert plan.timestamps[0] == pytest.approx(2.0)


@pytest.mark.parametrize("target", [0, -5, 0.5, 241, float("nan")])
def test_absurd_target_rate_is_rejected(target):
    with pytest.raises(PhysposeError, match="target frame rate"):
        plan_frames(_info(30, 30), target)


@pytest.mark.parametrize("start,end,match", [
    (5.0, None, "start 5 s is outside"), (-1.0, None, "start -1 s is outside"),
    (0.5, 0.2, "must be after start"), (0.0, 3.0, "past the end"),
    (0.0, float("inf"), "end inf s is not a time"), (0.0, float("nan"), "end nan s is not"),
])
def test_time_range_outside_the_video_is_rejected(start, end, match):
    with pytest.raises(PhysposeError, match=match):
        plan_frames(_info(30, 30), 25, start=start, end=end)


def test_read_frames_returns_the_planned_frames(tmp_path):
    info = probe(make_video(tmp_path / "v.avi", 30, fps=30))
    wanted = np.array([0, 3, 4, 17, 29])
    got = list(read_frames(info, wanted))
    assert [i for i, _ in got] == wanted.tolist()
    for i, image in got:  # MJPG is lossy: grey levels come back within a few units
        assert abs(float(image.mean()) - frame_value(i)) < 4


@pytest.mark.parametrize("degrees", [90, 270])
def test_a_phone_video_is_read_turned_as_players_show_it(tmp_path, degrees):
    """Landscape pixels with a rotation tag (how phones store portrait video): the frames come
    out turned by the tag, and the size says so."""
    path = tmp_path / "phone.mp4"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 25, (64, 48))
    for _ in range(5):
        image = np.zeros((48, 64, 3), np.uint8)
        image[:8, :8] = 255                      # a mark in the top-left corner
        writer.write(image)
    writer.release()
    info = probe(tag_rotation(path, degrees))
    assert (info.width, info.height) == (48, 64)
    _, image = next(read_frames(info, np.array([0])))
    assert image.shape == (64, 48, 3)
    y, x = np.argwhere(image[..., 0] > 200).mean(axis=0)
    # Turned clockwise the mark lands top right; counter-clockwise, bottom left.
    assert (x > 24 and y < 32) if degrees == 90 else (x < 24 and y > 32)


def test_timing_drift_tells_a_variable_frame_rate():
    info = _info(30.0, 100)
    even = np.arange(10) / 30.0 + 0.5
    assert timing_drift(info, np.arange(10), list(even)) == pytest.approx(0.0)
    assert drift_message(info, 0.2) is None
    late = even.copy()
    late[5:] += 0.1                         # a 0.1 s pause the container records
    assert timing_drift(info, np.arange(10), list(late)) == pytest.approx(3.0)
    assert "not evenly spaced" in drift_message(info, 3.0)


@pytest.mark.skipif(shutil.which("ffmpeg") is None, reason="needs the ffmpeg program to write "
                    "a variable-frame-rate file (apt-get install ffmpeg)")
def test_a_variable_frame_rate_video_is_warned_about(tmp_path):
    source = make_video(tmp_path / "even.mp4", 40, fps=20)
    uneven = tmp_path / "uneven.mp4"      # 6 frames of every 10 kept, at their own times
    subprocess.run(["ffmpeg", "-loglevel", "error", "-y", "-i", str(source), "-vf",
                    "select='lt(mod(n\\,10)\\,6)'", "-fps_mode", "vfr", "-c:v", "mpeg4",
                    str(uneven)], check=True)
    info = probe(uneven)
    times: list[float] = []
    indices = np.arange(info.frame_count)
    list(read_frames(info, indices, times))
    assert drift_message(info, timing_drift(info, indices, times)) is not None


def test_missing_file(tmp_path):
    with pytest.raises(PhysposeError, match="file not found") as err:
        probe(tmp_path / "nope.mp4")
    assert "nope.mp4" in str(err.value)


def test_image_instead_of_video(tmp_path):
    cv2.imwrite(str(tmp_path / "photo.png"), np.zeros((10, 10, 3), np.uint8))
    with pytest.raises(PhysposeError, match="this is an image, not a video"):
        probe(tmp_path / "photo.png")


def test_text_file(tmp_path):
    (tmp_path / "notes.txt").write_text("hello")
    with pytest.raises(PhysposeError, match="not a video file .*'.txt'"):
        probe(tmp_path / "notes.txt")


def test_text_file_named_like_a_video(tmp_path):
    (tmp_path / "fake.mp4").write_text("this is not a video\n" * 50)
    with pytest.raises(PhysposeError, match="cannot open this file as a video"):
        probe(tmp_path / "fake.mp4")


@pytest.mark.skipif(os.geteuid() == 0, reason="root reads any file")
def test_a_video_without_read_permission_is_not_called_corrupt(tmp_path):
    path = make_video(tmp_path / "locked.mp4", 3)
    path.chmod(0)
    with pytest.raises(PhysposeError, match="no permission to read"):
        probe(path)


def test_empty_file(tmp_path):
    (tmp_path / "empty.mp4").write_bytes(b"")
    with pytest.raises(PhysposeError, match="empty"):
        probe(tmp_path / "empty.mp4")


@pytest.mark.parametrize("ext", [".mp4", ".avi"])
def test_zero_frame_video(tmp_path, ext):
    path = make_video(tmp_path / f"zero{ext}", 0)
    with pytest.raises(PhysposeError, match="no frames|no decodable frames") as err:
        probe(path)
    assert f"zero{ext}" in str(err.value)


def test_truncated_mp4_cannot_be_opened(tmp_path):
    path = truncate(make_video(tmp_path / "v.mp4", 60), tmp_path / "cut.mp4", 0.5)
    with pytest.raises(PhysposeError, match="truncated"):
        probe(path)


def test_truncated_avi_fails_while_reading_and_says_where(tmp_path):
    path = truncate(make_video(tmp_path / "v.avi", 60), tmp_path / "cut.avi", 0.5)
    info = probe(path)  # the header survives, so it opens
    with pytest.raises(PhysposeError, match=r"decoding stopped after \d+ of 60 frames") as err:
        for _ in read_frames(info, np.arange(60)):
            pass
    assert "cut.avi, frame" in str(err.value)


@pytest.mark.parametrize("fps", [5000, 0.5])
def test_absurd_source_rate_is_refused_before_any_frame_is_read(tmp_path, fps):
    # A slide show at 0.5 fps had been read and detected, then refused by the observations'
    # own rate check with a remedy for keypoints files.
    path = make_video(tmp_path / "odd.mp4", 5, fps=fps)
    with pytest.raises(PhysposeError, match=f"frame rate of {fps:g} fps, outside the 1-1000"):
        probe(path)
