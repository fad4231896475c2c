"""Undo left/right limb swaps of the detector by temporal continuity (a two-state Viterbi).

Pose detectors now and then label the left leg (or arm) as the right one for a few frames.
Both labellings are anatomically plausible, so one frame cannot tell which is right; the motion
can: for each limb group the labelling sequence is chosen that moves the group's landmarks
least between frames (2d, hip-centred, in units of the person's torso length), with a cost per
switch, and of the two mirror-image sequences the one that keeps the detector's labels in more
frames. Swapped frames exchange the left and right landmarks (2d, 3d and confidences).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from physpose.joints import LANDMARK_INDEX
from physpose.kinematics.evidence import Evidence

GROUPS: dict[str, tuple[str, ...]] = {
    "legs": ("knee", "ankle", "heel", "foot_index"),
    "arms": ("elbow", "wrist", "pinky", "index", "thumb"),
}
SWITCH_COST = 4.0     # cost of a change of labelling, in units of the squared motion below
MOTION_SIGMA = 0.25   # torso lengths: typical landmark motion between frames at ~25 fps


def _pairs(parts: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
    return (np.array([LANDMARK_INDEX[f"left_{p}"] for p in parts]),
            np.array([LANDMARK_INDEX[f"right_{p}"] for p in parts]))


def _normalised_2d(ev: Evidence) -> np.ndarray:
    """(T, 33, 2) hip-centred 2d landmarks per torso length (median over frames)."""
    at = {n: ev.uv[:, i] for n, i in LANDMARK_INDEX.items()}
    hip = 0.5 * (at["left_hip"] + at["right_hip"])
    shoulder = 0.5 * (at["left_shoulder"] + at["right_shoulder"])
    torso = np.linalg.norm(shoulder - hip, axis=-1)
    scale = float(np.median(torso[ev.valid])) if ev.valid.any() else 1.0
    return (ev.uv - hip[:, None]) / max(scale, 1e-6)


def swap_states(ev: Evidence, parts: tuple[str, ...], fps_ref: float = 25.0) -> np.ndarray:
    """(T,) bool: frames whose left/right labels of `parts` should be exchanged."""
    left, right = _pairs(parts)
    x = _normalised_2d(ev)
    a = np.concatenate([x[:, left], x[:, right]], axis=1)     # labels as given
    b = np.concatenate([x[:, right], x[:, left]], axis=1)     # labels exchanged
    w = np.concatenate([ev.weight[:, left], ev.weight[:, right]], axis=1)
    sigma = MOTION_SIGMA * fps_ref / ev.fps
    states = (a, b)
    t_count = len(x)
    cost = np.zeros((t_count, 2))
    back = np.zeros((t_count, 2), dtype=int)
    last = 0  # the latest frame with evidence
    for t in range(1, t_count):
        if not ev.valid[t]:
            cost[t], back[t] = cost[t - 1], (0, 1)
            continue
        if not ev.valid[last]:
            last = t
            cost[t], back[t] = cost[t - 1], (0, 1)
            continue
        gap = t - last
        wt = np.minimum(w[t], w[last])
        trans = np.empty((2, 2))
        for i in range(2):
            for j in range(2):
                d2 = np.sum((states[j][t] - states[i][last]) ** 2, axis=-1) / (sigma * gap) ** 2
                trans[i, j] = np.sum(wt * d2) / max(wt.sum(), 1e-9) * len(wt)
                trans[i, j] += SWITCH_COST * (i != j)
        total = cost[t - 1][:, None] + trans
        back[t] = np.argmin(total, axis=0)
        cost[t] = total[back[t], [0, 1]]
        last = t
    path = np.zeros(t_count, dtype=int)
    path[-1] = int(np.argmin(cost[-1]))
    for t in range(t_count - 1, 0, -1):
        path[t - 1] = back[t, path[t]]
    swapped = path.astype(bool)
    if swapped[ev.valid].mean() > 0.5:  # the mirror sequence keeps more of the detector's labels
        swapped = ~swapped
    return swapped & ev.valid


def _exchange(values: np.ndarray, rows: np.ndarray, left: np.ndarray, right: np.ndarray
              ) -> np.ndarray:
    out = values.copy()
    out[np.ix_(rows, left)], out[np.ix_(rows, right)] = values[np.ix_(rows, right)], \
        values[np.ix_(rows, left)]
    return out


def unswap(ev: Evidence) -> Evidence:
    """Evidence with the detected limb swaps undone (see the module docstring)."""
    uv, weight, world = ev.uv, ev.weight, ev.world_ray
    for parts in GROUPS.values():
        rows = np.flatnonzero(swap_states(ev, parts))
        if rows.size:
            left, right = _pairs(parts)
            uv = _exchange(uv, rows, left, right)
            weight = _exchange(weight, rows, left, right)
            world = _exchange(world, rows, left, right)
    return dataclasses.replace(ev, uv=uv, weight=weight, world_ray=world)
