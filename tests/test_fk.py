"""Forward kinematics: JAX and NumPy agree with MuJoCo's own; batched, jit-able, differentiable."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from body_fixtures import SHAPES

from physpose.body import build_body
from physpose.fk import (angles_from_matrices, fk, fk_mujoco, fk_qpos, matrices_from_angles,
                         matrix_from_quat)
from physpose.joints import JOINT_INDEX, joints_from_landmarks
from physpose.skeleton import BONE_INDEX, DOF_LIMITS, DOF_NAMES, NUM_DOF


def _random_qpos(rng: np.random.Generator, n: int) -> np.ndarray:
    quat = rng.normal(size=(n, 4))
    quat /= np.linalg.norm(quat, axis=1, keepdims=True)
    angles = rng.uniform(DOF_LIMITS[:, 0], DOF_LIMITS[:, 1], size=(n, NUM_DOF))
    return np.concatenate([rng.uniform(-2, 2, size=(n, 3)), quat, angles], axis=1)


_FK_BATCH = jax.jit(jax.vmap(fk, in_axes=(None, 0, 0, 0)))


@pytest.mark.parametrize("name", sorted(SHAPES))
def test_jax_fk_matches_mujoco_on_random_poses(name):
    shape = SHAPES[name]
    q = _random_qpos(np.random.default_rng(len(name)), 64)
    ref_joints, ref_landmarks = fk_mujoco(build_body(shape), q)
    joints, landmarks = _FK_BATCH(jnp.asarray(shape.bones()), jnp.asarray(q[:, :3]),
                                  jnp.asarray(q[:, 3:7]), jnp.asarray(q[:, 7:]))
    assert joints.shape == (64, 21, 3) and landmarks.shape == (64, 33, 3)
    assert np.abs(np.asarray(joints) - ref_joints).max() < 1e-5
    assert np.abs(np.asarray(landmarks) - ref_landmarks).max() < 1e-5
    np_joints, np_landmarks = fk_qpos(shape.bones(), q)  # NumPy path, float64
    assert np.abs(np_joints - ref_joints).max() < 1e-12
    assert np.abs(np_landmarks - ref_landmarks).max() < 1e-12


def test_gradients_are_the_chain_derivatives():
    shape = SHAPES["tall"]
    knee, k = JOINT_INDEX["l_knee"], DOF_NAMES.index("l_hip_y")

    def left_knee(bones, angles):
        return fk(bones, jnp.zeros(3), jnp.array([1.0, 0, 0, 0]), angles)[0][knee]

    bones, angles = jnp.asarray(shape.bones()), jnp.zeros(NUM_DOF)
    d_bones = np.asarray(jax.jacfwd(left_knee, 0)(bones, angles))
    d_angles = np.asarray(jax.jacfwd(left_knee, 1)(bones, angles))
    assert np.allclose(d_bones[:, BONE_INDEX["thigh"]], [0, 0, -1])
    assert np.allclose(d_bones[:, BONE_INDEX["hip_width"]], [0, 0.5, 0])
    assert np.allclose(d_bones[:, BONE_INDEX["shank"]], 0)
    # Rotating the hip by +y about the hip swings the knee backwards by thigh length per rad.
    assert np.allclose(d_angles[:, k], [-shape.thigh, 0, 0], atol=1e-6)
    assert np.allclose(np.delete(d_angles, [k, k + 1, k + 2], axis=1), 0)


def test_root_rotation_as_matrix_or_quaternion():
    rng = np.random.default_rng(3)
    q = _random_qpos(rng, 5)
    bones = SHAPES["short"].bones()
    a = fk(bones, q[:, :3], q[:, 3:7], q[:, 7:])
    b = fk(bones, q[:, :3], matrix_from_quat(q[:, 3:7]), q[:, 7:])
    assert np.allclose(a[0], b[0]) and np.allclose(a[1], b[1])


def test_angles_matrices_round_trip():
    rng = np.random.default_rng(4)
    ang = rng.uniform(-np.pi, np.pi, size=(10, NUM_DOF))
    ang[:, 1::3] = rng.uniform(-1.5, 1.5, size=(10, NUM_DOF // 3))  # middle axis in (-pi/2, pi/2)
    rot = matrices_from_angles(ang)
    assert np.allclose(rot @ np.swapaxes(rot, -1, -2), np.eye(3), atol=1e-12)
    assert np.allclose(angles_from_matrices(rot), ang, atol=1e-9)


def test_proxy_joints_follow_the_landmarks_in_any_pose():
    q = _random_qpos(np.random.default_rng(5), 8)
    joints, landmarks = fk_qpos(SHAPES["heavy"].bones(), q)
    proxies = joints_from_landmarks(landmarks)
    for name in ("pelvis", "thorax", "head", "l_knee", "r_wrist", "l_ankle"):
        i = JOINT_INDEX[name]
        assert np.allclose(joints[:, i], proxies[:, i], atol=1e-12), name
