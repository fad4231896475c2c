"""Simulation speed of the body: steps/s single-threaded (mj_step) and batched (mujoco.rollout).

Two motions: holding the standing pose, and walking-like servo targets (hips, knees and
shoulders swinging at 1 Hz, so the feet leave and hit the ground; open loop, so the body
loses balance within a few seconds and the run also covers falling and lying contacts).
Batched runs start many perturbed initial states, as the trajectory optimisation does. Usage:

    uv run python benchmarks/bench_body.py --out out/bench_body.json [--threads 2]
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import mujoco
import numpy as np
from mujoco import rollout

from physpose.benchmark.runner import machine_description
from physpose.body import Body, build_body, standing_qpos
from physpose.shape import BodyShape
from physpose.skeleton import DOF_NAMES, NUM_DOF

_WALK_HZ = 1.0  # stride frequency, Hz
_SWING = {"hip_y": 0.45, "knee_y": 0.6, "shoulder_y": 0.35, "elbow_y": 0.3}  # amplitudes, rad


def targets(body: Body, motion: str, steps: int) -> np.ndarray:
    """Servo targets (steps, 48) for 'stand' or 'walk'."""
    stand = standing_qpos(body)[7:]
    ctrl = np.tile(stand, (steps, 1))
    if motion == "walk":
        t = np.arange(steps) * body.model.opt.timestep
        for side, phase in (("l", 0.0), ("r", np.pi)):
            s = np.sin(2 * np.pi * _WALK_HZ * t + phase)
            ctrl[:, DOF_NAMES.index(f"{side}_hip_y")] += -_SWING["hip_y"] * s
            ctrl[:, DOF_NAMES.index(f"{side}_knee_y")] += _SWING["knee_y"] * np.clip(s, 0, None)
            ctrl[:, DOF_NAMES.index(f"{side}_shoulder_y")] += _SWING["shoulder_y"] * s
            ctrl[:, DOF_NAMES.index(f"{side}_elbow_y")] += -_SWING["elbow_y"] * (1 + s) / 2
    return ctrl


def single_thread(body: Body, motion: str, steps: int) -> dict:
    model, data = body.model, mujoco.MjData(body.model)
    data.qpos[:] = standing_qpos(body)
    ctrl = targets(body, motion, steps)
    contacts = 0
    t0 = time.perf_counter()
    for k in range(steps):
        data.ctrl[:] = ctrl[k]
        mujoco.mj_step(model, data)
        contacts += data.ncon
    dt = time.perf_counter() - t0
    return {"motion": motion, "steps": steps, "seconds": dt, "steps_per_s": steps / dt,
            "mean_contacts": contacts / steps, "final_pelvis_z": float(data.qpos[2]),
            "finite": bool(np.isfinite(data.qpos).all())}


def batched(body: Body, motion: str, nbatch: int, nstep: int, threads: int) -> dict:
    model = body.model
    rng = np.random.default_rng(0)
    data = mujoco.MjData(model)
    data.qpos[:] = standing_qpos(body)
    size = mujoco.mj_stateSize(model, mujoco.mjtState.mjSTATE_FULLPHYSICS)
    state0 = np.empty(size)
    mujoco.mj_getState(model, data, state0, mujoco.mjtState.mjSTATE_FULLPHYSICS)
    states = np.tile(state0, (nbatch, 1))
    # Perturb the hinge velocities a little so the rollouts differ (qvel follows time + qpos).
    states[:, 1 + model.nq + 6:1 + model.nq + model.nv] += 0.2 * rng.standard_normal(
        (nbatch, NUM_DOF))
    ctrl = np.tile(targets(body, motion, nstep), (nbatch, 1, 1))
    ctrl += 0.05 * rng.standard_normal(ctrl.shape)
    datas = [mujoco.MjData(model) for _ in range(threads)]
    rollout.rollout(model, datas, states[:2], ctrl[:2])  # warm the thread pool
    t0 = time.perf_counter()
    state, _ = rollout.rollout(model, datas, states, ctrl)
    dt = time.perf_counter() - t0
    return {"motion": motion, "threads": threads, "rollouts": nbatch, "steps_each": nstep,
            "seconds": dt, "steps_per_s": nbatch * nstep / dt,
            "one_second_rollouts_per_s": nbatch * nstep / dt * model.opt.timestep,
            "finite": bool(np.isfinite(state).all())}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("out/bench_body.json"))
    parser.add_argument("--height", type=float, default=1.75)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--steps", type=int, default=4000, help="single-thread steps per motion")
    parser.add_argument("--rollouts", type=int, default=64, help="batched rollouts per motion")
    args = parser.parse_args()

    t0 = time.perf_counter()
    body = build_body(BodyShape.from_height(args.height))
    build_s = time.perf_counter() - t0
    steps_1s = int(round(1.0 / body.model.opt.timestep))
    result = {
        "machine": {"description": machine_description(), "platform": platform.platform(),
                    "mujoco": mujoco.__version__},
        "body": {"height": args.height, "total_mass": body.total_mass, "dof": body.model.nu,
                 "nq": body.model.nq, "ngeom": body.model.ngeom,
                 "timestep": body.model.opt.timestep, "build_s": build_s},
        "single_thread": [single_thread(body, m, args.steps) for m in ("stand", "walk")],
        "batched": [batched(body, m, args.rollouts, steps_1s, args.threads)
                    for m in ("stand", "walk")],
    }
    for row in result["single_thread"]:
        print(f"single thread, {row['motion']:5s}: {row['steps_per_s']:8.0f} steps/s "
              f"({row['mean_contacts']:.1f} contacts/step, pelvis ends at "
              f"{row['final_pelvis_z']:.2f} m)")
    for row in result["batched"]:
        print(f"rollout x{row['threads']} threads, {row['motion']:5s}: "
              f"{row['steps_per_s']:8.0f} steps/s = {row['one_second_rollouts_per_s']:.0f} "
              f"one-second rollouts/s")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
