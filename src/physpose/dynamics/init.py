"""Starting point of the optimisation: a smoothed reference motion, its states and servo targets.

The kinematic estimate is low-passed by a least-squares cubic B-spline fit (knot spacing
``reference_knot_spacing``; root quaternions sign-aligned first), which also gives velocities
and accelerations analytically on the 200 Hz simulation grid. Initial states take positions and
velocities from it (velocities are the derivative of the fit: finite differences of the
estimate, low-passed).

Initial servo targets follow the recipe measured in DESIGN.md ("Measured pitfalls"): inverse
dynamics (``mj_inverse``) of the smoothed motion with contacts disabled gives the generalised
force the motion needs; the part on the free root (a force and torque no motor can make) is
explained by ground forces at the sole points that are near the floor, solved as non-negative
least squares on the edges of a linearised friction cone; what remains on the hinges is the
motor torque, clipped to its limit, and the target that makes the servo produce it follows from the servo law in the model
(``q + tau / kp`` for position servos whose damping is passive). A least-squares spline fit of these targets (clipped to the joint
limits) gives the initial coefficients. The root force the ground forces leave unexplained is
kept as a measure of how far the estimate is from a motion the body can make.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import mujoco
import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.optimize import nnls

from physpose.dynamics import quat
from physpose.dynamics.spline import KnotGrid, fit_coefficients
from physpose.skeleton import DOF_LIMITS, NQ, NV

FRICTION_EDGES = 4        # sides of the friction pyramid (friction_pyramid builds 4)
CONE_MARGIN = 0.8         # use this fraction of the friction coefficient (inside the cone)
_FORCE_REGULARISER = 1e-6  # relative weight of |beta|^2 for a sole point on the floor
_HEIGHT_SCALE = 0.01      # m: a point this high above the floor costs (1 + 1)^2 = 4x as much


@dataclass(frozen=True, eq=False)
class Reference:
    """The smoothed kinematic motion on the simulation grid, step times n * dt (s).

    qpos (N+1, 55), qvel (N+1, 54), qacc (N+1, 54): MuJoCo coordinates (root angular velocity
    and acceleration in the pelvis frame).
    """

    dt: float
    qpos: np.ndarray
    qvel: np.ndarray
    qacc: np.ndarray

    @property
    def num_steps(self) -> int:
        return int(self.qpos.shape[0]) - 1

    def qpos_at(self, positions: np.ndarray) -> np.ndarray:
        """(F, 55) the positions at fractional steps (F,) in [0, N], linearly interpolated
        between steps (the root quaternion renormalised), as the simulation is sampled at
        frame times: a frame between two steps is not moved onto the nearer one, which at 30
        or 60 fps would space the frames 5 ms unevenly and make speeds taken frame to frame
        jump by 10-20 %."""
        i0, i1, w = step_interpolation(positions, self.num_steps)
        qpos = (1.0 - w[:, None]) * self.qpos[i0] + w[:, None] * self.qpos[i1]
        qpos[:, 3:7] = quat.normalised(qpos[:, 3:7])
        return qpos


def step_interpolation(positions: np.ndarray, last: int
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(i0, i1, w): the steps either side of fractional positions (F,) on a grid 0..last
    (clipped to it) and the weight of the later one, for linear interpolation."""
    pos = np.clip(np.asarray(positions, dtype=float), 0.0, last)
    i0 = np.minimum(np.floor(pos + 1e-9).astype(int), last)
    return i0, np.minimum(i0 + 1, last), np.clip(pos - i0, 0.0, 1.0)


def align_quaternion_signs(quat: np.ndarray) -> np.ndarray:
    """Flip quaternions (T, 4) so consecutive ones have a non-negative dot product."""
    q = np.array(quat, dtype=float)
    for t in range(1, len(q)):
        if np.dot(q[t], q[t - 1]) < 0:
            q[t] = -q[t]
    return q


def _reflected(values: np.ndarray) -> np.ndarray:
    """values[1:] (qpos rows) reflected through values[0], in reverse order: the motion
    before values[0] that mirrors the motion after it (rotations mirrored on the sphere)."""
    end, after = values[0], values[:0:-1]
    out = 2.0 * end - after
    out[:, 3:7] = quat.multiply(quat.multiply(end[3:7], quat.conjugate(after[:, 3:7])), end[3:7])
    return out


def smooth_reference(qpos: np.ndarray, fps: float, dt: float, num_steps: int,
                     knot_spacing: float) -> Reference:
    """Low-pass the estimate qpos (T, 55) at ``fps`` and sample it at steps 0..num_steps."""
    values = np.array(qpos, dtype=float)
    values[:, 3:7] = align_quaternion_signs(values[:, 3:7])
    # The estimate continued past both ends by its point reflection (x(-i) = 2 x(0) - x(i),
    # for the root's rotation q(-i) = q(0) q(i)* q(0); over two knot spacings), so that the
    # fit's speeds at the clip's first and last frames follow the motion's trend there instead
    # of the few noisy frames a spline's end rests on: the first window starts from them.
    pad = min(len(values) - 1, int(np.ceil(2 * knot_spacing * fps)))
    if pad:
        values = np.concatenate([_reflected(values[:pad + 1]), values,
                                 _reflected(values[:-pad - 2:-1])[::-1]])
        values[:, 3:7] = align_quaternion_signs(values[:, 3:7])
    shift = pad / fps  # clip time 0 on the padded grid
    t_frames = np.arange(len(values)) / fps
    t_steps = np.arange(num_steps + 1) * dt + shift
    grid = KnotGrid(knot_spacing, max(t_frames[-1], t_steps[-1]))
    basis = grid.matrix(t_frames)
    # Coefficients no frame constrains (a clip shorter than a few knots) rest on the nearest
    # frame's value rather than zero.
    nearest = values[np.clip(np.round(grid.centres() * fps).astype(int), 0, len(values) - 1)]
    coefs = fit_coefficients(basis, values, ridge=1e-3, prior=nearest)
    pos, vel, acc = (grid.matrix(t_steps, derivative=d) @ coefs for d in (0, 1, 2))
    rot, drot, ddrot = pos[:, 3:7], vel[:, 3:7], acc[:, 3:7]
    norm = np.linalg.norm(rot, axis=-1, keepdims=True)
    unit = rot / norm
    # The spline's quaternion q is not unit: u = q/|q|. omega_local = 2 (u* x udot)_vec and,
    # as (udot* x udot)_vec = 0, alpha = 2 (u* x uddot)_vec = 2 (u* x qddot)_vec / |q|
    # - 2 (d|q|/dt / |q|) omega (the terms along u itself have no vector part).
    dnorm = np.sum(unit * drot, axis=-1, keepdims=True)
    dunit = drot / norm - unit * dnorm / norm
    omega = 2.0 * quat.multiply(quat.conjugate(unit), dunit)[:, 1:]
    alpha = 2.0 * quat.multiply(quat.conjugate(unit), ddrot / norm)[:, 1:] \
        - 2.0 * dnorm / norm * omega
    qp = np.concatenate([pos[:, :3], unit, pos[:, 7:]], axis=1)
    qv = np.concatenate([vel[:, :3], omega, vel[:, 7:]], axis=1)
    qa = np.concatenate([acc[:, :3], alpha, acc[:, 7:]], axis=1)
    assert qp.shape[1] == NQ and qv.shape[1] == NV
    return Reference(dt=dt, qpos=qp, qvel=qv, qacc=qa)


def sole_points(model: mujoco.MjModel, foot_geoms: dict[str, int]) -> list[tuple[int, np.ndarray]]:
    """Points on the bottom face of each foot box: (body id, offset in the geom frame) x 6."""
    points = []
    for geom in foot_geoms.values():
        hx, hy, hz = model.geom_size[geom]
        for fx in (-1.0, 0.0, 1.0):
            for fy in (-1.0, 1.0):
                points.append((geom, np.array([fx * hx, fy * hy, -hz])))
    return points


def friction_pyramid(mu: float, normal: np.ndarray | None = None) -> np.ndarray:
    """(FRICTION_EDGES, 3) edges of the linearised friction cone about a unit normal (default
    +z), using ``CONE_MARGIN`` x the friction coefficient (inside the cone)."""
    normal = np.array([0.0, 0.0, 1.0]) if normal is None else np.asarray(normal, dtype=float)
    t1 = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(normal, t1)
    m = CONE_MARGIN * mu
    return np.stack([normal + m * t1, normal - m * t1, normal + m * t2, normal - m * t2])


def scene_boxes(model: mujoco.MjModel) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """(centre (3,), rotation (3, 3), half sizes (3,)) of the scene's boxes (obstacles)."""
    out = []
    for g in range(model.ngeom):
        if model.geom_bodyid[g] == 0 and model.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX:
            rot = np.zeros(9)
            mujoco.mju_quat2Mat(rot, model.geom_quat[g])
            out.append((model.geom_pos[g].copy(), rot.reshape(3, 3), model.geom_size[g].copy()))
    return out


def surface_below(point: np.ndarray, boxes: list, reach: float) -> float:
    """Height of what a point stands on: the highest box top (boxes: `scene_boxes`) under it
    and at most ``reach`` above it, else the floor, 0."""
    height = 0.0
    for centre, rot, half in boxes:
        local = rot.T @ (point - centre)
        top = centre[2] + float(np.abs(rot[2]) @ half)  # an upright box's top (yaw only)
        if abs(local[0]) <= half[0] and abs(local[1]) <= half[1] and top <= point[2] + reach:
            height = max(height, top)
    return height


def ground_forces(model: mujoco.MjModel, data: mujoco.MjData, wrench: np.ndarray,
                  points: list[tuple[int, np.ndarray]], mu: float, max_height: float,
                  boxes: list | None = None) -> np.ndarray:
    """Generalised force (nv,) of ground forces at sole points best explaining the root wrench.

    data holds the kinematics of the current state. wrench: (6,) the free joint's part of the
    inverse-dynamics force. Points higher than max_height (m) above what they stand on (the
    floor at z = 0, or the top of one of ``boxes``, `scene_boxes`) do not push.
    """
    edges = friction_pyramid(mu)
    columns, costs = [], []
    jacp = np.zeros((3, model.nv))
    for geom, offset in points:
        world = data.geom_xpos[geom] + data.geom_xmat[geom].reshape(3, 3) @ offset
        height = world[2] - (surface_below(world, boxes, max_height) if boxes else 0.0)
        if height > max_height:
            continue
        mujoco.mj_jac(model, data, jacp, None, world, model.geom_bodyid[geom])
        gen = (jacp.T @ edges.T).T  # (E, nv): generalised force of a unit push along each edge
        columns.append(gen)
        costs.append(np.full(len(edges), (1.0 + max(height, 0.0) / _HEIGHT_SCALE) ** 2))
    if not columns:
        return np.zeros(model.nv)
    gen = np.concatenate(columns, axis=0)  # (P*E, nv)
    cost = np.concatenate(costs)
    lhs = np.concatenate([gen[:, :6].T, np.diag(np.sqrt(_FORCE_REGULARISER * cost))])
    rhs = np.concatenate([wrench, np.zeros(len(cost))])
    beta, _ = nnls(lhs, rhs, maxiter=50 * lhs.shape[1])
    return gen.T @ beta


@dataclass(frozen=True, eq=False)
class InverseDynamics:
    """What the reference motion asks of the body, at steps 0..N.

    targets (N+1, 48): servo targets that make the servos produce its motor torques.
    root_residual (N+1,): the force on the root (in body weights, m g) that no ground force at
    the sole points explains: a push from nowhere that the motion would need. A physically
    consistent motion needs none; a noisy estimate does, and the simulated body, which gets no
    such push, cannot follow it there.
    """

    targets: np.ndarray
    root_residual: np.ndarray


def inverse_dynamics(model: mujoco.MjModel, ref: Reference, foot_geoms: dict[str, int],
                     mu: float, contact_height: float) -> InverseDynamics:
    """Motor torques of the reference (contacts disabled, ground forces fitted at the soles),
    turned into servo targets.

    Reads the servo law from the model: force = gain ctrl + bias0 + bias1 q + bias2 qdot,
    clipped to the force range; damping outside that law is passive and already in
    mj_inverse's balance.
    """
    m = copy.deepcopy(model)
    m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    data = mujoco.MjData(m)
    points = sole_points(m, foot_geoms)
    boxes = scene_boxes(m)
    torques = np.empty((len(ref.qpos), m.nu))
    residual = np.empty(len(ref.qpos))
    for n in range(len(ref.qpos)):
        data.qpos[:], data.qvel[:], data.qacc[:] = ref.qpos[n], ref.qvel[n], ref.qacc[n]
        mujoco.mj_inverse(m, data)
        need = data.qfrc_inverse.copy()
        need -= ground_forces(m, data, need[:6], points, mu, contact_height, boxes)
        torques[n] = need[6:]
        residual[n] = np.linalg.norm(need[:3])  # the free joint's force, world frame (N)
    lo, hi = m.actuator_forcerange[:, 0], m.actuator_forcerange[:, 1]
    torques = np.clip(torques, lo, hi)
    gain, bias = m.actuator_gainprm[:, 0], m.actuator_biasprm[:, :3]
    q, qd = ref.qpos[:, 7:], ref.qvel[:, 6:]
    weight = float(np.sum(m.body_mass)) * float(np.linalg.norm(m.opt.gravity))
    return InverseDynamics(
        targets=(torques - bias[:, 0] - bias[:, 1] * q - bias[:, 2] * qd) / gain,
        root_residual=residual / weight)


def initial_coefficients(grid: KnotGrid, step_times: np.ndarray, targets: np.ndarray
                         ) -> np.ndarray:
    """Spline coefficients (K, 48) fitted to targets (S, 48) at step_times, within joint limits."""
    clipped = np.clip(targets, DOF_LIMITS[:, 0], DOF_LIMITS[:, 1])
    nearest = clipped[np.clip(np.round(grid.centres() / (step_times[1] - step_times[0])
                                       ).astype(int), 0, len(clipped) - 1)]
    coefs = fit_coefficients(grid.matrix(step_times), clipped, ridge=1e-3, prior=nearest)
    return np.clip(coefs, DOF_LIMITS[:, 0], DOF_LIMITS[:, 1])


def geom_lowest(model: mujoco.MjModel, data: mujoco.MjData, geom: int) -> float:
    """Lowest z (m) of a box, capsule or sphere geom, after mj_kinematics."""
    size, pos = model.geom_size[geom], data.geom_xpos[geom]
    rot = data.geom_xmat[geom].reshape(3, 3)
    if model.geom_type[geom] == mujoco.mjtGeom.mjGEOM_BOX:
        return float(pos[2] - np.abs(rot[2]) @ size)
    if model.geom_type[geom] == mujoco.mjtGeom.mjGEOM_CAPSULE:
        return float(pos[2] - abs(rot[2, 2]) * size[1] - size[0])
    return float(pos[2] - size[0])


def lowest_point(model: mujoco.MjModel, data: mujoco.MjData,
                 bodies: set[int] | None = None) -> float:
    """Lowest z (m) of any body geom (or of the geoms of `bodies`, body ids) after
    mj_kinematics."""
    return min(geom_lowest(model, data, g) for g in range(model.ngeom) if model.geom_bodyid[g]
               and (bodies is None or model.geom_bodyid[g] in bodies))


def ground_state(model: mujoco.MjModel, qpos: np.ndarray, snap: float) -> np.ndarray:
    """qpos (55,) shifted up out of the floor, or down onto it when it hovers less than snap (m)."""
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    low = lowest_point(model, data)
    out = np.array(qpos, dtype=float)
    if low < snap:
        out[2] -= low
    return out


def smooth_sight_velocity(qvel: np.ndarray, root: np.ndarray, camera_centre: np.ndarray,
                          dt: float, sigma: float) -> np.ndarray:
    """qvel (N, 54) with the root's horizontal velocity along the camera's line of sight
    low-passed by a Gaussian of ``sigma`` s (the rest unchanged).

    root (N, 3): the root's positions at the same steps (dt s apart); camera_centre (3,) or
    (N, 3), world. A monocular estimate's depth is its noisiest part: its depth speed swings by
    up to a metre per second within a few frames, and a body started with it carries it off.
    """
    sight = root[:, :2] - np.broadcast_to(camera_centre, root.shape)[:, :2]
    sight /= np.maximum(np.linalg.norm(sight, axis=1, keepdims=True), 1e-9)
    along = np.einsum("ni,ni->n", qvel[:, :2], sight)
    smoothed = gaussian_filter1d(along, sigma / dt, mode="nearest")
    out = np.array(qvel, dtype=float)
    out[:, :2] += (smoothed - along)[:, None] * sight
    return out


def ground_motion(model: mujoco.MjModel, qpos: np.ndarray, snap: float) -> np.ndarray:
    """qpos (T, 55) with each frame shifted vertically as `ground_state` does: out of the floor,
    or down onto it when hovering less than snap (m); other frames (jumps) are unchanged."""
    return np.stack([ground_state(model, q, snap) for q in qpos])
