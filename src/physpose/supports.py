"""Supports the scene lacks but the kinematic estimate shows: where the person is held up by
something physpose was not told about, the simplest such thing.

- `support_boxes`: a box on the floor under feet that stay raised (`diagnostics.raised_runs`:
  the person stands on a box, a step, a ledge).
"""

from __future__ import annotations

import numpy as np

from physpose.metrics import foot_points
from physpose.scene import Box

SUPPORT_MARGIN = 0.3       # m added on every side of the feet's extent for a support box
RESTING_SPEED = 0.5        # m/s, a foot slower than this rests on its support


def support_boxes(joints: np.ndarray, runs: list[tuple[int, int, float]], fps: float
                  ) -> tuple[Box, ...]:
    """One box per `raised_runs` stretch, standing on the floor under the feet where they
    rest (the lower foot slower than RESTING_SPEED; a stretch can end in a leap off the
    support): its top at the 10th percentile of the resting feet's lowest point (they stand
    on it, not in it), its sides SUPPORT_MARGIN beyond where the resting soles are. The
    estimate says that something holds the person up there; this is the simplest such thing.
    A stretch without resting frames gets none."""
    if not runs:
        return ()
    soles = foot_points(np.asarray(joints, dtype=float))       # (T, 2, P, 3)
    centres = soles.mean(axis=2)                                 # (T, 2, 3)
    speed = np.linalg.norm(np.gradient(centres, axis=0), axis=-1) * fps
    lower = soles[..., 2].min(axis=2).argmin(axis=1)             # (T,) the lower foot
    resting = speed[np.arange(len(soles)), lower] < RESTING_SPEED
    boxes = []
    for a, b, _ in runs:
        frames = a + np.flatnonzero(resting[a:b + 1])
        if not len(frames):
            continue
        points = soles[frames].reshape(-1, 3)
        top = float(np.percentile(soles[frames, ..., 2].min(axis=(1, 2)), 10))
        lo = points[:, :2].min(axis=0) - SUPPORT_MARGIN
        hi = points[:, :2].max(axis=0) + SUPPORT_MARGIN
        centre = 0.5 * (lo + hi)
        boxes.append(Box(center=(float(centre[0]), float(centre[1]), top / 2),
                         size=(float(hi[0] - lo[0]), float(hi[1] - lo[1]), top)))
    return tuple(boxes)
