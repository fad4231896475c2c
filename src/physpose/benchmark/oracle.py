"""Diagnostic variants fed the ground truth itself (motion capture with `--truth-input` only).

``truth-ik`` puts the recorded motion onto physpose's body: bone lengths measured on the
truth's 33 synthesised landmarks, then inverse kinematics of those landmarks. What it scores
is the body's own representation error. ``dynamics-truth`` runs the trajectory optimisation
(default preset) with that motion as its kinematic input, so what it loses is the physics
stage's own error, not the estimate's. ``truth-reference`` is what ``dynamics-truth`` is asked
to follow: that motion on the floor, its standing feet laid flat and low-passed (no physics), so
the two split the physics stage's loss into its preparation and its simulation. Combine with
``--noiseless`` to give the image term clean detections too. These are oracles: they answer
"how well can this body and search follow a motion a person really made", they are not
estimators.
"""

from __future__ import annotations

import time

import numpy as np
from scipy.spatial.transform import Rotation

from physpose.benchmark.variants import VariantContext, register_variant
from physpose.errors import PhysposeError
from physpose.fk import fk, fk_qpos
from physpose.joints import JOINT_NAMES, LANDMARK_NAMES
from physpose.kinematics.ik import inverse_kinematics
from physpose.kinematics.result import KinematicFit
from physpose.observations import Observations
from physpose.reconstruction import Reconstruction
from physpose.shape import BodyShape, bone_lengths_from_landmarks


SOLE_JOINTS = ("l_heel", "r_heel", "l_toe", "r_toe")  # the body's sole points
FOOT_LANDMARKS = ("left_heel", "right_heel", "left_foot_index", "right_foot_index")
STANCE_HEIGHT = 0.03  # m: the truth's lowest foot point under this stands (the floor's level)


def truth_on_body(landmarks: np.ndarray, fps: float, camera_K: np.ndarray,
                  T_world2cam: np.ndarray, mass: float | None = None) -> KinematicFit:
    """The motion of world landmarks (T, 33, 3) as a kinematic fit of physpose's body.

    The shape comes from bone lengths measured on the landmarks (mass from the stature's
    average build when None); the pose from inverse kinematics, root placed where it best
    matches the landmarks (median offset over the 33).

    The fit's floor is where the body's soles stand as the truth's stand on its own. The
    detector simulator puts the heel and foot-index landmarks on the recorded soles, while the
    body's sit a quarter of its ankle height above its soles (skeleton.FOOT_LANDMARK_Z), so the
    body that matches those landmarks reaches about a third of its ankle height further down
    (1-5 cm into the truth's floor on the motion-capture clips). And a recording's floor is
    not exactly at z = 0: on the CMU clips its standing feet reach about 1 cm into it. The fit's
    world is therefore moved down by the median over frames of how much lower the body's
    lowest sole point is than the truth's lowest foot point, plus the median height of the
    truth's lowest foot point where it stands (under STANCE_HEIGHT), and its camera with it:
    every point stays where it was in the camera, and the body stands on the floor where the
    recorded feet stood.
    """
    shape = BodyShape.from_bone_lengths(bone_lengths_from_landmarks(landmarks), mass=mass)
    bones = shape.bones()
    root_rot, angles = inverse_kinematics(landmarks, bones)
    _, relative = fk(bones, np.zeros((len(landmarks), 3)), root_rot, angles)
    root_pos = np.median(landmarks - np.asarray(relative), axis=1)
    quat_wxyz = Rotation.from_matrix(root_rot).as_quat()[:, [3, 0, 1, 2]]
    qpos = np.concatenate([root_pos, quat_wxyz, angles], axis=1)
    joints, sites = fk_qpos(bones, qpos)
    sole = [JOINT_NAMES.index(n) for n in SOLE_JOINTS]
    feet = [LANDMARK_NAMES.index(n) for n in FOOT_LANDMARKS]
    truth_low = landmarks[:, feet, 2].min(axis=1)
    standing = truth_low[truth_low < STANCE_HEIGHT]
    floor = float(np.median(joints[:, sole, 2].min(axis=1) - truth_low)
                  + (np.median(standing) if len(standing) else 0.0))
    for points in (qpos[:, :3], joints, sites):  # a translation: every point moves with the root
        points[..., 2] -= floor
    T_world2cam = np.asarray(T_world2cam, float).copy()
    T_world2cam[:3, 3] += T_world2cam[:3, :3] @ np.array([0.0, 0.0, floor])
    return KinematicFit(fps=fps, shape=shape, qpos=qpos, joints=joints, landmarks=sites,
                        camera_K=np.asarray(camera_K, float),
                        T_world2cam=T_world2cam, variant="truth",
                        ground_estimated=False)


def _timed_truth_fit(obs: Observations, context: VariantContext, name: str
                     ) -> tuple[KinematicFit, float]:
    """The truth put onto the body (`truth_on_body`) for variant ``name``, and the seconds it
    took (as dynamics.variants._timed_fit gives the estimate's)."""
    if context.truth_landmarks is None or context.camera_K is None \
            or context.truth_T_world2cam is None:
        raise PhysposeError(f"variant {name} needs the ground truth, which this clip does not "
                            "give variants", path=obs.source,
                            remedy="run it on motion capture with --truth-input")
    start = time.perf_counter()
    kin = truth_on_body(context.truth_landmarks, obs.fps, context.camera_K,
                        context.truth_T_world2cam)
    return kin, time.perf_counter() - start


def truth_ik_variant(obs: Observations, context: VariantContext) -> Reconstruction:
    """The truth, put onto the body by inverse kinematics (no physics)."""
    kin, kinematics_s = _timed_truth_fit(obs, context, "truth-ik")
    recon = kin.to_reconstruction(obs)
    meta = dict(recon.meta, variant="truth-ik", timings_s={"kinematics": kinematics_s})
    return recon.replace(meta=meta)


def dynamics_truth_variant(obs: Observations, context: VariantContext) -> Reconstruction:
    """The trajectory optimisation (default preset) following the truth put onto the body."""
    from physpose.dynamics.config import PRESETS  # noqa: PLC0415 (keeps the registry light)
    from physpose.dynamics.variants import simulate_fit  # noqa: PLC0415

    kin, kinematics_s = _timed_truth_fit(obs, context, "dynamics-truth")
    return simulate_fit(kin, kinematics_s, obs, context, PRESETS["fast"], "dynamics-truth")


def truth_reference_variant(obs: Observations, context: VariantContext) -> Reconstruction:
    """The truth on the body as the default preset's windows are asked to follow it."""
    from physpose.dynamics.config import PRESETS  # noqa: PLC0415 (keeps the registry light)
    from physpose.dynamics.variants import reference_fit  # noqa: PLC0415

    kin, kinematics_s = _timed_truth_fit(obs, context, "truth-reference")
    return reference_fit(kin, kinematics_s, obs, PRESETS["fast"], "truth-reference")


register_variant("truth-ik", truth_ik_variant)
register_variant("truth-reference", truth_reference_variant)
register_variant("dynamics-truth", dynamics_truth_variant)
