"""Stance feet put flat on the floor in the reference motion, by leg inverse kinematics.

A kinematic estimate rarely has its stance feet flat: a foot box tilted by 10-15 degrees
touches the floor with one edge, so the simulated body that tracks it stands on 1-3 contact
points and has little authority to balance (docs/dynamics.md), and the float metric counts
such a foot as not in contact. Turning the foot flat about the ankle alone pushes one edge into
the floor; grounding then lifts the whole body and the other foot hovers. Here the whole leg
moves instead: for a foot that is low, slow and only mildly tilted, both legs' hip, knee and
ankle hinges and the root's height are solved (Levenberg-Marquardt on MuJoCo's Jacobians,
pulled towards the estimate) so that the foot box keeps its place and heading but lies flat
with its sole on z = 0, while a foot that is not standing keeps its pose. Lowering the root is
needed when the estimate's legs are straight: a tilted foot standing on its toe edge holds the
ankle higher than a flat one can. The root's horizontal position and orientation are not moved.
The correction fades in and out over a few frames.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from physpose.dynamics.init import geom_lowest
from physpose.skeleton import DOF_LIMITS, DOF_NAMES

LEG_JOINTS = ("hip", "knee", "ankle")
AXES = ("y", "x", "z")
MIN_START_KNEE = 0.2  # rad, knee flexion the leg solve starts from at least


@dataclass(frozen=True)
class StanceConfig:
    """Which feet count as standing, and how the leg is solved.

    height: m, the foot box's lowest point is below this. speed: m/s, its centre moves slower
    than this horizontally. max_tilt: rad, the sole's normal is within this of vertical (a foot
    rolling onto its toes or heel further than this is left as it is). fade_frames: frames on
    either side over which the correction fades in and out. iterations, damping:
    Levenberg-Marquardt steps per frame and the pull towards the estimate (per unit of each
    hinge's range).
    rotation_scale: m per rad when weighing orientation against position errors. height_range: m,
    the root height's counterpart of a hinge's range in that pull.
    """

    height: float = 0.03
    speed: float = 0.5
    max_tilt: float = np.radians(25.0)
    fade_frames: int = 2
    iterations: int = 20
    damping: float = 1e-5
    height_range: float = 0.1
    rotation_scale: float = 0.1


def _leg_dofs(side: str) -> np.ndarray:
    return np.array([DOF_NAMES.index(f"{side}_{j}_{a}") for j in LEG_JOINTS for a in AXES])


def _flat_pose(rot: np.ndarray, centre: np.ndarray, half_height: float
               ) -> tuple[np.ndarray, np.ndarray]:
    """The box's target: same heading and horizontal place, flat, its bottom face on z = 0."""
    forward = np.array([rot[0, 0], rot[1, 0], 0.0])
    forward /= max(np.linalg.norm(forward), 1e-9)
    up = np.array([0.0, 0.0, 1.0])
    target_rot = np.stack([forward, np.cross(up, forward), up], axis=1)
    return target_rot, np.array([centre[0], centre[1], half_height])


def _rotation_error(target: np.ndarray, current: np.ndarray) -> np.ndarray:
    """World rotation vector taking ``current`` to ``target`` (3x3 matrices)."""
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, (target @ current.T).ravel())
    vec = np.empty(3)
    mujoco.mju_quat2Vel(vec, quat, 1.0)
    return vec


def foot_states(model: mujoco.MjModel, qpos: np.ndarray, foot_geoms: dict[str, int]
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per frame and foot ([l, r]): box centre (T, 2, 3), lowest z (T, 2), tilt (T, 2) rad."""
    data = mujoco.MjData(model)
    centre = np.empty((len(qpos), 2, 3))
    lowest = np.empty((len(qpos), 2))
    tilt = np.empty((len(qpos), 2))
    for t, q in enumerate(qpos):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        for k, side in enumerate(("l", "r")):
            g = foot_geoms[side]
            centre[t, k] = data.geom_xpos[g]
            lowest[t, k] = geom_lowest(model, data, g)
            tilt[t, k] = np.arccos(np.clip(data.geom_xmat[g][8], -1.0, 1.0))  # sole normal vs z
    return centre, lowest, tilt


def stance_weights(centre: np.ndarray, lowest: np.ndarray, tilt: np.ndarray, fps: float,
                   cfg: StanceConfig = StanceConfig()) -> np.ndarray:
    """(T, 2) in [0, 1]: how much of the flat-foot correction each foot gets per frame."""
    if len(centre) > 1:
        speed = np.linalg.norm(np.gradient(centre[..., :2], axis=0), axis=-1) * fps
    else:
        speed = np.zeros(lowest.shape)
    standing = ((lowest < cfg.height) & (speed < cfg.speed) & (tilt < cfg.max_tilt)).astype(float)
    if cfg.fade_frames <= 0:
        return standing
    # A triangular fade: full weight needs the foot standing fade_frames either side.
    n = cfg.fade_frames
    kernel = np.concatenate([np.arange(1, n + 2), np.arange(n, 0, -1)]).astype(float)
    kernel /= kernel.sum()
    padded = np.pad(standing, ((n, n), (0, 0)), mode="edge")
    return np.stack([np.convolve(padded[:, k], kernel, mode="valid") for k in range(2)], axis=1)


def _foot_pose(data: mujoco.MjData, geom: int) -> tuple[np.ndarray, np.ndarray]:
    return data.geom_xpos[geom].copy(), data.geom_xmat[geom].reshape(3, 3).copy()


def solve_flat_feet(model: mujoco.MjModel, data: mujoco.MjData, qpos: np.ndarray,
                    foot_geoms: dict[str, int], weights: np.ndarray,
                    cfg: StanceConfig = StanceConfig()) -> np.ndarray:
    """qpos (55,) with the feet moved towards lying flat on the floor, by ``weights`` (2,).

    Unknowns: both legs' hinges and the root's height (a straight leg cannot reach down to a
    flat foot otherwise). Each foot's box is pulled, with its weight w, to its flat pose and,
    with 1 - w, to where it was; hinges and height are pulled towards the estimate's.
    """
    sides = ("l", "r")
    dofs = np.concatenate([_leg_dofs(s) for s in sides])
    rows = np.concatenate([[2], 7 + dofs])   # qpos entries: root z, leg hinges
    cols = np.concatenate([[2], 6 + dofs])   # matching qvel columns
    lo = np.concatenate([[-np.inf], DOF_LIMITS[dofs, 0]])
    hi = np.concatenate([[np.inf], DOF_LIMITS[dofs, 1]])
    span = np.concatenate([[cfg.height_range], DOF_LIMITS[dofs, 1] - DOF_LIMITS[dofs, 0]])
    pull = np.sqrt(cfg.damping) / span
    q0 = np.array(qpos, dtype=float)
    data.qpos[:] = q0
    mujoco.mj_kinematics(model, data)
    goals = []
    for k, side in enumerate(sides):
        geom = foot_geoms[side]
        pos, rot = _foot_pose(data, geom)
        flat_rot, flat_pos = _flat_pose(rot, pos, model.geom_size[geom][2])
        w = float(np.clip(weights[k], 0.0, 1.0))
        goals.append((geom, w, flat_pos, flat_rot, pos, rot))
    scale = cfg.rotation_scale

    def residual(q: np.ndarray) -> np.ndarray:
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        parts = []
        for geom, w, flat_pos, flat_rot, pos0, rot0 in goals:
            pos, rot = _foot_pose(data, geom)
            for gain, (tp, tr) in ((np.sqrt(w), (flat_pos, flat_rot)),
                                   (np.sqrt(1.0 - w), (pos0, rot0))):
                parts += [gain * (pos - tp), gain * scale * _rotation_error(rot, tr)]
        parts.append(pull * (q[rows] - q0[rows]))
        return np.concatenate(parts)

    def jacobian() -> np.ndarray:
        mujoco.mj_comPos(model, data)
        jacp, jacr = np.zeros((3, model.nv)), np.zeros((3, model.nv))
        blocks = []
        for geom, w, *_ in goals:
            mujoco.mj_jac(model, data, jacp, jacr, data.geom_xpos[geom].copy(),
                          model.geom_bodyid[geom])
            for gain in (np.sqrt(w), np.sqrt(1.0 - w)):
                blocks += [gain * jacp[:, cols], gain * scale * jacr[:, cols]]
        blocks.append(np.diag(pull))
        return np.concatenate(blocks)

    # Levenberg-Marquardt: a step is kept only when it lowers the residual. A straight knee is
    # a singular point (bending it does not move the foot to first order), so start bent.
    q, lam = q0.copy(), 1e-2
    for side in sides:
        knee = 7 + DOF_NAMES.index(f"{side}_knee_y")
        q[knee] = max(q[knee], MIN_START_KNEE)
    res = residual(q)
    cost = res @ res
    for _ in range(cfg.iterations):
        jac = jacobian()
        hess = jac.T @ jac
        step = np.linalg.solve(hess + lam * np.diag(np.diag(hess) + 1e-12), -jac.T @ res)
        trial = q.copy()
        trial[rows] = np.clip(q[rows] + step, lo, hi)
        trial_res = residual(trial)
        if trial_res @ trial_res < cost:
            q, res, cost, lam = trial, trial_res, trial_res @ trial_res, lam * 0.3
        else:
            lam *= 10.0
            residual(q)  # data back at q for the next Jacobian
    return q


def flatten_stance_feet(model: mujoco.MjModel, qpos: np.ndarray, fps: float,
                        foot_geoms: dict[str, int], cfg: StanceConfig = StanceConfig()
                        ) -> np.ndarray:
    """qpos (T, 55) with standing feet (see StanceConfig) flat on the floor, legs re-solved."""
    centre, lowest, tilt = foot_states(model, qpos, foot_geoms)
    weights = stance_weights(centre, lowest, tilt, fps, cfg)
    data = mujoco.MjData(model)
    out = np.array(qpos, dtype=float)
    for t in np.flatnonzero(weights.max(axis=1) > 0.0):
        out[t] = solve_flat_feet(model, data, out[t], foot_geoms, weights[t], cfg)
    return out
