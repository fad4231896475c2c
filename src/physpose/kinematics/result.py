"""`KinematicFit`: the kinematic stage's result, the dynamics stage's input."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from physpose.observations import Observations
from physpose.reconstruction import Reconstruction
from physpose.shape import BodyShape


@dataclass(frozen=True, eq=False)
class KinematicFit:
    """Per-frame body pose in the world frame (z up, ground z = 0), with the camera and shape."""

    fps: float                   # Hz, rate of the per-frame arrays (= the observations' rate)
    shape: BodyShape             # time-consistent body shape (+S)
    qpos: np.ndarray             # (T, 55) skeleton qpos layout: root pos, root quat wxyz, 48 hinges
    joints: np.ndarray           # (T, 21, 3) JOINT_NAMES, metres
    landmarks: np.ndarray        # (T, 33, 3) landmark sites (MediaPipe order), metres
    camera_K: np.ndarray         # (3, 3) intrinsics used (given or estimated)
    T_world2cam: np.ndarray      # (4, 4) world -> OpenCV camera
    variant: str                 # "S", "SO", "SO+G", "SO+T" or "SO+GT"
    ground_estimated: bool       # True when T_g was fitted (+G); else a level-camera guess
    losses: dict = dataclasses.field(default_factory=dict)   # final value of each loss term
    support_heights: np.ndarray | None = None  # (T,) m, the raised support's top the feet were
                                 # stood on in each frame (0: the floor); None: no raised feet
    timings: dict = dataclasses.field(default_factory=dict)  # seconds per sub-step
    label_exchanges: dict | None = None  # limb group -> [first, last] frames the swap repair
                                 # kept exchanged for 0.5 s or more; None: not recorded

    @property
    def num_frames(self) -> int:
        return int(self.qpos.shape[0])

    def to_reconstruction(self, obs: Observations, body_mjcf: str | None = None) -> Reconstruction:
        """The reconstruction.npz contract with the physics fields absent."""
        from physpose.joints import JOINT_NAMES

        return Reconstruction(
            fps=self.fps, joint_names=JOINT_NAMES, joints_kinematic=self.joints,
            camera_K=self.camera_K, camera_T_world2cam=self.T_world2cam,
            landmarks_kinematic=self.landmarks, keypoints2d=obs.keypoints2d,
            qpos_kinematic=self.qpos, body_mjcf=body_mjcf,
            meta={"source": obs.source, "variant": self.variant,
                  "frame_indices": None if obs.frame_indices is None
                  else np.asarray(obs.frame_indices).tolist(),
                  "timestamps": np.round(np.asarray(obs.timestamps, dtype=float), 6).tolist(),
                  "detected": np.asarray(obs.detected, dtype=bool).tolist(),
                  "image_size": [int(v) for v in obs.image_size],
                  "camera_homographies": None if obs.homographies is None
                  else np.round(np.asarray(obs.homographies), 9).tolist(),
                  "kinematics": {"losses": self.losses, "timings": self.timings,
                                 "ground_estimated": self.ground_estimated,
                                 "shape": dataclasses.asdict(self.shape)}},
        )
