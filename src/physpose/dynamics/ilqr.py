"""Iterative LQR refinement of one window's servo targets.

CMA-ES tells apart a few hundred open-loop samples per window; in the fast preset's budget it
rarely improves on its start (the inverse-dynamics or tracked targets) and never settles the
hinges it varies (docs/dynamics.md). This module optimises the window's servo targets, one per
simulation step, by iterative LQR (Li and Todorov 2004; Tassa, Erez and Todorov 2012):

1. linearise the simulation along the current trajectory: MuJoCo's finite-difference
   transition Jacobians (``mjd_transitionFD``, x' = A x + B u in the tangent space of
   positions and velocities), contacts included, taken every ``derivative_stride`` steps and
   held in between (and kept for the next iteration when a step is rejected);
2. solve the LQR problem of a quadratic tracking cost backwards in time (Riccati recursion),
   with the control Hessian damped by ``regularisation`` (Levenberg-Marquardt: raised tenfold
   after a rejected step, lowered after an accepted one);
3. roll the new targets out forwards *with the LQR feedback gains* on the state's deviation
   from the previous trajectory, under a line search on the feedforward step; the step is
   kept when the cost falls.

The feedback only acts while the optimiser rolls out: the targets it applied are recorded and
replay the motion exactly open loop, so the result is an ordinary servo-target sequence and the
body is still moved only by its motors and its contacts (no residual force).

Cost, summed over the window's states 1..n and controls 0..n-1:

    1/2 sum_t (e_q' W_q e_q + e_v' W_v e_v + foot_slide sum_standing |v_foot,xy|^2)
    + 1/2 control sum_t |u_t - u_start,t|^2

e_q = q_t minus the reference's q (MuJoCo's position difference: root translation in world
axes, root rotation in the pelvis frame, hinge angles), e_v the velocity difference; the last
state weighs ``terminal`` times (and the one the next window starts from ``handover`` times, 1
by default: measured, it did not bring that state nearer; docs/dynamics.md). The reference is
the smoothed (grounded, flat-footed) estimate the search follows; the control term keeps the
targets near where they started. The estimate's standing feet slide where it is noisy, and a
body made to follow its root closely would slide its feet too: the foot-slide term
(Gauss-Newton, on the horizontal velocity of the lowest corner of each foot box within 1 cm of
the floor, the point a sliding foot drags) keeps them where they stand, while a foot may still
roll over its toe or heel edge. Optional terms: the detections' re-projection error (``image``,
Gauss-Newton through the landmark sites' Jacobians) and the root's offset along the camera's
line of sight (``root_depth``).

The fast preset runs six iterations after every window's search (measured on motion capture:
nearer the truth on everyday motions, fewer restarts, a little further on athletic ones;
docs/dynamics.md, iLQR refinement); instead of the search it was no better.
"""

from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, fields

import mujoco
import numpy as np
from threadpoolctl import threadpool_limits

from physpose.dynamics.objective import MIN_DEPTH, pinhole
from physpose.errors import PhysposeError
from physpose.metrics import transform_points
from physpose.skeleton import NUM_DOF

_FULL = mujoco.mjtState.mjSTATE_FULLPHYSICS
_STEP_SIZES = (1.0, 0.5, 0.25, 0.1)
_MAX_REGULARISATION = 1e8
_FEEDBACK_CLIP = 0.5  # rad: largest target change the feedback makes in one step
_ON_FLOOR = 0.01  # m: a foot box whose lowest point is this low stands on the floor


@dataclass(frozen=True)
class RefineConfig:
    """iLQR refinement after each window's search (off while ``iterations`` is 0).

    Weights per simulation step: root_position (1/m^2), root_orientation and hinge (1/rad^2),
    root_velocity and hinge_velocity (s^2/m^2, s^2/rad^2), control (1/rad^2, servo targets
    away from their start), foot_slide (s^2/m^2, the horizontal speed of the lowest corner of
    a foot box that is on the floor), image (1/m^2 per landmark and frame: the detections'
    re-projection error, in metres at the person's depth, confidence-weighted, Huber beyond
    image_huber m), root_depth (1/m^2: added to root_position along the camera's line of sight
    to the reference root, where the image cannot see; needs the camera of ``ImageTerm``);
    terminal: the last state's weight multiplier; handover: that of the state the next
    window starts from (when the caller names its step), which the next window inherits.
    keep_ratio: a window keeps the refined targets when their objective (the search's, not
    this tracking cost) is at most keep_ratio times the search's result.
    derivative_stride: steps between linearisations (each is held until the next).
    regularisation: initial damping of the control Hessian.
    """

    iterations: int = 0
    root_position: float = 1e3
    root_orientation: float = 3e2
    hinge: float = 1e2
    root_velocity: float = 1.0
    hinge_velocity: float = 0.3
    control: float = 1.0
    foot_slide: float = 300.0
    image: float = 0.0
    image_huber: float = 0.03
    root_depth: float = 0.0
    terminal: float = 5.0
    handover: float = 1.0
    keep_ratio: float = 1.5
    derivative_stride: int = 2
    regularisation: float = 30.0

    def __post_init__(self) -> None:
        if self.iterations < 0 or self.derivative_stride < 1:
            raise PhysposeError(f"refine iterations={self.iterations} must be >= 0 and "
                                f"derivative_stride={self.derivative_stride} >= 1",
                                remedy="use e.g. RefineConfig(iterations=6)")
        for f in fields(self):
            if f.name not in ("iterations", "derivative_stride") and not getattr(self, f.name) >= 0:
                raise PhysposeError(f"refine {f.name}={getattr(self, f.name)} must be >= 0",
                                    remedy="use the default RefineConfig weights")

    @property
    def enabled(self) -> bool:
        return self.iterations > 0


@dataclass(frozen=True, eq=False)
class Refined:
    """states (n+1, nstate) FULLPHYSICS, ctrl (n, 48) the targets applied; costs: the
    tracking cost before and after each iteration; seconds: wall time."""

    states: np.ndarray
    ctrl: np.ndarray
    costs: list[float]
    seconds: float


@dataclass(frozen=True, eq=False)
class ImageTerm:
    """Detections a window's states are re-projected onto: steps (F,) the state index of
    each frame in the window, keypoints (F, 33, 3) px + confidence, metres_per_px (F,),
    camera K (3, 3) and T_world2cam (4, 4), site_ids (33,) the landmark sites;
    camera_travel (F, 3) m or None: how far a travelling camera had moved by each frame
    (travel.py), the body seen moved back by it."""

    steps: np.ndarray
    keypoints: np.ndarray
    metres_per_px: np.ndarray
    K: np.ndarray
    T_world2cam: np.ndarray
    site_ids: np.ndarray
    camera_travel: np.ndarray | None = None


def _normalised_jacobian(points: np.ndarray) -> np.ndarray:
    """(L, 2, 3): the derivative of ``objective.pinhole``'s normalised coordinates (x/z, y/z)
    by the camera-frame points (L, 3); a depth clamped at MIN_DEPTH does not vary."""
    z = np.maximum(points[:, 2], MIN_DEPTH)
    free = points[:, 2] > MIN_DEPTH
    out = np.zeros((len(points), 2, 3))
    out[:, 0, 0] = out[:, 1, 1] = 1.0 / z
    out[:, :, 2] = np.where(free[:, None], -points[:, :2] / z[:, None] ** 2, 0.0)
    return out


class _Problem:
    """One window's tracking problem on a model: ``data`` steps its rollouts, ``posed`` poses
    states for the foot and image terms (the derivatives' threads make their own)."""

    def __init__(self, model: mujoco.MjModel, state0: np.ndarray, ref_qpos: np.ndarray,
                 ref_qvel: np.ndarray, u_start: np.ndarray, cfg: RefineConfig,
                 feet: tuple[int, ...] = (), image: ImageTerm | None = None,
                 handover_step: int | None = None):
        self.model, self.state0, self.cfg = model, state0, cfg
        self.image = image if cfg.image else None
        self.sight = _lines_of_sight(ref_qpos[:, :3], image) \
            if cfg.root_depth and image is not None else None
        self.feet = feet
        self.ref_qpos, self.ref_qvel, self.u_start = ref_qpos, ref_qvel, u_start
        self.nv, self.nq = model.nv, model.nq
        self.data = mujoco.MjData(model)
        self.posed = mujoco.MjData(model)
        wq = np.full(self.nv, cfg.hinge)
        wq[:3], wq[3:6] = cfg.root_position, cfg.root_orientation
        wv = np.full(self.nv, cfg.hinge_velocity)
        wv[:6] = cfg.root_velocity
        n = len(u_start)
        self.step_scale = np.ones(n + 1)  # per state: the start is given, the last weighs more
        self.step_scale[0], self.step_scale[-1] = 0.0, cfg.terminal
        if handover_step is not None and 0 < handover_step < n:  # the last is terminal's
            self.step_scale[handover_step] = cfg.handover
        self.lxx = np.concatenate([wq, wv])[None] * self.step_scale[:, None]  # (n+1, 2 nv)

    def _qpos(self, states: np.ndarray) -> np.ndarray:
        return states[:, 1:1 + self.nq]

    def _qvel(self, states: np.ndarray) -> np.ndarray:
        return states[:, 1 + self.nq:1 + self.nq + self.nv]

    def deviation(self, states: np.ndarray, qpos: np.ndarray, qvel: np.ndarray) -> np.ndarray:
        """(n+1, 2 nv): states minus (qpos, qvel) in the tangent space."""
        out = np.empty((len(states), 2 * self.nv))
        for t, (q, q0) in enumerate(zip(self._qpos(states), qpos)):
            mujoco.mj_differentiatePos(self.model, out[t, :self.nv], 1.0, q0, q)
        out[:, self.nv:] = self._qvel(states) - qvel
        return out

    def slide_jacobians(self, states: np.ndarray) -> dict[int, np.ndarray]:
        """Per step with a foot on the floor: (k, 2, nv) horizontal velocity Jacobians of the
        lowest corners of its k foot boxes whose lowest corner is under ``_ON_FLOOR`` m (the
        point a sliding foot drags along the floor; a foot rolling over its toe or heel
        edge keeps that point still)."""
        if not self.cfg.foot_slide or not self.feet:
            return {}
        m, d = self.model, self.posed
        jac = np.zeros((3, self.nv))
        signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
        out = {}
        for t in range(1, len(states)):
            d.qpos[:] = states[t, 1:1 + self.nq]
            mujoco.mj_kinematics(m, d)
            rows = []
            for g in self.feet:
                corners = d.geom_xpos[g] + (signs * m.geom_size[g]) @ \
                    d.geom_xmat[g].reshape(3, 3).T
                low = corners[np.argmin(corners[:, 2])]
                if low[2] >= _ON_FLOOR:
                    continue
                if not rows:
                    mujoco.mj_comPos(m, d)
                mujoco.mj_jac(m, d, jac, None, low, int(m.geom_bodyid[g]))
                rows.append(jac[:2].copy())
            if rows:
                out[t] = np.stack(rows)
        return out

    def image_terms(self, states: np.ndarray, derivatives: bool
                    ) -> tuple[float, dict[int, tuple[np.ndarray, np.ndarray]]]:
        """The re-projection cost and, per frame's state index, its Gauss-Newton gradient
        (nv,) and Hessian (nv, nv) in the positions (Huber by reweighting)."""
        img = self.image
        if img is None:
            return 0.0, {}
        m, d = self.model, self.posed
        R = img.T_world2cam[:3, :3]
        delta, w = self.cfg.image_huber, self.cfg.image
        jac = np.zeros((len(img.site_ids), 3, self.nv))
        total, out = 0.0, {}
        for f, t in enumerate(img.steps):
            if t <= 0:
                continue  # the start state is given
            d.qpos[:] = states[t, 1:1 + self.nq]
            mujoco.mj_kinematics(m, d)
            sites = d.site_xpos[img.site_ids]
            if img.camera_travel is not None:
                sites = sites - img.camera_travel[f]
            cam = transform_points(img.T_world2cam, sites)
            uv = pinhole(cam, img.K)  # the search's own projection
            e = (uv - img.keypoints[f, :, :2]) * img.metres_per_px[f]  # (33, 2) m
            norm = np.linalg.norm(e, axis=1)
            conf = img.keypoints[f, :, 2]
            huber = np.where(norm <= delta, 0.5 * norm ** 2, delta * (norm - 0.5 * delta))
            total += w * float(np.sum(conf * huber))
            if not derivatives:
                continue
            mujoco.mj_comPos(m, d)
            for i, site in enumerate(img.site_ids):
                mujoco.mj_jacSite(m, d, jac[i], None, int(site))
            dpi = img.K[:2, :2] @ _normalised_jacobian(cam)  # d(uv)/d(camera point)
            J = np.einsum("lij,jk,lkv->liv", dpi, R, jac) * img.metres_per_px[f]  # (33, 2, nv)
            weight = w * conf * np.minimum(1.0, delta / np.maximum(norm, 1e-12))
            out[int(t)] = (np.einsum("l,liv,li->v", weight, J, e),
                           np.einsum("l,liv,liw->vw", weight, J, J))
        return total, out

    def depth_terms(self, states: np.ndarray, derivatives: bool
                    ) -> tuple[float, dict[int, tuple[np.ndarray, np.ndarray]]]:
        """The root-depth cost and, per state index, its gradient (nv,) and Hessian (nv, nv)
        in the positions (the root translation's tangent axes are the world's)."""
        if self.sight is None:
            return 0.0, {}
        along = np.einsum("ti,ti->t", self._qpos(states)[:, :3] - self.ref_qpos[:, :3],
                          self.sight)
        w = self.cfg.root_depth * self.step_scale
        total = 0.5 * float(np.sum(w * along ** 2))
        out = {}
        if derivatives:
            for t in range(1, len(states)):
                g, H = np.zeros(self.nv), np.zeros((self.nv, self.nv))
                g[:3] = w[t] * along[t] * self.sight[t]
                H[:3, :3] = w[t] * np.outer(self.sight[t], self.sight[t])
                out[t] = (g, H)
        return total, out

    def position_terms(self, states: np.ndarray) -> dict[int, tuple[np.ndarray, np.ndarray]]:
        """The image and depth terms' gradients and Hessians, summed per state index."""
        out: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        for terms in (self.image_terms(states, True)[1], self.depth_terms(states, True)[1]):
            for t, (g, H) in terms.items():
                out[t] = (out[t][0] + g, out[t][1] + H) if t in out else (g, H)
        return out

    def cost(self, states: np.ndarray, ctrl: np.ndarray) -> float:
        if not np.isfinite(states).all():
            return np.inf
        e = self.deviation(states, self.ref_qpos, self.ref_qvel)
        value = 0.5 * np.sum(self.lxx * e * e) \
            + 0.5 * self.cfg.control * np.sum((ctrl - self.u_start) ** 2)
        qvel = self._qvel(states)
        for t, J in self.slide_jacobians(states).items():
            value += 0.5 * self.cfg.foot_slide * np.sum((J @ qvel[t]) ** 2)
        return float(value + self.image_terms(states, False)[0]
                     + self.depth_terms(states, False)[0])

    def rollout(self, ctrl: np.ndarray, gains: tuple | None = None, step: float = 0.0
                ) -> tuple[np.ndarray, np.ndarray]:
        """Simulate ctrl from the start state; with gains (k, K, nominal states) apply
        ctrl + step k + K (x - nominal) instead. Returns (states, targets applied)."""
        m, d = self.model, self.data
        mujoco.mj_setState(m, d, self.state0, _FULL)
        states = np.full((len(ctrl) + 1, len(self.state0)), np.nan)
        applied = np.array(ctrl, dtype=float)
        mujoco.mj_getState(m, d, states[0], _FULL)
        dq = np.empty(self.nv)
        for t in range(len(ctrl)):
            if gains is not None:
                k, K, nominal = gains
                mujoco.mj_differentiatePos(m, dq, 1.0, nominal[t, 1:1 + self.nq], d.qpos)
                dx = np.concatenate([dq, d.qvel - nominal[t, 1 + self.nq:1 + self.nq + self.nv]])
                applied[t] += np.clip(step * k[t] + K[t] @ dx, -_FEEDBACK_CLIP, _FEEDBACK_CLIP)
            d.ctrl[:NUM_DOF] = applied[t]
            mujoco.mj_step(m, d)
            if not np.isfinite(d.qpos).all():
                break
            mujoco.mj_getState(m, d, states[t + 1], _FULL)
        return states, applied

    def linearise(self, states: np.ndarray, ctrl: np.ndarray, pool: ThreadPoolExecutor | None,
                  parts: int) -> tuple[np.ndarray, np.ndarray]:
        """Transition Jacobians A (n, 2nv, 2nv), B (n, 2nv, 48) along a trajectory, taken
        every derivative_stride steps (the pool's threads each take every k-th of them)."""
        m, n, stride = self.model, len(ctrl), self.cfg.derivative_stride
        nx = 2 * self.nv
        As, Bs = np.empty((n, nx, nx)), np.empty((n, nx, NUM_DOF))
        times = list(range(0, n, stride))

        def work(part: int, parts: int) -> None:
            d = mujoco.MjData(m)
            A, B = np.zeros((nx, nx)), np.zeros((nx, m.nu))
            for t in times[part::parts]:
                mujoco.mj_setState(m, d, states[t], _FULL)
                d.ctrl[:NUM_DOF] = ctrl[t]
                mujoco.mjd_transitionFD(m, d, 1e-6, False, A, B, None, None)
                As[t:t + stride], Bs[t:t + stride] = A, B[:, :NUM_DOF]

        if pool is None:
            work(0, 1)
        else:
            list(pool.map(work, range(parts), [parts] * parts))
        return As, Bs

    def cost_expansion(self, states: np.ndarray) -> tuple[np.ndarray, dict, dict]:
        """The state cost's gradient lx (n+1, 2nv) along a trajectory, with the Gauss-Newton
        Hessian blocks of the standing feet's slide ({t: (nv, nv)}, on the velocities) and of
        the image and depth terms ({t: (gradient, (nv, nv))}, on the positions)."""
        nv = self.nv
        lx = self.lxx * self.deviation(states, self.ref_qpos, self.ref_qvel)
        # Standing feet's horizontal speed (Gauss-Newton in the velocities).
        slide_h = {}
        qvel = self._qvel(states)
        for t, J in self.slide_jacobians(states).items():
            H = self.cfg.foot_slide * np.einsum("kiv,kiw->vw", J, J)
            lx[t, nv:] += H @ qvel[t]
            slide_h[t] = H
        image = self.position_terms(states)
        for t, (g, _) in image.items():
            lx[t, :nv] += g
        return lx, slide_h, image

    def gains(self, ctrl: np.ndarray, As: np.ndarray, Bs: np.ndarray,
              expansion: tuple[np.ndarray, dict, dict], mu: float
              ) -> tuple[np.ndarray, np.ndarray] | None:
        """Riccati recursion on the linearisation As, Bs and the ``cost_expansion`` of the
        trajectory ctrl drove: feedforward k (n, 48) and feedback K (n, 48, 2nv), or None
        where the damped control Hessian is not positive definite."""
        n, nx, nv = len(ctrl), 2 * self.nv, self.nv
        lx, slide_h, image = expansion  # read only, so a kept expansion serves again
        lu = self.cfg.control * (ctrl - self.u_start)
        ruu = (self.cfg.control + mu) * np.eye(NUM_DOF)
        ks, Ks = np.empty((n, NUM_DOF)), np.empty((n, NUM_DOF, nx))
        vx, vxx = lx[n], np.diag(self.lxx[n])
        if n in slide_h:
            vxx[nv:, nv:] += slide_h[n]
        if n in image:
            vxx[:nv, :nv] += image[n][1]
        for t in range(n - 1, -1, -1):
            A, B = As[t], Bs[t]
            qx = lx[t] + A.T @ vx
            qu = lu[t] + B.T @ vx
            vb = vxx @ B
            qxx = A.T @ vxx @ A
            qxx[np.diag_indices(nx)] += self.lxx[t]
            if t in slide_h and t > 0:
                qxx[nv:, nv:] += slide_h[t]
            if t in image:
                qxx[:nv, :nv] += image[t][1]
            quu = B.T @ vb + ruu
            qux = vb.T @ A
            try:
                chol = np.linalg.cholesky(quu)
            except np.linalg.LinAlgError:
                return None
            sol = -np.linalg.solve(chol.T, np.linalg.solve(chol, np.column_stack([qu, qux])))
            k, K = sol[:, 0], sol[:, 1:]
            ks[t], Ks[t] = k, K
            vx = qx + K.T @ (quu @ k + qu) + qux.T @ k
            vxx = qxx + K.T @ quu @ K + K.T @ qux + qux.T @ K
            vxx = 0.5 * (vxx + vxx.T)
        return ks, Ks


def camera_centres(T_world2cam: np.ndarray, steps: np.ndarray,
                   travel_steps: np.ndarray | None = None,
                   travel: np.ndarray | None = None) -> np.ndarray:
    """(len(steps), 3) the camera's centre in the world at each step: still, or moved on by
    ``travel`` (F, 3), its path at the (fractional) steps ``travel_steps`` (F,), interpolated."""
    R, tr = T_world2cam[:3, :3], T_world2cam[:3, 3]
    centre = np.broadcast_to(-R.T @ tr, (len(steps), 3)).copy()
    if travel is not None:
        centre += np.column_stack([np.interp(steps, travel_steps, travel[:, i])
                                   for i in range(3)])
    return centre


def _lines_of_sight(root: np.ndarray, camera: ImageTerm) -> np.ndarray:
    """(n+1, 3) unit vectors from the camera's centre to the reference root at each state
    (a travelling camera's centre moved on by its path, interpolated between frames)."""
    centre = camera_centres(camera.T_world2cam, np.arange(len(root)), camera.steps,
                            camera.camera_travel)
    sight = root - centre
    return sight / np.maximum(np.linalg.norm(sight, axis=1, keepdims=True), 1e-9)


def refine_targets(model: mujoco.MjModel, state0: np.ndarray, ctrl: np.ndarray,
                   ref_qpos: np.ndarray, ref_qvel: np.ndarray, cfg: RefineConfig,
                   nthread: int = 1, feet: tuple[int, ...] = (),
                   image: ImageTerm | None = None, handover_step: int | None = None
                   ) -> Refined:
    """iLQR on the servo targets ctrl (n, 48) from state0 (FULLPHYSICS) towards the reference
    states ref_qpos (n+1, nq), ref_qvel (n+1, nv). feet: geom ids of the foot boxes (the
    ``foot_slide`` term). image: the detections for the ``image`` term. handover_step: the
    state the next window starts from (weighted ``handover`` times; ignored at the last
    state, a clip's last window, which ``terminal`` weighs). Deterministic; nthread
    threads take the derivatives (the result does not depend on it)."""
    start = time.perf_counter()
    pool = ThreadPoolExecutor(nthread) if nthread > 1 else None
    try:
        problem = _Problem(model, state0, ref_qpos, ref_qvel, np.asarray(ctrl, dtype=float),
                           cfg, feet, image, handover_step)
        return _iterate(problem, cfg, pool, nthread, start)
    finally:
        if pool is not None:
            pool.shutdown()


def _iterate(problem: _Problem, cfg: RefineConfig, pool: ThreadPoolExecutor | None,
            nthread: int, start: float) -> Refined:
    states, applied = problem.rollout(problem.u_start)
    cost = problem.cost(states, applied)
    costs, mu = [cost], cfg.regularisation
    # A rejected step leaves the trajectory where it was, and with it its quadratic model (the
    # Jacobians, most of an iteration's time, and the cost's expansion): only the damping
    # changes, so the model is kept until a step is accepted.
    linearised = None
    # The recursion's matrices are small (108 x 108): BLAS threads only cost time there.
    with threadpool_limits(limits=1, user_api="blas"):
        for _ in range(cfg.iterations):
            if not np.isfinite(cost):
                break
            if linearised is None:
                linearised = (*problem.linearise(states, applied, pool, nthread),
                              problem.cost_expansion(states))
            As, Bs, expansion = linearised
            solved = None
            while solved is None and mu < _MAX_REGULARISATION:
                solved = problem.gains(applied, As, Bs, expansion, mu)
                if solved is None:
                    mu *= 10.0
            if solved is None:
                break
            accepted = False
            for step in _STEP_SIZES:
                new_states, new_applied = problem.rollout(applied, (*solved, states), step)
                new_cost = problem.cost(new_states, new_applied)
                if new_cost < cost:
                    states, applied, cost, accepted = new_states, new_applied, new_cost, True
                    linearised = None
                    break
            mu = max(mu / 3.0, 1e-6) if accepted else mu * 10.0
            costs.append(cost)
    return Refined(states=states, ctrl=applied, costs=costs, seconds=time.perf_counter() - start)
