"""Closed-loop balance feedback inside the rollouts (an option; off in both presets).

Open-loop servo targets are chaotic: a small change of one spline coefficient can decide
whether a window ends standing or falling, so the search's outcome varies with its seed by as
much as with anything else (docs/dynamics.md). This feedback keeps each sample over its feet
the way a standing person does.

The feedback is a virtual force on the centre of mass, realised by the Jacobian transpose
(virtual model control) at the ankles of the standing feet (the ankle strategy): every
``interval`` simulation steps, the horizontal COM error of each sample against the reference
(position and velocity, PD at ``frequency`` Hz with damping ratio ``damping``) gives a force
F = M (w^2 e + 2 z w e'); an ankle hinge j of a standing foot, with world axis a_j through p_j,
moves the body above it (the foot held) at dc/dq_j = -a_j x (c - p_j), so its torque share is
tau_j = (dc/dq_j) . F / n_standing, applied as a servo-target offset tau_j / kp_j (clipped to
+-``max_offset``). Which feet stand, and the axes, come from the reference pose at the chunk's
first step (the sample's own pose is close to it while it is worth keeping), so the gains of a
window are fixed before its search and the per-chunk feedback is one small matrix product for
the whole batch. Measured: it holds a standing body against pushes, helps on standing and slow
motions and makes walking feet slide; over the whole benchmark it changes no figure by more
than the seed noise, and does not make the search less seed-dependent (docs/dynamics.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from physpose.dynamics.init import Reference, geom_lowest
from physpose.errors import PhysposeError
from physpose.skeleton import DOF_NAMES, NUM_DOF


@dataclass(frozen=True)
class BalanceGains:
    """frequency: Hz of the COM PD (0 switches feedback off); damping: its ratio.
    interval: simulation steps between feedback updates. stance_height: m, a reference foot
    box this close to the floor stands. max_offset: rad, largest servo-target offset.
    max_speed: m/s, reference COM speed (horizontal) above which there is no feedback; the
    gains fade linearly from full at half that speed (the ankle strategy is how one stands,
    not how one walks: walking balances by where the feet land)."""

    frequency: float = 0.0
    damping: float = 1.0
    interval: int = 4
    stance_height: float = 0.03
    max_offset: float = 0.3
    max_speed: float = 0.8

    def __post_init__(self) -> None:
        bad = [f"{n}={getattr(self, n)}" for n, ok in (
            ("frequency", self.frequency >= 0), ("damping", self.damping >= 0),
            ("interval", self.interval >= 1), ("stance_height", self.stance_height >= 0),
            ("max_offset", self.max_offset > 0), ("max_speed", self.max_speed > 0)) if not ok]
        if bad:
            raise PhysposeError(f"balance gains out of range: {', '.join(bad)}",
                                remedy="use frequency >= 0 Hz (0: off), damping >= 0, "
                                       "interval >= 1 step, stance_height >= 0 m, "
                                       "max_offset > 0 rad, max_speed > 0 m/s")

    @property
    def enabled(self) -> bool:
        return self.frequency > 0


@dataclass(frozen=True, eq=False)
class BalancePlan:
    """Feedback of one window. From each step starts[c] (window-relative, starts[0] = 0) the
    servo targets are offset by gain[c] @ a (48,), a = kp (c_ref - c) + kd (v_ref - v), the
    horizontal COM acceleration asked for (m/s^2) from the sample's COM c and velocity v.

    starts (C,); gain (C, 48, 2) rad per m/s^2 (mass x COM Jacobian / servo kp, standing
    feet's ankles only); com, com_vel (C, 3): the reference's COM (m) and its velocity (m/s)
    at those steps; kp (1/s^2), kd (1/s); max_offset (rad).
    """

    starts: np.ndarray
    gain: np.ndarray
    com: np.ndarray
    com_vel: np.ndarray
    kp: float
    kd: float
    max_offset: float

    def offsets(self, chunk: int, com: np.ndarray, com_vel: np.ndarray) -> np.ndarray:
        """Servo-target offsets (B, 48) for chunk ``chunk`` from the samples' COM and its
        velocity (B, 3)."""
        acc = self.kp * (self.com[chunk, :2] - com[:, :2]) \
            + self.kd * (self.com_vel[chunk, :2] - com_vel[:, :2])
        out = acc @ self.gain[chunk].T
        return np.clip(out, -self.max_offset, self.max_offset)


# The ankle strategy: flexion and inversion of the standing feet. Measured on five
# motion-capture clips x two seeds (fast preset plus feedback at 0.5 Hz): ankles only
# MPJPE-G 99.6 mm, MPJPE-PA 50.7; hip and knee flexion, hip abduction and the ankles,
# offsets clipped at 0.1 rad, 101.3 / 51.8; the same at 0.3 rad, 106.9; no feedback,
# 109.7 / 55.6. With the knee's narrow secondary axes also steered, a sideways push of
# 0.25 m/s topples the standing body.
_BALANCE_DOFS = {side: [DOF_NAMES.index(f"{side}_{n}") for n in ("ankle_y", "ankle_x")]
                 for side in ("l", "r")}


def balance_plan(model: mujoco.MjModel, reference: Reference, start_step: int, num_steps: int,
                 foot_geoms: dict[str, int], kp_servo: np.ndarray, gains: BalanceGains
                 ) -> BalancePlan:
    """The feedback gains of the window of ``num_steps`` steps from ``start_step``."""
    data = mujoco.MjData(model)
    mass = float(np.sum(model.body_mass))
    joint_ids = [model.joint(name).id for name in DOF_NAMES]
    starts = np.arange(0, num_steps, gains.interval)
    last = reference.num_steps

    def com_at(step: int) -> np.ndarray:
        data.qpos[:] = reference.qpos[step]
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        return data.subtree_com[1].copy()  # body 1: the pelvis, root of the whole body

    gain = np.zeros((len(starts), NUM_DOF, 2))
    com = np.zeros((len(starts), 3))
    com_vel = np.zeros((len(starts), 3))
    for c, s in enumerate(starts):
        step = min(start_step + int(s), last)
        hi, lo = min(step + 1, last), max(step - 1, 0)
        com_vel[c] = (com_at(hi) - com_at(lo)) / (max(hi - lo, 1) * reference.dt)
        com[c] = com_at(step)  # also leaves the kinematics of this step in data
        speed = float(np.linalg.norm(com_vel[c, :2]))
        scale = float(np.clip(2.0 * (gains.max_speed - speed) / gains.max_speed, 0.0, 1.0))
        standing = [side for side in ("l", "r")
                    if geom_lowest(model, data, foot_geoms[side]) < gains.stance_height]
        for side in standing if scale > 0 else ():
            for k in _BALANCE_DOFS[side]:
                j = joint_ids[k]
                moved = -np.cross(data.xaxis[j], com[c] - data.xanchor[j])
                gain[c, k] = scale * mass * moved[:2] / kp_servo[k] / len(standing)
    w = 2 * np.pi * gains.frequency
    return BalancePlan(starts=starts, gain=gain, com=com, com_vel=com_vel, kp=w * w,
                       kd=2 * gains.damping * w, max_offset=gains.max_offset)
