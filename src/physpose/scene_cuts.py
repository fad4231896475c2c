"""Cuts in a video: frames at which the whole picture changes at once (an edited clip's shots).

physpose follows one person through one shot. Across a cut the detector may carry on with
another person (or the same one from elsewhere), and its landmark smoothing spreads the change
over a few frames, so that no single step looks like a jump (`diagnostics.person_jumps`); the
motion then joins two shots. Where the picture changes at once, the observe stage says so.

A frame's signature is a colour histogram and a grey thumbnail of the whole image. Between
consecutive analysed frames of the shared real clips and their altered copies (a pan following
a runner, a camera travelling along a road, dark and noisy, mirrored, cropped, 12 fps, a
person blacked out for ten frames, Sports2D's sun flare), the histogram changed by at most
0.33 and the thumbnail by at most 0.12 of the grey range; at the hard cuts of a helper's edited
clips (black to a scene, one scene to another) by 0.94-1.0 and 0.26-0.29, and between frames
of the three shared videos by 0.78-0.97 and 0.22-0.32. pose2sim's four cameras of one room
differ by only 0.19-0.45 and 0.13-0.18, as much as the largest changes within a shot; what tells
them apart is the thumbnails' structure. Aligned by the best shift of up to 4 px (a pan, a
travelling camera) and with their mean grey removed (a change of light), consecutive
thumbnails of a shot differed by at most 0.062 (a portrait crop of the tai chi clip, the person
large in the picture; Sports2D's flare 0.057), the four views' first frames by 0.129-0.150
(their histograms by 0.32-0.41), so such a change with the histogram's over 0.15 is a cut too
(stop 75, scratch cuts75.py; a person blacked out at once: 0.18, a change undone within
_TRANSITION frames, so no cut).
"""

from __future__ import annotations

import cv2
import numpy as np

HISTOGRAM_CHANGE = 0.6  # share of the colour histogram that moves between two frames ...
PIXEL_CHANGE = 0.2      # ... or mean grey change of the thumbnail (0-1) that makes a cut ...
ALIGNED_CHANGE = 0.1    # ... or the aligned change (Signature.aligned_change) ...
ALIGNED_HISTOGRAM = 0.15  # ... together with this histogram change
_SHIFT = 4              # px of the thumbnail: the largest shift tried in aligning two
_THUMBNAIL = (64, 36)   # px: small enough that noise and small motions average out
_BINS = (8, 4, 4)       # hue, saturation, value
_TRANSITION = 12        # frames: changes this close together are one transition


class Signature:
    """What a frame looks like as a whole: a normalised HSV histogram and a grey thumbnail."""

    def __init__(self, image: np.ndarray) -> None:
        small = cv2.resize(image, _THUMBNAIL, interpolation=cv2.INTER_AREA)
        hsv = cv2.cvtColor(small, cv2.COLOR_BGR2HSV)
        hist = cv2.calcHist([hsv], [0, 1, 2], None, list(_BINS), [0, 180, 0, 256, 0, 256])
        self.histogram = (hist.ravel() / max(float(hist.sum()), 1.0)).astype(np.float32)
        self.grey = cv2.cvtColor(small, cv2.COLOR_BGR2GRAY)  # uint8: 2.3 kB a frame

    def change(self, other: Signature) -> tuple[float, float]:
        """(histogram change, mean grey change), both in [0, 1]."""
        moved = 1.0 - float(np.minimum(self.histogram, other.histogram).sum())
        grey = np.abs(self.grey.astype(np.int16) - other.grey.astype(np.int16))
        return moved, float(grey.mean()) / 255.0

    def aligned_change(self, other: Signature) -> float:
        """Mean grey change (0-1) of the thumbnails at the best shift of up to _SHIFT px,
        each over the overlap with its mean removed: what a pan or a change of light leaves."""
        a, b = self.grey.astype(np.float32) / 255.0, other.grey.astype(np.float32) / 255.0
        h, w = a.shape
        best = np.inf
        for dy in range(-_SHIFT, _SHIFT + 1):
            for dx in range(-_SHIFT, _SHIFT + 1):
                pa = a[max(dy, 0):h + min(dy, 0), max(dx, 0):w + min(dx, 0)]
                pb = b[max(-dy, 0):h + min(-dy, 0), max(-dx, 0):w + min(-dx, 0)]
                best = min(best, float(np.abs((pa - pa.mean()) - (pb - pb.mean())).mean()))
        return best


def is_cut(before: Signature, after: Signature) -> bool:
    histogram, pixels = before.change(after)
    if histogram >= HISTOGRAM_CHANGE or pixels >= PIXEL_CHANGE:
        return True
    return histogram >= ALIGNED_HISTOGRAM and before.aligned_change(after) >= ALIGNED_CHANGE


class CutFinder:
    """Sees a video's frames in order (frame i is the i-th seen) and keeps their
    signatures. A run of changes close together (a blackout, a flash, a cut to black and
    back) counts as a cut only where the pictures before and after it differ too."""

    def __init__(self) -> None:
        self.signatures: list[Signature] = []
        self._changes: list[int] = []  # frames that differ from the frame before them

    def see(self, image: np.ndarray) -> None:
        self.signatures.append(Signature(image))
        if len(self.signatures) > 1 and is_cut(self.signatures[-2], self.signatures[-1]):
            self._changes.append(len(self.signatures) - 1)

    @property
    def frames(self) -> list[int]:
        """The first frame of each new shot."""
        cuts, runs = [], []
        for f in self._changes:
            if runs and f - runs[-1][-1] <= _TRANSITION:
                runs[-1].append(f)
            else:
                runs.append([f])
        for run in runs:
            if is_cut(self.signatures[run[0] - 1], self.signatures[run[-1]]):
                cuts.append(run[0])
        return cuts

    def between(self, a: int, b: int) -> bool:
        """Whether frames a < b lie in different shots: a cut after a, up to b, and the two
        pictures unlike each other."""
        return any(a < c <= b for c in self._changes) and is_cut(self.signatures[a],
                                                                 self.signatures[b])


def cut_message(times: list[float]) -> str | None:
    """A warning on the cuts found at these seconds into the video, or None."""
    if not times:
        return None
    at = ", ".join(f"{t:.2f}" for t in times)
    return (f"the video cuts at {at} s (the whole picture changes at once): physpose follows "
            "one person through one shot, and across a cut the detector may take another "
            "person or place; reconstruct each shot on its own with --start/--end")
