"""Trajectory optimisation (paper sec. 3.2): CMA-ES over servo-target spline coefficients.

``optimize_dynamics(body, kinematic_fit, observations, config) -> PhysicsResult``

Sequential windows (the default, as in the paper): each window starts from the simulated state
of the previous one at its first frame and searches the spline coefficients whose support
begins inside it; coefficients already acting before its start stay as the previous window's
search left them, so the whole clip is one simulation (driven by each window's kept targets:
the spline, or its refined per-step plan), except where the simulated
COM strays more than ``reset_distance`` from the estimate: the window is cut there and the run
restarts from the kinematic state (a recorded jump), as it does at a window whose search from
the simulated state finds no valid sample. Independent windows (the
paper's mode for long clips): every window starts from the kinematic state at its first frame,
searches all its coefficients, and the windows are searched side by side (their samples share
one batched rollout) and cross-faded where they overlap.

A window's CMA-ES search is search.py's and its iLQR refinement ilqr.py's; this module runs
the windows: their set-up, retries, cuts and restarts, and the join.

Every finished window is written to a run folder keyed by the inputs and the config, so an
interrupted run resumes at the first unfinished window. Same inputs, config and seed give the
same result.
"""

from __future__ import annotations

import dataclasses
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np
from tqdm import tqdm

from physpose.body import Body
from physpose.dynamics import checkpoint, quat
from physpose.dynamics.config import DynamicsConfig
from physpose.dynamics.forces import STEP_KEYS, frame_forces, missing_steps, step_forces
from physpose.dynamics.init import (Reference, geom_lowest, ground_motion, ground_state,
                                    initial_coefficients, inverse_dynamics,
                                    smooth_reference, smooth_sight_velocity)
from physpose.dynamics.objective import (ObjectiveReference, ObjectiveWeights, make_reference)
from physpose.dynamics.result import PhysicsResult, mean_window_loss
from physpose.dynamics.search import Best, search_averaged, window_seed
from physpose.dynamics.rollout import SimModel, Simulator, Trajectories, make_state, sim_model
from physpose.dynamics.spline import KnotGrid
from physpose.dynamics.stance import flatten_stance_feet
from physpose.dynamics.stretches import shift_stretches, stretch_shifts, translation_invariant
from physpose.dynamics.travel import camera_travel, camera_travels
from physpose.dynamics.balance import balance_plan
from physpose.dynamics.controller import track_reference
from physpose.dynamics.ilqr import ImageTerm, camera_centres, refine_targets
from physpose.dynamics.windows import (Window, WindowProblem, blend_weights, plan_windows,
                                       score, step_position, window_over)
from physpose.errors import PhysposeError, expect_type
from physpose.fk import site_positions
from physpose.joints import JOINT_NAMES
from physpose.reconstruction import restart_frames
from physpose.kinematics.result import KinematicFit
from physpose.observations import Observations
from physpose.skeleton import DOF_NAMES, NQ

MIN_FRAMES = 3
MIN_KEPT_SECONDS = 0.2  # a window cut short where it strays keeps at least this much


@dataclass(frozen=True, eq=False)
class _Setup:
    sim: SimModel
    windows: list[Window]
    grid: KnotGrid
    coefs0: np.ndarray        # (K, 48) initial coefficients
    reference: Reference      # smoothed estimate on the step grid
    objective: ObjectiveReference
    step_times: np.ndarray    # (N,) s, time of each control step
    frame_positions: np.ndarray  # (T,) the fractional simulation step of each frame
    root_residual: np.ndarray  # (N+1,) body weights, the estimate's unexplained root force
    head_height: np.ndarray   # (T,) m, the head joint's height in the estimate the windows follow
    start_qvel: np.ndarray    # (N+1, 54) velocities a window started from the estimate takes


def _check_inputs(body: Body, kin: KinematicFit, obs: Observations, config: DynamicsConfig,
                  bone_tolerance: float = 0.005) -> None:
    """PhysposeError, with a remedy, for inputs that do not belong together or are malformed."""
    for value, kind, what, remedy in (
            (body, Body, "body", "pass build_body(kinematic_fit.shape, scene)"),
            (kin, KinematicFit, "kinematic_fit", "pass fit_kinematics(observations)"),
            (obs, Observations, "observations", "pass the fit's observations"),
            (config, DynamicsConfig, "config", "pass e.g. physpose.dynamics.PRESETS['fast']")):
        expect_type(value, kind, f"optimize_dynamics' {what}", remedy)
    t = kin.num_frames
    if kin.qpos.shape != (t, NQ):
        raise PhysposeError(f"kinematic qpos has shape {kin.qpos.shape}, expected ({t}, {NQ})",
                            remedy="pass the KinematicFit of these observations")
    if obs.num_frames != t:
        raise PhysposeError(f"{obs.num_frames} observed frames but {t} kinematic frames",
                            path=obs.source, remedy="fit the kinematics on these observations")
    if abs(obs.fps - kin.fps) > 1e-6 * kin.fps:
        raise PhysposeError(f"observations at {obs.fps} fps, kinematics at {kin.fps} fps",
                            path=obs.source, remedy="fit the kinematics on these observations")
    if t < MIN_FRAMES:
        raise PhysposeError(f"{t} frames are too few for dynamics (need {MIN_FRAMES})",
                            path=obs.source, remedy="use a longer clip")
    bad = np.flatnonzero(~np.isfinite(kin.qpos).all(axis=1))
    if len(bad):
        raise PhysposeError("the kinematic estimate is not finite", path=obs.source,
                            frame=int(bad[0]), remedy="re-run the kinematic fit")
    bad = np.flatnonzero(np.abs(np.linalg.norm(kin.qpos[:, 3:7], axis=1) - 1.0) > 1e-3)
    if len(bad):
        raise PhysposeError("the kinematic estimate's root orientation is not a unit "
                            "quaternion (w, x, y, z)", path=obs.source, frame=int(bad[0]),
                            remedy="normalise qpos[:, 3:7], or re-run the kinematic fit")
    for name, shape in (("camera_K", (3, 3)), ("T_world2cam", (4, 4))):
        value = np.asarray(getattr(kin, name))
        if value.shape != shape or not np.isfinite(value).all():
            raise PhysposeError(f"the kinematic fit's {name} has shape {value.shape} or "
                                f"non-finite values, expected a finite {shape[0]}x{shape[1]} "
                                "matrix", path=obs.source, remedy="re-run the kinematic fit")
    # The body must have the fit's bones: the estimate's joint angles only put the body's
    # landmarks where the fit's were with the same segment lengths (its mass may differ).
    off = np.abs(body.shape.bones() - kin.shape.bones())
    if off.max() > bone_tolerance:
        raise PhysposeError(f"the body's bones differ from the kinematic fit's by up to "
                            f"{100 * off.max():.1f} cm", remedy="build the body from the fit's "
                            "shape: build_body(kinematic_fit.shape, scene)")


def _setup(sim: SimModel, kin: KinematicFit, obs: Observations, cfg: DynamicsConfig) -> _Setup:
    fps, dt = kin.fps, sim.dt
    windows = plan_windows(kin.num_frames, fps, dt, cfg.window, cfg.overlap,
                           anchor_last=cfg.independent, min_span=cfg.knot_spacing)
    num_steps = int(np.ceil(step_position(kin.num_frames - 1, fps, dt) - 1e-9))
    grounded = ground_motion(sim.model, kin.qpos, cfg.ground_snap) if cfg.ground_reference \
        else kin.qpos
    travel = None
    if camera_travels(cfg.camera, obs.camera_motion) and translation_invariant(sim.body.scene):
        # Filmed by a travelling camera: follow the estimate moved on by the camera's travel.
        travel = camera_travel(sim.model, grounded, fps)
        grounded = grounded.copy()
        grounded[:, :3] += travel
    if cfg.flat_stance:
        flat = flatten_stance_feet(sim.model, grounded, fps, sim.body.foot_geom_ids)
        grounded = ground_motion(sim.model, flat, cfg.ground_snap)
    reference = smooth_reference(grounded, fps, dt, num_steps, cfg.reference_knot_spacing)
    needs = inverse_dynamics(sim.model, reference, sim.body.foot_geom_ids,
                             sim.body.scene.ground_friction, cfg.contact_height)
    step_times = np.arange(num_steps) * dt
    grid = KnotGrid(cfg.knot_spacing, num_steps * dt)
    coefs0 = initial_coefficients(grid, step_times, needs.targets[:num_steps])
    frame_positions = step_position(np.arange(kin.num_frames), fps, dt)
    objective = make_reference(sim.model, grounded, obs.keypoints2d, kin.camera_K,
                               kin.T_world2cam, fps,
                               smooth_qpos=reference.qpos_at(frame_positions),
                               camera_travel=travel, swing_confidence=cfg.swing_confidence)
    head = mujoco.mj_name2id(sim.model, mujoco.mjtObj.mjOBJ_SITE, "head")
    return _Setup(sim=sim, windows=windows, grid=grid, coefs0=coefs0, reference=reference,
                  objective=objective, step_times=step_times, frame_positions=frame_positions,
                  root_residual=needs.root_residual,
                  head_height=site_positions(sim.model, [head], objective.qpos)[:, 0, 2],
                  start_qvel=_start_velocities(kin, reference, frame_positions, travel,
                                               cfg.start_sight_smoothing))


def _start_velocities(kin: KinematicFit, reference: Reference, frame_positions: np.ndarray,
                      travel: np.ndarray | None, sigma: float) -> np.ndarray:
    """The reference's velocities with the root's depth speed low-passed by ``sigma`` s
    (init.smooth_sight_velocity; as they are for 0), seen from the fit's camera (at the frames'
    fractional steps ``frame_positions``), which moved along ``travel`` (T, 3) where it
    travelled with the person."""
    if sigma <= 0:
        return reference.qvel
    centre = camera_centres(kin.T_world2cam, np.arange(reference.num_steps + 1),
                            frame_positions, travel)
    return smooth_sight_velocity(reference.qvel, reference.qpos[:, :3], centre, reference.dt,
                                 sigma)


def _kinematic_state(setup: _Setup, step: int, snap: float) -> np.ndarray:
    ref = setup.reference
    qpos = ground_state(setup.sim.model, ref.qpos[step], snap)
    return make_state(setup.sim, qpos, setup.start_qvel[step], time=step * setup.sim.dt)


def searched_dofs(search: str) -> np.ndarray:
    """Indices (DOF_NAMES) of the hinges whose targets the search varies."""
    if search == "all":
        return np.arange(len(DOF_NAMES))
    trunk = ("spine", "thorax") if search == "legs_trunk" else ()
    return np.array([k for k, n in enumerate(DOF_NAMES) if n.split("_")[0] in trunk
                     or n.split("_")[1] in ("hip", "knee", "ankle")])


def _problem(setup: _Setup, win: Window, coefs: np.ndarray, state0: np.ndarray,
             continued: bool, history: np.ndarray | None, cfg: DynamicsConfig) -> WindowProblem:
    free = setup.grid.searched(win.start_step * setup.sim.dt, win.end_step * setup.sim.dt,
                               continued)
    basis = setup.grid.basis(setup.step_times[win.start_step:win.end_step])
    mask = np.zeros(basis.shape[1], dtype=bool)
    mask[free] = True
    positions = step_position(win.frames, setup.objective.fps, setup.sim.dt) - win.start_step
    problem = WindowProblem(window=win, state0=state0, free=free, dofs=searched_dofs(cfg.search),
                            basis=basis[:, mask], fixed_ctrl=basis[:, ~mask] @ coefs[~mask],
                            start=coefs[free].copy(), positions=positions, history=history)
    if cfg.balance.enabled:
        plan = balance_plan(setup.sim.model, setup.reference, win.start_step, win.num_steps,
                            setup.sim.body.foot_geom_ids, setup.sim.body.kp, cfg.balance)
        problem = dataclasses.replace(problem, balance=plan)
    if not cfg.tracking_start:
        return problem
    _, tracked = track_reference(setup.sim.model, state0, setup.reference, win.start_step,
                                 win.num_steps, cfg.controller)
    return dataclasses.replace(problem, alternatives=(tracked,))


def _frame_outputs(setup: _Setup, b: Best, win: Window, frames: np.ndarray) -> dict:
    traj = Trajectories(states=b.states[None], sensors=b.sensors[None],
                        broken=np.zeros((1, len(b.states)), dtype=bool))
    pos = step_position(frames, setup.objective.fps, setup.sim.dt) - win.start_step
    s = traj.at(pos)
    return {"qpos": s.qpos[0], "joints": s.joints[0], "landmarks": s.landmarks[0], "com": s.com[0]}


def _record(win: Window, best: Best, initial: dict, evaluations: int, seconds: float,
            weights: ObjectiveWeights) -> dict:
    return {"index": win.index, "frames": [win.first, win.last],
            "steps": [win.start_step, win.end_step], "evaluations": evaluations,
            "loss_initial": initial["loss"], "terms_initial": initial["terms"],
            "initial_valid": initial["valid"], "loss_final": best.loss, "valid": best.valid,
            "start": ("inverse_dynamics", "tracking")[initial["start"]],
            "attempts": initial.get("attempts", 1), "handover_error": initial.get("handover_error"),
            "attempt_log": initial.get("attempt_log"),
            "kept": initial.get("kept", "search 0"), "search_losses": initial.get("search_losses"),
            "terms_final": best.terms, "weights": weights.as_dict(), "seconds": seconds,
            **({"refine": initial["refine"]} if "refine" in initial else {})}


_OUTPUT_KEYS = ("qpos", "joints", "landmarks", "com")  # per frame
_STEP_OUTPUT_KEYS = ("ctrl", *STEP_KEYS)  # per simulation step


def _step_outputs(setup: _Setup, best: Best, steps: int, timing: dict) -> dict:
    """The servo targets of a window's first ``steps`` steps and the forces during them
    (forces.py; their seconds added to timing["forces"])."""
    start = time.perf_counter()
    ctrl = best.ctrl[:steps]
    forces = step_forces(setup.sim.model, setup.sim.body.foot_geom_ids, best.states[:len(ctrl)],
                         ctrl)
    timing["forces"] = timing.get("forces", 0.0) + time.perf_counter() - start
    return {"ctrl": ctrl, **forces}


def _with_forces(arrays: dict) -> dict:
    """A checkpointed window's arrays, with NaN forces where it was written without them."""
    if all(k in arrays for k in STEP_KEYS):
        return arrays
    return {**arrays, **missing_steps(len(arrays["ctrl"]))}


def _handover_error(setup: _Setup, best: Best, win: Window, step_end: int) -> float:
    """Distance (m) between the simulated and the kinematic COM where the next window starts
    (infinite for an invalid result)."""
    if not best.valid:
        return np.inf
    com = best.sensors[step_end - win.start_step, -3:]
    frame = int(round(step_end * setup.sim.dt * setup.objective.fps))
    return float(np.linalg.norm(com - setup.objective.com[min(frame, len(setup.objective.com) - 1)]))


def _refine(setup: _Setup, problem: WindowProblem, best: Best, initial: dict,
            simulator: Simulator, cfg: DynamicsConfig, timing: dict,
            step_end: int | None = None) -> tuple[Best, dict]:
    """The search's result refined by iLQR (ilqr.py) towards the reference; kept when it is
    valid and its objective is at most ``keep_ratio`` times the search's (the objective and the
    refinement's tracking cost differ, so a small rise is allowed). The record gets
    ``refine``: tracking cost before and after, objective before, seconds, kept. step_end:
    where the next window starts from this one's state (None for independent windows)."""
    win = problem.window
    ref = setup.reference
    steps = np.minimum(np.arange(win.start_step, win.end_step + 1), ref.num_steps)
    model, foot_geoms = setup.sim.model, setup.sim.body.foot_geom_ids
    feet = (foot_geoms["l"], foot_geoms["r"])
    objective, image = setup.objective, None
    if cfg.refine.image or cfg.refine.root_depth:
        frames = win.frames
        travel = objective.camera_travel
        image = ImageTerm(steps=np.round(problem.positions).astype(int),
                          keypoints=objective.keypoints2d[frames],
                          metres_per_px=objective.metres_per_px[frames], K=objective.camera_K,
                          T_world2cam=objective.T_world2cam,
                          site_ids=setup.sim.body.landmark_site_ids,
                          camera_travel=None if travel is None else travel[frames])
    refined = refine_targets(model, problem.state0, best.ctrl[:win.num_steps], ref.qpos[steps],
                             ref.qvel[steps], cfg.refine, cfg.nthread, feet, image,
                             handover_step=None if step_end is None
                             else step_end - win.start_step)
    timing["refine"] = timing.get("refine", 0.0) + refined.seconds
    traj = simulator.run(problem.state0, refined.ctrl[None])
    scores, _ = score(problem.starting_from(refined.ctrl), traj, setup.objective, cfg.weights,
                      cfg.max_root_distance, cfg.max_penetration)
    loss = float(scores.total[0])
    keep = bool(np.isfinite(loss)) and (not best.valid
                                        or loss <= cfg.refine.keep_ratio * best.loss)
    record = {"cost_initial": refined.costs[0], "cost_final": refined.costs[-1],
              "loss_searched": best.loss, "seconds": refined.seconds, "kept": keep}
    initial = dict(initial, refine=record)
    if not keep:
        return best, initial
    return Best(x=best.x, loss=loss, fitness=loss, valid=True,
                terms={n: float(v[0]) for n, v in scores.terms.items()},
                states=traj.states[0].copy(), sensors=traj.sensors[0].copy(),
                ctrl=traj.ctrl[0].copy()), initial


def _finite_or_none(value: float) -> float | None:
    return float(value) if np.isfinite(value) else None


def _search_with_retries(problem: WindowProblem, simulator: Simulator, setup: _Setup,
                         cfg: DynamicsConfig, timing: dict, w: int, step_end: int, label: str,
                         progress: bool) -> tuple[WindowProblem, Best, dict, int]:
    """Search a window; while its best sample hands the next window a state whose COM is more
    than ``retry_distance`` from the estimate's (a fall in the making) or is invalid, search
    again with another seed and a larger step size, up to ``retries`` times. Keeps the attempt
    with the smallest handover error; returns its problem as searched (with its chosen start),
    best sample, initial record and the number of evaluations. The record's ``attempt_log``
    gives, per attempt, the handover error (m; None where invalid) after the search
    (``searched``) and after the refinement (``refined``, absent where it was not refined),
    and the attempt's seconds (all of it, and the refinement's). An attempt whose search
    hands on a COM further than ``refine_within`` is refined only if it is kept; one whose
    search hands on a COM further than ``retry_within`` (or an invalid state) is not retried."""
    chosen, evaluations, first_start, attempt_log = None, 0, None, []
    # Without search iterations an attempt is only its start (and its refinement): retrying
    # makes sense only from the other start guess.
    attempts = cfg.retries + 1 if cfg.iterations else min(cfg.retries + 1,
                                                          1 + len(problem.alternatives))
    for attempt in range(attempts):
        start = time.perf_counter()
        attempt_cfg = dataclasses.replace(cfg, sigma0=cfg.sigma0 * 1.5 ** attempt)
        # The first retry of a window with two start guesses goes on from the other one: the
        # better-scoring start can still be the one heading for a fall.
        force = 1 - first_start if attempt == 1 and problem.alternatives else None
        (searched,), (best,), (initial,), (count,) = search_averaged(
            [problem], simulator, setup.objective, attempt_cfg, timing,
            [window_seed(cfg.seed + 7919 * attempt, w)],
            label + (f" retry {attempt}" if attempt else ""), progress, force_start=force)
        if attempt == 0:
            first_start = initial["start"]
        evaluations += count
        error = _handover_error(setup, best, problem.window, step_end)
        attempt_log.append({"searched": _finite_or_none(error)})
        # A refinement moves the handover by centimetres: one that cannot bring the attempt
        # under retry_distance is spent only if the attempt is kept (below).
        refined = cfg.refine.enabled and error <= cfg.refine_within
        hopeless = not error <= cfg.retry_within
        if refined:
            best, initial, error = _refine_logged(setup, searched, best, initial, simulator, cfg,
                                                  timing, step_end, attempt_log[-1])
        attempt_log[-1]["seconds"] = time.perf_counter() - start
        if chosen is None or error < chosen[3]:
            chosen = (searched, best, initial, error, attempt, refined)
        if error <= cfg.retry_distance or hopeless:
            break
    searched, best, initial, error, kept, refined = chosen
    if cfg.refine.enabled and not refined:
        start = time.perf_counter()
        best, initial, error = _refine_logged(setup, searched, best, initial, simulator, cfg,
                                              timing, step_end, attempt_log[kept])
        attempt_log[kept]["seconds"] += time.perf_counter() - start
    initial = dict(initial, attempts=attempt + 1, handover_error=error, attempt_log=attempt_log)
    return searched, best, initial, evaluations


def _refine_logged(setup: _Setup, searched: WindowProblem, best: Best, initial: dict,
                   simulator: Simulator, cfg: DynamicsConfig, timing: dict, step_end: int,
                   log: dict) -> tuple[Best, dict, float]:
    """_refine, then the handover error of its result, both noted in an attempt's ``log``."""
    best, initial = _refine(setup, searched, best, initial, simulator, cfg, timing, step_end)
    error = _handover_error(setup, best, searched.window, step_end)
    log.update(refined=_finite_or_none(error), refine_seconds=initial["refine"]["seconds"])
    return best, initial, error


def _restart_point(setup: _Setup, win: Window, coefs: np.ndarray, cfg: DynamicsConfig
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The state and coefficients a window restarted from the kinematic state begins with:
    the estimate's state at its first step, and the initial coefficients from there on."""
    state = _kinematic_state(setup, win.start_step, cfg.ground_snap)
    active = setup.grid.active(win.start_step * setup.sim.dt, setup.grid.duration).start
    return state, np.where(np.arange(len(coefs))[:, None] >= active, setup.coefs0, coefs)


def _stray_frame(setup: _Setup, win: Window, arrays: dict, cfg: DynamicsConfig) -> int | None:
    """First frame a window keeps (``arrays``: its kept frames from win.first) at which the
    simulated body has strayed, or None: its COM more than ``reset_distance`` from the
    estimate's, or its head more than ``fall_distance`` below the estimate's. A cut keeps at
    least MIN_KEPT_SECONDS of the window and leaves at least two frames for the restart."""
    keep = max(1, int(round(MIN_KEPT_SECONDS * setup.objective.fps)))
    kept = slice(win.first, win.first + len(arrays["com"]))
    strayed = np.linalg.norm(arrays["com"] - setup.objective.com[kept], axis=-1) \
        > cfg.reset_distance
    drop = setup.head_height[kept] - arrays["joints"][:, JOINT_NAMES.index("head"), 2]
    strayed |= drop > cfg.fall_distance
    far = np.flatnonzero(strayed[keep:])
    if not len(far):
        return None
    cut = win.first + keep + int(far[0])
    return cut if cut < win.last else None


def _cut_window(win: Window, arrays: dict, restart: Window) -> dict:
    """A window's outputs and controls kept only up to where ``restart`` begins."""
    kept, kept_steps = restart.first - win.first, restart.start_step - win.start_step
    return dict(arrays, **{k: arrays[k][:kept_steps] for k in _STEP_OUTPUT_KEYS},
                **{k: arrays[k][:kept] for k in _OUTPUT_KEYS})


class _Pace:
    """The time left, from the mean seconds of the windows this run optimised (a long clip has
    hundreds of windows, each with its own bar)."""

    def __init__(self) -> None:
        self.seconds, self.windows = 0.0, 0

    def add(self, seconds: float, windows: int = 1) -> None:
        self.seconds, self.windows = self.seconds + seconds, self.windows + windows

    def left(self, windows: int) -> str:
        """' (about 1 h 31 min left)' for that many windows to go, or '' before two are done."""
        if self.windows < 2 or windows < 1:
            return ""
        minutes = round(self.seconds / self.windows * windows / 60)
        if minutes < 1:
            return " (under a minute left)"
        hours, minutes = divmod(minutes, 60)
        return f" (about {f'{hours} h ' if hours else ''}{minutes} min left)"


def _run_sequential(setup: _Setup, simulator: Simulator, cfg: DynamicsConfig, folder: Path | None,
                    progress: bool, timing: dict) -> tuple[dict, dict, list[dict]]:
    wins = list(setup.windows)  # a window that strays is cut short: the plan changes
    coefs = setup.coefs0.copy()
    state = _kinematic_state(setup, 0, cfg.ground_snap)
    parts: dict[str, list[np.ndarray]] = {k: [] for k in _OUTPUT_KEYS}
    step_parts: dict[str, list[np.ndarray]] = {k: [] for k in _STEP_OUTPUT_KEYS}
    records = []
    reset = False
    pace = _Pace()
    w = 0
    while w < len(wins):
        win = wins[w]
        commit_end = wins[w + 1].first if w + 1 < len(wins) else win.last + 1
        step_end = wins[w + 1].start_step if w + 1 < len(wins) else win.end_step
        continued = bool(w) and not reset
        saved = checkpoint.load_window(folder, w) if folder is not None else None
        if saved is None:
            start = time.perf_counter()
            joints_so_far = np.concatenate(parts["joints"]) if parts["joints"] else np.zeros((0,))
            history = joints_so_far[max(0, win.first - 2):win.first] if continued else None
            label = f"dynamics window {w + 1}/{len(wins)}{pace.left(len(wins) - w)}"
            problem = _problem(setup, win, coefs, state, continued, history, cfg)
            problem, best, initial, evaluations = _search_with_retries(
                problem, simulator, setup, cfg, timing, w, step_end, label, progress)
            restarted = continued and not best.valid
            if restarted:
                # No sample from the state handed over stayed valid: that state was already
                # heading for a fall. The window restarts from the kinematic state at its own
                # first frame instead (a recorded jump, as after a strayed handover), rather
                # than keep the least bad fall.
                continued_log = {"attempt_log": initial["attempt_log"],
                                 "evaluations": evaluations,
                                 "loss_initial": _finite_or_none(initial["loss"])}
                state, coefs = _restart_point(setup, win, coefs, cfg)
                problem = _problem(setup, win, coefs, state, False, None, cfg)
                problem, best, initial, more = _search_with_retries(
                    problem, simulator, setup, cfg, timing, w, step_end,
                    label + " from the estimate", progress)
                evaluations += more
            coefs = coefs.copy()
            coefs[problem.free] = problem.coefficients(best.x[None])[0]
            steps = _step_outputs(setup, best, step_end - win.start_step, timing)
            out = _frame_outputs(setup, best, win, np.arange(win.first, commit_end))
            next_state = best.states[step_end - win.start_step]
            record = _record(win, best, initial, evaluations, time.perf_counter() - start,
                             cfg.weights)
            pace.add(record["seconds"])
            if restarted:  # what the search from the state handed over found, kept
                record.update(restarted=True, continued=continued_log)
            arrays = {"coefs": coefs, "next_state": next_state, **steps, **out}
            if folder is not None:
                checkpoint.save_window(folder, w, arrays, record)
        else:  # optimised by an earlier run: its seconds are not this run's
            arrays, record = _with_forces(saved[0]), dict(saved[1], resumed=True)
        if record.get("restarted"):
            records[-1] = dict(records[-1], reset_after=True)
        coefs, state = arrays["coefs"], arrays["next_state"]
        # A window that could not keep the body near the estimate hands on a restart from the
        # kinematic state instead of a fall in progress (a jump in the output, recorded):
        # from the first kept frame whose COM strayed further than reset_distance (or whose
        # head fell further than fall_distance below the estimate's), or else from the next
        # window's start when the handover state's COM has strayed that far.
        cut = _stray_frame(setup, win, arrays, cfg)
        if cut is not None:
            following = wins[w + 1] if w + 1 < len(wins) else win
            restart = window_over(w + 1, cut, following.last, setup.objective.fps, setup.sim.dt)
            arrays = _cut_window(win, arrays, restart)
            wins[w + 1:w + 2] = [restart]
        reset = w + 1 < len(wins) and (cut is not None or (
            record.get("handover_error") is not None
            and record["handover_error"] > cfg.reset_distance))
        if reset:
            state, coefs = _restart_point(setup, wins[w + 1], coefs, cfg)
        record = dict(record, reset_after=bool(reset), cut_at=cut)
        for k in _OUTPUT_KEYS:
            parts[k].append(arrays[k])
        for k in step_parts:
            step_parts[k].append(arrays[k])
        records.append(record)
        w += 1
    return ({k: np.concatenate(v) for k, v in parts.items()},
            {k: np.concatenate(v) for k, v in step_parts.items()}, records)


def _run_independent(setup: _Setup, simulator: Simulator, cfg: DynamicsConfig,
                     folder: Path | None, progress: bool, timing: dict
                     ) -> tuple[dict, dict, list[dict]]:
    wins = setup.windows
    # The steps each window contributes: up to the next one's start (the rest is cross-faded
    # motion, and its controls and forces are not kept).
    kept = [(wins[w + 1].start_step if w + 1 < len(wins) else wins[w].end_step)
            - wins[w].start_step for w in range(len(wins))]
    results: list[tuple[dict, dict] | None] = [
        checkpoint.load_window(folder, w) if folder is not None else None for w in range(len(wins))]
    results = [None if r is None else (_with_forces(r[0]), dict(r[1], resumed=True))
               for r in results]
    todo = [w for w in range(len(wins)) if results[w] is None]
    pace = _Pace()
    for g in range(0, len(todo), cfg.parallel_windows):
        group = todo[g:g + cfg.parallel_windows]
        start = time.perf_counter()
        problems = [_problem(setup, wins[w], setup.coefs0,
                             _kinematic_state(setup, wins[w].start_step, cfg.ground_snap),
                             False, None, cfg) for w in group]
        label = (f"dynamics windows {group[0] + 1}-{group[-1] + 1}/{len(wins)}"
                 f"{pace.left(len(todo) - g)}")
        searched, bests, initials, counts = search_averaged(
            problems, simulator, setup.objective, cfg, timing,
            [window_seed(cfg.seed, w) for w in group], label, progress)
        if cfg.refine.enabled:
            for i in range(len(group)):
                bests[i], initials[i] = _refine(setup, searched[i], bests[i], initials[i],
                                                simulator, cfg, timing)
        elapsed = time.perf_counter() - start
        pace.add(elapsed, len(group))
        seconds = elapsed / len(group)
        for i, w in enumerate(group):
            win, best = wins[w], bests[i]
            out = _frame_outputs(setup, best, win, win.frames)
            record = _record(win, best, initials[i], counts[i], seconds, cfg.weights)
            arrays = {**_step_outputs(setup, best, kept[w], timing), **out}
            if folder is not None:
                checkpoint.save_window(folder, w, arrays, record)
            results[w] = (arrays, record)
    weights = blend_weights(wins, setup.objective.qpos.shape[0])
    joined = {}
    for k in _OUTPUT_KEYS:
        acc = None
        for w, win in enumerate(wins):
            part = results[w][0][k]
            wk = weights[w, win.first:win.last + 1].reshape((-1,) + (1,) * (part.ndim - 1))
            if acc is None:
                acc = np.zeros((weights.shape[1],) + part.shape[1:])
            if k == "qpos":  # quaternions: align signs before the cross-fade, renormalise after
                part = part.copy()
                sign = np.sign(np.sum(part[:, 3:7] * acc[win.first:win.last + 1, 3:7], axis=-1))
                part[:, 3:7] *= np.where(sign < 0, -1.0, 1.0)[:, None]
            acc[win.first:win.last + 1] += wk * part
        joined[k] = acc
    joined["qpos"][:, 3:7] = quat.normalised(joined["qpos"][:, 3:7])
    # The windows' kept steps one after another (not cross-faded).
    steps = {k: np.concatenate([results[w][0][k][:kept[w]] for w in range(len(wins))])
             for k in _STEP_OUTPUT_KEYS}
    return joined, steps, [results[w][1] for w in range(len(wins))]


def foot_heights(model: mujoco.MjModel, qpos: np.ndarray, foot_geoms: dict[str, int]
                 ) -> np.ndarray:
    """(T, 2) lowest z (m) of the left and right foot boxes for qpos (T, 55)."""
    data = mujoco.MjData(model)
    out = np.empty((len(qpos), 2))
    for t, q in enumerate(qpos):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        out[t] = [geom_lowest(model, data, foot_geoms[side]) for side in ("l", "r")]
    return out


def run_inputs(body: Body, kin: KinematicFit, obs: Observations, travels: bool = False) -> dict:
    """What a dynamics run depends on besides its config (for the checkpoint key); travels:
    the run follows a travelling camera (travel.py)."""
    inputs = {"qpos": kin.qpos, "fps": kin.fps, "keypoints2d": obs.keypoints2d,
              "camera_K": kin.camera_K, "T_world2cam": kin.T_world2cam, "body_xml": body.xml}
    if travels:  # since stop 30 (the key of every other run is as before)
        inputs["camera_travel"] = True
    if body.scene.obstacles:  # since stop 25 the initial targets let the soles push on boxes
        inputs["box_support"] = True
    return inputs


def reference_motion(body: Body, kinematic_fit: KinematicFit, observations: Observations,
                     config: DynamicsConfig = DynamicsConfig()) -> np.ndarray:
    """(T, 55) qpos at the frames: the motion the windows are asked to follow, i.e. the
    estimate put onto the floor, its standing feet laid flat (``flat_stance``) and low-passed
    (``reference_knot_spacing``), moved on by a travelling camera's path where ``camera``
    says so. No physics: it tells what the physics stage's preparation alone does to the
    estimate (the benchmark's ``dynamics-reference`` and ``truth-reference``)."""
    _check_inputs(body, kinematic_fit, observations, config)
    setup = _setup(sim_model(body), kinematic_fit, observations, config)
    return setup.reference.qpos_at(setup.frame_positions)


def optimize_dynamics(body: Body, kinematic_fit: KinematicFit, observations: Observations,
                      config: DynamicsConfig = DynamicsConfig(), *,
                      checkpoint_dir: str | Path | None = None, checkpoints: bool = True,
                      progress: bool = True) -> PhysicsResult:
    """Simulated motion of ``body`` that reproduces the kinematic estimate and the detections.

    checkpoint_dir: root of the run folders (default: the stage cache); checkpoints=False
    writes and reads none. progress: a tqdm bar per window on stderr.
    """
    _check_inputs(body, kinematic_fit, observations, config)
    timing: dict[str, float] = {}
    t0 = time.perf_counter()
    sim = sim_model(body)
    setup = _setup(sim, kinematic_fit, observations, config)  # the same for every seed
    timing["prepare"] = time.perf_counter() - t0
    run = _run_independent if config.independent else _run_sequential
    travel = setup.objective.camera_travel
    inputs = run_inputs(body, kinematic_fit, observations, travel is not None) \
        if checkpoints else None
    runs, table = [], []
    with Simulator(sim, config.nthread) as simulator:
        # Candidates: whole-clip runs with seeds seed, seed + 1, ..., each checkpointed as
        # the single run of its seed; the lowest mean window loss is kept.
        for j in range(config.candidates):
            single = dataclasses.replace(config, seed=config.seed + j, candidates=1)
            if config.candidates > 1 and progress:
                tqdm.write(f"dynamics: candidate {j + 1}/{config.candidates} "
                           f"(seed {single.seed})", file=sys.stderr)
            folder = None
            if checkpoints:
                key = checkpoint.run_key(single.window_identity(), inputs)
                folder = checkpoint.run_folder(key, checkpoint_dir)
            outputs, steps, records = run(setup, simulator, single, folder, progress, timing)
            runs.append((outputs, steps, records))
            valid = all(r["valid"] for r in records)
            table.append({"seed": single.seed,
                          "loss": mean_window_loss(records) if valid else float("inf")})
    k = min(range(len(runs)), key=lambda j: table[j]["loss"])
    outputs, steps, records = runs[k]
    outputs = {**outputs, **frame_forces(steps, setup.frame_positions,
                                         1.0 / (kinematic_fit.fps * sim.dt))}
    # The estimate's unexplained root force: the median over each window's steps, and per frame.
    residual = setup.root_residual
    records = [dict(r, reference_residual=float(np.median(residual[r["steps"][0]:
                                                                    r["steps"][1] + 1])))
               for r in records]
    restarts = restart_frames(records)
    shifts = np.zeros((0, 2))
    if config.place_stretches and not config.independent and translation_invariant(body.scene):
        shifts = stretch_shifts(outputs["com"], setup.objective.com, restarts)
        outputs = shift_stretches(outputs, restarts, shifts)
    timing["total"] = time.perf_counter() - t0
    # This run's optimisation; windows resumed from checkpoints took theirs in an earlier one.
    timing["search"] = sum(r["seconds"] for _, _, recs in runs for r in recs
                           if not r.get("resumed"))
    candidates = [dict(row, kept=j == k) for j, row in enumerate(table)] \
        if config.candidates > 1 else []
    return PhysicsResult(
        fps=kinematic_fit.fps, qpos=outputs["qpos"], joints=outputs["joints"],
        landmarks=outputs["landmarks"], com=outputs["com"],
        foot_heights=foot_heights(sim.model, outputs["qpos"], body.foot_geom_ids),
        ctrl=steps["ctrl"], grf=outputs["grf"], cop=outputs["cop"], torques=outputs["torques"],
        windows=records, timings=timing, config=config.identity(), candidates=candidates,
        reference_residual=residual[np.round(setup.frame_positions).astype(int)],
        stretch_shifts=shifts, camera_travel=travel)
