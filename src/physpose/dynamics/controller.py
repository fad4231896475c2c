"""Whole-body tracking controller: feedback that keeps a rollout near the reference motion.

Open-loop servo targets (the paper's control) reproduce a physically consistent motion, but an
estimate from video is not one, and an open-loop replay drifts within a fraction of a second.
This controller chooses the servo targets at every simulation step from the current state:

1. desired accelerations: the reference's plus PD feedback on every coordinate (root position,
   root orientation, hinges), with gains given as natural frequencies (size independent);
2. a plan that is physically consistent *at this step*: accelerations x and pushes lam >= 0
   along the friction-pyramid edges of the body's current contacts with the world, such that
   the root's six equations of motion ``M_root x + h_root = (J^T E lam)_root`` hold (heavily
   weighted), held contact points do not accelerate, and x is nearest the desired
   accelerations (root errors weigh ``root_weight`` times more than hinge ones). A least-squares
   problem with lam >= 0: x, which is free, is eliminated through a QR factorisation of its
   rows, leaving a small non-negative least squares in lam (scipy ``nnls``), the same solution
   as a bounded solver over both in half the time (benchmarks/bench_dynamics.py). A contact
   whose body point the reference lifts more than ``release_height`` above the floor is let go
   instead of held;
3. the hinge rows of ``M x + h - J^T E lam`` are the motor torques, applied through the
   position servos as targets ``q + tau / kp`` (body.py's servo law; its damping is passive
   and part of h).

The simulation then resolves the real contact forces; the next step corrects what the plan got
wrong. The root is only pushed by contacts, so the motion stays physical whatever the plan: the
controller only chooses motor targets, which are recorded and replay the motion exactly.

Measured (window starts every 0.5 s on motion-capture clips, 1 s each): with noise-free
detections the tracked root ends 0.2-6 cm from the estimate on a 4 s shuffling walk, where the
inverse-dynamics targets replayed open loop end 1-29 cm away; with the detector simulator's
noise both end 4-45 cm away: the noisy estimate itself is not physically consistent.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import mujoco
import numpy as np
from scipy.optimize import nnls

from physpose.dynamics.init import FRICTION_EDGES, Reference, friction_pyramid
from physpose.errors import PhysposeError
from physpose.skeleton import NUM_DOF

_FORCE_REGULARISER = 1e-3    # (per N): picks the smallest of equal force distributions
_ROOT_EQUATION_WEIGHT = 1e2   # the root's equations of motion are (nearly) hard constraints


@dataclass(frozen=True)
class ControllerGains:
    """PD loops and plan weights of the tracking controller.

    root_frequency / orientation_frequency / joint_frequency: Hz of the root position, root
    orientation and hinge loops; damping_ratio: all loops. root_weight: how much more a root
    acceleration error costs than a hinge one. contact_weight: how strongly held contact points
    are kept from accelerating. release_height: m, a contact the reference lifts higher is let go.
    """

    root_frequency: float = 2.0
    orientation_frequency: float = 3.0
    joint_frequency: float = 6.0
    damping_ratio: float = 1.0
    root_weight: float = 10.0
    contact_weight: float = 10.0
    release_height: float = 0.03

    def __post_init__(self) -> None:
        for f in fields(self):  # every gain, weight and height is a positive number
            if not getattr(self, f.name) > 0:
                raise PhysposeError(f"controller {f.name}={getattr(self, f.name)} must be > 0",
                                    remedy="use the default ControllerGains()")

    def pd(self, frequency: float) -> tuple[float, float]:
        w = 2 * np.pi * frequency
        return w * w, 2 * self.damping_ratio * w


def solve_with_pushes(A: np.ndarray, B: np.ndarray, b: np.ndarray, regulariser: float
                      ) -> tuple[np.ndarray, np.ndarray]:
    """(lam, x) minimising |A x + B lam - b|^2 + regulariser^2 |lam|^2 with lam >= 0, x free.

    A (R, n) has full column rank. With A = QR, the best x for a given lam is
    R^-1 Q^T (b - B lam), and what is left of the residual lies outside A's range, so lam
    solves the non-negative least squares |(I - QQ^T)(B lam - b)|^2 + regulariser^2 |lam|^2.
    """
    Q, R = np.linalg.qr(A)
    nl = B.shape[1]
    lam = np.zeros(nl)
    if nl:
        lhs = np.vstack([B - Q @ (Q.T @ B), regulariser * np.eye(nl)])
        rhs = np.concatenate([b - Q @ (Q.T @ b), np.zeros(nl)])
        lam, _ = nnls(lhs, rhs, maxiter=50 * nl)
    return lam, np.linalg.solve(R, Q.T @ (b - B @ lam))


class TrackingController:
    """Computes servo targets for a data whose position and velocity stages are computed
    (after ``mj_step1`` or ``mj_forward``)."""

    def __init__(self, model: mujoco.MjModel, gains: ControllerGains = ControllerGains()):
        self.model = model
        self.gains = gains
        self.kp = model.actuator_gainprm[:NUM_DOF, 0].copy()
        self.lo, self.hi = model.actuator_forcerange[:NUM_DOF].T
        nv = model.nv
        self._w = np.ones(nv)
        self._w[:6] = gains.root_weight
        self._M = np.zeros((nv, nv))
        self._jac = np.zeros((3, nv))
        self._ref_data = mujoco.MjData(model)
        self._err = np.empty(3)
        self._rot = np.empty(9)

    def desired_acceleration(self, data: mujoco.MjData, qpos: np.ndarray, qvel: np.ndarray,
                             qacc: np.ndarray) -> np.ndarray:
        """Reference acceleration plus PD feedback toward the reference state (nv,)."""
        g = self.gains
        kp_r, kd_r = g.pd(g.root_frequency)
        kp_o, kd_o = g.pd(g.orientation_frequency)
        kp_j, kd_j = g.pd(g.joint_frequency)
        q, v = data.qpos, data.qvel
        out = np.array(qacc, dtype=float)
        out[:3] += kp_r * (qpos[:3] - q[:3]) + kd_r * (qvel[:3] - v[:3])
        # Orientation error in the pelvis frame (the free joint's angular coordinates).
        mujoco.mju_subQuat(self._err, qpos[3:7], q[3:7])
        mujoco.mju_quat2Mat(self._rot, qpos[3:7])
        rot_ref = self._rot.reshape(3, 3)
        rot = data.xmat[1].reshape(3, 3)
        omega_ref = rot.T @ (rot_ref @ qvel[3:6])
        out[3:6] += kp_o * self._err + kd_o * (omega_ref - v[3:6])
        out[6:] += kp_j * (qpos[7:] - q[7:]) + kd_j * (qvel[6:] - v[6:])
        return out

    def _contacts(self, data: mujoco.MjData, ref_data: mujoco.MjData
                  ) -> tuple[np.ndarray, np.ndarray]:
        """Contacts between the body and the world that the reference keeps on the floor:
        (P, 3, nv) point Jacobians and (P, E, 3) friction-cone edges (world frame)."""
        m = self.model
        jacs, cones = [], []
        for i in range(data.ncon):
            c = data.contact[i]
            b1, b2 = m.geom_bodyid[c.geom1], m.geom_bodyid[c.geom2]
            if (b1 == 0) == (b2 == 0):
                continue  # self-contact: internal forces, no net push
            body = b2 if b1 == 0 else b1
            normal = np.array(c.frame[:3]) * (-1.0 if b1 != 0 else 1.0)  # frame: geom1 -> geom2
            # Where this point of the body is in the reference pose: a foot the reference
            # lifts is let go instead of being held on the floor.
            local = data.xmat[body].reshape(3, 3).T @ (c.pos - data.xpos[body])
            ref_point = ref_data.xpos[body] + ref_data.xmat[body].reshape(3, 3) @ local
            if ref_point[2] > self.gains.release_height:
                continue
            mu = max(m.geom_friction[c.geom1, 0], m.geom_friction[c.geom2, 0])
            mujoco.mj_jac(m, data, self._jac, None, c.pos, body)
            jacs.append(self._jac.copy())
            cones.append(friction_pyramid(mu, normal))
        if not jacs:
            return np.zeros((0, 3, m.nv)), np.zeros((0, FRICTION_EDGES, 3))
        return np.stack(jacs), np.stack(cones)

    def torques(self, data: mujoco.MjData, ref_data: mujoco.MjData, desired: np.ndarray
                ) -> np.ndarray:
        """Motor torques (48,) of the physically consistent plan nearest ``desired``.

        Unknowns: accelerations x (nv) and pushes lam >= 0 along friction-cone edges. Rows:
        w (x - desired); the root's equations of motion (heavily weighted); held contact
        points do not accelerate. The hinge rows of M x + h - J^T E lam are the torques.
        """
        m, nv = self.model, self.model.nv
        mujoco.mj_fullM(m, data, self._M)
        M = self._M
        h = data.qfrc_bias - data.qfrc_passive
        jacs, cones = self._contacts(data, ref_data)
        p = len(jacs)
        # (nv, P*E): generalised force of a unit push along each edge.
        G = np.einsum("pcv,pec->vpe", jacs, cones).reshape(nv, p * FRICTION_EDGES)
        nl = G.shape[1]
        we, wc = _ROOT_EQUATION_WEIGHT, self.gains.contact_weight
        # Rows over x (A) and over lam (B): w (x - desired); the root's equations of motion;
        # held contact points do not accelerate.
        A = np.vstack([np.diag(self._w), we * M[:6], wc * jacs.reshape(3 * p, nv)])
        B = np.zeros((len(A), nl))
        B[nv:nv + 6] = -we * G[:6]
        b = np.concatenate([self._w * desired, -we * h[:6], np.zeros(3 * p)])
        lam, x = solve_with_pushes(A, B, b, _FORCE_REGULARISER)
        tau = (M @ x + h - G @ lam)[6:]
        return np.clip(tau, self.lo, self.hi)

    def step_targets(self, data: mujoco.MjData, qpos: np.ndarray, qvel: np.ndarray,
                     qacc: np.ndarray) -> np.ndarray:
        """Servo targets (48,) toward the reference state (qpos, qvel, qacc) of this step."""
        self._ref_data.qpos[:] = qpos
        mujoco.mj_kinematics(self.model, self._ref_data)
        desired = self.desired_acceleration(data, qpos, qvel, qacc)
        return data.qpos[7:] + self.torques(data, self._ref_data, desired) / self.kp


def track_reference(model: mujoco.MjModel, state0: np.ndarray, ref: Reference, start_step: int,
                    num_steps: int, gains: ControllerGains = ControllerGains()
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Simulate num_steps under the controller from state0 (FULLPHYSICS) at reference step
    start_step (the reference's last step is held beyond its end).

    Returns (states (num_steps + 1, nstate), ctrl (num_steps, 48)): replaying ctrl open loop
    from state0 (rollout.Simulator) gives the same states.
    """
    full = mujoco.mjtState.mjSTATE_FULLPHYSICS
    data = mujoco.MjData(model)
    mujoco.mj_setState(model, data, state0, full)
    controller = TrackingController(model, gains)
    states = np.empty((num_steps + 1, mujoco.mj_stateSize(model, full)))
    applied = np.empty((num_steps, NUM_DOF))
    mujoco.mj_getState(model, data, states[0], full)
    for i in range(num_steps):
        mujoco.mj_step1(model, data)  # positions, velocities, contacts of the current state
        n = min(start_step + i, ref.num_steps)
        applied[i] = controller.step_targets(data, ref.qpos[n], ref.qvel[n], ref.qacc[n])
        data.ctrl[:NUM_DOF] = applied[i]
        mujoco.mj_step2(model, data)
        mujoco.mj_getState(model, data, states[i + 1], full)
    return states, applied
