"""Names shared by every stage: the project's joints and MediaPipe's 33 pose landmarks."""

from __future__ import annotations

import numpy as np

# The joints every output carries (../shared/DESIGN.md), in this order.
JOINT_NAMES: tuple[str, ...] = (
    "pelvis", "spine", "thorax", "neck", "head",
    "l_hip", "r_hip", "l_knee", "r_knee", "l_ankle", "r_ankle",
    "l_heel", "r_heel", "l_toe", "r_toe",
    "l_shoulder", "r_shoulder", "l_elbow", "r_elbow", "l_wrist", "r_wrist",
)
JOINT_INDEX: dict[str, int] = {name: i for i, name in enumerate(JOINT_NAMES)}

# MediaPipe Pose landmark order (index = position in the tuple).
LANDMARK_NAMES: tuple[str, ...] = (
    "nose",
    "left_eye_inner", "left_eye", "left_eye_outer",
    "right_eye_inner", "right_eye", "right_eye_outer",
    "left_ear", "right_ear", "mouth_left", "mouth_right",
    "left_shoulder", "right_shoulder", "left_elbow", "right_elbow",
    "left_wrist", "right_wrist", "left_pinky", "right_pinky",
    "left_index", "right_index", "left_thumb", "right_thumb",
    "left_hip", "right_hip", "left_knee", "right_knee",
    "left_ankle", "right_ankle", "left_heel", "right_heel",
    "left_foot_index", "right_foot_index",
)
LANDMARK_INDEX: dict[str, int] = {name: i for i, name in enumerate(LANDMARK_NAMES)}
NUM_LANDMARKS = len(LANDMARK_NAMES)  # 33

# Pairs drawn in overlays (MediaPipe's own skeleton topology, by name).
LANDMARK_EDGES: tuple[tuple[str, str], ...] = (
    ("left_shoulder", "right_shoulder"), ("left_hip", "right_hip"),
    ("left_shoulder", "left_hip"), ("right_shoulder", "right_hip"),
    ("left_shoulder", "left_elbow"), ("left_elbow", "left_wrist"),
    ("right_shoulder", "right_elbow"), ("right_elbow", "right_wrist"),
    ("left_wrist", "left_index"), ("left_wrist", "left_pinky"), ("left_wrist", "left_thumb"),
    ("right_wrist", "right_index"), ("right_wrist", "right_pinky"), ("right_wrist", "right_thumb"),
    ("left_hip", "left_knee"), ("left_knee", "left_ankle"),
    ("right_hip", "right_knee"), ("right_knee", "right_ankle"),
    ("left_ankle", "left_heel"), ("left_heel", "left_foot_index"), ("left_ankle", "left_foot_index"),
    ("right_ankle", "right_heel"), ("right_heel", "right_foot_index"),
    ("right_ankle", "right_foot_index"),
    ("nose", "left_eye"), ("nose", "right_eye"), ("left_eye", "left_ear"),
    ("right_eye", "right_ear"), ("mouth_left", "mouth_right"),
)

# Joints that MediaPipe observes directly: project joint -> landmark name.
_DIRECT = {
    "l_hip": "left_hip", "r_hip": "right_hip", "l_knee": "left_knee", "r_knee": "right_knee",
    "l_ankle": "left_ankle", "r_ankle": "right_ankle", "l_heel": "left_heel",
    "r_heel": "right_heel", "l_toe": "left_foot_index", "r_toe": "right_foot_index",
    "l_shoulder": "left_shoulder", "r_shoulder": "right_shoulder", "l_elbow": "left_elbow",
    "r_elbow": "right_elbow", "l_wrist": "left_wrist", "r_wrist": "right_wrist",
}


def joints_from_landmarks(landmarks: np.ndarray) -> np.ndarray:
    """Project joints from MediaPipe landmarks (works for 2d or 3d points).

    The trunk and head joints have no landmark of their own; they are proxies: pelvis = mid-hips,
    thorax = mid-shoulders, spine = midway pelvis-thorax, head = mid-ears, neck = midway
    thorax-head.

    landmarks: (..., 33, D) -> joints: (..., len(JOINT_NAMES), D)
    """
    lm = np.asarray(landmarks, dtype=float)
    if lm.shape[-2] != NUM_LANDMARKS:
        raise ValueError(f"expected {NUM_LANDMARKS} landmarks on axis -2, got shape {lm.shape}")

    def at(name: str) -> np.ndarray:
        return lm[..., LANDMARK_INDEX[name], :]

    pelvis = 0.5 * (at("left_hip") + at("right_hip"))
    thorax = 0.5 * (at("left_shoulder") + at("right_shoulder"))
    head = 0.5 * (at("left_ear") + at("right_ear"))
    derived = {
        "pelvis": pelvis, "thorax": thorax, "head": head,
        "spine": 0.5 * (pelvis + thorax), "neck": 0.5 * (thorax + head),
    }
    return np.stack([derived[n] if n in derived else at(_DIRECT[n]) for n in JOINT_NAMES], axis=-2)


def joint_confidence(confidence: np.ndarray) -> np.ndarray:
    """Per-joint detection confidence from the landmarks': (..., 33) -> (..., len(JOINT_NAMES)).

    A joint observed directly has its landmark's; a proxy placed between landmarks (pelvis,
    spine, thorax, neck, head) has the least of theirs: a pelvis is as sure as its less sure hip.
    """
    conf = np.asarray(confidence, dtype=float)
    if conf.shape[-1] != NUM_LANDMARKS:
        raise ValueError(f"expected {NUM_LANDMARKS} confidences on the last axis, got {conf.shape}")
    uses = joints_from_landmarks(np.eye(NUM_LANDMARKS)[..., None])[..., 0].T > 0   # (J, 33)
    return np.where(uses, conf[..., None, :], np.inf).min(axis=-1)
