"""A camera that travels with the person: where it went, read off the estimate's standing feet.

The kinematic fit assumes a still camera. When the camera travels (a tracking shot beside a
runner, a walker filmed from a moving car), the estimate's positions are the person's minus
the camera's travel: a runner the camera follows seems to run on the spot, their standing
feet sliding backwards at the camera's speed. A simulated body cannot do that; its feet push
it along the floor, so it strays from such an estimate and restarts.

A foot standing on the floor does not move, so whatever horizontal velocity the estimate gives
a standing foot is the camera's, reversed. `camera_travel` takes it from the estimate's feet,
each weighted by how surely it stands (how low its heel and toe are, above their standing
heights and above the other foot's), as a weighted median over a fraction of a second (a
camera's speed changes slowly, and a runner's flight phases have no foot down), low-passes it
and integrates it into the camera's path from the first frame. The dynamics then follows the estimate moved on by that path, the motion in the
world, while the re-projection term moves the simulated body back by it before projecting, as
the travelling camera saw it (objective.ObjectiveReference.camera_travel).
"""

from __future__ import annotations

import mujoco
import numpy as np
from scipy.ndimage import gaussian_filter1d

from physpose.dynamics.objective import FOOT_LANDMARKS, landmark_sites, standing_heights

VOTE_S = 0.2               # s, time scale (Gaussian sd) of the feet that vote on a frame's speed
SMOOTHING_S = 0.1          # s, low-pass (Gaussian sd) of the voted camera velocity
STANDING_LIFT = 0.05       # m: a foot this far above its standing height counts e^-1 as much
ABOVE_OTHER = 0.01         # m: a foot this far above the other foot counts e^-1 as much
CAMERA_SETTINGS = ("auto", "still", "travelling")  # DynamicsConfig.camera


def camera_travels(setting: str, camera_motion: str | None) -> bool:
    """Whether the dynamics follows a travelling camera: ``setting`` "travelling", or "auto"
    where the observe stage found the camera moving (Observations.camera_motion)."""
    return setting == "travelling" or (setting == "auto" and camera_motion == "moving")


def foot_velocities(model: mujoco.MjModel, qpos: np.ndarray, fps: float
                    ) -> tuple[np.ndarray, np.ndarray]:
    """(velocity (T, 2, 2) m/s, standing weight (T, 2)) of the left and right foot of a motion
    qpos (T, 55) on the floor z = 0: the horizontal velocity of the midpoint of heel and toe
    landmarks, and how surely the foot stands: its lift (the lower of heel and toe above their
    standing heights) against the floor (STANDING_LIFT) and against the other foot's
    (ABOVE_OTHER: a walker's swing foot stays within a few centimetres of the floor)."""
    landmarks = landmark_sites(model, qpos)
    rest = standing_heights(model)
    velocity, lift = [], []
    for _, heel, toe in FOOT_LANDMARKS:
        middle = 0.5 * (landmarks[:, heel, :2] + landmarks[:, toe, :2])
        velocity.append(np.gradient(middle, axis=0) * fps if len(qpos) > 1
                        else np.zeros_like(middle))
        lift.append(np.minimum(landmarks[:, heel, 2] - rest[heel], landmarks[:, toe, 2] - rest[toe]))
    lift = np.maximum(np.stack(lift, axis=1), 0.0)
    weight = np.exp(-lift / STANDING_LIFT - (lift - lift.min(axis=1, keepdims=True)) / ABOVE_OTHER)
    return np.stack(velocity, axis=1), weight


def weighted_median(values: np.ndarray, weights: np.ndarray) -> float:
    """The median of values (N,) under non-negative weights (N,) (the lower one at a tie)."""
    order = np.argsort(values)
    cumulative = np.cumsum(weights[order])
    return float(values[order][np.searchsorted(cumulative, 0.5 * cumulative[-1])])


def camera_travel(model: mujoco.MjModel, qpos: np.ndarray, fps: float) -> np.ndarray:
    """(T, 3) m: how far the camera had travelled horizontally by each frame (0 at frame 0),
    from the standing feet of a kinematic estimate qpos (T, 55) made as if it stood still.

    Each frame's camera velocity is the weighted median, per axis, of the reversed velocities
    of the feet of the frames around it (weights: how surely a foot stands, times a Gaussian in
    time, VOTE_S): a median, because a swing foot the estimate puts low now and then moves
    fast and would drag a mean along. The votes are then low-passed (SMOOTHING_S)."""
    velocity, weight = foot_velocities(model, qpos, fps)
    t = len(qpos)
    reach = int(np.ceil(2 * VOTE_S * fps))
    near = np.exp(-0.5 * (np.arange(-reach, reach + 1) / (VOTE_S * fps)) ** 2)
    voted = np.zeros((t, 2))
    for i in range(t):
        lo, hi = max(0, i - reach), min(t, i + reach + 1)
        w = (weight[lo:hi] * near[lo - i + reach:hi - i + reach, None]).ravel()
        if w.sum() <= 0:
            continue
        for axis in range(2):
            voted[i, axis] = -weighted_median(velocity[lo:hi, :, axis].ravel(), w)
    camera_velocity = gaussian_filter1d(voted, SMOOTHING_S * fps, axis=0, mode="nearest")
    travel = np.zeros((t, 3))
    steps = 0.5 * (camera_velocity[1:] + camera_velocity[:-1]) / fps
    travel[1:, :2] = np.cumsum(steps, axis=0)
    return travel
