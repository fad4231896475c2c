"""Ground reaction forces, centres of pressure and joint torques read back from a simulation."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from physpose.body import build_body, standing_qpos
from physpose.dynamics.forces import (MIN_NORMAL_FORCE, PARTS, STEP_KEYS, frame_forces,
                                      joint_torques, missing_steps, step_forces)
from physpose.dynamics.rollout import Simulator, make_state, sim_model
from physpose.dynamics.synthetic import motion_targets, seated_qpos, sitting_scene
from physpose.shape import BodyShape
from physpose.skeleton import DOF_NAMES, NUM_DOF, NV

G = 9.81


@pytest.fixture(scope="module")
def body():
    return build_body(BodyShape.from_height(1.75))


def simulate(body, qpos, targets):
    """(states (S + 1, nstate), applied targets (S, 48), sim) of a rollout from rest."""
    sim = sim_model(body)
    with Simulator(sim, nthread=1) as simulator:
        traj = simulator.run(make_state(sim, qpos, np.zeros(NV)), targets[None])
    return traj.states[0], traj.ctrl[0], sim


def com_velocities(sim, states):
    """(S + 1, 3) velocity of the whole body's centre of mass at each state."""
    data = mujoco.MjData(sim.model)
    out = np.empty((len(states), 3))
    for k, state in enumerate(states):
        mujoco.mj_setState(sim.model, data, state, mujoco.mjtState.mjSTATE_FULLPHYSICS)
        mujoco.mj_forward(sim.model, data)
        mujoco.mj_subtreeVel(sim.model, data)
        out[k] = data.subtree_linvel[1]
    return out


def test_the_forces_change_the_momentum_as_newton_says(body):
    """Over every step of a weight shift and a step, the environment's force plus gravity is
    the body's mass times its centre of mass's acceleration."""
    states, ctrl, sim = simulate(body, standing_qpos(body), motion_targets(body, "step", 1.5))
    forces = step_forces(sim.model, body.foot_geom_ids, states[:-1], ctrl)
    assert set(forces) == set(STEP_KEYS)
    m = body.total_mass
    acc = np.diff(com_velocities(sim, states), axis=0) / sim.dt
    residual = forces["step_force"].sum(axis=1) - m * (acc + [0.0, 0.0, G])
    assert np.abs(residual).max() < 0.02 * m * G
    # The lifted left foot carries less than half the weight for a while; the right then more.
    vertical = forces["step_force"][:, :, 2]
    assert (vertical[:, 0] < 0.3 * m * G).any() and (vertical[:, 1] > 0.7 * m * G).any()
    assert np.abs(vertical[:, 2]).max() < 1e-9  # nothing but the feet touches the floor


def test_a_standing_body_carries_its_weight_on_its_soles(body):
    steps = 200
    states, ctrl, sim = simulate(body, standing_qpos(body),
                                 np.tile(standing_qpos(body)[7:], (steps, 1)))
    forces = step_forces(sim.model, body.foot_geom_ids, states[-41:-1], ctrl[-40:])
    grf = frame_forces(forces, np.array([20.0]), 8.0)
    total = grf["grf"][0].sum(axis=0)
    np.testing.assert_allclose(total, [0.0, 0.0, body.total_mass * G], atol=0.01 * body.total_mass * G)
    # Each centre of pressure lies on the floor, under its own foot's box.
    data = mujoco.MjData(sim.model)
    mujoco.mj_setState(sim.model, data, states[-1], mujoco.mjtState.mjSTATE_FULLPHYSICS)
    mujoco.mj_forward(sim.model, data)
    for f, side in enumerate("lr"):
        geom = body.foot_geom_ids[side]
        local = data.geom_xmat[geom].reshape(3, 3).T @ (grf["cop"][0, f] - data.geom_xpos[geom])
        assert (np.abs(local[:2]) <= sim.model.geom_size[geom][:2] + 1e-6).all()
        assert abs(grf["cop"][0, f, 2]) < 0.01
    # The servos hold the pose against gravity: every torque finite, and the shoulders carry
    # the arms held a little away from the trunk (about 0.6 N m each on this body).
    assert grf["torques"].shape == (1, NUM_DOF) and np.isfinite(grf["torques"]).all()
    shoulders = [DOF_NAMES.index(f"{s}_shoulder_x") for s in "lr"]
    assert (np.abs(grf["torques"][0, shoulders]) > 0.3).all()


def test_a_seated_body_rests_on_the_seat(body):
    seated = build_body(body.shape, sitting_scene(body))
    q = seated_qpos(seated)
    states, ctrl, sim = simulate(seated, q, np.tile(q[7:], (600, 1)))  # settled after 3 s
    forces = step_forces(sim.model, seated.foot_geom_ids, states[-41:-1], ctrl[-40:])
    grf = frame_forces(forces, np.array([20.0]), 8.0)["grf"][0]
    m = seated.total_mass
    assert abs(grf[:, 2].sum() - m * G) < 0.02 * m * G
    assert grf[PARTS.index("body"), 2] > 0.3 * m * G  # the seat carries the thighs


def test_frame_means_and_centres_of_pressure():
    steps = 16
    forces = missing_steps(steps)
    forces["step_force"][:] = np.arange(steps, dtype=float)[:, None, None]
    forces["step_torque"][:] = 1.0
    forces["step_normal"][:] = [[10.0, 0.0]] * steps
    forces["step_pressure_moment"][:] = [[[1.0, 2.0, 0.0], [0.0, 0.0, 0.0]]] * steps
    out = frame_forces(forces, np.array([0.0, 8.0, 15.5]), 8.0)
    # Frame 1 (step 8) averages steps 4..11; frame 0 only the steps after the clip's start.
    np.testing.assert_allclose(out["grf"][:, 0, 0], [1.5, 7.5, 13.5])
    np.testing.assert_allclose(out["cop"][:, 0], [[0.1, 0.2, 0.0]] * 3)
    assert np.isnan(out["cop"][:, 1]).all()  # the right foot carries nothing
    assert MIN_NORMAL_FORCE > 0
    nan = frame_forces(missing_steps(steps), np.array([4.0]), 8.0)
    assert np.isnan(nan["grf"]).all() and np.isnan(nan["cop"]).all()


def test_joint_torques_are_what_inverse_dynamics_gives_the_hinges(body):
    """Hinge rows of M qacc + bias, less what the contacts push: the servos' torque (with their
    damping) plus the joint-limit reactions."""
    states, ctrl, sim = simulate(body, standing_qpos(body), motion_targets(body, "step", 1.0))
    model, data = sim.model, mujoco.MjData(sim.model)
    scratch, contact, inertial = np.zeros(model.nv), np.zeros(model.nv), np.zeros(model.nv)
    for k in (10, 120, 150):
        mujoco.mj_setState(model, data, states[k], mujoco.mjtState.mjSTATE_FULLPHYSICS)
        data.ctrl[:] = ctrl[k]
        mujoco.mj_forward(model, data)
        in_contact = data.efc_type >= int(mujoco.mjtConstraint.mjCNSTR_CONTACT_FRICTIONLESS)
        mujoco.mj_mulJacTVec(model, data, contact, data.efc_force * in_contact)
        mujoco.mj_mulM(model, data, inertial, data.qacc)
        expected = (inertial + data.qfrc_bias - contact)[6:]
        np.testing.assert_allclose(joint_torques(model, data, scratch), expected, atol=1e-6)
        assert np.abs(data.qfrc_passive[6:]).max() > 0  # the servo damping is in them


def test_a_joint_pushed_past_its_limit_is_held_by_the_limit(body):
    data = mujoco.MjData(body.model)
    q = standing_qpos(body)
    knee = 7 + DOF_NAMES.index("l_knee_y")
    lo, hi = body.model.jnt_range[body.model.dof_jntid[knee - 1]]
    q[knee] = hi + 0.05  # bent past its range
    data.qpos[:] = q
    data.ctrl[:] = q[7:]  # the servo holds the pose: no servo torque
    mujoco.mj_forward(body.model, data)
    torques = joint_torques(body.model, data, np.zeros(body.model.nv))
    k = DOF_NAMES.index("l_knee_y")
    servo = data.qfrc_actuator[6 + k] + data.qfrc_passive[6 + k]
    assert abs(servo) < 1e-6 and torques[k] < -1.0  # the limit pushes it back into range
