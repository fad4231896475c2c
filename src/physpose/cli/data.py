"""`physpose data`: fetch the built-in demo input."""

from __future__ import annotations

import argparse

from physpose.demo_data import ensure_pose2sim_demo


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("data", help="fetch the built-in demo clip (pose2sim, 4 calibrated views)",
                       description="Download the pose2sim wheel (no dependencies) and extract its "
                                   "single-person demo videos and calibration into data/.")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    print(ensure_pose2sim_demo())
    return 0
