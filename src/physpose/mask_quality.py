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
# The same on the masks' uint8 scale (probability x 255, rounded).
_LOW, _HIGH, _HALF = int(UNSURE_LOW * 255), int(np.ceil(UNSURE_HIGH * 255)), 127


def band_width(masks: np.ndarray) -> np.ndarray:
    """(T,) width in mask pixels of each mask's unsure band: pixels with probability between
    UNSURE_LOW and UNSURE_HIGH per outline pixel of the region above 0.5. NaN for an empty
    mask (no person in it), inf for a faint blob with no pixel above 0.5. masks: (T, h, w)
    uint8 probability x 255, read one frame at a time."""
    widths = np.full(len(masks), np.nan)
    for i, m in enumerate(masks):
        inside = m > _HALF
        outline = int((inside & ~binary_erosion(inside)).sum())
        unsure = int(((m > _LOW) & (m < _HIGH)).sum())
        if outline:
            widths[i] = unsure / outline
        elif unsure:
            widths[i] = np.inf
    return widths


def band_limit(widths: np.ndarray, max_width: float) -> float:
    """The widest unsure band a detection of a clip may have, given `band_width` of its
    detected frames: max_width mask pixels, or UNSURE_RATIO times their median where that is
    more; inf when max_width <= 0 or no frame has a mask."""
    widths = np.asarray(widths, dtype=float)
    if max_width <= 0 or np.isnan(widths).all():
        return np.inf
    return max(max_width, UNSURE_RATIO * float(np.nanmedian(widths)))


def unsure_frames(masks: np.ndarray, detected: np.ndarray, max_width: float) -> np.ndarray:
    """(T,) bool: detected frames whose mask's unsure band is wider than `band_limit`."""
    detected = np.asarray(detected, dtype=bool)
    flagged = np.zeros_like(detected)
    if max_width <= 0 or not detected.any():
        return flagged
    widths = band_width(np.asarray(masks)[detected])
    flagged[detected] = np.nan_to_num(widths, nan=0.0) > band_limit(widths, max_width)
    return flagged
