"""Undo left/right swaps of the detector (a Viterbi over labellings).

Pose detectors now and then label the left leg (or arm) as the right one for a few frames, or
flip the labels of the whole body at once (front/back confusion, e.g. while the person turns).
The landmarks with a side form three groups: legs, arms and the rest (trunk and face). A
frame's state says which groups are exchanged (2^3 states); the Viterbi path minimises
- motion: how far the landmarks move between frames, each landmark's squared motion saturating
  at MOTION_CAP so an outlier detection cannot force a swap; in the image (hip-centred, per torso
  length) and in MediaPipe's 3d (hip-centred, metres). The 3d term tells the legs apart where they
  cross in the image but not in depth (walking seen from the front); without it a false swap
  costs nothing at the crossing, and the attachment below, biased by the 3d error for a second at
  a time, decided whole strides wrongly (a crouched walk: the legs exchanged for 25 frames);
- attachment: a limb's labels relative to the trunk's cost the excess length of the knees'
  (elbows') distances to the hips (shoulders) of their own side over the crossed ones, in
  MediaPipe's 3d. This is what decides the legs, whose left and right cross each other in the
  image while walking, and it fixes which limb labelling of the two mirror images is right;
- a cost per swap event, an event exchanging one limb group or the whole body, so a clear
  whole-body flip seen on the arms carries the legs and the trunk along;
- a cost per frame in which a limb's labels are exchanged relative to the trunk's against the
  detector's (LABEL_COST): the detector labels most frames right, and only this weighs how long
  a repair lasts. Where nothing else links two labellings of a limb (a whole clip, or frames
  after the legs overlap in the image and in depth), the attachment alone decided; seen from
  the side it is weak (the hips' axis lies along the ray, where MediaPipe's depth is flattened
  and noisiest, and a walk's knees and feet pass close together), and it labelled whole clips
  the wrong way round (bench_swaps at 75/90/270 degrees: 11/12/8 of 120 runs with the legs
  wrong in over 10 % of frames; 1/1/0 with this cost).
Each landmark's motion is weighted by its own confidences under either labelling (before, by
those of the landmark holding its label as detected: a labelling and its mirror image then
moved at different costs, by up to 400 units over 4 s where the far side's confidences are
low, a hidden preference that decided mirror images from the side either way).
The motion scale shrinks with the frame rate (landmarks move less between frames) down to
MOTION_SIGMA_MIN, the detector's own frame-to-frame noise, which it reaches at 50 fps. Above,
where the floor lifts the scale by a factor k, the attachment costs are divided by k^2 like
the motion costs: a detector's 3d error persists over frames, so sampling the same seconds
more densely must not outvote the motion and the swap events' cost.
The labelling of a stretch of detections as a whole (all groups exchanged in each of its frames)
is a mirror image with about the same cost where nothing but a gap's weak motion term links it to
the rest (STRETCH_GAP or longer); in each such stretch the one keeping the trunk's detected
labels in more frames wins (a person seen again after a gap may be labelled either way by the
path). The price: a whole-body flip of the detector that lasts all or most of such a stretch is
taken as the detector's labels and not repaired. Swapped frames exchange the left and right
landmarks (2d, 3d and confidences).
"""

from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np

from physpose.joints import LANDMARK_INDEX, LANDMARK_NAMES
from physpose.kinematics.evidence import Evidence

GROUPS: dict[str, tuple[str, ...]] = {
    "legs": ("knee", "ankle", "heel", "foot_index"),
    "arms": ("elbow", "wrist", "pinky", "index", "thumb"),
}
GROUPS["trunk"] = tuple(n[5:] for n in LANDMARK_NAMES if n.startswith("left_")
                        and n[5:] not in GROUPS["legs"] + GROUPS["arms"])
EVENTS = (("legs",), ("arms",), tuple(GROUPS))  # what the detector swaps at once
ATTACH = {"legs": ("knee", "hip"), "arms": ("elbow", "shoulder")}  # limb joint, its root
SWITCH_COST = 4.0     # cost of a swap event, in units of the squared motion below
MOTION_SIGMA = 0.25   # torso lengths: typical landmark motion between frames at ~25 fps
MOTION_SIGMA_MIN = 0.125  # torso lengths: the detector's frame-to-frame noise (reached at 50 fps)
MOTION_SIGMA_3D = 0.125   # m: the same in MediaPipe's 3d (a torso is about 0.5 m); same floor ratio
MOTION_CAP = 9.0      # a landmark's (motion / sigma)^2 saturates towards this: c/(1 + c/cap)
ATTACH_SIGMA = 0.02   # m of excess limb-to-root distance per unit cost
LABEL_COST = 2.0      # per frame with a limb's labels exchanged relative to the trunk's
LONG_EXCHANGE = 0.5   # s: a limb exchanged against the detector's labels this long is reported
STRETCH_GAP = 0.2     # s without evidence that end a stretch (its labels judged on their own)


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


def _hip_centred_3d(ev: Evidence) -> np.ndarray:
    """(T, 33, 3) MediaPipe's 3d landmarks relative to the middle of its hips, metres."""
    hip = 0.5 * (ev.world_ray[:, LANDMARK_INDEX["left_hip"]]
                 + ev.world_ray[:, LANDMARK_INDEX["right_hip"]])
    return ev.world_ray - hip[:, None]


def _motion_sigma(fps: float, fps_ref: float) -> tuple[float, float]:
    """The motion scale between consecutive frames (torso lengths) and its lift by the noise
    floor over the scale of motion alone (1 up to 50 fps)."""
    nominal = MOTION_SIGMA * fps_ref / fps
    sigma = max(nominal, MOTION_SIGMA_MIN)
    return sigma, sigma / nominal


def _motion_costs(ev: Evidence, parts: tuple[str, ...], fps_ref: float) -> np.ndarray:
    """(T, 2, 2) cost of the move from the previous frame with evidence (state i, 1 =
    exchanged) to this frame (state j), in the image and in 3d; zero where either frame has no
    evidence."""
    sigma, _ = _motion_sigma(ev.fps, fps_ref)
    sigma_3d = sigma * MOTION_SIGMA_3D / MOTION_SIGMA
    return (_moves(_normalised_2d(ev), ev, parts, sigma)
            + _moves(_hip_centred_3d(ev), ev, parts, sigma_3d))


def _moves(x: np.ndarray, ev: Evidence, parts: tuple[str, ...], sigma: float) -> np.ndarray:
    """(T, 2, 2) the saturated squared motion of `parts`' landmarks `x` (T, 33, D) between
    frames with evidence, per motion scale `sigma` per frame, under both labellings."""
    left, right = _pairs(parts)
    states = (np.concatenate([x[:, left], x[:, right]], axis=1),     # labels as given
              np.concatenate([x[:, right], x[:, left]], axis=1))     # labels exchanged
    weights = (np.concatenate([ev.weight[:, left], ev.weight[:, right]], axis=1),
               np.concatenate([ev.weight[:, right], ev.weight[:, left]], axis=1))
    cost = np.zeros((len(x), 2, 2))
    good = np.flatnonzero(ev.valid)
    for last, t in zip(good[:-1], good[1:]):
        for i, j in itertools.product(range(2), range(2)):
            wt = np.minimum(weights[j][t], weights[i][last])   # each landmark's own weights
            d2 = np.sum((states[j][t] - states[i][last]) ** 2, axis=-1) / (sigma * (t - last)) ** 2
            d2 = d2 / (1.0 + d2 / MOTION_CAP)
            cost[t, i, j] = np.sum(wt * d2) / max(wt.sum(), 1e-9) * len(wt)
    return cost


def _attachment_costs(ev: Evidence, group: str) -> np.ndarray:
    """(T, 2) cost of a limb group's labels relative to the trunk's, as detected (column 0)
    or exchanged (1): the excess of the limb-to-root distances (knee - hip, elbow - shoulder,
    MediaPipe's 3d) over those of the other labelling, / ATTACH_SIGMA, x confidence."""
    joint, root = ATTACH[group]
    x = ev.world_ray
    jl, jr = x[:, LANDMARK_INDEX[f"left_{joint}"]], x[:, LANDMARK_INDEX[f"right_{joint}"]]
    rl, rr = x[:, LANDMARK_INDEX[f"left_{root}"]], x[:, LANDMARK_INDEX[f"right_{root}"]]
    keep = np.linalg.norm(jl - rl, axis=-1) + np.linalg.norm(jr - rr, axis=-1)
    cross = np.linalg.norm(jl - rr, axis=-1) + np.linalg.norm(jr - rl, axis=-1)
    names = [f"{side}_{n}" for side in ("left", "right") for n in (joint, root)]
    w = ev.weight[:, [LANDMARK_INDEX[n] for n in names]].min(axis=1)
    excess = (keep - cross) / ATTACH_SIGMA * w
    return np.stack([np.maximum(excess, 0.0), np.maximum(-excess, 0.0)], axis=1)


def _event_counts(groups: tuple[str, ...]) -> np.ndarray:
    """(S,) the fewest swap events (EVENTS) whose combination exchanges exactly the groups of
    each change pattern (bit g of the index = group g changes); inf if none does."""
    masks = [sum(1 << groups.index(g) for g in event if g in groups) for event in EVENTS]
    counts = np.full(1 << len(groups), np.inf)
    for chosen in itertools.product((0, 1), repeat=len(masks)):
        pattern = 0
        for use, mask in zip(chosen, masks):
            pattern ^= mask * use
        counts[pattern] = min(counts[pattern], sum(chosen))
    return counts


def swap_paths(ev: Evidence, groups: tuple[str, ...] = tuple(GROUPS), fps_ref: float = 25.0
               ) -> dict[str, np.ndarray]:
    """Group name -> (T,) bool: frames whose left/right labels of that group (GROUPS) should
    be exchanged, decided jointly for the groups (see the module docstring)."""
    motion = [_motion_costs(ev, GROUPS[g], fps_ref) for g in groups]
    n_states = 1 << len(groups)
    bits = (np.arange(n_states)[:, None] >> np.arange(len(groups))) & 1     # (S, G)
    switch = SWITCH_COST * _event_counts(groups)[np.bitwise_xor.outer(
        np.arange(n_states), np.arange(n_states))]                         # (S, S)
    t_count = ev.num_frames
    emit = np.zeros((t_count, n_states))
    if "trunk" in groups:
        for g, name in enumerate(groups):
            if name in ATTACH:
                relative = bits[:, g] ^ bits[:, groups.index("trunk")]
                emit += _attachment_costs(ev, name)[:, relative]
                emit += LABEL_COST * ev.valid[:, None] * relative[None, :]
        emit /= _motion_sigma(ev.fps, fps_ref)[1] ** 2
    cost = np.zeros((t_count, n_states))
    cost[0] = emit[0]
    back = np.zeros((t_count, n_states), dtype=int)
    back[0] = np.arange(n_states)
    for t in range(1, t_count):
        trans = switch + sum(m[t][bits[:, g][:, None], bits[:, g][None, :]]
                             for g, m in enumerate(motion))
        total = cost[t - 1][:, None] + trans + emit[t][None, :]
        back[t] = np.argmin(total, axis=0)
        cost[t] = total[back[t], np.arange(n_states)]
    path = np.zeros(t_count, dtype=int)
    path[-1] = int(np.argmin(cost[-1]))
    for t in range(t_count - 1, 0, -1):
        path[t - 1] = back[t, path[t]]
    swapped = bits[path].astype(bool)                                     # (T, G)
    # Exchanging every group in every frame of a stretch between gaps of STRETCH_GAP or more
    # costs about the same (a mirror image): in each stretch keep the labelling under which the
    # trunk keeps more of its detected labels (without a trunk group, there are no attachment
    # costs, and each group is decided alone).
    judge = [groups.index("trunk")] * len(groups) if "trunk" in groups else range(len(groups))
    for stretch in _stretches(ev.valid, max(1, math.ceil(STRETCH_GAP * ev.fps - 1e-9))):
        mirrored = swapped[stretch].mean(axis=0) > 0.5                    # (G,)
        swapped[stretch] ^= mirrored[list(judge)]
    return {name: swapped[:, g] & ev.valid for g, name in enumerate(groups)}


def _stretches(valid: np.ndarray, min_gap: int) -> list[np.ndarray]:
    """The frame indices of each run of valid frames, runs split where at least `min_gap`
    frames in a row are not valid."""
    frames = np.flatnonzero(valid)
    return [run for run in np.split(frames, np.flatnonzero(np.diff(frames) > min_gap) + 1)
            if run.size]


def _exchange(values: np.ndarray, rows: np.ndarray, left: np.ndarray, right: np.ndarray
              ) -> np.ndarray:
    out = values.copy()
    out[np.ix_(rows, left)], out[np.ix_(rows, right)] = values[np.ix_(rows, right)], \
        values[np.ix_(rows, left)]
    return out


def long_exchanges(ev: Evidence, paths: dict[str, np.ndarray]) -> dict[str, list[list[int]]]:
    """Limb group -> the [first, last] frames of each run (LONG_EXCHANGE or longer) in which
    `paths` keep its labels exchanged relative to the trunk's, against the detector's
    labelling; groups without such a run are left out."""
    if "trunk" not in paths:
        return {}
    shortest = max(1, math.ceil(LONG_EXCHANGE * ev.fps - 1e-9))
    out = {}
    for name in ATTACH:
        if name in paths:
            runs = _stretches((paths[name] ^ paths["trunk"]) & ev.valid, 1)
            long_runs = [[int(run[0]), int(run[-1])] for run in runs if run.size >= shortest]
            if long_runs:
                out[name] = long_runs
    return out


def unswap(ev: Evidence) -> tuple[Evidence, dict[str, list[list[int]]]]:
    """Evidence with the detected limb swaps undone (see the module docstring), and each limb
    group's runs of frames [first, last] kept exchanged against the detector's labels for
    LONG_EXCHANGE or longer: where the detector's swaps are short, that is where a wrong
    repair lies (bench_swaps), so the user is told (diagnostics.label_exchange_message)."""
    uv, weight, world = ev.uv, ev.weight, ev.world_ray
    paths = swap_paths(ev)
    for name, swapped in paths.items():
        rows = np.flatnonzero(swapped)
        if rows.size:
            left, right = _pairs(GROUPS[name])
            uv = _exchange(uv, rows, left, right)
            weight = _exchange(weight, rows, left, right)
            world = _exchange(world, rows, left, right)
    return dataclasses.replace(ev, uv=uv, weight=weight, world_ray=world), \
        long_exchanges(ev, paths)
