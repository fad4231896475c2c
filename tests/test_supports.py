"""Supports physpose adds to the scene where the estimate shows the person held up by
something it was not told about."""

from __future__ import annotations

import numpy as np
import pytest

from physpose import diagnostics, supports
from physpose.body import build_body
from physpose.dynamics.synthetic import simulated_clip
from physpose.metrics import foot_points
from physpose.shape import BodyShape


@pytest.fixture(scope="module")
def standing():
    fit, _, _ = simulated_clip(build_body(BodyShape.from_height(1.7)), "stand", seconds=2.0)
    return fit.joints, fit.fps


def test_a_box_under_feet_that_stay_raised(standing):
    joints, fps = standing
    up = joints.copy()
    up[10:40, :, 2] += 1.5                     # 1.2 s on a 1.5 m high box
    (run,) = diagnostics.raised_runs(up, fps)
    # The support physpose adds there: on the floor, its top under the feet, around them.
    (box,) = supports.support_boxes(up, [run], fps)
    top = box.center[2] + box.size[2] / 2
    assert box.center[2] == pytest.approx(box.size[2] / 2)
    lowest = foot_points(up[10:40])[..., 2].min()
    assert lowest - 0.02 < top <= up[10:40, :, 2].min() + 0.01
    soles = foot_points(up[10:40]).reshape(-1, 3)
    half = np.array(box.size[:2]) / 2
    assert (np.abs(soles[:, :2] - box.center[:2]) <= half - 0.29).all()
    # A stretch that ends in a leap off the support: the box is where the feet rested.
    leap = up.copy()
    leap[32:40, :, 0] += np.linspace(0.2, 1.6, 8)[:, None]
    (box2,) = supports.support_boxes(leap, [run], fps)
    assert box2.center[0] + box2.size[0] / 2 < box.center[0] + box.size[0] / 2 + 0.25
