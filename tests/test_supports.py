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


def test_support_heights_are_the_box_top_where_the_feet_are_on_it(standing):
    joints, fps = standing
    up = joints.copy()
    up[10:40, :, 2] += 1.5
    up[10:12, :, 2] -= 0.6                     # stepping up: feet still below the top
    (run,) = diagnostics.raised_runs(up, fps)
    (box,) = supports.support_boxes(up, [run], fps)
    heights = supports.support_heights(up, [run], fps)
    assert heights[12:40] == pytest.approx(box.center[2] + box.size[2] / 2)
    assert (heights[:12] == 0).all() and (heights[40:] == 0).all()
    assert (supports.support_heights(joints, [], fps) == 0).all()
    # A box built where the kinematic fit stood the feet takes the fit's top.
    (fitted,) = supports.support_boxes(up, [run], fps, np.where(heights > 0, 1.45, 0.0))
    assert fitted.center[2] + fitted.size[2] / 2 == pytest.approx(1.45)
    assert fitted.size[:2] == box.size[:2]


@pytest.fixture(scope="module")
def sitting():
    from physpose.dynamics.synthetic import sitting_scene
    bare = build_body(BodyShape.from_height(1.75))
    seated = build_body(bare.shape, sitting_scene(bare))
    fit, _, _ = simulated_clip(seated, "sit", seconds=3.0)
    return fit.joints, fit.fps, sitting_scene(bare).obstacles[0]


def test_feet_hanging_from_a_seat_are_not_stood_on_anything(sitting):
    joints, fps, _ = sitting
    high = joints.copy()
    high[..., 2] += 0.5                        # on a wall, the feet hanging half a metre up
    runs = diagnostics.raised_runs(high, fps)
    assert runs and supports.seated_runs(high, fps)
    seated = np.zeros(len(high), bool)
    for a, b, _ in supports.seated_runs(high, fps):
        seated[a:b + 1] = True
    assert (supports.support_heights(high, runs, fps)[seated] == 0).all()


def test_a_seat_under_a_person_who_sits(sitting, standing):
    joints, fps, true_seat = sitting
    (run,) = supports.seated_runs(joints, fps)
    first, last, top = run
    assert (last - first + 1) / fps >= 1.0 and last == len(joints) - 1
    true_top = true_seat.center[2] + true_seat.size[2] / 2
    assert true_top - 0.03 < top <= true_top + 0.01      # under the thighs, not in them
    (seat,) = supports.seat_boxes(joints, [run])
    assert seat.center[2] + seat.size[2] / 2 == pytest.approx(top)
    # The hips are over the seat; the feet are in front of it, clear of it.
    c, s = np.cos(seat.yaw), np.sin(seat.yaw)
    local = lambda p: np.array([[c, s], [-s, c]]) @ (p[:2] - np.array(seat.center[:2]))  # noqa: E731
    from physpose.joints import JOINT_INDEX as J
    for name in ("l_hip", "r_hip"):
        assert (np.abs(local(joints[last, J[name]])) < np.array(seat.size[:2]) / 2).all()
    for name in ("l_heel", "r_heel", "l_toe", "r_toe"):
        assert local(joints[last, J[name]])[0] > seat.size[0] / 2
    # Standing, stepping, and the sitting pose lowered onto the floor (lying, sitting on it)
    # get no seat.
    assert supports.seated_runs(standing[0], standing[1]) == []
    low = joints.copy()
    low[..., 2] -= 0.35
    assert supports.seated_runs(low, fps) == []
    assert supports.seat_boxes(joints, []) == ()


def test_a_box_prints_as_the_obstacle_option_reads_it():
    from physpose.scene import Box, parse_obstacle
    box = Box(center=(0.1, -0.25, 0.4), size=(0.5, 0.45, 0.1), yaw=np.radians(30))
    assert box.spec() == "box:0.10,-0.25,0.40,0.50,0.45,0.10,30"
    again = parse_obstacle(box.spec())
    assert again.center == pytest.approx(box.center) and again.yaw == pytest.approx(box.yaw)
    assert Box(center=(0, 0, 0.5), size=(1, 1, 1)).spec() == "box:0.00,0.00,0.50,1.00,1.00,1.00"
