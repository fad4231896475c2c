"""`physpose demo`: run every stage that exists on the built-in pose2sim clip."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from physpose.cli.observe import OVERLAY_FILE, run_observe
from physpose.demo_data import ensure_pose2sim_demo
from physpose.observe import ObserveConfig

DEMO_VIEW = "videos/cam01.mp4"  # the view the demo reconstructs (of the four calibrated ones)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="run the pipeline on the built-in demo clip",
                       description="Fetch the pose2sim demo clip if needed and run the pipeline "
                                   "stages on one view, writing everything into --out.")
    p.add_argument("--out", type=Path, default=Path("out/demo"), metavar="DIR",
                   help="output folder (default: out/demo)")
    p.add_argument("--no-cache", action="store_true", help="recompute every stage")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    start = time.perf_counter()
    video = ensure_pose2sim_demo() / DEMO_VIEW
    print(f"demo input: {video}")
    observed = run_observe(video, args.out, ObserveConfig(use_cache=not args.no_cache))
    print("observe: " + observed.summary(), end="")
    print(f"demo finished in {time.perf_counter() - start:.1f} s; results in {args.out.resolve()}")
    print(f"  check the detections by eye: {args.out.resolve() / OVERLAY_FILE}")
    return 0
