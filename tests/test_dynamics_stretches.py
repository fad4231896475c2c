"""Placing the simulated stretches: bounds at the restarts, shifts that match the estimate's
COM on average, and the claim behind it, that a horizontally moved simulation is the same
simulation on a floor without obstacles."""

from __future__ import annotations

import numpy as np

from physpose.body import build_body, standing_qpos
from physpose.dynamics.rollout import Simulator, make_state, sim_model
from physpose.dynamics.stretches import (shift_stretches, stretch_bounds, stretch_shifts,
                                         translation_invariant)
from physpose.scene import SceneConfig, parse_obstacle
from physpose.shape import BodyShape
from physpose.skeleton import NV


def test_bounds_split_at_the_restarts_and_ignore_the_edges():
    assert stretch_bounds(10, []) == [(0, 10)]
    assert stretch_bounds(10, [4, 7]) == [(0, 4), (4, 7), (7, 10)]
    assert stretch_bounds(10, [0, 7, 7, 10]) == [(0, 7), (7, 10)]


def test_each_stretch_moves_by_its_own_shift_and_then_matches_the_estimate_on_average():
    rng = np.random.default_rng(0)
    t = 12
    est = rng.normal(size=(t, 3))
    com = est + np.where(np.arange(t)[:, None] < 5, [0.3, -0.1, 0.05], [-0.2, 0.4, 0.0])
    com += 0.01 * rng.normal(size=(t, 3))
    shifts = stretch_shifts(com, est, [5])
    np.testing.assert_allclose(shifts, [[-0.3, 0.1], [0.2, -0.4]], atol=0.02)
    outputs = {"qpos": rng.normal(size=(t, 55)), "com": com, "joints": rng.normal(size=(t, 21, 3)),
               "landmarks": rng.normal(size=(t, 33, 3))}
    moved = shift_stretches(outputs, [5], shifts)
    for a, b in ((0, 5), (5, t)):
        np.testing.assert_allclose(moved["com"][a:b, :2].mean(0), est[a:b, :2].mean(0))
    np.testing.assert_allclose(moved["qpos"][:5, :2] - outputs["qpos"][:5, :2],
                               np.tile(shifts[0], (5, 1)))
    np.testing.assert_allclose(moved["joints"][7, :, :2] - outputs["joints"][7, :, :2],
                               np.tile(shifts[1], (21, 1)))
    # Heights, orientation and joint angles are untouched, and the inputs are not modified.
    np.testing.assert_array_equal(moved["qpos"][:, 2:], outputs["qpos"][:, 2:])
    np.testing.assert_array_equal(moved["landmarks"][..., 2], outputs["landmarks"][..., 2])
    assert not np.shares_memory(moved["qpos"], outputs["qpos"])


def test_only_a_floor_without_obstacles_allows_moving():
    assert translation_invariant(SceneConfig())
    assert not translation_invariant(SceneConfig(obstacles=(parse_obstacle("box:1,0,0.2,1,1,0.4"),)))


def test_a_moved_simulation_is_the_same_simulation():
    body = build_body(BodyShape.from_height(1.75))
    sim = sim_model(body)
    q0 = standing_qpos(body)
    moved = q0.copy()
    moved[:2] += [0.7, -0.4]
    rng = np.random.default_rng(1)
    ctrl = q0[7:] + 0.2 * np.sin(np.linspace(0, 6, 120)[:, None] + rng.uniform(0, 6, 48))
    v0 = 0.2 * rng.normal(size=NV)
    with Simulator(sim, nthread=1) as simulator:
        a = simulator.run(make_state(sim, q0, v0), ctrl[None]).states[0]
        b = simulator.run(make_state(sim, moved, v0), ctrl[None]).states[0]
    qa, qb = a[:, 1:56], b[:, 1:56]  # the state's qpos after its time
    assert np.abs(qa[:, 2] - qa[0, 2]).max() > 0.01  # the body moved (contacts changed)
    np.testing.assert_allclose(qb[:, :2] - [0.7, -0.4], qa[:, :2], atol=1e-6)
    np.testing.assert_allclose(qb[:, 2:], qa[:, 2:], atol=1e-6)
