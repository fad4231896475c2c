"""Following one person: the detections split where the detector jumped to someone else, the
subject's tracks, and where each frame is masked for the second look (observe.py)."""

from __future__ import annotations

import numpy as np

from physpose.subject import (Follower, covers, mask_outside, seed_regions, square_crop,
                              subject_regions, tiles,
                              subject_tracks)

FPS = 25.0


def _person(frames: np.ndarray, x0: float, speed: float, size: float, y: float = 500.0):
    """(F, 33, 3) detections of a person-sized cloud of points moving right at speed px/s."""
    shape = np.random.default_rng(1).uniform(-0.5, 0.5, (33, 2)) * [0.4 * size, size]
    kp = np.ones((len(frames), 33, 3))
    kp[..., 0] = (x0 + speed * frames / FPS)[:, None] + shape[:, 0]
    kp[..., 1] = y + shape[:, 1]
    return kp


def _switching_clip():
    """The subject walks right through 120 frames; in frames 60-79 the detector follows a
    nearer person (twice the size) on the far left instead."""
    frames = np.arange(120)
    kp = _person(frames, 900.0, 150.0, 300.0)
    kp[60:80] = _person(frames[60:80], 100.0, 100.0, 600.0, y=700.0)
    return kp


def test_the_subject_is_the_longest_track_and_the_tracks_that_continue_it():
    tracks, subject = subject_tracks(_switching_clip(), np.ones(120, bool), FPS)
    assert [(t[0], t[-1]) for t in tracks] == [(0, 59), (60, 79), (80, 119)]
    assert subject.tolist() == [True, False, True]
    # One person throughout: one track.
    tracks, subject = subject_tracks(_person(np.arange(50), 900.0, 150.0, 300.0),
                                     np.ones(50, bool), FPS)
    assert len(tracks) == 1 and subject.tolist() == [True]


def test_regions_hold_the_subject_and_leave_the_other_person_out():
    kp = _switching_clip()
    boxes = subject_regions(kp, np.ones(120, bool), FPS, (1920, 1080))
    assert boxes.shape == (120, 4)
    inside = lambda b, p: (b[0] <= p[0] <= b[2]) and (b[1] <= p[1] <= b[3])  # noqa: E731
    subject = _person(np.arange(120), 900.0, 150.0, 300.0)
    for t in range(120):
        centre = subject[t, :, :2].mean(axis=0)
        assert inside(boxes[t], centre)               # where the subject is (or was going)
    for t in range(60, 80):
        assert not inside(boxes[t], kp[t, :, :2].mean(axis=0))   # the other person is out
    # Where the subject is detected the region is its box plus half a diagonal each side.
    lo, hi = kp[10, :, :2].min(axis=0), kp[10, :, :2].max(axis=0)
    grow = 0.5 * np.linalg.norm(hi - lo)
    np.testing.assert_allclose(boxes[10], np.concatenate([lo - grow, hi + grow]), atol=1e-6)


def test_mask_outside_blacks_out_everything_but_the_box():
    image = np.full((40, 60, 3), 200, np.uint8)
    out = mask_outside(image, np.array([10.2, 5.0, 30.0, 20.7]))
    assert out[5:21, 10:30].min() == 200 and out.sum() == 200 * 3 * 16 * 20
    assert mask_outside(image, np.array([0.0, 0.0, 60.0, 40.0])).min() == 200


def test_a_named_person_is_found_by_a_point_on_them_and_followed():
    walker = _person(np.arange(40), 900.0, 150.0, 300.0)
    assert covers(walker[0], (900.0, 500.0)) and not covers(walker[0], (300.0, 500.0))
    # The boxes tried around the point: the whole image, then smaller squares on the point.
    boxes = seed_regions((900.0, 500.0), (1920, 1080))
    assert boxes[0].tolist() == [0, 0, 1920, 1080]
    sides = [b[2] - b[0] for b in boxes[1:]]
    assert sides == sorted(sides, reverse=True)
    assert all(b[0] <= 900 <= b[2] and b[1] <= 500 <= b[3] for b in boxes)
    # Following: each frame's region holds the walker's next detection, not a person
    # standing 600 px to the left; while unseen the region widens.
    follow = Follower(walker[0], FPS, (1920, 1080))
    for t in range(1, 40):
        x0, y0, x1, y1 = follow.region()
        centre = walker[t, :, :2].mean(axis=0)
        assert x0 <= centre[0] <= x1 and y0 <= centre[1] <= y1 and x0 > 300 + 150 * t / FPS
        follow.update(walker[t] if t < 30 else None)
    width = lambda b: b[2] - b[0]  # noqa: E731
    before = width(follow.region())
    follow.update(None)
    assert width(follow.region()) > before


def test_tiles_cover_the_image_at_every_size():
    boxes = tiles((1280, 720))
    for size in (0.6, 0.4, 0.25):
        side = size * 720
        group = [b for b in boxes if np.isclose(b[2] - b[0], side)]
        covered = np.zeros((720, 1280), bool)
        for x0, y0, x1, y1 in np.round(group).astype(int):
            assert 0 <= x0 and x1 <= 1280 and 0 <= y0 and y1 <= 720
            covered[y0:y1, x0:x1] = True
        assert covered.all()


def test_square_crop_maps_pixels_back_and_pads_outside_the_image():
    image = np.zeros((100, 200, 3), np.uint8)
    image[40, 190] = 255                      # a bright pixel near the right edge
    crop, origin, scale = square_crop(image, np.array([170.0, 30.0, 210.0, 50.0]), 80)
    assert crop.shape == (80, 80, 3) and scale == 0.5      # a 40 px square scaled up twice
    y, x = np.unravel_index(np.argmax(crop[..., 0]), crop.shape[:2])
    assert np.allclose(np.array([x, y]) * scale + origin, [190, 40], atol=1.0)
    assert (crop[:, -10:] == 128).all()       # beyond the image's right edge: grey
