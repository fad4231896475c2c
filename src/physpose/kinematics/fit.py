"""`fit_kinematics`: observations -> shape, camera, ground plane and per-frame pose (the
paper's HUND+SO+GT with our body model in place of GHUM; variants by configuration).

Steps (timed and logged by name):
1. camera: K given (argument, else the observations'), else the field-of-view prior.
2. shape (+S): bones and MediaPipe's depth/scale factors from the seed frames.
3. init (= variant S): closed-form IK on MediaPipe's landmarks, IK refined on them (3d only),
   root translation by 2d re-projection.
4. pose (+O, with +T): all frames jointly: 2d re-projection + 3d agreement + prior + limits
   (+ smoothness).
5. ground (+G): T_g from the posed body (L_gp), then the poses again with the plane fixed and
   the contact term on; where the feet stay raised (a box, a step), once more standing them
   on its top. Without +G, the level-camera guess.
6. world frame (camera.world_from_plane) and the result in the skeleton's qpos layout.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import jax
import numpy as np
from scipy.spatial.transform import Rotation
from tqdm import tqdm

from physpose import diagnostics, supports
from physpose.cache import Cache, stage_key
from physpose.errors import expect_type
from physpose.paths import cache_dir
from physpose.fk import fk_qpos, segment_frames
from physpose.kinematics import camera as cam
from physpose.kinematics.checkpoint import FitCheckpoints
from physpose.kinematics.config import VARIANT_NAMES, KinematicConfig
from physpose.kinematics.evidence import Evidence, gather_evidence, padded_length
from physpose.kinematics.ground import estimate_plane, level_plane
from physpose.kinematics.losses import rotvec_matrix
from physpose.kinematics.objective import Params, weight_dict
from physpose.kinematics.optim import reporting_iterations
from physpose.kinematics.pose_fit import (Problem, initial_pose, make_params, make_problem,
                                          settings_from)
from physpose.kinematics.precision import double_precision
from physpose.kinematics.result import KinematicFit
from physpose.kinematics.shape_fit import fit_shape
from physpose.kinematics.surface import SurfacePoints, centre_of_mass, place, surface_points
from physpose.kinematics.swaps import unswap
from physpose.observations import Observations
from physpose.shape import BodyShape
from physpose.skeleton import NQ

KINEMATICS_VERSION = 14  # bump when a change alters the result for the same input and config
_log = logging.getLogger(__name__)
Log = Callable[[str], None]


def _quiet(_: str) -> None:
    pass


def enable_compilation_cache() -> None:
    """Keep JAX's compiled objectives on disk (paths.cache_dir()/jax) so a new process does
    not compile them again, unless the user configured a JAX compilation cache already."""
    if not jax.config.jax_compilation_cache_dir:
        jax.config.update("jax_compilation_cache_dir", str(cache_dir() / "jax"))
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)


def stderr_log(message: str) -> None:
    print(f"kinematics: {message}", file=sys.stderr, flush=True)


def fit_kinematics(observations: Observations, config: KinematicConfig = KinematicConfig(), *,
                   height: float | None = None, mass: float | None = None,
                   camera_K: np.ndarray | None = None, log: Log = _quiet,
                   progress: bool = False) -> KinematicFit:
    """Fit the kinematic variant of `config` to the observations.

    height (m) fixes the body's scale, mass (kg) its mass (else from the stature at BMI 22);
    camera_K (3, 3) overrides the observations' intrinsics. Results are cached by observations,
    config and these arguments (config.use_cache); so are its finished steps until the whole
    fit is, so a fit stopped midway resumes after them (kinematics.checkpoint). log: each
    step's duration; progress: a bar on stderr per step, counting its iterations.
    """
    expect_type(observations, Observations, "fit_kinematics' observations",
                "pass Observations, e.g. physpose.pipeline.load_observations(path, "
                "ObserveConfig())")
    expect_type(config, KinematicConfig, "fit_kinematics' config",
                "pass e.g. KinematicConfig.preset('SO+GT')")
    K = camera_K if camera_K is not None else observations.camera_K
    if height is not None:
        BodyShape.from_height(height, mass)  # range checks with a clear message
    key = stage_key("kinematics", version=KINEMATICS_VERSION,
                    config=dataclasses.replace(config, use_cache=True, compile_cache=True),
                    extra={"observations": _observation_arrays(observations), "height": height,
                           "mass": mass, "camera_K": None if K is None else np.asarray(K, float)})
    cache = Cache("kinematics")
    if config.use_cache and (hit := cache.get(key)) is not None:
        log("cached result")
        fit = _from_arrays(hit)
    else:
        steps = FitCheckpoints(key if config.use_cache else None, log)
        fit = fit_variants(observations, (config.variant,), config, height=height, mass=mass,
                           camera_K=K, log=log, progress=progress,
                           checkpoints=steps)[config.variant]
        if config.use_cache and cache.put(key, _to_arrays(fit)) is not None:
            steps.clear()
    message = diagnostics.label_exchange_message(fit.label_exchanges, fit.fps)
    if message:  # given again for a cached fit
        _log.warning(message)
    return fit


@dataclass(frozen=True, eq=False)
class _Context:
    """What every variant shares: evidence, camera, shape and the initial (S) poses."""

    obs: Observations
    cfg: KinematicConfig
    ev: Evidence
    K: np.ndarray
    focal_prior: float
    K_given: bool
    shape: BodyShape
    surface: SurfacePoints
    height: float | None
    params: Params         # variant S
    problem: Problem
    timings: dict
    label_exchanges: dict  # swaps.unswap's long runs of exchanged limb labels

    def problem_at(self, params: Params, plane: np.ndarray = np.zeros(4),
                   support: np.ndarray | None = None) -> Problem:
        """The problem with the reprojection's depth scale taken from params' root depths
        (support: per-frame heights above the plane the feet stand on, default the floor)."""
        n = self.ev.num_frames
        return make_problem(self.ev, np.arange(n), self.problem.length, np.asarray(
            self.problem.fixed.R0)[:n], self.K, self.focal_prior,
            np.asarray(params.root_pos)[:n, 2], self.surface.offset, self.height,
            self.problem.settings, plane, self.cfg.pose.hard_limits, support)


class _Timer:
    """Times the fit's steps and logs each one's duration; with `progress`, a bar counts a
    step's L-BFGS iterations while it runs (on a clip of minutes a step takes minutes)."""

    def __init__(self, log: Log, progress: bool = False):
        self.log, self.progress, self.timings = log, progress, {}

    @contextmanager
    def step(self, name: str) -> Iterator[None]:
        start = time.perf_counter()
        bar = tqdm(desc=f"kinematics {name}", unit="it", leave=False, file=sys.stderr,
                   disable=not self.progress, dynamic_ncols=True)
        try:
            with reporting_iterations(bar.update):
                yield
        finally:
            bar.close()
        seconds = time.perf_counter() - start
        self.timings[name] = self.timings.get(name, 0.0) + seconds
        self.log(f"{name} done in {seconds:.1f} s")


def _prepare(obs: Observations, cfg: KinematicConfig, height, mass, K_given, timer: _Timer,
             steps: FitCheckpoints) -> _Context:
    """Evidence, camera, shape (+S) and the initial poses of every frame (variant S)."""
    with timer.step("evidence"):
        focal_prior = cam.focal_from_fov(obs.image_size, cfg.camera.diagonal_fov_deg)
        K = (cam.intrinsics(obs.image_size, focal_prior) if K_given is None
             else cam.check_intrinsics(K_given, obs.source))
        focal_prior = focal_prior if K_given is None else float(K[0, 0])
        ev = gather_evidence(obs, K, cfg.pose.min_confidence, cfg.pose.ray_aligned_world)
        exchanges: dict = {}
        if cfg.fix_swaps:
            ev, exchanges = unswap(ev)
        reference = surface_points(BodyShape.from_height(1.7))
        settings = settings_from(cfg.pose, cfg.ground_plane, cfg.shape, cfg.camera, reference)

    with timer.step("shape"):
        sf = fit_shape(ev, K, cfg, settings, reference.offset, height=height, mass=mass)
        shape = sf.shape
        surface = surface_points(shape)
        if surface.blocks != reference.blocks:
            raise AssertionError("the surface sampling depends on the shape")

    with timer.step("init"):
        n = ev.num_frames
        frames, length = np.arange(n), padded_length(n)
        root_pos, R0, angles = initial_pose(ev, frames, shape.bones(), K, sf.depth_scale,
                                            sf.world_scale)
        params = make_params(root_pos, np.zeros_like(root_pos), angles, shape.bones(),
                             sf.depth_scale, sf.world_scale, K[0, 0], length)
        problem = make_problem(ev, frames, length, R0, K, focal_prior, root_pos[:, 2],
                               surface.offset, height, settings, np.zeros(4),
                               cfg.pose.hard_limits)
        w = cfg.pose.weights

        def init() -> tuple[Params, dict]:
            p, _ = problem.run(params, ("root_rotvec", "angles"), weight_dict(
                world_landmarks=w.world_landmarks, pose_prior=w.pose_prior,
                joint_limits=w.joint_limits), cfg.pose.init_iterations)
            return problem.run(p, ("root_pos",), weight_dict(reprojection=w.reprojection),
                               cfg.pose.init_iterations)

        params, _ = steps.params("init", init)
        ctx = _Context(obs=obs, cfg=cfg, ev=ev, K=K, focal_prior=focal_prior,
                       K_given=K_given is not None, shape=shape, surface=surface,
                       height=height, params=params, problem=problem, timings=timer.timings,
                       label_exchanges=exchanges)
        ctx = dataclasses.replace(ctx, problem=ctx.problem_at(params))
    return ctx


def _pose_terms(cfg: KinematicConfig, temporal: bool, ground: bool, focal: bool) -> dict:
    w = cfg.pose.weights
    terms = dict(reprojection=w.reprojection, world_landmarks=w.world_landmarks,
                 pose_prior=w.pose_prior, joint_limits=w.joint_limits,
                 depth_scale_prior=w.depth_scale_prior, focal_prior=1.0 if focal else 0.0)
    if temporal:
        terms.update(temporal_velocity=w.temporal_velocity,
                     temporal_acceleration=w.temporal_acceleration,
                     temporal_angles=w.temporal_angles)
    if ground:
        terms.update(ground=w.ground)
    if ground and temporal:
        terms.update(ground_skate=w.ground_skate)
    return weight_dict(**terms)


def fit_variants(obs: Observations, variants: tuple[str, ...], cfg: KinematicConfig, *,
                 height: float | None = None, mass: float | None = None,
                 camera_K: np.ndarray | None = None, log: Log = _quiet,
                 progress: bool = False, checkpoints: FitCheckpoints | None = None
                 ) -> dict[str, KinematicFit]:
    """Several variants of one clip sharing their common steps (S -> SO -> SO+T; the plane of
    SO+G from SO's poses, of SO+GT from SO+T's). `cfg`'s variant flags are ignored; its other
    settings apply to all. No caching (see fit_kinematics); checkpoints, if given, keeps and
    reads back each finished step. progress: a bar on stderr per step, counting its
    iterations."""
    for v in variants:
        KinematicConfig.preset(v)  # unknown names fail early
    K = camera_K if camera_K is not None else obs.camera_K
    timer = _Timer(log, progress)
    steps = checkpoints if checkpoints is not None else FitCheckpoints(None)
    if cfg.compile_cache:
        enable_compilation_cache()
    with double_precision():
        ctx = _prepare(obs, cfg, height, mass, K, timer, steps)
        focal = not ctx.K_given and cfg.camera.refine_focal
        free = ("root_pos", "root_rotvec", "angles", "log_depth_scale")
        free += ("log_focal",) if focal else ()
        out: dict[str, KinematicFit] = {}
        stages: dict[str, tuple[Params, Problem, dict]] = {"S": (ctx.params, ctx.problem, {})}
        wanted = set(variants)
        if wanted - {"S"}:
            with timer.step("pose"):
                p, losses = steps.params("pose", lambda: ctx.problem.run(
                    ctx.params, free, _pose_terms(cfg, False, False, focal),
                    cfg.pose.iterations))
                stages["SO"] = (p, ctx.problem_at(p), losses)
        if wanted & {"SO+T", "SO+GT"}:
            with timer.step("temporal"):
                p, problem, _ = stages["SO"]
                p, losses = steps.params("temporal", lambda: problem.run(
                    p, free, _pose_terms(cfg, True, False, focal), cfg.pose.iterations))
                stages["SO+T"] = (p, ctx.problem_at(p), losses)
        for name, base, temporal in (("SO+G", "SO", False), ("SO+GT", "SO+T", True)):
            if name not in wanted:
                continue
            p, problem, _ = stages[base]
            for r in range(cfg.ground_plane.rounds):
                with timer.step("ground_plane"):
                    plane = steps.plane(f"{name} ground_plane {r}",
                                        lambda: _estimate_ground(ctx, p, problem))
                with timer.step("ground_pose"):
                    problem = ctx.problem_at(p, plane)
                    p, losses = steps.params(f"{name} ground_pose {r}", lambda: problem.run(
                        p, free, _pose_terms(cfg, temporal, True, focal), cfg.pose.iterations))
            if cfg.ground_plane.raised_supports:
                p, problem, losses = _stand_on_supports(
                    ctx, p, problem, losses, _pose_terms(cfg, temporal, True, focal), free,
                    timer, steps, f"{name} support_pose")
            stages[name] = (p, problem, losses)
        for v in variants:
            p, problem, losses = stages[v]
            ground = v in ("SO+G", "SO+GT")
            plane = np.asarray(problem.data.plane) if ground else _level_ground(ctx, p, problem)
            out[v] = _result(ctx, dataclasses.replace(cfg, **_FLAGS[v]), p, problem, plane,
                             losses, dict(timer.timings))
    return out


_FLAGS = {v: {"optimize_pose": c.optimize_pose, "ground": c.ground, "temporal": c.temporal}
          for v in VARIANT_NAMES for c in (KinematicConfig.preset(v),)}


def _estimate_ground(ctx: _Context, params: Params, problem: Problem) -> np.ndarray:
    points, com = _posed_surface(ctx, params, problem)
    plane, _ = estimate_plane(points, ctx.surface.left_foot, ctx.surface.right_foot, com,
                              ctx.cfg.ground_plane)
    return plane


def _stand_on_supports(ctx: _Context, params: Params, problem: Problem, losses: dict,
                       terms: dict, free: tuple[str, ...], timer: _Timer,
                       steps: FitCheckpoints, step: str) -> tuple[Params, Problem, dict]:
    """Where the fitted feet stay raised above the floor for a while (diagnostics.raised_runs:
    the person stands on a box, a step), the poses again (all frames) with the ground and
    skate terms standing the feet on that support's top (supports.support_heights; the fit's
    result carries it, and the physics' support box is built at it) instead of the floor.
    Without it those terms never reach feet a metre up, and their depth wanders as nothing
    else holds it."""
    plane = np.asarray(problem.data.plane)
    joints = _result(ctx, ctx.cfg, params, problem, plane, {}, {}).joints
    fps = float(ctx.obs.fps)
    heights = supports.support_heights(joints, diagnostics.raised_runs(joints, fps), fps)
    if not heights.any():
        return params, problem, losses
    with timer.step("support_pose"):
        problem = ctx.problem_at(params, plane, heights)
        params, losses = steps.params(step, lambda: problem.run(
            params, free, terms, ctx.cfg.pose.iterations))
    return params, problem, losses


def _level_ground(ctx: _Context, params: Params, problem: Problem) -> np.ndarray:
    points, _ = _posed_surface(ctx, params, problem)
    return level_plane(points, ctx.surface.left_foot | ctx.surface.right_foot,
                       ctx.cfg.ground_plane.level_percentile)


def _camera_pose(params: Params, problem: Problem, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(root positions (n, 3), root rotations (n, 3, 3)) in camera axes."""
    R = np.asarray(problem.fixed.R0)[:n] @ np.asarray(rotvec_matrix(params.root_rotvec[:n]))
    return np.asarray(params.root_pos)[:n], R


def _posed_surface(ctx: _Context, params: Params, problem: Problem
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Surface points (T_valid, P, 3) and centres of mass (T_valid, 3) of the frames with
    evidence, camera axes."""
    valid = ctx.ev.valid
    n = len(valid)
    pos, R = _camera_pose(params, problem, n)
    seg_pos, seg_rot = segment_frames(ctx.shape.bones(), pos, R, np.asarray(params.angles)[:n])
    points = place(ctx.surface, seg_pos, seg_rot)
    return points[valid], centre_of_mass(ctx.shape, ctx.surface, points)[valid]


def _result(ctx: _Context, cfg: KinematicConfig, params: Params, problem: Problem,
            plane: np.ndarray, losses: dict, timings: dict) -> KinematicFit:
    obs, ev, shape = ctx.obs, ctx.ev, ctx.shape
    n = ev.num_frames
    pos, R = _camera_pose(params, problem, n)
    first = int(np.argmax(ev.valid))
    T_world2cam = cam.world_from_plane(plane[:3], float(plane[3]), pos[first])
    R_w2c, t_w2c = T_world2cam[:3, :3], T_world2cam[:3, 3]
    qpos = np.zeros((n, NQ))
    qpos[:, :3] = (pos - t_w2c) @ R_w2c
    quat = Rotation.from_matrix(np.einsum("ji,tjk->tik", R_w2c, R)).as_quat()  # x, y, z, w
    qpos[:, 3:7] = np.concatenate([quat[:, 3:], quat[:, :3]], axis=1)
    qpos[:, 7:] = np.asarray(params.angles)[:n]
    joints, landmarks = fk_qpos(shape.bones(), qpos)
    f = float(np.exp(np.asarray(params.log_focal)))
    K = cam.intrinsics(obs.image_size, f)
    K[:2, 2] = np.asarray(problem.fixed.principal)
    losses = dict(losses, depth_scale=float(np.exp(np.asarray(params.log_depth_scale))),
                  world_scale=float(np.exp(np.asarray(params.log_world_scale))))
    support = np.asarray(problem.data.support, dtype=float)[:n]
    return KinematicFit(fps=float(obs.fps), shape=shape, qpos=qpos, joints=joints,
                        landmarks=landmarks, camera_K=K, T_world2cam=T_world2cam,
                        variant=cfg.variant, ground_estimated=cfg.ground, losses=losses,
                        timings=timings, support_heights=support if support.any() else None,
                        label_exchanges=ctx.label_exchanges)


def _observation_arrays(obs: Observations) -> dict:
    return {"keypoints2d": np.asarray(obs.keypoints2d), "fps": float(obs.fps),
            "image_size": list(obs.image_size), "detected": np.asarray(obs.detected),
            "interpolated": np.asarray(obs.interpolated),
            "world_landmarks": None if obs.world_landmarks is None
            else np.asarray(obs.world_landmarks),
            "camera_K": None if obs.camera_K is None else np.asarray(obs.camera_K)}


def _to_arrays(fit: KinematicFit) -> dict[str, np.ndarray]:
    meta = {"fps": fit.fps, "shape": dataclasses.asdict(fit.shape), "variant": fit.variant,
            "ground_estimated": fit.ground_estimated, "losses": fit.losses,
            "timings": fit.timings, "label_exchanges": fit.label_exchanges}
    arrays = {"qpos": fit.qpos, "joints": fit.joints, "landmarks": fit.landmarks,
              "camera_K": fit.camera_K, "T_world2cam": fit.T_world2cam,
              "meta": np.array(json.dumps(meta))}
    if fit.support_heights is not None:
        arrays["support_heights"] = fit.support_heights
    return arrays


def _from_arrays(a: dict[str, np.ndarray]) -> KinematicFit:
    meta = json.loads(str(a["meta"]))
    return KinematicFit(fps=meta["fps"], shape=BodyShape(**meta["shape"]), qpos=a["qpos"],
                        joints=a["joints"], landmarks=a["landmarks"], camera_K=a["camera_K"],
                        T_world2cam=a["T_world2cam"], variant=meta["variant"],
                        ground_estimated=meta["ground_estimated"], losses=meta["losses"],
                        timings=meta["timings"], support_heights=a.get("support_heights"),
                        label_exchanges=meta.get("label_exchanges"))
