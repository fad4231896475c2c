"""The person mask's unsure band: its width, and which detections it leaves out."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from physpose.mask_quality import band_width, unsure_frames
from physpose.observations import Observations
from physpose.observe import ObserveConfig, _band_bound, _drop_unsure


def _disc(radius: float, blur: float = 0.0, size: int = 128) -> np.ndarray:
    """A (size, size) uint8 mask of a disc, its edge softened by a Gaussian of sigma blur px."""
    y, x = np.mgrid[:size, :size]
    prob = (np.hypot(x - size / 2, y - size / 2) < radius).astype(np.float32)
    if blur > 0:
        prob = cv2.GaussianBlur(prob, (0, 0), blur)
    return np.round(255 * prob).astype(np.uint8)


def test_a_crisp_outline_is_about_a_pixel_wide_whatever_the_persons_size():
    crisp = band_width(np.stack([_disc(10, 0.6), _disc(40, 0.6)]))
    assert np.all(crisp < 2.0) and abs(crisp[0] - crisp[1]) < 0.3
    assert band_width(_disc(40, 4.0)[None])[0] > 3 * crisp[1]


def test_an_empty_mask_has_no_width():
    assert np.isnan(band_width(np.zeros((1, 8, 8), np.uint8))[0])


def test_only_a_blurred_detection_among_crisp_ones_is_unsure():
    masks = np.stack([_disc(30, 0.6)] * 6 + [_disc(30, 5.0)] + [np.zeros((128, 128), np.uint8)])
    detected = np.array([1, 1, 1, 1, 1, 1, 1, 0], bool)
    assert unsure_frames(masks, detected, 3.0).tolist() == [0, 0, 0, 0, 0, 0, 1, 0]
    assert not unsure_frames(masks, detected, 0.0).any()            # 0 keeps every detection
    assert not unsure_frames(masks, np.zeros(8, bool), 3.0).any()   # nothing detected


def test_a_clip_whose_masks_are_all_soft_loses_nothing():
    masks = np.stack([_disc(30, 4.0), _disc(30, 4.5), _disc(30, 5.0)])
    assert band_width(masks).min() > 3.0
    assert not unsure_frames(masks, np.ones(3, bool), 3.0).any()


def _observations(masks: np.ndarray) -> Observations:
    t = len(masks)
    kp = np.zeros((t, 33, 3))
    kp[:, :, 0] = np.arange(t)[:, None] * 10.0   # x moves 10 px per frame
    kp[:, :, 1] = 50.0
    kp[:, :, 2] = 0.9
    world = np.repeat(np.linspace(0, 1, 33)[None, :, None], t, 0) * np.ones((1, 1, 3))
    return Observations(source="clip.mp4", fps=25.0, image_size=(128, 128),
                        timestamps=np.arange(t) / 25.0, keypoints2d=kp,
                        detected=np.ones(t, bool), interpolated=np.zeros(t, bool),
                        world_landmarks=world, masks=masks)


def test_an_unsure_detection_becomes_a_gap_filled_from_its_neighbours():
    masks = np.stack([_disc(30, 0.6)] * 3 + [_disc(30, 5.0)] + [_disc(30, 0.6)] * 3)
    obs = _observations(masks)
    obs.keypoints2d[3, :, 0] = 500.0           # the torn landmarks
    kept = _drop_unsure(obs, ObserveConfig())
    assert kept.detected.tolist() == [1, 1, 1, 0, 1, 1, 1]
    assert kept.unsure.tolist() == [0, 0, 0, 1, 0, 0, 0]
    assert kept.interpolated.tolist() == [0, 0, 0, 1, 0, 0, 0]
    np.testing.assert_allclose(kept.keypoints2d[3, :, 0], 30.0)   # between 20 and 40
    np.testing.assert_array_equal(kept.masks[3], masks[2])        # both neighbours alike


def test_unsure_detections_at_the_start_are_left_unseen_not_filled():
    masks = np.stack([_disc(30, 5.0)] * 2 + [_disc(30, 0.6)] * 6)
    kept = _drop_unsure(_observations(masks), ObserveConfig())
    assert kept.detected.tolist() == [0, 0, 1, 1, 1, 1, 1, 1]
    assert not kept.interpolated.any() and kept.seen_span() == (2, 7)
    assert np.all(kept.keypoints2d[:2] == 0) and np.all(kept.masks[:2] == 0)


def test_the_band_bound_scales_with_the_masks_own_size_and_zero_turns_it_off():
    assert _band_bound(np.zeros((1, 144, 256), np.uint8), ObserveConfig()) == 3.0
    # A small video's masks are smaller than mask_long_side asks: the bound follows them.
    assert _band_bound(np.zeros((1, 64, 36), np.uint8), ObserveConfig()) == 0.75
    assert _band_bound(np.zeros((1, 512, 288), np.uint8), ObserveConfig()) == 6.0
    masks = np.stack([_disc(30, 0.6)] * 3 + [_disc(30, 5.0)] + [_disc(30, 0.6)] * 3)
    obs = _observations(masks)
    assert _drop_unsure(obs, ObserveConfig(unsure_mask_band=0)) is obs
    assert _drop_unsure(obs.replace(masks=None), ObserveConfig()).unsure is None


def test_a_faint_blob_with_nothing_sure_in_it_is_unsure_and_an_empty_mask_is_no_mask():
    faint = np.round(0.45 * _disc(30, 5.0)).astype(np.uint8)      # peaks under 0.5
    widths = band_width(np.stack([faint, np.zeros_like(faint)]))
    assert widths[0] == np.inf and np.isnan(widths[1])
    masks = np.stack([_disc(30, 0.6)] * 5 + [faint])
    assert unsure_frames(masks, np.ones(6, bool), 3.0).tolist() == [0, 0, 0, 0, 0, 1]


@pytest.mark.parametrize("band", [-1.0, float("nan")])
def test_config_rejects_a_band_that_is_no_width(band):
    with pytest.raises(Exception, match="unsure_mask_band"):
        ObserveConfig(unsure_mask_band=band)
