"""Placing the simulated stretches: where each continuous simulation stands on the floor.

A sequential run is one or more continuous simulations ("stretches"), split where it restarts
from the kinematic estimate. Each starts from the estimate's state at one frame, so its
horizontal place is the estimate's at that frame: a single noisy sample (the estimate's
root is least certain along the camera's line of sight). On a floor that is the same
everywhere (flat, no obstacles) a stretch moved horizontally by a constant is the same
simulation started from the moved state, under the same controls. So each stretch is moved so
that its centre of mass matches the estimate's on average over the whole stretch, horizontally
(docs/dynamics.md, "Stretches"). Heights, poses, contacts and controls are unchanged.
"""

from __future__ import annotations

import numpy as np

from physpose.scene import SceneConfig


def stretch_bounds(num_frames: int, restarts: list[int]) -> list[tuple[int, int]]:
    """[first, end) frames of each continuous stretch, split at the restart frames."""
    cuts = sorted({int(f) for f in restarts if 0 < f < num_frames})
    edges = [0, *cuts, num_frames]
    return [(a, b) for a, b in zip(edges[:-1], edges[1:]) if b > a]


def stretch_shifts(com: np.ndarray, estimate_com: np.ndarray, restarts: list[int]
                   ) -> np.ndarray:
    """(S, 2) horizontal shift (m) per stretch: the mean of estimate minus simulated COM."""
    bounds = stretch_bounds(len(com), restarts)
    return np.array([(estimate_com[a:b, :2] - com[a:b, :2]).mean(axis=0) for a, b in bounds])


def translation_invariant(scene: SceneConfig) -> bool:
    """Whether moving a simulation horizontally leaves it a solution (no obstacles)."""
    return not scene.obstacles


def shift_stretches(outputs: dict[str, np.ndarray], restarts: list[int], shifts: np.ndarray
                    ) -> dict[str, np.ndarray]:
    """Copies of the per-frame outputs (qpos (T, 55) free-root first; joints, landmarks (T, N, 3);
    com (T, 3); cop (T, 2, 3) where given; any others as they are) with each stretch moved
    horizontally by its shift."""
    out = {k: np.array(v, copy=True) for k, v in outputs.items()}
    for (a, b), d in zip(stretch_bounds(len(out["qpos"]), restarts), shifts):
        out["qpos"][a:b, :2] += d
        out["com"][a:b, :2] += d
        for key in ("joints", "landmarks", "cop"):
            if key in out:
                out[key][a:b, :, :2] += d
    return out
