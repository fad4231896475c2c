"""The shared skeleton definition: sizes, names, limits, landmark placement, rest pose."""

from __future__ import annotations

import numpy as np
import pytest

from physpose.fk import fk
from physpose.joints import JOINT_NAMES, LANDMARK_NAMES, joints_from_landmarks
from physpose.shape import HEAD_TOP_PER_EAR_WIDTH, BodyShape, stature_from_bones
from physpose.skeleton import (ACTUATED_SEGMENTS, AXES, BONE_NAMES, DOF_LIMITS, DOF_NAMES,
                               DOF_TORQUE, LANDMARK_PARENTS, LANDMARK_SITES, NQ, NUM_DOF, NV,
                               PARENTS, SEGMENT_INDEX, SEGMENT_NAMES, SEGMENTS,
                               landmark_offsets, rest_positions)


def test_sixteen_three_axis_joints_make_48_dof():
    assert len(ACTUATED_SEGMENTS) == 16 and NUM_DOF == 48 and NQ == 55 and NV == 54
    assert DOF_NAMES == tuple(f"{s}_{a}" for s in ACTUATED_SEGMENTS for a in AXES)
    assert len(set(DOF_NAMES)) == 48
    assert set(SEGMENT_NAMES) <= set(JOINT_NAMES)


def test_parents_precede_children():
    assert PARENTS[0] == -1
    assert all(0 <= p < i for i, p in enumerate(PARENTS) if i > 0)


def test_limits_contain_rest_pose_and_mirror_left_right():
    lo, hi = DOF_LIMITS.T
    assert np.all(lo < 0) and np.all(hi > 0) and np.all(lo >= -np.pi) and np.all(hi <= np.pi)
    for k, name in enumerate(DOF_NAMES):
        if name.startswith("l_"):
            r = DOF_NAMES.index("r_" + name[2:])
            if name.endswith("_y"):
                assert np.allclose(DOF_LIMITS[r], DOF_LIMITS[k])
            else:
                assert np.allclose(DOF_LIMITS[r], -DOF_LIMITS[k][::-1])
            assert DOF_TORQUE[r] == DOF_TORQUE[k]
    # Knees bend backwards only (+y), elbows forwards only (-y), within a few degrees.
    assert DOF_LIMITS[DOF_NAMES.index("l_knee_y")][0] > -0.1
    assert DOF_LIMITS[DOF_NAMES.index("l_elbow_y")][1] < 0.1


def test_strongest_and_weakest_joints():
    by_joint = {s.name: s.torque for s in SEGMENTS[1:]}
    assert max(by_joint, key=by_joint.get) in ("l_hip", "spine")
    assert by_joint["l_hip"] >= by_joint["l_knee"] >= by_joint["l_shoulder"] >= by_joint["l_wrist"]
    assert 200 <= by_joint["l_hip"] <= 300 and 10 <= by_joint["l_wrist"] <= 30
    assert 10 <= by_joint["head"] <= 30


def test_every_landmark_has_a_site_on_a_segment():
    assert set(LANDMARK_SITES) == set(LANDMARK_NAMES)
    assert all(parent in SEGMENT_INDEX for parent, _ in LANDMARK_SITES.values())


def test_rest_pose_geometry():
    shape = BodyShape.from_height(1.75)
    bones = shape.bones()
    pos = rest_positions(bones)
    off = landmark_offsets(bones)
    lm = pos[list(LANDMARK_PARENTS)] + off
    at = {n: lm[i] for i, n in enumerate(LANDMARK_NAMES)}
    for name in LANDMARK_NAMES:  # the person's left is +y
        if name.startswith("left") or name == "mouth_left":
            assert at[name][1] > 0, name
    assert at["nose"][0] > at["left_ear"][0] + 0.05          # faces +x
    assert at["left_foot_index"][0] > at["left_heel"][0] + 0.15
    assert at["left_wrist"][2] < at["left_elbow"][2] < at["left_shoulder"][2]  # arms hang down
    # Standing chain from the soles to the top of the head is the stature.
    sole = pos[SEGMENT_INDEX["l_ankle"], 2] - shape.ankle_height
    head_top = pos[SEGMENT_INDEX["head"], 2] + HEAD_TOP_PER_EAR_WIDTH * shape.ear_width
    assert head_top - sole == pytest.approx(stature_from_bones(bones)) == pytest.approx(1.75)


def test_trunk_joints_match_the_landmark_proxies_in_the_rest_pose():
    bones = BodyShape.from_height(1.6).bones()
    q = np.array([1.0, 0, 0, 0])
    joints, landmarks = fk(bones, np.zeros(3), q, np.zeros(NUM_DOF))
    proxies = joints_from_landmarks(landmarks)
    foot = [i for i, n in enumerate(JOINT_NAMES) if n[2:] in ("heel", "toe")]
    rest = [i for i in range(len(JOINT_NAMES)) if i not in foot]
    assert np.allclose(joints[rest], proxies[rest], atol=1e-12)


def test_heel_and_toe_joints_lie_on_the_sole_below_their_landmarks():
    shape = BodyShape.from_height(1.7)
    joints, landmarks = fk(shape.bones(), np.zeros(3), np.array([1.0, 0, 0, 0]), np.zeros(NUM_DOF))
    proxies = joints_from_landmarks(landmarks)
    sole_z = joints[JOINT_NAMES.index("l_ankle"), 2] - shape.ankle_height
    for name in ("l_heel", "r_heel", "l_toe", "r_toe"):
        i = JOINT_NAMES.index(name)
        assert joints[i, 2] == pytest.approx(sole_z, abs=1e-12)
        assert np.allclose(joints[i, :2], proxies[i, :2], atol=1e-12)  # straight below
        assert proxies[i, 2] > joints[i, 2] + 0.01


def test_bone_names_are_the_shape_fields():
    shape = BodyShape.from_height(1.8)
    assert [getattr(shape, n) for n in BONE_NAMES] == list(shape.bones())
