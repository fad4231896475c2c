"""BVH (Biovision hierarchy) reader: parse the hierarchy and motion, forward kinematics of our own.

Conventions followed (the de-facto BVH standard): a joint's position is its parent's position
plus the parent's global rotation applied to its OFFSET; the joint's local rotation is the
product of its rotation channels in the order listed (`Zrotation Yrotation Xrotation` ->
Rz @ Ry @ Rx), angles in degrees; position channels are added to the OFFSET. `End Site` blocks
become leaf nodes named `<parent>_end`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from physpose.errors import PhysposeError
from physpose.mocap.common import REST_EXTENT, MocapClip, finish_clip, line_error, read_lines
from physpose.mocap.rotations import euler_matrix
from physpose.mocap.skeleton import motion_from_tree

_REMEDY = "check that it is a BVH file (HIERARCHY ... MOTION ... Frames: ... Frame Time: ...)"
_CHANNELS = ("xposition", "yposition", "zposition", "xrotation", "yrotation", "zrotation")


@dataclass(frozen=True)
class BvhNode:
    name: str
    parent: int                 # index of the parent node, -1 for the root
    offset: np.ndarray          # (3,) in file units
    channels: tuple[str, ...]   # lower-case channel names, e.g. ("zrotation", "yrotation", ...)


@dataclass(frozen=True, eq=False)
class BvhFile:
    nodes: tuple[BvhNode, ...]
    frame_time: float           # seconds per frame
    motion: np.ndarray          # (T, total channels) in file units / degrees


def parse_bvh(path: str | Path) -> BvhFile:
    """Parse a BVH file; malformed input raises PhysposeError naming the file and line."""
    path = Path(path)
    lines = read_lines(path, "BVH")

    def fail(lineno: int, problem: str):
        raise line_error(path, lineno, problem, _REMEDY)

    def floats(tokens: list[str], lineno: int, count: int) -> np.ndarray:
        if len(tokens) != count:
            fail(lineno, f"expected {count} numbers, got {len(tokens)}")
        try:
            return np.array([float(t) for t in tokens])
        except ValueError:
            fail(lineno, f"not a number in {' '.join(tokens)!r}")

    nodes: list[BvhNode | None] = []
    pending: dict | None = None    # node declared (ROOT, JOINT, End Site) until its '{'
    open_fields: list[dict] = []   # nodes whose block is open, innermost last
    i = 0
    while i < len(lines) and not lines[i].strip():
        i += 1
    if i == len(lines) or lines[i].strip().upper() != "HIERARCHY":
        fail(i + 1, "the file must start with HIERARCHY")
    i += 1
    while i < len(lines):
        lineno, tokens = i + 1, lines[i].split()
        i += 1
        if not tokens:
            continue
        key = tokens[0].upper()
        if key in ("ROOT", "JOINT"):
            if (key == "ROOT") != (not open_fields) or (key == "ROOT" and nodes):
                fail(lineno, f"{key} in the wrong place (one ROOT, JOINTs inside it)")
            if len(tokens) < 2:
                fail(lineno, f"{key} without a name")
            pending = {"name": " ".join(tokens[1:]),
                       "parent": open_fields[-1]["index"] if open_fields else -1,
                       "offset": None, "channels": ()}
        elif key == "END":
            if not open_fields:
                fail(lineno, "End Site outside a joint")
            pending = {"name": open_fields[-1]["name"] + "_end",
                       "parent": open_fields[-1]["index"], "offset": None, "channels": (),
                       "end": True}
        elif key == "{":
            if pending is None:
                fail(lineno, "'{' without ROOT, JOINT or End Site")
            pending["index"] = len(nodes)
            nodes.append(None)  # filled when the block closes
            open_fields.append(pending)
            pending = None
        elif key == "OFFSET":
            if not open_fields:
                fail(lineno, "OFFSET outside a joint")
            open_fields[-1]["offset"] = floats(tokens[1:], lineno, 3)
        elif key == "CHANNELS":
            if not open_fields or open_fields[-1].get("end"):
                fail(lineno, "CHANNELS outside a joint")
            if len(tokens) < 2 or not tokens[1].isdigit() or int(tokens[1]) != len(tokens) - 2:
                fail(lineno, "CHANNELS count does not match the channel names")
            chans = tuple(t.lower() for t in tokens[2:])
            unknown = [c for c in chans if c not in _CHANNELS]
            if unknown:
                fail(lineno, f"unknown channel {unknown[0]!r}")
            open_fields[-1]["channels"] = chans
        elif key == "}":
            if not open_fields:
                fail(lineno, "unbalanced '}'")
            f = open_fields.pop()
            if f["offset"] is None:
                fail(lineno, f"joint {f['name']!r} has no OFFSET")
            nodes[f["index"]] = BvhNode(f["name"], f["parent"], f["offset"], f["channels"])
        elif key == "MOTION":
            break
        else:
            fail(lineno, f"unexpected {tokens[0]!r} in the hierarchy")
    else:
        fail(len(lines), "no MOTION section")
    if open_fields or not nodes:
        fail(i, "the hierarchy is empty or not closed before MOTION")

    header: dict[str, float] = {}
    for label in ("frames:", "frame time:"):
        while i < len(lines) and not lines[i].strip():
            i += 1
        if i == len(lines) or not lines[i].strip().lower().startswith(label):
            fail(i + 1, f"expected '{label.capitalize()} ...'")
        header[label] = floats(lines[i].strip()[len(label):].split(), i + 1, 1)[0]
        i += 1
    n_frames, frame_time = header["frames:"], float(header["frame time:"])
    if not (np.isfinite(n_frames) and n_frames >= 1 and n_frames == int(n_frames)) \
            or not (np.isfinite(frame_time) and frame_time > 0):
        fail(i, f"Frames ({n_frames:g}) must be a whole number and Frame Time ({frame_time:g}) "
                "a positive number of seconds")
    n_frames = int(n_frames)
    n_channels = sum(len(n.channels) for n in nodes)
    rows = []
    for j in range(i, len(lines)):
        tokens = lines[j].split()
        if tokens:
            rows.append(floats(tokens, j + 1, n_channels))
    if len(rows) != n_frames:
        fail(len(lines), f"header says {n_frames} frames but {len(rows)} motion rows follow")
    motion = np.stack(rows)
    if not np.isfinite(motion).all():
        fail(i + 1 + int(np.argmax(~np.isfinite(motion).all(1))), "non-finite motion values")
    return BvhFile(tuple(nodes), frame_time, motion)


def bvh_forward_kinematics(bvh: BvhFile, scale: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Global node positions (T, N, 3) (file units x scale) and rotations (T, N, 3, 3)."""
    t = bvh.motion.shape[0]
    n = len(bvh.nodes)
    pos = np.zeros((t, n, 3))
    rot = np.zeros((t, n, 3, 3))
    col = 0
    for k, node in enumerate(bvh.nodes):
        values = bvh.motion[:, col:col + len(node.channels)]
        col += len(node.channels)
        local_pos = np.broadcast_to(node.offset, (t, 3)).copy()
        rot_axes = ""
        rot_cols = []
        for c, name in enumerate(node.channels):
            if name.endswith("position"):
                local_pos[:, "xyz".index(name[0])] += values[:, c]
            else:
                rot_axes += name[0]
                rot_cols.append(c)
        local_rot = euler_matrix(np.deg2rad(values[:, rot_cols]), rot_axes)
        if node.parent < 0:
            pos[:, k], rot[:, k] = local_pos, local_rot
        else:
            parent_rot = rot[:, node.parent]
            pos[:, k] = pos[:, node.parent] + np.einsum("tij,tj->ti", parent_rot, local_pos)
            rot[:, k] = parent_rot @ local_rot
    return pos * scale, rot


# Length units a BVH file may be written in (metres per unit): metres, centimetres,
# millimetres, inches, and CMU's (its ASF "length 0.45": 1/0.45 inch, kept by the widely used
# cgspeed BVH conversion of the CMU database, whose people span about 30 units).
LENGTH_UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001, "inch": 0.0254, "cmu": 0.0254 / 0.45}
TYPICAL_EXTENT = 1.6        # m, an adult's


def guess_length_unit(extent: float) -> float | None:
    """Metres per file unit for a skeleton whose rest pose spans `extent` file units: of the
    LENGTH_UNITS that make it a plausible person, the one nearest a typical adult (None if
    none does)."""
    lo, hi = REST_EXTENT
    fits = [s for s in LENGTH_UNITS.values() if lo <= extent * s <= hi]
    return min(fits, key=lambda s: abs(np.log(extent * s / TYPICAL_EXTENT)), default=None)


def load_bvh(path: str | Path, target_fps: float | None = 25.0,
             scale: float | None = None) -> MocapClip:
    """Read a BVH clip into the project's world frame (see `physpose.mocap.common`).

    scale: metres per file unit; None guesses it from the rest-pose size of the skeleton
    (`guess_length_unit`: metres, centimetres, millimetres, inches or CMU's units).
    """
    path = Path(path)
    bvh = parse_bvh(path)
    names = [n.name for n in bvh.nodes]
    parents = [n.parent for n in bvh.nodes]
    rest = BvhFile(bvh.nodes, bvh.frame_time, np.zeros_like(bvh.motion[:1]))
    rest_pos = bvh_forward_kinematics(rest)[0][0]
    if scale is None:
        extent = float(np.ptp(rest_pos, axis=0).max())
        scale = guess_length_unit(extent)
        if scale is None:
            raise PhysposeError(f"cannot tell the length unit (the skeleton's rest pose spans "
                                f"{extent:g} units, a person in none of "
                                f"{', '.join(LENGTH_UNITS)})", path=path,
                                remedy="rescale the file to metres or centimetres (from Python: "
                                       "load_bvh(path, scale=metres per file unit))")
    pos, rot = bvh_forward_kinematics(bvh, scale)
    times = np.arange(len(bvh.motion)) * bvh.frame_time
    motion = motion_from_tree(path.stem, str(path), times, names, parents, pos, rot,
                              rest_pos * scale)
    return finish_clip(motion, target_fps)
