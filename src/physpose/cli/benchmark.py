"""`physpose benchmark`: score pipeline variants on motion capture, multi-view and real videos."""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

from physpose.benchmark import (BenchmarkConfig, Material, MaterialConfig, available_variants,
                                run_benchmark, shared_material, write_results)
from physpose.benchmark.material import MULTIVIEW_TRUTHS
from physpose.multiview.reference import find_multiview_files
from physpose.benchmark.report import render_markdown
from physpose.errors import PhysposeError
from physpose.paths import check_output_folder


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "benchmark", help="score pipeline variants (paper's Table 2 metrics)",
        description="Run pipeline variants on motion-capture clips (through the detector "
                    "simulator), calibrated multi-view folders (each view scored against the "
                    "triangulated reference) and real videos; write results.json and "
                    "results.md. Without clip arguments the shared material is used.")
    p.add_argument("--mocap", action="append", default=[], metavar="FILE", type=Path,
                   help="BVH, AMC (with its .asf beside it) or DeepMimic clip; repeatable")
    p.add_argument("--multiview", action="append", default=[], metavar="DIR", type=Path,
                   help="folder with videos/ and calibration/*.qca.txt (pose2sim layout); "
                        "repeatable")
    p.add_argument("--video", action="append", default=[], metavar="FILE", type=Path,
                   help="real video without ground truth; repeatable")
    p.add_argument("--variant", action="append", default=[], metavar="NAME",
                   help="variant to run (repeatable; default: baseline). "
                        "`--variant list` prints the registered names")
    p.add_argument("--max-seconds", type=float, default=MaterialConfig.max_seconds, metavar="S",
                   help="clip length cap in seconds (default: %(default)s, the paper's "
                        "100 frames at 25 fps)")
    p.add_argument("--start", type=float, default=MaterialConfig.start_seconds, metavar="S",
                   help="begin every clip S seconds in (default: %(default)s). The defaults were "
                        "tuned on the clips' first 4 s: later segments are held-out material")
    p.add_argument("--camera-azimuth", type=float, default=MaterialConfig.camera_azimuth_deg,
                   metavar="DEG", help="motion capture's virtual camera, degrees from the "
                                       "subject's front towards its left (default: %(default)s)")
    p.add_argument("--camera-height", type=float, default=MaterialConfig.camera_height,
                   metavar="M", help="motion capture's virtual camera, metres above the floor; "
                                     "it looks at the subject's mean pelvis, so a higher camera "
                                     "looks down (default: %(default)s)")
    p.add_argument("--fps", type=float, default=MaterialConfig.fps,
                   help="analysis rate in Hz (videos use the nearest rate that is a whole "
                        "fraction of theirs; default: %(default)s)")
    p.add_argument("--known-extrinsics", action="store_true",
                   help="also give variants the camera pose (ground figures are then trivial)")
    p.add_argument("--known-height", action="store_true",
                   help="give variants the person's stature when the material has it (mocap)")
    p.add_argument("--seed", type=int, default=0,
                   help="seed of the detector simulator's noise and of the dynamics variants' "
                        "CMA-ES (added to their own; default 0)")
    p.add_argument("--noiseless", action="store_true",
                   help="simulate motion-capture detections without noise or biases: an oracle "
                        "input, so what a variant still loses is its own error")
    p.add_argument("--truth-input", action="store_true",
                   help="give variants the motion-capture truth: only the diagnostic variants "
                        "truth-ik, truth-reference and dynamics-truth read it (how well the body "
                        "and the physics follow a motion a person really made)")
    p.add_argument("--slow-motion", type=int, default=1, metavar="X",
                   help="play motion capture as X times slow footage, not declared: the "
                        "detector simulator sees each clip at X times --fps and the variants "
                        "take its frames at --fps; every X-th frame is scored on the real "
                        "clock. What a user who films slow motion and does not pass "
                        "--slow-motion gets (motion capture only; default: 1)")
    p.add_argument("--multiview-truth", choices=MULTIVIEW_TRUTHS,
                   default=MaterialConfig.multiview_truth,
                   help="what each view of a multi-view folder is scored against: the reference "
                        "triangulated from every view (its own detections pull it towards "
                        "themselves) or from the other views alone (noisier; default: "
                        "%(default)s)")
    p.add_argument("--paired-against", metavar="NAME",
                   help="with two or more variants, the one the others are compared with clip "
                        "by clip (mean +- standard error of the per-clip differences; default: "
                        "the first --variant). `physpose compare` does the same across runs")
    p.add_argument("--out", type=Path, help="output folder for results.json and results.md "
                                           "(required, but for --variant list); both are "
                                           "rewritten after each file or folder of material "
                                           "(an earlier run's there are replaced), so a run "
                                           "stopped midway keeps what it finished")
    p.set_defaults(func=run)


def _materials(args: argparse.Namespace) -> tuple[list[Material], list[str]]:
    given = ([Material("mocap", p) for p in args.mocap]
             + [Material("multiview", p) for p in args.multiview]
             + [Material("video", p) for p in args.video])
    for m in given:
        if not m.path.exists():
            raise PhysposeError(f"{m.kind} input not found", path=m.path, remedy="check the path")
        if m.kind == "multiview":
            find_multiview_files(m.path)  # layout errors before any long work
        elif not m.path.is_file():
            raise PhysposeError(f"{m.kind} input is not a file", path=m.path,
                                remedy="pass a file; a pose2sim folder goes with --multiview")
    if given:
        return given, []
    found, skipped = shared_material()
    if args.slow_motion != 1:  # only motion capture can be slowed
        skipped += [f"{m.kind} {m.path}: --slow-motion plays motion capture only"
                    for m in found if m.kind != "mocap"]
        found = [m for m in found if m.kind == "mocap"]
    return found, skipped


def run(args: argparse.Namespace) -> int:
    variants = args.variant or ["baseline"]
    if "list" in variants:
        print("\n".join(available_variants()))
        return 0
    if args.out is None:
        raise PhysposeError("no output folder", remedy="pass --out DIR")
    check_output_folder(args.out)  # not after hours of work
    known = available_variants()
    unknown = [v for v in variants if v not in known]
    if unknown:
        raise PhysposeError(f"unknown variant(s) {', '.join(unknown)}",
                            remedy=f"choose from: {', '.join(known)}")
    # The configuration first: its checks (the paired base among the variants, the clip
    # settings) fail before the material is prepared.
    cfg = BenchmarkConfig(variants=tuple(dict.fromkeys(variants)),
                          paired_against=args.paired_against,
                          material=MaterialConfig(fps=args.fps, max_seconds=args.max_seconds,
                                                  start_seconds=args.start,
                                                  camera_azimuth_deg=args.camera_azimuth,
                                                  camera_height=args.camera_height,
                                                  known_extrinsics=args.known_extrinsics,
                                                  known_height=args.known_height,
                                                  seed=args.seed, noiseless=args.noiseless,
                                                  truth_input=args.truth_input,
                                                  slow_motion=args.slow_motion,
                                                  multiview_truth=args.multiview_truth))
    materials, skipped = _materials(args)
    for message in skipped:
        print(f"benchmark: skipping: {message}", file=sys.stderr)
    if not materials:
        raise PhysposeError("no benchmark material found",
                            remedy="pass --mocap/--multiview/--video or fetch the shared data")
    command = shlex.join(["physpose", *sys.argv[1:]]) if sys.argv[1:2] == ["benchmark"] \
        else "physpose benchmark"
    doc = run_benchmark(materials, cfg, skipped=skipped, command=command,
                        on_progress=lambda partial: write_results(partial, args.out))
    json_path, md_path = write_results(doc, args.out)
    print(render_markdown(doc))
    print(f"wrote {json_path}\nwrote {md_path}")
    if doc["failures"] and not doc["results"]:
        return 1
    return 0
