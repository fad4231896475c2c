"""Objective terms on hand-made motions: zero when the motion is the target, positive otherwise;
invalid samples are recognised and ranked below valid ones."""

from __future__ import annotations

import numpy as np
import pytest

from physpose.body import build_body, standing_qpos
from physpose.dynamics.objective import (FOOT_LANDMARKS, TERMS, ObjectiveWeights, evaluate_terms,
                                         invalid_from, joint_quaternions, make_reference, project,
                                         total)
from physpose.dynamics.rollout import FrameSamples
from physpose.dynamics.synthetic import virtual_camera
from physpose.dynamics.windows import Scores, ranked_fitness
from physpose.errors import PhysposeError
from physpose.fk import fk_mujoco
from physpose.shape import BodyShape
from physpose.skeleton import DOF_LIMITS, DOF_NAMES

FPS = 25.0
FRAMES = 10


@pytest.fixture(scope="module")
def scene():
    """A body, a slow knee-bend motion (T, 55) as the kinematic estimate, its reference."""
    body = build_body(BodyShape.from_height(1.75))
    q0 = standing_qpos(body)
    qpos = np.tile(q0, (FRAMES, 1))
    bend = 0.3 * np.linspace(0.0, 1.0, FRAMES) ** 2  # constant angular acceleration
    for side in "lr":
        qpos[:, 7 + DOF_NAMES.index(f"{side}_knee_y")] += bend
        qpos[:, 7 + DOF_NAMES.index(f"{side}_hip_y")] -= 0.5 * bend
    K, T = virtual_camera()
    _, landmarks = fk_mujoco(body, qpos)
    uv = project(landmarks, K, T)
    keypoints = np.concatenate([uv, np.full(uv.shape[:-1] + (1,), 0.9)], axis=-1)
    ref = make_reference(body.model, qpos, keypoints, K, T, FPS)
    return body, qpos, ref


def samples_of(body, qpos: np.ndarray) -> FrameSamples:
    """A batch of one: the motion qpos (F, 55) as a rollout would report it."""
    joints, landmarks = fk_mujoco(body, qpos)
    from physpose.dynamics.objective import centre_of_mass
    return FrameSamples(qpos=qpos[None], landmarks=landmarks[None], joints=joints[None],
                        com=centre_of_mass(body.model, qpos)[None],
                        broken=np.zeros((1, len(qpos)), dtype=bool))


def test_tracking_terms_vanish_on_the_target_and_grow_off_it(scene):
    body, qpos, ref = scene
    frames = np.arange(FRAMES)
    exact = evaluate_terms(samples_of(body, qpos), ref, frames)
    for name in ("com", "pose", "reprojection", "lim"):
        assert exact[name][0] == pytest.approx(0.0, abs=1e-9), name
    moved = qpos.copy()
    moved[1:, 0] += 0.05  # root 5 cm forward from frame 1 on
    moved[1:, 7 + DOF_NAMES.index("l_elbow_y")] -= 0.4
    off = evaluate_terms(samples_of(body, moved), ref, frames)
    for name in ("com", "pose", "reprojection"):
        assert off[name][0] > 1e-3, name


def test_pose_term_is_half_the_rotation_angle(scene):
    body, qpos, ref = scene
    moved = qpos.copy()
    moved[:, 7 + DOF_NAMES.index("r_shoulder_z")] += 0.2
    terms = evaluate_terms(samples_of(body, moved), ref, np.arange(FRAMES))
    assert terms["pose"][0] == pytest.approx(0.1, rel=1e-6)
    q = joint_quaternions(qpos)
    np.testing.assert_allclose(np.linalg.norm(q, axis=-1), 1.0)


def test_prior_zero_at_neutral_pose_and_positive_when_bent(scene):
    body, qpos, ref = scene
    neutral = np.tile(qpos[0], (FRAMES, 1))
    neutral[:, 7:] = np.clip(0.0, DOF_LIMITS[:, 0], DOF_LIMITS[:, 1])
    terms = evaluate_terms(samples_of(body, neutral), ref, np.arange(FRAMES))
    assert terms["prior"][0] == pytest.approx(0.0, abs=1e-12)
    assert evaluate_terms(samples_of(body, qpos), ref, np.arange(FRAMES))["prior"][0] > 0.01


def test_tv_zero_for_constant_acceleration_and_positive_for_jerks(scene):
    body, qpos, ref = scene
    frames = np.arange(FRAMES)
    glide = np.tile(qpos[0], (FRAMES, 1))
    glide[:, 0] += 0.5 * 0.8 * (frames / FPS) ** 2  # constant acceleration 0.8 m/s^2
    assert evaluate_terms(samples_of(body, glide), ref, frames)["tv"][0] == pytest.approx(0, abs=1e-9)
    jerky = glide.copy()
    jerky[::2, 0] += 0.01
    assert evaluate_terms(samples_of(body, jerky), ref, frames)["tv"][0] > 0.1


def test_limit_term_zero_inside_and_exponential_outside(scene):
    body, qpos, ref = scene
    frames = np.arange(FRAMES)
    k = DOF_NAMES.index("l_knee_y")
    values = []
    for excess in (0.05, 0.1):
        over = qpos.copy()
        over[:, 7 + k] = DOF_LIMITS[k, 1] + excess
        values.append(evaluate_terms(samples_of(body, over), ref, frames)["lim"][0])
    assert values[0] > 0 and values[1] > 2 * values[0]


@pytest.fixture(scope="module")
def stepping(scene):
    """The standing body with its left foot lifted (hip and knee flexion) in the last 6 frames."""
    body, qpos, _ = scene
    step = np.tile(standing_qpos(body), (FRAMES, 1))
    lift = np.r_[np.zeros(4), np.linspace(0.7, 1.0, FRAMES - 4)]
    step[:, 7 + DOF_NAMES.index("l_hip_y")] -= lift
    step[:, 7 + DOF_NAMES.index("l_knee_y")] += 1.5 * lift
    K, T = virtual_camera()
    uv = project(fk_mujoco(body, step)[1], K, T)
    keypoints = np.concatenate([uv, np.full(uv.shape[:-1] + (1,), 0.9)], axis=-1)
    return body, step, make_reference(body.model, step, keypoints, K, T, FPS)


def test_swing_mask_marks_the_lifted_foot_only(stepping):
    _, _, ref = stepping
    assert not ref.swing[:4].any() and not ref.swing[:, 1].any()  # standing, and the right foot
    assert ref.swing[4:, 0].all()


def test_swing_term_follows_the_lifted_foot_but_not_the_root_or_standing_feet(stepping):
    body, step, ref = stepping
    frames = np.arange(FRAMES)
    exact = evaluate_terms(samples_of(body, step), ref, frames)["swing"][0]
    assert exact == pytest.approx(0.0, abs=1e-9)
    shifted = step.copy()
    shifted[:, :2] += [0.2, -0.1]  # the whole body elsewhere on the floor: the same steps
    right_knee = step.copy()
    right_knee[:, 7 + DOF_NAMES.index("r_knee_y")] += 0.3  # the standing foot moves
    for same in (shifted, right_knee):
        assert evaluate_terms(samples_of(body, same), ref, frames)["swing"][0] == pytest.approx(
            0.0, abs=1e-9)
    lowered = step.copy()
    lowered[:, 2] -= 0.05  # the swing foot 5 cm lower in every swing frame
    swing_frames = ref.swing[1:, 0].sum()
    assert evaluate_terms(samples_of(body, lowered), ref, frames)["swing"][0] == pytest.approx(
        0.05 * swing_frames / (FRAMES - 1), rel=1e-6)


def test_swing_confidence_asks_less_of_a_foot_the_detector_barely_sees(stepping):
    """With swing_confidence, a swing foot-frame weighs its ankle, heel and toe detections'
    mean confidence: a lowered swing foot costs in proportion, per foot and frame."""
    body, step, ref = stepping
    K, T = virtual_camera()
    keypoints = ref.keypoints2d.copy()
    left = list(FOOT_LANDMARKS[0])
    keypoints[:, left, 2] = 0.9
    keypoints[-2:, left, 2] = [0.0, 0.3, 0.6]  # the last two frames barely seen
    weighted = make_reference(body.model, step, keypoints, K, T, FPS, swing_confidence=True)
    expected = ref.swing[:, 0] * keypoints[:, left, 2].mean(axis=-1)
    np.testing.assert_allclose(weighted.swing[:, 0], expected)
    assert not weighted.swing[:, 1].any()  # a standing foot stays unweighted at any confidence
    frames = np.arange(FRAMES)
    lowered = step.copy()
    lowered[:, 2] -= 0.05
    cost = evaluate_terms(samples_of(body, lowered), weighted, frames)["swing"][0]
    assert cost == pytest.approx(0.05 * expected[1:].sum() / (FRAMES - 1), rel=1e-6)
    assert cost < evaluate_terms(samples_of(body, lowered), ref, frames)["swing"][0]


def test_weights_skip_terms_and_total_is_the_weighted_sum(scene):
    body, qpos, ref = scene
    moved = qpos.copy()
    moved[:, 0] += 0.1
    s = samples_of(body, moved)
    weights = ObjectiveWeights(com=2.0, pose=0.0)
    terms = evaluate_terms(s, ref, np.arange(FRAMES), weights=weights)
    assert terms["pose"][0] == 0.0 and terms["com"][0] > 0
    assert total(terms, weights)[0] == pytest.approx(
        sum(getattr(weights, n) * terms[n][0] for n in TERMS))
    with pytest.raises(PhysposeError, match="ObjectiveWeights.com=-1.0 must be finite and >= 0"):
        ObjectiveWeights(com=-1.0)


def test_invalid_samples_are_found_and_ranked_below_valid_ones(scene):
    body, qpos, ref = scene
    frames = np.arange(FRAMES)
    good = samples_of(body, qpos)
    far = qpos.copy()
    far[6:, 0] += 2.0
    broken = samples_of(body, qpos)
    flags = broken.broken.copy()
    flags[0, 3:] = True
    broken = FrameSamples(broken.qpos, broken.landmarks, broken.joints, broken.com, flags)
    sunk = qpos.copy()
    sunk[4:, 2] -= 1.5
    batch = [good, samples_of(body, far), broken, samples_of(body, sunk)]
    first = [invalid_from(s, ref, frames, 1.0, 0.1)[0] for s in batch]
    assert first == [FRAMES, 6, 3, 4]
    scores = Scores(terms={}, total=np.array([5.0, np.inf, np.inf, np.inf, 3.0]),
                    invalid_from=np.array([FRAMES, 6, 3, 4, FRAMES]))
    fitness = ranked_fitness(scores, FRAMES)
    assert np.isfinite(fitness).all()
    order = np.argsort(fitness)
    assert list(order) == [4, 0, 1, 3, 2]  # valid by loss, then the latest failure first
