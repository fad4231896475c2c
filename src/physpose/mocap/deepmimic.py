"""DeepMimic motion clips (JSON `Frames`) with the character file that defines their skeleton.

A frame row is [dt, root position (3), root quaternion (w, x, y, z), then per joint in ID order:
4 quaternion values for a spherical joint, 1 angle (rad, about the joint's z axis) for a
revolute one, nothing for a fixed one]; dt is the time to the next frame. The character's world
frame is y up, and it faces +x with its right side towards +z. Joints sit at their parent joint
plus the parent's rotation applied to (AttachX, AttachY, AttachZ).

Mapping to the project's joints: hips, knees, ankles, shoulders, elbows, wrists are the joints
of the same names; heel and toe are the rear and front bottom-edge midpoints of the ankle's foot
box; the head (between the ears) is the centre of the neck joint's sphere, the head top that
sphere's top.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from physpose.errors import PhysposeError
from physpose.json_text import read_json_file
from physpose.mocap.common import SIDES, MocapClip, SkeletonMotion, finish_clip
from physpose.mocap.rotations import axis_rotation, quat_matrix

_REMEDY = "check it is a DeepMimic clip (JSON with 'Frames') and its character_*.txt skeleton"
_DOF = {"none": 0, "spherical": 4, "revolute": 1, "fixed": 0}
_SIDE_WORD = {"l": "left", "r": "right"}


def find_character(clip_path: Path, character: str | Path | None = None) -> Path:
    """The character file: given, else `character_<prefix>.txt` beside the clip
    (`humanoid3d_walk.txt` -> `character_humanoid3d.txt`), else the folder's only character_*.txt."""
    if character is not None:
        if not Path(character).is_file():
            raise PhysposeError("DeepMimic character file not found", path=character)
        return Path(character)
    same = clip_path.with_name("character_" + clip_path.stem.split("_")[0] + ".txt")
    if same.is_file():
        return same
    found = sorted(clip_path.parent.glob("character_*.txt"))
    if len(found) == 1:
        return found[0]
    raise PhysposeError(f"cannot tell which character file belongs to this clip (found "
                        f"{[f.name for f in found] or 'none'})", path=clip_path,
                        remedy="put character_<name>.txt beside the clip, or keep one "
                               "character file in its folder (from Python: character=...)")


def _read_json(path: Path) -> dict:
    return read_json_file(path, remedy=_REMEDY)


def _floats(row: list) -> bool:
    try:
        np.asarray(row, dtype=float)
    except (TypeError, ValueError, OverflowError):
        return False
    return True


def _character(path: Path) -> tuple[list[dict], dict[int, dict]]:
    data = _read_json(path)
    try:
        joints = sorted(data["Skeleton"]["Joints"], key=lambda j: j["ID"])
        bodies = {b["ID"]: b for b in data.get("BodyDefs", [])}
    except (KeyError, TypeError) as exc:
        raise PhysposeError(f"character file lacks Skeleton/Joints ({exc})", path=path,
                            remedy=_REMEDY) from None
    need = ("ID", "Name", "Type", "Parent", "AttachX", "AttachY", "AttachZ")
    for k, j in enumerate(joints):
        if not isinstance(j, dict) or any(key not in j for key in need) or not all(
                isinstance(j[key], (int, float)) and math.isfinite(j[key])
                for key in need if key not in ("Name", "Type")):
            raise PhysposeError(f"Skeleton/Joints[{k}] needs the numbers ID, Parent, AttachX/Y/Z, "
                                "a Name and a Type", path=path, remedy=_REMEDY)
        if j["ID"] != k or not (j["Parent"] < k):
            raise PhysposeError(f"joint {j.get('Name')!r}: IDs must be 0..N-1 with parents first",
                                path=path, remedy=_REMEDY)
        if j["Type"] not in _DOF:
            raise PhysposeError(f"joint {j['Name']!r} has unsupported type {j['Type']!r}",
                                path=path, remedy="only spherical, revolute and fixed joints")
        if any(j.get(f"AttachTheta{a}", 0) for a in "XYZ"):
            raise PhysposeError(f"joint {j['Name']!r} has a rotated attachment (AttachTheta)",
                                path=path, remedy="only unrotated joint frames are supported")
    return joints, bodies


def load_deepmimic(path: str | Path, target_fps: float | None = 25.0,
                   character: str | Path | None = None) -> MocapClip:
    """Read a DeepMimic clip into the project's world frame (see `physpose.mocap.common`)."""
    path = Path(path)
    char_path = find_character(path, character)
    joints, bodies = _character(char_path)
    clip = _read_json(path)
    frames = clip.get("Frames") if isinstance(clip, dict) else None
    width = 8 + sum(_DOF[j["Type"]] for j in joints[1:])
    if not isinstance(frames, list) or len(frames) < 2:
        raise PhysposeError("no 'Frames' list with at least two frames", path=path, remedy=_REMEDY)
    for k, row in enumerate(frames):
        if not isinstance(row, list) or len(row) != width:
            raise PhysposeError(f"Frames[{k}] has {len(row) if isinstance(row, list) else '?'} "
                                f"values, the character {char_path.name} needs {width}",
                                path=path, frame=k, remedy=_REMEDY)
    try:
        data = np.asarray(frames, dtype=float)
    except (TypeError, ValueError, OverflowError):  # Overflow: an integer of 309+ digits
        k = next(k for k, row in enumerate(frames) if not _floats(row))
        raise PhysposeError(f"Frames[{k}] holds something other than numbers", path=path,
                            frame=k, remedy=_REMEDY) from None
    if not np.isfinite(data).all():
        raise PhysposeError("non-finite values", path=path,
                            frame=int(np.argmax(~np.isfinite(data).all(1))), remedy=_REMEDY)
    times = np.concatenate([[0.0], np.cumsum(data[:-1, 0])])
    pos, rot = _forward_kinematics(joints, data)
    return finish_clip(_motion(path, char_path, times, joints, bodies, pos, rot), target_fps)


def _forward_kinematics(joints: list[dict], data: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Joint positions (T, N, 3) and global rotations (T, N, 3, 3) of frame rows (T, width)."""
    t = len(data)
    pos = np.zeros((t, len(joints), 3))
    rot = np.zeros((t, len(joints), 3, 3))
    pos[:, 0], rot[:, 0] = data[:, 1:4], quat_matrix(data[:, 4:8])
    col = 8
    for k, j in enumerate(joints[1:], start=1):
        n = _DOF[j["Type"]]
        values = data[:, col:col + n]
        col += n
        local = (quat_matrix(values) if n == 4 else axis_rotation("z", values[:, 0]) if n == 1
                 else np.broadcast_to(np.eye(3), (t, 3, 3)))
        attach = np.array([j["AttachX"], j["AttachY"], j["AttachZ"]])
        p = j["Parent"]
        pos[:, k] = pos[:, p] + rot[:, p] @ attach
        rot[:, k] = rot[:, p] @ local
    return pos, rot


def character_stature(character: str | Path) -> float:
    """Standing height (m) of a DeepMimic character in its zero pose: foot-box bottom to head top."""
    character = Path(character)
    joints, bodies = _character(character)
    row = [0.0] * 8
    row[4] = 1.0  # identity root quaternion
    for j in joints[1:]:
        row += [1.0, 0.0, 0.0, 0.0] if j["Type"] == "spherical" else [0.0] * _DOF[j["Type"]]
    pos, rot = _forward_kinematics(joints, np.array([row, row]))
    motion = _motion(character, character, np.array([0.0, 1.0]), joints, bodies, pos, rot)
    return float(motion.points["head_top"][0, 1] - motion.points["l_heel"][0, 1])


def _motion(path, char_path, times, joints, bodies, pos, rot) -> SkeletonMotion:
    index = {j["Name"]: j["ID"] for j in joints}

    def at(name: str) -> int:
        if name not in index:
            raise PhysposeError(f"the character has no joint {name!r}", path=char_path,
                                remedy="use a humanoid character with DeepMimic's joint names")
        return index[name]

    def local(k: int, v) -> np.ndarray:
        return pos[:, k] + rot[:, k] @ np.asarray(v, dtype=float)

    points = {}
    for s in SIDES:
        side = _SIDE_WORD[s]
        for part in ("hip", "knee", "ankle", "shoulder", "elbow", "wrist"):
            points[f"{s}_{part}"] = pos[:, at(f"{side}_{part}")]
        ankle = at(f"{side}_ankle")
        foot = bodies.get(ankle)
        if foot is None or foot.get("Shape") != "box" or any(
                k not in foot for k in ("AttachX", "AttachY", "AttachZ", "Param0", "Param1",
                                        "Param2")):
            raise PhysposeError(f"the {side} ankle has no box foot body (Shape box, AttachX/Y/Z, "
                                "Param0-2)", path=char_path, remedy=_REMEDY)
        centre = np.array([foot["AttachX"], foot["AttachY"], foot["AttachZ"]])
        half = 0.5 * np.array([foot["Param0"], foot["Param1"], foot["Param2"]])
        points[f"{s}_heel"] = local(ankle, centre + [-half[0], -half[1], 0.0])
        points[f"{s}_toe"] = local(ankle, centre + [half[0], -half[1], 0.0])
    neck = at("neck")
    head = bodies.get(neck)
    if head is None or head.get("Shape") != "sphere" or any(
            k not in head for k in ("AttachX", "AttachY", "AttachZ", "Param0")):
        raise PhysposeError("the neck joint has no sphere head body (Shape sphere, AttachX/Y/Z, "
                            "Param0)", path=char_path, remedy=_REMEDY)
    head_centre = np.array([head["AttachX"], head["AttachY"], head["AttachZ"]])
    points["head"] = local(neck, head_centre)
    points["head_top"] = local(neck, head_centre + [0.0, 0.5 * head["Param0"], 0.0])
    # Head columns: forward (+x), left (-z), up (+y). Hands continue the forearm (-y) with the
    # thumb forward (+x): the arms hang with the palms towards the body at rest.
    head_rot = rot[:, neck] @ np.stack([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]], axis=1)
    hand = np.stack([[0, -1.0, 0], [1, 0, 0], [0, 0, 1]], axis=1)  # columns: -y, +x, -y cross +x
    hand_rot = np.stack([rot[:, at(f"{_SIDE_WORD[s]}_elbow")] @ hand for s in SIDES], axis=1)
    return SkeletonMotion(name=path.stem, source=str(path), times=times, points=points,
                          head_rot=head_rot, hand_rot=hand_rot, up=np.array([0.0, 1.0, 0.0]))
