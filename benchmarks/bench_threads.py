"""How the dynamics stage scales with rollout threads, and that the thread count leaves the result
unchanged.

    uv run python benchmarks/bench_threads.py [--seconds 4] [--threads 1,2]

The fast preset runs on a simulated motion (physpose.dynamics.synthetic, a weight shift and a
step; no evaluation material needed) once per thread count. Each run's wall time is reported
with its ratio to the first count's, and its simulated joints are compared bit for bit with the
first run's: `DynamicsConfig.nthread` promises not to change results. Default thread counts: 1,
2 and every power of two up to this machine's cores.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import time

import numpy as np

from physpose.benchmark.runner import machine_description
from physpose.body import build_body
from physpose.dynamics import PRESETS, optimize_dynamics
from physpose.dynamics.synthetic import simulated_clip
from physpose.shape import BodyShape


def default_counts(cores: int) -> list[int]:
    """1, 2, 4, ... up to ``cores``, and ``cores`` itself."""
    counts = [1]
    while counts[-1] * 2 <= cores:
        counts.append(counts[-1] * 2)
    if counts[-1] != cores:
        counts.append(cores)
    return counts


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=4.0, help="clip length (s)")
    ap.add_argument("--motion", default="step", help="simulated motion (stand, shift, step)")
    ap.add_argument("--threads", help="comma-separated thread counts (default: 1, 2, 4, ... "
                                      "up to the cores)")
    ap.add_argument("--json", help="also write the figures to this file")
    args = ap.parse_args()
    cores = os.cpu_count() or 1
    counts = ([int(c) for c in args.threads.split(",")] if args.threads
              else default_counts(cores))

    body = build_body(BodyShape.from_height(1.75))
    fit, obs, _ = simulated_clip(body, args.motion, seconds=args.seconds)
    video_s = (fit.num_frames - 1) / fit.fps
    out = {"machine": machine_description(),
           "clip": f"simulated {args.motion}, {video_s:.2f} s at {fit.fps:g} fps", "runs": []}
    print(f"{out['clip']}; {out['machine']}; fast preset")
    first = None
    for n in counts:
        cfg = dataclasses.replace(PRESETS["fast"], nthread=n)
        start = time.perf_counter()
        res = optimize_dynamics(body, fit, obs, cfg, checkpoints=False, progress=False)
        wall = time.perf_counter() - start
        if first is None:
            first = (wall, res.joints)
        same = bool(np.array_equal(res.joints, first[1]))
        run = {"threads": n, "wall_s": wall, "wall_s_per_video_s": wall / video_s,
               "speedup": first[0] / wall, "identical_to_first": same,
               "timings_s": res.timings}
        out["runs"].append(run)
        print(f"{n:3d} threads: {wall:7.1f} s ({run['wall_s_per_video_s']:.1f} s per second of "
              f"video), {run['speedup']:.2f}x the {counts[0]}-thread speed; joints "
              f"{'identical to' if same else 'DIFFER from'} the first run's")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=2)


if __name__ == "__main__":
    main()
