"""Speed of the dynamics stage: wall time per second of video, default (fast) and paper presets.

    uv run python benchmarks/bench_dynamics.py [--seconds 4] [--paper-iterations 3]

The input is a simulated motion (physpose.dynamics.synthetic: a weight shift and a step), so
the benchmark needs no evaluation material. The fast preset runs the whole clip; the paper
preset (2000 iterations x 100 samples per 1 s window) is timed on one 1 s window for a few
iterations and extrapolated to its 2000 (reported as such). Rollout throughput (one-second
rollouts per second, two threads, open loop and under balance feedback) is printed for
reference, and so is the tracking controller's speed (the second start guess of every
window; seconds of wall time per simulated second). The fast preset refines every window by
iLQR after its search (dynamics/ilqr.py); it is also timed with the search alone and with the
iLQR alone (no CMA-ES iterations). ``--refine N`` sets the iLQR iterations (0: the search
alone only). Timings on a shared 2-core machine are noisy: compare ratios.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time

import numpy as np

from physpose.benchmark.runner import machine_description
from physpose.body import build_body, standing_qpos
from physpose.dynamics import PRESETS, optimize_dynamics
from physpose.dynamics.balance import BalanceGains, balance_plan
from physpose.dynamics.controller import track_reference
from physpose.dynamics.init import Reference, smooth_reference
from physpose.dynamics.rollout import Simulator, make_state, sim_model
from physpose.dynamics.synthetic import simulated_clip
from physpose.shape import BodyShape


def rollout_rate(body, batch: int = 32, seconds: float = 1.0, repeats: int = 3,
                 balance: bool = False) -> float:
    """One-second rollouts per second of wall time (two threads), standing body; with
    balance, under balance feedback at 0.5 Hz (chunked rollouts)."""
    sim = sim_model(body)
    q0 = standing_qpos(body)
    steps = int(round(seconds / sim.dt))
    ctrl = np.tile(q0[7:], (batch, steps, 1))
    ctrl += np.random.default_rng(0).normal(0.0, 0.02, ctrl.shape)
    feedback = None
    if balance:
        still = Reference(dt=sim.dt, qpos=np.tile(q0, (steps + 1, 1)),
                          qvel=np.zeros((steps + 1, sim.model.nv)),
                          qacc=np.zeros((steps + 1, sim.model.nv)))
        plan = balance_plan(sim.model, still, 0, steps, body.foot_geom_ids, body.kp,
                            BalanceGains(frequency=0.5))
        feedback = [(slice(0, batch), plan)]
    with Simulator(sim, nthread=2) as simulator:
        state0 = make_state(sim, q0, np.zeros(sim.model.nv))
        simulator.run(state0, ctrl[:2])
        start = time.perf_counter()
        for _ in range(repeats):
            simulator.run(state0, ctrl, feedback)
        elapsed = time.perf_counter() - start
    return batch * repeats * seconds / elapsed


def tracking_cost(body, fit, seconds: float = 1.0, repeats: int = 3) -> float:
    """Wall seconds per simulated second of the tracking controller following ``fit`` (the
    fast preset's reference smoothing and controller gains)."""
    fast = PRESETS["fast"]
    sim = sim_model(body)
    steps = int(round(seconds / sim.dt))
    ref = smooth_reference(fit.qpos, fit.fps, sim.dt, steps, fast.reference_knot_spacing)
    state0 = make_state(sim, ref.qpos[0], ref.qvel[0])
    start = time.perf_counter()
    for _ in range(repeats):
        track_reference(sim.model, state0, ref, 0, steps, fast.controller)
    return (time.perf_counter() - start) / (repeats * seconds)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=4.0, help="clip length (s)")
    ap.add_argument("--motion", default="step", help="simulated motion (stand, shift, step)")
    ap.add_argument("--paper-iterations", type=int, default=3,
                    help="iterations of the paper preset to time (extrapolated to 2000)")
    ap.add_argument("--refine", type=int,
                    help="iLQR iterations per window of the fast preset (default: the "
                         "preset's; 0 times the search alone)")
    ap.add_argument("--json", help="also write the figures to this file")
    args = ap.parse_args()

    body = build_body(BodyShape.from_height(1.75))
    fit, obs, _ = simulated_clip(body, args.motion, seconds=args.seconds)
    video_s = (fit.num_frames - 1) / fit.fps
    out = {"machine": machine_description(),
           "clip": f"simulated {args.motion}, {video_s:.2f} s at {fit.fps:g} fps",
           "rollouts_per_s": rollout_rate(body),
           "rollouts_per_s_with_balance": rollout_rate(body, balance=True),
           "tracking_s_per_simulated_s": tracking_cost(body, fit)}

    fast = PRESETS["fast"]
    if args.refine is not None:
        fast = dataclasses.replace(fast, refine=dataclasses.replace(fast.refine,
                                                                    iterations=args.refine))
    runs = {"fast": fast}
    if fast.refine.enabled:  # the search alone, and the iLQR alone (no CMA-ES iterations)
        runs["search_only"] = dataclasses.replace(fast, refine=dataclasses.replace(
            fast.refine, iterations=0))
        runs["ilqr_only"] = dataclasses.replace(fast, iterations=0)
    for name, cfg in runs.items():
        start = time.perf_counter()
        res = optimize_dynamics(body, fit, obs, cfg, checkpoints=False, progress=False)
        wall = time.perf_counter() - start
        err = np.linalg.norm(res.joints - fit.joints, axis=-1).mean()
        out[name] = {"wall_s": wall, "wall_s_per_video_s": wall / video_s,
                     "windows": len(res.windows),
                     "rollouts": int(sum(w["evaluations"] for w in res.windows)),
                     "refine_s": res.timings.get("refine", 0.0),
                     "timings_s": res.timings, "mpjpe_to_input_mm": 1000 * err}

    paper = dataclasses.replace(PRESETS["paper"], iterations=args.paper_iterations)
    window = fit.num_frames if video_s <= 1.0 else int(round(fit.fps)) + 1
    one = dataclasses.replace(fit, qpos=fit.qpos[:window], joints=fit.joints[:window],
                              landmarks=fit.landmarks[:window])
    one_obs = obs.replace(keypoints2d=obs.keypoints2d[:window], timestamps=obs.timestamps[:window],
                          detected=obs.detected[:window], interpolated=obs.interpolated[:window],
                          world_landmarks=obs.world_landmarks[:window])
    start = time.perf_counter()
    res = optimize_dynamics(body, one, one_obs, paper, checkpoints=False, progress=False)
    wall = time.perf_counter() - start
    search = res.timings["search"]
    per_iteration = search / max(args.paper_iterations, 1)
    out["paper_one_window"] = {
        "iterations_timed": args.paper_iterations, "wall_s": wall,
        "seconds_per_iteration": per_iteration,
        "extrapolated_2000_iterations_s": res.timings["prepare"] + per_iteration * 2000}

    print(f"{out['clip']}; {out['machine']}")
    print(f"rollouts: {out['rollouts_per_s']:.0f} one-second rollouts/s (2 threads); "
          f"{out['rollouts_per_s_with_balance']:.0f} with balance feedback (20 ms chunks)")
    print(f"tracking controller: {out['tracking_s_per_simulated_s']:.2f} s per simulated second")
    labels = {"fast": f"fast preset ({fast.refine.iterations} iLQR iterations per window)",
              "search_only": "the search alone (no iLQR)",
              "ilqr_only": f"iLQR alone ({fast.refine.iterations} iterations, no search)"}
    for name in runs:
        r = out[name]
        print(f"{labels[name]}: {r['wall_s']:.1f} s for {video_s:.2f} s of video = "
              f"{r['wall_s_per_video_s']:.1f} s per second ({r['windows']} windows, "
              f"{r['rollouts']} rollouts, iLQR {r['refine_s']:.1f} s); MPJPE to the input "
              f"{r['mpjpe_to_input_mm']:.1f} mm")
    p = out["paper_one_window"]
    print(f"paper preset, one 1 s window: {p['seconds_per_iteration']:.2f} s per iteration x "
          f"2000 = {p['extrapolated_2000_iterations_s'] / 60:.0f} min (extrapolated from "
          f"{p['iterations_timed']} iterations)")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=2)


if __name__ == "__main__":
    main()
