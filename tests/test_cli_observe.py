"""`physpose observe` and `physpose demo`: outputs, exit codes, messages, and no lost files."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from synthetic_video import make_noise_video

from physpose.cli import main
from physpose.cli.observe import ObserveRun
from physpose.keypoints_io import load_keypoints, save_keypoints
from physpose.observations import Observations

PHYSPOSE = Path(sys.executable).with_name("physpose")  # the installed console script


@pytest.fixture(autouse=True)
def _private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("PHYSPOSE_CACHE_DIR", str(tmp_path / "cache"))


def _keypoints(tmp_path, name="kp.json") -> Path:
    t = 4
    kp = np.zeros((t, 33, 3))
    kp[..., 0], kp[..., 1], kp[..., 2] = 100 + np.arange(33), 50 + 3 * np.arange(33), 0.9
    obs = Observations(source="synthetic", fps=25.0, image_size=(200, 160),
                       timestamps=np.arange(t) / 25, keypoints2d=kp,
                       detected=np.ones(t, bool), interpolated=np.zeros(t, bool))
    return save_keypoints(obs, tmp_path / name)


def test_keypoints_input_writes_all_outputs(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["observe", str(_keypoints(tmp_path)), "--out", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["config.json", "observations.npz",
                                                     "overlay_landmarks.mp4"]
    obs = Observations.load(out / "observations.npz")
    assert obs.num_frames == 4 and obs.image_size == (200, 160)
    config = json.loads((out / "config.json").read_text())
    assert config["input_kind"] == "keypoints" and config["frames"] == 4
    cap = cv2.VideoCapture(str(out / "overlay_landmarks.mp4"))
    assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == 4 and cap.get(cv2.CAP_PROP_FPS) == 25
    ok, frame = cap.read()
    assert ok and frame.shape[:2] == (160, 200)
    assert frame[:, 95:140].max() > 150  # the landmarks were drawn on the dark background
    assert "person found in 4/4 (100.0%)" in capsys.readouterr().out


def test_the_summary_counts_detections_left_out_as_torn(tmp_path):
    obs = load_keypoints(_keypoints(tmp_path))
    assert "torn" not in ObserveRun(obs, (), 1.0).summary()
    torn = obs.replace(detected=np.array([0, 1, 1, 1], bool),
                       unsure=np.array([1, 0, 0, 0], bool))
    assert "person found in 3/4 (75.0%), 0 interpolated, 1 left out as torn, 1.0 s" in \
        ObserveRun(torn, (), 1.0).summary()


def test_missing_input_exits_2_with_message(tmp_path, capsys):
    assert main(["observe", str(tmp_path / "nope.mp4"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "physpose observe: error:" in err and "nope.mp4: file not found" in err
    assert not (tmp_path / "o").exists()


def test_options_for_videos_are_refused_for_keypoints(tmp_path, capsys):
    assert main(["observe", str(_keypoints(tmp_path)), "--out", str(tmp_path / "o"),
                 "--fps", "10"]) == 2
    assert "apply to videos" in capsys.readouterr().err


@pytest.mark.parametrize("args,match", [
    (["--fps", "0"], "target frame rate 0 fps is outside 1-240"),
    (["--start", "9"], "start 9 s is outside the video"),
])
def test_bad_rates_and_ranges(tmp_path, capsys, args, match):
    video = make_noise_video(tmp_path / "v.mp4", 10)
    assert main(["observe", str(video), "--out", str(tmp_path / "o"), *args]) == 2
    assert match in capsys.readouterr().err


def test_failure_keeps_earlier_outputs(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["observe", str(_keypoints(tmp_path)), "--out", str(out)]) == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    bad = tmp_path / "bad.json"
    bad.write_text('{"fps": 25, "image_size": [10, 10], "keypoints2d": [[[1, 2]]]}')
    assert main(["observe", str(bad), "--out", str(out)]) == 2
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before  # nothing lost, no temp left
    assert "bad.json: keypoints2d has shape (1, 1, 2)" in capsys.readouterr().err


def test_no_person_video_via_the_console_script(tmp_path):
    """A real process: non-zero exit, the message on stderr, no traceback."""
    video = make_noise_video(tmp_path / "nobody.mp4", 8)
    proc = subprocess.run([str(PHYSPOSE), "observe", str(video), "--out", str(tmp_path / "o")],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert "nobody.mp4: a person was found in only 0 of 8 frames" in proc.stderr
    assert "Traceback" not in proc.stderr and "Traceback" not in proc.stdout


def test_a_file_that_is_no_video_gets_physposes_message_without_opencvs_warning(tmp_path):
    fake = tmp_path / "fake.mp4"
    fake.write_text("this is not a video\n" * 50)
    proc = subprocess.run([str(PHYSPOSE), "observe", str(fake), "--out", str(tmp_path / "o")],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert "fake.mp4: cannot open this file as a video" in proc.stderr
    assert "WARN" not in proc.stderr, proc.stderr


def test_a_run_with_stderr_closed_still_ends_with_its_exit_code(tmp_path):
    """Started with descriptor 2 closed (`2>&-`), Python has no sys.stderr; the progress bar
    must not crash the run."""
    video = make_noise_video(tmp_path / "nobody.mp4", 8)
    command = [str(PHYSPOSE), "observe", str(video), "--out", str(tmp_path / "o")]
    proc = subprocess.run(["sh", "-c", 'exec "$@" 2>&-', "sh", *command],
                          stdout=subprocess.PIPE, text=True, timeout=120)
    assert proc.returncode == 2, proc.stdout
    assert "Traceback" not in proc.stdout


def test_output_read_by_a_reader_that_went_away_ends_quietly(tmp_path):
    """`physpose ... | head`: the reader closed the pipe before the messages came; the run
    ends as a tool that SIGPIPE ends, without a misleading file-system error."""
    keypoints = _keypoints(tmp_path)
    read_end, write_end = os.pipe()
    os.close(read_end)
    try:
        proc = subprocess.run([str(PHYSPOSE), "observe", str(keypoints), "--out",
                               str(tmp_path / "o")], stdout=write_end,
                              stderr=subprocess.PIPE, text=True, timeout=120)
    finally:
        os.close(write_end)
    assert proc.returncode == 128 + signal.SIGPIPE, proc.stderr
    for word in ("error", "Broken pipe", "Traceback"):
        assert word not in proc.stderr, proc.stderr


def test_video_end_to_end_then_cached(pose2sim_demo, tmp_path, capsys):
    video = pose2sim_demo / "videos" / "cam04.mp4"
    out = tmp_path / "out"
    args = ["observe", str(video), "--out", str(out), "--end", "0.4", "--fps", "10"]
    assert main(args) == 0
    obs = Observations.load(out / "observations.npz")
    assert obs.num_frames == 4 and obs.fps == 10 and obs.detected.all()
    assert obs.frame_indices.tolist() == [0, 6, 12, 18]
    assert obs.camera_motion == "static"
    # The file is what `physpose fit` and `reconstruct` take as precomputed keypoints.
    again = load_keypoints(out / "observations.npz")
    assert again.camera_motion == "static" and again.num_frames == 4
    config = json.loads((out / "config.json").read_text())
    assert config["observe"]["target_fps"] == 10 and config["observe"]["end"] == 0.4
    cap = cv2.VideoCapture(str(out / "overlay_landmarks.mp4"))
    assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == 4
    assert "person found in 4/4" in capsys.readouterr().out
    assert len(list((tmp_path / "cache" / "observe").glob("*.npz"))) == 1
    assert main([*args, "--no-overlay"]) == 0  # second run: from the cache
    assert len(list((tmp_path / "cache" / "observe").glob("*.npz"))) == 1
