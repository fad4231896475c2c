"""`physpose fit`: video or observations -> the kinematic estimate (reconstruction.npz, no
physics), its config and an overlay video of the fitted body."""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

from physpose import __version__
from physpose.cli.body import check_person
from physpose.cli.camera_file import given_intrinsics
from physpose.cli.observe import add_video_options, config_from_args, refuse_video_options
from physpose.diagnostics import camera_pose_message, rate_message
from physpose.keypoints_io import is_keypoints_file
from physpose.kinematics.config import VARIANT_NAMES, KinematicConfig
from physpose.kinematics.fit import fit_kinematics, stderr_log
from physpose.metrics import camera_height, camera_tilt
from physpose.observations import check_slow_motion
from physpose.observe import footage_observe
from physpose.paths import check_output_folder

RECONSTRUCTION_FILE = "reconstruction.npz"
CONFIG_FILE = "config.json"
OVERLAY_FILE = "overlay.mp4"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "fit", help="fit the kinematic 3d estimate (shape, camera, ground, per-frame pose)",
        description="Fit the body's shape, the camera, the ground plane and the per-frame pose "
                    "to a video (observed with MediaPipe first) or to observations / keypoints "
                    f"(.npz, .json). Writes {RECONSTRUCTION_FILE} (kinematic fields only), "
                    f"{CONFIG_FILE} and {OVERLAY_FILE} into --out.")
    p.add_argument("input", type=Path, metavar="VIDEO_OR_OBSERVATIONS",
                   help="video file, observations.npz or a keypoints .json/.npz")
    p.add_argument("--out", type=Path, required=True, metavar="DIR", help="output folder")
    p.add_argument("--variant", choices=VARIANT_NAMES, default="SO+GT",
                   help="kinematic variant (paper's Table 1; default SO+GT)")
    p.add_argument("--height", type=float, help="the person's standing height, m")
    p.add_argument("--mass", type=float, help="the person's mass, kg")
    add_video_options(p)
    p.add_argument("--slow-motion", type=float, default=1.0, metavar="X",
                   help="the footage plays X times slower than real time (e.g. 4 for 120 fps "
                        "played at 30): the fit runs on the real clock and --fps is the "
                        "analysis rate in real time (default 1)")
    p.add_argument("--camera", type=Path, metavar="CALIB",
                   help="camera calibration: a Qualisys .qca.txt, a JSON file with K = "
                        "[[fx,0,cx],[0,fy,cy],[0,0,1]] or a text file of the 9 numbers "
                        "(default: the focal length that a camera turning by 5 degrees or more "
                        "reveals, else a 55-degree field of view across the image's diagonal)")
    p.add_argument("--camera-name", metavar="NAME",
                   help="which camera of a .qca.txt (default: the only one whose image size "
                        "matches the video, else the one named in the input's file name)")
    p.add_argument("--no-overlay", action="store_true", help="skip the overlay video")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from physpose.kinematics.variants import reconstruction_of
    from physpose.pipeline import load_observations

    start = time.perf_counter()
    observe_cfg = config_from_args(args)
    if is_keypoints_file(args.input):
        refuse_video_options(observe_cfg, args.input)
    check_slow_motion(args.slow_motion)
    check_person(args.height, args.mass)
    check_output_folder(args.out)
    K = given_intrinsics(args.camera, args.camera_name, args.input)  # before the work
    obs = load_observations(args.input, footage_observe(observe_cfg, args.slow_motion),
                            progress=sys.stderr.isatty()).on_real_clock(args.slow_motion)
    rate = rate_message(obs.fps)
    if rate:
        print(f"warning: {rate}", file=sys.stderr, flush=True)
    config = KinematicConfig.preset(args.variant, use_cache=not args.no_cache)
    fit = fit_kinematics(obs, config, height=args.height, mass=args.mass, camera_K=K,
                         log=stderr_log, progress=sys.stderr.isatty())
    height_found, tilt_found = camera_height(fit.T_world2cam), camera_tilt(fit.T_world2cam)
    doubt = camera_pose_message(height_found, tilt_found)
    if doubt:
        print(f"warning: {doubt}", file=sys.stderr, flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    recon = reconstruction_of(fit, obs)
    recon = recon.replace(meta={**recon.meta, "slow_motion": args.slow_motion,
                                "diagnostics": {"camera_height": height_found,
                                                "camera_tilt": tilt_found,
                                                "label_exchanges": fit.label_exchanges}})
    recon.save(args.out / RECONSTRUCTION_FILE)
    resolved = {"stage": "kinematics", "physpose_version": __version__,
                "input": str(args.input.resolve()), "variant": args.variant,
                "height": args.height, "mass": args.mass, "slow_motion": args.slow_motion,
                "camera": None if args.camera is None else str(args.camera.resolve()),
                "camera_name": args.camera_name,
                "observe": dataclasses.asdict(observe_cfg),
                "kinematics": dataclasses.asdict(config),
                "camera_K": fit.camera_K.tolist(), "losses": fit.losses,
                "timings_s": fit.timings, "shape": dataclasses.asdict(fit.shape)}
    (args.out / CONFIG_FILE).write_text(json.dumps(resolved, indent=2) + "\n")
    written = [args.out / RECONSTRUCTION_FILE, args.out / CONFIG_FILE]
    if not args.no_overlay:
        from physpose.render.overlay import render_overlay

        written.append(render_overlay(args.out, args.out / OVERLAY_FILE,
                                      progress=sys.stderr.isatty()).path)
    print(f"fit: {Path(obs.source).name}: {fit.num_frames} frames, variant {fit.variant}, "
          f"height {fit.shape.height:.2f} m, {time.perf_counter() - start:.1f} s")
    for path in written:
        print(f"  wrote {path}")
    return 0
