"""The articulated body, defined once for the kinematic fit (JAX) and the simulator (MuJoCo).

Frame and rest pose. World and every body frame share one orientation in the rest pose:
**x forward (the person faces +x), y to the person's left, z up**. The rest pose (all angles 0)
stands upright with the arms hanging down at the sides (palms facing the thighs, thumbs
forward) and the feet pointing forward; each joint's frame is parallel to its parent's.

Segments. A free root at the pelvis (mid-hip point) and 16 three-axis joints. Each segment is a
rigid body whose origin is the joint it hangs from, and it is named after that joint (body
``l_knee`` is the shank, origin at the knee). The trunk and head joints sit where
``physpose.joints.joints_from_landmarks`` puts its proxies: ``spine`` halfway between mid-hip
and mid-shoulder, ``thorax`` at mid-shoulder (it carries the shoulder girdle), ``neck`` halfway
between mid-shoulder and mid-ear, ``head`` at mid-ear.

Degrees of freedom. Each joint is three hinges applied in the order **y, x, z** (intrinsic, each
about the axis of the frame already rotated by the previous hinges, starting parallel to the
parent frame): R_local = Ry(a) Rx(b) Rz(c). y is the flexion/extension axis, x ab/adduction or
lateral bending, z axial rotation about the vertical (limb) axis, as in the ISB joint coordinate
systems (Wu et al. 2002). The sequence is singular only when the middle (x) hinge reaches +-90
degrees, which only the shoulders can (arm raised straight out to the side): fits that pass
through it can optimise rotations in another parametrisation and convert with
``physpose.fk.angles_from_matrices``. Sign convention (right-hand rule about +x/+y/+z): for a
limb hanging down, +y moves it backwards, +x moves it to the person's left, +z turns its front
to the left; for the trunk and head, +y bends forward, +x bends to the right.

Generalised coordinates (MuJoCo order): qpos = [root position (3), root quaternion w,x,y,z (4),
48 hinge angles in DOF_NAMES order]; qvel = [root linear (3, world), root angular (3, local),
48 hinge rates]; actuator k drives DOF_NAMES[k].

Joint ranges are the normal active ranges of motion of healthy adults (AAOS "Joint Motion:
Method of Measuring and Recording", 1965; Soucie et al., Haemophilia 17:500, 2011), with the
spine and neck ranges split between the two joints that model each region, and the secondary
axes of knee and elbow held to a few degrees.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from physpose.joints import JOINT_NAMES, LANDMARK_NAMES

# Bone-length parameters of the skeleton, metres (the kinematic fit's shape vector).
BONE_NAMES: tuple[str, ...] = (
    "hip_width",       # between the hip joint centres
    "trunk",           # mid-hip to mid-shoulder
    "shoulder_width",  # between the shoulder joint centres
    "neck",            # mid-shoulder to mid-ear
    "ear_width",       # ear to ear; scales the face landmarks
    "upper_arm",       # shoulder to elbow
    "forearm",         # elbow to wrist
    "hand",            # wrist to the index landmark (MediaPipe's "index")
    "thigh",           # hip to knee
    "shank",           # knee to ankle
    "ankle_height",    # ankle joint above the sole
    "foot_length",     # heel landmark to toe (foot index) landmark
    "heel_back",       # ankle to heel landmark, horizontally
)
BONE_INDEX: dict[str, int] = {n: i for i, n in enumerate(BONE_NAMES)}
NUM_BONES = len(BONE_NAMES)

AXES: tuple[str, ...] = ("y", "x", "z")  # hinge order within a joint (see module docstring)
AXIS_VECTORS: dict[str, tuple[float, float, float]] = {
    "x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}

# Offsets are linear in the bone lengths: {bone: (cx, cy, cz)} means sum of c * bone.
_Linear = dict[str, tuple[float, float, float]]


@dataclass(frozen=True)
class Segment:
    """One rigid body of the skeleton and the 3-axis joint it hangs from (none for the root).

    offset: joint position in the parent's frame (rest pose), linear in the bones.
    limits_deg: (lower, upper) per hinge in AXES order, degrees.
    torque: actuator force limit at the reference body (70 kg, 1.75 m), N·m, all three hinges.
    mass_group: the anatomical segment of the mass table whose mass this body shares.
    """

    name: str
    parent: str | None
    offset: _Linear
    limits_deg: tuple[tuple[float, float], ...] = ()
    torque: float = 0.0
    mass_group: str = ""


def _mirror(limits: tuple[tuple[float, float], ...]) -> tuple[tuple[float, float], ...]:
    """Right-side limits from left-side ones: the x and z hinges swap sign, y does not."""
    (y, x, z) = limits
    return (y, (-x[1], -x[0]), (-z[1], -z[0]))


# Left-side limits in AXES order (y, x, z), degrees. Left limb: +y = backwards (hip/shoulder
# extension, knee flexion, elbow extension, ankle plantarflexion, wrist ulnar deviation as the
# palm faces medially), +x = towards the person's left = outwards (abduction, ankle eversion,
# wrist extension), +z = front turned outwards (external rotation, forearm supination).
# hip: flexion 120 / extension 30, adduction 30 / abduction 45, internal 40 / external 45
_HIP = ((-120.0, 30.0), (-30.0, 45.0), (-40.0, 45.0))
# knee: flexion 150, varus/valgus 5, tibial rotation 20
_KNEE = ((-5.0, 150.0), (-5.0, 5.0), (-20.0, 20.0))
# ankle: dorsiflexion 25 / plantarflexion 50, inversion 35 / eversion 20, adduction 30
_ANKLE = ((-25.0, 50.0), (-35.0, 20.0), (-30.0, 30.0))
# shoulder: flexion 180 / extension 60, adduction 40 / abduction 180, internal 70 / external 90
_SHOULDER = ((-180.0, 60.0), (-40.0, 180.0), (-70.0, 90.0))
# elbow: flexion 150, carrying angle 5, pronation/supination 85 from mid-position
_ELBOW = ((-150.0, 5.0), (-5.0, 5.0), (-85.0, 85.0))
# wrist: radial 20 / ulnar 30 deviation, flexion 80 / extension 70, twist 15
_WRIST = ((-20.0, 30.0), (-80.0, 70.0), (-15.0, 15.0))
# Trunk: +y = flexion (forward), +x = lateral bend to the right, +z = rotation to the left.
_SPINE = ((-25.0, 50.0), (-25.0, 25.0), (-20.0, 20.0))     # lumbar share of thoracolumbar ROM
_THORAX = ((-20.0, 30.0), (-20.0, 20.0), (-35.0, 35.0))    # thoracic share
_NECK = ((-35.0, 30.0), (-25.0, 25.0), (-40.0, 40.0))      # lower cervical share
_HEAD = ((-30.0, 25.0), (-20.0, 20.0), (-40.0, 40.0))      # upper cervical share

# Torque limits (N·m) at the reference body (70 kg, 1.75 m); scaled by mass x height.
# Sources: DeepMimic humanoid (Peng et al., SIGGRAPH 2018: hip 200, knee 150, ankle 90,
# chest 200, shoulder 100, elbow 60, neck 50) raised towards adult peak isometric strength
# (hip/trunk extension 200-300, knee extension ~200, plantarflexion ~150, shoulder ~100,
# elbow ~70, wrist ~15, neck ~40 N·m; e.g. Anderson et al., J Biomech 40:3105, 2007;
# Harbo et al., Eur J Appl Physiol 112:267, 2012).
SEGMENTS: tuple[Segment, ...] = (
    Segment("pelvis", None, {}, mass_group="lower_trunk"),
    Segment("l_hip", "pelvis", {"hip_width": (0.0, 0.5, 0.0)}, _HIP, 250.0, "thigh"),
    Segment("l_knee", "l_hip", {"thigh": (0.0, 0.0, -1.0)}, _KNEE, 200.0, "shank"),
    Segment("l_ankle", "l_knee", {"shank": (0.0, 0.0, -1.0)}, _ANKLE, 150.0, "foot"),
    Segment("r_hip", "pelvis", {"hip_width": (0.0, -0.5, 0.0)}, _mirror(_HIP), 250.0, "thigh"),
    Segment("r_knee", "r_hip", {"thigh": (0.0, 0.0, -1.0)}, _mirror(_KNEE), 200.0, "shank"),
    Segment("r_ankle", "r_knee", {"shank": (0.0, 0.0, -1.0)}, _mirror(_ANKLE), 150.0, "foot"),
    Segment("spine", "pelvis", {"trunk": (0.0, 0.0, 0.5)}, _SPINE, 250.0, "upper_trunk"),
    Segment("thorax", "spine", {"trunk": (0.0, 0.0, 0.5)}, _THORAX, 200.0, "upper_trunk"),
    Segment("neck", "thorax", {"neck": (0.0, 0.0, 0.5)}, _NECK, 40.0, "head"),
    Segment("head", "neck", {"neck": (0.0, 0.0, 0.5)}, _HEAD, 20.0, "head"),
    Segment("l_shoulder", "thorax", {"shoulder_width": (0.0, 0.5, 0.0)}, _SHOULDER, 100.0,
            "upper_arm"),
    Segment("l_elbow", "l_shoulder", {"upper_arm": (0.0, 0.0, -1.0)}, _ELBOW, 70.0, "forearm"),
    Segment("l_wrist", "l_elbow", {"forearm": (0.0, 0.0, -1.0)}, _WRIST, 15.0, "hand"),
    Segment("r_shoulder", "thorax", {"shoulder_width": (0.0, -0.5, 0.0)}, _mirror(_SHOULDER),
            100.0, "upper_arm"),
    Segment("r_elbow", "r_shoulder", {"upper_arm": (0.0, 0.0, -1.0)}, _mirror(_ELBOW), 70.0,
            "forearm"),
    Segment("r_wrist", "r_elbow", {"forearm": (0.0, 0.0, -1.0)}, _mirror(_WRIST), 15.0, "hand"),
)
SEGMENT_NAMES: tuple[str, ...] = tuple(s.name for s in SEGMENTS)
SEGMENT_INDEX: dict[str, int] = {n: i for i, n in enumerate(SEGMENT_NAMES)}
# Parent index per segment (-1 for the root); parents precede children (depth-first order,
# which is also MuJoCo's body order).
PARENTS: tuple[int, ...] = tuple(-1 if s.parent is None else SEGMENT_INDEX[s.parent]
                                 for s in SEGMENTS)
ACTUATED_SEGMENTS: tuple[str, ...] = SEGMENT_NAMES[1:]  # the 16 three-axis joints
NUM_JOINTS3 = len(ACTUATED_SEGMENTS)  # 16
DOF_NAMES: tuple[str, ...] = tuple(f"{s}_{a}" for s in ACTUATED_SEGMENTS for a in AXES)
NUM_DOF = len(DOF_NAMES)  # 48
NQ = 7 + NUM_DOF  # 55
NV = 6 + NUM_DOF  # 54
ROOT_POS = slice(0, 3)
ROOT_QUAT = slice(3, 7)
HINGES = slice(7, NQ)

REFERENCE_MASS = 70.0    # kg, body the torque table is written for
REFERENCE_HEIGHT = 1.75  # m

# Landmark sites: (parent segment, offset linear in bones). Face offsets scale with ear_width
# (ear_width ~ 0.15 m: nose ~11 cm ahead of the ear canals), hand landmarks with the hand
# (palm facing medially, thumb forward), foot landmarks with the foot.
_FACE: dict[str, tuple[float, float, float]] = {
    "nose": (0.72, 0.0, -0.12),
    "left_eye_inner": (0.60, 0.11, 0.10), "left_eye": (0.57, 0.21, 0.11),
    "left_eye_outer": (0.50, 0.31, 0.10),
    "right_eye_inner": (0.60, -0.11, 0.10), "right_eye": (0.57, -0.21, 0.11),
    "right_eye_outer": (0.50, -0.31, 0.10),
    "left_ear": (0.0, 0.5, 0.0), "right_ear": (0.0, -0.5, 0.0),
    "mouth_left": (0.60, 0.16, -0.33), "mouth_right": (0.60, -0.16, -0.33),
}
# (the index landmark is exactly one "hand" length from the wrist)
_HAND = {"pinky": (-0.35, 0.0, -0.85), "index": (0.25, 0.0, -math.sqrt(1.0 - 0.25 ** 2)),
         "thumb": (0.45, -0.12, -0.60)}
# Heel and toe landmarks sit a quarter of the ankle height above the sole.
FOOT_LANDMARK_Z = -0.75


def _landmark_table() -> dict[str, tuple[str, _Linear]]:
    table: dict[str, tuple[str, _Linear]] = {}
    for name, c in _FACE.items():
        table[name] = ("head", {"ear_width": c})
    for side, s, sign in (("left", "l", 1.0), ("right", "r", -1.0)):
        for point, seg in (("shoulder", "shoulder"), ("elbow", "elbow"), ("wrist", "wrist"),
                           ("hip", "hip"), ("knee", "knee"), ("ankle", "ankle")):
            table[f"{side}_{point}"] = (f"{s}_{seg}", {})
        for finger, (cx, cy, cz) in _HAND.items():
            table[f"{side}_{finger}"] = (f"{s}_wrist", {"hand": (cx, sign * cy, cz)})
        table[f"{side}_heel"] = (f"{s}_ankle", {"heel_back": (-1.0, 0.0, 0.0),
                                                "ankle_height": (0.0, 0.0, FOOT_LANDMARK_Z)})
        table[f"{side}_foot_index"] = (f"{s}_ankle", {"foot_length": (1.0, 0.0, 0.0),
                                                      "heel_back": (-1.0, 0.0, 0.0),
                                                      "ankle_height": (0.0, 0.0, FOOT_LANDMARK_Z)})
    return table


LANDMARK_SITES: dict[str, tuple[str, _Linear]] = _landmark_table()
LANDMARK_PARENTS: tuple[int, ...] = tuple(SEGMENT_INDEX[LANDMARK_SITES[n][0]]
                                          for n in LANDMARK_NAMES)

# Project joints (JOINT_NAMES) as points: a segment origin, or, for heels and toes, the rear and
# front midpoints of the sole (the foot box's bottom face). Heel and toe joints are contact points
# so that the foot-contact metrics (physpose.metrics) see the sole where it is; mocap readers
# place them the same way. The MediaPipe heel/foot_index landmarks sit higher (FOOT_LANDMARK_Z).
_SOLE: dict[str, _Linear] = {
    "heel": {"heel_back": (-1.0, 0.0, 0.0), "ankle_height": (0.0, 0.0, -1.0)},
    "toe": {"foot_length": (1.0, 0.0, 0.0), "heel_back": (-1.0, 0.0, 0.0),
            "ankle_height": (0.0, 0.0, -1.0)},
}
JOINT_POINTS: dict[str, tuple[str, _Linear]] = {
    name: (name, {}) if name in SEGMENT_INDEX else (f"{name[0]}_ankle", _SOLE[name[2:]])
    for name in JOINT_NAMES
}
JOINT_PARENTS: tuple[int, ...] = tuple(SEGMENT_INDEX[JOINT_POINTS[n][0]] for n in JOINT_NAMES)


def _matrix(offsets: list[_Linear]) -> np.ndarray:
    """(N, 3, NUM_BONES) matrix M so that offsets = M @ bones."""
    m = np.zeros((len(offsets), 3, NUM_BONES))
    for i, lin in enumerate(offsets):
        for bone, c in lin.items():
            m[i, :, BONE_INDEX[bone]] += c
    return m


# offsets = einsum("nkb,b->nk", M, bones): plain linear maps, so the same arrays serve NumPy
# and JAX (differentiable in the bones).
SEGMENT_OFFSET_MATRIX: np.ndarray = _matrix([s.offset for s in SEGMENTS])  # (17, 3, 13)
LANDMARK_OFFSET_MATRIX: np.ndarray = _matrix([LANDMARK_SITES[n][1] for n in LANDMARK_NAMES])
JOINT_OFFSET_MATRIX: np.ndarray = _matrix([JOINT_POINTS[n][1] for n in JOINT_NAMES])

# Hinge ranges in DOF_NAMES order, radians: (48, 2).
DOF_LIMITS: np.ndarray = np.deg2rad(np.array(
    [lim for s in SEGMENTS[1:] for lim in s.limits_deg], dtype=float))
# Torque limits in DOF_NAMES order at the reference body, N·m: (48,).
DOF_TORQUE: np.ndarray = np.array([s.torque for s in SEGMENTS[1:] for _ in AXES], dtype=float)


def segment_offsets(bones: np.ndarray) -> np.ndarray:
    """Joint positions in their parents' frames for bone lengths (13,) -> (17, 3) metres."""
    return SEGMENT_OFFSET_MATRIX @ np.asarray(bones, dtype=float)


def landmark_offsets(bones: np.ndarray) -> np.ndarray:
    """Landmark sites in their segments' frames for bone lengths (13,) -> (33, 3) metres."""
    return LANDMARK_OFFSET_MATRIX @ np.asarray(bones, dtype=float)


def joint_offsets(bones: np.ndarray) -> np.ndarray:
    """Project joints (JOINT_NAMES) in their segments' frames (13,) -> (21, 3) metres."""
    return JOINT_OFFSET_MATRIX @ np.asarray(bones, dtype=float)


def rest_positions(bones: np.ndarray) -> np.ndarray:
    """Segment origins in the rest pose, pelvis at the origin: (13,) -> (17, 3) metres."""
    off = segment_offsets(bones)
    pos = np.zeros_like(off)
    for i, p in enumerate(PARENTS):
        if p >= 0:
            pos[i] = pos[p] + off[i]
    return pos
