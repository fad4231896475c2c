"""Poses of the simulated body over time: MJCF + qpos -> world poses of every body and geom.

Every output that draws or exports the capsule body (BVH, glTF, overlay, report) reads it
through `body_motion`, so they all agree on the body tree and on what a frame looks like.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from physpose.errors import PhysposeError
from physpose.reconstruction import Reconstruction

# MuJoCo geom types drawn and exported, by the name the outputs use.
GEOM_KINDS: dict[int, str] = {
    int(mujoco.mjtGeom.mjGEOM_SPHERE): "sphere",
    int(mujoco.mjtGeom.mjGEOM_CAPSULE): "capsule",
    int(mujoco.mjtGeom.mjGEOM_ELLIPSOID): "ellipsoid",
    int(mujoco.mjtGeom.mjGEOM_CYLINDER): "cylinder",
    int(mujoco.mjtGeom.mjGEOM_BOX): "box",
}


@dataclass(frozen=True)
class GeomShape:
    """One solid of the body, in its body's frame (MuJoCo sizes: radius, half-lengths; metres)."""

    name: str
    body: int            # index into BodyTree.names, or -1 for a static scene geom (world frame)
    kind: str            # one of GEOM_KINDS' values
    size: tuple[float, float, float]
    pos: tuple[float, float, float]
    quat: tuple[float, float, float, float]  # w, x, y, z
    rgba: tuple[float, float, float, float]


@dataclass(frozen=True)
class BodyTree:
    """The articulated character: bodies below the free root, parents before children."""

    names: tuple[str, ...]
    parents: tuple[int, ...]     # index into names; -1 for the root
    geoms: tuple[GeomShape, ...]  # the character's geoms (body >= 0)
    scene: tuple[GeomShape, ...]  # static obstacles in world coordinates (planes left out)


@dataclass(frozen=True, eq=False)
class BodyMotion:
    """World poses of the character's bodies over T frames (z up, metres)."""

    tree: BodyTree
    pos: np.ndarray    # (T, B, 3) body frame origins
    quat: np.ndarray   # (T, B, 4) body orientations, w x y z, sign-continuous over time
    com: np.ndarray    # (T, 3) centre of mass of the character

    @property
    def num_frames(self) -> int:
        return int(self.pos.shape[0])

    def local(self) -> tuple[np.ndarray, np.ndarray]:
        """Poses relative to the parent body: translations (T, B, 3), quaternions (T, B, 4)."""
        pos = self.pos.copy()
        quat = self.quat.copy()
        for b, p in enumerate(self.tree.parents):
            if p < 0:
                continue
            inv = quat_conj(self.quat[:, p])
            pos[:, b] = quat_rotate(inv, self.pos[:, b] - self.pos[:, p])
            quat[:, b] = quat_mul(inv, self.quat[:, b])
        return pos, quat

    def geom_poses(self) -> tuple[np.ndarray, np.ndarray]:
        """World poses of the character's geoms: centres (T, G, 3), quaternions (T, G, 4)."""
        body = np.array([g.body for g in self.tree.geoms], dtype=int)
        gpos = np.array([g.pos for g in self.tree.geoms], dtype=float).reshape(-1, 3)
        gquat = np.array([g.quat for g in self.tree.geoms], dtype=float).reshape(-1, 4)
        bq = self.quat[:, body]
        return self.pos[:, body] + quat_rotate(bq, gpos[None]), quat_mul(bq, gquat[None])


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of (..., 4) w-first quaternions."""
    aw, ax, ay, az = np.moveaxis(np.asarray(a, float), -1, 0)
    bw, bx, by, bz = np.moveaxis(np.asarray(b, float), -1, 0)
    return np.stack([aw * bw - ax * bx - ay * by - az * bz,
                     aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw], axis=-1)


def quat_conj(q: np.ndarray) -> np.ndarray:
    return np.asarray(q, float) * np.array([1.0, -1.0, -1.0, -1.0])


def quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate (..., 3) vectors by (..., 4) unit quaternions (w first)."""
    q = np.asarray(q, float)
    v = np.asarray(v, float)
    w, u = q[..., :1], q[..., 1:]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def quat_to_mat(q: np.ndarray) -> np.ndarray:
    """(..., 4) w-first unit quaternions -> (..., 3, 3) rotation matrices."""
    return np.stack([quat_rotate(q, e) for e in np.eye(3)], axis=-1)


def make_continuous(quat: np.ndarray) -> np.ndarray:
    """Flip signs along axis 0 so consecutive quaternions (T, ..., 4) lie in one hemisphere."""
    out = np.array(quat, dtype=float)
    for t in range(1, out.shape[0]):
        flip = np.sum(out[t] * out[t - 1], axis=-1) < 0
        out[t][flip] *= -1.0
    return out


def load_model(mjcf: str) -> mujoco.MjModel:
    """Compile an MJCF string; a broken one is a PhysposeError."""
    try:
        return mujoco.MjModel.from_xml_string(mjcf)
    except ValueError as exc:
        raise PhysposeError(f"the stored body model (body_mjcf) does not compile: {exc}",
                            remedy="re-run the reconstruction with this physpose version") from None


def body_weight(model: mujoco.MjModel) -> float:
    """N: the mass of every body in the model (the character; scenery is static) times the
    model's gravity."""
    return float(model.body_subtreemass[0]) * float(np.linalg.norm(model.opt.gravity))


def body_tree(model: mujoco.MjModel) -> BodyTree:
    """The character (subtree of the first free-jointed body) and the static scene of a model."""
    free = [j for j in range(model.njnt) if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE]
    if not free:
        raise PhysposeError("the body model has no free root joint",
                            remedy="pass a body built by physpose.body")
    root = int(model.jnt_bodyid[free[0]])
    members = [b for b in range(model.nbody) if _in_subtree(model, b, root)]
    index = {b: i for i, b in enumerate(members)}
    names = tuple(model.body(b).name or f"body{b}" for b in members)
    parents = tuple(-1 if b == root else index[int(model.body_parentid[b])] for b in members)
    geoms, scene = [], []
    for g in range(model.ngeom):
        kind = GEOM_KINDS.get(int(model.geom_type[g]))
        b = int(model.geom_bodyid[g])
        if kind is None or model.geom_rgba[g, 3] == 0:
            continue
        shape = GeomShape(name=model.geom(g).name or f"geom{g}", body=index.get(b, -1),
                          kind=kind, size=tuple(float(s) for s in model.geom_size[g]),
                          pos=tuple(float(s) for s in model.geom_pos[g]),
                          quat=tuple(float(s) for s in model.geom_quat[g]),
                          rgba=tuple(float(s) for s in model.geom_rgba[g]))
        if b in index:
            geoms.append(shape)
        elif _is_static(model, b):
            scene.append(shape)
    return BodyTree(names=names, parents=parents, geoms=tuple(geoms), scene=tuple(scene))


def _in_subtree(model: mujoco.MjModel, body: int, root: int) -> bool:
    while body > 0:
        if body == root:
            return True
        body = int(model.body_parentid[body])
    return False


def _is_static(model: mujoco.MjModel, body: int) -> bool:
    while body > 0:
        if model.body_jntnum[body] > 0:
            return False
        body = int(model.body_parentid[body])
    return True


def body_motion(mjcf: str, qpos: np.ndarray) -> BodyMotion:
    """Forward kinematics of every frame: qpos (T, nq) -> world poses of the character."""
    model = load_model(mjcf)
    qpos = np.asarray(qpos, dtype=float)
    if qpos.ndim != 2 or qpos.shape[1] != model.nq:
        raise PhysposeError(f"qpos has shape {qpos.shape}, the body model needs (T, {model.nq})",
                            remedy="re-run the reconstruction; the stored model and motion differ")
    tree = body_tree(model)
    ids = [model.body(n).id if model.body(n).name else None for n in tree.names]
    if None in ids:
        raise PhysposeError("every body of the body model must be named",
                            remedy="pass a body built by physpose.body")
    root = ids[0]
    data = mujoco.MjData(model)
    t = qpos.shape[0]
    pos = np.zeros((t, len(ids), 3))
    quat = np.zeros((t, len(ids), 4))
    com = np.zeros((t, 3))
    for i in range(t):
        data.qpos[:] = qpos[i]
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        pos[i] = data.xpos[ids]
        quat[i] = data.xquat[ids]
        com[i] = data.subtree_com[root]
    if not np.all(np.isfinite(pos)):
        bad = int(np.argwhere(~np.isfinite(pos))[0, 0])
        raise PhysposeError("the stored motion has non-finite body positions", frame=bad,
                            remedy="re-run the reconstruction")
    return BodyMotion(tree=tree, pos=pos, quat=make_continuous(quat), com=com)


def reconstruction_motion(rec: Reconstruction, which: str) -> BodyMotion | None:
    """The body motion of a result: which = 'physics' or 'kinematic'; None when not stored."""
    if which not in ("physics", "kinematic"):
        raise ValueError(f"which must be 'physics' or 'kinematic', not {which!r}")
    qpos = rec.qpos_physics if which == "physics" else rec.qpos_kinematic
    if qpos is None or rec.body_mjcf is None:
        return None
    return body_motion(rec.body_mjcf, qpos)
