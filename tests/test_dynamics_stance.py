"""Stance feet flattened in the reference by leg inverse kinematics (dynamics/stance.py)."""

from __future__ import annotations

import numpy as np
import pytest
from body_fixtures import dof

from physpose.body import build_body, standing_qpos
from physpose.dynamics.init import ground_state
from physpose.dynamics.stance import (StanceConfig, flatten_stance_feet, foot_states,
                                      stance_weights)
from physpose.shape import BodyShape

FPS = 30.0


@pytest.fixture(scope="module")
def body():
    return build_body(BodyShape.from_height(1.75))


def _still(qpos: np.ndarray, frames: int = 5) -> np.ndarray:
    return np.repeat(qpos[None], frames, axis=0)


def _tilted_stance(body, ankle_pitch: float, knee: float = 0.0) -> np.ndarray:
    """Standing, knees bent by ``knee`` rad (ankles bent back so the soles stay level), the
    right foot pitched about its ankle, then grounded: it stands on one edge of its box."""
    q = standing_qpos(body)
    for side in "lr":
        q[dof(f"{side}_knee_y")] += knee
        q[dof(f"{side}_ankle_y")] -= knee
    q[dof("r_ankle_y")] += ankle_pitch
    return ground_state(body.model, q, snap=0.1)


@pytest.mark.parametrize("pitch", [0.12, -0.12])
@pytest.mark.parametrize("knee", [0.0, 0.3])
def test_a_foot_on_its_edge_is_laid_flat_on_the_floor(body, pitch, knee):
    # A straight knee is a singular start for the leg solve; both must work.
    qpos = _still(_tilted_stance(body, pitch, knee))
    centre0, lowest0, tilt0 = foot_states(body.model, qpos, body.foot_geom_ids)
    assert tilt0[0, 1] > 0.1 and abs(lowest0[0, 1]) < 1e-6  # on an edge, touching the floor
    assert np.all(lowest0 < StanceConfig().height)        # both feet count as standing

    flat = flatten_stance_feet(body.model, qpos, FPS, body.foot_geom_ids)
    centre, lowest, tilt = foot_states(body.model, flat, body.foot_geom_ids)
    assert np.all(np.degrees(tilt) < 0.5)
    assert np.all(np.abs(lowest) < 1e-3)                  # both soles on the floor
    # The feet keep their place; only the legs and the root's height move.
    assert np.all(np.linalg.norm(centre[..., :2] - centre0[..., :2], axis=-1) < 0.01)
    np.testing.assert_allclose(flat[:, :2], qpos[:, :2])
    np.testing.assert_allclose(flat[:, 3:7], qpos[:, 3:7])
    untouched = [i for i in range(7, qpos.shape[1])
                 if not any(f"{s}_{j}" in name for s in "lr" for j in ("hip", "knee", "ankle")
                            for name in [_dof_name(i)])]
    np.testing.assert_allclose(flat[:, untouched], qpos[:, untouched])


def _dof_name(qpos_index: int) -> str:
    from physpose.skeleton import DOF_NAMES  # noqa: PLC0415
    return DOF_NAMES[qpos_index - 7]


def test_swinging_and_steeply_tilted_feet_are_left_alone(body):
    raised = standing_qpos(body)
    raised[2] += 0.1                                      # both feet 10 cm up: no stance
    steep = _tilted_stance(body, 0.8)                     # 46 degrees: rolling onto the toes
    for qpos in (_still(raised), _still(steep)):
        flat = flatten_stance_feet(body.model, qpos, FPS, body.foot_geom_ids)
        right = [dof(f"r_{j}_{a}") for j in ("hip", "knee", "ankle") for a in "yxz"]
        np.testing.assert_allclose(flat[:, right], qpos[:, right])
    _, lowest, _ = foot_states(body.model, _still(raised), body.foot_geom_ids)
    assert np.all(lowest > 0.09)


def test_weights_fade_in_and_out_around_a_stance():
    frames = 12
    centre = np.zeros((frames, 2, 3))
    lowest = np.full((frames, 2), 0.2)
    lowest[4:8, 0] = 0.0                                   # left foot down for frames 4-7
    tilt = np.zeros((frames, 2))
    w = stance_weights(centre, lowest, tilt, FPS, StanceConfig(fade_frames=2))
    assert np.all(w[:, 1] == 0.0)
    assert np.all(w[:2, 0] == 0.0) and np.all(w[10:, 0] == 0.0)
    assert np.all(np.diff(w[:6, 0]) >= 0) and np.all(np.diff(w[6:, 0]) <= 0)
    assert 0.0 < w[3, 0] < w[4, 0] < w[5, 0] <= 1.0


def test_a_fast_foot_is_not_standing():
    frames = 10
    centre = np.zeros((frames, 2, 3))
    centre[:, 0, 0] = np.arange(frames) * 0.05             # 1.5 m/s at 30 fps
    w = stance_weights(centre, np.zeros((frames, 2)), np.zeros((frames, 2)), FPS,
                       StanceConfig(fade_frames=0))
    assert np.all(w[:, 0] == 0.0) and np.all(w[:, 1] == 1.0)
