"""BVH export of the simulated body (`physpose.mocap.bvh` reads such files back).

One BVH joint per MuJoCo body with the subject's segment offsets. Axes are BVH's usual Y-up
(world x -> x, z -> y, -y -> z), units metres, rotations in degrees as ZXY Euler channels
(R = Rz Rx Ry). The root carries position channels; so does any body whose offset from its
parent changes over time (a hinge whose axis does not pass through the body origin).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from physpose.errors import PhysposeError
from physpose.render.bodymotion import BodyMotion, quat_rotate, quat_to_mat

# World (z up) -> BVH (y up): x' = x, y' = z, z' = -y.
R_WORLD2BVH = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])
_EULER = "ZXY"  # channel order, intrinsic
_ROT_CHANNELS = ("Zrotation", "Xrotation", "Yrotation")
_POS_CHANNELS = ("Xposition", "Yposition", "Zposition")
_FIXED_OFFSET_TOL = 1e-6  # m: a local offset varying more than this gets position channels
_LEAF_LENGTH = 0.05  # m, end-site length of a leaf body without geoms


@dataclass(frozen=True, eq=False)
class BvhClip:
    """A BVH file in memory (BVH axes and units)."""

    names: tuple[str, ...]
    parents: tuple[int, ...]                    # -1 for the root
    offsets: np.ndarray                         # (J, 3)
    channels: tuple[tuple[str, ...], ...]       # per joint, in file order
    end_sites: dict[int, np.ndarray]            # joint index -> end-site offset (3,)
    frame_time: float                           # s
    motion: np.ndarray                          # (T, sum of channel counts)


def write_bvh(motion: BodyMotion, fps: float, path: str | Path) -> Path:
    """Write the body motion as BVH at `fps` frames per second; returns the path."""
    path = Path(path)
    clip = motion_to_clip(motion, fps)
    lines = ["HIERARCHY"]
    children = {j: [c for c, p in enumerate(clip.parents) if p == j] for j in range(len(clip.names))}

    def emit(j: int, depth: int) -> None:
        pad = "  " * depth
        kind = "ROOT" if clip.parents[j] < 0 else "JOINT"
        lines.append(f"{pad}{kind} {clip.names[j]}")
        lines.append(f"{pad}{{")
        lines.append(f"{pad}  OFFSET {_fmt(clip.offsets[j])}")
        lines.append(f"{pad}  CHANNELS {len(clip.channels[j])} {' '.join(clip.channels[j])}")
        for c in children[j]:
            emit(c, depth + 1)
        if j in clip.end_sites:
            lines.extend([f"{pad}  End Site", f"{pad}  {{",
                          f"{pad}    OFFSET {_fmt(clip.end_sites[j])}", f"{pad}  }}"])
        lines.append(f"{pad}}}")

    emit(0, 0)
    lines += ["MOTION", f"Frames: {clip.motion.shape[0]}", f"Frame Time: {clip.frame_time:.8f}"]
    lines += [" ".join(f"{v:.6f}" for v in row) for row in clip.motion]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")
    return path


def motion_to_clip(motion: BodyMotion, fps: float) -> BvhClip:
    """Convert world body poses into BVH joints, offsets and channel values."""
    tree = motion.tree
    local_pos, local_quat = motion.local()
    c = R_WORLD2BVH
    local_pos = local_pos @ c.T                                       # (T, B, 3) BVH axes
    local_rot = c @ quat_to_mat(local_quat) @ c.T                     # (T, B, 3, 3)
    names = tuple(_bvh_name(n) for n in tree.names)
    if len(set(names)) != len(names):
        raise PhysposeError("body names are not unique once spaces are removed",
                            remedy="name every body of the model uniquely")
    offsets, channels, columns = [], [], []
    for b in range(len(names)):
        moving = tree.parents[b] < 0 or np.ptp(local_pos[:, b], axis=0).max() > _FIXED_OFFSET_TOL
        offset = np.zeros(3) if tree.parents[b] < 0 else local_pos[:, b].mean(axis=0)
        offsets.append(offset)
        euler = continuous_euler(Rotation.from_matrix(local_rot[:, b]).as_euler(_EULER,
                                                                                degrees=True))
        if moving:
            channels.append(_POS_CHANNELS + _ROT_CHANNELS)
            columns.append(np.concatenate([local_pos[:, b] - offset, euler], axis=1))
        else:
            channels.append(_ROT_CHANNELS)
            columns.append(euler)
    ends = {b: c @ _end_site(motion, b) for b in range(len(names)) if b not in tree.parents}
    # File order is depth-first; MuJoCo numbers bodies that way too, but do not rely on it.
    order = _preorder(tree.parents)
    new = {b: i for i, b in enumerate(order)}
    return BvhClip(names=tuple(names[b] for b in order),
                   parents=tuple(-1 if tree.parents[b] < 0 else new[tree.parents[b]]
                                 for b in order),
                   offsets=np.array(offsets)[order], channels=tuple(channels[b] for b in order),
                   end_sites={new[b]: e for b, e in ends.items()}, frame_time=1.0 / fps,
                   motion=np.concatenate([columns[b] for b in order], axis=1))


def continuous_euler(euler: np.ndarray) -> np.ndarray:
    """(T, 3) Tait-Bryan angles in degrees, each frame's rewritten as the equivalent triple
    nearest the previous frame's: whole turns added, or (a, b, c) -> (a + 180, 180 - b,
    c + 180), the same rotation. Near the middle angle's +-90 degrees (a shoulder raised to
    the horizontal) the principal values flip by about 180 degrees between frames that barely
    differ, and a tool interpolating the channels swings the limb through the flip."""
    out = np.array(euler, dtype=float, copy=True)
    for t in range(1, len(out)):
        a, b, c = out[t]
        best = None
        for cand in (np.array([a, b, c]), np.array([a + 180.0, 180.0 - b, c + 180.0])):
            cand = cand + 360.0 * np.round((out[t - 1] - cand) / 360.0)
            cost = float(np.sum((cand - out[t - 1]) ** 2))
            if best is None or cost < best[0]:
                best = (cost, cand)
        out[t] = best[1]
    return out


def _preorder(parents: tuple[int, ...]) -> list[int]:
    children = {j: [c for c, p in enumerate(parents) if p == j] for j in range(-1, len(parents))}
    order, stack = [], list(reversed(children[-1]))
    while stack:
        j = stack.pop()
        order.append(j)
        stack += reversed(children[j])
    return order


def _end_site(motion: BodyMotion, body: int) -> np.ndarray:
    """A leaf's end site: the point of its geoms farthest from the body origin (body frame)."""
    points = []
    for g in motion.tree.geoms:
        if g.body != body:
            continue
        if g.kind in ("capsule", "cylinder"):
            axis = quat_rotate(np.array(g.quat), np.array([0.0, 0.0, g.size[1]]))
            points += [np.add(g.pos, axis), np.subtract(g.pos, axis)]
        elif g.kind == "box":
            points += [np.add(g.pos, quat_rotate(np.array(g.quat), np.array(g.size) * s))
                       for s in ((1, 0, 0), (-1, 0, 0))]
        else:
            points.append(np.array(g.pos))
    if not points:
        return np.array([0.0, 0.0, _LEAF_LENGTH])
    best = max(points, key=lambda p: float(np.linalg.norm(p)))
    return best if np.linalg.norm(best) > 1e-6 else np.array([0.0, 0.0, _LEAF_LENGTH])


def _bvh_name(name: str) -> str:
    return re.sub(r"\s+", "_", name.strip()) or "body"


def _fmt(v: np.ndarray) -> str:
    return " ".join(f"{x:.6f}" for x in v)
