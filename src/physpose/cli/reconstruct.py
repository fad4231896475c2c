"""`physpose reconstruct`: video -> physically simulated 3d motion, metrics, report, overlay, exports."""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from physpose import diagnostics
from physpose.dynamics import PRESETS
from physpose.dynamics.config import available_cores
from physpose.dynamics.objective import TERMS, ObjectiveWeights
from physpose.dynamics.travel import CAMERA_SETTINGS
from physpose.cli.body import check_person, scene_from_args
from physpose.cli.camera_file import given_intrinsics
from physpose.cli.observe import (PERSON_HELP, STATIC_CAMERA_HELP, image_point,
                                  refuse_video_options)
from physpose.errors import PhysposeError
from physpose.export import FORMATS
from physpose.keypoints_io import is_keypoints_file
from physpose.observations import Observations
from physpose.outputs import DEFAULT_FORMATS, METRICS_FILE, metrics_table, write_outputs
from physpose.paths import check_output_folder
from physpose.pipeline import CONFIG_FILE, RECONSTRUCTION_FILE, PipelineConfig
from physpose.reconstruction import Reconstruction
from physpose.report.data import forces_summary, slow_motion_note, video_span

_OUTPUT_NAMES = {"metrics": "metrics", "report": "report (open in a browser)",
                 "overlay": "overlay video", "overlay_png": "overlay frame",
                 "bvh": "BVH (Blender)", "glb": "glTF binary", "csv": "joint table (CSV)",
                 "json": "joint table (JSON)", "forces": "forces and torques (CSV)"}


# Wall time of the physics per second of video on a 2-core machine, one run at a time: the
# fastest and slowest clip of the shared material on the machines of stops 88-94 (fast), and
# the paper preset's budget. A clip at least LONG_CLIP_S long is told beforehand.
PHYSICS_S_PER_S = {"fast": (10.0, 36.0), "paper": (43 * 60.0, 43 * 60.0)}
LONG_CLIP_S = 30.0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "reconstruct", help="video -> physically plausible 3d motion, report, overlay, exports",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Observe the person in a video (or read a keypoints .json/.npz), fit the\n"
                    "kinematic estimate, build a body sized to the person and optimise the motor\n"
                    "targets of its simulation. Writes into --out: reconstruction.npz,\n"
                    "config.json, metrics.json, report.html, overlay.mp4 + overlay.png and the\n"
                    "exports (motion.bvh, motion.glb, joints.csv, and forces.csv: the simulated\n"
                    "ground reaction forces and joint torques); prints the metrics, the files\n"
                    "and the time per stage. An interrupted run resumes where it stopped.",
        epilog="examples:\n"
               "  physpose reconstruct walk.mp4 --out out/walk --height 1.75\n"
               "  physpose reconstruct jump.mp4 --out out/jump --start 2 --end 5 --trampoline\n"
               "  physpose reconstruct sit.mp4 --out out/sit "
               "--obstacle box:-0.35,0,0.225,0.45,0.45,0.45\n"
               "  physpose reconstruct cam01.mp4 --out out/c1 --camera Calib.qca.txt "
               "--camera-name cam01")
    p.add_argument("video", type=Path, help="video file, or a keypoints .json/.npz")
    p.add_argument("--out", type=Path, required=True, metavar="DIR", help="output folder")
    p.add_argument("--preset", choices=tuple(PRESETS), default="fast",
                   help="optimisation budget: fast (default; {:.0f}-{:.0f} s of dynamics per "
                        "second of video per clip of the shared material, measured one run at a "
                        "time on 2-core machines) or paper (2000 x 100 samples per 1 s window: "
                        "about 19 min per window, {:.0f} min per second of video, on such a "
                        "machine)".format(*PHYSICS_S_PER_S["fast"],
                                          PHYSICS_S_PER_S["paper"][0] / 60))
    p.add_argument("--candidates", type=int, metavar="N",
                   help="optimise the whole clip N times (seeds 0..N-1) and keep the run with "
                        "the lowest loss: N times the time (default 1)")
    p.add_argument("--search-iterations", type=int, metavar="N",
                   help="CMA-ES iterations per window (default: the preset's, 30 in fast). 0 "
                        "skips the search: each window keeps the better of its two start "
                        "guesses and the iLQR refinement works from it, a quick preview at "
                        "about 0.4x the fast preset's time, as near the truth on motion "
                        "capture but with more restarts, a higher velocity error and, on a "
                        "travelling camera, feet that slide more (docs/dynamics.md, No search)")
    p.add_argument("--searches", type=int, metavar="N",
                   help="CMA-ES searches per window side by side (other seeds, the same "
                        "start); their average is kept, which cancels most of each search's "
                        "random walk: N times the search time (default: the preset's). Two "
                        "searches came about 1 mm nearer the truth in MPJPE-PA on motion "
                        "capture, while a travelling camera's feet slid more "
                        "(docs/dynamics.md, Search)")
    p.add_argument("--refine", type=int, metavar="N",
                   help="iLQR iterations refining each window's servo targets towards the "
                        "estimate and the detections after the search (0: off; default: the "
                        "preset's, 6 in fast, "
                        "0 in paper). On a simulated clip they took 4.8 s of the fast preset's "
                        "13.7 s per second of video (docs/dynamics.md, Measured, Speed at the "
                        "head)")
    p.add_argument("--threads", type=int, metavar="N",
                   help="threads for the simulated rollouts (default: every core this process "
                        f"may use, {available_cores()} here); the result is the same for any N, "
                        "only the time changes (on 16 cores, 2.4x the speed of 2 threads: "
                        "benchmarks/bench_threads.py)")
    p.add_argument("--balance-hz", type=float, metavar="HZ",
                   help="closed-loop balance feedback (centre of mass through the standing "
                        "ankles) in every simulated sample, Hz, e.g. 0.5; 0 (the default) is "
                        "off. Measured to help on standing and slow motions, to make walking "
                        "feet slide (docs/dynamics.md)")
    p.add_argument("--place-stretches", action=argparse.BooleanOptionalAction, default=None,
                   help="move each continuous simulated stretch (between restarts) "
                        "horizontally to where the estimate is on average (default on; on a "
                        "floor without obstacles this is the same simulation, moved); "
                        "--no-place-stretches keeps every stretch where the estimate put its "
                        "first frame")
    p.add_argument("--restart-distance", type=float, metavar="M",
                   help="restart the simulation from the estimate where the simulated centre "
                        "of mass strays further than M from the estimate's (default 0.15; "
                        "each restart is a jump in the output). 0.25 restarted half as often "
                        "on motion capture and made the feet slide less on real videos, at "
                        "2-4 px more image error and about 20 mm more MPJPE-G "
                        "(docs/dynamics_history.md, stop 55)")
    p.add_argument("--weight", action="append", default=[], metavar="TERM=W",
                   help="weight of one objective term, repeatable; terms: "
                        f"{', '.join(TERMS)}. The paper's weights are com=15 pose=0.5 "
                        "reprojection=4 prior=1 tv=1 lim=1 (no swing term); the fast preset sets "
                        "com=0 swing=12. E.g. "
                        "--weight pose=8: closer to the estimate's pose, feet slide more "
                        "(measured trade-off in docs/dynamics_history.md, stop 16)")
    g = p.add_argument_group("the person and the video")
    g.add_argument("--height", type=float, metavar="M", help="the person's standing height, m")
    g.add_argument("--mass", type=float, metavar="KG", help="the person's mass, kg")
    g.add_argument("--fps", type=float, help="analysis frame rate, Hz (default 25; in real "
                                             "time with --slow-motion)")
    g.add_argument("--slow-motion", type=float, metavar="X",
                   help="the footage plays X times slower than real time, e.g. 4 for 120 fps "
                        "footage played at 30 fps (below 1: sped up). The body is then "
                        "simulated on the real clock, under real gravity; the output's frame "
                        "rate, speeds and forces are real-time. --start/--end stay seconds "
                        "into the footage (default 1)")
    g.add_argument("--start", type=float, metavar="S", help="first second analysed (default 0)")
    g.add_argument("--end", type=float, metavar="S",
                   help="analysis stops before this second (default: end of the video)")
    g.add_argument("--person", type=image_point, metavar="X,Y", help=PERSON_HELP)
    g.add_argument("--static-camera", action="store_true", help=STATIC_CAMERA_HELP)
    g.add_argument("--camera-travel", choices=CAMERA_SETTINGS, default=None,
                   help="travelling: the camera moved along with the person (a tracking "
                        "shot): the physics follows the person's own path, the camera's "
                        "travel read off the estimate's standing feet; auto: so where the "
                        "camera is found moving; still (default): the camera stood still "
                        "(docs/dynamics.md, A travelling camera)")
    g.add_argument("--camera", type=Path, metavar="FILE",
                   help="camera calibration: a Qualisys .qca.txt, or a JSON file "
                        '{"K": [[fx,0,cx],[0,fy,cy],[0,0,1]]} (default: the focal length that '
                        "a camera turning by 5 degrees or more reveals, else a 55-degree field "
                        "of view across the image's diagonal; give the real one for a cropped or "
                        "zoomed video)")
    g.add_argument("--camera-name", metavar="NAME",
                   help="which camera of a .qca.txt (default: the only one whose image size "
                        "matches the video, else the one named in the video's file name)")
    g = p.add_argument_group("the scene (ground contact and obstacles)")
    g.add_argument("--ground-friction", type=float, metavar="MU",
                   help="sliding friction of the ground (default 0.9)")
    g.add_argument("--ground-stiffness", type=float, metavar="K",
                   help="ground stiffness, MuJoCo direct solref units (1/s^2 per unit mass; "
                        "default 10000, the hardest floor stable at the body's 5 ms step; "
                        "2500, the softer floor of earlier versions)")
    g.add_argument("--ground-damping", type=float, metavar="D",
                   help="ground damping, 1/s (default: critical for the stiffness)")
    g.add_argument("--auto-support", action=argparse.BooleanOptionalAction, default=True,
                   help="where the person's feet stay above the floor for longer than a jump, "
                        "put a box under them, and where the person sits, a seat (default on; "
                        "--no-auto-support: none, and the simulated body falls there)")
    g.add_argument("--trampoline", action="store_true",
                   help="a soft, springy floor (stiffness 150, damping 1.5; not with "
                        "--ground-stiffness/--ground-damping)")
    g.add_argument("--obstacle", action="append", default=[], metavar="box:x,y,z,sx,sy,sz[,yaw]",
                   help="a box in the world (centre and full sizes in m, yaw in degrees; "
                        "repeatable), e.g. a chair seat box:-0.35,0,0.225,0.45,0.45,0.45")
    g = p.add_argument_group("outputs")
    g.add_argument("--resume", action=argparse.BooleanOptionalAction, default=True,
                   help="reuse finished optimisation windows of an earlier run in --out "
                        "(default); --no-resume optimises every window again (observe and "
                        "the kinematic fit still come from the cache: --no-cache)")
    g.add_argument("--no-cache", action="store_true",
                   help="recompute every stage: observe and the kinematic fit too, not read "
                        "from the stage cache, and every window (implies --no-resume)")
    g.add_argument("--no-report", action="store_true", help="skip report.html")
    g.add_argument("--no-overlay", action="store_true", help="skip overlay.mp4 and overlay.png")
    g.add_argument("--export", default=",".join(DEFAULT_FORMATS), metavar="FORMATS",
                   help=f"comma-separated export formats out of {', '.join(FORMATS)} "
                        f"(default {','.join(DEFAULT_FORMATS)}; 'none' for no exports)")
    p.set_defaults(func=run)


def parse_formats(text: str) -> tuple[str, ...]:
    """'bvh,glb' -> ('bvh', 'glb'); 'none' or '' -> ()."""
    names = tuple(f.strip().lower() for f in text.split(",") if f.strip())
    if names in ((), ("none",)):
        return ()
    unknown = [f for f in names if f not in FORMATS]
    if unknown:
        raise PhysposeError(f"unknown export format(s) {', '.join(map(repr, unknown))}",
                            remedy=f"give --export as a comma-separated list of "
                                   f"{', '.join(FORMATS)} (or none)")
    return names


def parse_weights(texts: list[str], weights: ObjectiveWeights) -> ObjectiveWeights:
    """``weights`` with the terms named in ``texts`` ("TERM=W", e.g. "com=15") replaced."""
    for text in texts:
        term, sep, value = text.partition("=")
        term = term.strip().lower()
        if not sep and term in TERMS:
            raise PhysposeError(f"--weight {text!r} has no value",
                                remedy=f"write TERM=W, e.g. --weight {term}=1")
        if term not in TERMS:
            raise PhysposeError(f"--weight {text!r} names no objective term",
                                remedy=f"write TERM=W with TERM one of {', '.join(TERMS)}, "
                                       "e.g. --weight com=15")
        try:  # not a number, or one ObjectiveWeights rejects (negative, not finite)
            weights = dataclasses.replace(weights, **{term: float(value)})
        except (ValueError, PhysposeError):
            raise PhysposeError(f"--weight {text!r}: the weight must be a number >= 0",
                                remedy=f"e.g. --weight {term}=1 (0 removes the term)") from None
    return weights


def _check_option(ok: bool, option: str, value: float, need: str, remedy: str) -> None:
    """Refuse a flag's value, naming the flag, unless ok."""
    if not ok:
        raise PhysposeError(f"{option} {value} must be {need}", remedy=remedy)


def pipeline_config(args: argparse.Namespace) -> PipelineConfig:
    """The composed config of the flags (validated, before any heavy work)."""
    config = PipelineConfig.preset(args.preset)
    observe = config.observe
    if args.fps is not None:
        observe = dataclasses.replace(observe, target_fps=args.fps)
    observe = dataclasses.replace(observe, start=args.start, end=args.end, person=args.person,
                                  stabilize=not args.static_camera)
    dynamics = config.dynamics
    if args.candidates is not None:
        _check_option(args.candidates >= 1, "--candidates", args.candidates, ">= 1",
                      "pass how many whole-clip runs to keep the best of, e.g. --candidates 3 "
                      "(the default is 1)")
        dynamics = dataclasses.replace(dynamics, candidates=args.candidates)
    if args.search_iterations is not None:
        _check_option(args.search_iterations >= 0, "--search-iterations",
                      args.search_iterations, ">= 0",
                      "pass a number of CMA-ES iterations per window, e.g. --search-iterations "
                      "30, or 0 to skip the search")
        dynamics = dataclasses.replace(dynamics, iterations=args.search_iterations)
    if args.searches is not None:
        _check_option(args.searches >= 1, "--searches", args.searches, ">= 1",
                      "pass how many CMA-ES searches to average per window, e.g. --searches 2, "
                      "or leave it out for the preset's")
        dynamics = dataclasses.replace(dynamics, searches=args.searches)
    if dynamics.iterations == 0:
        # Only CMA-ES draws from the seed: without its iterations every candidate and every
        # side-by-side search would be the same run.
        for option, value in (("--candidates", dynamics.candidates),
                              ("--searches", dynamics.searches)):
            _check_option(value == 1, option, value, "1 with --search-iterations 0",
                          f"leave {option} out: without the search every run draws the same")
    if args.threads is not None:
        _check_option(args.threads >= 1, "--threads", args.threads, ">= 1",
                      "pass a number of threads, e.g. --threads 2, or leave it out to use "
                      f"every core ({available_cores()} here)")
        dynamics = dataclasses.replace(dynamics, nthread=args.threads)
    if args.weight:
        dynamics = dataclasses.replace(dynamics, weights=parse_weights(args.weight,
                                                                       dynamics.weights))
    if args.place_stretches is not None:
        dynamics = dataclasses.replace(dynamics, place_stretches=args.place_stretches)
    if args.camera_travel is not None:
        dynamics = dataclasses.replace(dynamics, camera=args.camera_travel)
    if args.refine is not None:
        _check_option(args.refine >= 0, "--refine", args.refine, ">= 0",
                      "pass a number of iLQR iterations, e.g. --refine 6, or --refine 0 to "
                      "switch the refinement off")
        dynamics = dataclasses.replace(dynamics, refine=dataclasses.replace(
            dynamics.refine, iterations=args.refine))
    if args.restart_distance is not None:
        _check_option(math.isfinite(args.restart_distance) and args.restart_distance > 0,
                      "--restart-distance", args.restart_distance, "a finite number > 0",
                      "pass metres, e.g. --restart-distance 0.25 (the default is 0.15)")
        dynamics = dataclasses.replace(dynamics, reset_distance=args.restart_distance)
    if args.balance_hz is not None:
        _check_option(math.isfinite(args.balance_hz) and args.balance_hz >= 0, "--balance-hz",
                      args.balance_hz, "a finite number >= 0",
                      "pass a frequency in Hz, e.g. --balance-hz 0.5, or 0 (the default) for "
                      "no balance feedback")
        dynamics = dataclasses.replace(dynamics, balance=dataclasses.replace(
            dynamics.balance, frequency=args.balance_hz))
    config = dataclasses.replace(config, observe=observe, dynamics=dynamics,
                                 scene=scene_from_args(args), auto_support=args.auto_support,
                                 slow_motion=1.0 if args.slow_motion is None else
                                 args.slow_motion)
    return config.without_cache() if args.no_cache else config


def check_input(video: Path, config: PipelineConfig
                ) -> tuple[tuple[int, int] | None, float | None]:
    """Fail fast on a missing/unreadable video or keypoints file, or a time range outside the
    video; returns the video's (width, height) and the seconds of it to analyse, on the
    footage's clock (None, None for a keypoints file)."""
    from physpose import video as videolib  # noqa: PLC0415

    if is_keypoints_file(video):
        if not video.is_file():
            raise PhysposeError("keypoints file not found", path=video, remedy="check the path")
        refuse_video_options(config.observe, video)
        return None, None
    info = videolib.probe(video)
    observe = config.footage_observe()
    plan = videolib.plan_frames(info, observe.target_fps, observe.start, observe.end)
    return info.image_size, len(plan.indices) / plan.fps


def duration_note(seconds: float, preset: str, candidates: int = 1, *,
                  keypoints: bool = False) -> str | None:
    """What a long clip (or any clip under the paper preset) will cost in physics time,
    before the work starts; seconds of video on the real clock. keypoints: the input is a
    keypoints file, which --start/--end do not cut."""
    if preset == "fast" and seconds < LONG_CLIP_S:
        return None
    rate_low, rate_high = PHYSICS_S_PER_S[preset]
    low, high = (candidates * rate * seconds / 60 for rate in (rate_low, rate_high))
    rates = (f"{rate_low / 60:.0f} min" if rate_low == rate_high
             else f"{rate_low:.0f}-{rate_high:.0f} s")
    times = f" (x {candidates} for --candidates {candidates})" if candidates > 1 else ""
    return (f"{seconds:.0f} s of video to reconstruct: the {preset} preset's physics took "
            f"{rates} per second of video on a 2-core machine{times}, so about "
            f"{_minutes(low, high)} there (less with more cores). An interrupted run resumes "
            "where it stopped; " + ("a keypoints file cut to a part reconstructs only that"
                                    if keypoints else "--start and --end reconstruct a part"))


def _tell_duration(footage_seconds: float, preset: str, config: PipelineConfig, *,
                   keypoints: bool) -> None:
    note = duration_note(footage_seconds / config.slow_motion, preset,
                         config.dynamics.candidates, keypoints=keypoints)
    if note:
        print(f"note: {note}", file=sys.stderr, flush=True)


def _minutes(low: float, high: float) -> str:
    """'30-87 min', '2.4 h', '50 min to 2.4 h' for a range of minutes."""
    def text(m: float) -> tuple[str, str]:
        return (f"{m:.0f}", "min") if m < 120 else (f"{m / 60:.1f}", "h")
    (a, unit_a), (b, unit_b) = text(low), text(high)
    if a == b and unit_a == unit_b:
        return f"{a} {unit_a}"
    return f"{a}-{b} {unit_b}" if unit_a == unit_b else f"{a} {unit_a} to {b} {unit_b}"


def restarts_line(recon: Reconstruction) -> str:
    """One line on where the physics motion restarts from the kinematic estimate (jumps)."""
    frames = recon.restarts
    if not frames:
        return "physics: one continuous simulation (no restarts)"
    where = ", ".join(f"{f} ({f / recon.fps:.2f} s)" for f in frames)
    times = "once" if len(frames) == 1 else f"{len(frames)} times"
    return (f"physics: restarted from the kinematic estimate {times}, where the simulated body "
            f"had strayed from it; the motion jumps at frame{'s' * (len(frames) > 1)} {where} "
            "(docs/dynamics.md, Retries)")


def undetected_line(recon: Reconstruction) -> str | None:
    """One line on the frames without a detection (too long a gap to interpolate), if any."""
    runs = recon.undetected_runs
    if not runs:
        return None
    count = int(recon.undetected.sum())
    where = ", ".join(f"{a}-{b} ({a / recon.fps:.2f}-{(b + 1) / recon.fps:.2f} s)" if b > a
                      else f"{a} ({a / recon.fps:.2f} s)" for a, b in runs)
    return (f"input: no person detected in {count} of {recon.num_frames} frames, at {where}; "
            "the motion there is inferred from the frames around them, not observed")


def diagnostics_lines(recon: Reconstruction) -> list[str]:
    """The warnings on the input that the pipeline found (physpose.diagnostics), if any."""
    return diagnostics.warning_lines(recon.meta.get("diagnostics", {}), recon.fps,
                                     recon.slow_motion)


def print_summary(recon: Reconstruction, out: Path, written: dict[str, Path],
                  metrics: dict | None, timings: dict[str, float]) -> None:
    """The end-of-run summary: metrics table, files and time per stage."""
    motions = "physics and kinematic motion" if recon.has_physics else "kinematic motion only"
    print(f"\n{recon.num_frames} frames at {recon.fps:g} fps ({recon.num_frames / recon.fps:.2f}"
          f" s), {motions}")
    span = video_span(recon)
    if span:
        print(f"they are {span} into the video; the times below count from the first of them "
              "unless they say 'into the video'")
    if recon.slow_motion != 1.0:
        print(slow_motion_note(recon))
    undetected = undetected_line(recon)
    if undetected:
        print(undetected)
    if recon.has_physics:
        print(restarts_line(recon))
        forces = forces_summary(recon)
        if forces is not None:
            print(f"physics: {forces} (forces.csv; docs/dynamics.md, Forces and torques)")
    for line in diagnostics_lines(recon):
        print(f"warning: {line}")
    if metrics:
        print("\nmetrics (no ground truth needed; docs/metrics.md):")
        print(metrics_table(metrics))
    print(f"\nfiles in {out.resolve()}:")
    files = {"reconstruction": out / RECONSTRUCTION_FILE, "config": out / CONFIG_FILE,
             **written}
    for key, path in files.items():
        print(f"  {_OUTPUT_NAMES.get(key, key):<26} {path.name}")
    total = sum(timings.values())
    print("\ntime per stage: " + ", ".join(f"{k} {v:.1f} s" for k, v in timings.items())
          + f" (total {total:.1f} s)")


def load_input(video: Path, config: PipelineConfig, camera_K: np.ndarray | None
               ) -> Observations:
    """Observations of the input (observe stage, cached), with the calibration's K if given."""
    from physpose.pipeline import load_observations  # noqa: PLC0415

    print(f"observe: {video}", file=sys.stderr, flush=True)
    obs = load_observations(video, config.footage_observe(), progress=True)
    return obs if camera_K is None else dataclasses.replace(obs, camera_K=camera_K)


def run(args: argparse.Namespace) -> int:
    from physpose.pipeline import reconstruct  # noqa: PLC0415 (heavy imports)

    formats = parse_formats(args.export)
    config = pipeline_config(args)
    image_size, seconds = check_input(args.video, config)
    check_person(args.height, args.mass)
    check_output_folder(args.out)
    K = given_intrinsics(args.camera, args.camera_name, args.video, image_size)
    if seconds is not None:  # a video: before observing it, which takes minutes on a long one
        _tell_duration(seconds, args.preset, config, keypoints=False)
    timings: dict[str, float] = {}
    clock = time.perf_counter()
    obs = load_input(args.video, config, K)
    timings["observe"] = time.perf_counter() - clock
    if seconds is None:  # a keypoints file, as read
        _tell_duration(obs.num_frames / obs.fps, args.preset, config, keypoints=True)
    recon = reconstruct(obs, args.out, config, height=args.height, mass=args.mass,
                        resume=args.resume and not args.no_cache, progress=True)
    timings.update({k: v for k, v in recon.meta.get("timings_s", {}).items()
                    if k != "observe"})
    written, metrics = finish(args.out, formats, report=not args.no_report,
                              overlay=not args.no_overlay, timings=timings)
    print_summary(recon, args.out, written, metrics, timings)
    return 0


def finish(out: Path, formats: tuple[str, ...], *, report: bool, overlay: bool,
           timings: dict[str, float]) -> tuple[dict[str, Path], dict]:
    """write_outputs with a progress line; adds its time to timings; returns (files, metrics)."""
    print("outputs: metrics" + ", report" * report + ", overlay video" * overlay
          + "".join(f", {f}" for f in formats), file=sys.stderr, flush=True)
    clock = time.perf_counter()
    written = write_outputs(out, formats=formats, report=report, overlay=overlay)
    timings["outputs"] = time.perf_counter() - clock
    return written, json.loads((out / METRICS_FILE).read_text())
