"""`PhysicsResult`: the dynamics stage's output, the simulated motion sampled at the frames."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from physpose.reconstruction import restart_frames


@dataclass(frozen=True, eq=False)
class PhysicsResult:
    """Simulated motion at the frame times (world frame, z up, ground z = 0, metres).

    qpos (T, 55) MuJoCo coordinates; joints (T, 21, 3) JOINT_NAMES; landmarks (T, 33, 3)
    landmark sites (MediaPipe order); com (T, 3) centre of mass; foot_heights (T, 2) lowest
    point of the left and right foot boxes (m); ctrl (S, 48) the servo targets applied at every
    200 Hz step (sequential windows) or the windows' targets one after another (independent).
    windows: one record per window (frames, steps, evaluations, initial and final loss and
    terms, seconds). timings: seconds per sub-step. config: the resolved DynamicsConfig.
    candidates: with DynamicsConfig.candidates > 1, one row per whole-clip run (seed, mean
    window loss, kept); empty otherwise. reference_residual (T,): the root force, in body
    weights, that the kinematic estimate needs and no ground contact explains (inverse dynamics
    of the smoothed estimate; 0 for a motion the body can make). Where it is large the
    simulated body cannot follow the estimate (docs/dynamics.md, "Consistency of the estimate").
    grf (T, 3, 3) N: the force of the floor and any obstacle on the left foot, the right foot
    and the rest of the body (forces.PARTS), world frame; cop (T, 2, 3) m: the centre of
    pressure under each foot, NaN where it carries no weight; torques (T, 48) N m: the torque
    across each hinge (its servo's, damping included, plus the joint-limit reaction;
    forces.joint_torques), DOF_NAMES order. Each is the mean over the simulation steps within half a frame
    of the frame (forces.py); NaN for windows resumed from a checkpoint written before
    physpose recorded forces.
    `restarts`: the frames at which the motion restarts from the kinematic estimate.
    stretch_shifts (S, 2): the horizontal shift (m) given to each continuous stretch, split at
    the restarts (DynamicsConfig.place_stretches; empty when not placed).
    camera_travel (T, 3): where the camera travelled with the person (DynamicsConfig.camera,
    travel.py), how far it had moved by each frame (m, horizontal, world axes): the simulated
    motion is where the person went, and the still camera of the kinematic fit sees it moved
    back by this. None for a camera that stood still.
    """

    fps: float
    qpos: np.ndarray
    joints: np.ndarray
    landmarks: np.ndarray
    com: np.ndarray
    foot_heights: np.ndarray
    ctrl: np.ndarray
    windows: list[dict] = dataclasses.field(default_factory=list)
    timings: dict = dataclasses.field(default_factory=dict)
    config: dict = dataclasses.field(default_factory=dict)
    candidates: list[dict] = dataclasses.field(default_factory=list)
    reference_residual: np.ndarray | None = None
    stretch_shifts: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 2)))
    camera_travel: np.ndarray | None = None
    grf: np.ndarray | None = None
    cop: np.ndarray | None = None
    torques: np.ndarray | None = None

    @property
    def num_frames(self) -> int:
        return int(self.qpos.shape[0])

    @property
    def restarts(self) -> list[int]:
        """Frames at which the run restarted from the kinematic state (`restart_frames`)."""
        return restart_frames(self.windows)

    def reconstruction_fields(self) -> dict[str, np.ndarray | None]:
        """The physics fields of a `Reconstruction` (physpose.reconstruction)."""
        return {"joints_physics": self.joints, "qpos_physics": self.qpos,
                "landmarks_physics": self.landmarks, "camera_travel_physics": self.camera_travel,
                "grf_physics": self.grf, "cop_physics": self.cop,
                "torques_physics": self.torques}

    def losses(self) -> dict[str, float]:
        """Final loss terms averaged over windows (unweighted), plus the weighted total."""
        if not self.windows:
            return {}
        names = self.windows[0]["terms_final"].keys()
        out = {n: float(np.mean([w["terms_final"][n] for w in self.windows])) for n in names}
        out["total"] = mean_window_loss(self.windows)
        return out

    def meta(self) -> dict:
        """JSON-able record of the run for a reconstruction's meta["dynamics"]."""
        return {"windows": self.windows, "losses": self.losses(), "candidates": self.candidates,
                "restarts": self.restarts, "stretch_shifts": self.stretch_shifts.tolist(),
                "reference": self.reference_summary(),
                "camera_travelled_m": None if self.camera_travel is None else
                float(np.linalg.norm(self.camera_travel[-1] - self.camera_travel[0]))}

    def reference_summary(self) -> dict[str, float]:
        """Median and 90th percentile over frames of ``reference_residual`` (body weights)."""
        if self.reference_residual is None or not len(self.reference_residual):
            return {}
        r = np.asarray(self.reference_residual, dtype=float)
        return {"root_residual_median": float(np.median(r)),
                "root_residual_p90": float(np.percentile(r, 90))}


def mean_window_loss(windows: list[dict]) -> float:
    """The windows' final weighted losses, averaged (unweighted by length)."""
    return float(np.mean([w["loss_final"] for w in windows]))
