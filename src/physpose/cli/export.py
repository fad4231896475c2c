"""`physpose export`, `physpose report` and `physpose overlay`: outputs of a result folder."""

from __future__ import annotations

import argparse
from pathlib import Path

from physpose.errors import about
from physpose.export import DEFAULT_NAMES, FORMATS, export
from physpose.paths import check_output_file
from physpose.reconstruction import Reconstruction
from physpose.render.result import MOTIONS

_RESULT_HELP = "result folder written by `physpose reconstruct` (holds reconstruction.npz)"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "export", help="export a result as BVH, glTF (.glb), CSV or JSON, or its forces as CSV",
        description="Export the motion of a result folder. bvh: a skeleton with the subject's "
                    "segment lengths (Y up, metres; loads in Blender). glb: the capsule body "
                    "animated over a ground plane (any glTF viewer). csv/json: world joint "
                    "positions (z up, metres) per frame, for every motion the result holds. "
                    "forces: the simulation's ground reaction forces on each foot and on the "
                    "rest of the body (N), the centre of pressure under each foot (m) and the "
                    "torque across every joint (N m), one row per frame (physics motion only).")
    p.add_argument("result", type=Path, metavar="RESULT_DIR", help=_RESULT_HELP)
    p.add_argument("--format", "-f", required=True, choices=FORMATS, dest="fmt",
                   help="file format")
    # A string, not a Path: a trailing "/" (a folder to make) must survive.
    p.add_argument("--out", "-o", default=None,
                   help="output file with the format's suffix, or a folder (made if the name "
                        "ends in /) to write the default name into (default: "
                        "RESULT_DIR/" + ", ".join(
                            f"{n} for {f}" for f, n in DEFAULT_NAMES.items()) + ")")
    p.add_argument("--motion", choices=MOTIONS, default=None,
                   help="which motion (default: physics if present, else kinematic; csv/json "
                        "default to all motions)")
    p.set_defaults(func=_run_export)

    p = sub.add_parser(
        "report", help="write the interactive HTML report of a result",
        description="Write one self-contained HTML file (opens offline): a 3d viewer of the "
                    "motion (play, pause, scrub, orbit, kinematic/physics toggle, foot "
                    "contacts), the metric table, and plots over time.")
    p.add_argument("result", type=Path, metavar="RESULT_DIR", help=_RESULT_HELP)
    p.add_argument("--out", "-o", type=Path, default=None,
                   help="output file (default: RESULT_DIR/report.html)")
    p.set_defaults(func=_run_report)

    p = sub.add_parser(
        "overlay", help="write the overlay video of a result",
        description="Write an mp4 at the analysis frame rate: the input frames with the "
                    "kinematic (orange) and physics (blue) body projected on them, beside a 3d "
                    "view of the body, ground grid and foot contacts from a second viewpoint.")
    p.add_argument("result", type=Path, metavar="RESULT_DIR", help=_RESULT_HELP)
    p.add_argument("--video", type=Path, default=None,
                   help="source video (default: the one recorded in the result; a plain "
                        "background when it is not found)")
    p.add_argument("--out", "-o", type=Path, default=None,
                   help="output file (default: RESULT_DIR/overlay.mp4)")
    p.add_argument("--png-frame", type=int, default=None, metavar="FRAME",
                   help="write only this frame (0-based) as a PNG instead: to --out, else "
                        "to RESULT_DIR/overlay_FRAME.png")
    p.set_defaults(func=_run_overlay)


def _run_export(args: argparse.Namespace) -> int:
    with about(Reconstruction.file_in(args.result)):
        print(export(args.result, args.fmt, args.out, motion=args.motion))
    return 0


def _run_report(args: argparse.Namespace) -> int:
    from physpose.report import build_report

    if args.out is not None:
        check_output_file(args.out, ".html")
    with about(Reconstruction.file_in(args.result)):
        print(build_report(args.result, args.out))
    return 0


def _run_overlay(args: argparse.Namespace) -> int:
    from physpose.render.overlay import render_overlay, save_overlay_png

    if args.out is not None:
        check_output_file(args.out, ".png" if args.png_frame is not None else ".mp4")
    with about(Reconstruction.file_in(args.result)):
        if args.png_frame is not None:
            out = args.out if args.out is not None else \
                args.result / f"overlay_{args.png_frame}.png"
            print(save_overlay_png(args.result, args.png_frame, out, video=args.video))
            return 0
        made = render_overlay(args.result, args.out, video=args.video, progress=True)
    print(f"{made.path} (drawn on {made.background})")
    return 0
