"""Closed-loop tracking of the reference motion, to start a window's search from a balanced guess.

Open-loop servo targets from inverse dynamics reproduce a physically consistent motion, but a
noisy kinematic estimate is not one: its replay drifts off balance within a fraction of a second
(measured: 5-30 cm at mid-window, up to 1 m at the end of 1 s windows on motion capture through
the detector simulator). Here the body is simulated once, step by step, with the inverse-dynamics
targets plus a balance feedback: a virtual force on the centre of mass and a virtual torque on
the pelvis (PD on their errors against the low-passed estimate) are produced by the legs whose
feet touch the floor, through the transpose of the Jacobian of the centre of mass and the
pelvis orientation with respect to the leg's hinges *with the foot held still* (hinge i then
turns everything above it by minus its angle: d(com) = -a_i x (com - p_i), d(rotation) = -a_i). The targets applied at every step are recorded; fitted by the window's
spline they give the search an open-loop start that stays near the estimate, since the
simulation is deterministic. No force acts on the root other than contacts.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from physpose.dynamics.init import Reference, geom_lowest
from physpose.dynamics.rollout import SimModel
from physpose.skeleton import DOF_NAMES

_FULL = mujoco.mjtState.mjSTATE_FULLPHYSICS
LEG_DOFS = {side: np.array([k for k, n in enumerate(DOF_NAMES)
                            if n.split("_")[0] == side and n.split("_")[1] in ("hip", "knee", "ankle")])
            for side in ("l", "r")}


@dataclass(frozen=True)
class TrackingGains:
    """Balance feedback: natural frequency (Hz) and damping ratio of the COM and pelvis loops,
    and how close (m) to the floor a foot's lowest point must be to push."""

    com_frequency: float = 0.5
    orientation_frequency: float = 0.0
    damping_ratio: float = 1.0
    stance_height: float = 0.02


def _orientation_error(R_ref: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Rotation vector (world frame) taking R to R_ref."""
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, (R_ref @ R.T).ravel())
    vec = np.empty(3)
    mujoco.mju_quat2Vel(vec, quat, 1.0)
    return vec


def reference_com(model: mujoco.MjModel, ref: Reference, steps: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Centre of mass (S, 3) and its velocity (S, 3) of the reference at the given steps."""
    data = mujoco.MjData(model)
    jac = np.zeros((3, model.nv))
    com, vel = np.empty((len(steps), 3)), np.empty((len(steps), 3))
    for i, n in enumerate(steps):
        data.qpos[:] = ref.qpos[n]
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        mujoco.mj_jacSubtreeCom(model, data, jac, 1)
        com[i], vel[i] = data.subtree_com[1], jac @ ref.qvel[n]
    return com, vel


def track(sim: SimModel, state0: np.ndarray, ref: Reference, start_step: int,
          feedforward: np.ndarray, gains: TrackingGains = TrackingGains()) -> np.ndarray:
    """Servo targets (S, 48) applied while tracking the reference from state0 for S steps."""
    m, body = sim.model, sim.body
    data = mujoco.MjData(m)
    mujoco.mj_setState(m, data, state0, _FULL)
    mujoco.mj_forward(m, data)
    steps = start_step + np.arange(len(feedforward))
    com_ref, vel_ref = reference_com(m, ref, np.minimum(steps, ref.num_steps))
    mass = float(m.body_subtreemass[1])
    inertia = mass * 0.5 ** 2  # kg m^2: the body's mass at ~half a metre from the feet
    wc, wr = 2 * np.pi * gains.com_frequency, 2 * np.pi * gains.orientation_frequency
    kp_c, kd_c = mass * wc ** 2, 2 * gains.damping_ratio * mass * wc
    kp_r, kd_r = inertia * wr ** 2, 2 * gains.damping_ratio * inertia * wr
    kp = m.actuator_gainprm[:len(DOF_NAMES), 0]
    jac_com = np.zeros((3, m.nv))
    leg_joints = {side: np.array([mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, DOF_NAMES[k])
                                  for k in dofs]) for side, dofs in LEG_DOFS.items()}
    out = np.empty_like(feedforward)
    for i, n in enumerate(np.minimum(steps, ref.num_steps)):
        mujoco.mj_jacSubtreeCom(m, data, jac_com, 1)
        force = kp_c * (com_ref[i] - data.subtree_com[1]) + kd_c * (vel_ref[i] - jac_com @ data.qvel)
        R = data.xmat[1].reshape(3, 3)
        R_ref = np.empty(9)
        mujoco.mju_quat2Mat(R_ref, ref.qpos[n, 3:7])
        R_ref = R_ref.reshape(3, 3)
        torque = kp_r * _orientation_error(R_ref, R) + kd_r * (R_ref @ ref.qvel[n, 3:6]
                                                              - R @ data.qvel[3:6])
        stance = [s for s, g in body.foot_geom_ids.items() if geom_lowest(m, data, g)
                  < gains.stance_height]
        tau = np.zeros(len(kp))
        com = data.subtree_com[1]
        for side in stance:
            joints = leg_joints[side]
            axes, anchors = data.xaxis[joints], data.xanchor[joints]
            lever = -np.cross(axes, com - anchors)           # (9, 3): d(com) per unit angle
            tau[LEG_DOFS[side]] += (lever @ force - axes @ torque) / len(stance)
        out[i] = feedforward[i] + tau / kp
        data.ctrl[:] = out[i]
        mujoco.mj_step(m, data)
    return out

