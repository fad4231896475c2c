"""How sure MediaPipe's person mask is of where the person is, frame by frame.

A mask MediaPipe is sure of passes from background to person across a band of unsure values
about one mask pixel wide. When its landmark model was handed a poor region of the image, the
mask is a blurred blob instead, and the same frame's landmarks are torn: on Sports2D's demo
(a man in front of a sun flare) the first detections put the legs on the flare with
visibilities above 0.5, and the kinematic fit laid the body on the floor and moved it 3 m in
depth over 12 frames. Neither the landmarks' own visibility nor their bone lengths tell those
frames apart (dynamics_history.md, stop 62); the mask's unsure band does.

`band_width` is the unsure pixels (values between UNSURE_LOW and UNSURE_HIGH) per pixel of the
outline of the mask's confident region: a width in mask pixels, independent of how large the
person is in the image. Measured at a 256-pixel mask (stop 63): the torn frames 3.6-6.2; every
detected frame of the three shared videos and the four pose2sim views at most 2.5 (clip medians
0.9-1.4). `unsure_frames` flags frames both wider than a bound and over UNSURE_RATIO times their
clip's median, so a clip whose masks are all soft (low light, a blurred camera) loses nothing.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import binary_erosion

UNSURE_LOW, UNSURE_HIGH = 0.15, 0.85   # mask probabilities counted as unsure
UNSURE_RATIO = 2.0                      # a flagged frame's band is at least this x the median


def band_width(masks: np.ndarray) -> np.ndarray:
    """(T,) width in mask pixels of each mask's unsure band: pixels with probability between
    UNSURE_LOW and UNSURE_HIGH per outline pixel of the region above 0.5; NaN where that region
    is empty. masks: (T, h, w) uint8 probability x 255."""
    masks = np.asarray(masks)
    prob = masks.astype(np.float32) / 255.0
    inside = prob > 0.5
    outline = np.array([(m & ~binary_erosion(m)).sum() for m in inside], dtype=float)
    unsure = ((prob > UNSURE_LOW) & (prob < UNSURE_HIGH)).sum(axis=(1, 2))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(outline > 0, unsure / outline, np.nan)


def band_limit(masks: np.ndarray, detected: np.ndarray, max_width: float) -> float:
    """The widest unsure band a detection of this clip may have: max_width mask pixels, or
    UNSURE_RATIO times the median over the detected frames where that is more (inf when
    max_width <= 0 or no detected frame has a mask)."""
    detected = np.asarray(detected, dtype=bool)
    if max_width <= 0 or not detected.any():
        return np.inf
    width = band_width(np.asarray(masks)[detected])
    if np.isnan(width).all():
        return np.inf
    return max(max_width, UNSURE_RATIO * float(np.nanmedian(width)))


def unsure_frames(masks: np.ndarray, detected: np.ndarray, max_width: float) -> np.ndarray:
    """(T,) bool: detected frames whose mask's unsure band is wider than `band_limit`."""
    detected = np.asarray(detected, dtype=bool)
    flagged = np.zeros_like(detected)
    limit = band_limit(masks, detected, max_width)
    if np.isfinite(limit):
        width = band_width(np.asarray(masks)[detected])
        flagged[detected] = np.nan_to_num(width, nan=0.0) > limit
    return flagged
