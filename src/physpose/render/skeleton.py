"""The stick skeleton of the project's joints, and the feet's heights and ground contacts."""

from __future__ import annotations

import numpy as np

from physpose.joints import JOINT_NAMES

# Parent of every joint in JOINT_NAMES (the pelvis is the root).
JOINT_PARENTS: dict[str, str | None] = {
    "pelvis": None, "spine": "pelvis", "thorax": "spine", "neck": "thorax", "head": "neck",
    "l_hip": "pelvis", "r_hip": "pelvis", "l_knee": "l_hip", "r_knee": "r_hip",
    "l_ankle": "l_knee", "r_ankle": "r_knee", "l_heel": "l_ankle", "r_heel": "r_ankle",
    "l_toe": "l_ankle", "r_toe": "r_ankle",
    "l_shoulder": "thorax", "r_shoulder": "thorax", "l_elbow": "l_shoulder",
    "r_elbow": "r_shoulder", "l_wrist": "l_elbow", "r_wrist": "r_elbow",
}
# (child, parent) pairs drawn as bones, plus the sole of each foot.
JOINT_EDGES: tuple[tuple[str, str], ...] = tuple(
    (c, p) for c, p in JOINT_PARENTS.items() if p is not None) + (("l_heel", "l_toe"),
                                                                   ("r_heel", "r_toe"))
FEET: dict[str, tuple[str, ...]] = {"left": ("l_heel", "l_toe"), "right": ("r_heel", "r_toe")}
CONTACT_HEIGHT = 0.03  # m: a foot whose lowest point is below this height touches the ground


def edge_indices(joint_names: tuple[str, ...] = JOINT_NAMES) -> np.ndarray:
    """(E, 2) index pairs into joint_names for JOINT_EDGES whose joints are both present."""
    index = {n: i for i, n in enumerate(joint_names)}
    return np.array([(index[a], index[b]) for a, b in JOINT_EDGES if a in index and b in index],
                    dtype=int).reshape(-1, 2)


def lowest_foot_points(joints: np.ndarray,
                       joint_names: tuple[str, ...] = JOINT_NAMES) -> np.ndarray:
    """The lowest joint of each foot (heel or toe): where it meets the ground.

    joints: (T, J, 3) world, metres -> (T, 2, 3), feet in FEET order (left, right).
    """
    index = {n: i for i, n in enumerate(joint_names)}
    feet = []
    for names in FEET.values():
        pts = joints[:, [index[n] for n in names]]                 # (T, k, 3)
        low = np.argmin(pts[..., 2], axis=1)
        feet.append(pts[np.arange(len(pts)), low])
    return np.stack(feet, axis=1)


def foot_heights(joints: np.ndarray, joint_names: tuple[str, ...] = JOINT_NAMES) -> np.ndarray:
    """Height above the ground (z = 0) of each foot's lowest joint: (T, J, 3) -> (T, 2) m."""
    return lowest_foot_points(joints, joint_names)[..., 2]


def foot_contacts(heights: np.ndarray, threshold: float = CONTACT_HEIGHT) -> np.ndarray:
    """(T, 2) bool: the foot is in contact with the ground (heights from `foot_heights`)."""
    return np.asarray(heights) < threshold
