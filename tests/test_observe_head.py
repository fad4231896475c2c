"""The clip's unseen head found again by a pass running backwards (observe._recover_head),
with MediaPipe and the video reader replaced by a scripted detector."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from physpose import observe as observe_mod
from physpose import video as videolib
from physpose.observations import Observations
from physpose.observe import FrameDetection, ObserveConfig, _recover_head

T = 12
FIRST = 5   # the forward pass's first sure detection


def _disc_mask(blur: float, shape=(144, 256)) -> np.ndarray:
    y, x = np.mgrid[:shape[0], :shape[1]]
    prob = (np.hypot(x - shape[1] / 2, y - shape[0] / 2) < 40).astype(np.float32)
    return np.round(255 * cv2.GaussianBlur(prob, (0, 0), blur)).astype(np.uint8)


def _keypoints(x: float) -> np.ndarray:
    kp = np.zeros((33, 3))
    kp[:, 0] = x + np.linspace(-40, 40, 33)
    kp[:, 1] = 300 + np.linspace(-150, 150, 33)
    kp[:, 2] = 0.9
    return kp


def _forward(image_size=(640, 360)) -> Observations:
    kp = np.zeros((T, 33, 3))
    masks = np.zeros((T, 144, 256), np.uint8)
    detected = np.zeros(T, bool)
    for i in range(FIRST, T):
        kp[i], masks[i], detected[i] = _keypoints(300 + 5 * i), _disc_mask(0.6), True
    return Observations(source="clip.mp4", fps=25.0, image_size=image_size,
                        timestamps=np.arange(T) / 25.0, keypoints2d=kp, detected=detected,
                        interpolated=np.zeros(T, bool), world_landmarks=np.zeros((T, 33, 3)),
                        masks=masks)


@pytest.fixture
def scripted(monkeypatch):
    """Frames whose pixels hold their index; a detector answering from `script[index]`
    (None: not found), recording the sizes of the images it was given."""
    script: dict[int, FrameDetection | None] = {}
    seen: list[tuple[int, int]] = []

    def read_frames(info, indices, times=None):
        for i in indices:
            yield int(i), np.full((info.height, info.width, 3), int(i), np.uint8)

    class Detector:
        def __init__(self, cfg, static=False):
            pass

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            pass

        def detect(self, image):
            seen.append(image.shape[:2])
            return script.get(int(image[0, 0, 0]))

    monkeypatch.setattr(videolib, "read_frames", read_frames)
    monkeypatch.setattr(observe_mod, "PoseDetector", Detector)
    return script, seen


def _run(obs: Observations, width=640, height=360) -> Observations:
    info = videolib.VideoInfo(Path("clip.mp4"), 25.0, T, width, height)
    plan = videolib.FramePlan(25.0, np.arange(T), np.arange(T) / 25.0)
    return _recover_head(info, plan, ObserveConfig(), obs, Path("clip.mp4"))


def _found(x: float, blur: float = 0.6, scale: float = 1.0) -> FrameDetection:
    kp = _keypoints(x)
    kp[:, :2] *= scale
    return FrameDetection(kp, np.ones((33, 3)), _disc_mask(blur))


def unsure_at(*frames) -> list[bool]:
    flags = np.zeros(T, bool)
    flags[list(frames)] = True
    return flags.tolist()


def test_the_unseen_head_is_found_by_tracking_the_person_backwards(scripted):
    script, seen = scripted
    script.update({i: _found(300 + 5 * i) for i in range(T)})
    obs = _forward()
    back = _run(obs)
    assert back.detected.all() and back.seen_span() == (0, T - 1)
    np.testing.assert_allclose(back.keypoints2d[:FIRST], [_keypoints(300 + 5 * i)
                                                          for i in range(FIRST)])
    np.testing.assert_array_equal(back.keypoints2d[FIRST:], obs.keypoints2d[FIRST:])
    assert np.all(back.world_landmarks[:FIRST] == 1.0) and back.masks[:FIRST].max() == 255
    assert len(seen) == FIRST + 4   # from 3 frames past the first sure one down to frame 0


def test_the_backward_pass_is_kept_down_to_its_first_miss_jump_or_unsure_mask(scripted):
    script, _ = scripted
    script.update({i: _found(300 + 5 * i) for i in range(T)})
    script[1] = None
    assert _run(_forward()).seen_span() == (2, T - 1)
    script[3] = _found(315, blur=6.0)            # a blurred blob: torn
    assert _run(_forward()).seen_span() == (FIRST - 1, T - 1)
    script[3] = _found(600)                      # someone else, where the person left the view
    assert _run(_forward()).seen_span() == (FIRST - 1, T - 1)


def test_a_backward_pass_that_followed_someone_else_is_not_used(scripted):
    script, _ = scripted
    script.update({i: _found(300 + 5 * i) for i in range(T)})
    script[FIRST] = _found(600)                  # elsewhere at the first sure frame
    obs = _forward()
    assert _run(obs) is obs


def test_large_frames_are_shrunk_for_the_backward_pass_and_its_landmarks_scaled_back(scripted):
    script, seen = scripted
    # Frames of 3840 x 2160 are held at 1920 x 1080: the detector answers in those pixels.
    script.update({i: _found(300 + 5 * i, scale=0.5) for i in range(T)})
    obs = _forward((3840, 2160))
    back = _run(obs, 3840, 2160)
    assert set(seen) == {(1080, 1920)}
    np.testing.assert_allclose(back.keypoints2d[0, :, :2], _keypoints(300)[:, :2])


def test_nothing_is_searched_when_the_person_is_seen_from_the_start_or_long_after_it(scripted):
    _, seen = scripted
    obs = _forward()
    whole = obs.replace(detected=np.ones(T, bool))
    assert _run(whole) is whole
    late = obs.replace(fps=2.0)                  # frame 5 is 2.5 s in: longer than 2 s
    assert _run(late) is late
    assert seen == []


def test_frames_left_out_as_torn_and_found_again_are_no_longer_unsure(scripted):
    script, _ = scripted
    script.update({i: _found(300 + 5 * i) for i in range(T)})
    unsure = np.zeros(T, bool)
    unsure[[2, 4]] = True                        # torn, left out by _drop_unsure
    obs = _forward().replace(unsure=unsure)
    assert _run(obs).unsure is None              # every one found again
    script[3] = None                             # the pass loses the person at frame 3
    left = _run(obs)
    assert left.seen_span() == (4, T - 1) and left.unsure.tolist() == unsure_at(2)


def test_a_person_leaving_the_picture_backwards_is_not_followed_out_of_it(scripted):
    script, _ = scripted
    script.update({i: _found(300 + 5 * i) for i in range(T)})
    # About 70 % of every detection's landmarks lie inside the 360-px-high image; frame 2's,
    # 100 px lower, only about 37 %, though MediaPipe would still call them visible.
    script[2].keypoints2d[:, 1] += 100
    assert _run(_forward()).seen_span() == (3, T - 1)


def test_backward_masks_are_brought_to_the_observations_mask_size(scripted):
    script, _ = scripted
    small = cv2.resize(_disc_mask(0.6), (128, 72), interpolation=cv2.INTER_AREA)
    script.update({i: FrameDetection(_keypoints(300 + 5 * i), np.ones((33, 3)), small)
                   for i in range(T)})
    back = _run(_forward())
    assert back.masks.shape == (T, 144, 256) and back.masks[0].max() > 200


def test_the_backward_pass_sees_only_the_region_the_forward_pass_was_masked_to(scripted,
                                                                            monkeypatch):
    script, _ = scripted
    script.update({i: _found(300 + 5 * i) for i in range(T)})
    masked = []

    def mask_outside(image, region):
        masked.append(tuple(region))
        return image

    monkeypatch.setattr(observe_mod, "mask_outside", mask_outside)
    regions = np.tile([10.0, 20.0, 600.0, 340.0], (T, 1))
    regions[:, 0] += np.arange(T)
    info = videolib.VideoInfo(Path("clip.mp4"), 25.0, T, 640, 360)
    plan = videolib.FramePlan(25.0, np.arange(T), np.arange(T) / 25.0)
    back = _recover_head(info, plan, ObserveConfig(), _forward(), Path("clip.mp4"), regions)
    assert back.detected.all()
    assert [r[0] for r in masked] == [10.0 + i for i in range(FIRST + 4)]
