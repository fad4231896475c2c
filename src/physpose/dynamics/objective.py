"""The trajectory objective of one window: named terms, weights under the same names.

Each term is a function ``_cost_<name>(samples, ref, frames, history) -> (B,)`` of a batch of
simulated windows sampled at the frame times; the total is ``sum(w[name] * cost[name])``.
Frame 0 of a window is its starting state (the same for every sample); terms average over the
window's other frames, so their values do not grow with the window's length (the paper sums
over frames; with one window length that is the same up to a constant factor). Units:

- ``com`` (paper eq. 1): |c - c_k|^2 + |c' - c'_k|^2, centre of mass (m) and its velocity (m/s,
  finite differences over frames) against the kinematic estimate's (the velocity target from
  the low-passed estimate, see `make_reference`).
- ``pose`` (eq. 2): sum over the 16 joints and the root of arccos |<q, q_k>| (rad, half the
  rotation angle between simulated and kinematic joint rotations).
- ``reprojection`` (eq. 3): mean over the 33 landmarks of confidence x image distance (px)
  between the projected landmark site and the detection, converted to metres at the person's
  depth (x depth / focal length, per frame). The paper sums raw pixels, whose size depends on
  the camera and the person's distance; per landmark and in metres the weighted term has the
  magnitude of the others, as the paper's tuning intended ("roughly equal magnitudes").
- ``prior`` (stands in for eq. 4, the normalising-flow pose prior, which is not available):
  |z| / sqrt(48) (the RMS z, so its size is that of one hinge's z) with z = (angle - neutral) / spread per hinge, a diagonal Gaussian pose prior whose mean
  is the upright neutral pose and whose standard deviation is a quarter of each hinge's
  anatomical range (so the range is the prior's +-2 sigma band; narrow secondary axes such as
  knee ab/adduction are held tightly). Like the flow prior's |z| it is small for ordinary poses
  and grows for contorted ones. Left and right sides get the same (mirrored) prior.
- ``tv`` (eq. 5): (1/J) sum_j |a_t - a_{t-1}|_1 over the 21 project joints, accelerations a
  (m/s^2) by second differences over frames, x TV_SCALE.
- ``lim``: sum over hinges of exp(excess / LIMIT_SOFTNESS) - 1, where excess (rad) is how far
  an angle lies outside its joint range (0 inside).
- ``swing`` (physpose's addition, not in the paper: weight 0 in its defaults): for each foot
  the reference lifts into swing (its heel and toe landmarks both more than SWING_HEIGHT above
  their heights in the standing pose), the mean distance (m) of the simulated ankle, heel and
  toe landmarks to the reference's; the horizontal part relative to the root, so the term
  shapes the step and not where the body is, the vertical part absolute, so the foot lifts and
  lands when the estimate's does. Summed over the feet, averaged over frames; with
  ``make_reference(swing_confidence=True)`` each foot-frame is weighted by the detections' mean
  confidence of that foot's ankle, heel and toe (a step the detector barely sees is asked for
  less). Standing feet are left to the simulation: the estimate's standing feet slide, and
  following them would slide the simulated ones (docs/dynamics.md, Swing feet).

A sample whose simulation broke, whose root strays more than ``max_root_distance`` from the
kinematic root, or that sinks a landmark more than ``max_penetration`` below the floor scores
+inf (`invalid_from` tells from which frame on, for ranking failures among themselves).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import mujoco
import numpy as np

from physpose.dynamics import quat
from physpose.dynamics.rollout import FrameSamples
from physpose.errors import check_field
from physpose.fk import site_positions
from physpose.joints import LANDMARK_NAMES
from physpose.metrics import transform_points
from physpose.skeleton import DOF_LIMITS, NUM_JOINTS3

TERMS: tuple[str, ...] = ("com", "pose", "reprojection", "prior", "tv", "lim", "swing")
TV_SCALE = 0.1             # the TV term's unit: 10 m/s^2 of acceleration change per frame -> 1
LIMIT_SOFTNESS = 0.05      # rad: the limit penalty grows e-fold per this much excess
_PRIOR_MEAN = np.clip(0.0, DOF_LIMITS[:, 0], DOF_LIMITS[:, 1])   # (48,) rad
_PRIOR_STD = (DOF_LIMITS[:, 1] - DOF_LIMITS[:, 0]) / 4.0         # (48,) rad
MIN_DEPTH = 0.1            # m: landmarks closer to the camera than this are projected at it
SWING_HEIGHT = 0.04        # m above standing: a reference foot this high is in swing
# Landmark indices of each foot (left, right): ankle, heel, toe.
FOOT_LANDMARKS = tuple(tuple(LANDMARK_NAMES.index(f"{side}_{part}")
                             for part in ("ankle", "heel", "foot_index"))
                       for side in ("left", "right"))


@dataclass(frozen=True)
class ObjectiveWeights:
    """Weight of each objective term (the paper's defaults); 0 removes the term (ablations)."""

    com: float = 15.0
    pose: float = 0.5
    reprojection: float = 4.0
    prior: float = 1.0
    tv: float = 1.0
    lim: float = 1.0
    swing: float = 0.0

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            check_field(self, f.name, np.isfinite(value) and value >= 0,
                        "finite and >= 0 (0 switches the term off)")

    def as_dict(self) -> dict[str, float]:
        return {name: float(getattr(self, name)) for name in TERMS}


@dataclass(frozen=True, eq=False)
class ObjectiveReference:
    """What the simulated motion is scored against, per frame of the clip (T frames).

    qpos (T, 55) kinematic estimate; quats (T, 17, 4) its root and joint rotations (w,x,y,z);
    com (T, 3) m; com_velocity (T-1, 3) m/s between consecutive frames; keypoints2d (T, 33, 3) px + confidence; camera_K (3, 3);
    T_world2cam (4, 4); metres_per_px (T,) at the kinematic root's depth; fps Hz.
    feet (T, 2, 3, 3) m: each foot's ankle, heel and toe landmarks (FOOT_LANDMARKS), x and y
    relative to the root; swing (T, 2): the ``swing`` term's weight of each foot, 0 where it
    stands, 1 (or the detections' confidence in it) where it is in swing.
    camera_travel (T, 3) m: where the camera travelled with the person (travel.py), how far it
    had moved by each frame; the ``reprojection`` term sees the simulated body moved back by
    it. None for a still camera.
    """

    qpos: np.ndarray
    quats: np.ndarray
    com: np.ndarray
    com_velocity: np.ndarray
    keypoints2d: np.ndarray
    camera_K: np.ndarray
    T_world2cam: np.ndarray
    metres_per_px: np.ndarray
    fps: float
    feet: np.ndarray
    swing: np.ndarray
    camera_travel: np.ndarray | None = None


def joint_quaternions(qpos: np.ndarray) -> np.ndarray:
    """Root and joint rotations (..., 17, 4) from qpos (..., 55); joints R = Ry(a) Rx(b) Rz(c)."""
    ang = qpos[..., 7:].reshape(qpos.shape[:-1] + (NUM_JOINTS3, 3))
    joints = quat.multiply(quat.multiply(quat.about_axis(ang[..., 0], 1),
                                         quat.about_axis(ang[..., 1], 0)),
                           quat.about_axis(ang[..., 2], 2))
    root = quat.normalised(qpos[..., 3:7])
    return np.concatenate([root[..., None, :], joints], axis=-2)


def landmark_sites(model: mujoco.MjModel, qpos: np.ndarray) -> np.ndarray:
    """World positions (T, 33, 3) m of the landmark sites for qpos (T, 55)."""
    ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, name) for name in LANDMARK_NAMES]
    return site_positions(model, ids, qpos)


def root_relative_feet(landmarks: np.ndarray, qpos: np.ndarray) -> np.ndarray:
    """Feet (..., 2, 3, 3) from landmarks (..., 33, 3): x and y relative to the root qpos[:2]."""
    feet = np.stack([landmarks[..., list(foot), :] for foot in FOOT_LANDMARKS], axis=-3)
    feet[..., :2] -= qpos[..., None, None, :2]
    return feet


def standing_heights(model: mujoco.MjModel) -> np.ndarray:
    """(33,) m: the landmark sites' heights in the model's standing pose (keyframe
    "standing", feet on the floor)."""
    key = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_KEY, "standing")
    if key < 0:
        raise ValueError("the body model has no 'standing' keyframe (build it with build_body)")
    return landmark_sites(model, model.key_qpos[key][None])[0, :, 2]


def swing_mask(model: mujoco.MjModel, landmarks: np.ndarray) -> np.ndarray:
    """(T, 2) bool: each foot's heel and toe (landmarks (T, 33, 3)) are both more than
    SWING_HEIGHT above their heights in the model's standing pose (`standing_heights`)."""
    lifted = landmarks[..., 2] - standing_heights(model) > SWING_HEIGHT  # (T, 33)
    return np.stack([lifted[:, heel] & lifted[:, toe] for _, heel, toe in FOOT_LANDMARKS], axis=-1)


def swing_weights(swing: np.ndarray, keypoints2d: np.ndarray | None) -> np.ndarray:
    """(T, 2) the ``swing`` term's weights: the swing mask (T, 2) as 0/1, times the mean
    detection confidence of each foot's ankle, heel and toe (keypoints2d (T, 33, 3)) if given."""
    weights = np.asarray(swing, dtype=float)
    if keypoints2d is None:
        return weights
    kp = np.asarray(keypoints2d, dtype=float)
    confidence = np.stack([kp[:, list(foot), 2].mean(axis=-1) for foot in FOOT_LANDMARKS], -1)
    return weights * np.clip(confidence, 0.0, 1.0)


def centre_of_mass(model: mujoco.MjModel, qpos: np.ndarray) -> np.ndarray:
    """Whole-body centre of mass (T, 3) m for qpos (T, 55)."""
    data = mujoco.MjData(model)
    out = np.empty((len(qpos), 3))
    for t, q in enumerate(qpos):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        out[t] = data.subtree_com[1]
    return out


def make_reference(model: mujoco.MjModel, qpos: np.ndarray, keypoints2d: np.ndarray,
                   camera_K: np.ndarray, T_world2cam: np.ndarray, fps: float,
                   smooth_qpos: np.ndarray | None = None,
                   camera_travel: np.ndarray | None = None,
                   swing_confidence: bool = False) -> ObjectiveReference:
    """The per-frame targets from a kinematic estimate qpos (T, 55) and its detections.

    smooth_qpos (T, 55): a low-passed estimate whose centre of mass gives the velocity target
    (finite differences of a jittery estimate's COM would ask the body to jitter); default qpos.
    camera_travel (T, 3): see ObjectiveReference (qpos is then the motion in the world, and
    T_world2cam the camera where it stood at frame 0).
    swing_confidence: weight each swing foot-frame by the detections' mean confidence of the
    foot's ankle, heel and toe (`swing_weights`).
    """
    smooth_com = centre_of_mass(model, qpos if smooth_qpos is None else smooth_qpos)
    filmed_root = qpos[:, :3] if camera_travel is None else qpos[:, :3] - camera_travel
    depth = transform_points(T_world2cam, filmed_root)[:, 2]
    focal = 0.5 * (camera_K[0, 0] + camera_K[1, 1])
    landmarks = landmark_sites(model, qpos)
    swing = swing_weights(swing_mask(model, landmarks), keypoints2d if swing_confidence else None)
    return ObjectiveReference(
        qpos=np.asarray(qpos, dtype=float), quats=joint_quaternions(qpos),
        com=centre_of_mass(model, qpos), com_velocity=np.diff(smooth_com, axis=0) * fps,
        keypoints2d=np.asarray(keypoints2d, dtype=float),
        camera_K=np.asarray(camera_K, dtype=float), T_world2cam=np.asarray(T_world2cam, dtype=float),
        metres_per_px=np.maximum(depth, MIN_DEPTH) / focal, fps=float(fps),
        feet=root_relative_feet(landmarks, qpos), swing=swing,
        camera_travel=None if camera_travel is None else np.asarray(camera_travel, dtype=float))


def _cost_com(s: FrameSamples, ref: ObjectiveReference, frames: np.ndarray, history) -> np.ndarray:
    pos = np.sum((s.com[:, 1:] - ref.com[frames[1:]]) ** 2, axis=-1).mean(axis=1)
    vel = np.diff(s.com, axis=1) * ref.fps
    vel_k = ref.com_velocity[frames[:-1]]
    return pos + np.sum((vel - vel_k) ** 2, axis=-1).mean(axis=1)


def _cost_pose(s: FrameSamples, ref: ObjectiveReference, frames: np.ndarray, history
               ) -> np.ndarray:
    angle = quat.half_angle(ref.quats[frames[1:]], joint_quaternions(s.qpos[:, 1:]))
    return angle.sum(axis=-1).mean(axis=1)


def project(points: np.ndarray, K: np.ndarray, T_world2cam: np.ndarray) -> np.ndarray:
    """Pinhole projection (..., 3) world -> (..., 2) px, depth clamped at MIN_DEPTH."""
    return pinhole(transform_points(T_world2cam, points), K)


def pinhole(cam: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Camera-frame points (..., 3) -> (..., 2) px, depth clamped at MIN_DEPTH."""
    z = np.maximum(cam[..., 2:3], MIN_DEPTH)
    return (cam[..., :2] / z) @ K[:2, :2].T + K[:2, 2]


def _cost_reprojection(s: FrameSamples, ref: ObjectiveReference, frames: np.ndarray, history
                       ) -> np.ndarray:
    landmarks = s.landmarks[:, 1:]
    if ref.camera_travel is not None:  # the simulated body as the travelling camera saw it
        landmarks = landmarks - ref.camera_travel[frames[1:], None, :]
    uv = project(landmarks, ref.camera_K, ref.T_world2cam)
    kp = ref.keypoints2d[frames[1:]]
    dist = np.linalg.norm(uv - kp[..., :2], axis=-1)  # (B, F-1, 33) px
    per_frame = np.mean(kp[..., 2] * dist, axis=-1) * ref.metres_per_px[frames[1:]]
    return per_frame.mean(axis=1)


def _cost_prior(s: FrameSamples, ref: ObjectiveReference, frames: np.ndarray, history
                ) -> np.ndarray:
    z = (s.qpos[:, 1:, 7:] - _PRIOR_MEAN) / _PRIOR_STD
    return np.linalg.norm(z, axis=-1).mean(axis=1) / np.sqrt(z.shape[-1])


def _cost_tv(s: FrameSamples, ref: ObjectiveReference, frames: np.ndarray, history
             ) -> np.ndarray:
    x = s.joints
    if history is not None and len(history):
        x = np.concatenate([np.broadcast_to(history, (len(x),) + history.shape), x], axis=1)
    if x.shape[1] < 4:
        return np.zeros(len(x))
    acc = (x[:, 2:] - 2 * x[:, 1:-1] + x[:, :-2]) * ref.fps ** 2
    tv = np.abs(np.diff(acc, axis=1)).sum(axis=-1).mean(axis=-1)  # (B, F'): (1/J) sum_j L1
    return TV_SCALE * tv.mean(axis=1)


def _cost_lim(s: FrameSamples, ref: ObjectiveReference, frames: np.ndarray, history
              ) -> np.ndarray:
    angles = s.qpos[:, 1:, 7:]
    excess = np.maximum(angles - DOF_LIMITS[:, 1], 0.0) + np.maximum(DOF_LIMITS[:, 0] - angles, 0.0)
    return np.expm1(excess / LIMIT_SOFTNESS).sum(axis=-1).mean(axis=1)


def _cost_swing(s: FrameSamples, ref: ObjectiveReference, frames: np.ndarray, history
                ) -> np.ndarray:
    feet = root_relative_feet(s.landmarks[:, 1:], s.qpos[:, 1:])  # (B, F-1, 2, 3, 3)
    dist = np.linalg.norm(feet - ref.feet[frames[1:]], axis=-1).mean(axis=-1)  # (B, F-1, 2)
    return (dist * ref.swing[frames[1:]]).sum(axis=-1).mean(axis=1)


_COSTS = {name: globals()[f"_cost_{name}"] for name in TERMS}


def evaluate_terms(samples: FrameSamples, ref: ObjectiveReference, frames: np.ndarray,
                   history: np.ndarray | None = None,
                   weights: ObjectiveWeights | None = None) -> dict[str, np.ndarray]:
    """Every term (B,) of a batch sampled at clip frames (F,) (frames[0] = the start state).

    history: (H, 21, 3) simulated joints of the H frames before frames[0] (for the TV term).
    Terms with weight 0 in ``weights`` are skipped (reported as 0).
    """
    frames = np.asarray(frames, dtype=int)
    out = {}
    for name, fn in _COSTS.items():
        if weights is not None and getattr(weights, name) == 0:
            out[name] = np.zeros(samples.qpos.shape[0])
        else:
            out[name] = fn(samples, ref, frames, history)
    return out


def invalid_from(samples: FrameSamples, ref: ObjectiveReference, frames: np.ndarray,
                 max_root_distance: float, max_penetration: float) -> np.ndarray:
    """(B,) the first frame index (within the window) at which a sample left the valid
    state space, or F when it never did."""
    far = np.linalg.norm(samples.qpos[..., :3] - ref.qpos[frames, :3], axis=-1) > max_root_distance
    sunk = samples.landmarks[..., 2].min(axis=-1) < -max_penetration
    bad = samples.broken | far | sunk | ~np.isfinite(samples.qpos).all(axis=-1)
    first = np.where(bad.any(axis=1), bad.argmax(axis=1), bad.shape[1])
    return first


def total(terms: dict[str, np.ndarray], weights: ObjectiveWeights) -> np.ndarray:
    """Weighted sum (B,) of the terms."""
    return sum(getattr(weights, name) * terms[name] for name in TERMS)
