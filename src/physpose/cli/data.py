"""`physpose data`: fetch the built-in demo input."""

from __future__ import annotations

import argparse

from physpose.demo_data import ensure_pose2sim_demo, ensure_sports2d_demo


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("data", help="fetch the built-in demo clip (pose2sim, 4 calibrated views) "
                                    "and a two-person test video (sports2d)",
                       description="Download the pose2sim and sports2d wheels (no dependencies) "
                                   "and extract pose2sim's single-person demo videos and "
                                   "calibration and sports2d's demo video into data/.")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    print(ensure_pose2sim_demo())
    print(ensure_sports2d_demo())
    return 0
