"""Forward kinematics of the skeleton: JAX (differentiable, for the kinematic fit) and MuJoCo.

Both paths compute the same thing: segment frames from the root pose and the 48 hinge angles
(skeleton.DOF_NAMES order, each joint R_local = Ry(a) Rx(b) Rz(c)), then the 21 project joints
(JOINT_NAMES) and the 33 landmark sites (LANDMARK_NAMES) in world coordinates, metres.

    joints, landmarks = fk(bones, root_pos, root_rot, angles)          # one frame
    joints, landmarks = jax.vmap(fk, (None, 0, 0, 0))(bones, P, Q, A)  # T frames

The functions broadcast over leading dimensions too, so a batch works without vmap.
"""

from __future__ import annotations

import jax.numpy as jnp
import mujoco
import numpy as np

from physpose.skeleton import (JOINT_OFFSET_MATRIX, JOINT_PARENTS, LANDMARK_OFFSET_MATRIX,
                               LANDMARK_PARENTS, NQ, NUM_DOF, NUM_JOINTS3, PARENTS,
                               SEGMENT_OFFSET_MATRIX)


def _xp(*arrays):
    """NumPy for NumPy inputs, jax.numpy otherwise (tracers, jax arrays)."""
    return np if all(isinstance(a, (np.ndarray, float, int)) for a in arrays) else jnp


def matrices_from_angles(angles):
    """Joint rotations from hinge angles: (..., 48) rad -> (..., 16, 3, 3), R = Ry Rx Rz."""
    xp = _xp(angles)
    a = xp.reshape(angles, angles.shape[:-1] + (NUM_JOINTS3, 3))
    c, s = xp.cos(a), xp.sin(a)
    ca, cb, cc = c[..., 0], c[..., 1], c[..., 2]
    sa, sb, sc = s[..., 0], s[..., 1], s[..., 2]
    rows = (
        (ca * cc + sa * sb * sc, -ca * sc + sa * sb * cc, sa * cb),
        (cb * sc, cb * cc, -sb),
        (-sa * cc + ca * sb * sc, sa * sc + ca * sb * cc, ca * cb),
    )
    return xp.stack([xp.stack(r, axis=-1) for r in rows], axis=-2)


def angles_from_matrices(rot):
    """Hinge angles from joint rotations: (..., 16, 3, 3) -> (..., 48) rad (inverse of the above).

    The middle (x) angle is in [-pi/2, pi/2]; the result may lie outside the joint limits.
    """
    xp = _xp(rot)
    a = xp.arctan2(rot[..., 0, 2], rot[..., 2, 2])
    b = xp.arctan2(-rot[..., 1, 2], xp.sqrt(rot[..., 1, 0] ** 2 + rot[..., 1, 1] ** 2))
    c = xp.arctan2(rot[..., 1, 0], rot[..., 1, 1])
    ang = xp.stack([a, b, c], axis=-1)
    return xp.reshape(ang, ang.shape[:-2] + (NUM_DOF,))


def matrix_from_quat(quat):
    """Rotations from quaternions (w, x, y, z), normalised first: (..., 4) -> (..., 3, 3)."""
    xp = _xp(quat)
    q = quat / xp.linalg.norm(quat, axis=-1, keepdims=True)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    rows = (
        (1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)),
        (2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)),
        (2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)),
    )
    return xp.stack([xp.stack(r, axis=-1) for r in rows], axis=-2)


def segment_frames(bones, root_pos, root_rot, angles):
    """World frames of the 17 segments.

    bones: (13,) metres (skeleton.BONE_NAMES). root_pos: (..., 3) m. root_rot: (..., 4)
    quaternion w,x,y,z or (..., 3, 3) matrix (world from pelvis). angles: (..., 48) rad.
    Returns (positions (..., 17, 3), rotations (..., 17, 3, 3)).
    """
    xp = _xp(bones, root_pos, root_rot, angles)
    offsets = xp.einsum("skb,b->sk", xp.asarray(SEGMENT_OFFSET_MATRIX), bones)
    root_r = root_rot if root_rot.shape[-2:] == (3, 3) else matrix_from_quat(root_rot)
    local = matrices_from_angles(angles)
    pos, rot = [root_pos], [root_r]
    for i in range(1, len(PARENTS)):
        p = PARENTS[i]
        pos.append(pos[p] + xp.einsum("...kj,j->...k", rot[p], offsets[i]))
        rot.append(rot[p] @ local[..., i - 1, :, :])
    return xp.stack(pos, axis=-2), xp.stack(rot, axis=-3)


def _points(pos, rot, parents, matrix, bones, xp):
    off = xp.einsum("nkb,b->nk", xp.asarray(matrix), bones)
    idx = np.asarray(parents)
    return pos[..., idx, :] + xp.einsum("...nkj,nj->...nk", rot[..., idx, :, :], off)


def fk(bones, root_pos, root_rot, angles):
    """World positions of the 21 project joints and the 33 landmark sites.

    bones (13,), root_pos (..., 3), root_rot (..., 4) quaternion or (..., 3, 3), angles
    (..., 48) -> (joints (..., 21, 3), landmarks (..., 33, 3)), metres. Differentiable (JAX)
    in every argument; NumPy inputs give NumPy outputs.
    """
    xp = _xp(bones, root_pos, root_rot, angles)
    pos, rot = segment_frames(bones, root_pos, root_rot, angles)
    return (_points(pos, rot, JOINT_PARENTS, JOINT_OFFSET_MATRIX, bones, xp),
            _points(pos, rot, LANDMARK_PARENTS, LANDMARK_OFFSET_MATRIX, bones, xp))


def fk_qpos(bones, qpos):
    """fk from MuJoCo generalised coordinates qpos (..., 55) (skeleton layout)."""
    return fk(bones, qpos[..., 0:3], qpos[..., 3:7], qpos[..., 7:NQ])


def site_positions(model: mujoco.MjModel, site_ids, qpos: np.ndarray) -> np.ndarray:
    """World positions (T, len(site_ids), 3) m of the given sites for qpos (T, 55), from
    MuJoCo's kinematics of ``model``."""
    data = mujoco.MjData(model)
    out = np.empty((len(qpos), len(site_ids), 3))
    for t, row in enumerate(qpos):
        data.qpos[:] = row
        mujoco.mj_kinematics(model, data)
        out[t] = data.site_xpos[site_ids]
    return out


def fk_mujoco(body, qpos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The same points from MuJoCo's own kinematics of a built Body (physpose.body).

    qpos: (T, 55) or (55,) -> (joints (T, 21, 3), landmarks (T, 33, 3)) (no T for one frame).
    """
    q = np.atleast_2d(np.asarray(qpos, dtype=float))
    if q.shape[-1] != NQ:
        raise ValueError(f"qpos must have {NQ} columns, got shape {q.shape}")
    ids = np.concatenate([body.joint_site_ids, body.landmark_site_ids])
    joints, landmarks = np.split(site_positions(body.model, ids, q),
                                 [len(body.joint_site_ids)], axis=1)
    if np.ndim(qpos) == 1:
        return joints[0], landmarks[0]
    return joints, landmarks
