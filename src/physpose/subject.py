"""One person through a clip: which detections are the subject, and where to look for it.

MediaPipe's legacy pose tracker follows one person and, when it loses that person, takes
whichever person its detector finds next (on Sports2D's demo video it jumps from a man
somersaulting off a box to a woman walking past, and back). `subject_tracks` splits the
detections at those jumps (`diagnostics.person_jumps`) into tracks and keeps as the subject the
track with the most frames plus the tracks that plausibly continue it (a similar image size,
and a place it can have reached at LINK_SPEED). `subject_regions` gives, per frame, the image
box the subject can be in: around its own detection, or between its detections before and
after, widening with the time since it was seen. observe.py runs the detector a second time on
frames masked to those boxes, so another person is not in view.

A user can also name the person (`ObserveConfig.person`, `--person X,Y`): a point on them in
the first analysed frame. `seed_regions` are the image boxes tried there, `covers` tells whether
a detection is the person at that point, and `Follower` gives each next frame's box around the
person's last detection, so the detector only ever sees that person.

A person too small in the image for MediaPipe's detector (which sees the whole frame shrunk to
a couple of hundred pixels) is found in `tiles` of the frame instead, and then followed in a
square crop around their last detection (`square_crop`), scaled up, so they fill the detector's
view.
"""

from __future__ import annotations

import cv2
import numpy as np

from physpose.diagnostics import (JUMP_SIZES, image_box_corners, image_boxes,
                                  person_jumps, size_ratio)

LINK_SPEED = 2.0   # box diagonals per second a subject's image box may move while unseen
LINK_SIZE = 1.5    # at most this ratio between the box sizes of two tracks of one subject
MARGIN = 0.5       # box diagonals added around the subject's box on every side


def subject_tracks(keypoints2d: np.ndarray, detected: np.ndarray, fps: float
                   ) -> tuple[list[np.ndarray], np.ndarray]:
    """The detections split at person jumps: (tracks, subject), tracks a list of frame-index
    arrays in time order and subject a bool array (one per track)."""
    centre, diagonal, ok = image_boxes(keypoints2d)
    frames = np.flatnonzero(np.asarray(detected, dtype=bool) & ok)
    if not len(frames):
        return [], np.zeros(0, bool)
    cuts = np.searchsorted(frames, person_jumps(keypoints2d, detected, fps))
    tracks = np.split(frames, cuts)
    subject = np.zeros(len(tracks), bool)
    main = int(np.argmax([len(t) for t in tracks]))
    subject[main] = True

    def continues(a: int, b: int) -> bool:
        """Track b is where the subject, last seen at frame a, can be at frame b."""
        size = 0.5 * (diagonal[a] + diagonal[b])
        reach = size * (JUMP_SIZES + LINK_SPEED * abs(b - a) / fps)
        return size_ratio(diagonal[a], diagonal[b]) <= LINK_SIZE \
            and np.linalg.norm(centre[b] - centre[a]) <= reach

    last = tracks[main][-1]
    for k in range(main + 1, len(tracks)):
        if continues(last, tracks[k][0]):
            subject[k], last = True, tracks[k][-1]
    first = tracks[main][0]
    for k in range(main - 1, -1, -1):
        if continues(first, tracks[k][-1]):
            subject[k], first = True, tracks[k][0]
    return tracks, subject


def subject_regions(keypoints2d: np.ndarray, detected: np.ndarray, fps: float,
                    image_size: tuple[int, int]) -> np.ndarray:
    """(T, 4) image boxes [x0, y0, x1, y1] (pixels, clipped to the image) where the subject
    can be in each frame: its box grown by MARGIN diagonals where it was detected; elsewhere
    the box interpolated between its detections before and after (or held from the nearer
    one), grown further by LINK_SPEED diagonals per second since or until it was seen."""
    keypoints2d = np.asarray(keypoints2d, dtype=float)
    t = len(keypoints2d)
    width, height = image_size
    full = np.array([0.0, 0.0, float(width), float(height)])
    tracks, subject = subject_tracks(keypoints2d, detected, fps)
    seen = np.concatenate([tr for tr, s in zip(tracks, subject) if s]) if subject.any() \
        else np.zeros(0, int)
    if not len(seen):
        return np.tile(full, (t, 1))
    lo, hi, _ = image_box_corners(keypoints2d)
    lo, hi = lo[seen], hi[seen]   # every subject frame has a box (its tracks are made of them)
    frames = np.arange(t)
    lo_all = np.stack([np.interp(frames, seen, lo[:, i]) for i in range(2)], axis=1)
    hi_all = np.stack([np.interp(frames, seen, hi[:, i]) for i in range(2)], axis=1)
    diagonal = np.linalg.norm(hi_all - lo_all, axis=1)
    # Frames to the nearest subject detection, before or after.
    after = np.searchsorted(seen, frames)
    before_gap = np.where(after > 0, frames - seen[np.maximum(after - 1, 0)], np.inf)
    at = np.minimum(after, len(seen) - 1)
    after_gap = np.where(after < len(seen), seen[at] - frames, np.inf)
    gap = np.minimum(before_gap, after_gap)
    grow = diagonal * (MARGIN + LINK_SPEED * gap / fps)
    boxes = np.concatenate([lo_all - grow[:, None], hi_all + grow[:, None]], axis=1)
    return np.clip(boxes, full[[0, 1, 0, 1]], full[[2, 3, 2, 3]])


def mask_outside(image: np.ndarray, box: np.ndarray) -> np.ndarray:
    """A copy of an image (H, W, 3) with everything outside box [x0, y0, x1, y1] black."""
    x0, y0 = np.floor(box[:2]).astype(int)
    x1, y1 = np.ceil(box[2:]).astype(int)
    out = np.zeros_like(image)
    out[max(y0, 0):max(y1, 0), max(x0, 0):max(x1, 0)] = \
        image[max(y0, 0):max(y1, 0), max(x0, 0):max(x1, 0)]
    return out


TILE_SIZES = (0.6, 0.4, 0.25)   # sides of the square tiles searched for a small person, in
                                # image heights; tiles overlap by half a side


def tiles(image_size: tuple[int, int]) -> list[np.ndarray]:
    """Square boxes [x0, y0, x1, y1] covering the image at each of TILE_SIZES, largest first."""
    width, height = image_size

    def starts(length: float, side: float) -> np.ndarray:   # half a side apart, both ends
        return np.linspace(0.0, length - side, int(np.ceil((length - side) / (side / 2))) + 1)

    boxes = []
    for size in TILE_SIZES:
        side = size * min(width, height)
        boxes += [np.array([x, y, x + side, y + side])
                  for y in starts(height, side) for x in starts(width, side)]
    return boxes


def square_crop(image: np.ndarray, box: np.ndarray, size: int
                ) -> tuple[np.ndarray, np.ndarray, float]:
    """The square around box [x0, y0, x1, y1] (its longer side, centred; the image padded with
    grey where it reaches outside) resized to size x size px. Returns the crop, its top-left
    corner in the image (x, y) and the image pixels per crop pixel."""
    centre = 0.5 * (box[:2] + box[2:])
    side = max(float(np.max(box[2:] - box[:2])), 8.0)
    x0, y0 = np.floor(centre - side / 2).astype(int)
    n = int(np.ceil(side))
    height, width = image.shape[:2]
    pad = max(0, -x0, -y0, x0 + n - width, y0 + n - height)
    padded = cv2.copyMakeBorder(image, pad, pad, pad, pad, cv2.BORDER_CONSTANT,
                                value=(128, 128, 128)) if pad else image
    crop = padded[y0 + pad:y0 + pad + n, x0 + pad:x0 + pad + n]
    scale = n / size
    resized = cv2.resize(crop, (size, size), interpolation=cv2.INTER_AREA if scale > 1
                         else cv2.INTER_LINEAR)
    return resized, np.array([x0, y0], dtype=float), scale


SEED_HALF_SIZES = (0.5, 0.3, 0.18)   # half-sides of the boxes tried around a --person point,
                                      # in image heights (after the whole image)
COVER_MARGIN = 0.15                   # a detection covers a point within this many diagonals


def seed_regions(point: tuple[float, float], image_size: tuple[int, int]) -> list[np.ndarray]:
    """The image boxes [x0, y0, x1, y1] tried in the first frame to find the person at a point:
    the whole image, then squares centred on the point, smaller and smaller, so that a more
    prominent person elsewhere ends up outside the box."""
    width, height = image_size
    x, y = point
    boxes = [np.array([0.0, 0.0, float(width), float(height)])]
    for half in SEED_HALF_SIZES:
        h = half * height
        boxes.append(np.clip([x - h, y - h, x + h, y + h], 0.0, [width, height, width, height]))
    return boxes


def detection_box(keypoints2d: np.ndarray) -> np.ndarray | None:
    """[x0, y0, x1, y1] of one detection's (33, 3) confident landmarks, None if too few."""
    lo, hi, ok = image_box_corners(np.asarray(keypoints2d, dtype=float)[None])
    return np.concatenate([lo[0], hi[0]]) if ok[0] else None


def covers(keypoints2d: np.ndarray, point: tuple[float, float]) -> bool:
    """Whether one detection's (33, 3) confident landmarks' box, grown by COVER_MARGIN of its
    diagonal, contains the point."""
    box = detection_box(keypoints2d)
    if box is None:
        return False
    grow = COVER_MARGIN * np.linalg.norm(box[2:] - box[:2])
    p = np.asarray(point, dtype=float)
    return bool(np.all(p >= box[:2] - grow) and np.all(p <= box[2:] + grow))


class Follower:
    """Where one person can be in the next frame: around their last detection's image box,
    grown by MARGIN diagonals, and by LINK_SPEED diagonals per second while they are unseen."""

    def __init__(self, keypoints2d: np.ndarray, fps: float, image_size: tuple[int, int]):
        self.fps = fps
        self.full = np.array([0.0, 0.0, float(image_size[0]), float(image_size[1])])
        self.unseen = 0
        self._box = detection_box(keypoints2d)

    def region(self) -> np.ndarray:
        """The box [x0, y0, x1, y1] (pixels, clipped to the image) to look in next."""
        lo, hi = self._box[:2], self._box[2:]
        grow = np.linalg.norm(hi - lo) * (MARGIN + LINK_SPEED * self.unseen / self.fps)
        return np.clip(np.concatenate([lo - grow, hi + grow]), self.full[[0, 1, 0, 1]],
                       self.full[[2, 3, 2, 3]])

    def update(self, keypoints2d: np.ndarray | None) -> None:
        """Take this frame's detection in the region (None: not found)."""
        box = None if keypoints2d is None else detection_box(keypoints2d)
        if box is None:
            self.unseen += 1
        else:
            self._box, self.unseen = box, 0
