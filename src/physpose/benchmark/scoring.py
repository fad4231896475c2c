"""Score one reconstruction of one clip: the paper's metrics plus the ground-plane estimate.

With ground truth, both motions are compared in the camera's coordinates (a monocular method's
world yaw is arbitrary): the estimate through its own `camera_T_world2cam`, the truth through
the real (or virtual) camera; the metrics then align the first frame's translation. MPJPE-2d
compares the estimate's projection with the truth's projection (with the real camera's lens
distortion), or for real videos with the detections. Plausibility metrics read the estimate in
its own world frame (z up, ground z = 0).
"""

from __future__ import annotations

import cv2
import numpy as np

from physpose.benchmark.material import Clip, Truth
from physpose.joints import joint_confidence, joints_from_landmarks
from physpose.metrics import (CONTACT_PRESETS, camera_height, camera_tilt, evaluate, project,
                             transform_points)
from physpose.reconstruction import Reconstruction

TRUTH_ROW = "(ground truth)"  # the row that scores the truth's own plausibility
MIN_DETECTION_CONFIDENCE = 0.5  # a detected joint counts in the video MPJPE-2d above this
_UP = np.array([0.0, 0.0, 1.0])


def score_clip(clip: Clip, recon: Reconstruction) -> tuple[dict[str, float], dict[str, float]]:
    """(metrics, ground figures) of `recon` on `clip`; keys carry their units."""
    step = clip.score_step  # slowed footage: its frames on the real clock (material.py)
    best = recon.joints("best")
    joints = best[::step]
    # One contact threshold for kinematic and physics output: the paper's -15 mm for dynamics
    # compensates GHUM mesh vertices lying below its box feet; our sole points are the box's
    # own bottom face (skeleton.JOINT_POINTS), so a resting simulated foot sits at about -2 mm
    # and would never count as "in contact" at -15 mm (docs/metrics.md).
    contact = CONTACT_PRESETS["kinematics"]
    est_2d = project(recon.as_filmed(best)[::step], recon.camera_K, recon.camera_T_world2cam)
    if clip.truth is not None:
        metrics = evaluate(joints, clip.truth.joints[::step], fps=recon.fps, contact=contact,
                           T_est2common=recon.camera_T_world2cam,
                           T_gt2common=clip.truth.T_world2cam, est_2d=est_2d,
                           target_2d=project_truth(clip.truth)[::step])
    else:
        kp = np.asarray(clip.observations.keypoints2d)
        target = joints_from_landmarks(kp[..., :2])
        conf = joint_confidence(kp[..., 2])
        weight = (conf >= MIN_DETECTION_CONFIDENCE) & clip.observations.detected[:, None]
        # Without truth, a physics motion's falls are judged against its kinematic input.
        metrics = evaluate(joints, fps=recon.fps, contact=contact, est_2d=est_2d,
                           target_2d=target, confidence_2d=weight.astype(float),
                           fall_reference=recon.joints_kinematic if recon.has_physics else None)
    return metrics, ground_figures(recon.camera_T_world2cam, clip.truth)


def truth_record(clip: Clip) -> dict:
    """The plausibility metrics of a clip's ground truth itself, as a reference row."""
    assert clip.truth is not None
    metrics = evaluate(clip.truth.joints[::clip.score_step], fps=clip.observations.fps,
                       contact=CONTACT_PRESETS["kinematics"])
    return {"variant": TRUTH_ROW, "kind": clip.kind, "clip": clip.name, "source": clip.source,
            "frames": clip.observations.num_frames, "fps": clip.observations.fps,
            "metrics": metrics, "ground": {}, "time_s": {}}


def project_truth(truth: Truth) -> np.ndarray:
    """(T, J, 2) pixels of the true joints in the true camera, lens distortion included."""
    cam = transform_points(truth.T_world2cam, truth.joints)
    uv, _ = cv2.projectPoints(cam.reshape(-1, 3), np.zeros(3), np.zeros(3), truth.K, truth.dist)
    return uv.reshape(cam.shape[:-1] + (2,))


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    cos = a @ b / (np.linalg.norm(a) * np.linalg.norm(b))
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


def ground_figures(T_est_world2cam: np.ndarray, truth: Truth | None) -> dict[str, float]:
    """The estimated ground plane (normal in camera axes, camera height), scored if truth exists.

    camera_tilt_deg: angle between the estimated up direction and the image's up axis (-y).
    """
    normal = T_est_world2cam[:3, :3] @ _UP
    height = camera_height(T_est_world2cam)
    out = {"camera_height_m": height, "camera_tilt_deg": camera_tilt(T_est_world2cam)}
    if truth is not None:
        true_height = camera_height(truth.T_world2cam)
        out.update(normal_angle_error_deg=_angle_deg(normal, truth.T_world2cam[:3, :3] @ _UP),
                   camera_height_true_m=true_height,
                   camera_height_error_pct=100.0 * abs(height - true_height) / true_height)
    return out
