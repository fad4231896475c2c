"""Precomputed keypoints: JSON/npz round trips, defaults, and errors naming file, frame, remedy."""

from __future__ import annotations

import json

import numpy as np
import pytest

from physpose.errors import PhysposeError
from physpose.joints import LANDMARK_NAMES
from physpose.keypoints_io import load_keypoints, save_keypoints
from physpose.observations import Observations

T = 6


def _doc(**changes) -> dict:
    rng = np.random.default_rng(0)
    kp = np.concatenate([rng.uniform(0, 300, (T, 33, 2)), rng.uniform(0.2, 1, (T, 33, 1))], -1)
    doc = {"fps": 30.0, "image_size": [320, 240], "keypoints2d": kp.tolist(),
           "world_landmarks": rng.normal(0, 0.3, (T, 33, 3)).tolist(),
           "camera_K": [[300, 0, 160], [0, 300, 120], [0, 0, 1]]}
    doc.update(changes)
    return {k: v for k, v in doc.items() if v is not ...}


def _write_json(tmp_path, doc, name="kp.json"):
    path = tmp_path / name
    path.write_text(json.dumps(doc))
    return path


def _write_npz(tmp_path, doc, name="kp.npz"):
    path = tmp_path / name
    np.savez(path, **{k: np.asarray(v) for k, v in doc.items()})
    return path


@pytest.mark.parametrize("writer", [_write_json, _write_npz])
def test_minimal_file_loads_with_defaults(tmp_path, writer):
    doc = _doc(world_landmarks=..., camera_K=...)
    doc["keypoints2d"][2] = np.zeros((33, 3)).tolist()  # a frame without a detection
    obs = load_keypoints(writer(tmp_path, doc))
    assert obs.num_frames == T and obs.fps == 30.0 and obs.image_size == (320, 240)
    np.testing.assert_allclose(obs.timestamps, np.arange(T) / 30.0)
    assert obs.detected.tolist() == [True, True, False, True, True, True]
    assert not obs.interpolated.any() and obs.world_landmarks is None and obs.camera_K is None


@pytest.mark.parametrize("ext", [".json", ".npz"])
def test_save_then_load_round_trips(tmp_path, ext):
    original = load_keypoints(_write_json(tmp_path, _doc(timestamps=(np.arange(T) * 0.04 + 1).tolist())))
    turned = np.repeat(np.eye(3)[None], T, axis=0)
    turned[:, 0, 2] = np.arange(T)    # where a turning camera's observe stage left them
    original = original.replace(interpolated=np.array([0, 0, 1, 0, 0, 0], bool),
                                frame_indices=np.arange(T) * 2, homographies=turned,
                                camera_motion="turning",
                                unsure=np.array([1, 0, 0, 0, 0, 0], bool))
    back = load_keypoints(save_keypoints(original, tmp_path / f"copy{ext}"))
    assert back.unsure.dtype == bool
    for key in ("keypoints2d", "world_landmarks", "camera_K", "timestamps", "detected",
                "interpolated", "frame_indices", "homographies", "unsure"):
        np.testing.assert_allclose(getattr(back, key), getattr(original, key), err_msg=key)
    assert back.fps == original.fps and back.image_size == original.image_size
    assert back.camera_motion == "turning"


def test_observations_npz_is_a_keypoints_file(tmp_path):
    obs = load_keypoints(_write_json(tmp_path, _doc()))
    obs = obs.replace(masks=np.zeros((T, 4, 3), np.uint8), unsure=np.zeros(T, bool))
    back = load_keypoints(obs.save(tmp_path / "observations.npz"))
    assert back.masks.shape == (T, 4, 3) and back.unsure.shape == (T,)
    np.testing.assert_array_equal(back.keypoints2d, obs.keypoints2d)


def test_landmark_names_guard(tmp_path):
    names = list(LANDMARK_NAMES)
    assert load_keypoints(_write_json(tmp_path, _doc(landmark_names=names))).num_frames == T
    names[11], names[12] = names[12], names[11]
    with pytest.raises(PhysposeError, match="landmark_names differ"):
        load_keypoints(_write_json(tmp_path, _doc(landmark_names=names)))


def _error(tmp_path, doc, writer=_write_json) -> str:
    with pytest.raises(PhysposeError) as err:
        load_keypoints(writer(tmp_path, doc))
    text = str(err.value)
    assert "kp." in text and "docs/keypoints_format.md" in text  # names the file and the doc
    return text


@pytest.mark.parametrize("writer", [_write_json, _write_npz])
def test_nan_names_the_frame(tmp_path, writer):
    doc = _doc()
    doc["keypoints2d"][3][5][0] = float("nan")
    text = _error(tmp_path, doc, writer)
    assert "frame 3" in text and "NaN" in text and "confidence 0" in text


def test_json_null_is_treated_as_missing_value(tmp_path):
    doc = _doc()
    doc["world_landmarks"][4][0][2] = None
    assert "frame 4: world_landmarks contains NaN" in _error(tmp_path, doc)


@pytest.mark.parametrize("writer", [_write_json, _write_npz])
def test_missing_required_keys(tmp_path, writer):
    text = _error(tmp_path, _doc(fps=..., keypoints2d=...), writer)
    assert "missing required key(s) fps, keypoints2d" in text


@pytest.mark.parametrize("shape", [(T, 17, 3), (T, 33, 2), (33, 3), (0, 33, 3)])
def test_wrong_keypoint_shapes(tmp_path, shape):
    text = _error(tmp_path, _doc(keypoints2d=np.zeros(shape)), _write_npz)
    assert f"keypoints2d has shape {shape}" in text and "(T, 33, 3)" in text


def test_world_landmarks_with_a_different_frame_count(tmp_path):
    text = _error(tmp_path, _doc(world_landmarks=np.zeros((T - 1, 33, 3)).tolist()))
    assert f"world_landmarks has shape ({T - 1}, 33, 3), expected ({T}, 33, 3)" in text


def test_ragged_lists(tmp_path):
    doc = _doc()
    doc["keypoints2d"][1] = doc["keypoints2d"][1][:20]
    assert "not a rectangular array" in _error(tmp_path, doc)


@pytest.mark.parametrize("fps", [0, -25, 5000, "25", None, True, [25, 30]])
def test_bad_fps(tmp_path, fps):
    assert "is not a frame rate" in _error(tmp_path, _doc(fps=fps))


@pytest.mark.parametrize("size", [[320], [0, 240], [320.5, 240], "320x240"])
def test_bad_image_size(tmp_path, size):
    assert "image_size" in _error(tmp_path, _doc(image_size=size))


def test_confidence_outside_unit_interval(tmp_path):
    doc = _doc()
    doc["keypoints2d"][2][7][2] = 95.0
    text = _error(tmp_path, doc)
    assert "frame 2" in text and "confidence 95 is outside [0, 1]" in text


def test_keypoints_far_outside_the_image_are_refused(tmp_path):
    doc = _doc()
    kp = np.array(doc["keypoints2d"])
    kp[3, 5] = [1e12, 100.0, 0.9]
    assert "frame 3" in _error(tmp_path, _doc(keypoints2d=kp.tolist()))
    assert "more than a picture away" in _error(tmp_path, _doc(keypoints2d=kp.tolist()))
    kp[3, 5, 2] = 1e-5  # MediaPipe's guess at an ankle out of view: far, but not sure
    kp[2, 0] = [-100.0, 400.0, 0.9]  # sure, a little outside the 320 x 240 picture
    load_keypoints(_write_json(tmp_path, _doc(keypoints2d=kp.tolist())))


def test_timestamps_must_increase(tmp_path):
    text = _error(tmp_path, _doc(timestamps=[0, 0.1, 0.2, 0.2, 0.3, 0.4]))
    assert "frame 3" in text and "not strictly increasing" in text


def test_unknown_key_is_probably_a_typo(tmp_path):
    assert "unknown key(s) world_landmark" in _error(tmp_path, _doc(world_landmark=[]))


def test_bad_camera_motion(tmp_path):
    with pytest.raises(PhysposeError, match=r"homographies has shape \(2, 3, 3\)"):
        load_keypoints(_write_json(tmp_path, _doc(homographies=np.zeros((2, 3, 3)).tolist())))
    with pytest.raises(PhysposeError, match="camera_motion 'panning' is not one of static, turning, moving"):
        load_keypoints(_write_json(tmp_path, _doc(camera_motion="panning")))


def test_bad_camera_matrix(tmp_path):
    assert "camera_K has shape (2, 2)" in _error(tmp_path, _doc(camera_K=[[1, 0], [0, 1]]))


def test_errors_found_by_the_observations_name_the_file_passed(tmp_path):
    """A keypoints file records the video it came from; a problem in the file is still
    reported against the file."""
    path = _write_npz(tmp_path, _doc(source="/videos/clip.mp4", masks=np.zeros((2, 3))))
    with pytest.raises(PhysposeError, match=r"masks has shape \(2, 3\)") as caught:
        load_keypoints(path)
    assert caught.value.path == str(path)


def test_unreadable_containers(tmp_path):
    (tmp_path / "kp.json").write_text("{not json")
    with pytest.raises(PhysposeError, match="not valid JSON"):
        load_keypoints(tmp_path / "kp.json")
    (tmp_path / "kp.npz").write_bytes(b"garbage")
    with pytest.raises(PhysposeError, match="not a readable npz"):
        load_keypoints(tmp_path / "kp.npz")
    (tmp_path / "list.json").write_text("[1, 2]")
    with pytest.raises(PhysposeError, match="top level must be an object"):
        load_keypoints(tmp_path / "list.json")
    with pytest.raises(PhysposeError, match="keypoints file not found"):
        load_keypoints(tmp_path / "absent.json")


def test_result_is_observations(tmp_path):
    assert isinstance(load_keypoints(_write_json(tmp_path, _doc())), Observations)


def test_bad_masks_are_refused(tmp_path):
    assert "masks is not a rectangular array" in _error(
        tmp_path, _doc(masks=[[[0, 1], [2, 3]]] * (T - 1) + [[[0, 1]]]))
    nan_masks = np.zeros((T, 2, 2))
    nan_masks[2, 1, 1] = np.nan
    assert "masks must hold numbers 0-255" in _error(tmp_path, _doc(masks=nan_masks.tolist()))


def test_a_singular_homography_names_its_frame(tmp_path):
    maps = np.tile(np.eye(3), (T, 1, 1))
    maps[4] = 0.0
    text = _error(tmp_path, _doc(homographies=maps.tolist()))
    assert "frame 4" in text and "singular" in text


def test_timestamps_at_another_rate_than_fps_are_refused(tmp_path):
    text = _error(tmp_path, _doc(timestamps=(np.arange(T) / 100.0).tolist()))
    assert "timestamps are 100 frames a second, fps says 30" in text


def test_a_camera_matrix_that_is_not_a_pinhole_is_blamed_on_the_file(tmp_path):
    text = _error(tmp_path, _doc(camera_K=[[0, 0, 0], [0, 0, 0], [0, 0, 0]], source="walk.mp4"))
    assert "not a pinhole matrix" in text and "walk.mp4" not in text


def test_another_format_is_refused(tmp_path):
    assert "is not physpose-keypoints version 1" in _error(tmp_path, _doc(format="coco"))


def test_timestamps_of_frames_picked_at_a_lower_rate_load(tmp_path):
    """`physpose observe --fps 20` on a 30 fps video keeps frames 0, 2, 3, 5, 6, 8
    (video.plan_frames): their median step says 15 frames a second, their mean 20."""
    times = np.array([0, 2, 3, 5, 6, 8]) / 30.0
    obs = load_keypoints(_write_json(tmp_path, _doc(fps=20.0, timestamps=times.tolist())))
    np.testing.assert_allclose(obs.timestamps, times)
