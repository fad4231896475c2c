"""Balance feedback: a pushed body is pulled back over its feet, only standing legs act, and the
targets a feedback rollout applied replay the same motion open loop."""

from __future__ import annotations

import numpy as np
import pytest

from physpose.body import build_body, standing_qpos
from physpose.dynamics.balance import BalanceGains, balance_plan
from physpose.dynamics.init import Reference
from physpose.dynamics.rollout import Simulator, make_state, sim_model
from physpose.errors import PhysposeError
from physpose.shape import BodyShape
from physpose.skeleton import DOF_NAMES, NV

STEPS = 200  # 1 s


@pytest.fixture(scope="module")
def body():
    return build_body(BodyShape.from_height(1.75))


def _still(q: np.ndarray, dt: float, steps: int = STEPS) -> Reference:
    qpos = np.tile(q, (steps + 1, 1))
    return Reference(dt=dt, qpos=qpos, qvel=np.zeros((steps + 1, NV)),
                     qacc=np.zeros((steps + 1, NV)))


def test_feedback_pulls_a_pushed_body_back_over_its_feet(body):
    sim = sim_model(body)
    q0 = standing_qpos(body)
    push = np.zeros(NV)
    push[0] = 0.25  # m/s forward: held targets alone let the body lean away
    state0 = make_state(sim, q0, push)
    ctrl = np.tile(q0[7:], (1, STEPS, 1))
    plan = balance_plan(sim.model, _still(q0, sim.dt), 0, STEPS, body.foot_geom_ids, body.kp,
                        BalanceGains(frequency=1.5))
    with Simulator(sim, nthread=1) as simulator:
        free = simulator.run(state0, ctrl)
        held = simulator.run(state0, ctrl, [(slice(0, 1), plan)])
        replay = simulator.run(state0, held.ctrl)
    assert not free.broken.any() and not held.broken.any()
    start = free.sensors[0, 0, -3:2 - 3]

    def drift(traj):
        return np.linalg.norm(traj.sensors[0, -1, -3:-1] - start)

    assert drift(held) < 0.5 * drift(free), (drift(held), drift(free))
    # Only the ankles are steered, and the applied targets are what a plain rollout replays.
    moved = np.flatnonzero(np.abs(held.ctrl[0] - ctrl[0]).max(axis=0) > 0)
    assert {DOF_NAMES[k].split("_")[1] for k in moved} == {"ankle"}
    np.testing.assert_allclose(replay.states, held.states, atol=1e-9)


def test_only_standing_legs_get_gains(body):
    sim = sim_model(body)
    q = standing_qpos(body)
    q[7 + DOF_NAMES.index("l_hip_y")] -= 0.6  # left thigh forward, left knee bent: foot up
    q[7 + DOF_NAMES.index("l_knee_y")] += 1.0
    plan = balance_plan(sim.model, _still(q, sim.dt, 20), 0, 20, body.foot_geom_ids, body.kp,
                        BalanceGains(frequency=1.0, interval=5))
    assert plan.starts.tolist() == [0, 5, 10, 15]
    rows = np.abs(plan.gain).max(axis=(0, 2)) > 0
    sides = {DOF_NAMES[k][:2] for k in np.flatnonzero(rows)}
    assert sides == {"r_"}, sides
    # No error, no offset; the offsets are clipped.
    com = plan.com[:1]
    assert np.all(plan.offsets(0, com, plan.com_vel[:1]) == 0)
    far = plan.offsets(0, com + np.array([[5.0, 0.0, 0.0]]), plan.com_vel[:1])
    assert np.abs(far).max() == pytest.approx(plan.max_offset)


def test_feedback_fades_out_while_the_reference_moves_fast(body):
    sim = sim_model(body)
    q = standing_qpos(body)
    gains = BalanceGains(frequency=1.0, interval=5, max_speed=0.8)

    def gain(speed):
        ref = _still(q, sim.dt, 20)
        ref.qpos[:, 0] += speed * sim.dt * np.arange(21)  # the whole body glides forward
        return balance_plan(sim.model, ref, 0, 20, body.foot_geom_ids, body.kp, gains).gain

    still, slow, half, fast = gain(0.0), gain(0.3), gain(0.6), gain(1.0)
    assert np.abs(still).max() > 0
    np.testing.assert_allclose(slow, still, atol=1e-9)          # under max_speed / 2: full
    np.testing.assert_allclose(half[1:3], 0.5 * still[1:3], rtol=1e-6, atol=1e-9)
    assert np.all(fast == 0)


def test_gains_are_checked():
    with pytest.raises(PhysposeError):
        BalanceGains(frequency=-1.0)
    with pytest.raises(PhysposeError):
        BalanceGains(interval=0)
    with pytest.raises(PhysposeError, match="max_speed"):
        BalanceGains(max_speed=0.0)
    assert not BalanceGains().enabled and BalanceGains(frequency=1.0).enabled
