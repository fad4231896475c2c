"""Ground reaction forces, centres of pressure and joint torques of the simulated motion.

The simulation already computes what a biomechanist would measure with force plates and
inverse dynamics: the force the floor (and any obstacle) exerts on each foot and on the rest
of the body, where under each foot it acts, and the torque across each joint. They are read
back from the kept simulation, step by step: the state before a 200 Hz step and the servo
targets applied during it give, through ``mj_forward``, the same contact and actuator forces
the step integrated (over a step they balance the change of the body's momentum to within
0.01 body weights). A frame's value is the mean over the steps within half a frame of its time.

Contact forces come from MuJoCo's soft contact model on the body's primitive shapes (box feet),
not from measured plates; docs/dynamics.md, "Forces and torques", gives what was checked.
"""

from __future__ import annotations

import mujoco
import numpy as np

from physpose.reconstruction import GRF_PARTS as PARTS
from physpose.skeleton import NUM_DOF

# PARTS: what the environment pushes on, the left foot box, the right foot box, every other geom.
_FULL = mujoco.mjtState.mjSTATE_FULLPHYSICS
MIN_NORMAL_FORCE = 1.0  # N; a foot carrying less over a frame has no centre of pressure

# Per-step arrays a dynamics window keeps beside its servo targets (and checkpoints), and the
# shape of one step's entry.
_STEP_SHAPES = {"step_force": (len(PARTS), 3), "step_pressure_moment": (2, 3),
                "step_normal": (2,), "step_torque": (NUM_DOF,)}
STEP_KEYS = tuple(_STEP_SHAPES)


def geom_parts(model: mujoco.MjModel, foot_geoms: dict[str, int]) -> np.ndarray:
    """(ngeom,) index into PARTS of each body geom; -1 for the environment's (world body)."""
    parts = np.where(model.geom_bodyid == 0, -1, PARTS.index("body"))
    parts[foot_geoms["l"]] = PARTS.index("l_foot")
    parts[foot_geoms["r"]] = PARTS.index("r_foot")
    return parts


def step_forces(model: mujoco.MjModel, foot_geoms: dict[str, int], states: np.ndarray,
                ctrl: np.ndarray) -> dict[str, np.ndarray]:
    """Forces during each of S steps, from the FULLPHYSICS states before them (S, nstate) and
    the servo targets applied (S, 48).

    step_force (S, 3, 3) N: force of the environment on each of PARTS (world frame, z up).
    step_pressure_moment (S, 2, 3) N m: per foot, the sum over its contacts of contact point
    times normal force; divided by step_normal (S, 2) N, the summed normal force, it is the
    centre of pressure. step_torque (S, 48) N m: the torque across each hinge (`joint_torques`,
    DOF_NAMES order).
    Contacts of the body with itself are internal and left out.
    """
    steps = min(len(states), len(ctrl))
    parts = geom_parts(model, foot_geoms)
    data = mujoco.MjData(model)
    out = {k: np.zeros((steps, *shape)) for k, shape in _STEP_SHAPES.items()}
    force, moment = out["step_force"], out["step_pressure_moment"]
    normal, torque = out["step_normal"], out["step_torque"]
    wrench = np.zeros(6)
    limits = np.zeros(model.nv)
    for k in range(steps):
        mujoco.mj_setState(model, data, states[k], _FULL)
        data.ctrl[:] = ctrl[k]
        mujoco.mj_forward(model, data)
        torque[k] = joint_torques(model, data, limits)
        for i in range(data.ncon):
            contact = data.contact[i]
            p1, p2 = parts[contact.geom1], parts[contact.geom2]
            if (p1 < 0) == (p2 < 0):
                continue  # the body touching itself, or two pieces of scenery
            mujoco.mj_contactForce(model, data, i, wrench)
            # The force acts along the normal from geom1 to geom2, pushing geom2 away.
            on_geom2 = contact.frame.reshape(3, 3).T @ wrench[:3]
            part, sign = (p2, 1.0) if p1 < 0 else (p1, -1.0)
            force[k, part] += sign * on_geom2
            if part < 2:
                moment[k, part] += contact.pos * wrench[0]
                normal[k, part] += wrench[0]
    return out


def joint_torques(model: mujoco.MjModel, data: mujoco.MjData, scratch: np.ndarray
                  ) -> np.ndarray:
    """(48,) N m: the torque across each hinge after mj_forward: the servo's (its clamped
    stiffness part and its unclamped damping, which MuJoCo applies as a passive force) plus the
    joint-limit reaction. What inverse dynamics of the motion, given the contact forces, would
    attribute to the joint. scratch: (nv,) work array."""
    limit = data.efc_force * (data.efc_type == int(mujoco.mjtConstraint.mjCNSTR_LIMIT_JOINT))
    mujoco.mj_mulJacTVec(model, data, scratch, limit)
    hinges = slice(model.nv - NUM_DOF, model.nv)
    return data.qfrc_actuator[hinges] + data.qfrc_passive[hinges] + scratch[hinges]


def missing_steps(steps: int) -> dict[str, np.ndarray]:
    """Per-step arrays for a window whose forces were not recorded (a checkpoint written
    before they were): NaN throughout."""
    return {k: np.full((steps, *shape), np.nan) for k, shape in _STEP_SHAPES.items()}


def frame_forces(steps: dict[str, np.ndarray], positions: np.ndarray, steps_per_frame: float
                 ) -> dict[str, np.ndarray]:
    """Per-frame means of the per-step arrays (STEP_KEYS, S steps) over the steps within half a
    frame of each frame's step position (positions (T,), fractional steps).

    grf (T, 3, 3) N per PARTS; cop (T, 2, 3) m per foot, NaN where the foot carries less than
    MIN_NORMAL_FORCE; torques (T, 48) N m.
    """
    total = len(steps["step_force"])
    half = steps_per_frame / 2.0
    grf = np.empty((len(positions), len(PARTS), 3))
    cop = np.full((len(positions), 2, 3), np.nan)
    torques = np.empty((len(positions), NUM_DOF))
    for t, p in enumerate(np.asarray(positions, dtype=float)):
        lo = int(np.clip(np.ceil(p - half - 1e-9), 0, max(total - 1, 0)))
        hi = int(np.clip(np.ceil(p + half - 1e-9), lo + 1, total))
        grf[t] = steps["step_force"][lo:hi].mean(axis=0)
        torques[t] = steps["step_torque"][lo:hi].mean(axis=0)
        normal = steps["step_normal"][lo:hi].sum(axis=0)
        moment = steps["step_pressure_moment"][lo:hi].sum(axis=0)
        carried = normal >= MIN_NORMAL_FORCE * (hi - lo)
        cop[t, carried] = moment[carried] / normal[carried, None]
    return {"grf": grf, "cop": cop, "torques": torques}
