"""`physpose observe`: video (or precomputed keypoints) -> observations.npz + overlay video."""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import shutil
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from physpose import __version__
from physpose.errors import PhysposeError
from physpose.keypoints_io import is_keypoints_file, load_keypoints
from physpose.observations import Observations
from physpose.observe import ObserveConfig, observe
from physpose.overlay2d import write_overlay
from physpose.paths import check_output_folder

OBSERVATIONS_FILE = "observations.npz"
OVERLAY_FILE = "overlay_landmarks.mp4"
CONFIG_FILE = "config.json"


@dataclass(frozen=True)
class ObserveRun:
    """What one run of the observe step produced."""

    observations: Observations
    files: tuple[Path, ...]   # the files written into the output folder
    seconds: float            # wall time of the run

    def summary(self) -> str:
        obs = self.observations
        n, found, filled = obs.num_frames, int(obs.detected.sum()), int(obs.interpolated.sum())
        torn = 0 if obs.unsure is None else int(obs.unsure.sum())
        return (f"{Path(obs.source).name}: {n} frames at {obs.fps:g} fps, person found in "
                f"{found}/{n} ({100 * found / n:.1f}%), {filled} interpolated, "
                + (f"{torn} left out as torn, " if torn else "") +
                f"{self.seconds:.1f} s{_camera_note(obs.camera_motion)}\n"
                + "".join(f"  wrote {p}\n" for p in self.files))


def _camera_note(kind: str | None) -> str:
    return {"turning": ", camera turning (detections mapped into the middle frame's view)",
            "moving": ", camera moving (not compensated)"}.get(kind or "", "")


def run_observe(source: str | Path, out_dir: str | Path, cfg: ObserveConfig = ObserveConfig(),
                *, overlay: bool = True, progress: bool = True) -> ObserveRun:
    """Observe a video (or load a .json/.npz keypoints file) and write the results to out_dir.

    Files are written into a temporary folder inside out_dir and moved into place only when
    all succeeded, so a failure never destroys earlier outputs.
    """
    start = time.perf_counter()
    source, out_dir = Path(source), Path(out_dir)
    keypoints = is_keypoints_file(source)
    if keypoints:
        refuse_video_options(cfg, source)
    check_output_folder(out_dir)
    obs = load_keypoints(source) if keypoints else observe(source, cfg, progress=progress)
    out_dir.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=out_dir, prefix=".observe-"))
    try:
        names = [OBSERVATIONS_FILE, CONFIG_FILE]
        obs.save(tmp / OBSERVATIONS_FILE)
        if overlay:
            write_overlay(obs, tmp / OVERLAY_FILE, None if keypoints else source,
                          progress=progress)
            names.append(OVERLAY_FILE)
        resolved = {
            "stage": "observe", "physpose_version": __version__,
            "input": str(source.resolve()), "input_kind": "keypoints" if keypoints else "video",
            "observe": None if keypoints else dataclasses.asdict(cfg),
            "frames": obs.num_frames, "fps": obs.fps, "image_size": list(obs.image_size),
        }
        (tmp / CONFIG_FILE).write_text(json.dumps(resolved, indent=2) + "\n")
        for name in names:
            os.replace(tmp / name, out_dir / name)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    files = tuple(out_dir / name for name in names)
    return ObserveRun(observations=obs, files=files, seconds=time.perf_counter() - start)


STATIC_CAMERA_HELP = ("take the camera as fixed: do not look for it turning (by default "
                      "physpose measures a pan or tilt from the background and maps the "
                      "detections into the middle frame's view)")
PERSON_HELP = ("follow the person at this pixel (x,y, origin top left) of the first analysed "
               "frame, e.g. 1210,600, instead of the one physpose picks (the one the detector "
               "finds most); for videos with several people")


def image_point(text: str) -> tuple[float, float]:
    """argparse type of --person: 'X,Y' in pixels."""
    try:
        x, y = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not X,Y in pixels, e.g. 640,360") from None
    return x, y


def add_video_options(p: argparse.ArgumentParser) -> None:
    """The options that say how a video is observed (observe and fit; reconstruct has its own
    help for them, in real time under --slow-motion)."""
    p.add_argument("--fps", type=float, default=None, metavar="F",
                   help=f"analysis frame rate, Hz (default {ObserveConfig.target_fps:g}; "
                        "never above the video's own)")
    p.add_argument("--start", type=float, default=None, metavar="S", help="start time, s")
    p.add_argument("--end", type=float, default=None, metavar="E", help="end time, s")
    p.add_argument("--person", type=image_point, default=None, metavar="X,Y", help=PERSON_HELP)
    p.add_argument("--static-camera", action="store_true", help=STATIC_CAMERA_HELP)
    p.add_argument("--no-cache", action="store_true", help="recompute even if cached")


def refuse_video_options(cfg: ObserveConfig, keypoints: Path) -> None:
    """Keypoints (or observations) were detected already: options that say how to observe a
    video (anything but the cache choice) cannot apply to them."""
    if cfg != dataclasses.replace(ObserveConfig(), use_cache=cfg.use_cache):
        raise PhysposeError("--fps/--start/--end/--person/--static-camera apply to videos, not "
                            "to precomputed keypoints", path=keypoints,
                            remedy="drop those options, or cut or resample the keypoints file")


def config_from_args(args: argparse.Namespace) -> ObserveConfig:
    """ObserveConfig from the shared --fps/--start/--end/--person/--static-camera/--no-cache
    options."""
    return ObserveConfig(target_fps=ObserveConfig.target_fps if args.fps is None else args.fps,
                         start=args.start, end=args.end, person=args.person,
                         stabilize=not args.static_camera, use_cache=not args.no_cache)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "observe", help="detect 2d/3d landmarks in a video (MediaPipe Pose)",
        description="Run MediaPipe Pose on a video resampled to --fps and write "
                    f"{OBSERVATIONS_FILE}, {OVERLAY_FILE} (landmarks drawn on the frames) and "
                    f"{CONFIG_FILE} into --out. A .json/.npz keypoints file (see "
                    "docs/keypoints_format.md) is loaded instead of detected.")
    p.add_argument("input", type=Path, metavar="VIDEO_OR_KEYPOINTS",
                   help="video (mp4, avi, mov, ...) or keypoints file (.json, .npz)")
    p.add_argument("--out", type=Path, required=True, metavar="DIR", help="output folder")
    add_video_options(p)
    p.add_argument("--no-overlay", action="store_true", help="skip the overlay video")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    run = run_observe(args.input, args.out, config_from_args(args), overlay=not args.no_overlay)
    print("observe: " + run.summary(), end="")
    return 0
