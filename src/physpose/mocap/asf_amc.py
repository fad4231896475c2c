"""Acclaim ASF (skeleton) / AMC (motion) reader with forward kinematics of our own.

Conventions (Acclaim format as used by the CMU database):
- lengths and the root translation are in file units; `:units length L` means one unit is 1/L
  inch, so metres = value * 0.0254 / L (CMU: L = 0.45). `angle deg|rad` for angles.
- a bone's `axis a b c XYZ` gives C = Rz(c) Ry(b) Rx(a) (rotations applied in the listed order
  about fixed axes); motion values of its `dof` (e.g. rx ry rz) give M the same way; the global
  rotation is R_bone = R_parent C M C^-1 and the bone runs from its parent's end to
  start + R_bone (direction * length), direction given in the rest pose's world axes.
- the root's `order` lists its AMC values (translation and rotation); `axis` and `orientation`
  give its C like a bone's.

The result is a tree with one node per bone start (named after the bone) and one `<bone>_end`
node per leaf bone, the same layout as the CMU BVH conversions (see `physpose.mocap.skeleton`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from physpose.errors import PhysposeError
from physpose.mocap.common import REST_EXTENT, MocapClip, finish_clip, line_error, read_lines
from physpose.mocap.rotations import euler_matrix
from physpose.mocap.skeleton import motion_from_tree

_INCH = 0.0254  # m
_ASF_REMEDY = "check that it is an Acclaim ASF skeleton (:units, :root, :bonedata, :hierarchy)"
_AMC_REMEDY = "check that it is an Acclaim AMC motion file that matches its ASF skeleton"


@dataclass(frozen=True)
class AsfBone:
    name: str
    direction: np.ndarray     # (3,) unit vector, rest-pose world axes
    length: float             # metres
    axis: np.ndarray          # (3,) rad, angles of C
    axis_order: str           # e.g. "xyz"
    dof: tuple[str, ...]      # e.g. ("rx", "ry", "rz")


@dataclass(frozen=True, eq=False)
class AsfSkeleton:
    path: str
    length_to_m: float        # metres per file length unit
    angle_to_rad: float
    root_order: tuple[str, ...]   # e.g. ("tx", "ty", "tz", "rx", "ry", "rz")
    root_axis_order: str
    root_position: np.ndarray     # (3,) m
    root_orientation: np.ndarray  # (3,) rad
    bones: dict[str, AsfBone]
    parent: dict[str, str]        # bone -> parent bone, or "root"
    order: tuple[str, ...]        # bones, parents before children


def _sections(lines: list[str]) -> list[tuple[str, int, list[tuple[int, list[str]]]]]:
    """Split an ASF into (keyword, line number, [(line number, tokens), ...]) sections."""
    out: list[tuple[str, int, list]] = []
    for i, line in enumerate(lines):
        s = line.split("#", 1)[0].strip()
        if not s:
            continue
        if s.startswith(":"):
            key, *rest = s[1:].split(None, 1)
            out.append((key.lower(), i + 1, [(i + 1, rest[0].split())] if rest else []))
        elif out:
            out[-1][2].append((i + 1, s.split()))
        else:
            raise PhysposeError(f"line {i + 1}: text before the first ':' keyword",
                                path=None, remedy=_ASF_REMEDY)
    return out


def parse_asf(path: str | Path) -> AsfSkeleton:
    """Parse an ASF skeleton; malformed input raises PhysposeError naming the file and line."""
    path = Path(path)
    lines = read_lines(path, "ASF")

    def fail(lineno: int, problem: str):
        raise line_error(path, lineno, problem, _ASF_REMEDY)

    def num(tok: str, lineno: int) -> float:
        try:
            value = float(tok)
        except ValueError:
            fail(lineno, f"{tok!r} is not a number")
        if not np.isfinite(value):
            fail(lineno, f"{tok!r} is not a finite number")
        return value

    def args(tokens: list[str], lineno: int, count: int) -> list[str]:
        if len(tokens) - 1 != count:
            fail(lineno, f"{tokens[0]} needs {count} value{'s' * (count > 1)}, got "
                         f"{len(tokens) - 1}")
        return tokens[1:]

    try:
        sections = _sections(lines)
    except PhysposeError as exc:
        raise PhysposeError(exc.problem, path=path, remedy=_ASF_REMEDY) from None
    by_key = {key: (lineno, body) for key, lineno, body in sections}
    for key in ("root", "bonedata", "hierarchy"):
        if key not in by_key:
            fail(len(lines), f"missing :{key} section")

    units = {"length": 1.0, "angle": "deg"}
    for lineno, tokens in by_key.get("units", (0, []))[1]:
        if tokens[0] in ("length", "mass"):
            units[tokens[0]] = num(args(tokens, lineno, 1)[0], lineno)
        elif len(tokens) >= 2 and tokens[0] == "angle":
            if tokens[1].lower() not in ("deg", "rad"):
                fail(lineno, f"angle unit {tokens[1]!r} is neither deg nor rad")
            units["angle"] = tokens[1].lower()
    if units["length"] <= 0:
        fail(by_key["units"][0], "length unit must be positive")
    to_m = _INCH / units["length"]
    to_rad = np.pi / 180 if units["angle"] == "deg" else 1.0

    root = {}
    for lineno, tokens in by_key["root"][1]:
        root[tokens[0].lower()] = (lineno, tokens[1:])
    for key in ("order", "axis", "position", "orientation"):
        if key not in root:
            fail(by_key["root"][0], f":root lacks '{key}'")
    root_order = tuple(t.lower() for t in root["order"][1])
    if sorted(root_order) != sorted(set(root_order)) or not set(root_order) <= {
            "tx", "ty", "tz", "rx", "ry", "rz"}:
        fail(root["order"][0], f"bad root order {root['order'][1]}")

    bones: dict[str, AsfBone] = {}
    block: dict | None = None
    for lineno, tokens in by_key["bonedata"][1]:
        key = tokens[0].lower()
        if key == "begin":
            block = {"line": lineno, "dof": ()}
        elif key == "end":
            if block is None:
                fail(lineno, "'end' without 'begin'")
            for need in ("name", "direction", "length", "axis"):
                if need not in block:
                    fail(block["line"], f"bone lacks '{need}'")
            d = block["direction"]
            if np.linalg.norm(d) == 0:
                fail(block["line"], f"bone {block['name']!r} has a zero direction")
            bones[block["name"]] = AsfBone(block["name"], d / np.linalg.norm(d),
                                           block["length"] * to_m, block["axis"] * to_rad,
                                           block["axis_order"], block["dof"])
            block = None
        elif block is None:
            fail(lineno, f"{tokens[0]!r} outside begin/end")
        elif key == "name":
            block["name"] = args(tokens, lineno, 1)[0]
        elif key == "direction":
            block["direction"] = np.array([num(t, lineno) for t in args(tokens, lineno, 3)])
        elif key == "length":
            block["length"] = num(args(tokens, lineno, 1)[0], lineno)
        elif key == "axis":
            if len(tokens) != 5 or sorted(tokens[4].lower()) != ["x", "y", "z"]:
                fail(lineno, "axis needs three angles and an order such as XYZ")
            block["axis"] = np.array([num(t, lineno) for t in tokens[1:4]])
            block["axis_order"] = tokens[4].lower()
        elif key == "dof":
            dof = tuple(t.lower() for t in tokens[1:])
            if not set(dof) <= {"rx", "ry", "rz", "tx", "ty", "tz", "l"}:
                fail(lineno, f"unknown dof in {tokens[1:]}")
            block["dof"] = dof
    if block is not None:
        fail(block["line"], "bone block not closed with 'end'")

    parent: dict[str, str] = {}
    for lineno, tokens in by_key["hierarchy"][1]:
        if tokens[0].lower() in ("begin", "end"):
            continue
        for child in tokens[1:]:
            if child not in bones:
                fail(lineno, f"hierarchy names unknown bone {child!r}")
            if tokens[0] != "root" and tokens[0] not in bones:
                fail(lineno, f"hierarchy names unknown bone {tokens[0]!r}")
            parent[child] = tokens[0]
    order: list[str] = []
    frontier = ["root"]
    while frontier:
        p = frontier.pop(0)
        kids = [b for b in bones if parent.get(b) == p]
        order += kids
        frontier += kids
    if len(order) != len(bones):
        missing = sorted(set(bones) - set(order))
        fail(by_key["hierarchy"][0], f"bones not connected to the root: {missing}")

    def vec(key: str) -> np.ndarray:
        lineno, toks = root[key]
        if len(toks) != 3:
            fail(lineno, f"root {key} needs three numbers")
        return np.array([num(t, lineno) for t in toks])

    axis_order = root["axis"][1][0].lower() if root["axis"][1] else ""
    if sorted(axis_order) != ["x", "y", "z"]:
        fail(root["axis"][0], "root axis must be an order such as XYZ")
    return AsfSkeleton(str(path), to_m, to_rad, root_order, axis_order,
                       vec("position") * to_m, vec("orientation") * to_rad,
                       bones, parent, tuple(order))


def parse_amc(path: str | Path, skeleton: AsfSkeleton) -> dict[str, np.ndarray]:
    """Per-bone motion values (T, len(dof)) in file units/degrees, plus "root" (T, len(order))."""
    path = Path(path)
    lines = read_lines(path, "AMC")

    def fail(lineno: int, problem: str):
        raise line_error(path, lineno, problem, _AMC_REMEDY)

    width = {b.name: len(b.dof) for b in skeleton.bones.values()}
    width["root"] = len(skeleton.root_order)
    frames: list[dict[str, list[float]]] = []
    for i, line in enumerate(lines):
        s = line.strip()
        if not s or s.startswith(("#", ":")):
            continue
        tokens = s.split()
        if len(tokens) == 1 and tokens[0].isdigit():
            if int(tokens[0]) != len(frames) + 1:
                fail(i + 1, f"frame number {tokens[0]} out of sequence (expected {len(frames) + 1})")
            frames.append({})
            continue
        if not frames:
            fail(i + 1, "motion values before the first frame number")
        name = tokens[0]
        if name not in width:
            fail(i + 1, f"bone {name!r} is not in the skeleton {skeleton.path}")
        if len(tokens) - 1 != width[name]:
            fail(i + 1, f"bone {name!r} has {len(tokens) - 1} values, its dof needs {width[name]}")
        try:
            values = [float(t) for t in tokens[1:]]
        except ValueError:
            fail(i + 1, "a motion value is not a number")
        if not np.isfinite(values).all():
            fail(i + 1, f"bone {name!r} has a NaN or infinite value")
        frames[-1][name] = values
    if not frames:
        fail(len(lines), "no frames")
    out = {}
    for name, w in width.items():
        if w == 0:
            continue
        missing = [k for k, f in enumerate(frames) if name not in f]
        if missing:
            raise PhysposeError(f"bone {name!r} has no values in frame {missing[0] + 1}",
                                path=path, remedy=_AMC_REMEDY)
        out[name] = np.array([f[name] for f in frames])
    return out


def asf_forward_kinematics(skeleton: AsfSkeleton, motion: dict[str, np.ndarray]
                           ) -> tuple[list[str], list[int], np.ndarray, np.ndarray]:
    """The skeleton as a tree of bone starts plus `<leaf>_end` nodes.

    Returns names, parents, positions (T, N, 3) m and global rotations (T, N, 3, 3).
    """
    t = len(motion["root"])

    def rotation(values: np.ndarray, dof: tuple[str, ...]) -> np.ndarray:
        """Rotation of the rx/ry/rz values (T, len(dof)), applied in the listed order."""
        cols = [k for k, d in enumerate(dof) if d[0] == "r"]
        order = "".join(dof[k][1] for k in cols)
        return euler_matrix(values[:, cols[::-1]] * skeleton.angle_to_rad, order[::-1])

    root_vals = {name: motion["root"][:, k] for k, name in enumerate(skeleton.root_order)}
    c_root = euler_matrix(skeleton.root_orientation[::-1], skeleton.root_axis_order[::-1])
    m_root = rotation(motion["root"], skeleton.root_order)
    root_pos = skeleton.root_position + np.stack(
        [root_vals.get(a, np.zeros(t)) for a in ("tx", "ty", "tz")], -1) * skeleton.length_to_m
    names, parents = ["root"], [-1]
    pos, rot = [root_pos], [c_root @ m_root @ c_root.T]
    end_of = {"root": root_pos}
    for name in skeleton.order:
        bone = skeleton.bones[name]
        m = rotation(motion[name], bone.dof) if bone.dof else np.eye(3)
        c = euler_matrix(bone.axis[::-1], bone.axis_order[::-1])
        r = rot[names.index(skeleton.parent[name])] @ c @ m @ c.T
        start = end_of[skeleton.parent[name]]
        end_of[name] = start + np.einsum("tij,j->ti", r, bone.direction * bone.length)
        names.append(name)
        parents.append(names.index(skeleton.parent[name]))
        pos.append(start)
        rot.append(r)
    for name in skeleton.order:
        if not any(p == name for p in skeleton.parent.values()):
            names.append(name + "_end")
            parents.append(names.index(name))
            pos.append(end_of[name])
            rot.append(rot[names.index(name)])
    return names, parents, np.stack(pos, 1), np.stack(rot, 1)


def find_asf(amc_path: str | Path, asf: str | Path | None = None) -> Path:
    """The skeleton of an AMC file.

    In this order: `asf` if given; `<stem>.asf` beside it; the stem without a trailing take
    number (`charleston1.amc` -> `charleston.asf`, CMU's `02_01.amc` -> `02.asf`); the only
    .asf in the folder.
    """
    amc_path = Path(amc_path)
    if asf is not None:
        if not Path(asf).is_file():
            raise PhysposeError("ASF skeleton not found", path=asf, remedy="pass an existing .asf")
        return Path(asf)
    for stem in (amc_path.stem, re.sub(r"[_\-. ]*\d+$", "", amc_path.stem)):
        same = amc_path.with_name(stem + ".asf")
        if stem and same.is_file():
            return same
    candidates = sorted(amc_path.parent.glob("*.asf"))
    if len(candidates) == 1:
        return candidates[0]
    found = "none" if not candidates else ", ".join(c.name for c in candidates)
    raise PhysposeError(f"cannot tell which ASF skeleton belongs to this AMC (found {found})",
                        path=amc_path,
                        remedy="name the .asf as the .amc is named (walk.asf for walk_01.amc), "
                               "or keep one .asf in its folder (from Python: asf=...)")


CMU_AMC_FPS = 120.0  # Hz; AMC files carry no rate, CMU captured at 120 Hz


def load_amc(path: str | Path, target_fps: float | None = 25.0, asf: str | Path | None = None,
             source_fps: float = CMU_AMC_FPS) -> MocapClip:
    """Read an AMC clip (skeleton from `find_asf`) into the project's world frame."""
    path = Path(path)
    skeleton = parse_asf(find_asf(path, asf))
    motion = parse_amc(path, skeleton)
    names, parents, pos, rot = asf_forward_kinematics(skeleton, motion)
    rest = {k: np.zeros((1, v.shape[1])) for k, v in motion.items()}
    rest_pos = asf_forward_kinematics(skeleton, rest)[2][0]
    extent = float(np.ptp(rest_pos, axis=0).max())
    if not REST_EXTENT[0] <= extent <= REST_EXTENT[1]:
        raise PhysposeError(f"the skeleton's rest pose spans {extent:.2f} m, not a person "
                            f"({REST_EXTENT[0]:g}-{REST_EXTENT[1]:g} m)", path=skeleton.path,
                            remedy="check ':units length' (one file unit is 1/length inch; "
                                   "CMU: length 0.45)")
    times = np.arange(len(pos)) / source_fps
    tree = motion_from_tree(path.stem, str(path), times, names, parents, pos, rot, rest_pos)
    return finish_clip(tree, target_fps)
