"""Map a generic kinematic tree (BVH, ASF/AMC) onto the anatomical points of a `SkeletonMotion`.

Joints are found by structure, not by a fixed naming scheme: the knee is the node named like a
knee/shin/lower leg (`LeftKnee`, `LeftLeg`, `ltibia`, `LeftLowerLeg`, ...), the hip is its parent,
the ankle its child, the ball of the foot the ankle's child and the toe tip the ball's child (or
End Site); the elbow is named like an elbow/forearm (`LeftElbow`, `LeftForeArm`, `lradius`),
the shoulder is its parent and the wrist its child; the head is the node named `head`. In both
BVH and ASF trees a node sits at the start of its segment and its global rotation moves the
segment, which is what the foot and hand frames below rely on. Rest-pose global rotations are
the identity in both formats, so a node's local frame equals the world frame of the rest pose.

Mocap skeletons have no foot geometry, so the sole is modelled (see docs/metrics.md):
- the sole plane lies `SOLE_BELOW_BALL` under the ball joint; its normal is the direction, in the
  ankle's (and toe's) local frame, that points straight down during stance (frames where the
  ball joint is slow and low), so heel and toe both touch in flat stance;
- heel = on that plane, `HEEL_FRACTION` of the foot length behind the ankle (moves with the
  foot segment); toe = on the toe segment's sole line, at the toe tip (moves with the toes).
"""

from __future__ import annotations

import re

import numpy as np

from physpose.errors import PhysposeError
from physpose.mocap.common import SIDES, SkeletonMotion, infer_up_axis, leading_jump
from physpose.mocap.rotations import frame_from_axes

SOLE_BELOW_BALL = 0.045   # m; CMU ASF clips: ball joint 4.3-6.4 cm above the lab floor in stance
HEEL_FRACTION = 0.23      # heel-to-ankle distance / foot length (ankle axis 20-25 % from the heel)
HEAD_TOP_FALLBACK = 0.12  # m above the head joint if the tree has no head end (vertex to ear)
_STANCE_SPEED = 0.2       # m/s, ball joint slower than this ...
_STANCE_HEIGHT = 0.03     # m, ... and within this of its low (5th percentile) height: stance
_MIN_STANCE_FRAMES = 5

_KNEE_NAMES = ("knee", "leg", "lowerleg", "shin", "tibia", "calf")
_ELBOW_NAMES = ("elbow", "forearm", "lowerarm", "radius")
_SIDE_WORDS = {"l": ("left", "l"), "r": ("right", "r")}


def _normalise(name: str) -> str:
    return re.sub(r"[^a-z0-9]", "", name.split(":")[-1].lower())


def _name_tails(name: str) -> list[str]:
    """The normalised name without 0, 1, 2... of its leading words ("Bip01 L Calf" ->
    bip01lcalf, 01lcalf, lcalf, calf), so prefixes such as "Bip01" or "Character1_" drop."""
    words = re.findall(r"[A-Z]+(?![a-z])|[A-Z]?[a-z]+|[0-9]+", name.split(":")[-1])
    return ["".join(words[k:]).lower() for k in range(len(words))]


def _depth(parents: list[int], k: int) -> int:
    depth = 0
    while parents[k] >= 0:
        k, depth = parents[k], depth + 1
    return depth


def _find(names: list[str], parents: list[int], side: str, bases: tuple[str, ...], path: str,
          what: str) -> int:
    """The joint named like side + base (or base + side), e.g. LeftLeg, l_knee, KneeLeft; failing
    that, a name ending so after a prefix (Bip01 L Calf, Character1_LeftLeg), the deepest such."""
    wanted = {w + b for w in _SIDE_WORDS[side] for b in bases}
    wanted |= {b + w for w in _SIDE_WORDS[side] for b in bases}
    hits = [k for k, n in enumerate(names) if _normalise(n) in wanted]
    if hits:
        return hits[0]
    tails = [k for k, n in enumerate(names) if wanted.intersection(_name_tails(n))]
    if tails:
        return max(tails, key=lambda k: _depth(parents, k))
    raise PhysposeError(f"no {('left', 'right')[side == 'r']} {what} joint found among "
                        f"{names}", path=path,
                        remedy=f"name the {what} joint like one of {sorted(wanted)[:6]}")


def _children(parents: list[int], k: int) -> list[int]:
    return [c for c, p in enumerate(parents) if p == k]


def _next_joint(parents: list[int], pos0: np.ndarray, k: int) -> int | None:
    """The child of k farthest from it (pos0: (N, 3), any frame; bones are rigid): the next
    joint along a limb, not a twist or roll bone placed part-way along the segment."""
    kids = _children(parents, k)
    if not kids:
        return None
    return max(kids, key=lambda c: float(np.linalg.norm(pos0[c] - pos0[k])))


def _leaves_below(parents: list[int], k: int) -> list[int]:
    kids = _children(parents, k)
    if not kids:
        return [k]
    return [leaf for c in kids for leaf in _leaves_below(parents, c)]


def _stance_down(rot: np.ndarray, height: np.ndarray, speed: np.ndarray,
                 up: np.ndarray) -> np.ndarray:
    """World 'down' in a node's local frame, averaged over stance frames. rot: (T,3,3) -> (3,)."""
    stance = (speed < _STANCE_SPEED) & (height < np.percentile(height, 5) + _STANCE_HEIGHT)
    if stance.sum() < _MIN_STANCE_FRAMES:
        return -up  # rest pose assumed flat-footed
    local = np.einsum("tji,j->ti", rot[stance], -up)
    mean = local.mean(axis=0)
    return mean / np.linalg.norm(mean)


def _foot_points(pos, rot, parents, ankle, times, up):
    """Heel and toe sole points (T, 3) each for one foot (see module docstring)."""
    ball = _next_joint(parents, pos[0], ankle)
    if ball is None:
        raise PhysposeError("the skeleton has no foot segment below the ankle", remedy=(
            "use a skeleton with a foot (ankle -> toe) segment"))
    tip = _next_joint(parents, pos[0], ball)
    a, b = pos[:, ankle], pos[:, ball]
    dt = np.gradient(times)
    speed = np.linalg.norm(np.gradient(b, axis=0), axis=1) / dt
    height = b @ up
    n_foot = _stance_down(rot[:, ankle], height, speed, up)
    n_toe = _stance_down(rot[:, ball], height, speed, up)
    # Foot-local geometry (constant: the ankle->ball offset is rigid in the ankle frame).
    ab_local = np.einsum("ji,j->i", rot[0, ankle], b[0] - a[0])
    fwd_foot = ab_local - (ab_local @ n_foot) * n_foot
    ab_along = np.linalg.norm(fwd_foot)
    fwd_foot /= ab_along
    if tip is not None:
        tip_local = np.einsum("ji,j->i", rot[0, ball], pos[0, tip] - b[0])
    else:
        tip_local = np.zeros(3)
    fwd_toe_dir = tip_local - (tip_local @ n_toe) * n_toe
    toe_len = np.linalg.norm(fwd_toe_dir)
    if toe_len < 1e-6:  # no toe segment: continue the foot's forward direction
        fwd_toe_dir = np.einsum("ji,j->i", rot[0, ball], rot[0, ankle] @ fwd_foot)
    fwd_toe = fwd_toe_dir / np.linalg.norm(fwd_toe_dir)
    foot_len = ab_along + toe_len
    heel_back = HEEL_FRACTION / (1 - HEEL_FRACTION) * foot_len
    sole_depth = ab_local @ n_foot + SOLE_BELOW_BALL   # ankle -> sole plane along the normal
    heel_local = -heel_back * fwd_foot + sole_depth * n_foot
    toe_local = toe_len * fwd_toe + SOLE_BELOW_BALL * n_toe
    heel = a + np.einsum("tij,j->ti", rot[:, ankle], heel_local)
    toe = b + np.einsum("tij,j->ti", rot[:, ball], toe_local)
    return heel, toe


def motion_from_tree(name: str, source: str, times: np.ndarray, names: list[str],
                     parents: list[int], pos: np.ndarray, rot: np.ndarray,
                     rest_pos: np.ndarray) -> SkeletonMotion:
    """Anatomical points of a kinematic tree.

    times: (T,) s; pos: (T, N, 3) m; rot: (T, N, 3, 3) global node rotations;
    rest_pos: (N, 3) node positions with all rotations zero.
    A rest pose held before the motion and joined to it by a jump is left out (`leading_jump`).
    """
    if len(times) < 2:
        raise PhysposeError(f"{len(times)} frame{'s' * (len(times) != 1)} of motion: nothing "
                            "moves", path=source, remedy="use a clip of at least two frames")
    dropped = leading_jump(pos, times)
    times, pos, rot = times[dropped:], pos[dropped:], rot[dropped:]
    norm = [_normalise(n) for n in names]
    heads = [k for k, n in enumerate(norm) if n == "head"] or [
        k for k, n in enumerate(norm) if n.endswith("head") and "end" not in n]
    if not heads:
        raise PhysposeError(f"no head joint found among {names}", path=source,
                            remedy="name the head joint 'Head'")
    head = heads[0]
    knee = {s: _find(names, parents, s, _KNEE_NAMES, source, "knee") for s in SIDES}
    elbow = {s: _find(names, parents, s, _ELBOW_NAMES, source, "elbow") for s in SIDES}
    points: dict[str, np.ndarray] = {}
    ankle = {}
    for s in SIDES:
        below_knee = _next_joint(parents, pos[0], knee[s])
        if below_knee is None:
            raise PhysposeError(f"the {names[knee[s]]} joint has no ankle below it", path=source)
        ankle[s] = below_knee
        points[f"{s}_hip"] = pos[:, parents[knee[s]]]
        points[f"{s}_knee"] = pos[:, knee[s]]
        points[f"{s}_ankle"] = pos[:, ankle[s]]
        wrist = _next_joint(parents, pos[0], elbow[s])
        if wrist is None:
            raise PhysposeError(f"the {names[elbow[s]]} joint has no wrist below it", path=source)
        points[f"{s}_shoulder"] = pos[:, parents[elbow[s]]]
        points[f"{s}_elbow"] = pos[:, elbow[s]]
        points[f"{s}_wrist"] = pos[:, wrist]
    points["head"] = pos[:, head]
    up = infer_up_axis(points)

    # Rest-pose facing direction: from the ankles towards the balls of the feet, horizontal.
    balls = {s: _next_joint(parents, pos[0], ankle[s]) for s in SIDES}
    fwd = sum(rest_pos[balls[s]] - rest_pos[ankle[s]] for s in SIDES if balls[s] is not None)
    rest_up = rest_pos[head] - 0.5 * (rest_pos[ankle["l"]] + rest_pos[ankle["r"]])
    rest_up /= np.linalg.norm(rest_up)
    rest_fwd = fwd - (fwd @ rest_up) * rest_up
    if np.linalg.norm(rest_fwd) < 1e-6:
        raise PhysposeError("cannot tell which way the skeleton faces in its rest pose",
                            path=source, remedy="use a skeleton whose feet point forward at rest")
    rest_fwd /= np.linalg.norm(rest_fwd)

    for s in SIDES:
        points[f"{s}_heel"], points[f"{s}_toe"] = _foot_points(
            pos, rot, parents, ankle[s], times, up)

    head_leaves = [k for k in _leaves_below(parents, head) if k != head]
    if head_leaves:
        points["head_top"] = pos[:, head_leaves[0]]
    else:
        points["head_top"] = pos[:, head] + HEAD_TOP_FALLBACK * np.einsum(
            "tij,j->ti", rot[:, head], rest_up)
    face = np.einsum("tij,j->ti", rot[:, head], rest_fwd)
    head_up = points["head_top"] - points["head"]
    up_fwd = frame_from_axes(head_up, face)  # columns: up, forward, up x forward = left
    head_rot = np.stack([up_fwd[..., 1], up_fwd[..., 2], up_fwd[..., 0]], axis=-1)

    hand_rot = []
    for s in SIDES:
        wrist = _next_joint(parents, pos[0], elbow[s])
        leaves = [k for k in _leaves_below(parents, wrist) if k != wrist]
        is_thumb = ["thumb" in "".join(norm[j] for j in _path(parents, wrist, k)) for k in leaves]
        fingers = [k for k, t in zip(leaves, is_thumb, strict=True) if not t]
        thumbs = [k for k, t in zip(leaves, is_thumb, strict=True) if t]
        w = pos[:, wrist]
        along = (pos[:, fingers].mean(axis=1) - w) if fingers else w - pos[:, elbow[s]]
        if thumbs:
            thumb = pos[:, thumbs].mean(axis=1) - w
        else:  # palms face the body at rest: the thumb points forward
            thumb = np.einsum("tij,j->ti", rot[:, wrist], rest_fwd)
        hand_rot.append(frame_from_axes(along, thumb))
    return SkeletonMotion(name=name, source=source, times=times, points=points,
                          head_rot=head_rot, hand_rot=np.stack(hand_rot, axis=1), up=up,
                          leading_frames_dropped=dropped)


def _path(parents: list[int], top: int, k: int) -> list[int]:
    """Nodes from `k` up to (excluding) its ancestor `top`."""
    out = []
    while k != top and k >= 0:
        out.append(k)
        k = parents[k]
    return out
