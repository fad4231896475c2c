"""Closed-form inverse kinematics: skeleton pose from 3d landmarks (the fit's initial poses).

Each segment's orientation comes straight from the landmarks: by least squares (Kabsch) where
a segment carries three or more landmarks (head, hands, feet), else from the bone direction
plus a hint for the twist about it (the bend plane of the next joint, the foot or hand, and the
parent's orientation swung onto the bone when the limb is straight). Joint angles are the
relative rotations, decomposed as skeleton.AXES and clipped to the joint limits.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from physpose.fk import angles_from_matrices
from physpose.joints import LANDMARK_INDEX
from physpose.pinhole import rotation_to
from physpose.skeleton import (DOF_LIMITS, LANDMARK_SITES, NUM_DOF, PARENTS, SEGMENT_INDEX,
                               landmark_offsets)

_FACE = ("nose", "left_eye_inner", "left_eye", "left_eye_outer", "right_eye_inner", "right_eye",
         "right_eye_outer", "left_ear", "right_ear", "mouth_left", "mouth_right")
_HAND = ("wrist", "index", "pinky", "thumb")
_FOOT = ("ankle", "heel", "foot_index")
_STRAIGHT_WEIGHT = 0.15  # weight of the swung parent axis against a bend direction (sin angle)
_HINT_WEIGHT = 0.3       # weight of the foot/hand axis in a limb's twist hint


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-9)


def _perp(v: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Component of v (..., 3) perpendicular to the unit axis (..., 3)."""
    return v - np.sum(v * axis, axis=-1, keepdims=True) * axis


def _frame_zx(z: np.ndarray, x_hint: np.ndarray) -> np.ndarray:
    """Rotations (..., 3, 3) with z axis along z and x axis towards x_hint (columns x, y, z)."""
    z = _unit(z)
    x = _unit(_perp(x_hint, z))
    return np.stack([x, np.cross(z, x), z], axis=-1)


def _frame_yz(y: np.ndarray, z_hint: np.ndarray) -> np.ndarray:
    """Rotations with y axis along y and z axis towards z_hint."""
    y = _unit(y)
    z = _unit(_perp(z_hint, y))
    return np.stack([np.cross(y, z), y, z], axis=-1)


def _kabsch(model: np.ndarray, observed: np.ndarray) -> np.ndarray:
    """Rotations R (T, 3, 3) minimising |R model_i - observed_i| over points (centred inside).

    model: (P, 3) points in the segment frame; observed: (T, P, 3).
    """
    a = model - model.mean(axis=0)
    b = observed - observed.mean(axis=1, keepdims=True)
    u, _, vt = np.linalg.svd(np.einsum("pi,tpj->tij", a, b))
    d = np.sign(np.linalg.det(np.einsum("tij,tjk->tik", u, vt)))
    u[:, :, -1] *= d[:, None]
    return np.einsum("tij,tjk->tki", u, vt)


def _swung(parent: np.ndarray, bone_dir: np.ndarray) -> np.ndarray:
    """x axis of the parent frame swung so its -z axis lies along bone_dir (minimal twist)."""
    down = -parent[..., :, 2]
    # Near the antipode (limb pointing straight along +z of the parent) the swing is undefined:
    # swing about the parent's x axis instead by leaving that axis unchanged.
    ok = np.sum(down * bone_dir, axis=-1) > -0.999
    swing = rotation_to(np.where(ok[..., None], down, bone_dir), bone_dir)
    return np.einsum("...ij,...j->...i", swing, parent[..., :, 0])


def _half(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The rotation halfway from a to b (both (T, 3, 3), world from segment)."""
    rel = Rotation.from_matrix(np.einsum("tji,tjk->tik", a, b)).as_rotvec()
    return a @ Rotation.from_rotvec(0.5 * rel).as_matrix()


def _points(lm: np.ndarray, names) -> np.ndarray:
    return lm[:, [LANDMARK_INDEX[n] for n in names]]


def segment_rotations(landmarks: np.ndarray, bones: np.ndarray) -> np.ndarray:
    """World (camera) orientations of the 17 segments from landmarks.

    landmarks: (T, 33, 3) metres, any frame (z need not be up). bones: (13,) skeleton.BONE_NAMES.
    Returns (T, 17, 3, 3), columns = the segment's x (forward), y (left), z (up) axes.
    """
    lm = np.asarray(landmarks, dtype=float)
    at = {n: lm[:, i] for n, i in LANDMARK_INDEX.items()}
    offsets = landmark_offsets(bones)
    site = {n: offsets[LANDMARK_INDEX[n]] for n in LANDMARK_SITES}
    rot = np.zeros((lm.shape[0], len(PARENTS), 3, 3))
    mid_hip = 0.5 * (at["left_hip"] + at["right_hip"])
    mid_shoulder = 0.5 * (at["left_shoulder"] + at["right_shoulder"])
    up = mid_shoulder - mid_hip
    pelvis = _frame_yz(at["left_hip"] - at["right_hip"], up)
    thorax = _frame_yz(at["left_shoulder"] - at["right_shoulder"], up)
    head = _kabsch(np.stack([site[n] for n in _FACE]), _points(lm, _FACE))
    rot[:, SEGMENT_INDEX["pelvis"]] = pelvis
    rot[:, SEGMENT_INDEX["thorax"]] = thorax
    rot[:, SEGMENT_INDEX["spine"]] = _half(pelvis, thorax)
    rot[:, SEGMENT_INDEX["head"]] = head
    rot[:, SEGMENT_INDEX["neck"]] = _half(thorax, head)
    for side, s in (("left", "l"), ("right", "r")):
        p = {n: at[f"{side}_{n}"] for n in ("shoulder", "elbow", "wrist", "hip", "knee",
                                             "ankle")}
        # Feet and hands: least squares on their three or four landmarks.
        foot_model = np.stack([np.zeros(3)] + [site[f"{side}_{n}"] for n in _FOOT[1:]])
        foot = _kabsch(foot_model, np.stack([p["ankle"]] + [at[f"{side}_{n}"]
                                                            for n in _FOOT[1:]], axis=1))
        hand_model = np.stack([np.zeros(3)] + [site[f"{side}_{n}"] for n in _HAND[1:]])
        hand = _kabsch(hand_model, np.stack([p["wrist"]] + [at[f"{side}_{n}"]
                                                            for n in _HAND[1:]], axis=1))
        # Legs: the thigh's x points away from the shank's backward bend, the shank's along
        # the foot.
        thigh_dir = _unit(p["knee"] - p["hip"])
        shank_dir = _unit(p["ankle"] - p["knee"])
        thigh = _frame_zx(-thigh_dir, -_perp(shank_dir, thigh_dir)
                          + _HINT_WEIGHT * _perp(foot[..., 0], thigh_dir)
                          + _STRAIGHT_WEIGHT * _swung(pelvis, thigh_dir))
        shank = _frame_zx(-shank_dir, _perp(foot[..., 0], shank_dir)
                          + _HINT_WEIGHT * _perp(thigh[..., 0], shank_dir))
        # Arms: the upper arm's x points towards the forearm's forward bend; the forearm's
        # twist follows the hand, else the elbow hinge.
        upper_dir = _unit(p["elbow"] - p["shoulder"])
        fore_dir = _unit(p["wrist"] - p["elbow"])
        upper = _frame_zx(-upper_dir, _perp(fore_dir, upper_dir)
                          + _STRAIGHT_WEIGHT * _swung(thorax, upper_dir))
        hinge_x = np.cross(upper[..., 1], -fore_dir)
        fore = _frame_zx(-fore_dir, _perp(hand[..., 0], fore_dir) + _HINT_WEIGHT * hinge_x)
        for seg, r in (("hip", thigh), ("knee", shank), ("ankle", foot), ("shoulder", upper),
                       ("elbow", fore), ("wrist", hand)):
            rot[:, SEGMENT_INDEX[f"{s}_{seg}"]] = r
    return rot


_BRANCH_STEP_WEIGHT = 0.25  # cost of a radian of change between frames (per rad outside limits)
_BRANCH_TOLERANCE = 0.6     # rad, the most the second form may lie outside the limits


def _wrap(angles: np.ndarray) -> np.ndarray:
    return (angles + np.pi) % (2 * np.pi) - np.pi


def _second_form(angles: np.ndarray) -> np.ndarray:
    """(a, b, c) -> (a + pi, pi - b, c + pi), wrapped: the same joint rotation (..., 3)."""
    return _wrap(angles * [1.0, -1.0, 1.0] + np.pi)


def _branches(forms: np.ndarray) -> np.ndarray:
    """Which form of each joint's rotation to use: (T, 16) bool, True for the second form.

    forms: (T, 16, 2, 3), each joint's angles in the first and the second form.

    Ry(a) Rx(b) Rz(c) is also Ry(a + pi) Rx(pi - b) Rz(c + pi). The first form has |b| <= 90
    degrees; only the second is within the limits of a shoulder abducted past the horizontal
    (arms raised overhead). Per joint, the forms are chosen over time (Viterbi, two states) to
    minimise the angles outside the limits plus _BRANCH_STEP_WEIGHT x the change from frame
    to frame. The second form is used only where it is within _BRANCH_TOLERANCE of the limits
    (not for a foot or hand triangle flipped by landmark noise, which no form fits), and only
    where the first stays out of them long enough to pay for the change (not for one frame
    whose twist the landmarks got wrong).
    """
    lo, hi = DOF_LIMITS[:, 0].reshape(-1, 1, 3), DOF_LIMITS[:, 1].reshape(-1, 1, 3)
    outside = (np.maximum(lo - forms, 0.0) + np.maximum(forms - hi, 0.0)).sum(-1)  # (T, J, 2)
    outside[..., 1] = np.where(outside[..., 1] > _BRANCH_TOLERANCE, 1e6, outside[..., 1])
    cost = outside[0]
    back = np.zeros(outside.shape, dtype=int)
    for t in range(1, len(forms)):
        # step[j, previous form, form]
        step = np.abs(_wrap(forms[t][:, None] - forms[t - 1][:, :, None])).sum(-1)
        total = cost[:, :, None] + _BRANCH_STEP_WEIGHT * step
        back[t] = total.argmin(axis=1)
        cost = total.min(axis=1) + outside[t]
    choice = np.zeros(outside.shape[:2], dtype=int)
    choice[-1] = cost.argmin(axis=1)
    for t in range(len(forms) - 1, 0, -1):
        choice[t - 1] = back[t][np.arange(choice.shape[1]), choice[t]]
    return choice.astype(bool)


def angles_from_rotations(rot: np.ndarray) -> np.ndarray:
    """Hinge angles (T, 48), clipped to the joint limits, from segment orientations (T, 17, 3, 3).

    Each joint's rotation is decomposed in the form `_branches` picks (arms raised overhead
    need the second one); where neither form is within the limits (a foot or hand triangle
    flipped by landmark noise), the angles are clipped.
    """
    parents = np.asarray(PARENTS[1:])
    local = np.einsum("tsji,tsjk->tsik", rot[:, parents], rot[:, 1:])
    primary = angles_from_matrices(local).reshape(len(rot), len(PARENTS) - 1, 3)
    if not len(rot):
        return primary.reshape(0, NUM_DOF)
    forms = np.stack([primary, _second_form(primary)], axis=2)  # (T, 16, 2, 3)
    angles = np.where(_branches(forms)[..., None], forms[:, :, 1], forms[:, :, 0])
    return np.clip(angles.reshape(len(rot), NUM_DOF), DOF_LIMITS[:, 0], DOF_LIMITS[:, 1])


def inverse_kinematics(landmarks: np.ndarray, bones: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(root rotations (T, 3, 3), hinge angles (T, 48)) of the skeleton best matching landmarks."""
    rot = segment_rotations(landmarks, bones)
    return rot[:, 0], angles_from_rotations(rot)
