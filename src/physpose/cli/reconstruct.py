"""`physpose reconstruct`: video -> physically simulated 3d motion (reconstruction.npz)."""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

from physpose.dynamics import PRESETS
from physpose.pipeline import CONFIG_FILE, RECONSTRUCTION_FILE, PipelineConfig, reconstruct


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "reconstruct", help="video -> physically plausible 3d motion (all stages)",
        description="Observe the person in a video (or read a keypoints .json/.npz), fit the "
                    "kinematic estimate, build a body sized to the person and optimise the "
                    "motor targets of its simulation; writes reconstruction.npz and "
                    "config.json into --out. An interrupted run resumes where it stopped.")
    p.add_argument("video", type=Path, help="video file, or a keypoints .json/.npz")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--preset", choices=tuple(PRESETS), default="fast",
                   help="optimisation budget: fast (default) or paper (2000 x 100 samples per "
                        "1 s window: hours per second of video on a few cores)")
    p.add_argument("--height", type=float, help="the person's standing height, m")
    p.add_argument("--mass", type=float, help="the person's mass, kg")
    p.add_argument("--fps", type=float, help="analysis frame rate, Hz (default 25)")
    p.add_argument("--resume", action=argparse.BooleanOptionalAction, default=True,
                   help="reuse finished optimisation windows of an earlier run in --out "
                        "(default); --no-resume starts over")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    config = PipelineConfig.preset(args.preset)
    if args.fps is not None:
        config = dataclasses.replace(
            config, observe=dataclasses.replace(config.observe, target_fps=args.fps))
    start = time.perf_counter()
    recon = reconstruct(args.video, args.out, config, height=args.height, mass=args.mass,
                        resume=args.resume, progress=sys.stderr.isatty())
    seconds = time.perf_counter() - start
    losses = recon.meta.get("dynamics", {}).get("losses", {})
    print(f"{args.video.name}: {recon.num_frames} frames at {recon.fps:g} fps reconstructed in "
          f"{seconds:.1f} s (dynamics loss {losses.get('total', float('nan')):.3g})")
    print(f"  wrote {args.out / RECONSTRUCTION_FILE}\n  wrote {args.out / CONFIG_FILE}")
    return 0
