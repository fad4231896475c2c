"""The observe stage: gap filling, config checks, clear failures, caching, and the real clip."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest
from synthetic_video import make_noise_video

from physpose.diagnostics import person_jumps
from physpose.errors import PhysposeError
from physpose.joints import LANDMARK_INDEX as LM
from physpose.mask_quality import band_width
from physpose.observe import (ObserveConfig, PoseDetector, _detect_all, downsample_mask,
                              fill_gaps, mask_shape, observe)
from physpose.video import plan_frames, probe, read_frames


@pytest.fixture(autouse=True)
def _private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("PHYSPOSE_CACHE_DIR", str(tmp_path / "cache"))


# --- pure helpers -------------------------------------------------------------------------

def test_fill_gaps_interpolates_short_gaps_linearly():
    values = np.array([0.0, 0, 0, 30, 0, 50, 0, 0, 0, 0, 100, 0])
    detected = np.array([1, 0, 0, 1, 0, 1, 0, 0, 0, 0, 1, 0], bool)
    filled, interp = fill_gaps(values, detected, max_gap=3)
    np.testing.assert_allclose(filled[:6], [0, 10, 20, 30, 40, 50])
    assert interp.tolist() == [0, 1, 1, 0, 1, 0, 0, 0, 0, 0, 0, 0]
    np.testing.assert_array_equal(filled[6:], values[6:])  # gap of 4 > 3 and the trailing gap stay


def test_fill_gaps_handles_landmark_arrays_and_uint8_masks():
    kp = np.zeros((4, 33, 3))
    kp[0], kp[3] = 1.0, 4.0
    filled, interp = fill_gaps(kp, np.array([1, 0, 0, 1], bool), max_gap=2)
    np.testing.assert_allclose(filled[1], 2.0)
    np.testing.assert_allclose(filled[2], 3.0)
    masks = np.zeros((3, 2, 2), np.uint8)
    masks[0], masks[2] = 0, 255
    filled_masks, _ = fill_gaps(masks, np.array([1, 0, 1], bool), max_gap=1)
    assert filled_masks.dtype == np.uint8 and filled_masks[1, 0, 0] == 128


def test_fill_gaps_with_zero_max_gap_fills_nothing():
    filled, interp = fill_gaps(np.arange(3.0), np.array([1, 0, 1], bool), max_gap=0)
    assert not interp.any() and filled[1] == 1.0


def test_mask_is_downsampled_to_the_long_side():
    assert mask_shape((1080, 1920), 256) == (256, 144)
    prob = np.zeros((1920, 1080), np.float32)
    prob[:960] = 1.0
    small = downsample_mask(prob, 256)
    assert small.shape == (256, 144) and small.dtype == np.uint8
    assert small[:127].min() == 255 and small[129:].max() == 0


def test_config_rejects_models_that_need_a_download():
    with pytest.raises(PhysposeError, match="model_complexity=2 is not available offline"):
        ObserveConfig(model_complexity=2)
    with pytest.raises(PhysposeError, match="min_detection_fraction"):
        ObserveConfig(min_detection_fraction=1.5)


# --- failures on synthetic videos ---------------------------------------------------------

def test_video_without_a_person_says_found_in_0_of_n(tmp_path):
    path = make_noise_video(tmp_path / "empty_room.mp4", 12, fps=10)
    with pytest.raises(PhysposeError, match=r"found in only 0 of 12 frames") as err:
        observe(path, ObserveConfig(), progress=False)
    assert "empty_room.mp4" in str(err.value) and "--start/--end" in str(err.value)
    assert not any((tmp_path / "cache").rglob("*.npz"))  # failures are not cached


def test_bad_target_rate_is_rejected_before_any_work(tmp_path):
    path = make_noise_video(tmp_path / "v.mp4", 3)
    with pytest.raises(PhysposeError, match="target frame rate 500"):
        observe(path, ObserveConfig(target_fps=500), progress=False)


# --- the real clip ------------------------------------------------------------------------

@pytest.fixture(scope="module")
def cam01(pose2sim_demo):
    return observe(pose2sim_demo / "videos" / "cam01.mp4", ObserveConfig(use_cache=False),
                   progress=False)


def test_real_clip_is_detected_in_almost_every_frame(cam01):
    assert cam01.fps == 25.0 and cam01.image_size == (1080, 1920)
    assert cam01.num_frames == 42  # 100 frames at 60 fps -> 1.667 s at 25 fps
    assert cam01.detected.mean() > 0.95
    np.testing.assert_allclose(cam01.timestamps, cam01.frame_indices / 60.0)
    assert cam01.masks.shape == (42, 256, 144)


def test_real_clip_landmarks_are_anatomically_sane(cam01):
    ok = cam01.detected
    kp = cam01.keypoints2d[ok]
    y = kp[..., 1]  # image rows grow downwards

    def below(a: str, b: str) -> float:
        return float(np.mean(y[:, LM[a]] > y[:, LM[b]]))

    for side in ("left", "right"):
        assert below(f"{side}_ankle", f"{side}_hip") > 0.95
        assert below(f"{side}_knee", f"{side}_hip") > 0.95
        assert below(f"{side}_hip", f"{side}_shoulder") > 0.95
        assert below(f"{side}_hip", "nose") > 0.95
    w, h = cam01.image_size
    inside = (kp[..., 0] > 0) & (kp[..., 0] < w) & (kp[..., 1] > 0) & (kp[..., 1] < h)
    assert inside[:, [LM["nose"], LM["left_hip"], LM["right_ankle"]]].all()
    # metric: legs are leg-long, shoulders are shoulder-wide
    world = cam01.world_landmarks[ok]

    def dist(a: str, b: str) -> np.ndarray:
        return np.linalg.norm(world[:, LM[a]] - world[:, LM[b]], axis=1)

    for side in ("left", "right"):
        leg = dist(f"{side}_hip", f"{side}_knee") + dist(f"{side}_knee", f"{side}_ankle")
        assert 0.6 < np.median(leg) < 1.1
    assert 0.2 < np.median(dist("left_shoulder", "right_shoulder")) < 0.5
    hips = 0.5 * (world[:, LM["left_hip"]] + world[:, LM["right_hip"]])
    assert np.abs(hips).max() < 0.05  # hip-centred


def test_real_clip_mask_covers_the_person(cam01):
    h, w = cam01.masks.shape[1:]
    sx, sy = w / cam01.image_size[0], h / cam01.image_size[1]
    on_body, hits = 0, 0
    for t in np.flatnonzero(cam01.detected):
        for name in ("left_hip", "right_hip", "left_shoulder", "right_shoulder"):
            x, y = cam01.keypoints2d[t, LM[name], :2]
            hits += 1
            on_body += cam01.masks[t, min(h - 1, int(y * sy)), min(w - 1, int(x * sx))] > 127
    assert on_body / hits > 0.9
    assert cam01.masks.mean() < 0.3 * 255  # the person does not fill the frame


def test_real_clip_masks_are_crisp_outlines(cam01):
    """A person MediaPipe is sure of has a mask whose unsure band is about a pixel wide (stop
    63: at most 1.5 px on cam01), well inside the bound that leaves detections out."""
    width = band_width(cam01.masks[cam01.detected])
    assert np.nanmax(width) < 2.0 < ObserveConfig().unsure_mask_band


def _world_axes_match_opencv(obs) -> tuple[float, float, float]:
    """(corr of world x with image x, same for y, fraction of frames with the nose in front of
    the chest under a right-handed frame)."""
    ok = obs.detected
    k = obs.keypoints2d[ok, :, :2]
    w = obs.world_landmarks[ok]
    kc, wc = k - k.mean(1, keepdims=True), w - w.mean(1, keepdims=True)
    cx = np.corrcoef(kc[..., 0].ravel(), wc[..., 0].ravel())[0, 1]
    cy = np.corrcoef(kc[..., 1].ravel(), wc[..., 1].ravel())[0, 1]
    at = {n: w[:, LM[n]] for n in ("left_shoulder", "right_shoulder", "left_hip", "right_hip",
                                   "nose")}
    left = at["left_shoulder"] - at["right_shoulder"] + at["left_hip"] - at["right_hip"]
    up = at["left_shoulder"] + at["right_shoulder"] - at["left_hip"] - at["right_hip"]
    forward = np.cross(left, up)  # body frame: left x up = forward when right-handed
    nose = at["nose"] - 0.5 * (at["left_shoulder"] + at["right_shoulder"])
    return cx, cy, float(np.mean(np.sum(nose * forward, axis=1) > 0))


def test_world_landmarks_use_opencv_camera_axes(cam01):
    cx, cy, ahead = _world_axes_match_opencv(cam01)
    assert cx > 0.9 and cy > 0.9  # x right, y down, like the image
    assert ahead > 0.95           # right-handed, so z points away from the camera


@pytest.mark.slow
@pytest.mark.parametrize("view", ["cam02", "cam03", "cam04"])
def test_world_axes_hold_in_every_view(pose2sim_demo, view):
    obs = observe(pose2sim_demo / "videos" / f"{view}.mp4", ObserveConfig(use_cache=False),
                  progress=False)
    assert obs.detected.mean() > 0.95
    cx, cy, ahead = _world_axes_match_opencv(obs)
    assert cx > 0.9 and cy > 0.9 and ahead > 0.95


def test_short_gaps_are_interpolated_and_long_gaps_flagged(pose2sim_demo, tmp_path):
    info = probe(pose2sim_demo / "videos" / "cam01.mp4")
    plan = plan_frames(info, 25)
    path = tmp_path / "gaps.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 25, (270, 480))
    blank = {10, 11} | set(range(18, 26))  # a 2-frame and an 8-frame blackout
    for k, (_, image) in enumerate(read_frames(info, plan.indices[:30])):
        image = cv2.resize(image, (270, 480), interpolation=cv2.INTER_AREA)
        writer.write(image * 0 if k in blank else image)
    writer.release()
    obs = observe(path, ObserveConfig(max_gap_frames=5), progress=False)
    assert np.flatnonzero(~obs.detected).tolist() == sorted(blank)
    assert np.flatnonzero(obs.interpolated).tolist() == [10, 11]
    kp = obs.keypoints2d
    np.testing.assert_allclose(kp[10], kp[9] + (kp[12] - kp[9]) / 3)
    assert (kp[18:26] == 0).all() and (obs.world_landmarks[18:26] == 0).all()


def test_cache_hit_for_same_settings_miss_when_they_change(pose2sim_demo, tmp_path, monkeypatch):
    calls = []
    original = PoseDetector.detect

    def counting(self, image):
        calls.append(1)
        return original(self, image)

    monkeypatch.setattr(PoseDetector, "detect", counting)
    video = pose2sim_demo / "videos" / "cam02.mp4"
    cfg = ObserveConfig(end=0.2)  # 5 frames
    first = observe(video, cfg, progress=False)
    assert len(calls) == 5
    again = observe(video, cfg, progress=False)
    assert len(calls) == 5  # hit: MediaPipe did not run
    np.testing.assert_array_equal(again.keypoints2d, first.keypoints2d)
    np.testing.assert_array_equal(again.masks, first.masks)
    assert again.image_size == first.image_size and again.fps == first.fps
    observe(video, ObserveConfig(end=0.2, mask_long_side=64), progress=False)
    assert len(calls) == 10  # miss: a setting changed
    observe(video, ObserveConfig(end=0.2, use_cache=False), progress=False)
    assert len(calls) == 15  # use_cache=False always recomputes
    assert len(list((tmp_path / "cache" / "observe").glob("*.npz"))) == 2
    copy = tmp_path / "renamed.mp4"
    copy.write_bytes(video.read_bytes())
    moved = observe(copy, cfg, progress=False)
    assert len(calls) == 15 and moved.source == str(copy)  # keyed by content, not by name


def test_a_cached_result_gives_the_warnings_of_the_run_that_made_it(pose2sim_demo, tmp_path,
                                                                     monkeypatch, caplog):
    # A variable frame rate, a person followed in a crop, a turning camera: what observe
    # warned about is told again when the same video comes from the cache, under its own name.
    import physpose.observe as observe_module
    original = observe_module._observe_uncached

    def noting(video, *args):
        observe_module._log.warning("%s: the frames are not evenly spaced", video)
        return original(video, *args)

    monkeypatch.setattr(observe_module, "_observe_uncached", noting)
    video = pose2sim_demo / "videos" / "cam02.mp4"
    cfg = ObserveConfig(end=0.1)
    with caplog.at_level("WARNING", logger="physpose.observe"):
        observe(video, cfg, progress=False)
    assert f"{video}: the frames are not evenly spaced" in caplog.text
    monkeypatch.setattr(observe_module, "_observe_uncached", None)  # a miss would fail now
    copy = tmp_path / "copy.mp4"
    copy.write_bytes(video.read_bytes())
    caplog.clear()
    with caplog.at_level("WARNING", logger="physpose.observe"):
        observe(copy, cfg, progress=False)
    assert f"{copy}: the frames are not evenly spaced" in caplog.text


def test_detections_torn_by_a_sun_flare_are_replaced_by_following_the_person_back(
        sports2d_demo):
    """Sports2D's demo starts with the man in front of a sun flare: MediaPipe's forward pass
    misses him in frames 0-2, 4 and 5 and tears him in 3, 6 and 7 (his feet on the flare,
    masks blurred blobs). Those are left out, and a pass running backwards from frame 11
    finds him standing on the box in all of frames 0-7, with crisp masks."""
    cfg = ObserveConfig(end=2.0, use_cache=False)   # shorter, and the crop pass takes over
    info = probe(sports2d_demo)
    raw = _detect_all(info, plan_frames(info, 25.0, None, 2.0), cfg, progress=False)
    assert np.flatnonzero(raw.detected)[:3].tolist() == [3, 6, 7]
    assert band_width(raw.masks[[3, 6, 7]]).min() > 3.0
    assert np.nanmax(band_width(raw.masks[raw.detected][3:])) < 2.0
    kept = observe(sports2d_demo, cfg, progress=False)
    assert kept.detected[:8].all() and kept.unsure is None
    assert np.nanmax(band_width(kept.masks[:8])) < 2.0
    ankles = [LM["left_ankle"], LM["right_ankle"]]
    x = kept.keypoints2d[:8][:, ankles, 0]
    assert np.ptp(x) < 80                                   # standing still, both feet
    assert raw.keypoints2d[3, ankles, 0].min() > x.max() + 200   # torn: out on the flare
    np.testing.assert_array_equal(kept.keypoints2d[8:], raw.keypoints2d[8:])


@pytest.mark.slow
def test_the_subject_is_followed_when_the_tracker_jumps_to_another_person(sports2d_demo):
    """Sports2D's demo: the tracker follows a man on a box, loses him as he somersaults off
    it, takes a woman walking past, then the man again; the second look, masked to where the
    man can be, follows him throughout."""
    info = probe(sports2d_demo)
    plan = plan_frames(info, 25.0, None, None)
    alone = _detect_all(info, plan, ObserveConfig(use_cache=False), progress=False)  # first look
    assert len(person_jumps(alone.keypoints2d, alone.detected, alone.fps)) >= 1
    obs = observe(sports2d_demo, ObserveConfig(use_cache=False), progress=False)
    assert person_jumps(obs.keypoints2d, obs.detected, obs.fps) == []
    assert obs.detected.mean() > 0.9
    # The man lands on the lawn right of the box: the last frames are his, not the woman's
    # (who leaves on the left).
    last = np.flatnonzero(obs.detected)[-5:]
    assert obs.keypoints2d[last][:, [LM["left_hip"], LM["right_hip"]], 0].mean() \
        > 0.6 * obs.image_size[0]


@pytest.mark.slow
def test_a_person_named_by_a_point_is_followed_instead_of_the_one_physpose_picks(sports2d_demo):
    """Sports2D's demo from 2.7 s: physpose would follow the man on the box; a point on the
    woman walking past on the right follows her leftwards across the lawn."""
    cfg = ObserveConfig(start=2.7, end=5.0, person=(1224.0, 720.0), use_cache=False)
    obs = observe(sports2d_demo, cfg, progress=False)
    assert person_jumps(obs.keypoints2d, obs.detected, obs.fps) == []
    hips = obs.keypoints2d[:, [LM["left_hip"], LM["right_hip"]], :2].mean(axis=1)
    seen = np.flatnonzero(obs.detected)
    assert len(seen) > 0.9 * obs.num_frames
    assert hips[seen[0], 0] > 0.6 * obs.image_size[0] and hips[seen[0], 1] > 0.5 * obs.image_size[1]
    assert hips[seen[-1], 0] < hips[seen[0], 0] - 500      # she walks left
    with pytest.raises(PhysposeError, match="no person found at --person 300,80"):
        observe(sports2d_demo, dataclasses.replace(cfg, person=(300.0, 80.0)), progress=False)
    with pytest.raises(PhysposeError, match="outside the 1768x994 image"):
        observe(sports2d_demo, dataclasses.replace(cfg, person=(2000.0, 80.0)), progress=False)


def _shrunk(video, path, scale, corner, frames):
    """The first `frames` analysed frames of `video` shrunk by `scale` into a grey 1280x720
    frame at `corner` (x, y), written to `path`; returns its probe."""
    info = probe(video)
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 25, (1280, 720))
    for _, image in read_frames(info, plan_frames(info, 25).indices[:frames]):
        small = cv2.resize(image, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
        canvas = np.full((720, 1280, 3), 110, np.uint8)
        h, w = small.shape[:2]
        canvas[corner[1]:corner[1] + h, corner[0]:corner[0] + w] = small
        writer.write(canvas)
    writer.release()
    return probe(path)


def _landmark_error(obs, truth, scale, corner):
    """Per confident landmark, px in the full-size video, where both found the person."""
    n = obs.num_frames
    both = obs.detected & truth.detected[:n]
    back = (obs.keypoints2d[both, :, :2] - corner) / scale
    seen = truth.keypoints2d[:n][both, :, 2] > 0.5
    return np.linalg.norm(back - truth.keypoints2d[:n][both, :, :2], axis=-1)[seen]


def test_a_person_too_small_for_the_detector_is_found_in_tiles_and_followed(pose2sim_demo,
                                                                             tmp_path, cam01):
    """cam01 shrunk into a corner of a wide grey frame (the person about a quarter of the image
    height): MediaPipe's whole-frame detector finds nobody, so observe looks in tiles and follows
    the person in a crop; the landmarks land where the full-size video's are."""
    scale, corner = 0.16, (900, 330)
    path = tmp_path / "small.avi"
    small_info = _shrunk(pose2sim_demo / "videos" / "cam01.mp4", path, scale, corner, 20)
    first_look = _detect_all(small_info, plan_frames(small_info, 25),
                             ObserveConfig(use_cache=False), progress=False, check=False)
    assert first_look.detected.mean() < 0.5
    obs = observe(path, ObserveConfig(use_cache=False), progress=False)
    assert obs.detected.mean() > 0.9
    assert np.median(_landmark_error(obs, cam01, scale, corner)) < 20.0  # 3 px of the small image
    # The mask lies on the person in the wide frame.
    k = int(np.flatnonzero(obs.detected)[0])
    mask = obs.masks[k].astype(float) / 255
    ys, xs = np.nonzero(mask > 0.5)
    mh, mw = mask.shape
    hips = obs.keypoints2d[k, [LM["left_hip"], LM["right_hip"]], :2].mean(axis=0)
    assert abs(xs.mean() * 1280 / mw - hips[0]) < 30 and abs(ys.mean() * 720 / mh - hips[1]) < 60


def test_a_small_person_found_only_now_and_then_is_followed_in_a_crop(pose2sim_demo, tmp_path,
                                                                      cam01):
    """cam01 shrunk to a third of the image height: the whole-frame detector finds the person in
    about three quarters of the frames, some of them wrongly; followed in a crop, in every frame
    and where the full-size video puts them."""
    scale, corner = 0.2, (900, 330)
    path = tmp_path / "patchy.avi"
    info = _shrunk(pose2sim_demo / "videos" / "cam01.mp4", path, scale, corner, 42)
    first_look = _detect_all(info, plan_frames(info, 25), ObserveConfig(use_cache=False),
                             progress=False, check=False)
    assert 0.5 <= first_look.detected.mean() < 0.9
    obs = observe(path, ObserveConfig(use_cache=False), progress=False)
    assert obs.detected.mean() > 0.95
    error = _landmark_error(obs, cam01, scale, corner)
    assert np.median(error) < 15.0 < np.median(_landmark_error(first_look, cam01, scale, corner))
