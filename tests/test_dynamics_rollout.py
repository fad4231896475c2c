"""Batched rollouts: sensors line up with states, frame sampling, broken samples are flagged;
the inverse-dynamics start reproduces a simulated motion."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from physpose.body import build_body, standing_qpos
from physpose.dynamics.init import (ground_state, initial_coefficients,
                                    inverse_dynamics, smooth_reference)
from physpose.dynamics.rollout import Simulator, make_state, sim_model
from physpose.dynamics.spline import KnotGrid
from physpose.dynamics.synthetic import motion_targets, simulated_clip
from physpose.scene import Box, SceneConfig
from physpose.shape import BodyShape
from physpose.skeleton import NV


@pytest.fixture(scope="module")
def body():
    return build_body(BodyShape.from_height(1.75))


def test_sensors_describe_the_returned_states(body):
    sim = sim_model(body)
    q0 = standing_qpos(body)
    state0 = make_state(sim, q0, np.zeros(NV))
    ctrl = np.tile(q0[7:], (2, 30, 1))
    ctrl[1, :, 0] += 0.3
    with Simulator(sim, nthread=2) as simulator:
        traj = simulator.run(state0, ctrl)
    assert traj.states.shape == (2, 31, sim.nstate) and not traj.broken.any()
    data = mujoco.MjData(sim.model)
    for n in (0, 17, 30):
        mujoco.mj_setState(sim.model, data, traj.states[1, n], mujoco.mjtState.mjSTATE_FULLPHYSICS)
        mujoco.mj_forward(sim.model, data)
        np.testing.assert_allclose(traj.sensors[1, n], data.sensordata, atol=1e-9)
        assert data.time == pytest.approx(n * sim.dt)
    # Frame sampling interpolates between steps; at whole steps it is the step itself.
    samples = traj.at(np.array([0.0, 17.0, 17.5]))
    np.testing.assert_allclose(samples.qpos[1, 1], traj.states[1, 17, 1:56], atol=1e-12)
    np.testing.assert_allclose(samples.com[1, 2], 0.5 * (traj.sensors[1, 17, -3:]
                                                         + traj.sensors[1, 18, -3:]))
    assert samples.landmarks.shape == (2, 3, 33, 3) and samples.joints.shape == (2, 3, 21, 3)


def test_a_sample_that_makes_mujoco_warn_is_broken_from_then_on(body):
    sim = sim_model(body)
    q0 = standing_qpos(body)
    ctrl = np.tile(q0[7:], (2, 20, 1))
    ctrl[1, 5:, 3] = np.nan  # MuJoCo warns about bad controls; rollout freezes the sample
    with Simulator(sim, nthread=2) as simulator:
        traj = simulator.run(make_state(sim, q0, np.zeros(NV)), ctrl)
    assert not traj.broken[0].any()
    assert not traj.broken[1, :5].any() and traj.broken[1, -1]


def test_ground_state_lifts_out_of_the_floor_and_snaps_down(body):
    q = standing_qpos(body)
    for dz, expect in ((-0.02, 0.0), (0.02, 0.0), (0.2, 0.2)):
        moved = q.copy()
        moved[2] += dz
        assert ground_state(body.model, moved, snap=0.03)[2] == pytest.approx(q[2] + expect,
                                                                               abs=1e-3)


def test_inverse_dynamics_start_reproduces_a_simulated_motion(body):
    """DESIGN.md's recipe: the open-loop start stays within 2 cm over a 1 s weight shift."""
    fit, _, truth = simulated_clip(body, "shift", seconds=1.0)
    sim = sim_model(body)
    n = len(truth)
    ref = smooth_reference(fit.qpos, fit.fps, sim.dt, n, 0.1)
    needs = inverse_dynamics(sim.model, ref, body.foot_geom_ids, 0.9, 0.03)
    targets = needs.targets
    assert np.abs(targets[:n] - truth).mean() < 0.005  # rad
    grid = KnotGrid(0.1, n * sim.dt)
    times = np.arange(n) * sim.dt
    ctrl = grid.basis(times) @ initial_coefficients(grid, times, targets[:n])
    with Simulator(sim, nthread=1) as simulator:
        traj = simulator.run(make_state(sim, ref.qpos[0], ref.qvel[0]), ctrl[None])
    samples = traj.at(np.arange(fit.num_frames) / (fit.fps * sim.dt))
    err = np.linalg.norm(samples.joints[0] - fit.joints, axis=-1).mean()
    assert err < 0.02
    # Holding the standing pose (no inverse dynamics) is a worse start for the same motion.
    stand = np.tile(standing_qpos(body)[7:], (1, n, 1))
    with Simulator(sim, nthread=1) as simulator:
        held = simulator.run(make_state(sim, ref.qpos[0], ref.qvel[0]), stand)
    held_err = np.linalg.norm(held.at(np.arange(fit.num_frames) / (fit.fps * sim.dt)).joints[0]
                              - fit.joints, axis=-1).mean()
    assert held_err > err
    assert motion_targets(body, "shift", 1.0).shape == truth.shape


def test_inverse_dynamics_measures_the_root_force_no_contact_explains(body):
    """A simulated motion needs (almost) no push from nowhere; the same motion lifted 10 cm
    off the floor needs its whole weight."""
    fit, _, _ = simulated_clip(body, "shift", seconds=1.0)
    sim = sim_model(body)
    n = int(round(1.0 / sim.dt))
    real = smooth_reference(fit.qpos, fit.fps, sim.dt, n, 0.1)
    lifted = fit.qpos.copy()
    lifted[:, 2] += 0.1
    floating = smooth_reference(lifted, fit.fps, sim.dt, n, 0.1)
    residual = [inverse_dynamics(sim.model, ref, body.foot_geom_ids, 0.9, 0.03).root_residual
                for ref in (real, floating)]
    assert np.median(residual[0]) < 0.02  # body weights
    assert np.median(residual[1]) == pytest.approx(1.0, abs=0.02)
    # Lifted onto a 10 cm box under the feet, the box explains it again (the soles push on
    # whatever they stand on: floor or box top).
    on_box = build_body(body.shape, SceneConfig(obstacles=(Box(center=(0.0, 0.0, 0.05),
                                                                   size=(2.0, 2.0, 0.1)),)))
    supported = inverse_dynamics(sim_model(on_box).model, floating, on_box.foot_geom_ids, 0.9,
                                 0.03).root_residual
    assert np.median(supported) < 0.02
