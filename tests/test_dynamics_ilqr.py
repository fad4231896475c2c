"""iLQR refinement of servo targets: it finds the motion a known set of targets made, from
wrong targets, and its result replays exactly open loop."""

from __future__ import annotations

import numpy as np
import pytest

from physpose.body import build_body, standing_qpos
from physpose.dynamics import ilqr
from physpose.dynamics.config import PRESETS, DynamicsConfig
from physpose.dynamics.ilqr import RefineConfig, refine_targets
from physpose.dynamics.rollout import Simulator, make_state, sim_model
from physpose.dynamics.synthetic import motion_targets
from physpose.errors import PhysposeError
from physpose.shape import BodyShape
from physpose.skeleton import DOF_NAMES, NQ, NV


@pytest.fixture(scope="module")
def stepping():
    """(sim, state0, true targets (S, 48), true states (S+1, nstate)) of 0.6 s of the
    simulated step motion (the left foot lifts from 0.45 s)."""
    body = build_body(BodyShape.from_height(1.75))
    sim = sim_model(body)
    targets = motion_targets(body, "step", 0.6)
    state0 = make_state(sim, standing_qpos(body), np.zeros(NV))
    with Simulator(sim, nthread=1) as simulator:
        states = simulator.run(state0, targets[None]).states[0]
    return sim, state0, targets, states


def _hinge_rms(states: np.ndarray, truth: np.ndarray) -> float:
    return float(np.sqrt(np.mean((states[:, 8:1 + NQ] - truth[:, 8:1 + NQ]) ** 2)))


def _landmarks(sim, states: np.ndarray) -> np.ndarray:
    """(S, 33, 3) world positions of the landmark sites at each state."""
    import mujoco  # noqa: PLC0415

    d = mujoco.MjData(sim.model)
    out = []
    for state in states:
        d.qpos[:] = state[1:1 + NQ]
        mujoco.mj_kinematics(sim.model, d)
        out.append(d.site_xpos[sim.body.landmark_site_ids].copy())
    return np.array(out)


def _crouched(targets: np.ndarray) -> np.ndarray:
    """The targets of a crouched, leaning motion instead (hips, left knee, spine +0.08 rad)."""
    wrong = targets.copy()
    for name in ("l_hip_y", "r_hip_y", "l_knee_y", "spine_y"):
        wrong[:, DOF_NAMES.index(name)] += 0.08
    return wrong


def test_refinement_finds_the_motion_from_wrong_targets(stepping):
    sim, state0, targets, truth = stepping
    wrong = _crouched(targets)
    with Simulator(sim, nthread=1) as simulator:
        start = simulator.run(state0, wrong[None]).states[0]
    qpos, qvel = truth[:, 1:1 + NQ], truth[:, 1 + NQ:1 + NQ + NV]
    refined = refine_targets(sim.model, state0, wrong, qpos, qvel, RefineConfig(iterations=4))
    assert refined.costs[-1] < 0.2 * refined.costs[0]
    assert all(b <= a for a, b in zip(refined.costs, refined.costs[1:]))  # never worse
    assert _hinge_rms(refined.states, truth) < 0.3 * _hinge_rms(start, truth)
    root_error = np.linalg.norm(refined.states[:, 1:4] - truth[:, 1:4], axis=-1)
    assert root_error.max() < 0.01  # m


def test_refined_targets_replay_the_refined_motion_exactly(stepping):
    sim, state0, targets, truth = stepping
    qpos, qvel = truth[:, 1:1 + NQ], truth[:, 1 + NQ:1 + NQ + NV]
    refined = refine_targets(sim.model, state0, targets + 0.03, qpos, qvel,
                             RefineConfig(iterations=2))
    with Simulator(sim, nthread=1) as simulator:
        replay = simulator.run(state0, refined.ctrl[None]).states[0]
    np.testing.assert_array_equal(replay, refined.states)


def test_zero_iterations_return_the_start(stepping):
    sim, state0, targets, truth = stepping
    refined = refine_targets(sim.model, state0, targets, truth[:, 1:1 + NQ],
                             truth[:, 1 + NQ:1 + NQ + NV], RefineConfig(iterations=0))
    np.testing.assert_array_equal(refined.ctrl, targets)
    assert refined.costs == [pytest.approx(0.0, abs=1e-9)]


def test_a_rejected_step_keeps_its_linearisation(stepping, monkeypatch):
    """A rejected step leaves the trajectory where it was, so the next iteration reuses its
    transition Jacobians and cost expansion: they are taken once per trajectory the
    refinement reaches."""
    sim, state0, targets, truth = stepping
    linearised, expanded = [], []
    linearise, expand = ilqr._Problem.linearise, ilqr._Problem.cost_expansion

    def counting(self, states, *args):
        linearised.append(states.copy())
        return linearise(self, states, *args)

    def counting_expansions(self, states):
        expanded.append(states.copy())
        return expand(self, states)

    monkeypatch.setattr(ilqr._Problem, "linearise", counting)
    monkeypatch.setattr(ilqr._Problem, "cost_expansion", counting_expansions)
    # Hardly damped, the first steps overshoot and are rejected (here the cost stays at its
    # start for four iterations).
    refined = refine_targets(sim.model, state0, targets + 0.03, truth[:, 1:1 + NQ],
                             truth[:, 1 + NQ:1 + NQ + NV],
                             RefineConfig(iterations=6, regularisation=1e-3))
    accepted = sum(b < a for a, b in zip(refined.costs, refined.costs[1:]))
    assert 0 < accepted < 6
    assert len(linearised) <= accepted + 1
    assert len(expanded) == len(linearised)
    for a, b in zip(linearised, linearised[1:]):
        assert not np.array_equal(a, b)


@pytest.mark.parametrize("changes", [{"iterations": -1}, {"derivative_stride": 0},
                                     {"hinge": -1.0}, {"control": float("nan")},
                                     {"keep_ratio": -1.0}, {"handover": -1.0}])
def test_bad_refine_settings_are_refused(changes):
    with pytest.raises(PhysposeError):
        RefineConfig(**changes)


def test_refinement_off_leaves_checkpoint_keys_as_they_were():
    assert "refine" not in DynamicsConfig().identity()
    assert "refine" not in PRESETS["paper"].window_identity()
    on = DynamicsConfig(refine=RefineConfig(iterations=3))
    assert on.identity()["refine"]["iterations"] == 3
    # The ratio fixed before it was a setting (1.5) keeps the keys too; any other ratio is
    # keyed, so a changed default can never reuse those earlier checkpoints.
    old = DynamicsConfig(refine=RefineConfig(iterations=3, keep_ratio=1.5))
    assert "keep_ratio" not in old.identity()["refine"]
    stricter = DynamicsConfig(refine=RefineConfig(iterations=3, keep_ratio=1.1))
    assert stricter.identity()["refine"]["keep_ratio"] == 1.1
    # Likewise the depth term, off (0) unless asked for.
    assert "root_depth" not in on.identity()["refine"]
    deep = DynamicsConfig(refine=RefineConfig(iterations=3, root_depth=900.0))
    assert deep.identity()["refine"]["root_depth"] == 900.0
    # And the handover weight, 1 (unweighted) unless asked for.
    assert "handover" not in on.identity()["refine"]
    handed = DynamicsConfig(refine=RefineConfig(iterations=3, handover=20.0))
    assert handed.identity()["refine"]["handover"] == 20.0


def test_the_handover_weight_pulls_the_next_windows_start_onto_the_reference(stepping):
    """From crouched targets, two iterations leave the motion between its start and the
    reference; weighting the state the next window would start from brings that state
    nearer the reference than the same refinement without it."""
    sim, state0, targets, truth = stepping
    wrong = _crouched(targets)
    qpos, qvel = truth[:, 1:1 + NQ], truth[:, 1 + NQ:1 + NQ + NV]
    handover = len(targets) // 2

    def error_at_handover(weight: float) -> float:
        cfg = RefineConfig(iterations=2, handover=weight)
        refined = refine_targets(sim.model, state0, wrong, qpos, qvel, cfg,
                                 handover_step=handover)
        return _hinge_rms(refined.states[handover:handover + 1], truth[handover:handover + 1])

    assert error_at_handover(50.0) < 0.7 * error_at_handover(1.0)


def test_threads_do_not_change_the_result(stepping):
    sim, state0, targets, truth = stepping
    args = (sim.model, state0, targets + 0.03, truth[:, 1:1 + NQ], truth[:, 1 + NQ:1 + NQ + NV],
            RefineConfig(iterations=1))
    one, two = refine_targets(*args, nthread=1), refine_targets(*args, nthread=2)
    np.testing.assert_array_equal(one.ctrl, two.ctrl)


def test_a_standing_foot_is_kept_from_sliding(stepping):
    """Asked to follow a reference that drags the standing right foot sideways, the foot
    slide term keeps that foot where it stands (at a cost in tracking)."""
    sim, state0, targets, truth = stepping
    qpos, qvel = truth[:, 1:1 + NQ].copy(), truth[:, 1 + NQ:1 + NQ + NV].copy()
    t = np.arange(len(qpos)) * sim.dt
    qpos[:, 1] += 0.3 * t  # the whole body drifts sideways at 0.3 m/s: standing feet slide
    qvel[:, 1] += 0.3
    foot = sim.body.foot_geom_ids["r"]
    right = int(sim.model.geom_bodyid[foot])

    def right_foot_travel(cfg: RefineConfig) -> float:
        refined = refine_targets(sim.model, state0, targets, qpos, qvel, cfg, 1, (foot,))
        import mujoco  # noqa: PLC0415
        d = mujoco.MjData(sim.model)
        xy = []
        for state in refined.states[[0, -1]]:
            d.qpos[:] = state[1:1 + NQ]
            mujoco.mj_kinematics(sim.model, d)
            xy.append(d.xpos[right, :2].copy())
        return float(np.linalg.norm(xy[1] - xy[0]))

    free = right_foot_travel(RefineConfig(iterations=3, foot_slide=0.0))
    held = right_foot_travel(RefineConfig(iterations=3, foot_slide=1e4))
    assert held < 0.5 * free


@pytest.mark.parametrize("travelling", [False, True])
def test_the_image_term_pulls_the_body_onto_the_detections(stepping, travelling):
    """The reference is the true motion moved 10 cm sideways; the detections are the true
    motion's (seen by a camera that travels 0.3 m/s forward with the person when
    ``travelling``). With the image term the refined body lands nearer the detections."""
    from physpose.dynamics.ilqr import ImageTerm  # noqa: PLC0415
    from physpose.dynamics.objective import project  # noqa: PLC0415
    from physpose.dynamics.synthetic import virtual_camera  # noqa: PLC0415

    sim, state0, targets, truth = stepping
    K, T = virtual_camera()
    sites = sim.body.landmark_site_ids

    steps = np.arange(8, len(truth), 8)
    travel = np.zeros((len(steps), 3))
    if travelling:
        travel[:, 0] = 0.3 * steps * sim.model.opt.timestep
    uv = project(_landmarks(sim, truth[steps]) - travel[:, None], K, T)
    keypoints = np.concatenate([uv, np.ones(uv.shape[:-1] + (1,))], axis=-1)
    image = ImageTerm(steps=steps, keypoints=keypoints, metres_per_px=np.full(len(steps), 0.004),
                      K=K, T_world2cam=T, site_ids=sites,
                      camera_travel=travel if travelling else None)
    qpos, qvel = truth[:, 1:1 + NQ].copy(), truth[:, 1 + NQ:1 + NQ + NV]
    qpos[:, 1] += 0.10  # the reference stands 10 cm to the side of where the person is

    def image_error(cfg: RefineConfig) -> float:
        refined = refine_targets(sim.model, state0, targets, qpos, qvel, cfg, image=image)
        seen = _landmarks(sim, refined.states[steps]) - travel[:, None]
        return float(np.linalg.norm(project(seen, K, T) - uv, axis=-1).mean())

    base = RefineConfig(iterations=3, root_position=100.0, foot_slide=0.0)
    without = image_error(base)
    with_image = image_error(RefineConfig(iterations=3, root_position=100.0, foot_slide=0.0,
                                          image=3e3))
    assert with_image < 0.7 * without


def test_the_depth_term_holds_the_root_along_the_line_of_sight(stepping):
    """The reference is the true motion moved 10 cm away from the camera, with the root
    loosely tracked: root_depth keeps the refined root nearer the reference along the line of
    sight (where the detections hardly see it) than the same refinement without it."""
    from physpose.dynamics.ilqr import ImageTerm  # noqa: PLC0415
    from physpose.dynamics.synthetic import virtual_camera  # noqa: PLC0415

    sim, state0, targets, truth = stepping
    K, T = virtual_camera()
    centre = -T[:3, :3].T @ T[:3, 3]
    qpos, qvel = truth[:, 1:1 + NQ].copy(), truth[:, 1 + NQ:1 + NQ + NV]
    sight = qpos[:, :3] - centre
    sight /= np.linalg.norm(sight, axis=1, keepdims=True)
    qpos[:, :3] += 0.10 * sight
    steps = np.arange(8, len(truth), 8)
    camera = ImageTerm(steps=steps, keypoints=np.zeros((len(steps), 33, 3)),
                       metres_per_px=np.full(len(steps), 0.004), K=K, T_world2cam=T,
                       site_ids=sim.body.landmark_site_ids)

    def depth_error(root_depth: float) -> float:
        cfg = RefineConfig(iterations=8, root_position=10.0, foot_slide=0.0,
                           root_depth=root_depth)
        refined = refine_targets(sim.model, state0, targets, qpos, qvel, cfg, image=camera)
        off = refined.states[1:, 1:4] - qpos[1:, :3]
        return float(np.abs(np.einsum("ti,ti->t", off, sight[1:])).mean())

    assert depth_error(3e3) < 0.5 * depth_error(0.0)


def test_the_image_term_projects_through_a_skewed_camera(stepping):
    """The refinement projects as the search's objective does, skew and a travelling camera
    included: zero cost on the exact projections, and a gradient that matches the cost's
    finite differences."""
    from physpose.dynamics.ilqr import ImageTerm, _Problem  # noqa: PLC0415
    from physpose.dynamics.objective import project  # noqa: PLC0415
    from physpose.dynamics.synthetic import virtual_camera  # noqa: PLC0415

    sim, state0, targets, truth = stepping
    K, T = virtual_camera()
    K = K.copy()
    K[0, 1] = 0.3 * K[0, 0]  # a strong skew, so that leaving it out shows
    sites = sim.body.landmark_site_ids
    steps = np.arange(8, len(truth), 8)
    travel = np.outer(np.arange(len(steps)), [0.02, -0.01, 0.005])  # the camera moving along
    uv = project(_landmarks(sim, truth[steps]) - travel[:, None], K, T)
    image = ImageTerm(steps=steps, keypoints=np.concatenate([uv, np.ones(uv.shape[:-1] + (1,))],
                                                            axis=-1),
                      metres_per_px=np.full(len(steps), 0.004), K=K, T_world2cam=T,
                      site_ids=sites, camera_travel=travel)
    qpos, qvel = truth[:, 1:1 + NQ], truth[:, 1 + NQ:1 + NQ + NV]
    problem = _Problem(sim.model, state0, qpos, qvel, targets, RefineConfig(image=3e3),
                       image=image)
    cost, _ = problem.image_terms(truth, derivatives=False)
    assert cost < 1e-12
    # Off the detections (the body 3 cm to the side and 2 cm up), the gradient along the
    # root's translation matches the cost's central differences.
    moved = truth.copy()
    moved[:, 1:3] += [0.03, 0.02]
    _, grads = problem.image_terms(moved, derivatives=True)
    gradient = sum(g for g, _ in grads.values())[:3]
    numeric = np.zeros(3)
    for axis in range(3):
        plus, minus = moved.copy(), moved.copy()
        plus[:, 1 + axis] += 1e-6
        minus[:, 1 + axis] -= 1e-6
        numeric[axis] = (problem.image_terms(plus, False)[0]
                         - problem.image_terms(minus, False)[0]) / 2e-6
    np.testing.assert_allclose(gradient, numeric, rtol=1e-4, atol=1e-6)


def test_the_projection_jacobian_matches_the_projection():
    """The image term's derivative of the normalised coordinates matches central differences
    of ``objective.project``, also for a point inside the clamped depth, where it is flat
    in depth."""
    from physpose.dynamics.ilqr import _normalised_jacobian  # noqa: PLC0415
    from physpose.dynamics.objective import MIN_DEPTH, project  # noqa: PLC0415

    K = np.array([[1000.0, 0.0, 0.0], [0.0, 1000.0, 0.0], [0.0, 0.0, 1.0]])
    T = np.eye(4)
    points = np.array([[0.3, -0.2, 3.0], [-1.0, 0.5, 1.2], [0.2, 0.1, 0.5 * MIN_DEPTH]])
    numeric = np.zeros((len(points), 2, 3))
    for axis in range(3):
        step = np.zeros(3)
        step[axis] = 1e-6
        numeric[:, :, axis] = (project(points + step, K, T) - project(points - step, K, T)) \
            / 2e-6 / 1000.0
    analytic = _normalised_jacobian(points)
    np.testing.assert_allclose(analytic, numeric, rtol=1e-6, atol=1e-6)
    assert np.all(analytic[2, :, 2] == 0.0)
